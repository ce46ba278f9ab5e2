"""float64 GPF blocks, one function per hardware block, vectorised over the particles.

Shapes: N particles, n state components; `x` is (N, n), `w` is (N,). These are the accuracy
yardstick for the fixed-point model, so every convention below is the hardware's contract:

- bot: x = [px, vx, py, vy]; x' = Phi x + Gamma sqrt(q) e_proc; bearing residual
  d = wrap(z - atan2(py - oy, px - ox)) in (-pi, pi]; exponent t = 0.5 d^2 / R log2(e).
- uav: x = [q0, q1, q2, q3, vE, vN, vU] (scalar-first, body-to-navigation, ENU);
  omega' = omega + sigma_w e_gyro, a' = a + sigma_a e_acc,
  q' = (I + dt/2 Omega(omega')) q (particles are NOT renormalised),
  v' = v + (C(q) a' + g) dt with C of the OLD q and g = [0, 0, -9.8];
  exponent t = 0.5 ||v_gps - v||^2 / sigma_v^2 log2(e).
- Weights w = 2^-(t - min t) with t clamped at REACH = 2^8: relative to the step's best
  particle, as in fixed point. A step whose every exponent is at least REACH - 1 has no
  particle within reach: its weights are then all in (1/2, 1] (flag "zero_weights").
- Shapes may carry a leading run axis R: x (R, N, n), w (R, N), per-run operands (R, ...).
- Omega(w) = [[0,-wx,-wy,-wz],[wx,0,wz,-wy],[wy,-wz,0,wx],[wz,wy,-wx,0]]: identical to seed 002
  eq. 12 (and eq. 3); it is q_dot = 1/2 q (x) [0, w] with the Hamilton product.
- C(q) is the homogeneous quadratic form (q0^2 + q1^2 - q2^2 - q3^2 on the diagonal, no "1 -
  2(...)"): for a unit q it is the rotation matrix, for a particle of norm r it is r^2 times it,
  so a norm error acts as a pure scale error of the specific force and the GPS weight pulls the
  particle norms back towards 1.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from gpf.model.formats import T_INT_BITS

Array = npt.NDArray[np.float64]

GRAVITY = np.array([0.0, 0.0, -9.8])
ZERO_WEIGHTS = "zero_weights"
NOT_PD = "not_pd"
LOW_ESS = "low_ess"
FLAGS = (ZERO_WEIGHTS, NOT_PD, LOW_ESS)
# Cholesky pivot floor, relative to the diagonal entry: a power of two so that fixed point can
# apply it with a shift. A pivot <= floor means Sigma is not (numerically) positive definite.
PIVOT_REL_FLOOR = 2.0**-30
PIVOT_ABS_FLOOR = 2.0**-200  # when the diagonal entry itself is <= 0
LOG2E = math.log2(math.e)
REACH = float(2**T_INT_BITS)  # an exponent t beyond the fixed-point format's: out of reach


def sample_cond(mu: Array, L: Array, e_cond: Array) -> Array:  # noqa: N803 (L as in SPEC)
    """Conditioning particles x = mu + L e for every row e of e_cond (..., N, n)."""
    mu, L = np.asarray(mu), np.asarray(L)  # noqa: N806
    return mu[..., None, :] + np.einsum("...kj,...ij->...ki", e_cond, L)


def bot_matrices(dt: float) -> tuple[Array, Array]:
    """Phi (4x4) and Gamma (4x2) of the constant-velocity model, state [px, vx, py, vy]."""
    phi = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]], dtype=float)
    gamma = np.array([[dt * dt / 2, 0], [dt, 0], [0, dt * dt / 2], [0, dt]], dtype=float)
    return phi, gamma


def propagate_bot(x: Array, e_proc: Array, cfg: Any) -> Array:
    """x' = Phi x + Gamma w with w = sqrt(process_var) e_proc; x (..., 4), e_proc (..., 2)."""
    phi, gamma = bot_matrices(cfg.dt)
    w = math.sqrt(cfg.app_params["process_var"]) * e_proc
    return x @ phi.T + w @ gamma.T


def wrap_angle(a: Array | float) -> Array:
    """Wrap to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2 * np.pi)


def exponent_bot(x: Array, z: Any, obs: Array, cfg: Any) -> Array:
    """t = 0.5 d^2 / R log2(e), d the wrapped bearing residual seen from obs = (ox, oy); z and
    obs per run (...,) and (..., 2) for x (..., N, 4)."""
    z, obs = np.asarray(z, dtype=float), np.asarray(obs, dtype=float)
    d = wrap_angle(z[..., None] - np.arctan2(x[..., 2] - obs[..., 1, None],
                                             x[..., 0] - obs[..., 0, None]))
    return 0.5 * d * d / cfg.app_params["bearing_var"] * LOG2E


def relative_weights(t: Array) -> tuple[Array, Array]:
    """w = 2^-(t - min t) over the last axis, t clamped at REACH; and per run whether no
    particle is within reach (every exponent >= REACH - 1): its weights are then in (1/2, 1]."""
    t = np.minimum(t, REACH)
    best = t.min(axis=-1, keepdims=True)
    return np.exp2(best - t), best[..., 0] >= REACH - 1


def weight_bot(x: Array, z: Any, obs: Array, cfg: Any) -> Array:
    """Relative weights of bot particles (see relative_weights)."""
    return relative_weights(exponent_bot(x, z, obs, cfg))[0]


def rotation_matrix(q: Array) -> Array:
    """C(q) (..., 3, 3), body to navigation, homogeneous form (|q|^2 times a rotation)."""
    q0, q1, q2, q3 = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    rows = [
        [q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
        [2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)],
        [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def omega_matrix(w: Array) -> Array:
    """Omega(w) of seed 002 eq. 12, (..., 4, 4)."""
    wx, wy, wz = np.moveaxis(np.asarray(w, dtype=float), -1, 0)
    o = np.zeros_like(wx)
    rows = [[o, -wx, -wy, -wz], [wx, o, wz, -wy], [wy, -wz, o, wx], [wz, wy, -wx, o]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def propagate_uav(x: Array, e_gyro: Array, e_acc: Array, omega: Array, a: Array,
                  cfg: Any) -> Array:
    """One IMU step of every particle; x (..., N, 7), e_gyro and e_acc (..., N, 3), omega and a
    (..., 3) per run.

    Written out per component (the same sums as omega_matrix(w) @ q and rotation_matrix(q) @ a,
    without building N small matrices): C(q) f = (q0^2 - |u|^2) f + 2 (u.f) u + 2 q0 (u x f),
    u = (q1, q2, q3), is the homogeneous form for any norm of q.
    """
    p = cfg.app_params
    dt = cfg.dt
    omega, a = np.asarray(omega, dtype=float), np.asarray(a, dtype=float)
    wx, wy, wz = np.moveaxis(omega[..., None, :] + math.radians(p["sigma_omega_deg"]) * e_gyro,
                             -1, 0)
    fx, fy, fz = np.moveaxis(a[..., None, :] + p["sigma_a"] * e_acc, -1, 0)
    q0, q1, q2, q3 = (x[..., i] for i in range(4))
    h = 0.5 * dt
    out = np.empty_like(x)
    out[..., 0] = q0 + h * (-wx * q1 - wy * q2 - wz * q3)
    out[..., 1] = q1 + h * (wx * q0 + wz * q2 - wy * q3)
    out[..., 2] = q2 + h * (wy * q0 - wz * q1 + wx * q3)
    out[..., 3] = q3 + h * (wz * q0 + wy * q1 - wx * q2)
    s = q0 * q0 - (q1 * q1 + q2 * q2 + q3 * q3)
    uf2 = 2 * (q1 * fx + q2 * fy + q3 * fz)
    out[..., 4] = x[..., 4] + (s * fx + uf2 * q1 + 2 * q0 * (q2 * fz - q3 * fy) + GRAVITY[0]) * dt
    out[..., 5] = x[..., 5] + (s * fy + uf2 * q2 + 2 * q0 * (q3 * fx - q1 * fz) + GRAVITY[1]) * dt
    out[..., 6] = x[..., 6] + (s * fz + uf2 * q3 + 2 * q0 * (q1 * fy - q2 * fx) + GRAVITY[2]) * dt
    return out


def exponent_uav(x: Array, v_gps: Array, cfg: Any) -> Array:
    """t = 0.5 ||v_gps - v||^2 / sigma_v^2 log2(e); v_gps (..., 3) per run."""
    d = np.asarray(v_gps, dtype=float)[..., None, :] - x[..., 4:]
    return 0.5 * np.sum(d * d, axis=-1) / cfg.app_params["sigma_v"] ** 2 * LOG2E


def weight_uav(x: Array, v_gps: Array, cfg: Any) -> Array:
    """Relative weights of uav particles (see relative_weights)."""
    return relative_weights(exponent_uav(x, v_gps, cfg))[0]


def moments(x: Array, w: Array, ref: Array, app: str, covariance: str = "full"
            ) -> tuple[Array, Array]:
    """Weighted mean and covariance in one pass, deviations taken from `ref` (per run).

    W = sum w, S1 = sum w (x - ref), S2 = sum w (x - ref)(x - ref)^T; mu = ref + S1/W,
    Sigma = S2/W - (S1/W)(S1/W)^T. uav: the quaternion part of mu is then normalised and
    `covariance == "block"` zeroes the q-v cross blocks. W > 0: the best weight is 1.
    """
    dev = x - ref[..., None, :]
    total = np.sum(w, axis=-1)
    m = np.einsum("...k,...ki->...i", w, dev) / total[..., None]
    s2 = np.einsum("...k,...ki,...kj->...ij", w, dev, dev) / total[..., None, None]
    mu = ref + m
    sigma = s2 - m[..., :, None] * m[..., None, :]
    if app == "uav":
        norm = np.linalg.norm(mu[..., :4], axis=-1, keepdims=True)
        mu[..., :4] /= np.where(norm > 0, norm, 1.0)   # a zero quaternion is left as it is
        if covariance == "block":
            sigma[..., :4, 4:] = 0.0
            sigma[..., 4:, :4] = 0.0
    return mu, sigma


def effective_sample_size(w: Array) -> Array:
    """(sum w)^2 / sum w^2 per run."""
    return np.sum(w, axis=-1) ** 2 / np.sum(w * w, axis=-1)


def process_noise(cfg: Any) -> tuple[Array, Array]:
    """(F, Q): one step of the process model acting on a covariance, F Sigma F^T + Q. bot: the
    constant-velocity Phi and Gamma diag(q, q) Gamma^T; uav: the identity (one 10 ms IMU step
    moves a covariance by under 0.2 %) and the IMU noise per step, (dt/2 sigma_omega)^2 on
    each quaternion component and (sigma_a dt)^2 on each velocity."""
    if cfg.app == "bot":
        phi, gamma = bot_matrices(cfg.dt)
        return phi, cfg.app_params["process_var"] * gamma @ gamma.T
    p, dt = cfg.app_params, cfg.dt
    q_q = (dt / 2 * math.radians(p["sigma_omega_deg"])) ** 2
    return np.eye(7), np.diag([q_q] * 4 + [(p["sigma_a"] * dt) ** 2] * 3)


def predicted_covariance(sigma: Array, cfg: Any) -> Array:
    """F Sigma F^T + Q (process_noise) of covariances (..., n, n)."""
    f, q = process_noise(cfg)
    return f @ sigma @ f.T + q


def cholesky(sigma: Array) -> tuple[Array, Array]:
    """Lower-triangular L with L L^T = Sigma (..., n, n), regularised when Sigma is not positive
    definite; returns L and per matrix whether it was (the "not_pd" flag).

    Column by column, n square roots and n reciprocals, fixed latency (no retry), as the
    hardware does it. A pivot d_j (Sigma_jj minus the squares already in row j) that is not
    above floor_j = 2^-30 Sigma_jj (2^-200 when Sigma_jj <= 0) is replaced by floor_j and the
    column below it is set to zero (that direction is decorrelated from the later ones, which
    keeps L bounded even for an indefinite Sigma). For a positive semidefinite Sigma the change
    is at most sqrt(d_i floor_j) per entry.
    """
    sigma = np.asarray(sigma, dtype=float)
    n = sigma.shape[-1]
    chol = np.zeros(sigma.shape)
    not_pd = np.zeros(sigma.shape[:-2], dtype=bool)
    for j in range(n):
        row = chol[..., j, :j]
        diag = sigma[..., j, j]
        d = diag - np.sum(row * row, axis=-1)
        floor = np.where(diag > 0, PIVOT_REL_FLOOR * diag, PIVOT_ABS_FLOOR)
        floored = ~(d > floor)           # also catches NaN
        not_pd |= floored
        ljj = np.sqrt(np.where(floored, floor, d))
        chol[..., j, j] = ljj
        below = (sigma[..., j + 1:, j] - np.einsum("...ik,...k->...i", chol[..., j + 1:, :j], row)
                 ) / ljj[..., None]
        chol[..., j + 1:, j] = np.where(floored[..., None], 0.0, below)
    return chol, not_pd

"""float64 GPF blocks, one function per hardware block, vectorised over the particles.

Shapes: N particles, n state components; `x` is (N, n), `w` is (N,). These are the accuracy
yardstick for the fixed-point model, so every convention below is the hardware's contract:

- bot: x = [px, vx, py, vy]; x' = Phi x + Gamma sqrt(q) e_proc; bearing residual
  d = wrap(z - atan2(py - oy, px - ox)) in (-pi, pi]; w = exp(-0.5 d^2 / R).
- uav: x = [q0, q1, q2, q3, vE, vN, vU] (scalar-first, body-to-navigation, ENU);
  omega' = omega + sigma_w e_gyro, a' = a + sigma_a e_acc,
  q' = (I + dt/2 Omega(omega')) q (particles are NOT renormalised),
  v' = v + (C(q) a' + g) dt with C of the OLD q and g = [0, 0, -9.8];
  w = exp(-0.5 ||v_gps - v||^2 / sigma_v^2).
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

Array = npt.NDArray[np.float64]

GRAVITY = np.array([0.0, 0.0, -9.8])
ZERO_WEIGHTS = "zero_weights"
NOT_PD = "not_pd"
FLAGS = (ZERO_WEIGHTS, NOT_PD)
# Cholesky pivot floor, relative to the diagonal entry: a power of two so that fixed point can
# apply it with a shift. A pivot <= floor means Sigma is not (numerically) positive definite.
PIVOT_REL_FLOOR = 2.0**-30
PIVOT_ABS_FLOOR = 2.0**-200  # when the diagonal entry itself is <= 0


def sample_cond(mu: Array, L: Array, e_cond: Array) -> Array:  # noqa: N803 (L as in SPEC)
    """Conditioning particles x = mu + L e for every row e of e_cond (N, n)."""
    return mu + e_cond @ L.T


def bot_matrices(dt: float) -> tuple[Array, Array]:
    """Phi (4x4) and Gamma (4x2) of the constant-velocity model, state [px, vx, py, vy]."""
    phi = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]], dtype=float)
    gamma = np.array([[dt * dt / 2, 0], [dt, 0], [0, dt * dt / 2], [0, dt]], dtype=float)
    return phi, gamma


def propagate_bot(x: Array, e_proc: Array, cfg: Any) -> Array:
    """x' = Phi x + Gamma w with w = sqrt(process_var) e_proc; x (N, 4), e_proc (N, 2)."""
    phi, gamma = bot_matrices(cfg.dt)
    w = math.sqrt(cfg.app_params["process_var"]) * e_proc
    return x @ phi.T + w @ gamma.T


def wrap_angle(a: Array | float) -> Array:
    """Wrap to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2 * np.pi)


def weight_bot(x: Array, z: float, obs: Array, cfg: Any) -> Array:
    """exp(-0.5 d^2 / R), d the wrapped bearing residual seen from the observer obs = (ox, oy)."""
    d = wrap_angle(z - np.arctan2(x[:, 2] - obs[1], x[:, 0] - obs[0]))
    return np.exp(-0.5 * d * d / cfg.app_params["bearing_var"])


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
    """One IMU step of every particle; x (N, 7), e_gyro and e_acc (N, 3), omega and a (3,).

    Written out per component (the same sums as omega_matrix(w) @ q and rotation_matrix(q) @ a,
    without building N small matrices): C(q) f = (q0^2 - |u|^2) f + 2 (u.f) u + 2 q0 (u x f),
    u = (q1, q2, q3), is the homogeneous form for any norm of q.
    """
    p = cfg.app_params
    dt = cfg.dt
    wx, wy, wz = (omega + math.radians(p["sigma_omega_deg"]) * e_gyro).T
    fx, fy, fz = (a + p["sigma_a"] * e_acc).T
    q0, q1, q2, q3 = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
    h = 0.5 * dt
    out = np.empty_like(x)
    out[:, 0] = q0 + h * (-wx * q1 - wy * q2 - wz * q3)
    out[:, 1] = q1 + h * (wx * q0 + wz * q2 - wy * q3)
    out[:, 2] = q2 + h * (wy * q0 - wz * q1 + wx * q3)
    out[:, 3] = q3 + h * (wz * q0 + wy * q1 - wx * q2)
    s = q0 * q0 - (q1 * q1 + q2 * q2 + q3 * q3)
    uf2 = 2 * (q1 * fx + q2 * fy + q3 * fz)
    out[:, 4] = x[:, 4] + (s * fx + uf2 * q1 + 2 * q0 * (q2 * fz - q3 * fy) + GRAVITY[0]) * dt
    out[:, 5] = x[:, 5] + (s * fy + uf2 * q2 + 2 * q0 * (q3 * fx - q1 * fz) + GRAVITY[1]) * dt
    out[:, 6] = x[:, 6] + (s * fz + uf2 * q3 + 2 * q0 * (q1 * fy - q2 * fx) + GRAVITY[2]) * dt
    return out


def weight_uav(x: Array, v_gps: Array, cfg: Any) -> Array:
    """exp(-0.5 ||v_gps - v||^2 / sigma_v^2) for every particle."""
    d = v_gps - x[:, 4:]
    return np.exp(-0.5 * np.sum(d * d, axis=1) / cfg.app_params["sigma_v"] ** 2)


def moments(x: Array, w: Array, ref: Array, app: str, covariance: str = "full", *,
            sigma_prev: Array | None = None) -> tuple[Array, Array, set[str]]:
    """Weighted mean and covariance in one pass, deviations taken from `ref`.

    W = sum w, S1 = sum w (x - ref), S2 = sum w (x - ref)(x - ref)^T; mu = ref + S1/W,
    Sigma = S2/W - (S1/W)(S1/W)^T. uav: the quaternion part of mu is then normalised and
    `covariance == "block"` zeroes the q-v cross blocks. All weights zero (W == 0 or not finite):
    mu = ref, Sigma = sigma_prev (NaN if not given) and the "zero_weights" flag.
    """
    n = x.shape[1]
    total = float(np.sum(w))
    if not (math.isfinite(total) and total > 0):
        prev = np.full((n, n), np.nan) if sigma_prev is None else np.array(sigma_prev, float)
        return np.array(ref, dtype=float), prev, {ZERO_WEIGHTS}
    dev = x - ref
    s1 = w @ dev
    s2 = (dev * w[:, None]).T @ dev
    m = s1 / total
    mu = ref + m
    sigma = s2 / total - np.outer(m, m)
    if app == "uav":
        norm = np.linalg.norm(mu[:4])
        if norm > 0:  # a zero quaternion is left as it is, as in fixed point
            mu[:4] /= norm
        if covariance == "block":
            sigma[:4, 4:] = 0.0
            sigma[4:, :4] = 0.0
    return mu, sigma, set()


def cholesky(sigma: Array) -> tuple[Array, set[str]]:
    """Lower-triangular L with L L^T = Sigma, regularised when Sigma is not positive definite.

    Column by column, n square roots and n reciprocals, fixed latency (no retry), as the
    hardware does it. A pivot d_j (Sigma_jj minus the squares already in row j) that is not
    above floor_j = 2^-30 Sigma_jj (2^-200 when Sigma_jj <= 0) is replaced by floor_j and the
    column below it is set to zero (that direction is decorrelated from the later ones, which
    keeps L bounded even for an indefinite Sigma); the "not_pd" flag is raised. For a positive
    semidefinite Sigma the change is at most sqrt(d_i floor_j) per entry.
    """
    n = sigma.shape[0]
    chol = np.zeros((n, n))
    flags: set[str] = set()
    for j in range(n):
        row = chol[j, :j]
        d = sigma[j, j] - row @ row
        floor = PIVOT_REL_FLOOR * sigma[j, j] if sigma[j, j] > 0 else PIVOT_ABS_FLOOR
        if not d > floor:  # also catches NaN
            chol[j, j] = math.sqrt(floor)
            flags.add(NOT_PD)
            continue
        chol[j, j] = math.sqrt(d)
        chol[j + 1:, j] = (sigma[j + 1:, j] - chol[j + 1:, :j] @ row) * (1.0 / chol[j, j])
    return chol, flags

"""Bit-exact fixed-point GPF blocks, with the same boundaries as the RTL blocks.

All arrays hold raw integers (see formats.py for their formats). Line-rate blocks are vectorised
over particles: x has shape (N, n). Every function returns a `flags` int of Flag bits (sticky
status: OR them over a step); the line-rate ones, given per_particle=True, return each
particle's flags instead (an (N,) array: what the RTL's per-lane `sat` bit shows). Rounding is
half up, every overflow saturates and sets Flag.SAT, except where saturating is exact (an
exponent past the weight's underflow).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntFlag

import numpy as np

from gpf.model.fixed import Format, saturate, shift_round
from gpf.model.formats import CHOL_FLOOR_LSB, CHOL_FLOOR_REL_BITS, INV_GUARD, Const, Datapath
from gpf.model.primitives import div_round, sqrt_round


class Flag(IntFlag):
    SAT = 1            # a datapath value saturated
    ZERO_WEIGHTS = 2   # every weight was 0: the step fell back to the predicted mean
    NOT_PD = 4         # a Cholesky pivot was below the floor: regularised


def _any(flag: np.ndarray | bool, bit: Flag) -> int:
    return int(bit) if np.any(flag) else 0


def _marks(flag: np.ndarray | bool, bit: Flag) -> np.ndarray:
    """`bit` where `flag` is set, per element."""
    return np.where(flag, np.int64(bit), np.int64(0))


def _flags(marks: np.ndarray | int, n: int, per_particle: bool) -> np.ndarray | int:
    """A line-rate block's flags: per particle, or ORed over all n particles."""
    each = np.broadcast_to(np.asarray(marks, dtype=np.int64), (n,))
    if per_particle:
        return each.copy()
    return int(np.bitwise_or.reduce(each)) if n else 0


def round_sum(terms: list[tuple[np.ndarray | int, int]], out: Format
              ) -> tuple[np.ndarray, np.ndarray]:
    """Sum of exact terms (raw, frac), rounded once (half up) to `out` and saturated; the
    Flag.SAT marks per element."""
    frac = max(f for _, f in terms)
    total = sum(np.asarray(raw, dtype=np.int64) << (frac - f) for raw, f in terms)
    rounded = shift_round(total, frac - out.frac_bits, "half_up", width=62)
    raw, flag = saturate(rounded, out)
    return raw, _marks(flag, Flag.SAT)


def cmul(raw: np.ndarray, frac: int, c: Const) -> tuple[np.ndarray, int]:
    """An exact product with a constant: (raw, frac)."""
    return raw * c.raw, frac + c.frac


# ---- sample_cond -----------------------------------------------------------------------------
def sample_cond(dp: Datapath, mu: np.ndarray, chol: np.ndarray, e: np.ndarray,
                per_particle: bool = False) -> tuple[np.ndarray, np.ndarray | int]:
    """x_i = mu_i + sum_{j<=i} L_ij e_j, one rounding per component. mu (n,), L (n, n), e (N, n)."""
    out = np.empty(e.shape, dtype=np.int64)
    flags = 0
    for i in range(dp.n):
        terms = [(np.int64(mu[i]), dp.x[i].frac_bits)]
        terms += [(int(chol[i, j]) * e[:, j], dp.chol[i].frac_bits + dp.noise.frac_bits)
                  for j in range(i + 1)]
        out[:, i], f = round_sum(terms, dp.x[i])
        flags |= f
    return out, _flags(flags, len(e), per_particle)


# ---- propagate -------------------------------------------------------------------------------
def propagate_bot(dp: Datapath, x: np.ndarray, e: np.ndarray, per_particle: bool = False
                  ) -> tuple[np.ndarray, np.ndarray | int]:
    """p' = p + T v + a e, v' = v + b e per axis (x: [px, vx, py, vy], e: (N, 2) draws)."""
    c = dp.consts
    fx = dp.x[0].frac_bits
    fe = dp.noise.frac_bits
    out = np.empty_like(x)
    flags = 0
    for axis in range(2):
        p, v, draw = x[:, 2 * axis], x[:, 2 * axis + 1], e[:, axis]
        out[:, 2 * axis], f1 = round_sum([(p, fx), cmul(v, fx, c["T"]),
                                          cmul(draw, fe, c["a"])], dp.x[2 * axis])
        out[:, 2 * axis + 1], f2 = round_sum([(v, fx), cmul(draw, fe, c["b"])],
                                             dp.x[2 * axis + 1])
        flags |= f1 | f2
    return out, _flags(flags, len(x), per_particle)


# uav: q' = q + (dt/2) Omega(omega') q; rows of Omega(w) q as (sign, k of w, j of q) triples
_OMEGA_Q = (
    ((-1, 0, 1), (-1, 1, 2), (-1, 2, 3)),
    ((+1, 0, 0), (+1, 2, 2), (-1, 1, 3)),
    ((+1, 1, 0), (-1, 2, 1), (+1, 0, 3)),
    ((+1, 2, 0), (+1, 1, 1), (-1, 0, 2)),
)
# C(q) (body to navigation) entries as sums of (coefficient, a, b) for coefficient q_a q_b
_ROT = (
    (((1, 0, 0), (1, 1, 1), (-1, 2, 2), (-1, 3, 3)), ((2, 1, 2), (-2, 0, 3)),
     ((2, 1, 3), (2, 0, 2))),
    (((2, 1, 2), (2, 0, 3)), ((1, 0, 0), (-1, 1, 1), (1, 2, 2), (-1, 3, 3)),
     ((2, 2, 3), (-2, 0, 1))),
    (((2, 1, 3), (-2, 0, 2)), ((2, 2, 3), (2, 0, 1)),
     ((1, 0, 0), (-1, 1, 1), (-1, 2, 2), (1, 3, 3))),
)


def _sat_word(raw: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Saturate into `width` signed bits, whatever the binary point."""
    out, flag = saturate(raw, Format(True, 0, width - 1))
    return out, _marks(flag, Flag.SAT)


def propagate_uav(dp: Datapath, x: np.ndarray, e: np.ndarray, omega: np.ndarray,
                  accel: np.ndarray, per_particle: bool = False
                  ) -> tuple[np.ndarray, np.ndarray | int]:
    """Attitude and velocity, one IMU period. x: (N, 7) [q0..q3, vE, vN, vU]; e: (N, 6) draws
    [gyro x3, accel x3]; omega, accel: raw inputs in dp.gyro, dp.accel.

    omega' = omega + s_w e_g and a' = a + s_a e_a (rounded to the input formats);
    h = omega' dt/2 (one word, dp.h_frac fraction bits); q'_i = q_i + sum +-h_k q_j (one
    rounding); C_nm = sum +-c q_a q_b (one rounding, dp.rot); f_n = sum_m C_nm a'_m + g_n (one
    rounding, dp.accel); v'_n = v_n + f_n dt (one rounding). C uses the old q.
    """
    c, fe, flags = dp.consts, dp.noise.frac_bits, 0
    fg, fa, fq = dp.gyro.frac_bits, dp.accel.frac_bits, dp.x[0].frac_bits
    h = []
    for k in range(3):
        wk, f1 = round_sum([(np.int64(omega[k]), fg), cmul(e[:, k], fe, c["s_w"])], dp.gyro)
        prod, frac = cmul(wk, fg, c["dt2"])
        hk, f2 = _sat_word(shift_round(prod, frac - dp.h_frac, "half_up", width=62), dp.word)
        h.append(hk)
        flags |= f1 | f2
    a = []
    for m in range(3):
        am, f = round_sum([(np.int64(accel[m]), fa), cmul(e[:, 3 + m], fe, c["s_a"])],
                          dp.accel)
        a.append(am)
        flags |= f
    q = [x[:, i] for i in range(4)]
    out = np.empty_like(x)
    for i, row in enumerate(_OMEGA_Q):
        terms = [(q[i], fq)] + [(sign * h[k] * q[j], dp.h_frac + fq) for sign, k, j in row]
        out[:, i], f = round_sum(terms, dp.x[i])
        flags |= f
    rot = [[round_sum([(coef * q[ia] * q[ib], 2 * fq) for coef, ia, ib in entry], dp.rot)
            for entry in row] for row in _ROT]
    fr = dp.rot.frac_bits
    for n in range(3):
        flags |= rot[n][0][1] | rot[n][1][1] | rot[n][2][1]
        terms = [(rot[n][m][0] * a[m], fr + fa) for m in range(3)]
        terms.append((np.int64(dp.consts[f"g{n}"].raw), dp.consts[f"g{n}"].frac))
        f_n, f1 = round_sum(terms, dp.accel)
        out[:, 4 + n], f2 = round_sum([(x[:, 4 + n], dp.x[4 + n].frac_bits),
                                       cmul(f_n, fa, c["dt"])], dp.x[4 + n])
        flags |= f1 | f2
    return out, _flags(flags, len(x), per_particle)


# ---- weight ----------------------------------------------------------------------------------
def exponent_from_u(dp: Datapath, u_terms: list[np.ndarray]) -> np.ndarray:
    """t = sum u_k^2, saturated at its maximum (2^-t is 0 there already: no flag)."""
    total = sum(np.asarray(u, dtype=np.int64) ** 2 for u in u_terms)
    t = shift_round(total, 2 * dp.u.frac_bits - dp.t.frac_bits, "half_up", width=62)
    return np.minimum(t, dp.t.max_raw)


def whiten(dp: Datapath, d: np.ndarray, d_frac: int) -> np.ndarray:
    """u = d * c_u in the u format, saturated (|u| >= 16 means w = 0 anyway: no flag)."""
    prod, frac = cmul(d, d_frac, dp.consts["c_u"])
    u = shift_round(prod, frac - dp.u.frac_bits, "half_up", width=62)
    return np.clip(u, dp.u.min_raw, dp.u.max_raw)


def wrap_angle(raw: np.ndarray, frac: int) -> np.ndarray:
    """Binary angles (one turn = 2^frac) wrap modulo one turn into [-1/2, 1/2) turn: the
    two's complement wrap of a `frac`-bit word, the intended modular arithmetic of angles."""
    half = 1 << (frac - 1)
    return ((raw + half) % (1 << frac)) - half


def weight_bot(dp: Datapath, x: np.ndarray, z: int, obs: tuple[int, int],
               per_particle: bool = False) -> tuple[np.ndarray, np.ndarray | int]:
    """w = 2^-t, t = (wrap(z - atan2(py - oy, px - ox)) c_u)^2; z and atan2 in turns."""
    dx, f1 = saturate(x[:, 0] - obs[0], dp.x[0])
    dy, f2 = saturate(x[:, 2] - obs[1], dp.x[2])
    theta = dp.cordic.atan2(dy, dx)
    d = wrap_angle(np.int64(z) - theta, dp.angle_frac)
    t = exponent_from_u(dp, [whiten(dp, d, dp.angle_frac)])
    return dp.exp2(t), _flags(_marks(f1 | f2, Flag.SAT), len(x), per_particle)


def weight_uav(dp: Datapath, x: np.ndarray, v_gps: np.ndarray, per_particle: bool = False
               ) -> tuple[np.ndarray, np.ndarray | int]:
    """w = 2^-t, t = sum_k ((v_gps,k - v_k) c_u)^2 over the 3 velocity components."""
    flags, us = 0, []
    for k in range(3):
        fmt = dp.x[4 + k]
        dv, f = saturate(np.int64(v_gps[k]) - x[:, 4 + k], fmt)
        flags |= _marks(f, Flag.SAT)
        us.append(whiten(dp, dv, fmt.frac_bits))
    return dp.exp2(exponent_from_u(dp, us)), _flags(flags, len(x), per_particle)


# ---- moments ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sums:
    """What the moments block accumulates at line rate (exact integers)."""

    w: int                  # sum w, weight fraction bits
    s1: list[int]           # sum w dx_i, fraction bits weight + x_i
    s2: dict[tuple[int, int], int]  # sum p_i dx_j (i >= j), fraction x_i + x_j + p_guard
    p_guard: int            # p_i = w dx_i keeps this many bits below x_i's LSB


def product_guard(dp: Datapath) -> int:
    """Guard bits of p = w dx: as many as keep p dx within 62 bits (at most the weight's
    fraction, where p is exact). Small weights would otherwise round p to nothing."""
    return max(0, min(dp.weight.frac_bits, 62 - 2 * dp.word))


def exact_sum(values: np.ndarray) -> int:
    """The exact sum of int64 values of up to 62 bits (what a wide accumulator holds)."""
    high = values >> 31
    low = values & ((1 << 31) - 1)
    return (int(high.sum(dtype=np.int64)) << 31) + int(low.sum(dtype=np.int64))


def accumulate(dp: Datapath, x: np.ndarray, w: np.ndarray, ref: np.ndarray,
               pairs: list[tuple[int, int]]) -> tuple[Sums, int]:
    """One pass: dx = x - ref (saturated), W, S1 and S2 over the given (i, j) pairs."""
    flags = 0
    dx = np.empty_like(x)
    for i in range(dp.n):
        dx[:, i], f = saturate(x[:, i] - ref[i], dp.x[i])
        flags |= _any(f, Flag.SAT)
    guard = product_guard(dp)
    wdx = w[:, None] * dx                       # exact: weight x state bits
    p = shift_round(wdx, dp.weight.frac_bits - guard, "half_up", width=62)  # |w| <= 1
    s1 = [exact_sum(wdx[:, i]) for i in range(dp.n)]
    s2 = {(i, j): exact_sum(p[:, i] * dx[:, j]) for i, j in pairs}
    return Sums(int(w.sum(dtype=np.int64)), s1, s2, guard), flags


def finalise(dp: Datapath, sums: Sums, ref: np.ndarray, pairs: list[tuple[int, int]]
             ) -> tuple[np.ndarray, dict[tuple[int, int], int], int]:
    """mu = ref + S1/W; Sigma_ij = S2_ij/W - m_i m_j (exact divisions, one rounding each).

    m_i = S1_i / W carries CHOL_SHIFT extra fraction bits, so m_i m_j has Sigma's fraction.
    Returns mu (state formats), Sigma entries (raw, fraction dp.cov_frac(i, j)) and flags.
    """
    flags = 0
    m = []
    for i in range(dp.n):
        shift = dp.chol[i].frac_bits - dp.x[i].frac_bits
        m.append(int(div_round(sums.s1[i], sums.w, shift)))  # fraction chol_i
    mu = np.empty(dp.n, dtype=np.int64)
    for i in range(dp.n):
        shift = dp.chol[i].frac_bits - dp.x[i].frac_bits
        value = int(ref[i]) + int(shift_round(m[i], shift, "half_up", width=62))
        mu[i], f = saturate(value, dp.x[i])
        flags |= _any(f, Flag.SAT)
    sigma = {}
    for i, j in pairs:
        # S2: fraction x_i + x_j + guard; W: weight fraction; Sigma_ij: cov_frac(i, j)
        shift = (dp.weight.frac_bits + dp.cov_frac(i, j) - dp.x[i].frac_bits
                 - dp.x[j].frac_bits - sums.p_guard)
        value = int(div_round(sums.s2[(i, j)], sums.w, shift)) - m[i] * m[j]
        sigma[(i, j)], f = saturate(value, dp.sigma(i, j))
        flags |= _any(f, Flag.SAT)
    return mu, sigma, flags


def normalise_quaternion(dp: Datapath, mu: np.ndarray) -> tuple[np.ndarray, int]:
    """uav: q_hat = q / |q| (exact: |q| by a square root with CHOL_SHIFT guard bits, then 4
    rounded divisions). A zero quaternion is left as it is."""
    fq = dp.x[0].frac_bits
    norm2 = sum(int(mu[i]) ** 2 for i in range(4))               # fraction 2 fq
    if norm2 == 0:
        return mu, 0
    guard = dp.chol[0].frac_bits - fq
    norm = int(sqrt_round(norm2, 2 * fq, fq + guard))            # fraction fq + guard
    out, flags = mu.copy(), 0
    for i in range(4):
        out[i], f = saturate(int(div_round(int(mu[i]), norm, fq + guard)), dp.x[i])
        flags |= _any(f, Flag.SAT)
    return out, flags


def moments(dp: Datapath, x: np.ndarray, w: np.ndarray, ref: np.ndarray,
            pairs: list[tuple[int, int]]) -> tuple[np.ndarray, dict[tuple[int, int], int], int]:
    """The moments block over one step's particles: mu (uav: quaternion normalised) and Sigma.
    Every weight 0: mu = ref, Sigma = 0 and Flag.ZERO_WEIGHTS (the filter keeps its previous
    Sigma and L)."""
    sums, flags = accumulate(dp, x, w, ref, pairs)
    if sums.w == 0:
        return ref.copy(), dict.fromkeys(pairs, 0), flags | Flag.ZERO_WEIGHTS
    mu, sigma, f = finalise(dp, sums, ref, pairs)
    flags |= f
    if dp.app == "uav":
        mu, f = normalise_quaternion(dp, mu)
        flags |= f
    return mu, sigma, flags


def cov_pairs(dp: Datapath, covariance: str) -> list[tuple[int, int]]:
    """Lower-triangle (i >= j) entries kept: all, or the uav's [q] and [v] blocks."""
    pairs = [(i, j) for i in range(dp.n) for j in range(i + 1)]
    if covariance == "block" and dp.app == "uav":
        pairs = [(i, j) for i, j in pairs if (i < 4) == (j < 4)]
    return pairs


# ---- cholesky --------------------------------------------------------------------------------
def cholesky(dp: Datapath, sigma: dict[tuple[int, int], int]) -> tuple[np.ndarray, int]:
    """L with Sigma = L L^T: n square roots, n reciprocals, exact integer arithmetic.

    A pivot below max((CHOL_FLOOR_LSB LSB of L)^2, Sigma_jj 2^-CHOL_FLOOR_REL_BITS) is raised
    to that floor and its column below the
    diagonal set to 0 (flag NOT_PD): the filter keeps a valid factor when the covariance is
    singular or not positive definite.
    """
    n, flags = dp.n, 0
    chol = np.zeros((n, n), dtype=np.int64)
    for j in range(n):
        fj = dp.chol[j].frac_bits
        d = sigma[(j, j)] - sum(int(chol[j, k]) ** 2 for k in range(j))   # fraction 2 fj
        # below a floor relative to the diagonal the pivot is rounding residue of a (near)
        # singular direction: give it the floor's spread and no correlation rather than
        # divide that residue by a tiny pivot
        floor = max(CHOL_FLOOR_LSB**2, sigma[(j, j)] >> CHOL_FLOOR_REL_BITS)
        floored = d < floor
        if floored:
            d, flags = floor, flags | Flag.NOT_PD
        ljj, f = saturate(int(sqrt_round(d, 2 * fj, fj)), dp.chol[j])
        chol[j, j] = ljj
        flags |= _any(f, Flag.SAT)
        if floored:
            continue
        inv = int(div_round(1, int(ljj), 2 * fj + INV_GUARD))   # 1/L_jj, fraction fj + G
        for i in range(j + 1, n):
            if (i, j) not in sigma:
                continue
            num = sigma[(i, j)] - sum(int(chol[i, k]) * int(chol[j, k]) for k in range(j))
            # num: fraction fi + fj; inv: fj + G; L_ij: fi
            value = int(shift_round(num * inv, 2 * fj + INV_GUARD, "half_up", width=200))
            chol[i, j], f = saturate(value, dp.chol[i])
            flags |= _any(f, Flag.SAT)
    return chol, flags

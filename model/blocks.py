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
from typing import Any

import numpy as np

from gpf.model.fixed import Format, saturate, shift_round
from gpf.model.formats import (
    CHOL_FLOOR_LSB,
    CHOL_FLOOR_REL_BITS,
    SHIFT_BITS,
    Const,
    Datapath,
)
from gpf.model.primitives import div_round, sqrt_round

# round_sum and the products below form exact sums in int64: each is declared a signed
# 62-bit word to shift_round, whatever the operands within their formats (gpf.limits checks
# that a config's constants keep them so)
MODEL_SUM_BITS = 62


class Flag(IntFlag):
    SAT = 1            # a datapath value saturated
    ZERO_WEIGHTS = 2   # no particle within the exponent's reach: every weight in (1/2, 1]
    NOT_PD = 4         # a Cholesky pivot was below the floor: regularised
    LOW_ESS = 8        # effective sample size below ess_min: the predicted covariance is used


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
    rounded = shift_round(total, frac - out.frac_bits, "half_up", width=MODEL_SUM_BITS)
    raw, flag = saturate(rounded, out)
    return raw, _marks(flag, Flag.SAT)


def cmul(raw: np.ndarray, frac: int, c: Const) -> tuple[np.ndarray, int]:
    """An exact product with a constant: (raw, frac)."""
    return raw * c.raw, frac + c.frac


# ---- sample_cond -----------------------------------------------------------------------------
def sample_cond(dp: Datapath, mu: np.ndarray, chol: np.ndarray, e: np.ndarray,
                pairs: list[tuple[int, int]], per_particle: bool = False
                ) -> tuple[np.ndarray, np.ndarray | int]:
    """x_i = mu_i + sum_{j<=i} L_ij e_j over the covariance's pairs (L_ij of any other pair is 0
    by construction, cholesky_batch, and takes no product), one rounding per component. mu (n,),
    L (n, n), e (N, n); or mu (N, n) and L (N, n, n), one per particle (runs stacked)."""
    mu, chol = np.asarray(mu, dtype=np.int64), np.asarray(chol, dtype=np.int64)
    out = np.empty(e.shape, dtype=np.int64)
    flags = 0
    kept = set(pairs)
    for i in range(dp.n):
        terms = [(mu[..., i], dp.x[i].frac_bits)]
        terms += [(chol[..., i, j] * e[:, j], dp.chol[i].frac_bits + dp.noise.frac_bits)
                  for j in range(i + 1) if (i, j) in kept]
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


def half_angles(dp: Datapath, e: np.ndarray, omega: np.ndarray
                ) -> tuple[list[np.ndarray], np.ndarray | int]:
    """propagate_uav's h_k = omega'_k dt/2 (one word, dp.h_frac fraction bits), omega' = omega
    + s_w e_g rounded to dp.gyro; e (N, >= 3) draws, omega raw (3,) or one row per particle.
    Returns ([h0, h1, h2], flags)."""
    c, fe, fg, flags = dp.consts, dp.noise.frac_bits, dp.gyro.frac_bits, 0
    h = []
    for k in range(3):
        wk, f1 = round_sum([(omega[..., k], fg), cmul(e[:, k], fe, c["s_w"])], dp.gyro)
        prod, frac = cmul(wk, fg, c["dt2"])
        hk, f2 = _sat_word(shift_round(prod, frac - dp.h_frac, "half_up",
                                       width=MODEL_SUM_BITS), dp.word)
        h.append(hk)
        flags |= f1 | f2
    return h, flags


def propagate_uav(dp: Datapath, x: np.ndarray, e: np.ndarray, omega: np.ndarray,
                  accel: np.ndarray, per_particle: bool = False
                  ) -> tuple[np.ndarray, np.ndarray | int]:
    """Attitude and velocity, one IMU period. x: (N, 7) [q0..q3, vE, vN, vU]; e: (N, 6) draws
    [gyro x3, accel x3]; omega, accel: raw inputs in dp.gyro, dp.accel, (3,) or one row per
    particle.

    omega' = omega + s_w e_g and a' = a + s_a e_a (rounded to the input formats);
    h = omega' dt/2 (one word, dp.h_frac fraction bits); q'_i = q_i + sum +-h_k q_j (one
    rounding); C_nm = sum +-c q_a q_b (one rounding, dp.rot); f_n = sum_m C_nm a'_m + g_n (one
    rounding, dp.accel); v'_n = v_n + f_n dt (one rounding). C uses the old q.
    """
    c, fe = dp.consts, dp.noise.frac_bits
    omega, accel = np.asarray(omega, dtype=np.int64), np.asarray(accel, dtype=np.int64)
    fa, fq = dp.accel.frac_bits, dp.x[0].frac_bits
    h, flags = half_angles(dp, e, omega)
    a = []
    for m in range(3):
        am, f = round_sum([(accel[..., m], fa), cmul(e[:, 3 + m], fe, c["s_a"])],
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
    """t = sum u_k^2, saturated at its maximum (beyond the exponent's reach: no flag)."""
    total = sum(np.asarray(u, dtype=np.int64) ** 2 for u in u_terms)
    t = shift_round(total, 2 * dp.u.frac_bits - dp.t.frac_bits, "half_up", width=MODEL_SUM_BITS)
    return np.minimum(t, dp.t.max_raw)


def whiten(dp: Datapath, d: np.ndarray, d_frac: int) -> np.ndarray:
    """u = d * c_u in the u format, saturated (|u| >= 32 is beyond the exponent's reach: no
    flag)."""
    prod, frac = cmul(d, d_frac, dp.consts["c_u"])
    u = shift_round(prod, frac - dp.u.frac_bits, "half_up", width=MODEL_SUM_BITS)
    return np.clip(u, dp.u.min_raw, dp.u.max_raw)


def wrap_angle(raw: np.ndarray, frac: int) -> np.ndarray:
    """Binary angles (one turn = 2^frac) wrap modulo one turn into [-1/2, 1/2) turn: the
    two's complement wrap of a `frac`-bit word, the intended modular arithmetic of angles."""
    half = 1 << (frac - 1)
    return ((raw + half) % (1 << frac)) - half


def exponent_bot(dp: Datapath, x: np.ndarray, z: Any, obs: Any) -> tuple[np.ndarray, np.ndarray]:
    """t = (wrap(z - atan2(py - oy, px - ox)) c_u)^2, z and atan2 in turns; per particle SAT
    marks (dx or dy saturated). z and obs = (ox, oy) are scalars or one value per particle."""
    dx, f1 = saturate(x[:, 0] - np.asarray(obs[0], dtype=np.int64), dp.x[0])
    dy, f2 = saturate(x[:, 2] - np.asarray(obs[1], dtype=np.int64), dp.x[2])
    theta = dp.cordic.atan2(dy, dx)
    d = wrap_angle(np.asarray(z, dtype=np.int64) - theta, dp.angle_frac)
    return exponent_from_u(dp, [whiten(dp, d, dp.angle_frac)]), _marks(f1 | f2, Flag.SAT)


def exponent_uav(dp: Datapath, x: np.ndarray, v_gps: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """t = sum_k ((v_gps,k - v_k) c_u)^2 over the 3 velocity components; per particle SAT marks.
    v_gps is (3,) or one row per particle."""
    v_gps = np.asarray(v_gps, dtype=np.int64)
    marks, us = np.zeros(len(x), dtype=np.int64), []
    for k in range(3):
        fmt = dp.x[4 + k]
        dv, f = saturate(v_gps[..., k] - x[:, 4 + k], fmt)
        marks |= _marks(f, Flag.SAT)
        us.append(whiten(dp, dv, fmt.frac_bits))
    return exponent_from_u(dp, us), marks


def reach_top(dp: Datapath) -> int:
    """The integer part of the largest exponent: where a step's running minimum starts. A step
    whose every exponent is at least this has no particle within the exponent's reach."""
    return dp.t.max_raw >> dp.t.frac_bits


def relative_weights(dp: Datapath, t: np.ndarray, lanes: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Weights relative to the best particle so far, for one step's exponents t (..., N) in
    beats of `lanes` particles.

    R_b = min(R_{b-1}, min over beat b of floor(t)), R_0 = reach_top; every particle of beat b
    gets w = 2^-(t - R_b), so the best particle of a step has w in (1/2, 1] and the weights
    cannot all underflow. shift_b = min(R_{b-1} - R_b, 2^SHIFT_BITS - 1) (..., N / lanes) is
    the exact power-of-two rescale of everything summed before beat b (the moments block
    applies it; a shift as wide as an accumulator clears it, so the cap changes nothing).
    Returns (w, shift)."""
    top = reach_top(dp)
    floor = t >> dp.t.frac_bits
    beat_min = floor.reshape(*floor.shape[:-1], -1, lanes).min(axis=-1)
    running = np.minimum.accumulate(np.minimum(beat_min, top), axis=-1)
    before = np.concatenate([np.full(running.shape[:-1] + (1,), top, dtype=np.int64),
                             running[..., :-1]], axis=-1)
    offset = np.repeat(running, lanes, axis=-1) << dp.t.frac_bits
    return dp.exp2(t - offset), np.minimum(before - running, (1 << SHIFT_BITS) - 1)


def weight_bot(dp: Datapath, x: np.ndarray, z: Any, obs: Any, lanes: int = 1,
               per_particle: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | int]:
    """The weight block for one step's particles x (N, 4) in beats of `lanes`: (w, shift,
    flags), w relative to the best particle so far (relative_weights)."""
    t, marks = exponent_bot(dp, x, z, obs)
    w, shift = relative_weights(dp, t, lanes)
    return w, shift, _flags(marks, len(x), per_particle)


def weight_uav(dp: Datapath, x: np.ndarray, v_gps: np.ndarray, lanes: int = 1,
               per_particle: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | int]:
    """As weight_bot for the uav's GPS velocity likelihood."""
    t, marks = exponent_uav(dp, x, v_gps)
    w, shift = relative_weights(dp, t, lanes)
    return w, shift, _flags(marks, len(x), per_particle)


# ---- moments ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sums:
    """What the moments block accumulates at line rate, per run (object arrays of exact
    integers, leading axis R): every sum rescaled by the beats' shifts (round half up), so all
    are relative to the step's best particle (interleaved_sums)."""

    w: np.ndarray           # (R,) sum w, weight fraction bits
    s1: np.ndarray          # (R, n) sum w dx_i, fraction weight + x_i
    s2: np.ndarray          # (R, P) sum p_i dx_j over the pairs, fraction x_i + x_j + p_guard
    ww: np.ndarray          # (R,) sum w^2 (rescaled by 2 shift), fraction 2 x weight
    in_reach: np.ndarray    # (R,) bool: some beat moved the running minimum below reach_top
    p_guard: int            # p_i = w dx_i keeps this many bits below x_i's LSB


# p = w dx rounded to at most this many bits (signed): one multiplier operand, the DSP48E1's
# 25-bit port (two 18-bit parts on ECP5), so S2's p_i dx_j is one product a pair at line rate
P_BITS = 25


def product_max(dp: Datapath, guard: int) -> int:
    """Largest |p|, p = round(w dx 2^-(weight fraction - guard)), over the formats' extremes."""
    k = dp.weight.frac_bits - guard
    return (dp.weight.max_raw * (1 << (dp.word - 1)) + ((1 << k) >> 1)) >> k


def product_width(dp: Datapath, guard: int) -> int:
    """Signed width of p (product_max)."""
    return product_max(dp, guard).bit_length() + 1


def product_guard(dp: Datapath) -> int:
    """Guard bits of p = w dx below x's LSB: as many as keep p within P_BITS (and p dx within 62
    bits), at most the weight's fraction (p exact). The rounding error, under half a guard LSB
    of dx a particle and of either sign, is far below the covariance's own sampling error
    (Monte Carlo: README "Quality against float64"); too few guard bits would round small
    weights' p to nothing."""
    guard = max(0, min(dp.weight.frac_bits, 62 - 2 * dp.word))
    while guard > 0 and product_width(dp, guard) > P_BITS:
        guard -= 1
    return guard


def round_shift(acc: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """round(acc 2^-shift), half up, on object arrays of Python ints (any shift >= 0)."""
    shift = np.asarray(shift).astype(object)
    return (acc + ((1 << shift) >> 1)) >> shift


_LOW = (1 << 31) - 1


def rescaled_sums(values: np.ndarray, shift: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per run, acc <- round_shift(acc, shift_b scale) + (sum of beat b's values) over beats b.

    values (R, N, A) int64 terms of up to 62 bits, one column per accumulator; shift (R, B)
    with N = B x lanes; scale (A,) how many times the shift each accumulator takes. Exact: the
    particles between two rescales (a few segments a step: the running minimum falls rarely)
    are summed in one pass, in int64 where the column's largest magnitude allows, else as
    31-bit halves; only the segment sums go through Python integers. Returns (R, A) object."""
    runs, n, cols = values.shape
    beats = shift.shape[1]
    lanes = n // beats
    event = shift > 0
    event[:, 0] = True                           # every run's first segment starts at beat 0
    er, eb = np.nonzero(event)                   # segment starts, run by run in order
    starts = er * n + eb * lanes
    flat = values.reshape(runs * n, cols)
    biggest = np.abs(flat).max(axis=0) if flat.size else np.zeros(cols, np.int64)
    safe = biggest < (1 << 62) // max(n, 1)      # n of them cannot overflow int64
    seg = np.empty((len(starts), cols), dtype=object)
    if np.any(safe):
        seg[:, safe] = np.add.reduceat(flat[:, safe], starts, axis=0).astype(object)
    if not np.all(safe):
        wide = flat[:, ~safe]
        hi = np.add.reduceat(wide >> 31, starts, axis=0).astype(object)
        lo = np.add.reduceat(wide & _LOW, starts, axis=0).astype(object)
        seg[:, ~safe] = (hi << 31) + lo
    rank = np.arange(len(er)) - np.searchsorted(er, er)   # a segment's place in its run
    kmax = int(rank.max()) + 1
    padded = np.zeros((runs, kmax, cols), dtype=object)
    padded[er, rank] = seg
    seg_shift = np.zeros((runs, kmax), dtype=np.int64)
    seg_shift[er, rank] = np.where(eb > 0, shift[er, eb], 0)
    acc = padded[:, 0]
    for k in range(1, kmax):
        acc = round_shift(acc, seg_shift[:, k, None] * scale[None, :]) + padded[:, k]
    return acc


def interleaved_sums(values: np.ndarray, shift: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """The moments block's sums: two accumulators take the beats in turn (beat b to b mod 2), a
    beat of zeros with shift 0 after the step's last, then their total. Each accumulator
    rescales by every shift since its own last beat, in one rounding: acc <- round(acc
    2^-(s_b-1 + s_b) scale) + beat b (rescaled_sums on its beats). Each is updated every other
    beat, so the hardware's rescale and add take a clock each (a loop of two clocks, the two
    accumulators in flight in it); the zero beat brings the other accumulator to the last
    beat's scale. A rescale rounds two partial sums instead of one whole (at most half an LSB
    more a rescale; quality: README, "Quality against float64"). values (R, N, A), shift (R, B),
    N = B x lanes; returns (R, A) object."""
    runs, n, cols = values.shape
    beats = shift.shape[1]
    lanes = n // beats
    v = np.concatenate([values.reshape(runs, beats, lanes, cols),
                        np.zeros((runs, 1, lanes, cols), dtype=values.dtype)], axis=1)
    s = np.concatenate([shift, np.zeros((runs, 1), dtype=shift.dtype)], axis=1)
    since = s.copy()
    since[:, 1:] += s[:, :-1]                    # the shifts since the same accumulator's last
    total = np.zeros((runs, cols), dtype=object)
    for first in (0, 1):
        beats_of = v[:, first::2]
        if beats_of.shape[1]:
            total = total + rescaled_sums(beats_of.reshape(runs, -1, cols), since[:, first::2],
                                          scale)
    return total


def accumulate(dp: Datapath, x: np.ndarray, w: np.ndarray, shift: np.ndarray,
               ref: np.ndarray, pairs: list[tuple[int, int]]) -> tuple[Sums, np.ndarray]:
    """One pass per run: dx = x - ref (saturated), W, S1, S2 and sum w^2, rescaled by the
    weight block's shifts. x (R, N, n), w (R, N), shift (R, B), ref (R, n). Flags per run."""
    runs, n_part, n = x.shape
    dx, f = _saturate_columns(dp, x - ref[:, None, :])
    flags = np.where(np.any(f, axis=(1, 2)), np.int64(Flag.SAT), np.int64(0))
    guard = product_guard(dp)
    values = np.empty((runs, n_part, 2 + n + len(pairs)), dtype=np.int64)
    values[..., 0] = w
    wdx = values[..., 1:1 + n]
    np.multiply(w[..., None], dx, out=wdx)            # exact: weight x state bits
    p = shift_round(wdx, dp.weight.frac_bits - guard, "half_up", width=MODEL_SUM_BITS)  # |w| <= 1
    for q, (i, j) in enumerate(pairs):
        np.multiply(p[..., i], dx[..., j], out=values[..., 1 + n + q])
    np.multiply(w, w, out=values[..., -1])
    scale = np.array([1] * (1 + n + len(pairs)) + [2], dtype=np.int64)
    acc = interleaved_sums(values, shift, scale)
    in_reach = np.any(shift > 0, axis=1)
    sums = Sums(acc[:, 0], acc[:, 1:1 + n], acc[:, 1 + n:1 + n + len(pairs)], acc[:, -1],
                in_reach, guard)
    return sums, flags


def _saturate_columns(dp: Datapath, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """saturate() of each state component into its own format (..., n)."""
    out, flag = np.empty_like(v), np.empty(v.shape, dtype=bool)
    for i, fmt in enumerate(dp.x):
        out[..., i], flag[..., i] = saturate(v[..., i], fmt)
    return out, flag


def _sat_obj(v: np.ndarray, fmt: Any) -> tuple[np.ndarray, np.ndarray]:
    """Clamp an object array of ints into fmt: (int64 values, flags)."""
    lo, hi = fmt.min_raw, fmt.max_raw
    flag = np.array([(x < lo) or (x > hi) for x in v.flat], dtype=bool).reshape(v.shape)
    out = np.array([min(max(x, lo), hi) for x in v.flat], dtype=np.int64).reshape(v.shape)
    return out, flag


def finalise(dp: Datapath, sums: Sums, ref: np.ndarray, pairs: list[tuple[int, int]]
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """mu = ref + S1/W; Sigma_ij = S2_ij/W - m_i m_j; ESS = W^2 / sum w^2 (exact divisions, one
    rounding each), per run. W > 0: the best particle's weight is at least 1/2.

    m_i = S1_i / W carries CHOL_SHIFT extra fraction bits, so m_i m_j has Sigma's fraction; mu
    rounds S1/W once (rounding m_i again would bias it: half-up twice moves [k + 1/4, k + 1/2)
    up, +1/4 LSB a step for s = 1, a drift the weakly observable tilt of the uav cannot undo).
    Both come from one quotient in hardware. Returns mu (R, n) state formats, Sigma (R, P) raw
    (fraction dp.cov_frac(i, j)), ESS (R,) in dp.ess, flags (R,)."""
    runs = len(sums.w)
    flags = np.zeros(runs, dtype=np.int64)
    m, mu = [], np.empty((runs, dp.n), dtype=np.int64)
    for i in range(dp.n):
        shift = dp.chol[i].frac_bits - dp.x[i].frac_bits
        m.append(div_round(sums.s1[:, i], sums.w, shift))            # fraction chol_i
        value = ref[:, i].astype(object) + div_round(sums.s1[:, i], sums.w, 0)
        mu[:, i], f = _sat_obj(value, dp.x[i])
        flags |= np.where(f, np.int64(Flag.SAT), np.int64(0))
    sigma = np.empty((runs, len(pairs)), dtype=np.int64)
    for q, (i, j) in enumerate(pairs):
        # S2: fraction x_i + x_j + guard; W: weight fraction; Sigma_ij: cov_frac(i, j)
        shift = (dp.weight.frac_bits + dp.cov_frac(i, j) - dp.x[i].frac_bits
                 - dp.x[j].frac_bits - sums.p_guard)
        value = div_round(sums.s2[:, q], sums.w, shift) - m[i] * m[j]
        sigma[:, q], f = _sat_obj(value, dp.sigma(i, j))
        flags |= np.where(f, np.int64(Flag.SAT), np.int64(0))
    ess, _ = _sat_obj(div_round(sums.w * sums.w, sums.ww, dp.ess.frac_bits), dp.ess)
    flags |= np.where(sums.in_reach, np.int64(0), np.int64(Flag.ZERO_WEIGHTS))
    return mu, sigma, ess, flags


def normalise_quaternion(dp: Datapath, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """uav: q_hat = q / |q| for mu (R, n) (exact: |q| by a square root with CHOL_SHIFT guard
    bits, then 4 rounded divisions). A zero quaternion is left as it is. Returns (mu, flags)."""
    fq = dp.x[0].frac_bits
    q = _obj(mu[:, :4])
    norm2 = np.sum(q * q, axis=1)                                 # fraction 2 fq
    zero = np.asarray(norm2 == 0, dtype=bool)
    guard = dp.chol[0].frac_bits - fq
    norm = _obj(sqrt_round(np.where(zero, 1, norm2), 2 * fq, fq + guard))  # fraction fq + guard
    out, flags = mu.copy(), np.zeros(len(mu), dtype=np.int64)
    for i in range(4):
        value, f = _sat_obj(div_round(q[:, i], norm, fq + guard), dp.x[i])
        out[:, i] = np.where(zero, mu[:, i], value)
        flags |= np.where(f & ~zero, np.int64(Flag.SAT), np.int64(0))
    return out, flags


@dataclass(frozen=True)
class MomentsResult:
    """The moments block's result beat for R runs."""

    mu: np.ndarray       # (R, n) state formats (uav: quaternion normalised)
    sigma: np.ndarray    # (R, P) raw, the pairs' order
    ess: np.ndarray      # (R,) raw, dp.ess
    flags: np.ndarray    # (R,) SAT, ZERO_WEIGHTS


def moments_batch(dp: Datapath, x: np.ndarray, w: np.ndarray, shift: np.ndarray,
                  ref: np.ndarray, pairs: list[tuple[int, int]]) -> MomentsResult:
    """The moments block over one step's particles of R runs (see accumulate). No particle
    within reach (every exponent >= reach_top) leaves every weight in (1/2, 1]: mu and Sigma
    are then about the predicted mean and spread, and ZERO_WEIGHTS says so."""
    sums, flags = accumulate(dp, x, w, shift, ref, pairs)
    mu, sigma, ess, f = finalise(dp, sums, ref, pairs)
    flags = flags | f
    if dp.app == "uav":
        mu, fq = normalise_quaternion(dp, mu)
        flags = flags | fq
    return MomentsResult(mu, sigma, ess, flags)


def moments(dp: Datapath, x: np.ndarray, w: np.ndarray, shift: np.ndarray, ref: np.ndarray,
            pairs: list[tuple[int, int]]
            ) -> tuple[np.ndarray, dict[tuple[int, int], int], int, int]:
    """moments_batch for one step: x (N, n), w (N,), shift (B,), ref (n,); returns mu, Sigma
    by pair, ESS (raw) and flags."""
    res = moments_batch(dp, x[None], w[None], shift[None], np.asarray(ref)[None], pairs)
    sigma = {pr: int(v) for pr, v in zip(pairs, res.sigma[0], strict=True)}
    return res.mu[0], sigma, int(res.ess[0]), int(res.flags[0])


def cov_pairs(dp: Datapath, covariance: str) -> list[tuple[int, int]]:
    """Lower-triangle (i >= j) entries kept: all, or the uav's [q] and [v] blocks."""
    pairs = [(i, j) for i in range(dp.n) for j in range(i + 1)]
    if covariance == "block" and dp.app == "uav":
        pairs = [(i, j) for i, j in pairs if (i < 4) == (j < 4)]
    return pairs


# ---- predicted covariance (sigma_predict) ----------------------------------------------------
Term = tuple[int | None, str | None]   # (source pair index or None, constant name or None)


def prediction_terms(dp: Datapath, pairs: list[tuple[int, int]]) -> list[list[Term]]:
    """F Sigma F^T + Q as terms per entry (pairs' order): (q, None) is Sigma_q itself, (q, c)
    Sigma_q times the constant c, (None, c) the constant alone. bot: Phi = I + T E (E: position
    <- velocity), so Sigma + T (E S + S E^T) + T^2 E S E^T, and Gamma Q Gamma^T per axis (q_pp,
    q_pv, q_vv); uav: the identity and q_q, q_v on the diagonal."""
    index = {pr: q for q, pr in enumerate(pairs)}

    def at(a: int, b: int) -> int:
        return index[(max(a, b), min(a, b))]

    out = []
    for i, j in pairs:
        terms: list[Term] = [(at(i, j), None)]
        if dp.app == "bot":
            if i % 2 == 0:
                terms.append((at(i + 1, j), "T"))
            if j % 2 == 0:
                terms.append((at(i, j + 1), "T"))
            if i % 2 == 0 and j % 2 == 0:
                terms.append((at(i + 1, j + 1), "T2"))
            if i // 2 == j // 2:
                terms.append((None, {(0, 0): "q_pp", (1, 0): "q_pv", (1, 1): "q_vv"}[
                    (i % 2, j % 2)]))
        elif i == j:
            terms.append((None, "q_q" if i < 4 else "q_v"))
        out.append(terms)
    return out


def term_frac(dp: Datapath, pairs: list[tuple[int, int]], term: Term) -> int:
    """The fraction bits of a term's exact value."""
    src, name = term
    frac = 0 if src is None else dp.cov_frac(*pairs[src])
    return frac + (0 if name is None else dp.consts[name].frac)


def predicted_sigma(dp: Datapath, sigma: np.ndarray, pairs: list[tuple[int, int]]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """F Sigma F^T + Q (prediction_terms) of R covariances (R, P) raw, the pairs' order, as
    float_blocks' predicted_covariance: every entry one exact sum, rounded half up once into its
    format and saturated (flag SAT). Returns (Sigma, flags)."""
    out = np.empty_like(sigma, dtype=np.int64)
    flags = np.zeros(len(sigma), dtype=np.int64)
    for q, terms in enumerate(prediction_terms(dp, pairs)):
        top = max(term_frac(dp, pairs, t) for t in terms)
        total = _obj(np.zeros(len(sigma), dtype=np.int64))
        for src, name in terms:
            value = _obj(np.ones(len(sigma), np.int64) if src is None else sigma[:, src])
            if name is not None:
                value = value * dp.consts[name].raw
            total = total + value * (1 << (top - term_frac(dp, pairs, (src, name))))
        shift = top - dp.cov_frac(*pairs[q])
        out[:, q], f = _sat_obj((total + ((1 << shift) >> 1)) >> shift, dp.sigma(*pairs[q]))
        flags |= np.where(f, np.int64(Flag.SAT), np.int64(0))
    return out, flags


# ---- cholesky --------------------------------------------------------------------------------
def _obj(a: Any) -> np.ndarray:
    """An object array of Python ints (exact at any width)."""
    out = np.empty(np.size(a), dtype=object)
    out[:] = [int(v) for v in np.ravel(a)]
    return out.reshape(np.shape(a))


def cholesky_batch(dp: Datapath, sigma: np.ndarray, pairs: list[tuple[int, int]]
                   ) -> tuple[np.ndarray, np.ndarray]:
    """L with Sigma = L L^T for R matrices at once: sigma (R, P) raw in the pairs' order; n
    square roots and one exactly rounded quotient per L_ij below the diagonal, exact integer
    arithmetic. Returns L (R, n, n) and flags (R,).

    A pivot below max((CHOL_FLOOR_LSB LSB of L)^2, Sigma_jj 2^-CHOL_FLOOR_REL_BITS) is raised
    to that floor and its column below the diagonal set to 0 (flag NOT_PD): the filter keeps a
    valid factor when the covariance is singular or not positive definite.
    """
    n, runs = dp.n, len(sigma)
    col = {pr: _obj(sigma[:, q]) for q, pr in enumerate(pairs)}
    chol = [[_obj(np.zeros(runs, np.int64)) for _ in range(n)] for _ in range(n)]
    flags = np.zeros(runs, dtype=np.int64)
    for j in range(n):
        fj = dp.chol[j].frac_bits
        d = col[(j, j)] - sum((chol[j][k] * chol[j][k] for k in range(j)), _obj(0))
        # below a floor relative to the diagonal the pivot is rounding residue of a (near)
        # singular direction: give it the floor's spread and no correlation rather than
        # divide that residue by a tiny pivot
        rel = col[(j, j)] >> CHOL_FLOOR_REL_BITS
        floor = np.where(rel > CHOL_FLOOR_LSB**2, rel, CHOL_FLOOR_LSB**2)
        floored = np.asarray(d < floor, dtype=bool)
        flags |= np.where(floored, np.int64(Flag.NOT_PD), np.int64(0))
        d = np.where(floored, floor, d)
        ljj, f = saturate(sqrt_round(d, 2 * fj, fj), dp.chol[j])
        chol[j][j] = _obj(ljj)
        flags |= np.where(f, np.int64(Flag.SAT), np.int64(0))
        for i in range(j + 1, n):
            if (i, j) not in col:
                continue
            num = col[(i, j)] - sum((chol[i][k] * chol[j][k] for k in range(j)), _obj(0))
            # num: fraction fi + fj; L_jj: fj; L_ij = round(num / L_jj): fi, one exact rounding
            value, f = saturate(_obj(div_round(num, ljj, 0)), dp.chol[i])
            chol[i][j] = _obj(np.where(floored, 0, value))
            flags |= np.where(f & ~floored, np.int64(Flag.SAT), np.int64(0))
    out = np.array([[[int(chol[i][j][r]) for j in range(n)] for i in range(n)]
                    for r in range(runs)], dtype=np.int64).reshape(runs, n, n)
    return out, flags


def cholesky(dp: Datapath, sigma: dict[tuple[int, int], int]) -> tuple[np.ndarray, int]:
    """cholesky_batch of one matrix given by pair: (L (n, n), flags)."""
    pairs = list(sigma)
    chol, flags = cholesky_batch(dp, np.array([[sigma[p] for p in pairs]], dtype=object),
                                 pairs)
    return chol[0], int(flags[0])

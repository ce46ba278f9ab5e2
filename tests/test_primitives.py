"""Tests of gpf.model.primitives: CORDIC atan2 and 2^-t against float64, sqrt and division
against exact integer and rational arithmetic (math.isqrt, fractions.Fraction)."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gpf.model.primitives import (
    Cordic,
    Exp2Neg,
    _exp2_table,
    _isqrt64,
    div_round,
    recip,
    sqrt_round,
)

FAST = settings(max_examples=200, deadline=None)
RNG_SEED = 20240611


def lsb_error(c: Cordic, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Model minus float64 atan2, in output LSBs, taken modulo one turn; (0, 0) excluded."""
    keep = (x != 0) | (y != 0)
    y, x = y[keep], x[keep]
    out = c.atan2(y, x)
    ref = np.arctan2(y.astype(np.float64), x.astype(np.float64)) / (2 * np.pi)
    d = np.ldexp(out.astype(np.float64), -c.angle_frac) - ref
    return np.ldexp((d + 0.5) % 1.0 - 0.5, c.angle_frac)


def all_pairs(width: int) -> tuple[np.ndarray, np.ndarray]:
    v = np.arange(-(1 << (width - 1)), 1 << (width - 1), dtype=np.int64)
    yy, xx = np.meshgrid(v, v, indexing="ij")
    return yy.ravel(), xx.ravel()


# --- Cordic ------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle_frac", [10, 12])
def test_cordic_exhaustive_8bit(angle_frac: int) -> None:
    c = Cordic.for_widths(8, angle_frac)
    y, x = all_pairs(8)  # 65,536 pairs
    err = np.abs(lsb_error(c, y, x)).max()
    assert err <= 1.5, f"{c}: max error {err:.4f} output LSB over all 8-bit pairs"
    assert err <= 0.83, f"{c}: max error {err:.4f} LSB, measured 0.820 (A=10), 0.817 (A=12)"
    out = c.atan2(y, x)
    half = 1 << (angle_frac - 1)
    assert out.dtype == np.int64 and out.min() == -half and out.max() < half


def test_cordic_bot_random() -> None:
    """bot config: positions s7.16, so dx, dy are 24-bit raw; the angle ignores the binary point."""
    c = Cordic.for_widths(24, 23)
    rng = np.random.default_rng(RNG_SEED)
    y, x = rng.integers(-(1 << 23), 1 << 23, size=(2, 1_000_000))
    err = np.abs(lsb_error(c, y, x)).max()
    assert err <= 1.5, f"{c}: max error {err:.4f} output LSB over 1e6 random pairs"
    # The hardest inputs are the smallest vectors (truncation error ~ 1 / |(x, y)|).
    sy, sx = all_pairs(8)
    small = np.abs(lsb_error(c, sy, sx)).max()
    assert small <= 1.5, f"{c}: max error {small:.4f} LSB over all |x|, |y| <= 128"
    assert max(err, small) <= 0.83, f"measured 0.818 / 0.815, got {err:.4f} / {small:.4f}"


CONFIGS = [(8, 10), (8, 12), (20, 19), (24, 23)]


@pytest.mark.parametrize(("width", "angle_frac"), CONFIGS)
def test_cordic_axes_diagonals_and_corners(width: int, angle_frac: int) -> None:
    c = Cordic.for_widths(width, angle_frac)
    top = (1 << (width - 1)) - 1
    rng = np.random.default_rng(RNG_SEED)
    mags = np.unique(np.concatenate([
        np.arange(1, min(top, 4096) + 1),
        rng.integers(1, top + 1, size=20_000),
        [top] + [(1 << k) + d for k in range(width - 1) for d in (-1, 0, 1)],
    ]))
    mags = mags[(mags >= 1) & (mags <= top)].astype(np.int64)
    zero = np.zeros_like(mags)
    q = 1 << (angle_frac - 2)  # a quarter turn
    expected = {  # (y, x) -> exact binary angle
        "+x axis": (zero, mags, 0), "+y axis": (mags, zero, q), "-y axis": (-mags, zero, -q),
        "-x axis": (zero, -mags, -2 * q),  # a half turn wraps to -0.5 turn
        "diagonal 1": (mags, mags, q // 2), "diagonal 2": (mags, -mags, 3 * q // 2),
        "diagonal 3": (-mags, -mags, -3 * q // 2), "diagonal 4": (-mags, mags, -q // 2),
    }
    for name, (y, x, want) in expected.items():
        got = c.atan2(y, x)
        bad = mags[got != want]
        assert bad.size == 0, f"{c} {name}: not exact at |v| = {bad[:5]}"
    lo = -(1 << (width - 1))
    assert c.atan2(0, lo) == -2 * q       # x = min negative: half turn
    assert c.atan2(lo, 0) == -q           # y = min negative
    assert c.atan2(lo, lo) == -3 * q // 2
    assert c.atan2(top, top) == q // 2
    assert c.atan2(0, 0) == 0             # zero detect
    for y, x in ((top, lo), (lo, top), (lo, 1), (1, lo), (-1, lo)):
        assert abs(lsb_error(c, np.array([y]), np.array([x]))[0]) <= 1.5


@pytest.mark.parametrize(("width", "angle_frac"), CONFIGS)
def test_cordic_xy_width_holds_and_is_needed(width: int, angle_frac: int) -> None:
    c = Cordic.for_widths(width, angle_frac)
    assert c.xy_width == width + c.guard_bits + 2
    lo, top = -(1 << (width - 1)), (1 << (width - 1)) - 1
    corners = np.array([lo, lo + 1, -1, 0, 1, top - 1, top], dtype=np.int64)
    yy, xx = np.meshgrid(corners, corners)
    rng = np.random.default_rng(RNG_SEED)
    y = np.concatenate([yy.ravel(), rng.integers(lo, top + 1, 50_000)])
    x = np.concatenate([xx.ravel(), rng.integers(lo, top + 1, 50_000)])
    _, vmin, vmax = c._vectoring(y, x)
    limit = 1 << (c.xy_width - 1)
    # Analytic: |(X, Y)| <= K sqrt(2) 2^(W-1+G) + truncation (< sqrt(2) per step, times <= K).
    bound = 1.6468 * math.sqrt(2) * 2.0 ** (width - 1 + c.guard_bits) + 2.4 * c.iterations
    assert -limit <= vmin and vmax < limit and max(-vmin, vmax) <= bound < limit
    assert max(-vmin, vmax) >= limit // 2, "one bit fewer would overflow at (min, min)"


def test_cordic_tables_and_parameters() -> None:
    c = Cordic.for_widths(24, 23)
    assert (c.iterations, c.guard_bits, c.xy_width, c.z_width) == (23, 23, 49, 46)
    d = Cordic.for_widths(20, 19)
    assert (d.iterations, d.guard_bits, d.xy_width, d.z_width) == (19, 19, 41, 38)
    for cc in (c, d, Cordic.for_widths(8, 10)):
        frac = cc.angle_frac + cc.guard_bits
        assert cc.angles[0] == 1 << (frac - 3)  # atan(1) = 1/8 turn exactly
        for i, a in enumerate(cc.angles):
            v = math.atan(2.0**-i) / (2 * math.pi) * 2.0**frac  # float64 is within 2^-8 here
            assert abs(a - v) <= 0.5 + 2.0**-8, (cc, i)
        assert len(cc.angles) == cc.iterations


def test_cordic_interface() -> None:
    c = Cordic.for_widths(8, 10)
    assert isinstance(c.atan2(3, 4), int)
    grid = c.atan2(np.arange(6).reshape(2, 3), 5)
    assert grid.shape == (2, 3) and grid.dtype == np.int64
    assert np.array_equal(grid.ravel(), [c.atan2(v, 5) for v in range(6)])
    with pytest.raises(ValueError):
        c.atan2(128, 0)
    with pytest.raises(ValueError):
        c.atan2(0, -129)
    with pytest.raises(TypeError):
        c.atan2(np.array([0.5]), 1)
    with pytest.raises(ValueError):
        Cordic(40, 23, 23, 23)  # X, Y would need 65 bits
    with pytest.raises(ValueError):
        Cordic.for_widths(8, 1)


# --- Exp2Neg -----------------------------------------------------------------------------------


def exp2_error(e: Exp2Neg, t: np.ndarray) -> np.ndarray:
    w = e(t)
    return w - np.exp2(e.out_frac - np.ldexp(t.astype(np.float64), -e.in_frac))


def check_underflow(e: Exp2Neg, t: np.ndarray, w: np.ndarray) -> None:
    """w = 0 only below half an LSB (t > F+1) and always from t >= F+2; w <= 1 in between."""
    one = 1 << e.in_frac
    f1, f2 = (e.out_frac + 1) * one, (e.out_frac + 2) * one
    assert np.all(t[w == 0] > f1)
    assert np.all(w[t >= f2] == 0)
    between = (t >= f1) & (t < f2)
    assert np.all(w[between] <= 1)
    assert np.all(w[t == f1] == 1)  # exactly half an LSB rounds up


def test_exp2_exhaustive_u4_12() -> None:
    e = Exp2Neg.for_formats(in_width=16, in_frac=12, out_frac=15)
    t = np.arange(1 << 16, dtype=np.int64)
    w = e(t)
    err = np.abs(exp2_error(e, t)).max()
    assert err <= 1.0, f"{e}: max error {err:.4f} output LSB over every t"
    assert err <= e.error_bound() and e.error_bound() <= 1.0
    assert w[0] == 1 << 15
    assert np.all(np.diff(w) <= 0), "not monotone"
    check_underflow(e, t, w)


def test_exp2_u6_18_dense() -> None:
    e = Exp2Neg.for_formats(in_width=24, in_frac=18, out_frac=23)
    rng = np.random.default_rng(RNG_SEED)
    t = np.unique(np.concatenate([
        np.arange(1 << 18),                           # every fraction of the first octave
        rng.integers(0, 25 << 18, size=600_000),      # where w > 0
        np.arange(0, 1 << 24, 97),                    # the whole range
    ])).astype(np.int64)
    w = e(t)
    err = np.abs(exp2_error(e, t)).max()
    assert err <= 1.0, f"{e}: max error {err:.4f} output LSB over {t.size} values"
    assert w[0] == 1 << 23 and np.all(np.diff(w) <= 0)
    check_underflow(e, t, w)


def test_exp2_bot_parameters_and_error() -> None:
    e = Exp2Neg.for_formats(in_width=24, in_frac=16, out_frac=23)
    assert (e.lut_bits, e.guard_bits, e.rem_bits) == (10, 6, 6)
    t = np.arange(26 << 16, dtype=np.int64)  # every t with w > 0, and a little past
    w = e(t)
    err = np.abs(exp2_error(e, t)).max()
    assert err <= 1.0, f"{e}: max error {err:.4f} output LSB over every t < 26"
    assert np.all(np.diff(w) <= 0)
    check_underflow(e, t, w)
    assert e((1 << 24) - 1) == 0
    assert Exp2Neg(24, 16, 23, 9, 8).error_bound() > 1.0  # L = 10 is the smallest table


def test_exp2_tables() -> None:
    for e in (Exp2Neg.for_formats(24, 16, 23), Exp2Neg.for_formats(16, 12, 15)):
        big, seg = e.out_frac + e.guard_bits, 1 << e.lut_bits
        assert len(e.base) == seg + 1 and len(e.slope) == seg
        assert e.base[0] == 1 << big and e.base[-1] == 1 << (big - 1)
        ref = [math.floor(2.0 ** (big - k / seg) + 0.5) for k in range(seg + 1)]
        assert list(e.base) == ref  # float64 is exact enough for 29 bits
        assert all(s == b - a for s, a, b in zip(e.slope, e.base, e.base[1:], strict=False))
        assert all(s <= 0 for s in e.slope)
        assert max(-s for s in e.slope) < 1 << (e.slope_width - 1)


def test_exp2_padded_lut() -> None:
    """in_frac < L: the fraction is padded, every t reads an exact table entry."""
    e = Exp2Neg(in_width=10, in_frac=4, out_frac=11, lut_bits=6, guard_bits=2)
    assert e.rem_bits == 0
    t = np.arange(1 << 10, dtype=np.int64)
    assert np.abs(exp2_error(e, t)).max() <= e.error_bound() <= 1.0
    assert Exp2Neg.for_formats(10, 4, 11).lut_bits == 4
    assert isinstance(e(3), int)
    with pytest.raises(ValueError):
        e(1 << 10)
    with pytest.raises(ValueError):
        e(-1)


# --- sqrt_round --------------------------------------------------------------------------------


def sqrt_ok(x: int, in_frac: int, out_frac: int, r: int) -> bool:
    """r = round_half_up(sqrt(x 2^-in_frac) 2^out_frac): |r - sqrt(X)| <= 1/2, exactly."""
    big = Fraction(x, 1 << in_frac) * (1 << (2 * out_frac))
    return r >= 0 and (r == 0 or (2 * r - 1) ** 2 <= 4 * big) and 4 * big < (2 * r + 1) ** 2


@FAST
@given(st.integers(0, 1 << 200), st.integers(0, 40), st.integers(0, 60))
def test_sqrt_round_exact_wide(x: int, in_frac: int, out_frac: int) -> None:
    if 2 * out_frac < in_frac:
        with pytest.raises(ValueError):
            sqrt_round(x, in_frac, out_frac)
        return
    r = sqrt_round(x, in_frac, out_frac)
    assert isinstance(r, int) and sqrt_ok(x, in_frac, out_frac, r)
    big = x << (2 * out_frac - in_frac)
    assert r == (math.isqrt(4 * big) + 1) >> 1


@FAST
@given(st.lists(st.integers(0, (1 << 63) - 1), min_size=1, max_size=30), st.integers(0, 8),
       st.integers(0, 8))
def test_sqrt_round_arrays(xs: list[int], in_frac: int, out_frac: int) -> None:
    if 2 * out_frac < in_frac:
        return
    got = sqrt_round(np.array(xs, dtype=np.int64), in_frac, out_frac)
    assert all(sqrt_ok(x, in_frac, out_frac, int(r)) for x, r in zip(xs, got, strict=True))


def test_sqrt_int64_near_limits_and_squares() -> None:
    top = math.isqrt((1 << 63) - 1)
    rng = np.random.default_rng(RNG_SEED)
    roots = np.concatenate([np.arange(top - 2000, top + 1), np.arange(0, 3000),
                            rng.integers(0, top, 100_000), [1 << 31, (1 << 31) - 1]])
    vals = [v for m in map(int, roots) for v in (m * m - 1, m * m, m * m + 1, m * m + m,
                                                  m * m + m + 1) if 0 <= v < 1 << 63]
    vals += [(1 << 62) + d for d in range(-50, 51)] + [(1 << 63) - 1 - d for d in range(100)]
    arr = np.array(vals, dtype=np.int64)
    got = sqrt_round(arr, 0, 0)  # round(sqrt(x)): int64 path (X - r^2 > r)
    assert got.dtype == np.int64
    want = np.array([(math.isqrt(4 * v) + 1) >> 1 for v in vals], dtype=np.int64)
    assert np.array_equal(got, want)
    assert np.array_equal(_isqrt64(arr), np.array([math.isqrt(v) for v in vals]))


def test_sqrt_round_dtypes_and_errors() -> None:
    small = sqrt_round(np.array([4, 9], dtype=np.int64), 4, 8)
    assert small.dtype == np.int64 and list(small) == [128, 192]  # 0.5, 0.75 in u.8
    wide = sqrt_round(np.array([(1 << 62) - 1, 2]), 0, 2)  # X = x << 4 leaves int64
    assert wide.dtype == object
    assert all(sqrt_ok(x, 0, 2, r) for x, r in zip([(1 << 62) - 1, 2], wide, strict=True))
    obj = sqrt_round(np.array([1 << 100, 3], dtype=object), 0, 0)
    assert obj[0] == 1 << 50 and obj[1] == 2
    assert sqrt_round(2, 0, 0) == 1 and sqrt_round(3, 0, 0) == 2  # 1.41 -> 1, 1.73 -> 2
    with pytest.raises(ValueError):
        sqrt_round(-1, 0, 0)
    with pytest.raises(ValueError):
        sqrt_round(4, 5, 2)
    with pytest.raises(TypeError):
        sqrt_round(2.0, 0, 0)


# --- div_round ---------------------------------------------------------------------------------


def div_ref(num: int, den: int, shift: int) -> int:
    return math.floor(Fraction(num) * Fraction(2) ** shift / den + Fraction(1, 2))


@FAST
@given(st.integers(-(1 << 100), 1 << 100), st.integers(1, 1 << 80), st.integers(-20, 80))
def test_div_round_exact_wide(num: int, den: int, shift: int) -> None:
    r = div_round(num, den, shift)
    assert isinstance(r, int) and r == div_ref(num, den, shift)
    assert abs(Fraction(r) - Fraction(num) * Fraction(2) ** shift / den) <= Fraction(1, 2)


@FAST
@given(st.lists(st.tuples(st.integers(-(1 << 40), 1 << 40), st.integers(1, 1 << 40)),
                min_size=1, max_size=30), st.integers(0, 21))
def test_div_round_arrays_int64(pairs: list[tuple[int, int]], shift: int) -> None:
    num = np.array([p[0] for p in pairs], dtype=np.int64)
    den = np.array([p[1] for p in pairs], dtype=np.int64)
    got = div_round(num, den, shift)
    assert got.dtype == np.int64
    assert list(got) == [div_ref(n, d, shift) for n, d in pairs]


@FAST
@given(st.integers(-(1 << 20), 1 << 20), st.integers(1, 1 << 20), st.integers(0, 10))
def test_div_round_ties_toward_plus_inf(q: int, half_den: int, shift: int) -> None:
    den = 2 * half_den
    num = (2 * q + 1) * half_den  # num / den = q + 1/2 exactly
    assert div_round(num, den, 0) == q + 1
    assert div_round(num << shift, den << shift, 0) == q + 1


def test_div_round_directed() -> None:
    assert div_round(-3, 2, 0) == -1 and div_round(3, 2, 0) == 2  # ties up
    assert div_round(-5, 2, 0) == -2 and div_round(-1, 2, 0) == 0
    assert div_round(-7, 4, 1) == -3  # -3.5 -> -3
    assert recip(3, 4) == 5 and recip(np.array([1, 2, 3]), 10).tolist() == [1024, 512, 341]
    big = div_round(np.array([1 << 61, -(1 << 61)]), 3, 8)  # |num| << 8 leaves 62 bits
    assert big.dtype == object and list(big) == [div_ref(1 << 61, 3, 8), div_ref(-(1 << 61), 3, 8)]
    both = div_round(np.array([[1], [-7]]), np.array([2, 3, 4]), 2)  # broadcasting
    assert both.shape == (2, 3)
    assert both.tolist() == [[div_ref(n, d, 2) for d in (2, 3, 4)] for n in (1, -7)]
    with pytest.raises(ValueError):
        div_round(1, 0, 4)
    with pytest.raises(ValueError):
        div_round(1, np.array([3, -1]), 4)


# --- constants ---------------------------------------------------------------------------------


def test_constants_json_and_deterministic() -> None:
    for make in (lambda: Cordic.for_widths(24, 23), lambda: Cordic.for_widths(8, 12),
                 lambda: Exp2Neg.for_formats(in_width=24, in_frac=16, out_frac=23),
                 lambda: Exp2Neg.for_formats(16, 12, 15)):
        a, b = make(), make()
        text = json.dumps(a.constants(), sort_keys=True)
        assert text == json.dumps(b.constants(), sort_keys=True)
        assert json.loads(text) == a.constants()
    c = Cordic.for_widths(24, 23).constants()
    assert c["angles"][0] == 1 << 43 and c["quarter"] == 1 << 44 and c["out_width"] == 23
    e = Exp2Neg.for_formats(24, 16, 23).constants()
    assert e["m_width"] == 30 and len(e["base"]) == 1025 and e["base"][0] == 1 << 29


@pytest.mark.parametrize(("big", "lut"), [(29, 10), (21, 6), (15, 4), (8, 0), (40, 7)])
def test_exp2_table_matches_nested_isqrt(big: int, lut: int) -> None:
    """The fast table equals round(2^(big - k/2^L)) by L nested isqrt of 2^(2^L (big+1) - k)."""
    seg = 1 << lut
    want = []
    for k in range(seg + 1):
        v = 1 << (seg * (big + 1) - k)
        for _ in range(lut):
            v = math.isqrt(v)  # floor(2^((big+1) - k/seg)) = floor(2 * exact)
        want.append((v + 1) >> 1)
    assert list(_exp2_table(big, lut)) == want

"""Arithmetic primitives of the GPF datapath, modelled as the exact hardware algorithms.

Every function works on raw two's-complement integers (numpy int64 arrays, object arrays of
Python ints where stated, or Python ints: all-scalar input gives a Python int back) with integer
arithmetic only, so the RTL can repeat it step for step. `>>` is the arithmetic right shift,
floor(v / 2^s); "round half up" is floor(v / 2^s + 1/2) = (v + 2^(s-1)) >> s. Tables are tuples
of Python ints computed exactly with big integers (no libm), so every machine builds the same
RTL; `constants()` gives them with the parameters as a JSON-able dict for the generator.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["Cordic", "Exp2Neg", "div_round", "recip", "sqrt_round"]

_I64_MIN, _I64_MAX = -(1 << 63), (1 << 63) - 1


# --- Cordic: atan2 in turns -------------------------------------------------------------------


@dataclass(frozen=True)
class Cordic:
    """atan2(y, x) by CORDIC in vectoring mode, as a binary angle in turns (1 turn = 2 pi).

    W = in_width, A = angle_frac, G = guard_bits, N = iterations. The result has A fraction
    bits of a turn and lies in [-2^(A-1), 2^(A-1)), i.e. [-0.5, 0.5) turn: an A-bit two's
    complement binary angle, so one turn is 2^A and wrapping is modulo one turn. (It also fits
    Format s0.A, whose top bit is then a copy of the sign; wrap differences modulo 2^A.)
    X, Y are signed W+G+2 bits: |(x, y)| <= sqrt(2) 2^(W-1) (W+G+1 bits hold -(-2^(W-1)) << G),
    times the gain K = 1.6468 is < 2.33 2^(W-1+G), plus < 2.4 N truncation units (< sqrt(2)
    a step, times at most K): < 2^(W+G+1) since 2.4 N < 1.67 2^(W+G-1) for any sane N.
    z is A+G bits, units 2^-(A+G) turn, wrapping modulo one turn (two's complement).
      1. X = x << G, Y = y << G.
      2. X < 0 and Y >= 0: X, Y, z = Y, -X, +Q;  X < 0 and Y < 0: X, Y, z = -Y, X, -Q;
         else z = 0.  Q = 2^(A+G-2), a quarter turn. Now X >= 0, and X never decreases.
      3. For i = 0 .. N-1: Y >= 0: X, Y, z = X + (Y >> i), Y - (X >> i), z + ANGLE[i]
                           Y < 0:  X, Y, z = X - (Y >> i), Y + (X >> i), z - ANGLE[i]
         ANGLE[i] = round_half_up(atan(2^-i) / (2 pi) 2^(A+G)) (ANGLE[0] = 2^(A+G-3)).
      4. out = (z + 2^(G-1)) >> G (z if G = 0), wrapped to A bits: a half turn comes out as
         -2^(A-1). Wrapping z (A+G bits) before rounding gives the same bits.
      5. x == 0 and y == 0 forces out = 0 (a zero detect on the inputs): steps 1-4 alone give
         sum(ANGLE) >> G there (Y = 0 counts as Y >= 0, so every step rotates up).
    The model keeps z unbounded and wraps once at the end, and checks that X and Y stay within
    W+G+2 bits.
    """

    in_width: int
    angle_frac: int
    iterations: int
    guard_bits: int

    def __post_init__(self) -> None:
        _check_counts(self, in_width=2, angle_frac=2, iterations=1, guard_bits=0)
        if self.xy_width > 63 or self.z_width > 63:
            raise ValueError(f"{self}: X, Y ({self.xy_width} bits) and z ({self.z_width} bits) "
                             "must fit in 63 bits")

    @classmethod
    def for_widths(cls, in_width: int, angle_frac: int) -> Cordic:
        """N = A iterations and G = A guard bits.

        Error sources, in output LSBs: the final rounding 1/2; the residual angle after N steps,
        at most atan(2^-(N-1)) = 1/pi; the table roundings N 2^-(G+1); the X/Y truncations,
        about N 2^-G rad over the smallest vectors (|(x, y)| = 1 raw, for any W), for which a
        worst-case sum asks G ~ A + 2 but measurements need far less. Measured with N = A over
        all |x|, |y| < 128 and 2e5 pairs below 2^11 for A = 4 .. 23: max error <= 0.82 LSB for
        G = A, up to 1.04 for G = A - 2, up to 2 for G = A - 3; G = A - 1 misses a few axis and
        diagonal points with |x|, |y| <= 5, G = A makes all of them exact (checked for every
        magnitude at W = 24, A = 23 and W = 20, A = 19). Chosen parameters, max error: W = 8,
        A = 10: 0.817 (exhaustive); W = 8, A = 12: 0.806 (exhaustive); W = 24, A = 23: 0.818
        (1e7 random pairs and all |x|, |y| <= 256); W = 20, A = 19: 0.820.
        """
        a = _count(angle_frac, "angle_frac")
        return cls(in_width, a, a, a)

    @property
    def xy_width(self) -> int:
        return self.in_width + self.guard_bits + 2

    @property
    def z_width(self) -> int:
        return self.angle_frac + self.guard_bits

    @cached_property
    def angles(self) -> tuple[int, ...]:
        """ANGLE[i] in units of 2^-(A+G) turn: big-integer series to 96 extra bits, no libm."""
        frac = self.angle_frac + self.guard_bits
        prec = frac + 96
        pi = 16 * _atan_inv(5, prec) - 4 * _atan_inv(239, prec)
        atans = [pi >> 2] + [_atan_inv(1 << i, prec) for i in range(1, self.iterations)]
        return tuple(((t << frac) + pi) // (2 * pi) for t in atans)  # round(t / (2 pi))

    def constants(self) -> dict[str, Any]:
        return {**asdict(self), "out_width": self.angle_frac, "xy_width": self.xy_width,
                "z_width": self.z_width, "quarter": 1 << (self.angle_frac + self.guard_bits - 2),
                "angles": list(self.angles)}

    def atan2(self, y: Any, x: Any) -> Any:
        """Raw angle (int64, A fraction bits of a turn, [-2^(A-1), 2^(A-1))) of raw y, x
        (signed in_width bits, the same format)."""
        yv, xv, shape, scalar = _pair(y, x, self.in_width, "Cordic input")
        z, lo, hi = self._vectoring(yv, xv)
        if lo < -(1 << (self.xy_width - 1)) or hi >= 1 << (self.xy_width - 1):
            raise AssertionError(f"{self}: X/Y overflow [{lo}, {hi}]")  # excluded by analysis
        g, a = self.guard_bits, self.angle_frac
        r = (z + (1 << g >> 1)) >> g
        out = ((r + (1 << a >> 1)) & ((1 << a) - 1)) - (1 << a >> 1)
        out = np.where((xv == 0) & (yv == 0), 0, out)
        return _finish(out, shape, scalar)

    def _vectoring(self, y: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, int, int]:
        """Steps 1-3: z, and the least and greatest X or Y seen (overflow check)."""
        g, q = self.guard_bits, 1 << (self.angle_frac + self.guard_bits - 2)
        x, y = x << g, y << g
        neg, up = x < 0, y >= 0
        x, y, z = (np.where(neg, np.where(up, y, -y), x), np.where(neg, np.where(up, -x, x), y),
                   np.where(neg, np.where(up, q, -q), 0))
        lo, hi = _span(x, y)
        for i, angle in enumerate(self.angles):
            d = np.where(y >= 0, 1, -1)
            sh = min(i, 62)  # |X|, |Y| < 2^62: any longer shift gives the same 0 or -1
            x, y, z = x + d * (y >> sh), y - d * (x >> sh), z + d * angle
            lo, hi = min(lo, *_span(x, y)), max(hi, *_span(x, y))
        return z, lo, hi


# --- Exp2Neg: w = 2^-t --------------------------------------------------------------------------


@dataclass(frozen=True)
class Exp2Neg:
    """w = 2^-t for t >= 0 (t raw unsigned in_width bits, in_frac fraction bits) as u1.F.

    F = out_frac, L = lut_bits, G = guard_bits, R = max(in_frac - L, 0), P = max(L - in_frac, 0).
      1. n = t >> in_frac (in_width - in_frac bits); f = (t mod 2^in_frac) << P; k = f >> R
         (L bits, the segment), r = f mod 2^R (R bits).
      2. m = BASE[k] + ((SLOPE[k] r + 2^(R-1)) >> R)  (m = BASE[k] if R = 0): BASE is unsigned
         F+G+1 bits, SLOPE signed `slope_width` bits (<= 0), the product slope_width+R bits;
         2^(F+G-1) <= m <= 2^(F+G), F+G+1 bits.
      3. s = n + G; w = (m + 2^(s-1)) >> s (w = m if s = 0); w = 0 when s > F+G+1 (the width of
         m), exactly what the formula gives there, so the shifter needs only F+G+2 positions.
    BASE[k] = round_half_up(2^(-k/2^L) 2^(F+G)), k = 0 .. 2^L (BASE[2^L] = 2^(F+G-1)), exact;
    SLOPE[k] = BASE[k+1] - BASE[k]. w(0) = 2^F. w is non-increasing in t: BASE is, SLOPE <= 0,
    and m at r = 2^R - 1 is >= BASE[k+1]. Underflow: w = 0 exactly when m < 2^(s-1); since
    2^(F+G-1) <= m <= 2^(F+G) that is always when t >= F+2, never when t <= F+1 (where the
    exact value is >= half an LSB), and for F+1 < t < F+2 (exact value below half an LSB)
    unless m rounded up to 2^(F+G). So w = 0 implies 2^-t < 2^-(F+1).
    """

    in_width: int
    in_frac: int
    out_frac: int
    lut_bits: int
    guard_bits: int

    def __post_init__(self) -> None:
        _check_counts(self, in_width=1, in_frac=0, out_frac=0, lut_bits=0, guard_bits=0)
        if self.in_frac > self.in_width or self.in_width > 62:
            raise ValueError(f"{self}: need in_frac <= in_width <= 62")
        if self.out_frac + self.guard_bits < 1:
            raise ValueError(f"{self}: need out_frac + guard_bits >= 1")
        if self.out_frac + self.guard_bits + max(self.in_frac - self.lut_bits, 0) > 60:
            raise ValueError(f"{self}: the interpolation product must fit in 62 bits")

    @classmethod
    def for_formats(cls, in_width: int, in_frac: int, out_frac: int) -> Exp2Neg:
        """The smallest L <= in_frac, then the smallest G <= 8, with `error_bound()` <= 1."""
        for lut in range(in_frac + 1):
            for guard in range(0 if out_frac else 1, 9):
                e = cls(in_width, in_frac, out_frac, lut, guard)
                if e.error_bound() <= 1.0:
                    return e
        raise AssertionError("unreachable: L = in_frac, G = 1 gives 1.0")

    def error_bound(self) -> float:
        """A rigorous bound on |w - 2^-t 2^F|, output LSBs: 1/2 (last rounding) + 2^-G (BASE
        rounding 1/2, product rounding 1/2, in units of m; just 1/2 when R = 0) + the chord
        error of linear interpolation, h^2/8 max|f''| = (ln 2)^2 / 8 2^(F-2L) (0 when R = 0)."""
        chord = 0.0 if self.in_frac <= self.lut_bits else math.log(2) ** 2 / 8 * 2.0 ** (
            self.out_frac - 2 * self.lut_bits)
        return 0.5 + 2.0**-self.guard_bits * (1.0 if chord else 0.5) + chord

    @property
    def rem_bits(self) -> int:
        return max(self.in_frac - self.lut_bits, 0)

    @property
    def base(self) -> tuple[int, ...]:
        return _exp2_table(self.out_frac + self.guard_bits, self.lut_bits)

    @cached_property
    def slope(self) -> tuple[int, ...]:
        return tuple(b - a for a, b in zip(self.base, self.base[1:], strict=False))

    @property
    def slope_width(self) -> int:
        return (-min(self.slope) - 1).bit_length() + 1  # two's complement width of min SLOPE

    def constants(self) -> dict[str, Any]:
        return {**asdict(self), "rem_bits": self.rem_bits, "slope_width": self.slope_width,
                "m_width": self.out_frac + self.guard_bits + 1, "base": list(self.base),
                "slope": list(self.slope)}

    def __call__(self, t: Any) -> Any:
        """Raw w (int64, out_frac fraction bits) for raw t (unsigned, in_width bits)."""
        tv, shape, scalar = _ints(t, 0, (1 << self.in_width) - 1, "Exp2Neg input")
        big, rb = self.out_frac + self.guard_bits, self.rem_bits
        n = tv >> self.in_frac
        f = (tv & ((1 << self.in_frac) - 1)) << max(self.lut_bits - self.in_frac, 0)
        k, r = f >> rb, f & ((1 << rb) - 1)
        m = np.asarray(self.base, dtype=np.int64)[k]
        if rb:
            m = m + ((np.asarray(self.slope, dtype=np.int64)[k] * r + (1 << (rb - 1))) >> rb)
        s = np.minimum(n + self.guard_bits, big + 2)
        w = (m + ((1 << s) >> 1)) >> s
        return _finish(np.where(s > big + 1, 0, w), shape, scalar)


# --- exact square root and division ------------------------------------------------------------


def sqrt_round(x: Any, in_frac: int, out_frac: int) -> Any:
    """round_half_up(sqrt(x 2^-in_frac) 2^out_frac), exact, for x >= 0.

    With X = x << (2 out_frac - in_frac) the result is round(sqrt(X)) = (isqrt(4X) + 1) >> 1:
    what a digit-by-digit unit gives when run one digit further and rounded (no ties exist:
    sqrt(X) = m + 1/2 would need X = m^2 + m + 1/4). 2 out_frac - in_frac < 0 raises
    ValueError: X would not be an integer, so the radicand would need rounding first and the
    result would no longer be the exact rounding. Negative x raises ValueError.
    dtype: int64 when every X fits in int64 (computed as r + (X - r^2 > r), r = isqrt(X), the
    same value without forming 4X), else object arrays with math.isqrt per element.
    """
    shift = 2 * _count(out_frac, "out_frac") - _count(in_frac, "in_frac")
    if shift < 0:
        raise ValueError(f"sqrt_round needs 2 out_frac - in_frac >= 0, got {shift}")
    v, shape, scalar = _ints(x, 0, None, "sqrt_round input")
    if v.dtype != object and shift < 63 and (v.size == 0 or int(v.max()) <= _I64_MAX >> shift):
        big = v << shift
        r = _isqrt64(big)
        out = r + (big - r * r > r)
    else:
        out = _obj([(math.isqrt(4 * (int(e) << shift)) + 1) >> 1 for e in v.flat])
    return _finish(out, shape, scalar)


def div_round(num: Any, den: Any, shift: int) -> Any:
    """round_half_up(num 2^shift / den) = floor(num 2^shift / den + 1/2), exact, den > 0.

    Ties go toward +inf for either sign of num. A negative shift multiplies den by 2^-shift.
    dtype: int64 when every |num| << shift and den << -shift is below 2^62 (quotient q and
    remainder 0 <= rem < den by floor division, result q + (rem >= den - rem)); else object
    arrays: (2 (num << shift) + den) // (2 den).
    """
    shift = _as_int(shift, "shift")
    n, n_shape, n_scalar = _ints(num, None, None, "div_round numerator")
    d, d_shape, d_scalar = _ints(den, 1, None, "div_round denominator")
    shape = np.broadcast_shapes(n_shape, d_shape)
    n, d = (np.broadcast_to(a.reshape(s), shape).reshape(-1) for a, s in ((n, n_shape),
                                                                        (d, d_shape)))
    ns, ds = max(shift, 0), max(-shift, 0)
    lim = 1 << 62
    if n.dtype != object and d.dtype != object and ns < 62 and ds < 62 and (n.size == 0 or (
            int(n.max()) < lim >> ns and int(n.min()) > -(lim >> ns) and int(d.max()) < lim >> ds)):
        q, rem = np.divmod(n << ns, d << ds)
        out = q + (rem >= (d << ds) - rem)
    else:
        nn, dd = _obj([int(a) for a in n]) << ns, _obj([int(a) for a in d]) << ds
        out = (2 * nn + dd) // (2 * dd)
    return _finish(out, shape, n_scalar and d_scalar)


def recip(den: Any, shift: int) -> Any:
    """round_half_up(2^shift / den) = div_round(1, den, shift)."""
    return div_round(1, den, shift)


# --- helpers -----------------------------------------------------------------------------------


def _isqrt64(v: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Exact floor(sqrt(v)) for int64 0 <= v < 2^63.

    Float64 gives sqrt(v)(1 + e), |e| < 2^-52 (one rounding of v, one of sqrt), so it is within
    3.04e9 * 2^-52 < 1e-6 of sqrt(v) and its floor within one of isqrt(v): one step down and
    one up fix it. Squares go through uint64: (isqrt(2^63 - 1) + 1)^2 < 2^64.
    """
    s = np.floor(np.sqrt(v.astype(np.float64))).astype(np.int64)
    u = v.astype(np.uint64)
    su = s.astype(np.uint64)
    s = s - (su * su > u)
    su = s.astype(np.uint64) + np.uint64(1)
    return s + (su * su <= u)


@functools.lru_cache(maxsize=64)
def _exp2_table(big: int, lut: int) -> tuple[int, ...]:
    """round_half_up(2^(big - k/2^L)), k = 0 .. 2^L, exact.

    a_k = floor(a_(k-1) c / 2^P) with c = floor(2^(P - 1/2^L)) (L nested isqrt: floor(sqrt(
    floor(v))) = floor(sqrt(v))) undershoots 2^(P - k/2^L) by less than 2k; where that could
    change the rounding, the candidate b is checked exactly: (2b-1)^2^L <= 2^e < (2b+1)^2^L.
    """
    seg, prec = 1 << lut, big + 64
    one, margin = 1 << prec, (2 * seg + 2) << big
    c = 1 << (prec * seg - 1)
    for _ in range(lut):
        c = math.isqrt(c)
    a, out = one, []
    for k in range(seg + 1):
        t = (a << big) + (one >> 1)
        b, frac = t >> prec, t & (one - 1)
        if frac < margin or frac > one - margin:
            e = seg * (big + 1) - k  # 2^e = (2 * 2^(big - k/seg))^seg
            while b > 0 and (2 * b - 1) ** seg > 1 << e:
                b -= 1
            while (2 * b + 1) ** seg <= 1 << e:
                b += 1
        out.append(b)
        a = (a * c) >> prec
    return tuple(out)


def _atan_inv(q: int, prec: int) -> int:
    """atan(1/q) 2^prec by the alternating series, within (number of terms) units."""
    power, total, k, q2 = (1 << prec) // q, 0, 0, q * q
    while power:
        total += power // (2 * k + 1) if k % 2 == 0 else -(power // (2 * k + 1))
        power //= q2
        k += 1
    return total


def _span(x: np.ndarray, y: np.ndarray) -> tuple[int, int]:
    if x.size == 0:
        return 0, 0
    return min(int(x.min()), int(y.min())), max(int(x.max()), int(y.max()))


def _check_counts(obj: Any, **minimum: int) -> None:
    for name, lo in minimum.items():
        value = _as_int(getattr(obj, name), f"{type(obj).__name__}.{name}")
        if value < lo:
            raise ValueError(f"{type(obj).__name__}.{name} must be >= {lo}, got {value}")
        object.__setattr__(obj, name, value)


def _as_int(value: Any, name: str) -> int:
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be an int, got {value!r}")
    return int(value)


def _count(value: Any, name: str) -> int:
    value = _as_int(value, name)
    if value < 0:
        raise ValueError(f"{name} must be >= 0, got {value}")
    return value


def _obj(values: list[int]) -> npt.NDArray[np.object_]:
    out = np.empty(len(values), dtype=object)
    out[:] = values
    return out


def _ints(x: Any, lo: int | None, hi: int | None, label: str
          ) -> tuple[np.ndarray, tuple[int, ...], bool]:
    """Flat int64 array (object of Python ints when some value leaves int64), shape, scalar.

    Values outside [lo, hi] (None: unbounded) raise ValueError; bools and floats TypeError.
    """
    scalar = not isinstance(x, np.ndarray) and np.ndim(x) == 0
    arr = np.asarray(x, dtype=object) if not isinstance(x, np.ndarray) else x
    shape = arr.shape
    if arr.dtype.kind == "i" or (arr.dtype.kind == "u" and arr.dtype.itemsize < 8):
        flat = arr.astype(np.int64).reshape(-1)
    elif arr.dtype.kind in "uO":
        vals = arr.reshape(-1).tolist()
        if not all(isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_)
                   for v in vals):
            raise TypeError(f"{label} must be integers")
        vals = [int(v) for v in vals]
        fits = all(_I64_MIN <= v <= _I64_MAX for v in vals)
        flat = np.array(vals, dtype=np.int64) if fits else _obj(vals)
    else:
        raise TypeError(f"{label} must be integers, got dtype {arr.dtype}")
    if flat.size and ((lo is not None and int(flat.min()) < lo)
                      or (hi is not None and int(flat.max()) > hi)):
        raise ValueError(f"{label} outside [{lo}, {hi}]")
    return flat, shape, scalar


def _pair(y: Any, x: Any, width: int, label: str
          ) -> tuple[np.ndarray, np.ndarray, tuple[int, ...], bool]:
    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    yv, ys, yscalar = _ints(y, lo, hi, label)
    xv, xs, xscalar = _ints(x, lo, hi, label)
    shape = np.broadcast_shapes(ys, xs)
    yv, xv = (np.broadcast_to(v.reshape(s), shape).reshape(-1).astype(np.int64)
              for v, s in ((yv, ys), (xv, xs)))
    return yv, xv, shape, yscalar and xscalar


def _finish(out: np.ndarray, shape: tuple[int, ...], scalar: bool) -> Any:
    if scalar:
        return int(out.reshape(-1)[0])
    return np.asarray(out).reshape(shape)

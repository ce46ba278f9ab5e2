"""Bit-exact fixed-point arithmetic on raw two's-complement integers.

A raw value is the real value times 2**frac_bits. Every function takes Python ints or numpy
integer arrays (broadcast together) and returns a Python int for all-scalar input, else an array.

The working dtype is chosen from the formats and widths alone, never from the data: int64 when
every input, intermediate and result provably fits in int64, otherwise numpy object arrays of
Python ints (exact but much slower), and the result keeps that dtype. Nothing ever wraps: raw
inputs outside their declared format raise ValueError, and results outside the target format are
saturated and flagged.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

import numpy as np
import numpy.typing as npt

__all__ = [
    "Flags",
    "Format",
    "Raw",
    "RawArray",
    "Rounding",
    "add_sat",
    "mul_round",
    "requantise",
    "saturate",
    "shift_round",
]

Rounding: TypeAlias = Literal["half_up", "truncate"]
RawArray: TypeAlias = npt.NDArray[np.int64] | npt.NDArray[np.object_]
Raw: TypeAlias = int | RawArray
Flags: TypeAlias = bool | npt.NDArray[np.bool_]

_INT64_MIN = -(1 << 63)
_INT64_MAX = (1 << 63) - 1
_ROUNDINGS = ("half_up", "truncate")
_FORMAT_RE = re.compile(r"([su])([0-9]+)\.([0-9]+)")


@dataclass(frozen=True)
class Format:
    """Fixed-point format: sI.F is 1 sign + I integer + F fraction bits; uI.F is I + F bits."""

    signed: bool
    int_bits: int
    frac_bits: int

    def __post_init__(self) -> None:
        for name in ("int_bits", "frac_bits"):
            value = getattr(self, name)
            if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
                raise TypeError(f"Format.{name} must be an int, got {value!r}")
            if value < 0:
                raise ValueError(f"Format.{name} must be >= 0, got {value}")
            object.__setattr__(self, name, int(value))  # numpy ints would leak into bounds
        if not isinstance(self.signed, bool | np.bool_):
            raise TypeError(f"Format.signed must be a bool, got {self.signed!r}")
        object.__setattr__(self, "signed", bool(self.signed))
        if self.width < 1:
            raise ValueError(f"{self} has no bits: a format needs a width of at least 1")

    @classmethod
    def parse(cls, text: str) -> Format:
        """Parse "s3.20" (signed, width 24) or "u1.23" (unsigned, width 24)."""
        if not isinstance(text, str):
            raise TypeError(f"a fixed-point format must be given as text, got {text!r}")
        match = _FORMAT_RE.fullmatch(text)
        if match is None:
            raise ValueError(
                f"{text!r} is not a fixed-point format: expected sI.F or uI.F, e.g. s3.20"
            )
        kind, int_bits, frac_bits = match.groups()
        if kind == "u" and int(int_bits) + int(frac_bits) == 0:
            raise ValueError(f"{text!r} is not a fixed-point format: it has no bits")
        return cls(kind == "s", int(int_bits), int(frac_bits))

    def __str__(self) -> str:
        return f"{'s' if self.signed else 'u'}{self.int_bits}.{self.frac_bits}"

    @property
    def width(self) -> int:
        """Total number of bits, sign bit included."""
        return int(self.signed) + self.int_bits + self.frac_bits

    @property
    def min_raw(self) -> int:
        return -(1 << (self.width - 1)) if self.signed else 0

    @property
    def max_raw(self) -> int:
        return (1 << (self.width - int(self.signed))) - 1

    @property
    def lsb(self) -> float:
        return math.ldexp(1.0, -self.frac_bits)

    @property
    def min_real(self) -> float:
        return self.min_raw / (1 << self.frac_bits)  # int / int is correctly rounded

    @property
    def max_real(self) -> float:
        return self.max_raw / (1 << self.frac_bits)

    def to_real(self, raw: Any) -> npt.NDArray[np.float64] | float:
        """Raw values to float64, correctly rounded (a float for scalar input)."""
        shape, scalar = _shape_of(raw)
        wide = not _fits(self.min_raw, self.max_raw)
        v = _prepare(raw, self.min_raw, self.max_raw, wide, f"raw value of {self}")
        if wide:
            # Python int / int rounds once, correctly, whatever the size.
            real = np.asarray(v / (1 << self.frac_bits), dtype=np.float64)
        else:
            # astype rounds once; scaling by a power of two is then exact.
            real = np.ldexp(v.astype(np.float64), -self.frac_bits)
        return float(real[0]) if scalar else real.reshape(shape)

    def from_real(self, x: Any, rounding: Rounding = "half_up") -> tuple[Raw, Flags]:
        """Quantise floats into this format; returns (raw, flag) with flag True where saturated.

        "half_up" is floor(x * 2**F + 1/2), "truncate" is floor(x * 2**F); +-inf saturate,
        NaN raises ValueError.
        """
        _check_rounding(rounding)
        shape, scalar = _shape_of(x)
        xf = np.atleast_1d(np.asarray(x, dtype=np.float64))
        if np.isnan(xf).any():
            raise ValueError(f"cannot quantise NaN into {self}")
        lo, hi = self.min_raw, self.max_raw
        wide = not _fits(lo, hi)
        if wide:
            # Exact per element; +-inf map just outside the range so saturation flags them.
            vals = [
                (hi + 1 if v > 0 else lo - 1) if math.isinf(v) else _quantise(v, self, rounding)
                for v in xf.ravel().tolist()
            ]
            r = np.empty(len(vals), dtype=object)
            r[:] = vals
            raw, flag = _saturate_core(r.reshape(xf.shape), lo - 1, hi + 1, self)
        else:
            # Exact: only the exponent changes (F <= 64); overflow to inf then saturates.
            with np.errstate(over="ignore"):
                y = np.ldexp(xf, self.frac_bits)
            r = np.floor(y)
            if rounding == "half_up":
                # y - r is exact; y + 0.5 would round for |y| >= 2**52.
                with np.errstate(invalid="ignore"):  # inf - inf for infinite inputs
                    r = r + ((y - r) >= 0.5)
            # r is integral, so compare with hi + 1 and lo: powers of two, exact as floats.
            above = r >= float(hi + 1)
            below = r < float(lo)
            flag = above | below
            raw = np.where(flag, 0.0, r).astype(np.int64)
            raw = np.where(above, hi, np.where(below, lo, raw))
        return _finish(raw, shape, scalar, wide), _finish_flags(flag, shape, scalar)


def shift_round(
    raw: Any, shift: int, rounding: Rounding, *, width: int, signed: bool = True
) -> Raw:
    """Divide by 2**shift with rounding; a negative shift multiplies by 2**-shift.

    "half_up" is floor(v / 2**shift + 1/2) = (v + (1 << (shift - 1))) >> shift and "truncate"
    is floor(v / 2**shift) = v >> shift. `width` and `signed` declare the range of the inputs
    (two's complement `width` bits if signed, else `width` unsigned bits) and pick the dtype.
    """
    _check_rounding(rounding)
    shift = _as_int(shift, "shift")
    lo, hi = _int_range(width, signed)
    shape, scalar = _shape_of(raw)
    rlo, rhi = _shift_int(lo, shift, rounding), _shift_int(hi, shift, rounding)
    wide = not _fits(lo, hi, rlo, rhi)
    label = f"raw value of a {'signed' if signed else 'unsigned'} {width}-bit input"
    v = _prepare(raw, lo, hi, wide, label)
    return _finish(_shift_core(v, shift, rounding, hi, wide), shape, scalar, wide)


def saturate(raw: Any, fmt: Format) -> tuple[Raw, Flags]:
    """Clamp into [fmt.min_raw, fmt.max_raw]; flag is True exactly where clamping happened.

    The input may be any integer; the result keeps its dtype (int64 or object).
    """
    shape, scalar = _shape_of(raw)
    v = _as_int_array(raw, "raw value")
    wide = v.dtype == object
    vlo, vhi = (fmt.min_raw - 1, fmt.max_raw + 1) if wide else (_INT64_MIN, _INT64_MAX)
    out, flag = _saturate_core(v, vlo, vhi, fmt)
    return _finish(out, shape, scalar, wide), _finish_flags(flag, shape, scalar)


def requantise(raw: Any, src: Format, dst: Format, rounding: Rounding) -> tuple[Raw, Flags]:
    """Move raw values from src to dst: shift_round the fraction bits, then saturate into dst."""
    _check_rounding(rounding)
    shape, scalar = _shape_of(raw)
    shift = src.frac_bits - dst.frac_bits
    rlo = _shift_int(src.min_raw, shift, rounding)
    rhi = _shift_int(src.max_raw, shift, rounding)
    wide = not _fits(src.min_raw, src.max_raw, rlo, rhi)
    v = _prepare(raw, src.min_raw, src.max_raw, wide, f"raw value of {src}")
    out, flag = _saturate_core(_shift_core(v, shift, rounding, src.max_raw, wide), rlo, rhi, dst)
    return _finish(out, shape, scalar, wide), _finish_flags(flag, shape, scalar)


def mul_round(
    a: Any, fa: Format, b: Any, fb: Format, out: Format, rounding: Rounding
) -> tuple[Raw, Flags]:
    """Exact product a*b (fa.frac_bits + fb.frac_bits fraction bits), rounded and saturated."""
    _check_rounding(rounding)
    shape, scalar = _shape_of(a, b)
    corners = [x * y for x in (fa.min_raw, fa.max_raw) for y in (fb.min_raw, fb.max_raw)]
    plo, phi = min(corners), max(corners)
    shift = fa.frac_bits + fb.frac_bits - out.frac_bits
    rlo, rhi = _shift_int(plo, shift, rounding), _shift_int(phi, shift, rounding)
    bounds = (fa.min_raw, fa.max_raw, fb.min_raw, fb.max_raw, plo, phi, rlo, rhi)
    wide = not _fits(*bounds)
    va = _prepare(a, fa.min_raw, fa.max_raw, wide, f"raw value of a ({fa})")
    vb = _prepare(b, fb.min_raw, fb.max_raw, wide, f"raw value of b ({fb})")
    r, flag = _saturate_core(_shift_core(va * vb, shift, rounding, phi, wide), rlo, rhi, out)
    return _finish(r, shape, scalar, wide), _finish_flags(flag, shape, scalar)


def add_sat(a: Any, b: Any, fmt: Format) -> tuple[Raw, Flags]:
    """Saturating a + b, both raw values of fmt (so already in the same fraction bits)."""
    shape, scalar = _shape_of(a, b)
    slo, shi = 2 * fmt.min_raw, 2 * fmt.max_raw
    wide = not _fits(fmt.min_raw, fmt.max_raw, slo, shi)
    va = _prepare(a, fmt.min_raw, fmt.max_raw, wide, f"raw value of a ({fmt})")
    vb = _prepare(b, fmt.min_raw, fmt.max_raw, wide, f"raw value of b ({fmt})")
    r, flag = _saturate_core(va + vb, slo, shi, fmt)
    return _finish(r, shape, scalar, wide), _finish_flags(flag, shape, scalar)


# --- helpers -----------------------------------------------------------------------------------


def _check_rounding(rounding: str) -> None:
    if rounding not in _ROUNDINGS:
        raise ValueError(f"unknown rounding {rounding!r}: expected 'half_up' or 'truncate'")


def _as_int(value: Any, name: str) -> int:
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be an int, got {value!r}")
    return int(value)


def _int_range(width: int, signed: bool) -> tuple[int, int]:
    width = _as_int(width, "width")
    if width < 1:
        raise ValueError(f"width must be >= 1, got {width}")
    if signed:
        return -(1 << (width - 1)), (1 << (width - 1)) - 1
    return 0, (1 << width) - 1


def _fits(*bounds: int) -> bool:
    return all(_INT64_MIN <= b <= _INT64_MAX for b in bounds)


def _shift_int(v: Any, shift: int, rounding: str) -> Any:
    """shift_round on Python ints (or object arrays of them); exact at any size.

    It is monotonic, so applied to the ends of an input range it gives the ends of the output.
    """
    if shift <= 0:
        return v << -shift
    if rounding == "truncate":
        return v >> shift
    return (v + (1 << (shift - 1))) >> shift


def _shift_core(v: np.ndarray, shift: int, rounding: str, hi: int, wide: bool) -> np.ndarray:
    """shift_round on a prepared array whose values are at most hi."""
    if shift == 0:
        return v
    if shift < 0:
        return v << -shift  # the caller checked that the result fits the dtype
    if wide:
        return _shift_int(v, shift, rounding)
    # int64 from here. Any shift >= 63 floors to 0 or -1, so clamp to 63 rather than lean on
    # how numpy treats shifts past the word width.
    if rounding == "truncate":
        return v >> min(shift, 63)
    if hi + (1 << (shift - 1)) <= _INT64_MAX:
        return (v + (1 << (shift - 1))) >> shift
    # The +half carry could overflow: use floor(v / 2**s) + bit s-1 of v, which is equal.
    return (v >> min(shift, 63)) + ((v >> min(shift - 1, 63)) & 1)


def _saturate_core(v: np.ndarray, vlo: int, vhi: int, fmt: Format) -> tuple[np.ndarray, Any]:
    """Clamp v, known to lie in [vlo, vhi], into fmt; only clamp the ends that can be crossed."""
    lo = fmt.min_raw if vlo < fmt.min_raw else None
    hi = fmt.max_raw if vhi > fmt.max_raw else None
    if lo is None and hi is None:
        return v, np.zeros(v.shape, dtype=bool)
    # Bounds used here lie strictly inside [vlo, vhi], so they fit the working dtype.
    out = np.clip(v, lo, hi)
    return out, np.asarray(out != v, dtype=bool)


def _shape_of(*xs: Any) -> tuple[tuple[int, ...], bool]:
    """Broadcast shape of the inputs, and whether they are all non-array scalars."""
    shape = np.broadcast_shapes(*(np.shape(x) for x in xs))
    scalar = all(not isinstance(x, np.ndarray) and np.ndim(x) == 0 for x in xs)
    return shape, scalar


def _as_int_array(x: Any, label: str) -> np.ndarray:
    """At-least-1-d int64 or object array of Python ints; refuses floats and bools."""
    if isinstance(x, bool | np.bool_):
        raise TypeError(f"{label} must be an integer, got {x!r}")
    if isinstance(x, int | np.integer):
        arr = np.empty(1, dtype=object)
        arr[0] = int(x)  # Python int: exact whatever its size
        return arr
    # Sequences go through object so big Python ints are never squeezed into a fixed dtype.
    arr = np.atleast_1d(x if isinstance(x, np.ndarray) else np.array(x, dtype=object))
    kind, size = arr.dtype.kind, arr.dtype.itemsize
    if kind == "i" or (kind == "u" and size < 8):
        return arr.astype(np.int64, copy=False)
    if kind == "u":
        return arr.astype(object)  # uint64 may exceed int64
    if kind == "O":
        types = set(map(type, arr.flat))
        if types <= {int}:
            return arr
        if all(issubclass(t, int | np.integer) and not issubclass(t, bool) for t in types):
            # numpy ints inside an object array would wrap: make them Python ints.
            fixed = np.empty(arr.size, dtype=object)
            fixed[:] = [int(v) for v in arr.flat]
            return fixed.reshape(arr.shape)
        bad = next(t for t in types if t is bool or not issubclass(t, int | np.integer))
        raise TypeError(f"{label} must be an integer, got {bad.__name__}")
    raise TypeError(f"{label} must be an integer, got an array of {arr.dtype}")


def _prepare(x: Any, lo: int, hi: int, wide: bool, label: str) -> np.ndarray:
    """Check every value lies in [lo, hi] (out of range means a bug upstream), then cast."""
    arr = _as_int_array(x, label)
    if arr.size:
        amin, amax = int(arr.min()), int(arr.max())
        if amin < lo or amax > hi:
            bad = amin if amin < lo else amax
            raise ValueError(f"{label}: {bad} is outside [{lo}, {hi}]")
    return arr.astype(object if wide else np.int64, copy=False)


def _finish(v: np.ndarray, shape: tuple[int, ...], scalar: bool, wide: bool) -> Raw:
    if scalar:
        return int(v.reshape(-1)[0])
    return np.asarray(v, dtype=object if wide else np.int64).reshape(shape)


def _finish_flags(flag: Any, shape: tuple[int, ...], scalar: bool) -> Flags:
    flag = np.asarray(flag, dtype=bool)
    if scalar:
        return bool(flag.reshape(-1)[0])
    return flag.reshape(shape)  # same size: inputs were broadcast to at least 1-d


def _quantise(x: float, fmt: Format, rounding: str) -> int:
    """floor(x * 2**F (+ 1/2)) exactly, for a finite float."""
    num, den = x.as_integer_ratio()  # den is a power of two
    num <<= fmt.frac_bits
    if rounding == "half_up":
        return (2 * num + den) // (2 * den)
    return num // den

"""Bit-exact scoreboard: compares raw fields beat by beat, lane by lane, in order.

The first mismatch is reported with block, beat, lane, field, and expected/actual both as real
numbers and as raw hex; totals of matched and mismatched values are kept for the summary.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from gpf.model.fixed import Format


@dataclass(frozen=True)
class Field:
    name: str
    fmt: Format


def unpack(words: list[int], fields: list[Field], lanes: int,
           beat_fields: list[Field] | tuple[Field, ...] = ()) -> dict[str, np.ndarray]:
    """Split stream words into raw field values: (beats, lanes) int64 per field, and (beats, 1)
    per beat field.

    Fields are packed LSB first within a lane; lanes are concatenated, lane 0 lowest; a beat's
    own fields (one per beat, not per lane) follow the last lane. Vectorised (the words as a bit
    matrix): the scoreboard must not set the pace of long runs.
    """
    lane_w = sum(f.fmt.width for f in fields)
    total = lane_w * lanes + sum(f.fmt.width for f in beat_fields)
    nbytes = max(1, (total + 7) // 8)
    raw = np.frombuffer(b"".join(w.to_bytes(nbytes, "little") for w in words),
                        dtype=np.uint8).reshape(len(words), nbytes)
    bits = np.unpackbits(raw, axis=1, bitorder="little").astype(np.int64)

    def read(offset: int, width: int) -> np.ndarray:
        return bits[:, offset:offset + width] @ np.left_shift(np.int64(1), np.arange(width))

    return _fields(len(words), fields, lanes, beat_fields, read)


def _fields(rows: int, fields: list[Field], lanes: int,
            beat_fields: list[Field] | tuple[Field, ...],
            read: Callable[[int, int], np.ndarray]) -> dict[str, np.ndarray]:
    """unpack()'s fields, each from read(offset, width): its raw bits as unsigned int64."""
    out = {f.name: np.zeros((rows, lanes), dtype=np.int64) for f in fields}
    out.update({f.name: np.zeros((rows, 1), dtype=np.int64) for f in beat_fields})
    lane_w = sum(f.fmt.width for f in fields)
    groups = [(lane, lane * lane_w, fields) for lane in range(lanes)]
    groups.append((0, lanes * lane_w, list(beat_fields)))
    for lane, offset, group in groups:
        for f in group:
            width = f.fmt.width
            assert width <= 62, f"{f.name}: {width}-bit fields are not unpacked"
            value = read(offset, width)
            if f.fmt.signed:
                value = np.where(value >> (width - 1) != 0, value - (1 << width), value)
            out[f.name][:, lane] = value
            offset += width
    return out


# ASCII hex digit -> its value; anything else (x, z, X, Z: an undefined bit) -> 16
_HEX = np.full(256, 16, dtype=np.uint8)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _HEX[ord(chr(_c).upper())] = _i


def hex_bytes(digits: np.ndarray) -> np.ndarray:
    """Hex numbers as ASCII, (rows, digits) most significant digit first, as bytes (rows,
    bytes + 16) least significant first, zero bytes after them (unpack_hex reads 8 at a time);
    ValueError if a digit is not hex (a simulator's x or z)."""
    nibbles = _HEX[digits]
    if (nibbles > 15).any():
        row = int(np.argwhere(nibbles > 15)[0][0])
        raise ValueError(f"row {row}: {bytes(digits[row]).decode()!r} is not hex")
    if nibbles.shape[1] % 2:
        nibbles = np.pad(nibbles, ((0, 0), (1, 0)))
    msb_first = (nibbles[:, 0::2] << 4) | nibbles[:, 1::2]
    return np.pad(msb_first[:, ::-1], ((0, 0), (0, 16)))


def _word(raw: np.ndarray, first: int) -> np.ndarray:
    """The 64-bit little-endian word at byte `first` of every row."""
    return np.ascontiguousarray(raw[:, first:first + 8]).view("<u8")[:, 0]


def unpack_hex(digits: np.ndarray, fields: list[Field], lanes: int,
               beat_fields: list[Field] | tuple[Field, ...] = ()) -> dict[str, np.ndarray]:
    """unpack() from the words as ASCII hex (rows, digits), most significant digit first: each
    field read as the 64-bit little-endian word at its first byte, shifted and masked."""
    raw = hex_bytes(digits)

    def read(offset: int, width: int) -> np.ndarray:
        first, shift = offset // 8, offset % 8
        word = _word(raw, first) >> np.uint64(shift)
        if width + shift > 64:   # its last bits in the byte after those 8
            word |= _word(raw, first + 8) << np.uint64(64 - shift)
        return (word & np.uint64((1 << width) - 1)).astype(np.int64)

    return _fields(len(raw), fields, lanes, beat_fields, read)


def pack(fields: list[Field], values: dict[str, np.ndarray],
         beat_fields: list[Field] | tuple[Field, ...] = ()) -> list[int]:
    """Stream words from raw field values (beats, lanes) and beat fields (beats, 1): the inverse
    of unpack()."""
    lane_w = sum(f.fmt.width for f in fields)
    beats, lanes = np.asarray(values[fields[0].name]).shape
    words = []
    for beat in range(beats):
        word = 0
        for lane in range(lanes):
            shift = lane * lane_w
            for f in fields:
                word |= (int(values[f.name][beat, lane]) & ((1 << f.fmt.width) - 1)) << shift
                shift += f.fmt.width
        shift = lanes * lane_w
        for f in beat_fields:
            word |= (int(np.asarray(values[f.name])[beat, 0]) & ((1 << f.fmt.width) - 1)) << shift
            shift += f.fmt.width
        words.append(word)
    return words


@dataclass
class Scoreboard:
    block: str
    fields: list[Field]
    matched: int = 0
    mismatched: int = 0
    first_mismatch: str | None = None
    expect_mismatch: bool = False  # a deliberately corrupted model: mismatches are the point
    log: logging.Logger = field(default_factory=lambda: logging.getLogger("tb.scoreboard"))

    def compare(self, expected: dict[str, np.ndarray], actual: dict[str, np.ndarray],
                first_beat: int = 0) -> int:
        """Compare (beats, lanes) arrays field by field; return the new mismatch count."""
        new = 0
        for f in self.fields:
            exp, act = np.asarray(expected[f.name]), np.asarray(actual[f.name])
            if exp.shape != act.shape:
                raise AssertionError(f"{self.block}.{f.name}: expected {exp.shape} values, "
                                     f"got {act.shape}")
            bad = exp != act
            n_bad = int(bad.sum())
            self.matched += exp.size - n_bad
            new += n_bad
            if n_bad and self.first_mismatch is None:
                beat, lane = (int(i) for i in np.argwhere(bad)[0])
                self.first_mismatch = self.describe(f, first_beat + beat, lane,
                                                    int(exp[beat, lane]), int(act[beat, lane]))
                report = self.log.info if self.expect_mismatch else self.log.error
                report("first mismatch: %s", self.first_mismatch)
        self.mismatched += new
        return new

    def describe(self, f: Field, beat: int, lane: int, exp: int, act: int) -> str:
        digits = (f.fmt.width + 3) // 4

        def show(raw: int) -> str:
            bits = raw & ((1 << f.fmt.width) - 1)
            return f"{float(f.fmt.to_real(raw)):.9g} (0x{bits:0{digits}x})"

        return (f"{self.block}: beat {beat}, lane {lane}, field {f.name} [{f.fmt}]: "
                f"expected {show(exp)}, actual {show(act)}")

    def summary(self) -> str:
        return f"{self.block}: {self.matched} matched, {self.mismatched} mismatched"

    def assert_clean(self) -> None:
        """Pass only with zero mismatches AND something compared."""
        assert self.mismatched == 0, f"{self.summary()}; first: {self.first_mismatch}"
        assert self.matched > 0, f"{self.block}: nothing was compared"

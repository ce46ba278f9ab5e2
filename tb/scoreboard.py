"""Bit-exact scoreboard: compares raw fields beat by beat, lane by lane, in order.

The first mismatch is reported with block, beat, lane, field, and expected/actual both as real
numbers and as raw hex; totals of matched and mismatched values are kept for the summary.
"""

from __future__ import annotations

import logging
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
    bits = np.unpackbits(raw, axis=1, bitorder="little")
    out = {f.name: np.zeros((len(words), lanes), dtype=np.int64) for f in fields}
    out.update({f.name: np.zeros((len(words), 1), dtype=np.int64) for f in beat_fields})
    groups = [(lane, lane * lane_w, fields) for lane in range(lanes)]
    groups.append((0, lanes * lane_w, list(beat_fields)))
    for lane, offset, group in groups:
        for f in group:
            width = f.fmt.width
            assert width <= 62, f"{f.name}: {width}-bit fields are not unpacked"
            weights = np.left_shift(np.int64(1), np.arange(width, dtype=np.int64))
            value = bits[:, offset:offset + width].astype(np.int64) @ weights
            if f.fmt.signed:
                value = np.where(value >> (width - 1) != 0, value - (1 << width), value)
            out[f.name][:, lane] = value
            offset += width
    return out


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

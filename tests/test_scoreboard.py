"""The scoreboard's field packing: unpack() is the inverse of pack() for any formats and lanes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gpf.model.fixed import Format
from gpf.tb.scoreboard import Field, pack, unpack, unpack_hex

formats = st.builds(lambda signed, i, f: Format(signed, i, f), st.booleans(),
                    st.integers(1, 30), st.integers(0, 30))


@settings(max_examples=200, deadline=None)
@given(st.lists(formats, min_size=1, max_size=6), st.integers(1, 4), st.integers(0, 20),
       st.integers(0, 2**32 - 1))
def test_unpack_inverts_pack(fmts: list[Format], lanes: int, beats: int, seed: int) -> None:
    fields = [Field(f"f{k}", fmt) for k, fmt in enumerate(fmts)]
    rng = np.random.default_rng(seed)
    values = {f.name: rng.integers(f.fmt.min_raw, f.fmt.max_raw + 1, size=(beats, lanes))
              for f in fields}
    if beats == 0:
        values = {k: v.reshape(0, lanes) for k, v in values.items()}
        got = unpack([], fields, lanes)
    else:
        got = unpack(pack(fields, values), fields, lanes)
    for f in fields:
        np.testing.assert_array_equal(got[f.name], values[f.name])


def verilog_hex(word: int, width: int) -> bytes:
    """A word as $fwrite's %h writes it: every digit of its width, leading zeros kept."""
    return f"{word:0{-(-width // 4)}x}".encode()


@settings(max_examples=200, deadline=None)
@given(st.lists(formats, min_size=1, max_size=6), st.integers(1, 4), st.integers(1, 20),
       st.integers(0, 2**32 - 1), st.booleans())
def test_unpack_hex_reads_what_pack_wrote(fmts: list[Format], lanes: int, beats: int,
                                          seed: int, upper: bool) -> None:
    """The harness's records (hex, as $fwrite %h writes them, either case) unpack to the
    values packed, as unpack() reads the words."""
    fields = [Field(f"f{k}", fmt) for k, fmt in enumerate(fmts)]
    beat_fields = [Field("b", Format(False, 5, 0))]
    rng = np.random.default_rng(seed)
    values = {f.name: rng.integers(f.fmt.min_raw, f.fmt.max_raw + 1, size=(beats, lanes))
              for f in fields}
    values["b"] = rng.integers(0, 32, size=(beats, 1))
    width = lanes * sum(f.fmt.width for f in fields) + 5
    lines = [verilog_hex(w, width) for w in pack(fields, values, beat_fields)]
    lines = [line.upper() if upper else line for line in lines]
    digits = np.frombuffer(b"".join(lines), dtype=np.uint8).reshape(beats, -1)
    got = unpack_hex(digits, fields, lanes, beat_fields)
    for name, v in values.items():
        np.testing.assert_array_equal(got[name], v)


def test_unpack_hex_refuses_undefined_digits() -> None:
    fields = [Field("f", Format(False, 8, 0))]
    with pytest.raises(ValueError, match="not hex"):
        unpack_hex(np.frombuffer(b"0x", dtype=np.uint8).reshape(1, 2), fields, 1)


def test_unpack_hex_reads_a_field_across_nine_bytes() -> None:
    """A 60-bit field after a 7-bit one spans bytes 0..8: read from two words."""
    fields = [Field("a", Format(False, 7, 0)), Field("wide", Format(True, 30, 30))]
    values = {"a": np.array([[0x55], [0x7F]]), "wide": np.array([[-(2**59)], [2**59 - 3]])}
    lines = [verilog_hex(w, 67) for w in pack(fields, values)]
    digits = np.frombuffer(b"".join(lines), dtype=np.uint8).reshape(2, -1)
    got = unpack_hex(digits, fields, 1)
    np.testing.assert_array_equal(got["wide"], values["wide"])
    np.testing.assert_array_equal(got["a"], values["a"])

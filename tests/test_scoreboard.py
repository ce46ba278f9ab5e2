"""The scoreboard's field packing: unpack() is the inverse of pack() for any formats and lanes."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gpf.model.fixed import Format
from gpf.tb.scoreboard import Field, pack, unpack

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

"""Per-particle flags of a vectorised model block (model.blocks functions OR their flags over
all particles; the RTL's `sat` field is per particle)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gpf.model.blocks import Flag
from gpf.model.fixed import Format


def sat_per_row(out: np.ndarray, fmts: tuple[Format, ...] | list[Format],
                flags_of_row: Callable[[int], int]) -> np.ndarray:
    """1 where the model flags Flag.SAT for that row alone, else 0.

    Saturation leaves a component at its format's end, so only rows with an output at min_raw
    or max_raw can be flagged: the model is called once per such row (`flags_of_row(r)`)."""
    lo = np.array([f.min_raw for f in fmts], dtype=np.int64)
    hi = np.array([f.max_raw for f in fmts], dtype=np.int64)
    ends = np.any((out == lo) | (out == hi), axis=1)
    sat = np.zeros(len(out), dtype=np.int64)
    for r in np.flatnonzero(ends):
        sat[r] = 1 if flags_of_row(int(r)) & Flag.SAT else 0
    return sat

"""Functional coverage of the testbenches (cocotb-coverage), and each stream block's group.

A simulation process keeps one coverage database (cocotb-coverage's `coverage_db`, a singleton).
Cover points are created where a testbench first samples them, so a group has all its bins in
the database once it is sampled at all. `save()` writes the database, as cocotb-coverage's YAML
export, to the file gpf.sim.run_sim names in GPF_COVERAGE_FILE (one a simulation run); without
it nothing is written. `gpf coverage` (gpf/coverage.py) merges the files and reports the bins.

Bins are strings, hit once per sampling event: a batch of beats through a block (run_stream), a
step of the whole filter. Values come from the streams as the simulation carried them (the
scoreboard has checked them against the model bit for bit); stall and tlast bins from the stream
drivers' own records (tb/stream.py). Runs of a deliberately wrong model sample nothing.

Each stream block's group `<block>.<app>`:
  lanes          LANES 1, 2, 4 of the run
  rail           each output field at its format's top (max) or bottom (min; signed fields): the
                 saturation of each component in each direction
  sat            a lane's sat bit raised (0 -> 1 between consecutive beats) and cleared (1 -> 0)
  flags          each flag of a `flags` field raised and cleared between consecutive results
  tlast          steps (input beats up to tlast) of 1, 2-8, 9-64 and 65+ beats
  stall.s_axis   idle clocks before an input beat (0, 1, 2+) and the block's backpressure
  stall.m_axis   clocks an output beat waited for tready (0, 1, 2-3, 4+)
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from cocotb_coverage import coverage

from gpf.model.blocks import Flag
from gpf.tb.scoreboard import Field

FILE_ENV = "GPF_COVERAGE_FILE"
FLAG_NAMES = {Flag.SAT: "sat", Flag.ZERO_WEIGHTS: "zero_weights", Flag.NOT_PD: "not_pd",
              Flag.LOW_ESS: "low_ess"}
LANES = (1, 2, 4)
SOURCE_BINS = ("gap 0", "gap 1", "gap 2+", "backpressure")
SINK_BINS = ("wait 0", "wait 1", "wait 2-3", "wait 4+")
STEP_BINS = ("1", "2-8", "9-64", "65+")


def enabled() -> bool:
    return bool(os.environ.get(FILE_ENV))


class Group:
    """Cover points under one name (`<name>.<point>`), each a cocotb-coverage CoverPoint with
    string bins, sampled by `hit(point, bin, ...)`."""

    def __init__(self, name: str):
        self.name = name
        self._samplers: dict[str, object] = {}
        self._bins: dict[str, tuple[str, ...]] = {}

    def point(self, point: str, bins: Iterable[str]) -> Group:
        """Declare a point (once per process: cocotb-coverage returns an existing one)."""
        if point not in self._samplers:
            bins = tuple(bins)

            def sample(value: str) -> None:   # the bin is matched on the argument
                del value

            full = f"{self.name}.{point}"
            self._samplers[point] = coverage.CoverPoint(full, bins=list(bins))(sample)
            self._bins[point] = bins
        return self

    def has(self, point: str) -> bool:
        return point in self._samplers

    def hit(self, point: str, *bins: str) -> None:
        sampler = self._samplers[point]
        for b in bins:
            if b not in self._bins[point]:
                raise ValueError(f"{self.name}.{point}: no bin {b!r}")
            sampler(b)


_groups: dict[str, Group] = {}


def group(name: str) -> Group:
    if name not in _groups:
        _groups[name] = Group(name)
    return _groups[name]


def save() -> None:
    """Write the process's database (all groups sampled so far) over its file."""
    path = os.environ.get(FILE_ENV)
    if not path:
        return
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}")
    coverage.coverage_db.export_to_yaml(str(tmp))
    tmp.replace(out)


# ---- bins from values ----------------------------------------------------------------------

def rail_bins(fields: Iterable[Field]) -> list[str]:
    """`<field>:max` for every field wider than a bit, `<field>:min` for the signed ones."""
    out = []
    for f in fields:
        if f.fmt.width > 1 and f.name != "flags":
            out.append(f"{f.name}:max")
            if f.fmt.signed:
                out.append(f"{f.name}:min")
    return out


def rails_hit(fields: Iterable[Field], values: dict[str, np.ndarray], prefix: str = ""
              ) -> list[str]:
    """The rail bins (rail_bins) some value reaches."""
    out = []
    for f in fields:
        if f.fmt.width <= 1 or f.name == "flags" or f.name not in values:
            continue
        v = np.asarray(values[f.name])
        if np.any(v == f.fmt.max_raw):
            out.append(f"{prefix}{f.name}:max")
        if f.fmt.signed and np.any(v == f.fmt.min_raw):
            out.append(f"{prefix}{f.name}:min")
    return out


def transitions(bits: np.ndarray) -> list[str]:
    """`raised` / `cleared` if a bit goes 0 -> 1 / 1 -> 0 between consecutive rows (beats or
    results), per column (lane); a first row that is set counts as raised."""
    b = np.asarray(bits, dtype=np.int64).reshape(len(bits), -1) != 0
    before = np.vstack([np.zeros((1, b.shape[1]), dtype=bool), b[:-1]])
    out = []
    if np.any(b & ~before):
        out.append("raised")
    if np.any(~b & before):
        out.append("cleared")
    return out


def flag_bins() -> list[str]:
    return [f"{name} {edge}" for name in FLAG_NAMES.values() for edge in ("raised", "cleared")]


def flags_hit(flags: np.ndarray) -> list[str]:
    """flag_bins reached by a sequence of flag words (one per result, in order)."""
    flags = np.asarray(flags, dtype=np.int64).reshape(-1)
    return [f"{name} {edge}" for bit, name in FLAG_NAMES.items()
            for edge in transitions(flags & int(bit))]


def step_bin(beats: int) -> str:
    return "1" if beats == 1 else "2-8" if beats <= 8 else "9-64" if beats <= 64 else "65+"


def step_lengths(lasts: list[bool]) -> Counter[int]:
    """Beats per step of a stream (a step ends with tlast; an unfinished tail is not one)."""
    out: Counter[int] = Counter()
    run = 0
    for last in lasts:
        run += 1
        if last:
            out[run] += 1
            run = 0
    return out


def source_bins(gaps: Counter[int], waits: Counter[int]) -> list[str]:
    """Stall bins of a stream the testbench drives: its idle gaps, the block's backpressure."""
    out = [f"gap {g}" for g in (0, 1) if gaps[g]]
    if any(gaps[g] for g in gaps if g >= 2):
        out.append("gap 2+")
    if any(waits[w] for w in waits if w >= 1):
        out.append("backpressure")
    return out


def sink_bins(waits: Counter[int]) -> list[str]:
    """Stall bins of a stream the testbench takes: clocks each beat waited for tready."""
    out = []
    for label, lo, hi in (("wait 0", 0, 0), ("wait 1", 1, 1), ("wait 2-3", 2, 3),
                          ("wait 4+", 4, 1 << 62)):
        if any(waits[w] for w in waits if lo <= w <= hi):
            out.append(label)
    return out


# ---- the stream blocks (tb/streaming.py's run_stream) --------------------------------------

def block_group(block, app: str) -> Group:
    g = group(f"{block.name}.{app}")
    outs = list(block.fields_out) + list(block.beat_out)
    g.point("lanes", (f"lanes {n}" for n in LANES))
    rails = rail_bins(outs)
    if rails:
        g.point("rail", rails)
    if any(f.name == "sat" for f in outs):
        g.point("sat", ("raised", "cleared"))
    if any(f.name == "flags" for f in outs):
        g.point("flags", flag_bins())
    g.point("tlast", STEP_BINS)
    g.point("stall.s_axis", SOURCE_BINS)
    g.point("stall.m_axis", SINK_BINS)
    return g


def sample_block(block, app: str, lanes: int, got: dict[str, np.ndarray], lasts_in: list[bool],
                 source, sink) -> None:
    """One batch of beats through a stream block: its outputs (as the simulation carried them),
    the input's steps, both streams' stall records."""
    if not enabled():
        return
    g = block_group(block, app)
    outs = list(block.fields_out) + list(block.beat_out)
    g.hit("lanes", f"lanes {lanes}")
    if g.has("rail"):
        g.hit("rail", *rails_hit(outs, got))
    if "sat" in got:
        g.hit("sat", *transitions(got["sat"]))
    if "flags" in got:
        g.hit("flags", *flags_hit(got["flags"][:, 0]))
    g.hit("tlast", *sorted({step_bin(n) for n in step_lengths(lasts_in)}))
    g.hit("stall.s_axis", *source_bins(source.gaps, source.waits))
    g.hit("stall.m_axis", *sink_bins(sink.waits))
    save()


# ---- the GRNG (tb/grng/test_grng.py: every batch of samples it checks) ----------------------

SIGMAS = ("0-1", "1-2", "2-3", "3-4", "4-5", "5+")


def z_band(z_real: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's sign (negative) and band of |z| in sigmas (an index into SIGMAS)."""
    z = np.asarray(z_real, dtype=float)
    return z < 0, np.minimum(np.floor(np.abs(z)), len(SIGMAS) - 1).astype(int)


def sample_grng(app: str, lanes: int, z_real: np.ndarray) -> None:
    """A batch of the GRNG's samples (reals): LANES, and each sign's band of |z| in sigmas."""
    if not enabled():
        return
    g = group(f"grng.{app}")
    g.point("lanes", (f"lanes {n}" for n in LANES))
    g.point("z", (f"{sign}{band}" for sign in "-+" for band in SIGMAS))
    g.hit("lanes", f"lanes {lanes}")
    negative, band = z_band(np.reshape(z_real, -1))
    g.hit("z", *sorted({f"{'-' if neg else '+'}{SIGMAS[k]}"
                        for neg, k in zip(negative, band, strict=True)}))
    save()

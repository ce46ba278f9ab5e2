"""How a whole-filter run's steps reach gpf_<app> and its outputs come back, one step at a time.

HarnessFeed: gpf_<app>_harness (rtl/templates/gpf_harness.sv.j2) sends the step beats from a
  memory preloaded from a file, stalls every stream at random from a seed the test prints,
  records every output beat into a file per stream, checks the outputs' AXI4-Stream protocol,
  and counts: Python wakes once a step and reads the step's beats in bulk (numpy).
StreamFeed: cocotb's own drivers and monitors (tb/stream.py), clock by clock: gpf_<app>_axi,
  whose streams and registers the harness does not drive, and runs longer than the harness
  holds.

Both give a step's beats as StepBeats, what the scoreboard compares.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, First, ReadOnly, RisingEdge, Timer, ValueChange

from gpf.tb.harness import CLOCK_NS
from gpf.tb.scoreboard import Field, unpack, unpack_hex
from gpf.tb.stream import Beat, ProtocolError, Sink, Source, StreamLoop

STIMULUS = "gpf_harness_steps.hex"     # what the harness's $readmemh reads (its working folder)
RECORDS = {tap: f"gpf_harness_{tap}.hex" for tap in ("cond", "part", "est")}
PORTS = ("m_cond", "m_part", "m_est", "s_step")      # the harness's violation_port codes
KINDS = ("a beat not taken changed or was withdrawn before the handshake",
         "tvalid or tready X or Z after reset", "tdata or tlast X or Z while tvalid is high")


@dataclass
class StepBeats:
    """One step's beats: per tap its tlast per beat and raw fields; the result's fields and
    the clock it crossed on."""

    lasts: dict[str, np.ndarray]          # "cond", "part": (beats,) bool
    taps: dict[str, dict[str, np.ndarray]]
    est: dict[str, np.ndarray]
    est_cycle: int


@dataclass(frozen=True)
class Layout:
    """The fields of every output stream, as filter.streams() gives them."""

    cond: list[Field]
    part: list[Field]
    est: list[Field]
    shift: Field
    lanes: int

    def width(self, tap: str) -> int:
        if tap == "est":
            return sum(f.fmt.width for f in self.est)
        fields = self.cond if tap == "cond" else self.part
        return self.lanes * sum(f.fmt.width for f in fields) + (tap == "part") * \
            self.shift.fmt.width

    def unpack_tap(self, tap: str, words: list[int] | np.ndarray, hex_digits: bool = False
                   ) -> dict[str, np.ndarray]:
        """The tap's fields from its words, or from them as ASCII hex digits (rows, digits)."""
        fields, per_beat = (self.cond, ()) if tap == "cond" else (self.part, (self.shift,))
        if hex_digits:
            return unpack_hex(words, fields, self.lanes, per_beat)
        return unpack(list(words), fields, self.lanes, per_beat)


@dataclass
class Stalls:
    """A stream's stall record for functional coverage (tb/coverage.py's source_bins and
    sink_bins), as Source and Sink keep it: idle clocks before each beat, clocks each beat
    waited."""

    gaps: Counter[int] = field(default_factory=Counter)
    waits: Counter[int] = field(default_factory=Counter)


def stall_level(stall: float) -> int:
    """A stall probability in the harness's 256ths (0: never, 256: always)."""
    return min(256, max(0, round(stall * 256)))


def write_stimulus(workdir: Path, step_words: list[int], step_w: int) -> None:
    """The step beats the harness's $readmemh reads."""
    digits = -(-step_w // 4)
    (workdir / STIMULUS).write_text("".join(f"{w:0{digits}x}\n" for w in step_words))


class Records:
    """The harness's record files of a run, read a step at a time (in any thread: no simulator
    handle). A step's beats are all there once its result's line is: the harness flushes the
    three files together, m_est's last."""

    def __init__(self, layout: Layout, workdir: Path = Path(".")):
        self.layout, self.workdir = layout, workdir
        self.files: dict[str, BinaryIO] = {}
        # a record line: tlast's digit, tdata's digits, a newline; m_est's: cycle, space, tdata
        digits = {tap: -(-layout.width(tap) // 4) for tap in RECORDS}
        self.line = {"cond": 2 + digits["cond"], "part": 2 + digits["part"],
                     "est": 10 + digits["est"]}

    def remove(self) -> None:
        """An earlier run's records gone (a run that never opens its own must not read them)."""
        for name in RECORDS.values():
            (self.workdir / name).unlink(missing_ok=True)

    def open(self) -> None:
        for tap, name in RECORDS.items():
            self.files[tap] = (self.workdir / name).open("rb")

    def results(self) -> int:
        """The results recorded so far (complete lines of m_est)."""
        path = self.workdir / RECORDS["est"]
        return path.stat().st_size // self.line["est"] if path.exists() else 0

    def read(self, k: int, beats: int) -> StepBeats:
        """Step k's beats (its result is out: every beat of it is there)."""
        lasts, taps = {}, {}
        for tap in ("cond", "part"):
            rows = self._rows(tap, beats, k)
            lasts[tap] = rows[:, 0] == ord("1")
            taps[tap] = self._unpack(tap, rows[:, 1:-1], k)
        row = self._rows("est", 1, k)
        est = self._unpack("est", row[:, 9:-1], k)
        return StepBeats(lasts, taps, est, int(bytes(row[0, :8]), 16))

    def _rows(self, tap: str, n: int, k: int) -> np.ndarray:
        size = self.line[tap]
        data = self.files[tap].read(n * size)
        got = len(data) // size
        assert got == n, f"step {k}: {got} m_{tap} beats, expected {n}"
        return np.frombuffer(data, dtype=np.uint8).reshape(n, size)

    def _unpack(self, tap: str, digits: np.ndarray, k: int) -> dict[str, np.ndarray]:
        try:
            if tap == "est":
                return unpack_hex(digits, self.layout.est, 1)
            return self.layout.unpack_tap(tap, digits, hex_digits=True)
        except ValueError as exc:   # the harness flags X or Z first: a harness fault
            raise AssertionError(f"step {k}: m_{tap}: undefined bits recorded ({exc})") from None

    def close(self) -> None:
        for f in self.files.values():
            f.close()


def stall_counts(read: Callable[[str], list[int]]) -> tuple[Stalls, dict[str, Stalls]]:
    """The harness's stall records, read(port) giving its four counts: s_step's and each
    output's (their bins' counts, each under the smallest length of its bin)."""
    g = read("step_gaps")
    step = Stalls(Counter({0: g[0], 1: g[1], 2: g[2]}), Counter({1: g[3]}))
    sinks = {}
    for tap in RECORDS:
        w = read(f"{tap}_waits")
        sinks[tap] = Stalls(waits=Counter({0: w[0], 1: w[1], 2: w[2], 4: w[3]}))
    return step, sinks


class HarnessFeed:
    """The run's steps through gpf_<app>_harness (see the module's docstring)."""

    def __init__(self, dut: SimHandleBase, layout: Layout, stall: float, stall_seed: int,
                 workdir: Path = Path(".")):
        self.dut, self.layout, self.stall, self.seed = dut, layout, stall, stall_seed
        self.workdir = workdir
        self.records = Records(layout, workdir)

    async def start(self, step_words: list[int], step_w: int) -> None:
        """Preload the step beats, then hand the core's streams to the harness."""
        write_stimulus(self.workdir, step_words, step_w)
        d = self.dut
        d.steps.value = len(step_words)
        d.stall.value = stall_level(self.stall)
        d.stall_seed.value = self.seed
        d.fast.value = 1
        d.load.value = 1
        await RisingEdge(d.clk)   # the harness loads at this edge (load rose)
        await ReadOnly()          # and has opened its records by now
        await RisingEdge(d.clk)
        d.load.value = 0
        self.records.open()

    def read(self, k: int, beats: int) -> StepBeats:
        """Step k's beats from the records (in the checker's thread)."""
        return self.records.read(k, beats)

    async def wait(self, k: int, limit: int) -> None:
        """Until the k-th result is out (failing after `limit` clocks, or on a violation)."""
        d = self.dut
        timeout = Timer(limit * CLOCK_NS, "ns")
        while int(d.est_count.value) < k:
            self.check_protocol()
            if await First(ValueChange(d.est_count), timeout) is timeout:
                raise AssertionError(f"step {k}: no result after {limit} clocks "
                                     f"({int(d.step_count.value)} step beats taken, "
                                     f"{int(d.cond_count.value)} m_cond and "
                                     f"{int(d.part_count.value)} m_part beats out)")
        self.check_protocol()

    def check_protocol(self) -> None:
        d = self.dut
        if int(d.violations.value):
            port, kind = PORTS[int(d.violation_port.value)], KINDS[int(d.violation_kind.value)]
            raise ProtocolError(f"gpf harness: {port}: AXI4-Stream protocol violation at cycle "
                                f"{int(d.violation_cycle.value)} of the run: {kind} (the "
                                "simulator's log has every one)")

    async def finish(self, steps: int, beats: int) -> None:
        """After the last result: nothing more may come out; the streams back to cocotb."""
        d = self.dut
        await ClockCycles(d.clk, 50)
        self.check_protocol()
        assert int(d.step_count.value) == steps, "step beats left untaken"
        assert int(d.est_count.value) == steps, "extra result beats"
        assert int(d.cond_count.value) == int(d.part_count.value) == steps * beats, \
            "extra tap beats"
        def counts(port: str) -> list[int]:
            v = int(getattr(self.dut, port).value)
            return [(v >> (32 * i)) & 0xFFFFFFFF for i in range(4)]

        self.stalls = stall_counts(counts)
        d.fast.value = 0
        self.records.close()


class StreamFeed:
    """The run's steps through cocotb's drivers and monitors (see the module's docstring)."""

    def __init__(self, dut: SimHandleBase, clk: SimHandleBase, layout: Layout, stall: float,
                 rng: random.Random, est_last: bool, est_hold: int = 0):
        self.dut, self.clk, self.layout = dut, clk, layout
        self.stall, self.rng, self.est_last = stall, rng, est_last
        self.sinks = {k: Sink(dut, f"m_{k}", stall, rng, has_last=(k != "est" or est_last),
                              hold=est_hold if k == "est" else 0)
                      for k in ("cond", "part", "est")}

    async def start(self, step_words: list[int], step_w: int) -> None:
        self.steps_in = Source(self.dut, "s_step", self.stall, self.rng,
                               [(w, True) for w in step_words], has_last=self.est_last)
        # one coroutine drives the step inputs and reads every output
        self.loop = StreamLoop(self.clk, [self.steps_in, *self.sinks.values()])

    @property
    def beats(self) -> dict[str, list[Beat]]:
        return {k: sink.beats for k, sink in self.sinks.items()}

    async def wait(self, k: int, limit: int) -> None:
        """Until the k-th result is out (failing after `limit` clocks)."""
        from cocotb.triggers import SimTimeoutError, with_timeout

        try:
            await with_timeout(self.sinks["est"].wait(k), limit * CLOCK_NS, "ns")
        except SimTimeoutError:
            raise AssertionError(f"step {k}: no result after {limit} clocks") from None

    def read(self, k: int, beats: int) -> StepBeats:
        """Step k's beats as the monitors took them (its result is out)."""
        lo, hi = (k - 1) * beats, k * beats
        lasts, taps = {}, {}
        for tap in ("cond", "part"):
            got = self.sinks[tap].beats[lo:hi]
            assert len(got) == beats, f"step {k}: {len(got)} {tap} beats, expected {beats}"
            lasts[tap] = np.array([bt.last for bt in got])
            taps[tap] = self.layout.unpack_tap(tap, [bt.data for bt in got])
        result = self.sinks["est"].beats[k - 1]
        return StepBeats(lasts, taps, unpack([result.data], self.layout.est, 1), result.cycle)

    async def finish(self, steps: int, beats: int) -> None:
        await self.steps_in.done.wait()
        for _ in range(50):   # nothing more may come out
            await RisingEdge(self.clk)
        self.loop.stop()
        self.stalls = (self.steps_in, self.sinks)
        mons = self.beats
        assert len(mons["est"]) == steps, "extra result beats"
        assert len(mons["cond"]) == len(mons["part"]) == steps * beats, "extra tap beats"

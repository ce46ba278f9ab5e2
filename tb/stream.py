"""AXI4-Stream helpers for the testbenches: a random `tready` driver and a beat monitor.

Monitors sample after the rising edge once signals settle (ReadOnly) and record a beat only when
tvalid && tready, so the scoreboard sees what crossed the bus, not what a driver meant to send.
"""

from __future__ import annotations

import logging
import random
from collections.abc import Callable
from dataclasses import dataclass

import cocotb
from cocotb.handle import SimHandleBase
from cocotb.simtime import get_sim_time
from cocotb.triggers import Event, ReadOnly, RisingEdge, Trigger, ValueChange
from cocotb.utils import get_sim_steps

from gpf.tb.harness import CLOCK_NS


@dataclass
class Beat:
    data: int
    cycle: int
    last: bool = False


class ReadyDriver:
    """Drives `tready`: high with probability 1 - stall (a fresh random choice every clock)."""

    def __init__(self, clk: SimHandleBase, tready: SimHandleBase, stall: float,
                 rng: random.Random):
        self.clk, self.tready, self.stall, self.rng = clk, tready, stall, rng
        self.tready.value = 0 if stall >= 1 else 1
        self._task = cocotb.start_soon(self._run())

    async def _run(self) -> None:
        while True:
            await RisingEdge(self.clk)
            self.tready.value = 0 if self.rng.random() < self.stall else 1

    def stop(self, ready: int = 1) -> None:
        self._task.cancel()
        self.tready.value = ready


class StreamMonitor:
    """Records every beat (tvalid && tready) of one AXI4-Stream port into `beats`."""

    def __init__(self, clk: SimHandleBase, prefix: SimHandleBase, name: str,
                 has_last: bool = False):
        self.clk = clk
        self.tvalid = getattr(prefix, f"{name}_tvalid")
        self.tready = getattr(prefix, f"{name}_tready")
        self.tdata = getattr(prefix, f"{name}_tdata")
        self.tlast = getattr(prefix, f"{name}_tlast") if has_last else None
        self.beats: list[Beat] = []
        self.cycles = 0
        self.log = logging.getLogger(f"tb.{name}.mon")
        self._task = cocotb.start_soon(self._run())

    async def _run(self) -> None:
        while True:
            await RisingEdge(self.clk)
            await ReadOnly()
            self.cycles += 1
            if self.tvalid.value == 1 and self.tready.value == 1:
                last = bool(self.tlast.value) if self.tlast is not None else False
                # to_unsigned() raises on X or Z: an undefined output is an error, not a 0
                self.beats.append(Beat(self.tdata.value.to_unsigned(), self.cycles, last))

    def stop(self) -> None:
        self._task.cancel()


class StreamDriver:
    """Drives an AXI4-Stream slave port (`<name>_tvalid/tready/tdata/tlast`) with beats, idle
    for a random clock before a beat with probability `idle`; holds each beat until taken.

    A beat may carry a new value for the `op` port (per-step operands, which the block samples
    with the first beat of a step): it is driven as that beat is presented."""

    def __init__(self, clk: SimHandleBase, prefix: SimHandleBase, name: str, idle: float,
                 rng: random.Random, op: SimHandleBase | None = None, has_last: bool = True):
        self.clk, self.idle, self.rng, self.op = clk, idle, rng, op
        self.tvalid = getattr(prefix, f"{name}_tvalid")
        self.tready = getattr(prefix, f"{name}_tready")
        self.tdata = getattr(prefix, f"{name}_tdata")
        self.tlast = getattr(prefix, f"{name}_tlast") if has_last else None
        self.tvalid.value = 0

    async def send(self, beats: list[tuple[int, bool]] | list[tuple[int, bool, int | None]]
                   ) -> None:
        for data, last, *op in beats:
            while self.rng.random() < self.idle:
                self.tvalid.value = 0
                await RisingEdge(self.clk)
            if op and op[0] is not None:
                assert self.op is not None, "operands given but no op port"
                self.op.value = op[0]
            self.tvalid.value = 1
            self.tdata.value = data
            if self.tlast is not None:
                self.tlast.value = int(last)
            while True:
                await ReadOnly()
                taken = self.tready.value == 1
                await RisingEdge(self.clk)
                if taken:
                    break
        self.tvalid.value = 0


# ---- one coroutine for every port of a testbench ---------------------------------------------
#
# The classes above run a coroutine each and wake on every clock. StreamLoop does their jobs
# for several ports in one coroutine (one RisingEdge and one ReadOnly per clock instead of
# about seven wake-ups), and sleeps through clocks on which no beat can cross: a beat needs
# tvalid && tready at ReadOnly, so while one of them is low and only the block can raise it,
# a value change of that signal is what to wait for. Cycle numbers come from the simulation
# time, so a beat's cycle is exact whether or not the clocks before it were watched.


AWAKE, WATCH, IDLE = "awake", "watch", "idle"   # what a port needs from StreamLoop


class Source:
    """Drives a slave port of the block like StreamDriver: before each beat a random idle
    clock with probability `idle` (repeated), then the beat held until taken."""

    def __init__(self, prefix: SimHandleBase, name: str, idle: float, rng: random.Random,
                 beats: list[tuple[int, bool]] | list[tuple[int, bool, int | None]],
                 op: SimHandleBase | None = None, has_last: bool = True):
        self.tvalid = getattr(prefix, f"{name}_tvalid")
        self.tready = getattr(prefix, f"{name}_tready")
        self.tdata = getattr(prefix, f"{name}_tdata")
        self.tlast = getattr(prefix, f"{name}_tlast") if has_last else None
        self.idle, self.rng, self.op = idle, rng, op
        self.beats: list[Beat] = []   # what crossed the bus
        self.done = Event()           # set once every beat was taken
        self._todo = iter(beats)
        self._gap = 0                 # idle clocks before the next beat is presented
        self._state = "next"          # next (draw a gap) | gap | presenting | done
        self.tvalid.value = self._valid = 0
        self.watch = self.tready   # what the block drives and a sleeping loop waits on

    def drive(self) -> None:
        """After a clock edge: move on if the beat was taken, present the next one."""
        if self._state == "next":
            self._gap = 0
            while self.rng.random() < self.idle:
                self._gap += 1
            self._state = "gap"
        if self._state != "gap":
            return
        if self._gap:
            self._gap -= 1
        elif (beat := next(self._todo, None)) is not None:
            self._present(*beat)
            return
        else:
            self._state = "done"
            self.done.set()
        if self._valid:   # writes only on a change: each one costs the simulator
            self.tvalid.value = self._valid = 0

    def _present(self, data: int, last: bool, op: int | None = None) -> None:
        if op is not None:
            assert self.op is not None, "operands given but no op port"
            self.op.value = op
        self.tvalid.value = self._valid = 1
        self.tdata.value = data
        if self.tlast is not None:
            self.tlast.value = int(last)
        self._state = "presenting"

    def settled(self, cycle: Callable[[], int]) -> str:
        """At ReadOnly: record a beat; say whether the port needs the next clock (AWAKE), a
        change of its `watch` signal (WATCH) or nothing more (IDLE)."""
        if self._state == "presenting":
            if self.tready.value != 1:
                return WATCH    # the beat is held until the block raises tready
            if self.tvalid.value == 1:
                self.beats.append(Beat(self.tdata.value.to_unsigned(), cycle(), _last(self)))
                self._state = "next"
        return IDLE if self._state == "done" else AWAKE


class Sink:
    """Takes beats from a master port of the block like ReadyDriver + StreamMonitor: `tready`
    low with probability `stall` on every clock on which tvalid is high."""

    def __init__(self, prefix: SimHandleBase, name: str, stall: float, rng: random.Random,
                 has_last: bool = True):
        self.tvalid = getattr(prefix, f"{name}_tvalid")
        self.tready = getattr(prefix, f"{name}_tready")
        self.tdata = getattr(prefix, f"{name}_tdata")
        self.tlast = getattr(prefix, f"{name}_tlast") if has_last else None
        self.stall, self.rng = stall, rng
        self.beats: list[Beat] = []
        self._ready = 0 if stall >= 1 else 1
        self.tready.value = self._ready
        self._want, self._got = 0, Event()
        self.watch = self.tvalid

    def drive(self) -> None:
        ready = 0 if self.rng.random() < self.stall else 1
        if ready != self._ready:
            self.tready.value = self._ready = ready

    def settled(self, cycle: Callable[[], int]) -> str:
        if self.tvalid.value == 1:
            if self.tready.value == 1:
                # to_unsigned() raises on X or Z: an undefined output is an error, not a 0
                self.beats.append(Beat(self.tdata.value.to_unsigned(), cycle(), _last(self)))
                if len(self.beats) >= self._want:
                    self._got.set()
            return AWAKE       # a new random tready every clock while a beat is offered
        # sleep only with tready high: a block may need it to move even with tvalid low
        return WATCH if self._ready or self.stall >= 1 else AWAKE

    def wait(self, n: int) -> Trigger:
        """Fires once n beats have been taken."""
        self._want, self._got = n, Event()
        if len(self.beats) >= n:
            self._got.set()
        return self._got.wait()


def _last(port: Source | Sink) -> bool:
    return port.tlast is not None and port.tlast.value == 1


class StreamLoop:
    """Runs Sources and Sinks on one clock in one coroutine (see above) until stop()."""

    def __init__(self, clk: SimHandleBase, ports: list[Source | Sink],
                 period_ns: float = CLOCK_NS):
        self.clk, self.ports = clk, ports
        self.period = get_sim_steps(period_ns, "ns")
        self._wake = Event()
        self._asleep = [False] * len(ports)   # per port: waiting for its `watch` to change
        self._tasks = [cocotb.start_soon(self._run())]
        # one watcher per port rather than First(): First starts tasks on every call
        self._tasks += [cocotb.start_soon(self._watch(k)) for k in range(len(ports))]

    async def _watch(self, k: int) -> None:
        change = ValueChange(self.ports[k].watch)
        while True:
            await change
            if self._asleep[k]:
                self._wake.set()

    async def _run(self) -> None:
        edge, settle = RisingEdge(self.clk), ReadOnly()
        await edge
        start = get_sim_time("step") - self.period   # the first clock is cycle 1

        def cycle() -> int:
            return (get_sim_time("step") - start) // self.period

        while True:
            for port in self.ports:
                port.drive()
            await settle
            states = [port.settled(cycle) for port in self.ports]
            if AWAKE in states:
                await edge
            else:   # no beat can cross until a watched signal changes
                self._asleep = [state == WATCH for state in states]
                self._wake.clear()
                await self._wake.wait()
                self._asleep = [False] * len(self.ports)

    def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for port in self.ports:
            if isinstance(port, Sink):
                port.tready.value = 1

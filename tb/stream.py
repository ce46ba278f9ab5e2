"""AXI4-Stream helpers for the testbenches: a random `tready` driver and a beat monitor.

Monitors sample after the rising edge once signals settle (ReadOnly) and record a beat only when
tvalid && tready, so the scoreboard sees what crossed the bus, not what a driver meant to send.
"""

from __future__ import annotations

import logging
import random
from dataclasses import dataclass

import cocotb
from cocotb.handle import SimHandleBase
from cocotb.triggers import Event, ReadOnly, RisingEdge


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


class StreamSinks:
    """Several AXI4-Stream outputs read by ONE coroutine per clock: each clock it draws every
    `tready` (low with probability `stall`), then samples after the edge settles and records the
    beats that crossed (tvalid && tready) in `beats[name]`. One coroutine instead of a monitor and
    a ready driver per stream: cocotb's per-clock wake-ups set the pace of long runs.
    `arrived(name, count)` waits (in simulated time, without polling) until `count` beats of
    `name` have crossed."""

    def __init__(self, clk: SimHandleBase, prefix: SimHandleBase, names: list[str],
                 has_last: dict[str, bool], stall: float, rng: random.Random):
        self.clk, self.stall, self.rng = clk, stall, rng
        self.ports = [(name, getattr(prefix, f"{name}_tvalid"), getattr(prefix, f"{name}_tready"),
                       getattr(prefix, f"{name}_tdata"),
                       getattr(prefix, f"{name}_tlast") if has_last.get(name) else None)
                      for name in names]
        self.beats: dict[str, list[Beat]] = {name: [] for name in names}
        self.cycles = 0
        self._events = {name: Event() for name in names}
        self._ready = [1] * len(names)
        for _, _, tready, _, _ in self.ports:
            tready.value = 1
        self._task = cocotb.start_soon(self._run())

    async def _run(self) -> None:
        edge, settle = RisingEdge(self.clk), ReadOnly()
        while True:
            await edge
            if self.stall:
                for i, (_, _, tready, _, _) in enumerate(self.ports):
                    ready = 0 if self.rng.random() < self.stall else 1
                    if ready != self._ready[i]:
                        tready.value = ready
                        self._ready[i] = ready
            await settle
            self.cycles += 1
            for i, (name, tvalid, _, tdata, tlast) in enumerate(self.ports):
                if self._ready[i] and tvalid.value == 1:
                    last = bool(tlast.value) if tlast is not None else False
                    # to_unsigned() raises on X or Z: an undefined output is an error, not a 0
                    self.beats[name].append(Beat(tdata.value.to_unsigned(), self.cycles, last))
                    self._events[name].set()

    async def arrived(self, name: str, count: int) -> None:
        while len(self.beats[name]) < count:
            self._events[name].clear()
            await self._events[name].wait()

    def stop(self) -> None:
        self._task.cancel()
        for _, _, tready, _, _ in self.ports:
            tready.value = 1

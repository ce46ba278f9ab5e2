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
from cocotb.triggers import ReadOnly, RisingEdge


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

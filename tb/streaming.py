"""The test every pipelined stream block gets: random beats through the block with random
stalls on both sides, every output field checked bit-exactly against the block's model (fed
from the input beats seen on the bus), tlast carried, and the no-stall throughput and latency."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, RisingEdge

from gpf.tb.harness import Bench, start
from gpf.tb.scoreboard import Field, Scoreboard, pack, unpack
from gpf.tb.stream import ReadyDriver, StreamDriver, StreamMonitor

Model = Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]


@dataclass
class StreamBlock:
    """A block with one input and one output stream, `lanes` lanes of fields each."""

    name: str
    fields_in: list[Field]
    fields_out: list[Field]
    lanes: int
    latency: int
    model: Model          # raw input fields (beats, lanes) -> raw output fields


def idle_inputs(dut: SimHandleBase) -> None:
    dut.s_axis_tvalid.value = 0
    dut.s_axis_tdata.value = 0
    dut.s_axis_tlast.value = 0
    dut.m_axis_tready.value = 1


async def run_stream(dut: SimHandleBase, block: StreamBlock, b: Bench,
                     inputs: dict[str, np.ndarray], lasts: list[bool], stall_in: float,
                     stall_out: float, tag: str, expect_mismatch: bool = False
                     ) -> tuple[Scoreboard, StreamMonitor, StreamMonitor]:
    """Send every beat, collect as many outputs (failing, not hanging, if they stop), score."""
    mon_in = StreamMonitor(dut.clk, dut, "s_axis", has_last=True)
    mon_out = StreamMonitor(dut.clk, dut, "m_axis", has_last=True)
    ready = ReadyDriver(dut.clk, dut.m_axis_tready, stall_out, b.rng(f"{tag}-ready"))
    driver = StreamDriver(dut.clk, dut, "s_axis", stall_in, b.rng(f"{tag}-valid"))
    n = len(lasts)
    await RisingEdge(dut.clk)  # the monitors sample from the next clock on: start there
    await driver.send(list(zip(pack(block.fields_in, inputs), lasts, strict=True)))
    limit, clocks = 50 * n + 100 + 10 * block.latency, 0
    while len(mon_out.beats) < n:
        await RisingEdge(dut.clk)
        clocks += 1
        assert clocks < limit, f"{block.name}: {len(mon_out.beats)} of {n} beats came out"
    for _ in range(2 * block.latency + 2):   # nothing more may come out
        await RisingEdge(dut.clk)
    ready.stop()
    mon_in.stop()
    mon_out.stop()
    assert len(mon_out.beats) == n, f"{block.name}: {len(mon_out.beats)} beats out for {n} in"
    seen = unpack([beat.data for beat in mon_in.beats], block.fields_in, block.lanes)
    expected = block.model(seen)
    sb = Scoreboard(block.name, block.fields_out, expect_mismatch=expect_mismatch)
    sb.compare(expected, unpack([beat.data for beat in mon_out.beats], block.fields_out,
                                block.lanes))
    lasts_in = [beat.last for beat in mon_in.beats]
    lasts_out = [beat.last for beat in mon_out.beats]
    assert lasts_out == lasts_in, f"{block.name}: tlast not carried with its beat"
    return sb, mon_in, mon_out


def random_lasts(rng, n: int, every: int = 64) -> list[bool]:
    lasts = [rng.random() < 1 / every for _ in range(n)]
    lasts[-1] = True
    return lasts


def log_uniform(rng: np.random.Generator, width: int, shape: tuple[int, ...]) -> np.ndarray:
    """Unsigned `width`-bit values spread over every magnitude: the bit length uniform in
    0 .. width (0 gives the value 0), then the value uniform among those of that length."""
    bits = rng.integers(0, width + 1, size=shape)
    hi = np.left_shift(np.int64(1), bits)
    return rng.integers(hi >> 1, hi)


Inputs = Callable[[int, str], dict[str, np.ndarray]]   # (beats, tag) -> raw input fields


def random_beat_count(b: Bench, stalls: tuple[float, float]) -> int:
    """The main stall shape gets the full count (10,000; 100,000 at TEST_LEVEL=long)."""
    return (100_000 if b.long else 10_000) if stalls == (0.3, 0.3) else 2_000


async def check_random_beats(dut: SimHandleBase, block: StreamBlock, b: Bench,
                             inputs: Inputs, stalls: tuple[float, float]) -> None:
    """Random beats with input gaps and output stalls: every field bit-exact, tlast carried."""
    n = random_beat_count(b, stalls)
    tag = f"{block.name}-{stalls}"
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, block, b, inputs(n, tag), random_lasts(b.rng(tag), n),
                                *stalls, tag)
    dut._log.info("stalls in/out %s: %s", stalls, sb.summary())
    sb.assert_clean()


async def check_latency_and_throughput(dut: SimHandleBase, block: StreamBlock, b: Bench,
                                       inputs: Inputs, n: int = 500) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock,
    so n beats take n + LATENCY clocks."""
    idle_inputs(dut)
    await start(dut)
    await ClockCycles(dut.clk, 3)
    tag = f"{block.name}-tp"
    sb, mon_in, mon_out = await run_stream(dut, block, b, inputs(n, tag),
                                           [False] * (n - 1) + [True], 0.0, 0.0, tag)
    sb.assert_clean()
    first_in, first_out = mon_in.beats[0].cycle, mon_out.beats[0].cycle
    assert first_out - first_in == block.latency, (
        f"latency {first_out - first_in}, manifest says {block.latency}")
    span = mon_out.beats[-1].cycle - first_in + 1
    assert span == n + block.latency, (
        f"{n} beats took {span} clocks, expected {n + block.latency}")

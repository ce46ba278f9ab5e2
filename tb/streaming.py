"""The test every stream block gets: random beats through the block with random stalls on both
sides, every output field checked bit-exactly against the block's model (fed from the input
beats seen on the bus), tlast carried, and the no-stall throughput and latency.

A step is the beats up to and including one with tlast. Blocks with per-step operands (mu and L,
a measurement, ...) take them on an `op` port, sampled with the first beat of each step. A
reducing block (moments) answers a whole step with one beat."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from cocotb.handle import SimHandleBase
from cocotb.triggers import ClockCycles, Combine, First, Timer

from gpf.tb import coverage
from gpf.tb.harness import CLOCK_NS, Bench, start
from gpf.tb.scoreboard import Field, Scoreboard, pack, unpack
from gpf.tb.stream import Sink, Source, StreamLoop

# raw input fields (beats, lanes) -> raw output fields (output beats, lanes). `seen` also holds
# STEP, each input beat's step number (beats,), and every operand field per input beat (beats,).
Model = Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]
STEP = "_step"


@dataclass
class StreamBlock:
    """A block with one input and one output stream, `lanes` lanes of fields each."""

    name: str
    fields_in: list[Field]
    fields_out: list[Field]
    lanes: int
    latency: int          # clocks from an input beat (reducing: a step's last) to its output
    model: Model
    fields_op: list[Field] = field(default_factory=list)   # per-step operands on `op`
    reduces: bool = False  # one output beat (tlast set, one lane) per input step
    interval: int = 1      # clocks between input beats at full rate (serial blocks: more)
    beat_in: list[Field] = field(default_factory=list)    # a beat's own fields, after its lanes
    beat_out: list[Field] = field(default_factory=list)


def idle_inputs(dut: SimHandleBase) -> None:
    dut.s_axis_tvalid.value = 0
    dut.s_axis_tdata.value = 0
    dut.s_axis_tlast.value = 0
    dut.m_axis_tready.value = 1


def step_numbers(lasts: list[bool]) -> np.ndarray:
    """The step of every beat: a step ends with a beat whose tlast is set."""
    ends = np.asarray(lasts, dtype=np.int64)
    return np.concatenate(([0], np.cumsum(ends)[:-1])).astype(np.int64)


def with_operands(block: StreamBlock, seen: dict[str, np.ndarray], lasts: list[bool],
                  ops: dict[str, np.ndarray] | None) -> dict[str, np.ndarray]:
    """`seen` plus STEP and each beat's operands (the values of its step)."""
    steps = step_numbers(lasts)
    out = dict(seen, **{STEP: steps})
    for f in block.fields_op:
        out[f.name] = np.asarray(ops[f.name], dtype=np.int64)[steps]
    return out


def _op_words(block: StreamBlock, ops: dict[str, np.ndarray] | None, lasts: list[bool]
              ) -> list[int | None]:
    """The `op` word to drive with each beat: a step's operands with its first beat, their
    bitwise complement from its second (the block samples op with a step's first beat and must
    hold it: a block that read op later would see the complement); None: unchanged."""
    if not block.fields_op:
        return [None] * len(lasts)
    words = pack(block.fields_op, {k: np.asarray(v)[:, None] for k, v in ops.items()})
    mask = (1 << sum(f.fmt.width for f in block.fields_op)) - 1
    firsts = [True] + list(lasts[:-1])
    seconds = [False] + firsts[:-1]
    return [words[s] if first else (~words[s] & mask if second else None)
            for s, first, second in zip(step_numbers(lasts), firsts, seconds, strict=True)]


async def run_stream(dut: SimHandleBase, block: StreamBlock, b: Bench,
                     inputs: dict[str, np.ndarray], lasts: list[bool], stall_in: float,
                     stall_out: float, tag: str, expect_mismatch: bool = False,
                     ops: dict[str, np.ndarray] | None = None
                     ) -> tuple[Scoreboard, Source, Sink]:
    """Send every beat (and each step's operands, (steps,) per operand field), collect as many
    outputs as due (failing, not hanging, if they stop), score."""
    n = sum(lasts) if block.reduces else len(lasts)
    beats = list(zip(pack(block.fields_in, inputs, block.beat_in), lasts,
                     _op_words(block, ops, lasts), strict=True))
    mon_in = Source(dut, "s_axis", stall_in, b.rng(f"{tag}-valid"), beats,
                    op=dut.op if block.fields_op else None)
    mon_out = Sink(dut, "m_axis", stall_out, b.rng(f"{tag}-ready"))
    loop = StreamLoop(dut.clk, [mon_in, mon_out])
    limit = 50 * (len(lasts) + n) * block.interval + 100 + 10 * block.latency
    timeout = Timer(limit * CLOCK_NS, "ns")
    if await First(Combine(mon_in.done.wait(), mon_out.wait(n)), timeout) is timeout:
        raise AssertionError(f"{block.name}: {len(mon_in.beats)} of {len(lasts)} beats went "
                             f"in, {len(mon_out.beats)} of {n} came out")
    await ClockCycles(dut.clk, 2 * block.latency + 2)   # nothing more may come out
    loop.stop()
    assert len(mon_out.beats) == n, f"{block.name}: {len(mon_out.beats)} beats out for {n} in"
    seen = unpack([beat.data for beat in mon_in.beats], block.fields_in, block.lanes,
                  block.beat_in)
    lasts_in = [beat.last for beat in mon_in.beats]
    expected = block.model(with_operands(block, seen, lasts_in, ops))
    sb = Scoreboard(block.name, block.fields_out + block.beat_out,
                    expect_mismatch=expect_mismatch)
    got = unpack([beat.data for beat in mon_out.beats], block.fields_out,
                 1 if block.reduces else block.lanes, block.beat_out)
    sb.compare(expected, got)
    if not expect_mismatch:
        coverage.sample_block(block, b.cfg.app, b.cfg.lanes, got, lasts_in, mon_in, mon_out)
    lasts_out = [beat.last for beat in mon_out.beats]
    if block.reduces:
        assert all(lasts_out), f"{block.name}: a step's result beat without tlast"
    else:
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
Operands = Callable[[int, str], dict[str, np.ndarray]]  # (steps, tag) -> (steps,) per field


def random_beat_count(b: Bench, stalls: tuple[float, float]) -> int:
    """The main stall shape gets the full count (10,000; 100,000 at TEST_LEVEL=long; 2,000 at
    TEST_LEVEL=short; 200 at quick), the others 2,000 (400 short, 100 quick)."""
    if stalls != (0.3, 0.3):
        return 100 if b.quick else 400 if b.short else 2_000
    return 100_000 if b.long else 200 if b.quick else 2_000 if b.short else 10_000


async def check_random_beats(dut: SimHandleBase, block: StreamBlock, b: Bench,
                             inputs: Inputs, stalls: tuple[float, float],
                             operands: Operands | None = None, every: int = 64) -> None:
    """Random beats with input gaps and output stalls (steps of about `every` beats, each with
    its own random operands): every field bit-exact, tlast carried."""
    n = random_beat_count(b, stalls)
    tag = f"{block.name}-{stalls}"
    lasts = random_lasts(b.rng(tag), n, every)
    ops = operands(sum(lasts), tag) if operands else None
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, block, b, inputs(n, tag), lasts, *stalls, tag, ops=ops)
    dut._log.info("stalls in/out %s: %s", stalls, sb.summary())
    sb.assert_clean()


async def check_latency_and_throughput(dut: SimHandleBase, block: StreamBlock, b: Bench,
                                       inputs: Inputs, n: int = 500,
                                       operands: Operands | None = None) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat (reducing: after
    the step's last), a new input beat every INTERVAL clocks, so n beats (one step) take
    (n - 1) INTERVAL + 1 + LATENCY clocks: after reset, and again for a step that follows
    another after 1, 2 and 3 idle clocks (a block's state after a step, its beats' parity)."""
    idle_inputs(dut)
    await start(dut)
    await ClockCycles(dut.clk, 3)
    lasts = [True] * n if block.interval > 1 else [False] * (n - 1) + [True]
    for idle in (None, 1, 2, 3):   # None: the step after reset
        if idle is not None:
            await ClockCycles(dut.clk, idle)
        tag = f"{block.name}-tp" + (f"-after{idle}" if idle is not None else "")
        ops = operands(sum(lasts), tag) if operands else None
        sb, mon_in, mon_out = await run_stream(dut, block, b, inputs(n, tag), lasts, 0.0, 0.0,
                                               tag, ops=ops)
        sb.assert_clean()
        first_in = mon_in.beats[0].cycle
        answered = mon_in.beats[-1 if block.reduces else 0].cycle
        latency = mon_out.beats[0].cycle - answered
        after = "" if idle is None else f" (a step {idle} clocks after another's end)"
        assert latency == block.latency, \
            f"latency {latency}, manifest says {block.latency}{after}"
        span = mon_out.beats[-1].cycle - first_in + 1
        due = (n - 1) * block.interval + 1 + block.latency
        assert span == due, f"{n} beats took {span} clocks, expected {due}{after}"


async def check_corrupted_model_is_caught(dut: SimHandleBase, block: StreamBlock, b: Bench,
                                          inputs: Inputs, operands: Operands | None = None,
                                          n: int = 1_000, every: int = 50) -> None:
    """`block` carries a deliberately wrong model: the scoreboard must report a mismatch (the
    test that shows the scoreboard can fail)."""
    lasts = ([False] * (every - 1) + [True]) * (n // every)
    ops = operands(sum(lasts), "bad") if operands else None
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, block, b, inputs(len(lasts), "bad"), lasts, 0.2, 0.2,
                                f"{block.name}-bad", expect_mismatch=True, ops=ops)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)

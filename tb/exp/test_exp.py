"""cocotb testbench of `exp` (w = 2^-t): every lane of every beat against Exp2Neg."""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.fixed import Format
from gpf.model.formats import datapath
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field
from gpf.tb.streaming import (
    Inputs,
    StreamBlock,
    check_latency_and_throughput,
    check_random_beats,
    idle_inputs,
    run_stream,
)


def block(b: Bench, model=None) -> StreamBlock:
    dp = datapath(b.cfg)
    exp2 = model or dp.exp2
    return StreamBlock(
        "exp", [Field("t", dp.t)], [Field("w", dp.weight)], b.cfg.lanes,
        b.manifest["modules"]["exp"]["latency"],
        lambda seen: {"w": np.asarray(exp2(seen["t"]), dtype=np.int64)})


def random_t(b: Bench, fmt: Format, n: int, tag: str) -> np.ndarray:
    """Half uniform over the whole range, half where weights live (t < 24: w > 2^-24)."""
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    wide = rng.integers(0, fmt.max_raw + 1, size=(n, b.cfg.lanes))
    near = rng.integers(0, min(fmt.max_raw, 24 << fmt.frac_bits) + 1, size=(n, b.cfg.lanes))
    return np.where(rng.random((n, b.cfg.lanes)) < 0.5, wide, near)


def random_inputs(b: Bench, blk: StreamBlock) -> Inputs:
    """The random stimulus of the random-beats and throughput tests."""

    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        return {"t": random_t(b, blk.fields_in[0].fmt, n, tag)}

    return inputs


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random t with random input gaps and output stalls: every w bit-exact, tlast carried."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b, blk), stalls)


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """t = 0 (w = 1 exactly), every integer n, the underflow edge F+1 .. F+2, the maximum."""
    b = bench()
    blk = block(b)
    fmt, f = blk.fields_in[0].fmt, datapath(b.cfg).weight.frac_bits
    one = 1 << fmt.frac_bits
    values = [0, 1, one - 1, one, fmt.max_raw, fmt.max_raw - 1]
    values += [n * one + d for n in range(fmt.max_raw // one + 1) for d in (0, 1, one // 2)]
    values += list(range((f + 1) * one - 3, (f + 2) * one + 3))
    values = [v for v in values if 0 <= v <= fmt.max_raw]
    t = np.array(values, dtype=np.int64)[:, None].repeat(b.cfg.lanes, axis=1)
    idle_inputs(dut)
    await start(dut)
    sb, _, out = await run_stream(dut, blk, b, {"t": t}, [False] * (len(t) - 1) + [True],
                                  0.2, 0.2, "exp-corners")
    sb.assert_clean()
    assert out.beats[0].data & ((1 << (f + 1)) - 1) == 1 << f, "2^-0 must be exactly 1"


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    blk = block(b)
    await check_latency_and_throughput(dut, blk, b, random_inputs(b, blk))


class OffByOneSlope:
    """Deliberately wrong model: one interpolation step too steep in every segment."""

    def __init__(self, exp2):
        self.exp2 = exp2

    def __call__(self, t):
        w = np.asarray(self.exp2(t), dtype=np.int64)
        return np.where((np.asarray(t) % 7) == 3, w + 1, w)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    b = bench()
    blk = block(b, OffByOneSlope(datapath(b.cfg).exp2))
    n = 1_000
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, {"t": random_t(b, blk.fields_in[0].fmt, n, "bad")},
                                [False] * (n - 1) + [True], 0.2, 0.2, "exp-bad",
                                expect_mismatch=True)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)

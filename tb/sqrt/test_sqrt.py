"""cocotb testbench of `sqrt` (L = round(sqrt(d)), saturated): every lane of every beat
against sqrt_round and saturate, the model of the Cholesky's square root."""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.fixed import Format, saturate
from gpf.model.formats import datapath
from gpf.model.primitives import sqrt_round
from gpf.rtl.generate import sqrt_context
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field, unpack
from gpf.tb.streaming import (
    Inputs,
    StreamBlock,
    check_latency_and_throughput,
    check_random_beats,
    idle_inputs,
    log_uniform,
    run_stream,
)


def formats(b: Bench) -> tuple[Format, Format]:
    """d and L formats as generated, checked against the config's datapath.

    From the generator's context (what the manifest records), not from the manifest file:
    build/<config>/rtl/manifest.json lists only the modules of the latest `generate` call, so
    a concurrent run of another block on the same config rewrites it under this one."""
    k = sqrt_context(b.cfg)
    d_fmt, l_fmt = Format.parse(k["d_fmt"]), Format.parse(k["l_fmt"])
    dp = datapath(b.cfg)
    chol = dp.chol[0]
    assert d_fmt.frac_bits == dp.cov_frac(0, 0) == 2 * chol.frac_bits, (d_fmt, chol)
    assert d_fmt.width == 2 * chol.width and not d_fmt.signed, d_fmt
    assert l_fmt.frac_bits == chol.frac_bits and l_fmt.max_raw == chol.max_raw, (l_fmt, chol)
    return d_fmt, l_fmt


def sqrt_model(d_fmt: Format, l_fmt: Format):
    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        root = sqrt_round(seen["d"], d_fmt.frac_bits, l_fmt.frac_bits)
        ljj, sat = saturate(root, l_fmt)
        return {"l": np.asarray(ljj, dtype=np.int64), "sat": np.asarray(sat, dtype=np.int64)}
    return model


def block(b: Bench, model=None) -> StreamBlock:
    d_fmt, l_fmt = formats(b)
    return StreamBlock(
        "sqrt", [Field("d", d_fmt)], [Field("l", l_fmt), Field("sat", Format(False, 1, 0))],
        b.cfg.lanes, sqrt_context(b.cfg)["latency"],
        model or sqrt_model(d_fmt, l_fmt))


def random_d(b: Bench, n: int, tag: str) -> np.ndarray:
    """A third uniform over all of d (mostly saturating), a third uniform below saturation
    (where pivots live), a third log-uniform (every magnitude, down to 0)."""
    d_fmt, l_fmt = formats(b)
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    shape = (n, b.cfg.lanes)
    wide = rng.integers(0, d_fmt.max_raw + 1, size=shape)
    fits = rng.integers(0, (l_fmt.max_raw + 1) ** 2, size=shape)
    spread = log_uniform(rng, d_fmt.width, shape)
    return np.choose(rng.integers(0, 3, size=shape), [wide, fits, spread])


def corner_d(b: Bench) -> list[int]:
    """0, 1, the maximum; perfect squares m^2 and m^2 - 1, m^2 + 1, m^2 + m (rounds down to m),
    m^2 + m + 1 (rounds up to m + 1) for small m, m near powers of two, random m, and m at the
    saturation edge; powers of two and their neighbours."""
    d_fmt, l_fmt = formats(b)
    rng = b.rng("sqrt-corners")
    lmax = l_fmt.max_raw
    ms = set(range(64)) | {(1 << k) + e for k in range(l_fmt.width + 1) for e in (-1, 0, 1)}
    ms |= {lmax + e for e in range(-3, 3)} | {rng.randrange(lmax + 1) for _ in range(64)}
    values = {0, 1, 2, 3, d_fmt.max_raw, d_fmt.max_raw - 1}
    for m in ms:
        values |= {m * m - 1, m * m, m * m + 1, m * m + m, m * m + m + 1}
    values |= {(1 << k) + e for k in range(d_fmt.width + 1) for e in (-1, 0, 1)}
    return sorted(v for v in values if 0 <= v <= d_fmt.max_raw)


def random_inputs(b: Bench, blk: StreamBlock) -> Inputs:
    """The random stimulus of the random-beats and throughput tests."""

    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        return {"d": random_d(b, n, tag)}

    return inputs


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random d with random input gaps and output stalls: every L and sat bit-exact, tlast
    carried."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b, blk), stalls)


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """Directed corners (corner_d), lane i shifted by 7 i so the lanes see different values."""
    b = bench()
    blk = block(b)
    values = np.array(corner_d(b), dtype=np.int64)
    d = np.stack([np.roll(values, 7 * lane) for lane in range(b.cfg.lanes)], axis=1)
    idle_inputs(dut)
    await start(dut)
    sb, _, out = await run_stream(dut, blk, b, {"d": d}, [False] * (len(d) - 1) + [True],
                                  0.2, 0.2, "sqrt-corners")
    dut._log.info("%d corner values: %s", len(values), sb.summary())
    sb.assert_clean()
    got = unpack([beat.data for beat in out.beats], blk.fields_out, b.cfg.lanes)
    lmax = blk.fields_out[0].fmt.max_raw
    assert (got["l"][0, 0], got["sat"][0, 0]) == (0, 0), "sqrt(0) must be 0, not saturated"
    assert (got["l"][-1, 0], got["sat"][-1, 0]) == (lmax, 1), "the maximum d must saturate"


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    blk = block(b)
    await check_latency_and_throughput(dut, blk, b, random_inputs(b, blk))


def off_by_one(d_fmt: Format, l_fmt: Format):
    """Deliberately wrong model: L's LSB flipped wherever d mod 7 == 3."""
    right = sqrt_model(d_fmt, l_fmt)

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = right(seen)
        return {**out, "l": np.where(np.asarray(seen["d"]) % 7 == 3, out["l"] ^ 1, out["l"])}
    return model


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    b = bench()
    blk = block(b, off_by_one(*formats(b)))
    n = 1_000
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, {"d": random_d(b, n, "bad")},
                                [False] * (n - 1) + [True], 0.2, 0.2, "sqrt-bad",
                                expect_mismatch=True)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)

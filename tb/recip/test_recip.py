"""cocotb testbench of `recip` (inv = round(2^(2F+G) / L)): every lane of every beat against
recip (div_round); L = 0 gives all ones. (The Cholesky once used this 1/L_jj; it now divides
each row directly.)"""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.fixed import Format
from gpf.model.formats import INV_GUARD, datapath
from gpf.model.primitives import recip
from gpf.rtl.generate import recip_context
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


def formats(b: Bench) -> tuple[Format, Format, int]:
    """L and 1/L formats and the shift 2F + G as generated, checked against the config's
    datapath. From the generator's context, not the manifest file (see tb/sqrt/test_sqrt.py)."""
    k = recip_context(b.cfg)
    l_fmt, inv_fmt, shift = Format.parse(k["l_fmt"]), Format.parse(k["inv_fmt"]), k["shift"]
    chol = datapath(b.cfg).chol[0]
    f = chol.frac_bits
    assert shift == 2 * f + INV_GUARD, shift
    assert l_fmt.frac_bits == f and l_fmt.max_raw == chol.max_raw and not l_fmt.signed, l_fmt
    assert inv_fmt.frac_bits == f + INV_GUARD and not inv_fmt.signed, inv_fmt
    assert int(recip(1, shift)) == 1 << shift <= inv_fmt.max_raw, inv_fmt  # L = 1 fits
    return l_fmt, inv_fmt, shift


def recip_model(inv_fmt: Format, shift: int, rounded: bool = True):
    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        den = np.asarray(seen["l"], dtype=np.int64)
        safe = np.maximum(den, 1)
        inv = np.asarray(recip(safe, shift) if rounded else (1 << shift) // safe, dtype=np.int64)
        return {"inv": np.where(den == 0, inv_fmt.max_raw, inv)}  # L = 0: all ones
    return model


def block(b: Bench, model=None) -> StreamBlock:
    l_fmt, inv_fmt, shift = formats(b)
    return StreamBlock(
        "recip", [Field("l", l_fmt)], [Field("inv", inv_fmt)], b.cfg.lanes,
        recip_context(b.cfg)["latency"], model or recip_model(inv_fmt, shift))


def random_l(b: Bench, n: int, tag: str) -> np.ndarray:
    """Half uniform over all of L, half log-uniform (every magnitude; 0 now and then)."""
    l_fmt = formats(b)[0]
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    shape = (n, b.cfg.lanes)
    wide = rng.integers(0, l_fmt.max_raw + 1, size=shape)
    spread = log_uniform(rng, l_fmt.width, shape)
    return np.where(rng.random(shape) < 0.5, wide, spread)


def near_ties(l_fmt: Format, shift: int, count: int = 64) -> list[int]:
    """The L whose 2^shift / L is nearest to a rounding tie (fraction 1/2).

    No L in range gives an exact tie: 2^shift / L = m + 1/2 needs 2^(shift+1) = L (2m + 1),
    so L = 2^(shift+1), far above L's maximum. The nearest have |2 (2^shift mod L) - L| = 1."""
    den = np.arange(1, l_fmt.max_raw + 1, dtype=np.int64)
    dist = np.abs(2 * (np.int64(1 << shift) % den) - den)
    return [int(v) for v in den[np.argsort(dist, kind="stable")[:count]]]


def corner_l(b: Bench) -> list[int]:
    """0 (all ones), 1 (2^shift), every L up to 1024, the maximum, powers of two and their
    neighbours, the L nearest to rounding ties, and random L."""
    l_fmt, _, shift = formats(b)
    rng = b.rng("recip-corners")
    values = set(range(1025)) | {l_fmt.max_raw - e for e in range(4)}
    values |= {(1 << k) + e for k in range(l_fmt.width + 1) for e in (-1, 0, 1)}
    values |= set(near_ties(l_fmt, shift)) | {rng.randrange(l_fmt.max_raw + 1) for _ in range(64)}
    return sorted(v for v in values if 0 <= v <= l_fmt.max_raw)


def random_inputs(b: Bench, blk: StreamBlock) -> Inputs:
    """The random stimulus of the random-beats and throughput tests."""

    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        return {"l": random_l(b, n, tag)}

    return inputs


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random L with random input gaps and output stalls: every 1/L bit-exact, tlast carried."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b, blk), stalls)


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """Directed corners (corner_l), lane i shifted by 7 i so the lanes see different values."""
    b = bench()
    blk = block(b)
    _, inv_fmt, shift = formats(b)
    values = np.array(corner_l(b), dtype=np.int64)
    ls = np.stack([np.roll(values, 7 * lane) for lane in range(b.cfg.lanes)], axis=1)
    idle_inputs(dut)
    await start(dut)
    sb, _, out = await run_stream(dut, blk, b, {"l": ls}, [False] * (len(ls) - 1) + [True],
                                  0.2, 0.2, "recip-corners")
    dut._log.info("%d corner values: %s", len(values), sb.summary())
    sb.assert_clean()
    got = unpack([beat.data for beat in out.beats], blk.fields_out, b.cfg.lanes)["inv"][:, 0]
    assert got[0] == inv_fmt.max_raw, "1/0 must be all ones"
    assert got[1] == 1 << shift, "1/1 must be exactly 2^shift"


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    blk = block(b)
    await check_latency_and_throughput(dut, blk, b, random_inputs(b, blk))


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """Deliberately wrong model: truncating division instead of rounding."""
    b = bench()
    _, inv_fmt, shift = formats(b)
    blk = block(b, recip_model(inv_fmt, shift, rounded=False))
    n = 1_000
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, {"l": random_l(b, n, "bad")},
                                [False] * (n - 1) + [True], 0.2, 0.2, "recip-bad",
                                expect_mismatch=True)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)

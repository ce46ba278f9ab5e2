"""cocotb testbench of `sigma_predict` (the predicted covariance F Sigma F^T + Q, one matrix per
beat): every entry and the SAT flag of every beat against gpf.model.blocks.predicted_sigma. The
matrices are the Cholesky testbench's (realistic, any scale, singular, not positive definite,
zero, huge, at the floors) and its corners (every entry at a format's end)."""

from __future__ import annotations

import dataclasses

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import Flag, predicted_sigma
from gpf.model.fixed import Format
from gpf.model.formats import Const
from gpf.rtl.generate import sigma_predict_context
from gpf.tb.cholesky.test_cholesky import (
    check_wrong_model_caught,
    corner_sigmas,
    random_inputs,
    run_matrices,
)
from gpf.tb.harness import Bench, bench
from gpf.tb.scoreboard import Field, unpack
from gpf.tb.streaming import StreamBlock, check_latency_and_throughput, check_random_beats

FLAGS = Format.parse("u3.0")


def predict_model(b: Bench, dp=None):
    dp, pairs = dp or b.dp, b.pairs

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        sigma = np.stack([seen[f"s{i}{j}"][:, 0] for i, j in pairs], axis=1)
        out, flags = predicted_sigma(dp, sigma, pairs)
        res = {f"p{i}{j}": out[:, q, None] for q, (i, j) in enumerate(pairs)}
        res["flags"] = flags[:, None]
        return res

    return model


def block(b: Bench, model=None) -> StreamBlock:
    dp, pairs = b.dp, b.pairs
    k = sigma_predict_context(b.cfg)
    assert b.manifest["modules"]["sigma_predict"]["latency"] == k["latency"]
    fields_in = [Field(f"s{i}{j}", dp.sigma(i, j)) for i, j in pairs]
    fields_out = [Field(f"p{i}{j}", dp.sigma(i, j)) for i, j in pairs] + [Field("flags", FLAGS)]
    assert sum(f.fmt.width for f in fields_out) == k["out_width"]
    return StreamBlock("sigma_predict", fields_in, fields_out, 1, k["latency"],
                       model or predict_model(b), interval=k["interval"])


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random matrices (one per beat) with random input gaps and output stalls: every entry
    and the flags bit-exact."""
    b = bench()
    await check_random_beats(dut, block(b), b, random_inputs(b), stalls, every=1)


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """The Cholesky's corner matrices (every entry at a format's end among them): SAT must
    really happen, and clean results too."""
    b = bench()
    blk = block(b)
    mats = corner_sigmas(b)
    sb, _, out = await run_matrices(dut, blk, b, mats, 0.2, "sigma_predict-corners")
    dut._log.info("%d corner matrices: %s", len(mats), sb.summary())
    sb.assert_clean()
    flags = unpack([beat.data for beat in out.beats], blk.fields_out, 1)["flags"][:, 0]
    assert np.any(flags & Flag.SAT), "no corner saturated"
    assert np.any(flags == 0), "no corner was clean"


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the result LATENCY clocks after its beat, a new matrix every INTERVAL."""
    b = bench()
    await check_latency_and_throughput(dut, block(b), b, random_inputs(b), n=100)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """Deliberately wrong model: bot's T one LSB off, uav's velocity noise q_v doubled (one LSB
    of it is a thousandth of Sigma's)."""
    b = bench()
    dp = b.dp
    name = "T" if dp.app == "bot" else "q_v"
    c = dp.consts[name]
    raw = c.raw + 1 if dp.app == "bot" else 2 * c.raw
    bad = dataclasses.replace(dp, consts={**dp.consts, name: Const(c.value, raw, c.frac)})
    await check_wrong_model_caught(dut, block(b, predict_model(b, bad)), b, "sigma_predict-bad")

"""cocotb testbench of `propagate_bot` (p' = p + T v + a e, v' = v + b e per axis, rounded
once per component and saturated): every lane of every beat against
model.blocks.propagate_bot."""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import Flag, propagate_bot
from gpf.model.fixed import Format
from gpf.model.formats import Datapath, datapath
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field, unpack
from gpf.tb.streaming import (
    Inputs,
    StreamBlock,
    check_corrupted_model_is_caught,
    check_latency_and_throughput,
    check_random_beats,
    idle_inputs,
    run_stream,
)

SAT = Format(False, 1, 0)


def propagate_model(dp: Datapath):
    """propagate_bot over every beat and lane; sat per particle."""

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        beats, lanes = seen["x0"].shape
        x = np.stack([seen[f"x{i}"] for i in range(4)], axis=-1).reshape(-1, 4)
        e = np.stack([seen[f"e{j}"] for j in range(2)], axis=-1).reshape(-1, 2)
        out, flags = propagate_bot(dp, x, e, per_particle=True)
        sat = (flags & Flag.SAT != 0).astype(np.int64)
        out = out.reshape(beats, lanes, 4)
        return {**{f"x{i}": out[:, :, i] for i in range(4)}, "sat": sat.reshape(beats, lanes)}

    return model


def block(b: Bench, model=None) -> StreamBlock:
    dp = datapath(b.cfg)
    ins = [Field(f"x{i}", dp.x[i]) for i in range(4)] + [Field(f"e{j}", dp.noise)
                                                          for j in range(2)]
    outs = [Field(f"x{i}", dp.x[i]) for i in range(4)] + [Field("sat", SAT)]
    return StreamBlock("propagate_bot", ins, outs, b.cfg.lanes,
                       b.manifest["modules"]["propagate_bot"]["latency"],
                       model or propagate_model(dp))


def random_beats(b: Bench, n: int, tag: str) -> dict[str, np.ndarray]:
    """Half realistic (positions within half the range, speeds within 1/16 of it, Gaussian
    draws), half uniform over the whole formats (p + T v often saturates)."""
    dp = datapath(b.cfg)
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    shape = (n, b.cfg.lanes)
    real = rng.random(shape) < 0.5
    out = {}
    for i, fmt in enumerate(dp.x):
        div = 2 if i % 2 == 0 else 16
        near = rng.integers(fmt.min_raw // div, fmt.max_raw // div + 1, size=shape)
        wide = rng.integers(fmt.min_raw, fmt.max_raw + 1, size=shape)
        out[f"x{i}"] = np.where(real, near, wide)
    noise = dp.noise
    for j in range(2):
        draws = np.clip(np.round(rng.standard_normal(shape) * (1 << noise.frac_bits)),
                        noise.min_raw, noise.max_raw).astype(np.int64)
        wide = rng.integers(noise.min_raw, noise.max_raw + 1, size=shape)
        out[f"e{j}"] = np.where(real | (rng.random(shape) < 0.5), draws, wide)
    return out


def random_inputs(b: Bench) -> Inputs:
    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        return random_beats(b, n, tag)

    return inputs


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random states and draws with random input gaps and output stalls: every component and
    sat bit-exact, tlast carried."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b), stalls)


def corner_beats(b: Bench) -> dict[str, np.ndarray]:
    """Zero; p and v pushed out of range both ways (p + T v, v + b e) and back in; e at its
    ends with a zero state; then every field drawn from its ends and neighbours, 0 and +-1."""
    dp = datapath(b.cfg)
    x, e = dp.x[0], dp.noise
    rng = np.random.default_rng(b.rng("propagate_bot-corners").getrandbits(32))
    directed = [
        # px, vx, py, vy, ex, ey
        (0, 0, 0, 0, 0, 0),
        (x.max_raw, x.max_raw, x.min_raw, x.min_raw, 0, 0),          # p + T v out both ways
        (x.max_raw, x.min_raw, x.min_raw, x.max_raw, 0, 0),          # and back in
        (0, x.max_raw, 0, x.min_raw, e.max_raw, e.min_raw),          # v + b e out both ways
        (0, x.max_raw, 0, x.min_raw, e.min_raw, e.max_raw),
        (x.max_raw, 0, x.min_raw, 0, e.max_raw, e.min_raw),          # p + a e out both ways
        (0, 0, 0, 0, e.max_raw, e.min_raw),                          # e at its ends
        (0, 0, 0, 0, e.min_raw, e.max_raw),
        (x.max_raw - 1, 1, x.min_raw + 1, -1, 0, 0),                 # just out
        (x.max_raw - 1, 0, x.min_raw + 1, 0, 1, -1),
        (x.max_raw, 0, x.min_raw, 0, 0, 0),                          # at the ends, staying
    ]
    xs = [x.min_raw, x.min_raw + 1, -1, 0, 1, x.max_raw - 1, x.max_raw]
    es = [e.min_raw, e.min_raw + 1, -1, 0, 1, e.max_raw - 1, e.max_raw]
    mixed = [tuple(rng.choice(xs) for _ in range(4)) + tuple(rng.choice(es) for _ in range(2))
             for _ in range(1_000)]
    rows = np.array(directed + mixed, dtype=np.int64)
    lanes = b.cfg.lanes
    # lane k sees the rows shifted by 5 k, so the lanes see different values
    cols = np.stack([np.roll(rows, 5 * k, axis=0) for k in range(lanes)], axis=1)
    names = [f"x{i}" for i in range(4)] + ["e0", "e1"]
    return {name: cols[:, :, c] for c, name in enumerate(names)}


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """Directed corners (corner_beats): zero gives zero, saturation of p and v both ways."""
    b = bench()
    blk = block(b)
    dp = datapath(b.cfg)
    beats = corner_beats(b)
    n = len(beats["x0"])
    idle_inputs(dut)
    await start(dut)
    sb, _, out = await run_stream(dut, blk, b, beats, [False] * (n - 1) + [True], 0.2, 0.2,
                                  "propagate_bot-corners")
    dut._log.info("%d corner beats: %s", n, sb.summary())
    sb.assert_clean()
    got = unpack([beat.data for beat in out.beats], blk.fields_out, b.cfg.lanes)
    assert all(got[f"x{i}"][0, 0] == 0 for i in range(4)) and got["sat"][0, 0] == 0, \
        "zero must propagate to zero"
    sat = got["sat"].astype(bool)
    fmt = dp.x[0]
    for i, name in enumerate(("px", "vx", "py", "vy")):
        up = sat & (got[f"x{i}"] == fmt.max_raw)
        down = sat & (got[f"x{i}"] == fmt.min_raw)
        assert up.any() and down.any(), f"{name} must saturate both ways in the corners"
    dut._log.info("saturated particles: %d of %d", sat.sum(), sat.size)


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    blk = block(b)
    await check_latency_and_throughput(dut, blk, b, random_inputs(b))


def wrong_velocity(dp: Datapath):
    """Deliberately wrong model: vy's LSB flipped wherever e1 mod 7 == 3."""
    right = propagate_model(dp)

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = right(seen)
        return {**out, "x3": np.where(np.asarray(seen["e1"]) % 7 == 3, out["x3"] ^ 1,
                                      out["x3"])}
    return model


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    b = bench()
    blk = block(b, wrong_velocity(datapath(b.cfg)))
    await check_corrupted_model_is_caught(dut, blk, b, random_inputs(b))

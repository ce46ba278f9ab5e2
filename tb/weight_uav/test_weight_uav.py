"""cocotb testbench of `weight_uav` (w = 2^-(t - R), t = sum_k ((v_gps,k - v_k) c_u)^2, R the
step's running minimum of floor(t)): every particle passed through, every weight, every sat flag
and every beat's shift against model.blocks.weight_uav, one call per step (the GPS velocity is
a per-step operand)."""

from __future__ import annotations

import math

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import weight_uav
from gpf.model.formats import Datapath, datapath
from gpf.tb.harness import Bench, bench
from gpf.tb.scoreboard import Field
from gpf.tb.streaming import (
    StreamBlock,
    check_corrupted_model_is_caught,
    check_latency_and_throughput,
    check_random_beats,
)
from gpf.tb.weight_common import (
    SAT,
    SHIFT,
    check_weights_span,
    run_steps,
    spread_lanes,
    step_model,
    wrong_c_u,
)

N = 7          # q0 .. q3, vE, vN, vU
V = (4, 5, 6)  # the velocity components
OPS = ["v0", "v1", "v2"]


def block(b: Bench, dp: Datapath | None = None) -> StreamBlock:
    dp = dp or datapath(b.cfg)
    k = b.manifest["modules"]["weight_uav"]["constants"]
    assert (k["word"], k["w_width"], k["terms"]) == (dp.word, dp.weight.width, 3), k

    def fn(rows: np.ndarray, ops: dict[str, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return weight_uav(dp, rows, np.array([ops[name] for name in OPS], dtype=np.int64),
                          b.cfg.lanes, per_particle=True)

    xs = [Field(f"x{i}", dp.x[i]) for i in range(N)]
    return StreamBlock(
        "weight_uav", xs, xs + [Field("w", dp.weight), SAT], b.cfg.lanes,
        b.manifest["modules"]["weight_uav"]["latency"], step_model(fn, N, OPS),
        fields_op=[Field(name, dp.x[i]) for name, i in zip(OPS, V, strict=True)],
        beat_out=[SHIFT])


class Scenario:
    """A velocity the particle clouds sit around (fixed for the run) and GPS fixes near it, so
    that weights span 0 .. 1; unit quaternions; plus full-range shares."""

    def __init__(self, b: Bench) -> None:
        self.b, self.dp = b, datapath(b.cfg)
        self.q, self.v = self.dp.x[0], self.dp.x[V[0]]
        self.one = 1 << self.v.frac_bits                      # 1 m/s raw
        self.sigma = b.cfg.app_params["sigma_v"] * self.one
        self.velocity = self._rng("scenario").normal(0, 5, 3) * self.one

    def _rng(self, tag: str) -> np.random.Generator:
        return np.random.default_rng(self.b.rng(f"weight_uav-{tag}").getrandbits(32))

    def inputs(self, n: int, tag: str) -> dict[str, np.ndarray]:
        """75% clouds around the velocity (spread 1 mm/s .. 0.3 m/s) with unit quaternions,
        15% uniform over the whole range, 10% extreme values."""
        rng, shape = self._rng(f"x-{tag}"), (n, self.b.cfg.lanes)
        spread = np.exp2(rng.uniform(math.log2(0.001), math.log2(0.3), shape)) * self.one
        quat = rng.normal(0, 1, shape + (4,))
        quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
        kind = rng.choice(3, size=shape, p=[0.75, 0.15, 0.10])
        out = {}
        for i in range(N):
            fmt = self.dp.x[i]
            if i < 4:
                near = quat[..., i] * (1 << fmt.frac_bits)
            else:
                near = self.velocity[i - V[0]] + rng.normal(0, 1, shape) * spread
            near = np.clip(np.rint(near), fmt.min_raw, fmt.max_raw).astype(np.int64)
            wide = rng.integers(fmt.min_raw, fmt.max_raw + 1, size=shape)
            ends = rng.choice([fmt.min_raw, fmt.min_raw + 1, 0, fmt.max_raw - 1, fmt.max_raw],
                              size=shape)
            out[f"x{i}"] = np.choose(kind, [near, wide, ends])
        return out

    def operands(self, steps: int, tag: str) -> dict[str, np.ndarray]:
        """65% the velocity plus GPS noise of 0.5 .. 8 sigma, 10% 5 m/s away (weights 0), 10%
        at the range's ends, 15% anywhere."""
        rng, fmt = self._rng(f"op-{tag}"), self.v
        kind = rng.choice(4, size=steps, p=[0.65, 0.1, 0.1, 0.15])
        scale = self.sigma * np.exp2(rng.uniform(-1, 3, steps))
        out = {}
        for k, name in enumerate(OPS):
            noisy = self.velocity[k] + rng.normal(0, 1, steps) * scale
            far = self.velocity[k] + rng.choice([-5, 5], size=steps) * self.one
            options = [np.clip(np.rint(v), fmt.min_raw, fmt.max_raw).astype(np.int64)
                       for v in (noisy, far)]
            options += [rng.choice([fmt.min_raw, fmt.max_raw], size=steps),
                        rng.integers(fmt.min_raw, fmt.max_raw + 1, size=steps)]
            out[name] = np.choose(kind, options)
        return out


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Particle clouds and full-range particles, a new GPS velocity every step, random input
    gaps and output stalls: particles, weights and flags bit-exact, tlast carried."""
    b = bench()
    sc = Scenario(b)
    await check_random_beats(dut, block(b), b, sc.inputs, stalls, operands=sc.operands)


def corner_steps(b: Bench) -> dict[str, tuple[np.ndarray, dict[str, int]]]:
    """Named steps: particles (beats, lanes, 7) and operands."""
    dp, lanes = datapath(b.cfg), b.cfg.lanes
    fmt = dp.x[V[0]]
    lo, hi, one = fmt.min_raw, fmt.max_raw, 1 << fmt.frac_bits
    qone = 1 << dp.x[0].frac_bits
    quats = [(qone, 0, 0, 0), (0, -qone, 0, 0), (qone // 2, qone // 2, -qone // 2, qone // 2)]
    gps = (3 * one, -one, one // 7)

    def rows(vels: list[tuple[int, int, int]]) -> np.ndarray:
        return spread_lanes(np.array([quats[i % 3] + v for i, v in enumerate(vels)],
                                     dtype=np.int64), lanes)

    def ops(v: tuple[int, int, int]) -> dict[str, int]:
        return dict(zip(OPS, v, strict=True))

    rng = np.random.default_rng(b.rng("weight_uav-corners").getrandbits(32))
    cloud = [tuple(int(c) for c in gps + rng.normal(0, 0.05 * one, 3)) for _ in range(24)]
    # the innovation shrinks beat by beat: each beat holds a new best (lane 0 of a beat sees
    # the rows rotated, so the rows are kept in groups of `lanes` equal particles)
    sigma = b.cfg.app_params["sigma_v"] * one
    closing = [(gps[0] + int(k * sigma), gps[1], gps[2]) for k in (30, 20, 12, 6, 3, 1.5, 0)]
    return {
        # zero innovation: w exactly 1
        "w_one": (rows([gps] * 4), ops(gps)),
        "w_one_zero": (rows([(0, 0, 0)] * 3), ops((0, 0, 0))),
        "w_one_ends": (rows([(lo, hi, lo)] * 3), ops((lo, hi, lo))),
        # the GPS fix 5 m/s (250 sigma) from the cloud: no particle within reach
        "out_of_reach": (rows(cloud), ops(tuple(g + 5 * one for g in gps))),
        # v_gps at one end of the range, the particles at the other: every difference saturates
        "sat_high_gps": (rows([(lo, lo, lo), (lo + one, lo, lo), (lo, lo, lo + 1)]),
                         ops((hi, hi, hi))),
        "sat_low_gps": (rows([(hi, hi, hi), (hi, hi - one, hi), (1, hi, hi)]), ops((lo, lo, lo))),
        # vE alone saturates: hi - lo and hi - (-1) overflow, hi - 0 and hi - 1 do not
        "sat_one": (rows([(lo, 0, 0), (0, 5, 0), (-1, 0, 0), (1, 0, 0)]), ops((hi, 0, 0))),
        "cloud": (rows(cloud), ops(gps)),
        "new_best": (np.repeat(np.array([quats[0] + v for v in closing], np.int64)[:, None],
                               lanes, axis=1), ops(gps)),
    }


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """w exactly 1 (zero innovation, also at the range's ends), no particle within reach (GPS
    far away: every weight in (1/2, 1], no rescale), every difference saturating either way, one
    saturating component, a cloud, and a new best particle on every beat (rescales)."""
    b = bench()
    blk, dp = block(b), datapath(b.cfg)
    steps = corner_steps(b)
    got = await run_steps(dut, blk, b, list(steps.values()), "weight_uav-corners")
    one_w = 1 << dp.weight.frac_bits
    parts, at = {}, 0
    for name, (rows, _) in steps.items():
        parts[name] = {k: v[at:at + len(rows)] for k, v in got.items()}
        at += len(rows)
    for name in ("w_one", "w_one_zero", "w_one_ends"):
        assert (parts[name]["w"] == one_w).all(), f"{name}: w not exactly 1"
        assert not parts[name]["sat"].any()
    for name in ("out_of_reach", "sat_high_gps", "sat_low_gps"):
        w, shift = parts[name]["w"], parts[name]["shift"]
        assert (w > one_w // 2).all(), f"{name}: a weight not in (1/2, 1] beyond reach"
        assert (shift == 0).all(), f"{name}: a rescale beyond reach"
    for name in ("sat_high_gps", "sat_low_gps"):
        assert parts[name]["sat"].all(), f"{name}: not every particle saturates"
    assert parts["sat_one"]["sat"].sum() == 2 * b.cfg.lanes, "sat_one: two of four saturate"
    assert ((parts["cloud"]["w"] > 0) & (parts["cloud"]["w"] < one_w)).any()
    new = parts["new_best"]
    assert (new["shift"][1:] > 0).all(), f"new_best: a beat without a rescale: {new['shift']}"
    assert (new["w"] > one_w // 2).all(), "new_best: the best so far below 1/2"


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    sc = Scenario(b)
    await check_latency_and_throughput(dut, block(b), b, sc.inputs, operands=sc.operands)


@cocotb.test()
async def test_weights_span(dut: SimHandleBase) -> None:
    """Steps of 32: the random stimulus reaches weights 0, strictly between and above 1/2, and
    saturation (shares from the model on the beats the scoreboard compared)."""
    b = bench()
    await check_weights_span(dut, block(b), b, Scenario(b), 64)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """A deliberately wrong model: c_u one LSB too large."""
    b = bench()
    bad = wrong_c_u(datapath(b.cfg))
    blk, sc = block(b, bad), Scenario(b)
    await check_corrupted_model_is_caught(dut, blk, b, sc.inputs, sc.operands)

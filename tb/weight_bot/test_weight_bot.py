"""cocotb testbench of `weight_bot` (w = 2^-(t - R), t = (wrap(z - atan2(py - oy, px - ox)) c_u)^2,
R the step's running minimum of floor(t)): every particle passed through, every weight, every
sat flag and every beat's shift against model.blocks.weight_bot, one call per step (the observer
and the bearing z are per-step operands)."""

from __future__ import annotations

import math

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import weight_bot
from gpf.model.formats import Datapath, datapath
from gpf.tb.cordic_atan2.test_cordic_atan2 import turns
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

N = 4   # px, vx, py, vy


def block(b: Bench, dp: Datapath | None = None) -> StreamBlock:
    dp = dp or datapath(b.cfg)
    k = b.manifest["modules"]["weight_bot"]["constants"]
    assert (k["word"], k["angle_width"], k["w_width"]) == (dp.word, dp.angle_frac,
                                                           dp.weight.width), k

    def fn(rows: np.ndarray, ops: dict[str, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return weight_bot(dp, rows, ops["z"], (ops["ox"], ops["oy"]), b.cfg.lanes,
                          per_particle=True)

    xs = [Field(f"x{i}", dp.x[i]) for i in range(N)]
    return StreamBlock(
        "weight_bot", xs, xs + [Field("w", dp.weight), SAT], b.cfg.lanes,
        b.manifest["modules"]["weight_bot"]["latency"], step_model(fn, N, ["z", "ox", "oy"]),
        fields_op=[Field("z", turns(dp.angle_frac)), Field("ox", dp.x[0]),
                   Field("oy", dp.x[2])], beat_out=[SHIFT])


class Scenario:
    """A target the particle clouds sit around (fixed for the run), observers around it and
    bearings near the true one, so that weights span 0 .. 1; plus full-range shares."""

    def __init__(self, b: Bench) -> None:
        self.b, self.dp = b, datapath(b.cfg)
        self.fmt = self.dp.x[0]
        self.one = 1 << self.fmt.frac_bits               # 1 m (1 m/s) raw
        rng = self._rng("scenario")
        self.target = rng.uniform(-1, 1, 2) * self.fmt.max_raw / 8
        self.velocity = rng.normal(0, 0.3, 2) * self.one

    def _rng(self, tag: str) -> np.random.Generator:
        return np.random.default_rng(self.b.rng(f"weight_bot-{tag}").getrandbits(32))

    def clip(self, v: np.ndarray) -> np.ndarray:
        return np.clip(np.rint(v), self.fmt.min_raw, self.fmt.max_raw).astype(np.int64)

    def inputs(self, n: int, tag: str) -> dict[str, np.ndarray]:
        """75% clouds around the target (spread 5 mm .. 4 m), 15% uniform over the whole
        range, 10% extreme values."""
        rng, lanes, fmt = self._rng(f"x-{tag}"), self.b.cfg.lanes, self.fmt
        shape = (n, lanes)
        spread = np.exp2(rng.uniform(math.log2(0.005), 2, shape)) * self.one
        kind = rng.choice(3, size=shape, p=[0.75, 0.15, 0.10])
        out = {}
        for i in range(N):
            axis, vel = i // 2, i % 2
            centre = self.velocity[axis] if vel else self.target[axis]
            cloud = self.clip(centre + rng.normal(0, 1, shape) * (0.3 * self.one if vel
                                                                  else spread))
            wide = rng.integers(fmt.min_raw, fmt.max_raw + 1, size=shape)
            ends = rng.choice([fmt.min_raw, fmt.min_raw + 1, 0, fmt.max_raw - 1, fmt.max_raw],
                              size=shape)
            out[f"x{i}"] = np.choose(kind, [cloud, wide, ends])
        return out

    def bearing(self, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """The true bearing as a raw binary angle (wrapped)."""
        return self.wrap(np.rint(np.arctan2(dy, dx) / (2 * np.pi) * (1 << self.dp.angle_frac)))

    def wrap(self, raw: np.ndarray) -> np.ndarray:
        a = self.dp.angle_frac
        return ((raw.astype(np.int64) + (1 << (a - 1))) % (1 << a)) - (1 << (a - 1))

    def operands(self, steps: int, tag: str) -> dict[str, np.ndarray]:
        """Observers: 70% 0.5 m .. range/4 from the target, 15% at the range's corners, 15%
        anywhere. z: 60% the true bearing of the target plus noise of 0.5 .. 8 sigma, 20% any
        angle, 10% the opposite bearing (weights 0), 10% within 64 LSB of a half turn."""
        rng, fmt, a = self._rng(f"op-{tag}"), self.fmt, self.dp.angle_frac
        dist = np.exp2(rng.uniform(math.log2(0.5 * self.one), math.log2(fmt.max_raw / 4), steps))
        phi = rng.uniform(-np.pi, np.pi, steps)
        near = [self.clip(self.target[0] + dist * np.cos(phi)),
                self.clip(self.target[1] + dist * np.sin(phi))]
        okind = rng.choice(3, size=steps, p=[0.7, 0.15, 0.15])
        obs = []
        for axis in range(2):
            corner = rng.choice([fmt.min_raw, fmt.max_raw], size=steps)
            wide = rng.integers(fmt.min_raw, fmt.max_raw + 1, size=steps)
            obs.append(np.choose(okind, [near[axis], corner, wide]))
        true = self.bearing(self.target[0] - obs[0], self.target[1] - obs[1])
        sigma = math.sqrt(self.b.cfg.app_params["bearing_var"]) / (2 * np.pi) * (1 << a)
        noisy = self.wrap(true + rng.normal(0, 1, steps) * sigma * np.exp2(rng.uniform(-1, 3,
                                                                                  steps)))
        zkind = rng.choice(4, size=steps, p=[0.6, 0.2, 0.1, 0.1])
        z = np.choose(zkind, [noisy, rng.integers(-(1 << (a - 1)), 1 << (a - 1), size=steps),
                              self.wrap(true + (1 << (a - 1))),
                              self.wrap(rng.integers(-64, 65, size=steps) + (1 << (a - 1)))])
        return {"z": z, "ox": obs[0], "oy": obs[1]}


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Particle clouds and full-range particles, a new observer and bearing every step, random
    input gaps and output stalls: particles, weights and flags bit-exact, tlast carried."""
    b = bench()
    sc = Scenario(b)
    await check_random_beats(dut, block(b), b, sc.inputs, stalls, operands=sc.operands)


def corner_steps(b: Bench) -> dict[str, tuple[np.ndarray, dict[str, int]]]:
    """Named steps: particles (beats, lanes, 4) and operands."""
    dp, lanes = datapath(b.cfg), b.cfg.lanes
    fmt, a = dp.x[0], dp.angle_frac
    lo, hi, one = fmt.min_raw, fmt.max_raw, 1 << fmt.frac_bits
    half = 1 << (a - 1)
    ox, oy = one, -2 * one

    def rows(points: list[tuple[int, int]]) -> np.ndarray:
        return spread_lanes(np.array([(px, 7, py, -7) for px, py in points], dtype=np.int64),
                            lanes)

    ks = [1, 2, 3, 100, one, 20 * one]
    rng = np.random.default_rng(b.rng("weight_bot-corners").getrandbits(32))
    cloud = [(int(x), int(y)) for x, y in rng.normal(0, 0.2 * one, (32, 2)) + (10 * one, 5 * one)]
    # due west, within 1/64 rad of the axis on either side (and on it)
    west = [(ox - 3 * one + int(d), oy + s * int(e)) for d, e in
            rng.integers(0, one, (16, 2)) // (1, 24) for s in (1, -1)] + [(ox - one, oy)]
    sc = Scenario(b)
    cloud_bearing = int(sc.bearing(np.array(10.0 * one - ox), np.array(5.0 * one - oy)))
    # the innovation shrinks beat by beat (k sigma off the bearing z = 0, due east of the
    # observer): each beat holds a new best; a beat's lanes carry equal particles
    sigma = math.sqrt(b.cfg.app_params["bearing_var"])
    closing = np.array([(ox + 4 * one, 7, oy + int(4 * one * math.tan(k * sigma)), -7)
                        for k in (30, 20, 12, 6, 3, 1.5, 0)], dtype=np.int64)
    return {
        # theta exactly 0 (on the +x axis, or dx = dy = 0) and z = 0: w exactly 1
        "w_one_axis": (rows([(ox + k, oy) for k in ks] + [(ox, oy)]), {"z": 0, "ox": ox, "oy": oy}),
        # theta exactly 3/8 turn on the diagonal
        "w_one_diagonal": (rows([(ox - k, oy + k) for k in ks]),
                           {"z": 3 << (a - 3), "ox": ox, "oy": oy}),
        # z opposite the cloud's bearing: no particle within reach
        "out_of_reach": (rows(cloud), {"z": int(sc.wrap(np.array(cloud_bearing + half))),
                                       "ox": ox, "oy": oy}),
        # the observer at one end of the range, the particles at the other: dx, dy saturate
        "sat_low_observer": (rows([(hi, hi), (hi, 0), (0, hi), (hi - one, lo + one), (hi, lo)]),
                             {"z": 1 << (a - 3), "ox": lo, "oy": lo}),
        "sat_high_observer": (rows([(lo, lo), (lo, 0), (0, lo), (lo, hi), (lo + one, lo)]),
                              {"z": -(3 << (a - 3)), "ox": hi, "oy": hi}),
        # particles due west: theta on both sides of +-1/2 turn, z = -1/2 and just below +1/2
        "wrap_minus_half": (rows(west), {"z": -half, "ox": ox, "oy": oy}),
        "wrap_plus_half": (rows(west), {"z": half - 3, "ox": ox, "oy": oy}),
        # extreme particles, the observer inside the range
        "extremes": (rows([(lo, lo), (hi, hi), (lo, hi), (hi, lo), (0, 0), (ox, lo), (lo, oy)]),
                     {"z": -half, "ox": ox, "oy": oy}),
        "new_best": (np.repeat(closing[:, None], lanes, axis=1), {"z": 0, "ox": ox, "oy": oy}),
    }


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """w exactly 1 (zero innovation), no particle within reach (z opposite the particles: every
    weight in (1/2, 1], no rescale), dx/dy saturation with the observer at either end, bearings
    across +-1/2 turn, extremes, and a new best particle on every beat (rescales)."""
    b = bench()
    blk, dp = block(b), datapath(b.cfg)
    steps = corner_steps(b)
    got = await run_steps(dut, blk, b, list(steps.values()), "weight_bot-corners")
    one_w = 1 << dp.weight.frac_bits
    start_beat = 0
    parts = {}
    for name, (rows, _) in steps.items():
        parts[name] = {k: v[start_beat:start_beat + len(rows)] for k, v in got.items()}
        start_beat += len(rows)
    for name in ("w_one_axis", "w_one_diagonal"):
        assert (parts[name]["w"] == one_w).all(), f"{name}: w not exactly 1: {parts[name]['w']}"
    w, shift = parts["out_of_reach"]["w"], parts["out_of_reach"]["shift"]
    assert (w > one_w // 2).all(), "out_of_reach: a weight not in (1/2, 1]: not equal enough"
    assert (shift == 0).all(), "out_of_reach: a rescale beyond reach"
    new = parts["new_best"]
    assert (new["shift"][1:] > 0).all(), f"new_best: a beat without a rescale: {new['shift']}"
    assert (new["w"] > one_w // 2).all(), "new_best: the best so far below 1/2"
    for name in ("sat_low_observer", "sat_high_observer"):
        assert parts[name]["sat"].all(), f"{name}: not every particle saturates"
    for name in ("wrap_minus_half", "wrap_plus_half"):
        assert (parts[name]["w"] > one_w // 2).mean() > 0.5, f"{name}: the wrap lost weights"
    assert parts["w_one_axis"]["sat"].sum() == 0
    dut._log.info("corner steps: %s", ", ".join(steps))


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    sc = Scenario(b)
    await check_latency_and_throughput(dut, block(b), b, sc.inputs, operands=sc.operands)


@cocotb.test()
async def test_weights_span(dut: SimHandleBase) -> None:
    """The random stimulus reaches every region: weights 0, strictly between, 1; saturation."""
    b = bench()
    await check_weights_span(dut, block(b), b, Scenario(b), 62)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """A deliberately wrong model: c_u one LSB too large."""
    b = bench()
    bad = wrong_c_u(datapath(b.cfg))
    blk = block(b, bad)
    sc = Scenario(b)
    await check_corrupted_model_is_caught(dut, blk, b, sc.inputs, sc.operands)

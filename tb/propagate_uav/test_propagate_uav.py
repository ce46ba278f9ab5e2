"""cocotb testbench of `propagate_uav` (attitude and velocity over one IMU period): every state
word and the saturation flag of every lane of every beat against blocks.propagate_uav, step by
step with that step's omega and accel operands."""

from __future__ import annotations

import math
from collections.abc import Callable

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model import blocks
from gpf.model.fixed import Format
from gpf.model.formats import GRAVITY, Datapath, datapath
from gpf.rtl.generate import propagate_uav_context
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field, unpack
from gpf.tb.streaming import (
    STEP,
    Inputs,
    Operands,
    StreamBlock,
    check_corrupted_model_is_caught,
    check_latency_and_throughput,
    check_random_beats,
    idle_inputs,
    run_stream,
)

N_X, N_E = 7, 6
SAT = Format(False, 1, 0)
# (x, e, omega, accel) -> (x', per-row sat): one step's particles
StepModel = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                     tuple[np.ndarray, np.ndarray]]


def step_model(dp: Datapath) -> StepModel:
    def run(x, e, omega, accel):
        out, flags = blocks.propagate_uav(dp, x, e, omega, accel, per_particle=True)
        return out, (flags & blocks.Flag.SAT != 0).astype(np.int64)
    return run


def row_by_row(dp: Datapath, x, e, omega, accel) -> np.ndarray:
    """Each particle's sat from the model called on that particle alone (the definition)."""
    return np.array([int(bool(blocks.propagate_uav(dp, x[i:i + 1], e[i:i + 1], omega, accel)[1]
                              & blocks.Flag.SAT)) for i in range(len(x))], dtype=np.int64)


def stream_model(run: StepModel) -> Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]]:
    """The stream's model: each step's beats (all lanes) through `run` with its operands."""
    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        beats, lanes = seen["x0"].shape
        x = np.stack([seen[f"x{i}"] for i in range(N_X)], axis=-1)
        e = np.stack([seen[f"e{j}"] for j in range(N_E)], axis=-1)
        out = np.zeros_like(x)
        sat = np.zeros((beats, lanes), dtype=np.int64)
        for step in np.unique(seen[STEP]):
            at = seen[STEP] == step
            first = np.flatnonzero(at)[0]
            omega = np.array([seen[f"omega{k}"][first] for k in range(3)], dtype=np.int64)
            accel = np.array([seen[f"accel{m}"][first] for m in range(3)], dtype=np.int64)
            y, s = run(x[at].reshape(-1, N_X), e[at].reshape(-1, N_E), omega, accel)
            out[at] = y.reshape(-1, lanes, N_X)
            sat[at] = s.reshape(-1, lanes)
        return {**{f"x{i}": out[..., i] for i in range(N_X)}, "sat": sat}
    return model


def block(b: Bench, run: StepModel | None = None) -> StreamBlock:
    """Fields as generated: the latency from the generator's context (not manifest.json,
    which a concurrent run of another block may be rewriting)."""
    dp = datapath(b.cfg)
    return StreamBlock(
        "propagate_uav",
        [Field(f"x{i}", dp.x[i]) for i in range(N_X)]
        + [Field(f"e{j}", dp.noise) for j in range(N_E)],
        [Field(f"x{i}", dp.x[i]) for i in range(N_X)] + [Field("sat", SAT)],
        b.cfg.lanes, propagate_uav_context(b.cfg)["latency"],
        stream_model(run or step_model(dp)),
        fields_op=[Field(f"omega{k}", dp.gyro) for k in range(3)]
        + [Field(f"accel{m}", dp.accel) for m in range(3)])


def raw(fmt: Format, real: np.ndarray | float) -> np.ndarray:
    """Real values to raw, rounded and clipped into `fmt`."""
    return np.clip(np.round(np.asarray(real) * 2.0**fmt.frac_bits), fmt.min_raw,
                   fmt.max_raw).astype(np.int64)


def full_range(rng: np.random.Generator, fmt: Format, shape) -> np.ndarray:
    return rng.integers(fmt.min_raw, fmt.max_raw + 1, size=shape)


def random_inputs(b: Bench) -> Inputs:
    """Realistic particles: unit quaternions with small noise, velocities within +-40 m/s,
    N(0, 1) draws; a fifth of the states and a tenth of the draws full-range words."""
    dp = datapath(b.cfg)

    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        rng = np.random.default_rng(b.rng(tag).getrandbits(32))
        shape = (n, b.cfg.lanes)
        q = rng.normal(size=shape + (4,))
        q = q / np.linalg.norm(q, axis=-1, keepdims=True) + rng.normal(0, 1e-3, shape + (4,))
        v = rng.uniform(-40, 40, shape + (3,))
        wide_x, wide_e = rng.random(shape) < 0.2, rng.random(shape) < 0.1
        out = {}
        for i in range(N_X):
            fmt = dp.x[i]
            real = raw(fmt, q[..., i] if i < 4 else v[..., i - 4])
            out[f"x{i}"] = np.where(wide_x, full_range(rng, fmt, shape), real)
        for j in range(N_E):
            out[f"e{j}"] = np.where(wide_e, full_range(rng, dp.noise, shape),
                                    raw(dp.noise, rng.normal(size=shape)))
        return out

    return inputs


def random_operands(b: Bench) -> Operands:
    """Body rates within +-2 rad/s, specific force gravity +-20 m/s^2 per axis; a fifth of
    the steps full-range words."""
    dp = datapath(b.cfg)

    def operands(steps: int, tag: str) -> dict[str, np.ndarray]:
        rng = np.random.default_rng(b.rng(f"{tag}-op").getrandbits(32))
        wide = rng.random(steps) < 0.2
        out = {}
        for k in range(3):
            out[f"omega{k}"] = np.where(wide, full_range(rng, dp.gyro, steps),
                                        raw(dp.gyro, rng.uniform(-2, 2, steps)))
        for m in range(3):
            real = -GRAVITY[m] + rng.uniform(-20, 20, steps)
            out[f"accel{m}"] = np.where(wide, full_range(rng, dp.accel, steps),
                                        raw(dp.accel, real))
        return out

    return operands


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random particles and per-step IMU operands with random input gaps and output stalls:
    every state word and sat bit-exact, tlast carried, each step with its own operands."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b), stalls,
                             operands=random_operands(b))


Corner = tuple[str, np.ndarray, np.ndarray, list[int], list[int], bool | None]


def corners(dp: Datapath) -> list[Corner]:
    """(name, x rows, e rows, omega, accel, every row saturates?) per step."""
    qf, vf, ef, gf, af = dp.x[0], dp.x[4], dp.noise, dp.gyro, dp.accel
    one = 1 << qf.frac_bits

    def rows(q, v, e=(0,) * N_E, n=1):
        x = np.array([list(q) + list(v)] * n, dtype=np.int64)
        return x, np.array([list(e)] * n, dtype=np.int64)

    ident = (one, 0, 0, 0)
    c45, s45 = math.cos(math.pi / 8), math.sin(math.pi / 8)
    yaw45 = tuple(int(v) for v in raw(qf, np.array([c45, 0, 0, s45])))
    unit = tuple(int(v) for v in raw(qf, np.array([0.5, -0.5, 0.5, 0.5])))
    vmax, vmin, emax, emin = vf.max_raw, vf.min_raw, ef.max_raw, ef.min_raw
    gmax, gmin, amax, amin = gf.max_raw, gf.min_raw, af.max_raw, af.min_raw
    a40 = int(raw(af, 40.0))
    g_up = [0, 0, int(raw(af, 9.8))]
    out: list[Corner] = []
    out.append(("zero state, draws and operands", *rows((0,) * 4, (0,) * 3, n=3),
                [0, 0, 0], [0, 0, 0], False))
    out.append(("velocity pushed past its maximum",
                *rows(ident, (vmax, vmax, vmax - 1), n=2), [0, 0, 0], [a40, a40, a40], True))
    out.append(("velocity pushed past its minimum",
                *rows(ident, (vmin, vmin + 1, vmin), n=2), [0, 0, 0], [-a40, -a40, -a40],
                True))
    out.append(("velocity at its maximum, pulled back", *rows(ident, (0, 0, vmax)),
                [0, 0, 0], [0, 0, 0], False))
    out.append(("omega' past its maximum", *rows(unit, (0,) * 3, (emax,) * 3 + (0,) * 3),
                [gmax] * 3, g_up, True))
    out.append(("omega' past its minimum", *rows(unit, (0,) * 3, (emin,) * 3 + (0,) * 3),
                [gmin] * 3, g_up, True))
    out.append(("omega at its extremes, no draw (largest |h|)", *rows(unit, (1, 2, 3)),
                [gmax, gmin, gmax], g_up, None))
    out.append(("a' past its maximum", *rows(ident, (0,) * 3, (0,) * 3 + (emax,) * 3),
                [0, 0, 0], [amax] * 3, True))
    out.append(("a' past its minimum", *rows(ident, (0,) * 3, (0,) * 3 + (emin,) * 3),
                [0, 0, 0], [amin] * 3, True))
    out.append(("f = C a' + g past the accel format (45 deg yaw)", *rows(yaw45, (0,) * 3),
                [0, 0, 0], [amax, amin, 0], True))
    out.append(("C(q) past the rot format", *rows((one + one // 2, 0, 0, 0), (0,) * 3),
                [0, 0, 0], g_up, True))
    out.append(("q' past its maximum", *rows((qf.max_raw, qf.min_raw, qf.min_raw,
                                              qf.min_raw), (0,) * 3),
                [int(raw(gf, 2.0))] * 3, g_up, True))
    out.append(("draws at their extremes", *rows(unit, (100, -200, 300), (emax,) * N_E),
                [int(raw(gf, 1.0))] * 3, g_up, None))
    out.append(("draws at their extremes, negative", *rows(unit, (100, -200, 300),
                                                           (emin,) * N_E),
                [int(raw(gf, -1.0))] * 3, g_up, None))
    out.append(("full-range words everywhere",
                *rows((qf.max_raw,) * 4, (vmax,) * 3, (emax,) * N_E),
                [gmax] * 3, [amax] * 3, True))
    out.append(("most negative words everywhere",
                *rows((qf.min_raw,) * 4, (vmin,) * 3, (emin,) * N_E),
                [gmin] * 3, [amin] * 3, True))
    omega0 = half_way_omega(dp)
    out.append(("q'_0 = -h_0 q_1 exactly half way between two outputs (its rounding constant)",
                *rows((0, one, 0, 0), (0,) * 3), [omega0, 0, 0], g_up, False))
    return out


def half_way_omega(dp: Datapath) -> int:
    """A gyro word whose h_0 puts q'_0 = -h_0 q_1 (q = (0, 1, 0, 0), no draws) exactly half way
    between two outputs: h_0 2^f_q an odd multiple of 2^(h_frac - 1), where only the rounding
    constant decides (a constant off by the negated terms' count rounds it the other way)."""
    a = dp.h_frac - 1 - dp.x[0].frac_bits
    omega = np.arange(1, 1 << 16, dtype=np.int64)
    rows = np.zeros((len(omega), 3), dtype=np.int64)
    h0 = blocks.half_angles(dp, rows, np.column_stack([omega, rows[:, :2]]))[0][0]
    return int(omega[np.flatnonzero(h0 % (2 << a) == 1 << a)[0]])


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """One step per corner (its own omega and accel): zero state, velocity pushed past either
    end of its format (and pulled back from it), omega' and a' past either end, f = C a' + g
    and C(q) past their formats, q' past its end, extreme draws, full-range words, q'_0
    exactly half way between two outputs (only its rounding constant decides). Each
    corner's saturation is checked against the model row by row, and the ones built to
    saturate must."""
    b = bench()
    dp = datapath(b.cfg)
    lanes = b.cfg.lanes
    cases = corners(dp)
    ins = {f.name: [] for f in block(b).fields_in}
    ops = {f"{n}{k}": [] for n in ("omega", "accel") for k in range(3)}
    lasts: list[bool] = []
    for name, x, e, omega, accel, saturates in cases:
        sat = row_by_row(dp, x, e, np.array(omega), np.array(accel))
        if saturates is not None:
            assert bool(sat.all() if saturates else not sat.any()), f"{name}: sat {sat}"
        beats = max(len(x), 2)   # each lane of each beat a row (rolled per lane)
        for i in range(N_X):
            ins[f"x{i}"] += [[x[(t + lane) % len(x), i] for lane in range(lanes)]
                             for t in range(beats)]
        for j in range(N_E):
            ins[f"e{j}"] += [[e[(t + lane) % len(e), j] for lane in range(lanes)]
                             for t in range(beats)]
        for k in range(3):
            ops[f"omega{k}"].append(omega[k])
            ops[f"accel{k}"].append(accel[k])
        lasts += [False] * (beats - 1) + [True]
    idle_inputs(dut)
    await start(dut)
    blk = block(b)
    sb, _, out = await run_stream(
        dut, blk, b, {k: np.array(v, dtype=np.int64) for k, v in ins.items()}, lasts,
        0.2, 0.2, "propagate_uav-corners", ops={k: np.array(v) for k, v in ops.items()})
    dut._log.info("%d corner steps: %s", len(cases), sb.summary())
    sb.assert_clean()
    got = unpack([beat.data for beat in out.beats], blk.fields_out, lanes)
    assert got["sat"].any() and not got["sat"][0].any(), "corners must saturate, zero not"
    # h = omega' dt/2 has h_frac fraction bits chosen so that |omega'| dt/2 always fits: the
    # generator's range analysis proves it (no saturation logic); the extreme-omega corner
    # gives the largest |h| there is
    h_sat = [r["sat"] for r in propagate_uav_context(b.cfg)["stages"][3]
             if r.get("base", "").startswith("h")]
    dut._log.info("h saturation %s", "reachable" if any(h_sat) else
                  "unreachable: |omega'| dt/2 always fits its word")


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    await check_latency_and_throughput(dut, block(b), b, random_inputs(b),
                                       operands=random_operands(b))


@cocotb.test()
async def test_operands_change_every_beat(dut: SimHandleBase) -> None:
    """Steps of one beat each (every beat has its own operands, driven while earlier steps are
    still in the pipeline) and of two beats, with stalls: each beat must use its step's."""
    b = bench()
    blk = block(b)
    n = 600
    rng = b.rng("short-steps")
    lasts = [rng.random() < 0.7 for _ in range(n)]
    lasts[-1] = True
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, random_inputs(b)(n, "short"), lasts, 0.3, 0.3,
                                "propagate_uav-short",
                                ops=random_operands(b)(sum(lasts), "short"))
    sb.assert_clean()


def new_q_for_c(dp: Datapath) -> StepModel:
    """Deliberately wrong model: C(q) from the NEW q (v' from a second pass on q')."""
    right = step_model(dp)

    def run(x, e, omega, accel):
        out, sat = right(x, e, omega, accel)
        again, _ = right(np.concatenate([out[:, :4], x[:, 4:]], axis=1), e, omega, accel)
        return np.concatenate([out[:, :4], again[:, 4:]], axis=1), sat
    return run


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    b = bench()
    blk = block(b, new_q_for_c(datapath(b.cfg)))
    await check_corrupted_model_is_caught(dut, blk, b, random_inputs(b), random_operands(b))

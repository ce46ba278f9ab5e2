"""cocotb testbench of `sample_cond` (x = mu + L e, one rounding per component, saturated):
every lane of every beat against model.blocks.sample_cond with each step's own mu and L."""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import Flag, cholesky, cov_pairs, sample_cond
from gpf.model.fixed import Format
from gpf.model.formats import Datapath
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
    log_uniform,
    run_stream,
)

SAT = Format(False, 1, 0)
Step = tuple[np.ndarray, np.ndarray, np.ndarray]   # mu (n,), L (n, n), e (beats, lanes, n)


def pairs(n: int) -> list[tuple[int, int]]:
    """L's lower triangle in the order of the op port: by rows."""
    return [(i, j) for i in range(n) for j in range(i + 1)]


def fields(dp: Datapath) -> tuple[list[Field], list[Field], list[Field]]:
    n = dp.n
    ins = [Field(f"e{j}", dp.noise) for j in range(n)]
    outs = [Field(f"x{i}", dp.x[i]) for i in range(n)] + [Field("sat", SAT)]
    ops = [Field(f"mu{i}", dp.x[i]) for i in range(n)]
    ops += [Field(f"l{i}_{j}", dp.chol[i]) for i, j in pairs(n)]
    return ins, outs, ops


def step_operands(seen: dict[str, np.ndarray], n: int, beat: int) -> tuple[np.ndarray, ...]:
    mu = np.array([seen[f"mu{i}"][beat] for i in range(n)], dtype=np.int64)
    chol = np.zeros((n, n), dtype=np.int64)
    for i, j in pairs(n):
        chol[i, j] = seen[f"l{i}_{j}"][beat]
    return mu, chol


def sample_model(dp: Datapath, kept: list[tuple[int, int]]):
    """Per step: sample_cond over all its beats and lanes; sat per particle."""
    n = dp.n

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        steps = seen[STEP]
        beats, lanes = seen["e0"].shape
        e = np.stack([seen[f"e{j}"] for j in range(n)], axis=-1)
        x = np.zeros((beats, lanes, n), dtype=np.int64)
        sat = np.zeros((beats, lanes), dtype=np.int64)
        for s in np.unique(steps):
            rows = steps == s
            mu, chol = step_operands(seen, n, int(np.argmax(rows)))
            flat = e[rows].reshape(-1, n)
            out, flags = sample_cond(dp, mu, chol, flat, kept, per_particle=True)
            x[rows] = out.reshape(-1, lanes, n)
            sat[rows] = (flags & Flag.SAT != 0).reshape(-1, lanes)
        return {**{f"x{i}": x[:, :, i] for i in range(n)}, "sat": sat}

    return model


def block(b: Bench, model=None) -> StreamBlock:
    dp = b.dp
    ins, outs, ops = fields(dp)
    return StreamBlock("sample_cond", ins, outs, b.cfg.lanes,
                       b.manifest["modules"]["sample_cond"]["latency"],
                       model or sample_model(dp, b.pairs), fields_op=ops)


# ---- stimulus ---------------------------------------------------------------------------------
def normal_draws(rng: np.random.Generator, fmt: Format, shape: tuple[int, ...]) -> np.ndarray:
    """N(0, 1) draws in the noise format, as the GRNG gives them."""
    raw = np.round(rng.standard_normal(shape) * (1 << fmt.frac_bits)).astype(np.int64)
    return np.clip(raw, fmt.min_raw, fmt.max_raw)


def random_e(b: Bench, n: int, tag: str) -> np.ndarray:
    """(beats, lanes, n): 3/4 Gaussian draws, 1/4 uniform over the whole noise format."""
    dp = b.dp
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    shape = (n, b.cfg.lanes, dp.n)
    wide = rng.integers(dp.noise.min_raw, dp.noise.max_raw + 1, size=shape)
    return np.where(rng.random(shape) < 0.75, normal_draws(rng, dp.noise, shape), wide)


def realistic_chol(dp: Datapath, rng: np.random.Generator, covariance: str,
                   sigma0: list[float]) -> np.ndarray:
    """L of a random covariance through the model's own Cholesky: standard deviations from
    the config's sigma0 up to half of L's range (log-uniform), random correlations, only the
    entries `covariance` keeps (uav "block": the [q] and [v] blocks)."""
    n = dp.n
    lo = np.sqrt(np.asarray(sigma0, dtype=float))
    hi = np.array([f.max_real / 2 for f in dp.chol])
    std = lo * (hi / lo) ** rng.random(n)
    g = rng.standard_normal((n, n))
    c = g @ g.T + rng.random() * n * np.eye(n)
    d = np.sqrt(np.diag(c))
    cov = np.outer(std, std) * c / np.outer(d, d)
    sigma = {}
    for i, j in cov_pairs(dp, covariance):
        fmt = dp.sigma(i, j)
        sigma[(i, j)] = int(np.clip(round(cov[i, j] * 2.0**fmt.frac_bits), fmt.min_raw,
                                    fmt.max_raw))
    return cholesky(dp, sigma)[0]


def random_chol(dp: Datapath, rng: np.random.Generator, style: int, sigma0: list[float]
                ) -> np.ndarray:
    """0, 1: realistic (block and full covariance); 2: every entry uniform over L's format;
    3: entries of every magnitude, random signs, some zero."""
    n = dp.n
    if style < 2:
        return realistic_chol(dp, rng, "block" if style == 0 else "full", sigma0)
    chol = np.zeros((n, n), dtype=np.int64)
    for i, j in pairs(n):
        fmt = dp.chol[i]
        if style == 2:
            chol[i, j] = rng.integers(fmt.min_raw, fmt.max_raw + 1)
        else:
            v = int(log_uniform(rng, fmt.width - 1, (1,))[0])
            chol[i, j] = 0 if rng.random() < 0.1 else (v if rng.random() < 0.5 else -v)
    return chol


def random_mu(dp: Datapath, rng: np.random.Generator, wide: bool) -> np.ndarray:
    """Uniform over the state formats (wide) or over their middle half (where estimates are)."""
    return np.array([rng.integers(f.min_raw // (1 if wide else 2),
                                  (f.max_raw // (1 if wide else 2)) + 1) for f in dp.x])


def operands_of(dp: Datapath, steps: list[tuple[np.ndarray, np.ndarray]]
                ) -> dict[str, np.ndarray]:
    """(mu, L) per step -> (steps,) per operand field."""
    out = {f"mu{i}": np.array([mu[i] for mu, _ in steps], dtype=np.int64) for i in range(dp.n)}
    out.update({f"l{i}_{j}": np.array([chol[i, j] for _, chol in steps], dtype=np.int64)
                for i, j in pairs(dp.n)})
    return out


def random_operands(b: Bench) -> Operands:
    """Each step: realistic L (block or full covariance) half the time, raw extremes else;
    mu in the middle of the range mostly, over all of it a quarter of the time."""
    dp = b.dp
    sigma0 = list(b.cfg.app_params["sigma0_diag"])

    def operands(steps: int, tag: str) -> dict[str, np.ndarray]:
        rng = np.random.default_rng(b.rng(f"{tag}-op").getrandbits(32))
        styles = rng.choice(4, size=steps, p=[0.25, 0.25, 0.25, 0.25])
        return operands_of(dp, [(random_mu(dp, rng, rng.random() < 0.25),
                                 random_chol(dp, rng, int(s), sigma0)) for s in styles])

    return operands


def random_inputs(b: Bench) -> Inputs:
    n = b.dp.n

    def inputs(beats: int, tag: str) -> dict[str, np.ndarray]:
        e = random_e(b, beats, tag)
        return {f"e{j}": e[:, :, j] for j in range(n)}

    return inputs


# ---- tests ------------------------------------------------------------------------------------
@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random draws, each step with its own random mu and L, random input gaps and output
    stalls: every x and sat bit-exact, tlast carried, operands kept per step."""
    b = bench()
    blk = block(b)
    await check_random_beats(dut, blk, b, random_inputs(b), stalls, random_operands(b))


def corner_steps(b: Bench) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(mu, L, e (beats, lanes, n)) per step: L = 0; e at its ends with L at its ends; mu at
    the ends with L e pushing out (both ways) and in; half-LSB ties; block and full L."""
    dp = b.dp
    sigma0 = list(b.cfg.app_params["sigma0_diag"])
    n, lanes, noise = dp.n, b.cfg.lanes, dp.noise
    rng = np.random.default_rng(b.rng("sample_cond-corners").getrandbits(32))
    xmin = np.array([f.min_raw for f in dp.x])
    xmax = np.array([f.max_raw for f in dp.x])
    lmax = np.array([f.max_raw for f in dp.chol])
    lmin = np.array([f.min_raw for f in dp.chol])
    ends = np.array([noise.min_raw, noise.max_raw, noise.min_raw + 1, noise.max_raw - 1, 0, 1,
                     -1])
    zero = np.zeros((n, n), dtype=np.int64)
    lower = np.tril(np.ones((n, n), dtype=bool))

    def e_of(*values: int, beats: int = 16) -> np.ndarray:
        return np.full((beats, lanes, n), 0, dtype=np.int64) + np.array(values)[:, None, None][
            np.arange(beats) % len(values)]

    def e_ends(beats: int = 32) -> np.ndarray:
        return rng.choice(ends, size=(beats, lanes, n))

    steps = [
        (np.zeros(n, dtype=np.int64), zero, e_ends()),                  # all zero but e
        (random_mu(dp, rng, True), zero, e_ends()),                     # L = 0: x = mu
        (xmax.copy(), zero, e_ends()), (xmin.copy(), zero, e_ends()),
        (np.zeros(n, dtype=np.int64), np.diag(lmax), e_ends()),         # e, L at their ends
        (np.zeros(n, dtype=np.int64), np.diag(lmin), e_ends()),
        (np.zeros(n, dtype=np.int64), np.where(lower, lmax[:, None], 0), e_ends()),
        (np.zeros(n, dtype=np.int64), np.where(lower, lmin[:, None], 0), e_ends()),
        # mu at an end, L e pushing out (saturates) or back in (does not)
        (xmax - 1, np.diag(lmax // 64), e_of(noise.max_raw, noise.max_raw // 8, 1, 0, -1,
                                             noise.min_raw)),
        (xmin + 1, np.diag(lmax // 64), e_of(noise.min_raw, noise.min_raw // 8, -1, 0, 1,
                                             noise.max_raw)),
        (xmax, np.where(lower, lmax[:, None], 0), e_ends()),
        (xmin, np.where(lower, lmax[:, None], 0), e_ends()),
    ]
    # half-LSB ties: L e one half of x's LSB and its neighbours, either sign, mu anywhere
    shift = [dp.chol[i].frac_bits + noise.frac_bits - dp.x[i].frac_bits for i in range(n)]
    for k in range(3):
        chol = np.diag([1 << min(k, dp.chol[i].width - 2) for i in range(n)])
        half = [1 << max(shift[i] - 1 - min(k, dp.chol[i].width - 2), 0) for i in range(n)]
        e = np.stack([np.array([h * m + d for m in (1, -1, 3, -3) for d in (-1, 0, 1)]
                               )[np.arange(24) % 12] for h in half], axis=-1)
        e = np.clip(e, noise.min_raw, noise.max_raw)[:, None, :].repeat(lanes, axis=1)
        steps.append((random_mu(dp, rng, True), chol, e))
    # realistic L, block and full, and raw extremes, with mu anywhere
    for style in (0, 1, 0, 1, 2, 3):
        steps.append((random_mu(dp, rng, True), random_chol(dp, rng, style, sigma0), e_ends()))
        steps.append((random_mu(dp, rng, False), random_chol(dp, rng, style, sigma0),
                      random_e(b, 32, f"corner-{style}-{len(steps)}")))
    return steps


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """Directed steps (corner_steps); checks that L = 0 gives x = mu and that saturation
    happened both ways."""
    b = bench()
    blk = block(b)
    dp = b.dp
    steps = corner_steps(b)
    e = np.concatenate([s[2] for s in steps])
    lasts = [beat == len(s[2]) - 1 for s in steps for beat in range(len(s[2]))]
    ops = operands_of(dp, [(mu, chol) for mu, chol, _ in steps])
    idle_inputs(dut)
    await start(dut)
    sb, _, out = await run_stream(dut, blk, b, {f"e{j}": e[:, :, j] for j in range(dp.n)},
                                  lasts, 0.2, 0.2, "sample_cond-corners", ops=ops)
    dut._log.info("%d corner steps, %d beats: %s", len(steps), len(e), sb.summary())
    sb.assert_clean()
    got = unpack([beat.data for beat in out.beats], blk.fields_out, b.cfg.lanes)
    x = np.stack([got[f"x{i}"] for i in range(dp.n)], axis=-1)
    mu1 = steps[1][0]
    rows = slice(len(steps[0][2]), len(steps[0][2]) + len(steps[1][2]))
    assert (x[rows] == mu1).all() and not got["sat"][rows].any(), "L = 0 must give x = mu"
    sat = got["sat"].astype(bool)
    up = sat & (x == np.array([f.max_raw for f in dp.x])).any(axis=-1)
    down = sat & (x == np.array([f.min_raw for f in dp.x])).any(axis=-1)
    assert up.any() and down.any(), "saturation must happen both ways in the corners"
    dut._log.info("saturated: %d up, %d down of %d particles", up.sum(), down.sum(), sat.size)


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: the first result LATENCY clocks after the first beat, then one a clock."""
    b = bench()
    blk = block(b)
    await check_latency_and_throughput(dut, blk, b, random_inputs(b),
                                       operands=random_operands(b))


@cocotb.test()
async def test_operands_change_while_busy(dut: SimHandleBase) -> None:
    """One-beat steps back to back without stalls: every beat is a new step whose operands
    arrive while the previous steps' beats are still in the pipeline."""
    b = bench()
    blk = block(b)
    n = 300
    idle_inputs(dut)
    await start(dut)
    sb, _, _ = await run_stream(dut, blk, b, random_inputs(b)(n, "op-busy"), [True] * n,
                                0.0, 0.0, "sample_cond-op-busy",
                                ops=random_operands(b)(n, "op-busy"))
    sb.assert_clean()


def wrong_rounding(b: Bench):
    """Deliberately wrong model: x_0's LSB flipped wherever e_0 mod 7 == 3."""
    right = sample_model(b.dp, b.pairs)

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = right(seen)
        return {**out, "x0": np.where(np.asarray(seen["e0"]) % 7 == 3, out["x0"] ^ 1,
                                      out["x0"])}
    return model


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    b = bench()
    blk = block(b, wrong_rounding(b))
    await check_corrupted_model_is_caught(dut, blk, b, random_inputs(b), random_operands(b))


"""cocotb testbench of `cholesky` (L with Sigma = L L^T, one matrix per beat): every L_ij and
the flags (SAT, NOT_PD) of every beat against gpf.model.blocks.cholesky_batch."""

from __future__ import annotations

import math
from unittest import mock

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model import blocks
from gpf.model.blocks import Flag
from gpf.model.fixed import Format
from gpf.model.formats import CHOL_FLOOR_LSB, CHOL_FLOOR_REL_BITS
from gpf.rtl.generate import cholesky_context, covariance_pairs
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field, unpack
from gpf.tb.streaming import (
    Inputs,
    StreamBlock,
    check_latency_and_throughput,
    check_random_beats,
    idle_inputs,
    run_stream,
)

FLAGS = Format.parse("u3.0")


def lower(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i + 1)]


def cholesky_model(b: Bench):
    dp, pairs = b.dp, b.pairs

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        # every beat in one call: the model's exact arithmetic is vectorised over matrices
        # (one call per matrix made the model 3/4 of this testbench's time)
        sigma = np.stack([np.asarray(seen[f"s{i}{j}"])[:, 0] for i, j in pairs], axis=1)
        chol, flags = blocks.cholesky_batch(dp, sigma, pairs)
        out = {f"l{i}{j}": chol[:, i, j, None] for i, j in lower(dp.n)}
        out["flags"] = np.asarray(flags, dtype=np.int64)[:, None]
        return out

    return model


def block(b: Bench, model=None) -> StreamBlock:
    dp, pairs = b.dp, b.pairs
    k = cholesky_context(b.cfg)
    assert pairs == covariance_pairs(b.cfg)
    assert b.manifest["modules"]["cholesky"]["latency"] == k["latency"]
    fields_in = [Field(f"s{i}{j}", dp.sigma(i, j)) for i, j in pairs]
    fields_out = [Field(f"l{i}{j}", dp.chol[i]) for i, j in lower(dp.n)] + [Field("flags", FLAGS)]
    assert sum(f.fmt.width for f in fields_in) == k["in_width"]
    assert sum(f.fmt.width for f in fields_out) == k["out_width"]
    return StreamBlock("cholesky", fields_in, fields_out, 1, k["latency"],
                       model or cholesky_model(b), interval=k["interval"])


# ---- stimulus: Sigma from a real L, quantised to Sigma's formats ------------------------------
def to_raw(b: Bench, sigma: np.ndarray) -> dict[tuple[int, int], int]:
    """Real Sigma (n, n) -> raw entries of the pairs, rounded and clipped to their formats."""
    dp = b.dp
    out = {}
    for i, j in b.pairs:
        fmt = dp.sigma(i, j)
        raw = math.floor(float(sigma[i, j]) * 2.0 ** fmt.frac_bits + 0.5) if math.isfinite(
            sigma[i, j]) else fmt.max_raw
        out[(i, j)] = min(max(raw, fmt.min_raw), fmt.max_raw)
    return out


def scales(b: Bench, rng: np.random.Generator, kind: str) -> np.ndarray:
    """Per-component standard deviations: around the config's sigma0 (times 10^-1 .. 10^2), or
    log-uniform from 2^5 LSB of L (below that most pivots floor) to the format's top."""
    dp = b.dp
    if kind == "realistic":
        sd0 = np.sqrt(np.asarray(b.cfg.app_params["sigma0_diag"], dtype=float))
        return sd0 * 10.0 ** rng.uniform(-1, 2, dp.n)
    lo = np.array([5 - f.frac_bits for f in dp.chol], dtype=float)
    hi = np.array([f.int_bits + 1 for f in dp.chol], dtype=float)
    return 2.0 ** rng.uniform(lo, hi)


def random_l(rng: np.random.Generator, n: int, corr: float) -> np.ndarray:
    """A lower-triangular factor with positive diagonal and correlations of strength `corr`."""
    c = np.tril(rng.normal(size=(n, n)) * corr, -1)
    return c + np.diag(rng.uniform(0.05, 1.0, n))


def random_sigma(b: Bench, rng: np.random.Generator) -> dict[tuple[int, int], int]:
    """One matrix from a mixture: SPD (realistic or any scale, weak to strong correlations),
    rank-deficient, not positive definite (a diagonal entry lowered or negative), the zero
    matrix, a huge diagonal (L saturates), tiny diagonals near the floor."""
    n = b.dp.n
    kind = rng.choice(["realistic", "wide", "singular", "notpd", "zero", "huge", "tiny"],
                      p=[0.35, 0.25, 0.12, 0.1, 0.02, 0.08, 0.08])
    corr = float(rng.choice([0.0, 0.3, 1.0, 5.0]))
    if kind == "zero":
        return to_raw(b, np.zeros((n, n)))
    if kind == "tiny":
        return tiny_sigma(b, rng)
    sd = scales(b, rng, "realistic" if kind in ("realistic", "singular", "notpd") else "wide")
    fac = random_l(rng, n, corr)
    if kind == "singular":   # some columns of L dropped: Sigma of rank < n
        fac[:, rng.random(n) < 0.4] = 0.0
    sig = (fac @ fac.T) * np.outer(sd, sd)
    if kind == "notpd":
        j = int(rng.integers(n))
        sig[j, j] = sig[j, j] * rng.uniform(-1.0, 0.9)
    if kind == "huge":       # diagonals up to the format's maximum
        j = rng.random(n) < 0.5
        sig[j, j] = 2.0 ** rng.uniform(30, 60, int(j.sum()))
    return to_raw(b, sig)


def tiny_sigma(b: Bench, rng: np.random.Generator) -> dict[tuple[int, int], int]:
    """Pivots at a floor's edge (within a few LSB^2): a diagonal entry at the absolute floor
    CHOL_FLOOR_LSB^2, or (half the time) a pair a, a+1 with L_aa = x, L_(a+1)a = y exactly
    (Sigma_aa = x^2, Sigma_(a+1)a = x y, |x|, |y| < 2^15 so L_(a+1)a = round(x y / x) = y) and
    Sigma_(a+1)(a+1) = y^2 + (y^2 >> REL) + delta: a pivot at the relative floor."""
    dp, pairs = b.dp, b.pairs
    fl = CHOL_FLOOR_LSB**2
    raw = {p: 0 for p in pairs}
    for j in range(dp.n):
        raw[(j, j)] = fl + int(rng.integers(0, 1 << 12))
    edge = int(rng.integers(dp.n))
    raw[(edge, edge)] = fl + int(rng.integers(-2, 3))
    a = int(rng.integers(dp.n - 1))
    if rng.random() < 0.5 and (a + 1, a) in raw:
        x, y = int(rng.integers(1 << 8, 1 << 15)), int(rng.integers(1 << 12, 1 << 15))
        y *= int(rng.choice([-1, 1]))
        raw[(a, a)], raw[(a + 1, a)] = x * x, x * y
        raw[(a + 1, a + 1)] = y * y + ((y * y) >> CHOL_FLOOR_REL_BITS) + int(rng.integers(-2, 3))
    return {p: min(max(v, dp.sigma(*p).min_raw), dp.sigma(*p).max_raw) for p, v in raw.items()}


def stack(b: Bench, mats: list[dict[tuple[int, int], int]]) -> dict[str, np.ndarray]:
    return {f"s{i}{j}": np.array([[m[(i, j)]] for m in mats], dtype=np.int64)
            for i, j in b.pairs}


async def run_matrices(dut: SimHandleBase, blk: StreamBlock, b: Bench,
                       mats: list[dict[tuple[int, int], int]], stalls: float, tag: str,
                       expect_mismatch: bool = False):
    """One matrix a beat through a serial matrix block (this one or sigma_predict), random
    stalls both sides; returns run_stream's (scoreboard, source, sink)."""
    idle_inputs(dut)
    await start(dut)
    return await run_stream(dut, blk, b, stack(b, mats), [True] * len(mats), stalls, stalls,
                            tag, expect_mismatch=expect_mismatch)


async def check_wrong_model_caught(dut: SimHandleBase, blk: StreamBlock, b: Bench,
                                   tag: str) -> None:
    """200 random matrices against a deliberately wrong model: the scoreboard must mismatch."""
    rng = np.random.default_rng(b.rng("bad").getrandbits(32))
    mats = [random_sigma(b, rng) for _ in range(200)]
    sb, _, _ = await run_matrices(dut, blk, b, mats, 0.2, tag, expect_mismatch=True)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)


def random_inputs(b: Bench) -> Inputs:
    def inputs(n: int, tag: str) -> dict[str, np.ndarray]:
        rng = np.random.default_rng(b.rng(tag).getrandbits(32))
        return stack(b, [random_sigma(b, rng) for _ in range(n)])

    return inputs


def corner_sigmas(b: Bench) -> list[dict[tuple[int, int], int]]:
    """Zero, identity-like, the maximum diagonal (every L_jj saturates), the most negative
    entries, full-range off-diagonals (L_ij saturates), exact floor values, a negative pivot,
    rank one, and random matrices of every kind."""
    dp, pairs = b.dp, b.pairs
    fl = CHOL_FLOOR_LSB**2
    lw = dp.chol[0].width          # L's word
    rng = np.random.default_rng(b.rng("cholesky-corners").getrandbits(32))

    def mat(fn) -> dict[tuple[int, int], int]:
        return {(i, j): min(max(int(fn(i, j)), dp.sigma(i, j).min_raw), dp.sigma(i, j).max_raw)
                for i, j in pairs}

    mats = [
        mat(lambda i, j: 0),
        mat(lambda i, j: (1 << dp.cov_frac(i, i)) if i == j else 0),
        mat(lambda i, j: dp.sigma(i, j).max_raw if i == j else 0),
        mat(lambda i, j: dp.sigma(i, j).max_raw),
        mat(lambda i, j: dp.sigma(i, j).min_raw),
        mat(lambda i, j: fl if i == j else 0),
        mat(lambda i, j: fl - 1 if i == j else 0),
        mat(lambda i, j: fl + 1 if i == j else 0),
        mat(lambda i, j: fl if i == j else dp.sigma(i, j).max_raw),
        mat(lambda i, j: fl if i == j else dp.sigma(i, j).min_raw),
        mat(lambda i, j: 1 << 40 if i == j else (1 << 40) - 1),         # rank one, nearly
        mat(lambda i, j: 1 << 40 if i == j else 1 << 39),
        mat(lambda i, j: -(1 << 30) if i == j else 0),                   # negative pivots
        mat(lambda i, j: (1 << 20) if i == j else (1 << 20) - (1 << 4)),  # relative floor edge
        mat(lambda i, j: (1 << 34) if i == j else (1 << 34) - (1 << 18)),
        mat(lambda i, j: (1 << 34) if i == j else (1 << 34) - (1 << 17)),
        mat(lambda i, j: (1 << 33) if i == j else (1 << 33) - (1 << 17) + 1),
        mat(lambda i, j: (1 << (2 * lw - 2)) - (1 << lw) if i == j else 0),   # L_jj at its top
        mat(lambda i, j: (1 << (2 * lw - 2)) if i == j else 0),
        mat(lambda i, j: 300 if i == j else (1 << 40) * (-1) ** (i + j)),   # L_ij saturates
    ]
    mats += [tiny_sigma(b, rng) for _ in range(40)]
    mats += [random_sigma(b, rng) for _ in range(100)]
    return mats


@cocotb.test()
@cocotb.parametrize(stalls=[(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)])
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Random matrices (one per beat, tlast on every beat) with random input gaps and output
    stalls: every L_ij and the flags bit-exact."""
    b = bench()
    # every=1: tlast on every beat (a step is one matrix); 10,000 matrices in the main shape
    await check_random_beats(dut, block(b), b, random_inputs(b), stalls, every=1)


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """Directed corners (corner_sigmas): SAT and NOT_PD must both really happen."""
    b = bench()
    blk = block(b)
    mats = corner_sigmas(b)
    sb, _, out = await run_matrices(dut, blk, b, mats, 0.2, "cholesky-corners")
    dut._log.info("%d corner matrices: %s", len(mats), sb.summary())
    sb.assert_clean()
    flags = unpack([beat.data for beat in out.beats], blk.fields_out, 1)["flags"][:, 0]
    assert np.any(flags & Flag.SAT), "no corner saturated"
    assert np.any(flags & Flag.NOT_PD), "no corner was floored"
    assert np.any(flags == 0), "no corner was clean"
    assert np.any(flags == Flag.SAT | Flag.NOT_PD), "SAT and NOT_PD never together"


@cocotb.test()
async def test_floor_edge(dut: SimHandleBase) -> None:
    """Matrices around both floors only: pivots just below, at and above each."""
    b = bench()
    blk = block(b)
    rng = np.random.default_rng(b.rng("cholesky-floor").getrandbits(32))
    mats = [tiny_sigma(b, rng) for _ in range(200)]
    sb, _, out = await run_matrices(dut, blk, b, mats, 0.1, "cholesky-floor")
    sb.assert_clean()
    flags = unpack([beat.data for beat in out.beats], blk.fields_out, 1)["flags"][:, 0]
    floored = float(np.mean((flags & Flag.NOT_PD) != 0))
    dut._log.info("floor edge: %s, %.0f%% floored", sb.summary(), 100 * floored)
    assert 0.05 < floored < 0.95, f"floor edge not straddled: {floored:.2f} floored"


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: L LATENCY clocks after its beat, a new matrix every INTERVAL clocks."""
    b = bench()
    await check_latency_and_throughput(dut, block(b), b, random_inputs(b), n=100)


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """Deliberately wrong model: L_ij = num / L_jj rounded toward -inf instead of to nearest."""
    b = bench()
    good = cholesky_model(b)

    def floor_div(num, den, shift):
        return np.floor_divide(np.asarray(num, dtype=object) * 2**shift, den)

    def bad(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        with mock.patch.object(blocks, "div_round", floor_div):
            return good(seen)

    await check_wrong_model_caught(dut, block(b, bad), b, "cholesky-bad")

"""cocotb testbench of `moments`: one result beat per step (mu, Sigma, flags, ESS) against the
model's moments() (accumulate with the rescales + finalise, + normalise_quaternion for uav),
bit-exact.

A step is built whole (its reference, its particles around it, their exponents t) so that
particles are realistic: a spread around ref, t exponential with a random scale; the weights and
each beat's shift then come from the weight block's own model (relative_weights), as in the
filter: relative to the best particle so far, rescaling the sums whenever a beat brings a new
best. The corner test adds the edges: no particle within reach, one particle carrying the
weight, all weights 1.0, a new best on every beat (and shifts that clear the sums), x far from
ref (dx saturates), 1-beat steps, a full step of cfg.particles particles with the extreme values
that size the accumulators, Sigma near zero, (uav) tiny or zero quaternions, and an ESS
quotient exactly on a rounding boundary (ess_boundary: W^2 must be exact to its last bit)."""

from __future__ import annotations

import cocotb
import numpy as np
from cocotb.handle import SimHandleBase

from gpf.model.blocks import accumulate, moments, reach_top, relative_weights
from gpf.model.fixed import Format, saturate
from gpf.model.formats import SHIFT_BITS, Datapath
from gpf.model.primitives import div_round
from gpf.tb.harness import Bench, bench, start
from gpf.tb.scoreboard import Field, unpack
from gpf.tb.streaming import (
    STEP,
    StreamBlock,
    check_latency_and_throughput,
    idle_inputs,
    random_beat_count,
    run_stream,
)

FLAGS = Format(False, 3, 0)
SHIFT = Field("shift", Format(False, SHIFT_BITS, 0))
STALLS = [(0.0, 0.0), (0.3, 0.3), (0.1, 0.7), (0.7, 0.1)]


def sigma_name(i: int, j: int) -> str:
    return f"s{i}_{j}"


def step_particles(seen: dict[str, np.ndarray], rows: np.ndarray, n: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """x (N, n), w (N,), shift (beats,) and ref (n,) of the beats `rows` (lanes flattened)."""
    x = np.stack([seen[f"x{i}"][rows].reshape(-1) for i in range(n)], axis=1)
    w = seen["w"][rows].reshape(-1)
    ref = np.array([seen[f"ref{i}"][rows][0] for i in range(n)], dtype=np.int64)
    return x, w, seen["shift"][rows, 0], ref


def without_mean_product(dp: Datapath, x: np.ndarray, w: np.ndarray, shift: np.ndarray,
                         ref: np.ndarray, pairs: list[tuple[int, int]], sigma: dict) -> dict:
    """The corrupted model's Sigma: the second moment about ref, m_i m_j not subtracted."""
    sums, _ = accumulate(dp, x[None], w[None], shift[None], ref[None], pairs)
    m = [int(div_round(sums.s1[0, i], sums.w[0], dp.chol[i].frac_bits - dp.x[i].frac_bits))
         for i in range(dp.n)]
    return {(i, j): int(saturate(v + m[i] * m[j], dp.sigma(i, j))[0])
            for (i, j), v in sigma.items()}


def moments_model(b: Bench, corrupt: bool = False):
    dp, pairs = b.dp, b.pairs

    def model(seen: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out: dict[str, list[int]] = {}
        for s in np.unique(seen[STEP]):
            x, w, shift, ref = step_particles(seen, seen[STEP] == s, dp.n)
            mu, sigma, ess, flags = moments(dp, x, w, shift, ref, pairs)
            if corrupt:
                sigma = without_mean_product(dp, x, w, shift, ref, pairs, sigma)
            values = {f"mu{i}": int(mu[i]) for i in range(dp.n)}
            values |= {sigma_name(i, j): int(sigma[(i, j)]) for i, j in pairs}
            values |= {"flags": int(flags), "ess": ess}
            for k, v in values.items():
                out.setdefault(k, []).append(v)
        return {k: np.array(v, dtype=np.int64)[:, None] for k, v in out.items()}

    return model


def block(b: Bench, model=None) -> StreamBlock:
    dp = b.dp
    fields_in = [Field(f"x{i}", dp.x[i]) for i in range(dp.n)] + [Field("w", dp.weight)]
    fields_op = [Field(f"ref{i}", dp.x[i]) for i in range(dp.n)]
    fields_out = [Field(f"mu{i}", dp.x[i]) for i in range(dp.n)]
    fields_out += [Field(sigma_name(i, j), dp.sigma(i, j)) for i, j in b.pairs]
    fields_out += [Field("flags", FLAGS), Field("ess", dp.ess)]
    return StreamBlock("moments", fields_in, fields_out, b.cfg.lanes,
                       b.manifest["modules"]["moments"]["latency"], model or moments_model(b),
                       fields_op=fields_op, reduces=True, beat_in=[SHIFT])


# ---- stimulus: whole steps -------------------------------------------------------------------

class Steps:
    """Steps collected into the kit's shapes: inputs (beats, lanes), lasts, ops (steps,)."""

    def __init__(self, b: Bench):
        self.dp = b.dp
        self.lanes = b.cfg.lanes
        self.max_beats = b.cfg.particles // b.cfg.lanes   # a step holds at most N particles
        self.x: list[np.ndarray] = []
        self.w: list[np.ndarray] = []
        self.shift: list[np.ndarray] = []
        self.refs: list[np.ndarray] = []

    def add(self, x: np.ndarray, t: np.ndarray, ref: np.ndarray) -> None:
        """x (beats, lanes, n), the exponents t (beats, lanes) as reals (clipped to the t
        format), ref (n,); the weights and shifts as the weight block makes them."""
        assert 1 <= len(t) <= self.max_beats
        dp = self.dp
        lo = np.array([f.min_raw for f in dp.x])
        hi = np.array([f.max_raw for f in dp.x])
        raw_t = np.clip(np.floor(np.asarray(t, float) * 2**dp.t.frac_bits), 0, dp.t.max_raw)
        w, shift = relative_weights(dp, raw_t.astype(np.int64).reshape(-1), self.lanes)
        self.x.append(np.clip(np.asarray(x, dtype=np.int64), lo, hi))
        self.w.append(w.reshape(len(t), self.lanes))
        self.shift.append(shift)
        self.refs.append(np.clip(np.asarray(ref, dtype=np.int64), lo, hi))

    def inputs(self) -> dict[str, np.ndarray]:
        x = np.concatenate(self.x)
        out = {f"x{i}": x[:, :, i] for i in range(self.dp.n)}
        out["w"] = np.concatenate(self.w)
        out["shift"] = np.concatenate(self.shift)[:, None]
        return out

    def lasts(self) -> list[bool]:
        return [k == len(w) - 1 for w in self.w for k in range(len(w))]

    def ops(self) -> dict[str, np.ndarray]:
        refs = np.array(self.refs)
        return {f"ref{i}": refs[:, i] for i in range(self.dp.n)}


def realistic_ref(dp: Datapath, rng: np.random.Generator) -> np.ndarray:
    """bot: positions and velocities within half the range; uav: a unit quaternion (as raw)
    and velocities within half the range."""
    half = np.array([f.max_raw // 2 for f in dp.x])
    ref = rng.integers(-half, half + 1)
    if dp.app == "uav":
        q = rng.normal(size=4)
        ref[:4] = np.round(q / np.linalg.norm(q) * (1 << dp.x[0].frac_bits))
    return ref


def exponents(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """t exponential with a random scale (peaked or flat sets of weights), offset by a random
    best (the weights are relative to it), some particles far away."""
    t = rng.exponential(rng.uniform(0.3, 12.0), size=shape) + rng.choice([0.0, 3.0, 200.0])
    return np.where(rng.random(shape) < rng.choice([0.0, 0.05, 0.5]), rng.uniform(
        30, 1100, size=shape), t)


def realistic_step(s: Steps, rng: np.random.Generator, beats: int) -> None:
    """Particles around ref (a per-component spread from a few LSB to 1/8 of the range; now
    and then the whole cloud offset, so that mu moves away from ref), exp-like weights."""
    dp = s.dp
    ref = realistic_ref(dp, rng)
    spread = 2.0 ** rng.uniform(1, dp.word - 4, size=dp.n)
    offset = np.where(rng.random(dp.n) < 0.3, rng.normal(size=dp.n) * spread * 4, 0)
    x = ref + offset + rng.normal(size=(beats, s.lanes, dp.n)) * spread
    s.add(np.round(x), exponents(rng, (beats, s.lanes)), ref)


def step_lengths(rng: np.random.Generator, total: int, max_beats: int) -> list[int]:
    """Random lengths (mostly about 64 beats, some single beats, some long) up to `total`."""
    out: list[int] = []
    while sum(out) < total:
        kind = rng.random()
        n = 1 if kind < 0.05 else int(rng.integers(100, 400)) if kind < 0.15 else int(
            rng.geometric(1 / 64))
        out.append(min(n, max_beats, total - sum(out)))
    return out


def random_steps(b: Bench, total: int, tag: str) -> Steps:
    rng = np.random.default_rng(b.rng(tag).getrandbits(32))
    s = Steps(b)
    for beats in step_lengths(rng, total, s.max_beats):
        realistic_step(s, rng, beats)
    return s


def ess_boundary(dp: Datapath, lanes: int, max_beats: int) -> tuple[int, int, int] | None:
    """(n_one, n_low, t_low): the fewest particles, n_one of weight 1.0 (t = 0) then n_low of
    weight 2^-t_low, whose ESS quotient W^2 / sum w^2 sits exactly on a rounding boundary
    (W^2 2^(f+1) an odd multiple of sum w^2): W^2 even one LSB off moves the rounded ESS. None
    if no such step fits."""
    f = dp.ess.frac_bits
    one = int(dp.exp2(np.array([0]))[0])
    for total in range(lanes, max_beats * lanes + 1, lanes):
        for t_low in (1, 2, 3):
            low = int(dp.exp2(np.array([t_low << dp.t.frac_bits]))[0])
            for n_low in range(1, total):
                n_one = total - n_low
                w = n_one * one + n_low * low
                ww = n_one * one * one + n_low * low * low
                if ((w * w) << (f + 1)) % (2 * ww) == ww:
                    return n_one, n_low, t_low
    return None


def corner_steps(b: Bench) -> Steps:
    s = Steps(b)
    dp, lanes, n = s.dp, s.lanes, s.dp.n
    rng = np.random.default_rng(b.rng("moments-corners").getrandbits(32))
    top = float(reach_top(dp))
    xmin = np.array([f.min_raw for f in dp.x])
    xmax = np.array([f.max_raw for f in dp.x])

    def around(beats: int, spread: float = 64.0) -> tuple[np.ndarray, np.ndarray]:
        ref = realistic_ref(dp, rng)
        return np.round(ref + rng.normal(size=(beats, lanes, n)) * spread), ref

    x, ref = around(40)
    s.add(x, rng.uniform(top, top + 1, (40, lanes)), ref)       # no particle within reach
    s.add(np.broadcast_to(xmin, (5, lanes, n)), np.full((5, lanes), 2 * top), xmax)  # and SAT
    for t1 in (0.0, 0.99, 17.0, 300.0):                         # one particle carries the weight
        x, ref = around(30)
        t = np.full((30, lanes), t1 + 40.0)
        t[rng.integers(30), rng.integers(lanes)] = t1
        s.add(x, t, ref)
    x, ref = around(50, 3000.0)
    s.add(x, np.zeros((50, lanes)), ref)                       # all weights 1.0
    x, ref = around(60, 500.0)                                 # a new best on every beat
    s.add(x, np.linspace(900, 0, 60)[:, None] + rng.uniform(0, 0.5, (60, lanes)), ref)
    x, ref = around(40, 500.0)                                 # shifts of 1 .. 127 (capped)
    s.add(x, np.repeat([1000.0, 990, 900, 800, 700, 573, 446, 319, 192, 64, 63, 62, 61, 60,
                        59, 58, 50, 40, 30, 20], 2)[:, None] + np.zeros((1, lanes)), ref)
    x, ref = around(20, 3000.0)                                # far from ref: dx saturates
    s.add(np.where(rng.random(x.shape) < 0.2, xmin, x), exponents(rng, (20, lanes)),
          np.where(rng.random(n) < 0.5, xmax, xmin))
    for t1 in (0.0, 5.5, top + 0.5):                            # 1-beat steps
        x, ref = around(1, 1000.0)
        s.add(x, np.full((1, lanes), t1), ref)
    for c in (0, 1, -3):                                       # Sigma (near) zero
        x, ref = around(60)
        x = np.broadcast_to(ref + c, x.shape) + (rng.random(x.shape) < 0.05)
        s.add(x, exponents(rng, (60, lanes)), ref)
    full = s.max_beats                                         # the accumulators' widths
    ones = np.zeros((full, lanes))                             # w = 1.0, the largest
    s.add(np.broadcast_to(xmin, (full, lanes, n)), ones, xmax)  # dx = min everywhere
    mixed = np.where(np.arange(n) % 2 == 0, xmin, xmax)         # dx_i dx_j most negative
    s.add(np.broadcast_to(mixed, (full, lanes, n)), ones, np.zeros(n))
    s.add(np.broadcast_to(xmax, (full, lanes, n)), ones, xmin)  # dx = max (saturated)
    late = np.full((full, lanes), 126.0)                        # full sums, then cleared
    late[-1] = 0.0
    s.add(np.broadcast_to(xmax, (full, lanes, n)), late, xmin)
    for edge in (xmax, xmin):                                  # the mean at its format's edges
        s.add(np.broadcast_to(edge, (8, lanes, n)), np.zeros((8, lanes)), edge)
    # the covariance at its edges: particles split between two opposite corners, equal weights,
    # ref between them (every component together; odd against even components)
    apart = (np.arange(16) % 2 == 0)[:, None, None]
    for a, b in ((xmax, xmin), (mixed, np.where(np.arange(n) % 2 == 0, xmax, xmin))):
        s.add(np.where(apart, a, b) + np.zeros((16, lanes, n)), np.zeros((16, lanes)),
              np.zeros(n))
    if dp.app == "uav":                                        # tiny and zero quaternions
        for q in ([0, 0, 0, 0], [1, 0, 0, 0], [1, 1, 1, 0], [-1, 1, -1, 1], [0, 0, 0, -3]):
            ref = realistic_ref(dp, rng)
            ref[:4] = q
            x = np.broadcast_to(ref, (3, lanes, n)).copy()
            x[..., 4:] += rng.integers(-50, 51, size=(3, lanes, n - 4))
            s.add(x, exponents(rng, (3, lanes)), ref)
    boundary = ess_boundary(dp, lanes, s.max_beats)   # W^2 exact to its last bit
    if boundary:
        n_one, n_low, t_low = boundary
        x, ref = around((n_one + n_low) // lanes)
        s.add(x, np.r_[np.zeros(n_one), np.full(n_low, float(t_low))].reshape(-1, lanes), ref)
    for _ in range(10):
        realistic_step(s, rng, int(rng.integers(1, 80)))
    return s


# ---- tests -----------------------------------------------------------------------------------

async def run_steps(dut: SimHandleBase, b: Bench, s: Steps, stalls: tuple[float, float],
                    tag: str, blk: StreamBlock | None = None, expect_mismatch: bool = False):
    idle_inputs(dut)
    await start(dut)
    return await run_stream(dut, blk or block(b), b, s.inputs(), s.lasts(), *stalls, tag,
                            expect_mismatch=expect_mismatch, ops=s.ops())


@cocotb.test()
@cocotb.parametrize(stalls=STALLS)
async def test_random_beats(dut: SimHandleBase, stalls: tuple[float, float]) -> None:
    """Realistic steps of random length, random input gaps and output stalls: every mu, Sigma
    and flag bit-exact."""
    b = bench()
    tag = f"moments-{stalls}"
    s = random_steps(b, random_beat_count(b, stalls), tag)
    sb, _, _ = await run_steps(dut, b, s, stalls, tag)
    dut._log.info("stalls in/out %s, %d steps: %s", stalls, len(s.w), sb.summary())
    sb.assert_clean()


@cocotb.test()
async def test_corners(dut: SimHandleBase) -> None:
    """The corner steps (corner_steps); ZERO_WEIGHTS (no particle within reach) and SAT must both
    really occur."""
    b = bench()
    s = corner_steps(b)
    blk = block(b)
    sb, _, out = await run_steps(dut, b, s, (0.2, 0.2), "moments-corners", blk)
    dut._log.info("%d corner steps: %s", len(s.w), sb.summary())
    sb.assert_clean()
    flags = unpack([beat.data for beat in out.beats], blk.fields_out, 1)["flags"][:, 0]
    assert (flags & 2).any() and (flags & 1).any() and not (flags & 4).any(), flags


@cocotb.test()
async def test_latency_and_throughput(dut: SimHandleBase) -> None:
    """Without stalls: one step of 500 beats (fewer if the config's N / LANES is) at a beat a
    clock, its result LATENCY clocks after the last beat."""
    b = bench()
    cache: dict[str, Steps] = {}
    beats = min(500, Steps(b).max_beats)

    def steps(tag: str) -> Steps:
        if tag not in cache:
            rng = np.random.default_rng(b.rng(tag).getrandbits(32))
            cache[tag] = Steps(b)
            realistic_step(cache[tag], rng, beats)
        return cache[tag]

    await check_latency_and_throughput(
        dut, block(b), b, lambda n, tag: steps(tag).inputs(), n=beats,
        operands=lambda n, tag: steps(tag).ops())


@cocotb.test()
async def test_back_to_back_steps(dut: SimHandleBase) -> None:
    """Short steps with no gaps: each waits for the previous result, none is lost."""
    b = bench()
    rng = np.random.default_rng(b.rng("moments-b2b").getrandbits(32))
    s = Steps(b)
    for _ in range(40):
        realistic_step(s, rng, int(rng.integers(1, 4)))
    sb, _, _ = await run_steps(dut, b, s, (0.0, 0.0), "moments-b2b")
    sb.assert_clean()


@cocotb.test()
async def test_corrupted_model_is_caught(dut: SimHandleBase) -> None:
    """Deliberately wrong model: Sigma about ref instead of about the mean (m_i m_j kept)."""
    b = bench()
    s = random_steps(b, 1_000, "moments-bad")
    sb, _, _ = await run_steps(dut, b, s, (0.2, 0.2), "moments-bad",
                               block(b, moments_model(b, corrupt=True)), expect_mismatch=True)
    assert sb.mismatched > 0 and sb.first_mismatch is not None, "a wrong model passed"
    dut._log.info("corrupted model caught: %s", sb.first_mismatch)

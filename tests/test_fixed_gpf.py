"""The bit-exact fixed-point GPF blocks: against exact rationals where the block is exact,
against numpy/float64 where it approximates, and the fault paths."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from gpf.config import load_config
from gpf.model import blocks
from gpf.model.blocks import Flag
from gpf.model.fixed_gpf import FixedGPF, run
from gpf.model.float_gpf import FloatGPF, propagate_uav, weight_bot
from gpf.model.formats import datapath
from gpf.model.scenarios import bot_fixed_observer, uav_flight

BOT = load_config("configs/bot.toml")
UAV = load_config("configs/uav.toml")
WIDE = 24  # the exactness tests below size their raw inputs for 24-bit words


def frac_round(value: Fraction) -> int:
    """Round half up, exactly."""
    return math.floor(value + Fraction(1, 2))


def random_spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    a = rng.normal(size=(n, n)) * scale
    return a @ a.T + np.eye(n) * scale**2 * 0.1


def quantise_sigma(dp, sigma: np.ndarray, pairs) -> dict:
    return {(i, j): math.floor(sigma[i, j] * 2.0 ** dp.cov_frac(i, j) + 0.5) for i, j in pairs}


def test_sample_cond_is_exact() -> None:
    dp = datapath(BOT, WIDE)
    rng = np.random.default_rng(1)
    mu = rng.integers(-(1 << 18), 1 << 18, size=4)
    chol = np.tril(rng.integers(-(1 << 18), 1 << 18, size=(4, 4)))
    e = rng.integers(-(1 << 16), 1 << 16, size=(200, 4))
    x, flags = blocks.sample_cond(dp, mu, chol, e)
    assert flags == 0
    for p in range(0, 200, 37):
        for i in range(4):
            exact = Fraction(int(mu[i]), 2 ** dp.x[i].frac_bits) + sum(
                Fraction(int(chol[i, j]) * int(e[p, j]),
                         2 ** (dp.chol[i].frac_bits + dp.noise.frac_bits)) for j in range(i + 1))
            assert x[p, i] == frac_round(exact * 2 ** dp.x[i].frac_bits)


def test_sample_cond_saturates_with_flag() -> None:
    dp = datapath(BOT)
    mu = np.full(4, dp.x[0].max_raw - 10)
    chol = np.eye(4, dtype=np.int64) * (1 << dp.chol[0].frac_bits)   # L = I
    e = np.full((3, 4), 1 << dp.noise.frac_bits)                       # e = 1
    x, flags = blocks.sample_cond(dp, mu, chol, e)
    assert flags & Flag.SAT and np.all(x == dp.x[0].max_raw)


def test_propagate_bot_is_exact() -> None:
    dp = datapath(BOT, WIDE)
    rng = np.random.default_rng(2)
    x = rng.integers(-(1 << 20), 1 << 20, size=(50, 4))
    e = rng.integers(-(1 << 16), 1 << 16, size=(50, 2))
    out, _ = blocks.propagate_bot(dp, x, e)
    c = dp.consts
    fx, fe = dp.x[0].frac_bits, dp.noise.frac_bits

    def real(raw, frac):
        return Fraction(int(raw), 2**frac)

    for p in range(50):
        for axis in range(2):
            pos, vel, draw = x[p, 2 * axis], x[p, 2 * axis + 1], e[p, axis]
            new_p = (real(pos, fx) + real(c["T"].raw, c["T"].frac) * real(vel, fx)
                     + real(c["a"].raw, c["a"].frac) * real(draw, fe))
            new_v = real(vel, fx) + real(c["b"].raw, c["b"].frac) * real(draw, fe)
            assert out[p, 2 * axis] == frac_round(new_p * 2**fx)
            assert out[p, 2 * axis + 1] == frac_round(new_v * 2**fx)


def test_weight_bot_close_to_float() -> None:
    gpf = FixedGPF(BOT, particles=256, word=WIDE)
    dp = gpf.dp
    rng = np.random.default_rng(3)
    xr = np.column_stack([rng.uniform(1, 3, 256), np.zeros(256), rng.uniform(2, 4, 256),
                          np.zeros(256)])
    x = np.array([[dp.x[i].from_real(v)[0] for i, v in enumerate(row)] for row in xr])
    inputs = {"z": 1.15, "observer": (0.0, 0.0)}
    w, _ = gpf.weight(x, gpf.quantise_inputs(inputs))
    w_real = dp.weight.to_real(w)
    w_float = weight_bot(dp_real_state(gpf, x), 1.15, np.zeros(2), BOT)
    # CORDIC and 2^-x are approximations: a few weight LSB, plus the bearing's quantisation
    assert np.max(np.abs(w_real - w_float)) < 2e-4


def dp_real_state(gpf: FixedGPF, x: np.ndarray) -> np.ndarray:
    return np.column_stack([gpf.dp.x[i].to_real(x[:, i]) for i in range(x.shape[1])])


def test_moments_against_numpy() -> None:
    gpf = FixedGPF(BOT, particles=2048)
    dp = gpf.dp
    rng = np.random.default_rng(4)
    xr = rng.normal([5, 1, 7, -1], [0.3, 0.1, 0.4, 0.05], size=(2048, 4))
    x = np.array([[dp.x[i].from_real(v)[0] for i, v in enumerate(row)] for row in xr])
    w = np.array([dp.weight.from_real(v)[0] for v in rng.uniform(0, 1, 2048)])
    ref = gpf.quantise_state([5.1, 0.9, 6.9, -1.0])
    sums, flags = blocks.accumulate(dp, x, w, ref, gpf.pairs)
    mu, sigma, f2 = blocks.finalise(dp, sums, ref, gpf.pairs)
    assert flags == 0 and f2 == 0
    x_real, w_real = dp_real_state(gpf, x), dp.weight.to_real(w)
    mean = np.average(x_real, axis=0, weights=w_real)
    cov = np.cov(x_real.T, aweights=w_real, bias=True)
    assert np.allclose(gpf.to_real_mu(mu), mean, atol=2 * dp.x[0].lsb)
    assert np.allclose(gpf.to_real_sigma(sigma), cov, atol=4 * dp.x[0].lsb * 0.5)


@pytest.mark.parametrize("seed", range(5))
def test_cholesky_against_numpy(seed: int) -> None:
    dp = datapath(UAV)
    pairs = blocks.cov_pairs(dp, "full")
    sigma = random_spd(np.random.default_rng(seed), 7, 0.05)
    chol, flags = blocks.cholesky(dp, quantise_sigma(dp, sigma, pairs))
    assert flags == 0
    real = np.array([[dp.chol[i].to_real(int(chol[i, j])) for j in range(7)] for i in range(7)])
    assert np.allclose(real, np.linalg.cholesky(sigma), atol=4 * dp.chol[4].lsb)


def test_cholesky_regularises_singular_with_flag() -> None:
    dp = datapath(UAV, WIDE)
    pairs = blocks.cov_pairs(dp, "full")
    v = np.random.default_rng(9).normal(size=(7, 3)) * 0.05
    sigma = v @ v.T                                              # rank 3: not positive definite
    chol, flags = blocks.cholesky(dp, quantise_sigma(dp, sigma, pairs))
    assert flags & Flag.NOT_PD
    real = np.array([[dp.chol[i].to_real(int(chol[i, j])) for j in range(7)] for i in range(7)])
    assert np.all(np.diag(real) > 0)
    # the factor reproduces Sigma up to rounding: the degenerate directions carry no spread
    assert np.abs(real @ real.T - sigma).max() < 1e-4 * np.abs(sigma).max()


def test_zero_weights_fall_back_with_flag() -> None:
    gpf = FixedGPF(BOT, particles=64)
    mu, chol = gpf.init(np.array([1.0, 0.3, 3.0, 0.3]), np.diag([0.01, 0.002, 0.01, 0.002]))
    sigma = quantise_sigma(gpf.dp, np.diag([0.01, 0.002, 0.01, 0.002]), gpf.pairs)
    draws = gpf.draws(1, seed=3)[0]
    # the bearing points the other way: every particle's weight underflows to exactly 0
    res = gpf.step(mu, chol, sigma, gpf.quantise_inputs({"z": -1.9, "observer": (0, 0)}),
                   draws, keep_particles=True)
    assert res.flags & Flag.ZERO_WEIGHTS
    assert np.all(res.particles["weight"] == 0)
    ref, _ = gpf.propagate(mu[None, :], np.zeros((1, 2), np.int64), {})
    assert np.array_equal(res.mu, ref[0]) and np.array_equal(res.chol, chol)
    # and the next step, with a sensible bearing, is normal again
    nxt = gpf.step(res.mu, res.chol, res.sigma,
                   gpf.quantise_inputs({"z": math.atan2(3.6, 1.6), "observer": (0, 0)}),
                   gpf.draws(2, seed=3)[1])
    assert not nxt.flags & Flag.ZERO_WEIGHTS


def test_propagate_uav_close_to_float() -> None:
    gpf = FixedGPF(UAV, particles=128)
    dp = gpf.dp
    rng = np.random.default_rng(5)
    q = rng.normal([0.9, 0.1, -0.2, 0.3], 0.01, size=(128, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    xr = np.column_stack([q, rng.normal([10, 5, 1], 0.1, size=(128, 3))])
    x = np.array([[dp.x[i].from_real(v)[0] for i, v in enumerate(row)] for row in xr])
    e = rng.integers(-(1 << 15), 1 << 15, size=(128, 6))
    inputs = gpf.quantise_inputs({"omega": [0.1, -0.2, 0.3], "accel": [0.5, 0.2, 9.9],
                                  "v_gps": [10, 5, 1]})
    out, flags = gpf.propagate(x, e, inputs)
    assert flags == 0
    omega = dp.gyro.to_real(inputs["omega"])
    accel = dp.accel.to_real(inputs["accel"])
    ref = propagate_uav(dp_real_state(gpf, x), dp.noise.to_real(e[:, :3]),
                        dp.noise.to_real(e[:, 3:]), omega, accel, UAV)
    got = dp_real_state(gpf, out)
    assert np.abs(got[:, :4] - ref[:, :4]).max() < 4 * dp.x[0].lsb
    assert np.abs(got[:, 4:] - ref[:, 4:]).max() < 4 * dp.x[4].lsb


def test_same_seed_same_run_and_close_to_float() -> None:
    sc = bot_fixed_observer(BOT, 10, 7)
    gpf = FixedGPF(BOT, particles=256)
    a, b = run(gpf, sc, seed=11), run(gpf, sc, seed=11)
    assert np.array_equal(a.mu, b.mu) and np.array_equal(a.flags, b.flags)
    flt = FloatGPF(BOT, 256).run(sc, draws=gpf.dp.noise.to_real(a.draws))
    assert np.abs(a.mu - flt.mu).max() < 0.01       # metres: quantisation only


def test_uav_filter_runs_with_flags_predicted() -> None:
    sc = uav_flight(UAV, 20, 3)
    gpf = FixedGPF(UAV, particles=128)
    out = run(gpf, sc, seed=2)
    assert np.all(np.isfinite(out.mu))
    q = out.mu[1:, :4]
    assert np.allclose(np.linalg.norm(q, axis=1), 1, atol=1e-5)


def _line_rate_calls(rng: np.random.Generator) -> list:
    """(name, call(x rows, per_particle)) for every line-rate block, on inputs where about
    half the particles saturate somewhere (full-range states and draws)."""
    bot, uav = datapath(BOT), datapath(UAV)

    def full(dp, shape):
        return rng.integers(dp.x[0].min_raw, dp.x[0].max_raw + 1, size=shape)

    e_bot = rng.integers(bot.noise.min_raw, bot.noise.max_raw + 1, size=(64, 6))
    e_uav = rng.integers(uav.noise.min_raw, uav.noise.max_raw + 1, size=(64, 13))
    x_bot, x_uav = full(bot, (64, 4)), full(uav, (64, 7))
    mu = full(bot, 4)
    chol = np.tril(rng.integers(bot.chol[0].min_raw, bot.chol[0].max_raw + 1, size=(4, 4)))
    omega = rng.integers(uav.gyro.min_raw, uav.gyro.max_raw + 1, size=3)
    accel = rng.integers(uav.accel.min_raw, uav.accel.max_raw + 1, size=3)
    return [
        ("sample_cond", lambda r, p: blocks.sample_cond(bot, mu, chol, e_bot[r, :4], p)),
        ("propagate_bot", lambda r, p: blocks.propagate_bot(bot, x_bot[r], e_bot[r, 4:], p)),
        ("propagate_uav", lambda r, p: blocks.propagate_uav(uav, x_uav[r], e_uav[r, :6], omega,
                                                            accel, p)),
        ("weight_bot", lambda r, p: blocks.weight_bot(bot, x_bot[r], 1000, (int(mu[0]),
                                                                             int(mu[2])), p)),
        ("weight_uav", lambda r, p: blocks.weight_uav(uav, x_uav[r], x_uav[0, 4:], p)),
    ]


@pytest.mark.parametrize("index", range(5))
def test_per_particle_flags_are_each_particle_alone(index: int) -> None:
    """per_particle=True gives, for every particle, the flags of that particle on its own,
    and ORed they are the block's flags."""
    name, call = _line_rate_calls(np.random.default_rng(index))[index]
    rows = np.arange(64)
    out, each = call(rows, True)
    out_all, flags = call(rows, False)
    assert np.array_equal(out, out_all)
    alone = [call(np.array([r]), False)[1] for r in rows]
    assert list(each) == alone, name
    assert int(np.bitwise_or.reduce(each)) == flags
    assert 0 < np.count_nonzero(each) < 64, f"{name}: stimulus must flag some, not all"

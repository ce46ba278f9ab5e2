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
from gpf.model.float_blocks import exponent_bot
from gpf.model.float_gpf import FloatGPF, propagate_uav
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


def lower(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i + 1)]


def test_sample_cond_is_exact() -> None:
    dp = datapath(BOT, WIDE)
    rng = np.random.default_rng(1)
    mu = rng.integers(-(1 << 18), 1 << 18, size=4)
    chol = np.tril(rng.integers(-(1 << 18), 1 << 18, size=(4, 4)))
    e = rng.integers(-(1 << 16), 1 << 16, size=(200, 4))
    x, flags = blocks.sample_cond(dp, mu, chol, e, lower(4))
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
    x, flags = blocks.sample_cond(dp, mu, chol, e, lower(4))
    assert flags & Flag.SAT and np.all(x == dp.x[0].max_raw)


def test_sample_cond_takes_only_the_covariance_pairs() -> None:
    """uav "block": L_ij across the blocks is 0 from the Cholesky and takes no product; any
    value there leaves x as it is, and an L of the blocks only gives the full sum's x."""
    dp = datapath(UAV)
    rng = np.random.default_rng(3)
    block = blocks.cov_pairs(dp, "block")
    mu = rng.integers(-(1 << 10), 1 << 10, size=7)
    chol = np.tril(rng.integers(-(1 << 12), 1 << 12, size=(7, 7)))
    e = rng.integers(-(1 << 14), 1 << 14, size=(50, 7))
    zeroed = chol.copy()
    zeroed[4:, :4] = 0
    x, _ = blocks.sample_cond(dp, mu, chol, e, block)
    assert np.array_equal(x, blocks.sample_cond(dp, mu, zeroed, e, block)[0])
    assert np.array_equal(x, blocks.sample_cond(dp, mu, zeroed, e, lower(7))[0])
    assert not np.array_equal(x, blocks.sample_cond(dp, mu, chol, e, lower(7))[0])


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


def test_exponent_bot_close_to_float() -> None:
    """t = d^2 log2(e) / 2R: the CORDIC's bearing and the roundings of u and t only."""
    gpf = FixedGPF(BOT, particles=256, word=WIDE)
    dp = gpf.dp
    rng = np.random.default_rng(3)
    xr = np.column_stack([rng.uniform(1, 3, 256), np.zeros(256), rng.uniform(2, 4, 256),
                          np.zeros(256)])
    x = np.array([[dp.x[i].from_real(v)[0] for i, v in enumerate(row)] for row in xr])
    raw = gpf.quantise_inputs({"z": 1.15, "observer": (0.0, 0.0)})
    t, _ = blocks.exponent_bot(dp, x, raw["z"], raw["observer"])
    t_float = exponent_bot(dp_real_state(gpf, x), 1.15, np.zeros(2), BOT)
    near = t_float < 40
    assert np.abs(dp.t.to_real(t) - t_float)[near].max() < 2e-3 * (1 + t_float[near]).max()


def test_relative_weights() -> None:
    """Every particle of beat b gets exactly 2^-(t - R_b), R_b the running minimum of floor(t)
    over the beats; the step's best has w in (1/2, 1]; the shifts add up to R's fall."""
    dp = datapath(BOT)
    rng = np.random.default_rng(7)
    for lanes in (1, 2, 4):
        t = (rng.exponential(30, size=(5, 64)) * 2**dp.t.frac_bits).astype(np.int64)
        w, shift = blocks.relative_weights(dp, t, lanes)
        floor = (t >> dp.t.frac_bits).reshape(5, -1, lanes).min(axis=2)
        running = np.minimum.accumulate(np.minimum(floor, blocks.reach_top(dp)), axis=1)
        expect = dp.exp2(t - (np.repeat(running, lanes, axis=1) << dp.t.frac_bits))
        assert np.array_equal(w, expect)
        best = np.argmin(t, axis=1)
        one = 1 << dp.weight.frac_bits
        assert np.all(w[np.arange(5), best] > one // 2) and np.all(w <= one)
        total = blocks.reach_top(dp) - running[:, -1]
        assert np.all(np.minimum(shift, 127).sum(axis=1) >= np.minimum(total, 127))
        assert np.all(shift[:, 1:] == np.minimum(running[:, :-1] - running[:, 1:], 127))


def test_rescaled_sums_are_the_sequential_recurrence() -> None:
    """acc <- round(acc 2^-shift scale) + beat, exactly as a loop over beats in Python ints."""
    rng = np.random.default_rng(11)
    for lanes in (1, 3):
        values = rng.integers(-(1 << 61), 1 << 61, size=(4, 30 * lanes, 3))
        shift = np.where(rng.random((4, 30)) < 0.3, rng.integers(0, 130, (4, 30)), 0)
        scale = np.array([1, 2, 1])
        got = blocks.rescaled_sums(values, shift, scale)
        for r in range(4):
            acc = [0, 0, 0]
            for b in range(30):
                beat = values[r, b * lanes:(b + 1) * lanes].astype(object).sum(axis=0)
                for c in range(3):
                    s_ = int(shift[r, b]) * int(scale[c]) if b else 0
                    acc[c] = ((acc[c] + ((1 << s_) >> 1)) >> s_) + int(beat[c])
            assert list(got[r]) == acc


def test_interleaved_sums_are_two_sequential_recurrences() -> None:
    """Beat b to accumulator b mod 2, a zero beat after the last, each accumulator rescaled by
    the shifts since its own last beat in one rounding, then their total: as a loop over beats
    in Python ints (any number of beats, odd and even, any lanes)."""
    rng = np.random.default_rng(3)
    scale = np.array([1, 2, 1])
    for lanes in (1, 2, 3):
        for beats in (1, 2, 3, 30):
            values = rng.integers(-(1 << 61), 1 << 61, size=(4, beats * lanes, 3))
            shift = np.where(rng.random((4, beats)) < 0.3, rng.integers(0, 128, (4, beats)), 0)
            got = blocks.interleaved_sums(values, shift, scale)
            for r in range(4):
                acc = [[0, 0, 0], [0, 0, 0]]
                sums = [values[r, b * lanes:(b + 1) * lanes].astype(object).sum(axis=0)
                        for b in range(beats)] + [np.zeros(3, dtype=object)]
                sh = [int(v) for v in shift[r]] + [0]
                for b in range(beats + 1):
                    for c in range(3):
                        s_ = (sh[b - 1] + sh[b]) * int(scale[c]) if b >= 2 else 0
                        acc[b % 2][c] = ((acc[b % 2][c] + ((1 << s_) >> 1)) >> s_) + int(sums[b][c])
                assert list(got[r]) == [acc[0][c] + acc[1][c] for c in range(3)]


def test_moments_against_numpy() -> None:
    """Weights relative to the best (with rescales): mean and covariance as numpy's weighted
    ones of 2^-(t - min t), the ESS as Kish's."""
    gpf = FixedGPF(BOT, particles=2048)
    dp = gpf.dp
    rng = np.random.default_rng(4)
    xr = rng.normal([5, 1, 7, -1], [0.3, 0.1, 0.4, 0.05], size=(2048, 4))
    x = np.array([[dp.x[i].from_real(v)[0] for i, v in enumerate(row)] for row in xr])
    t = (rng.exponential(6.0, size=2048) * 2**dp.t.frac_bits).astype(np.int64) + (40 << 10)
    t[:300] = np.sort(t[:300])[::-1]                # the best so far improves now and then
    w, shift = blocks.relative_weights(dp, t, 1)
    assert np.count_nonzero(shift[1:]) > 2          # rescales happened
    ref = gpf.quantise_state([5.1, 0.9, 6.9, -1.0])
    mu, sigma, ess, flags = blocks.moments(dp, x, w, shift, ref, gpf.pairs)
    assert flags == 0
    x_real = dp_real_state(gpf, x)
    w_real = np.exp2(-(dp.t.to_real(t) - dp.t.to_real(t).min()))
    mean = np.average(x_real, axis=0, weights=w_real)
    cov = np.cov(x_real.T, aweights=w_real, bias=True)
    assert np.allclose(gpf.to_real_mu(mu), mean, atol=2 * dp.x[0].lsb)
    assert np.allclose(gpf.to_real_sigma(sigma), cov, rtol=2e-3, atol=4 * dp.x[0].lsb)
    kish = w_real.sum() ** 2 / (w_real**2).sum()
    assert abs(dp.ess.to_real(ess) - kish) < 0.01 * kish


def test_mean_is_rounded_once() -> None:
    """mu_i = ref_i + round(S1_i / W) exactly: no second rounding of the quotient that also
    feeds Sigma (a double half-up rounding biases the mean by a quarter LSB a step)."""
    dp = datapath(UAV)
    pairs = blocks.cov_pairs(dp, "block")
    rng = np.random.default_rng(12)
    x = rng.integers(-3000, 3000, size=(1, 300, 7))
    w = rng.integers(1, 1 << dp.weight.frac_bits, size=(1, 300))
    ref = np.zeros((1, 7), dtype=np.int64)
    sums, _ = blocks.accumulate(dp, x, w, np.zeros((1, 300), np.int64), ref, pairs)
    mu, _, _, _ = blocks.finalise(dp, sums, ref, pairs)
    for i in range(7):
        exact = Fraction(int(sums.s1[0, i]), int(sums.w[0]))
        assert mu[0, i] == frac_round(exact)


def test_predicted_sigma_is_one_rounding() -> None:
    """F Sigma F^T + Q of the model's 18-bit constants, each entry within half an LSB of the
    exact value (float64 on the same constants), for both applications; and within the
    constants' quantisation of float_blocks' predicted_covariance."""
    from gpf.model.float_blocks import predicted_covariance

    rng = np.random.default_rng(13)
    for cfg in (BOT, UAV):
        dp = datapath(cfg)
        pairs = blocks.cov_pairs(dp, cfg.covariance)
        sig = random_spd(rng, dp.n, 0.05)
        raw = np.array([[quantise_sigma(dp, sig, pairs)[p] for p in pairs]])
        pred, flags = blocks.predicted_sigma(dp, raw, pairs)
        real = FixedGPF(cfg, 64).to_real_sigma(raw[0])
        c = {k: v.real for k, v in dp.consts.items()}
        if cfg.app == "bot":
            f = np.eye(4) + np.diag([c["T"], 0, c["T"], 0], 1)[:4, :4]
            exact = f @ real @ f.T
            exact[[0, 2], [0, 2]] += c["T2"] * real[[1, 3], [1, 3]] - c["T"] ** 2 * real[
                [1, 3], [1, 3]]
            exact[[2, 0], [0, 2]] += c["T2"] * real[[3, 1], [1, 3]] - c["T"] ** 2 * real[
                [3, 1], [1, 3]]
            for a in (0, 2):
                exact[a, a] += c["q_pp"]
                exact[a + 1, a] += c["q_pv"]
                exact[a, a + 1] += c["q_pv"]
                exact[a + 1, a + 1] += c["q_vv"]
        else:
            exact = real + np.diag([c["q_q"]] * 4 + [c["q_v"]] * 3)
        loose = predicted_covariance(real, cfg)
        for q, (i, j) in enumerate(pairs):
            lsb = 2.0 ** -dp.cov_frac(i, j)
            assert abs(pred[0, q] * lsb - exact[i, j]) <= 0.5 * lsb * (1 + 1e-6), (cfg.name, i, j)
            assert abs(pred[0, q] * lsb - loose[i, j]) < 1e-4 * abs(loose[i, j]) + lsb
        assert flags[0] == 0


def dp_real_state(gpf: FixedGPF, x: np.ndarray) -> np.ndarray:
    return np.column_stack([gpf.dp.x[i].to_real(x[:, i]) for i in range(x.shape[1])])


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


def test_out_of_reach_predicts_with_flag() -> None:
    """The bearing points the other way: no particle within the exponent's reach. Every weight
    is then in (1/2, 1] (the measurement ignored): mu is the cloud's own mean, near the
    prediction, flag ZERO_WEIGHTS; the next step, with a sensible bearing, is normal again."""
    gpf = FixedGPF(BOT, particles=64)
    mu, chol = gpf.init(np.array([1.0, 0.3, 3.0, 0.3]), np.diag([0.01, 0.002, 0.01, 0.002]))
    sigma = quantise_sigma(gpf.dp, np.diag([0.01, 0.002, 0.01, 0.002]), gpf.pairs)
    draws = gpf.draws(2, seed=3)
    res = gpf.step(mu, chol, sigma, gpf.quantise_inputs({"z": -1.9, "observer": (0, 0)}),
                   draws[0], keep_particles=True)
    one = 1 << gpf.dp.weight.frac_bits
    assert res.flags & Flag.ZERO_WEIGHTS
    assert np.all(res.particles["weight"] > one // 2) and np.all(res.particles["shift"] == 0)
    assert gpf.dp.ess.to_real(res.ess) > 60
    prop = gpf.to_real_mu(res.particles["prop"])
    assert np.allclose(gpf.to_real_mu(res.mu), prop.mean(axis=0), atol=0.02)
    nxt = gpf.step(res.mu, res.chol, res.sigma,
                   gpf.quantise_inputs({"z": math.atan2(3.6, 1.6), "observer": (0, 0)}),
                   draws[1])
    assert not nxt.flags & Flag.ZERO_WEIGHTS


def test_low_ess_samples_from_the_predicted_covariance() -> None:
    """A step whose ESS is below N / 32 (a bearing 12 sigma off a tight cloud): its Sigma is
    the prediction of the previous one, not the collapsed weighted one, flag LOW_ESS; with
    the rule off (ess_min = 0) the weighted one stays."""
    sig0 = np.diag([0.04, 0.01, 0.04, 0.01])
    mu0 = np.array([1.0, 0.3, 3.0, 0.3])
    z = math.atan2(3.3, 1.3) + 12 * math.sqrt(BOT.app_params["bearing_var"])
    for cfg, expect_low in ((BOT, True), (load_config("configs/bot.toml",
                                                      {"filter.ess_min": 0}), False)):
        gpf = FixedGPF(cfg, particles=256)
        mu, chol = gpf.init(mu0, sig0)
        sigma = gpf.quantise_sigma(sig0)
        res = gpf.step(mu, chol, sigma, gpf.quantise_inputs({"z": z, "observer": (0, 0)}),
                       gpf.draws(1, seed=5)[0])
        assert gpf.dp.ess.to_real(res.ess) < 256 / 32
        prev = np.array([[sigma[p] for p in gpf.pairs]])
        pred = dict(zip(gpf.pairs, blocks.predicted_sigma(gpf.dp, prev, gpf.pairs)[0][0],
                        strict=True))
        assert bool(res.flags & Flag.LOW_ESS) == expect_low
        assert (res.sigma == {p: int(v) for p, v in pred.items()}) == expect_low


def test_batch_step_is_the_single_steps() -> None:
    """R runs stepped together give each run's own single steps, bit for bit."""
    for cfg in (BOT, UAV):
        gpf = FixedGPF(cfg, particles=64)
        scs = [(bot_fixed_observer if cfg.app == "bot" else uav_flight)(cfg, 3, 20 + r)
               for r in range(3)]
        singles = [run(gpf, sc, seed=40 + r) for r, sc in enumerate(scs)]
        flt = FloatGPF(cfg, 64)
        states = [gpf.init(*flt.initial(sc)) for sc in scs]
        mu = np.stack([m for m, _ in states])
        chol = np.stack([c for _, c in states])
        sigma = np.array([[gpf.quantise_sigma(flt.initial(sc)[1])[p] for p in gpf.pairs]
                          for sc in scs])
        for k in range(1, 4):
            inputs = gpf.stack_inputs([gpf.quantise_inputs(sc.step_inputs(k)) for sc in scs])
            res = gpf.step_batch(mu, chol, sigma, inputs,
                                 np.stack([one.draws[k - 1] for one in singles]))
            mu, chol, sigma = res.mu, res.chol, res.sigma
            for r, one in enumerate(singles):
                assert np.array_equal(gpf.to_real_mu(mu[r]), one.mu[k])
                assert res.flags[r] == one.flags[k]


def test_draw_stream_is_the_whole_draws() -> None:
    gpf = FixedGPF(UAV, particles=32)
    whole = gpf.draws(7, seed=9)
    stream = gpf.draw_stream(9)
    parts = np.concatenate([stream.next(3), stream.next(0), stream.next(4)])
    assert np.array_equal(whole, parts)


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
    out, flags = blocks.propagate_uav(dp, x, e, inputs["omega"], inputs["accel"])
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
        ("sample_cond", lambda r, p: blocks.sample_cond(bot, mu, chol, e_bot[r, :4], lower(4), p)),
        ("propagate_bot", lambda r, p: blocks.propagate_bot(bot, x_bot[r], e_bot[r, 4:], p)),
        ("propagate_uav", lambda r, p: blocks.propagate_uav(uav, x_uav[r], e_uav[r, :6], omega,
                                                            accel, p)),
        ("weight_bot", lambda r, p: _no_shift(blocks.weight_bot(
            bot, x_bot[r], 1000, (int(mu[0]), int(mu[2])), per_particle=p))),
        ("weight_uav", lambda r, p: _no_shift(blocks.weight_uav(uav, x_uav[r], x_uav[0, 4:],
                                                                per_particle=p))),
    ]


def _no_shift(out: tuple) -> tuple:
    """A weight block's (w, shift, flags) as (w, flags)."""
    return out[0], out[2]


@pytest.mark.parametrize("index", range(5))
def test_per_particle_flags_are_each_particle_alone(index: int) -> None:
    """per_particle=True gives, for every particle, the flags of that particle on its own,
    and ORed they are the block's flags (the weights themselves are relative to the others)."""
    name, call = _line_rate_calls(np.random.default_rng(index))[index]
    rows = np.arange(64)
    out, each = call(rows, True)
    out_all, flags = call(rows, False)
    assert np.array_equal(out, out_all)
    alone = [call(np.array([r]), False)[1] for r in rows]
    assert list(each) == alone, name
    assert int(np.bitwise_or.reduce(each)) == flags
    assert 0 < np.count_nonzero(each) < 64, f"{name}: stimulus must flag some, not all"

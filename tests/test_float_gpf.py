"""float64 GPF model: vectorised blocks against a plain per-particle loop, moments and Cholesky
against numpy, the fault paths, filter behaviour on the shipped scenarios, scenario CSV files."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gpf.config import load_config
from gpf.model.float_gpf import (
    LOW_ESS,
    NOT_PD,
    ZERO_WEIGHTS,
    FloatGPF,
    attitude_error_deg,
    cholesky,
    moments,
    omega_matrix,
    position_rmse,
    rotation_matrix,
)
from gpf.model.scenarios import (
    bot_fixed_observer,
    bot_manoeuvring_observer,
    read_csv,
    uav_flight,
    write_csv,
)

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
BOT = load_config(CONFIGS / "bot.toml")
UAV = load_config(CONFIGS / "uav.toml")
UAV_FULL = dataclasses.replace(UAV, app_params={**UAV.app_params, "covariance": "full"})


# ---- a plain reference: one particle at a time, math.* and lists ---------------------------
def wrap(d: float) -> float:
    while d > math.pi:
        d -= 2 * math.pi
    while d <= -math.pi:
        d += 2 * math.pi
    return d


def ref_bot(x: list[float], e: list[float], cfg) -> list[float]:
    t, s = cfg.dt, math.sqrt(cfg.app_params["process_var"])
    px, vx, py, vy = x
    return [px + t * vx + t * t / 2 * s * e[0], vx + t * s * e[0],
            py + t * vy + t * t / 2 * s * e[1], vy + t * s * e[1]]


def ref_uav(x: list[float], eg: list[float], ea: list[float], omega, accel, cfg) -> list[float]:
    p = cfg.app_params
    wx, wy, wz = (omega[i] + math.radians(p["sigma_omega_deg"]) * eg[i] for i in range(3))
    f = [accel[i] + p["sigma_a"] * ea[i] for i in range(3)]
    q0, q1, q2, q3 = x[:4]
    big_omega = [[0, -wx, -wy, -wz], [wx, 0, wz, -wy], [wy, -wz, 0, wx], [wz, wy, -wx, 0]]
    q = [x[i] + cfg.dt / 2 * sum(big_omega[i][j] * x[j] for j in range(4)) for i in range(4)]
    c = [[q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
         [2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)],
         [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3]]
    g = [0.0, 0.0, -9.8]
    v = [x[4 + i] + (sum(c[i][j] * f[j] for j in range(3)) + g[i]) * cfg.dt for i in range(3)]
    return q + v


def ref_step(cfg, mu, chol, inputs, draws):
    """One GPF step written plainly: loop over particles, then numpy.linalg.cholesky."""
    n = len(mu)
    xs, ws = [], []
    for e in draws.tolist():
        xc = [mu[i] + sum(chol[i][j] * e[j] for j in range(i + 1)) for i in range(n)]
        if cfg.app == "bot":
            x = ref_bot(xc, e[4:6], cfg)
            ox, oy = inputs["observer"]
            d = wrap(inputs["z"] - math.atan2(x[2] - oy, x[0] - ox))
            w = math.exp(-0.5 * d * d / cfg.app_params["bearing_var"])
        else:
            x = ref_uav(xc, e[7:10], e[10:13], inputs["omega"], inputs["accel"], cfg)
            d2 = sum((inputs["v_gps"][i] - x[4 + i]) ** 2 for i in range(3))
            w = math.exp(-0.5 * d2 / cfg.app_params["sigma_v"] ** 2)
        xs.append(x)
        ws.append(w)
    if cfg.app == "bot":
        ref = ref_bot(list(mu), [0.0, 0.0], cfg)
    else:
        ref = ref_uav(list(mu), [0.0] * 3, [0.0] * 3, inputs["omega"], inputs["accel"], cfg)
    big_w = sum(ws)
    pairs = list(zip(xs, ws, strict=True))
    s1 = [sum(w * (x[i] - ref[i]) for x, w in pairs) for i in range(n)]
    s2 = [[sum(w * (x[i] - ref[i]) * (x[j] - ref[j]) for x, w in pairs) for j in range(n)]
          for i in range(n)]
    m = [s / big_w for s in s1]
    new_mu = np.array([ref[i] + m[i] for i in range(n)])
    sigma = np.array([[s2[i][j] / big_w - m[i] * m[j] for j in range(n)] for i in range(n)])
    if cfg.app == "uav":
        new_mu[:4] /= math.sqrt(sum(v * v for v in new_mu[:4]))
        if cfg.covariance == "block":
            sigma[:4, 4:] = sigma[4:, :4] = 0.0
    return new_mu, sigma, np.linalg.cholesky(sigma)


@pytest.mark.parametrize("cfg, make", [(BOT, bot_manoeuvring_observer), (UAV, uav_flight),
                                       (UAV_FULL, uav_flight)], ids=["bot", "uav", "uav-full"])
def test_vectorised_step_equals_plain_loop(cfg, make) -> None:
    scenario = make(cfg, 5, seed=11)
    gpf = FloatGPF(cfg, particles=64)
    rng = np.random.default_rng(5)
    mu, sigma = gpf.initial(scenario)
    chol = np.linalg.cholesky(sigma)
    mu_ref, chol_ref = mu.copy(), chol.copy()
    for k in range(1, 6):
        draws = rng.standard_normal((64, gpf.draws_per_particle))
        res = gpf.step(mu, chol, scenario.step_inputs(k), draws)
        mu_ref, sigma_ref, chol_ref = ref_step(cfg, mu_ref, chol_ref, scenario.step_inputs(k),
                                               draws)
        assert res.flags == set()
        scale = np.sqrt(np.outer(np.diag(sigma_ref), np.diag(sigma_ref)))
        np.testing.assert_allclose(res.mu, mu_ref, rtol=1e-12, atol=1e-12)
        # relative to the entry's scale sqrt(Sigma_ii Sigma_jj): summation order only
        assert np.all(np.abs(res.Sigma - sigma_ref) <= 1e-11 * scale)
        assert np.all(np.abs(res.L - chol_ref) <= 1e-11 * np.sqrt(scale))
        mu, chol = res.mu, res.L


def test_quaternion_conventions() -> None:
    """Omega(w) q == q (x) [0, w] (seed 002 eq. 12); C(unit q) is the rotation q v q*."""
    rng = np.random.default_rng(2)

    def hamilton(a, b):
        return np.array([a[0] * b[0] - a[1:] @ b[1:],
                         *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:]))])

    for _ in range(10):
        q, w, v = rng.standard_normal(4), rng.standard_normal(3), rng.standard_normal(3)
        np.testing.assert_allclose(omega_matrix(w) @ q, hamilton(q, np.r_[0.0, w]), atol=1e-14)
        u = q / np.linalg.norm(q)
        rotated = hamilton(hamilton(u, np.r_[0.0, v]), u * [1, -1, -1, -1])[1:]
        np.testing.assert_allclose(rotation_matrix(u) @ v, rotated, atol=1e-14)
        np.testing.assert_allclose(rotation_matrix(q), np.dot(q, q) * rotation_matrix(u),
                                   atol=1e-13)


@pytest.mark.parametrize("app, covariance", [("bot", "full"), ("uav", "full"), ("uav", "block")])
def test_moments_match_numpy(app: str, covariance: str) -> None:
    rng = np.random.default_rng(3)
    n = 4 if app == "bot" else 7
    x = rng.standard_normal((500, n)) * rng.uniform(0.01, 2, n) + rng.uniform(-5, 5, n)
    w = rng.uniform(0, 1, 500) ** 3
    ref = x[0] + 0.3                           # any reference: the shift must not matter
    mu, sigma = moments(x, w, ref, app, covariance)
    want_mu = np.average(x, axis=0, weights=w)
    want_sigma = np.cov(x.T, aweights=w, bias=True)
    if app == "uav":
        want_mu[:4] /= np.linalg.norm(want_mu[:4])
        if covariance == "block":
            want_sigma[:4, 4:] = want_sigma[4:, :4] = 0.0
    np.testing.assert_allclose(mu, want_mu, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sigma, want_sigma, rtol=1e-10, atol=1e-12)


def test_cholesky_spd_matches_numpy() -> None:
    rng = np.random.default_rng(4)
    for n in (4, 7):
        for _ in range(20):
            a = rng.standard_normal((n, n)) * rng.uniform(1e-3, 10, n)
            sigma = a @ a.T + 1e-6 * np.eye(n)
            chol, not_pd = cholesky(sigma)
            assert not not_pd
            np.testing.assert_allclose(chol, np.linalg.cholesky(sigma), rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("kind", ["rank-deficient", "near-singular", "indefinite", "zero"])
def test_cholesky_regularises_and_flags(kind: str) -> None:
    rng = np.random.default_rng(6)
    a = rng.standard_normal((7, 5))
    sigma = {"rank-deficient": a @ a.T,
             "near-singular": a @ a.T + np.diag([1e-14] * 7),
             "indefinite": np.diag([1.0, 2.0, -0.5, 1.0, 3.0, 1.0, 1.0]) + 0.1,
             "zero": np.zeros((7, 7))}[kind]
    chol, not_pd = cholesky(sigma)
    assert not_pd
    assert np.all(np.isfinite(chol)) and np.all(np.diag(chol) > 0)
    assert np.array_equal(chol, np.tril(chol))
    if kind != "indefinite":                   # PSD: the change stays tiny
        scale = max(1.0, float(np.max(np.diag(sigma))))
        np.testing.assert_allclose(chol @ chol.T, sigma, atol=1e-4 * scale)


def test_out_of_reach_predicts_and_flags() -> None:
    """A bearing half a turn off at step 4: no particle within the exponent's reach (as in
    fixed point): equal weights up to a factor 2, mu the cloud's mean near the prediction, the
    flag; and the filter goes on."""
    scenario = bot_fixed_observer(BOT, 10, seed=1)
    scenario.measurements["z"][4] = wrap(scenario.measurements["z"][4] + math.pi)  # behind
    gpf = FloatGPF(BOT, 256)
    res = gpf.run(scenario, rng=np.random.default_rng(1))
    assert res.flags[ZERO_WEIGHTS].tolist() == [k == 4 for k in range(11)]
    mu3, chol3 = res.mu[3], np.linalg.cholesky(res.Sigma[3])
    step = gpf.step(mu3, chol3, scenario.step_inputs(4), np.random.default_rng(0)
                    .standard_normal((256, 6)))
    assert ZERO_WEIGHTS in step.flags and np.all(step.w > 0.5)
    np.testing.assert_allclose(step.mu, step.x.mean(axis=0), atol=0.01)
    assert np.all(np.isfinite(res.mu)) and res.ess[5] > 1


def test_low_ess_takes_the_predicted_covariance() -> None:
    """ESS below cfg.ess_min N: the step's Sigma is F Sigma_prev F^T + Q, flag low_ess."""
    from gpf.model.float_blocks import predicted_covariance

    scenario = bot_fixed_observer(BOT, 2, seed=1)
    z = scenario.measurements["z"][1] + 12 * math.sqrt(BOT.app_params["bearing_var"])
    scenario.measurements["z"][1] = z
    gpf = FloatGPF(BOT, 256)
    mu, sigma = gpf.initial(scenario)
    step = gpf.step(mu, np.linalg.cholesky(sigma), scenario.step_inputs(1),
                    np.random.default_rng(2).standard_normal((256, 6)), sigma)
    assert step.ess < 256 * BOT.ess_min and LOW_ESS in step.flags
    np.testing.assert_allclose(step.Sigma, predicted_covariance(sigma, BOT))


def test_degenerate_particles_flag_not_pd() -> None:
    scenario = uav_flight(UAV, 3, seed=1)
    gpf = FloatGPF(UAV, 64)
    mu, sigma = gpf.initial(scenario)
    same = np.tile(np.random.default_rng(0).standard_normal(13), (64, 1))  # 64 equal particles
    res = gpf.step(mu, np.linalg.cholesky(sigma), scenario.step_inputs(1), same)
    assert NOT_PD in res.flags
    assert np.all(np.isfinite(res.L))
    nxt = gpf.step(res.mu, res.L, scenario.step_inputs(2),
                   np.random.default_rng(1).standard_normal((64, 13)))
    assert np.all(np.isfinite(nxt.mu))


def _final_rmse(make, runs: int = 20) -> float:
    est, truth = [], []
    for run in range(runs):
        scenario = make(BOT, 50, seed=100 + run)
        res = FloatGPF(BOT, 1024).run(scenario, rng=np.random.default_rng(1000 + run))
        est.append(res.mu[-1])
        truth.append(scenario.truth[-1])
    return float(position_rmse(np.array(est), np.array(truth)))


def test_bot_manoeuvring_observer_converges_fixed_does_not() -> None:
    fixed = _final_rmse(bot_fixed_observer)
    moving = _final_rmse(bot_manoeuvring_observer)
    print(f"bot final position RMSE, 20 runs, N = 1024: fixed {fixed:.2f} m, "
          f"manoeuvring {moving:.2f} m")
    assert fixed > 4.0                          # range unobservable: the error grows
    assert moving < 0.4 * fixed


# N = 512 is marginal for seed 002's noise at 100 Hz: over seeds 1..10 the mean attitude error
# is 0.9-3.7 deg on 8 and 2 lose lock (a first-step weight collapse, then the attitude
# covariance shrinks and the turns throw the particles off the GPS); N = 2048 keeps all ten.
# Seed 4 is a median one.
SEED_UAV = 4


def test_uav_tracks_attitude_through_the_flight() -> None:
    scenario = uav_flight(UAV, 6000, seed=SEED_UAV)  # 60 s: climb, two turns, level flight
    res = FloatGPF(UAV, 512).run(scenario, rng=np.random.default_rng(SEED_UAV))
    err = attitude_error_deg(res.mu, scenario.truth)
    v_rmse = float(np.sqrt(np.mean(np.sum((res.mu[1:, 4:] - scenario.truth[1:, 4:]) ** 2, 1))))
    print(f"uav N = 512: attitude error mean {err.mean():.2f} deg, max {err.max():.2f} deg, "
          f"velocity RMSE {v_rmse:.4f} m/s")
    assert err.mean() < 3.0 and err.max() < 5.0
    assert v_rmse < 0.05
    assert not res.flags[ZERO_WEIGHTS].any()



def test_flight_truth_is_consistent() -> None:
    """No sideslip, no angle of attack: v = |v| C(q) e_x along the whole integrated truth."""
    s = uav_flight(UAV, 6000, seed=1)
    q, v = s.truth[:, :4], s.truth[:, 4:]
    forward = rotation_matrix(q)[:, :, 0]
    np.testing.assert_allclose(v, np.linalg.norm(v, axis=1)[:, None] * forward, atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)
    heading_change = np.degrees(np.ptp(np.unwrap(np.arctan2(v[:, 1], v[:, 0]))))
    assert heading_change > 90 and np.ptp(v[:, 2]) > 1.0   # it turns and it climbs


@pytest.mark.parametrize("make, steps", [(bot_fixed_observer, 50),
                                         (bot_manoeuvring_observer, 50), (uav_flight, 40)])
def test_csv_round_trip_is_exact(tmp_path: Path, make, steps: int) -> None:
    cfg = UAV if make is uav_flight else BOT
    s = make(cfg, steps, seed=3)
    write_csv(s, tmp_path / "s.csv")
    back = read_csv(tmp_path / "s.csv")
    assert (back.app, back.dt, back.steps, back.meta) == (s.app, s.dt, s.steps, s.meta)
    for a, b in [(s.t, back.t), (s.truth, back.truth), (s.mu0, back.mu0),
                 *[(s.inputs[k], back.inputs[k]) for k in s.inputs],
                 *[(s.measurements[k], back.measurements[k]) for k in s.measurements]]:
        assert a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def test_csv_without_metadata_or_truth(tmp_path: Path) -> None:
    path = tmp_path / "recorded.csv"
    path.write_text("k,t,z,ox,oy,px,vx,py,vy\n0,0,,,,,,,\n1,0.5,1.2,0,0,,,,\n"
                    "2,1.0,1.1,0.5,-0.25,,,,\n")
    s = read_csv(path)
    assert s.app == "bot" and s.dt == 0.5 and s.steps == 2 and s.mu0 is None
    assert np.isnan(s.truth).all() and s.step_inputs(2)["observer"].tolist() == [0.5, -0.25]
    res = FloatGPF(BOT, 128).run(s, rng=np.random.default_rng(0))
    assert np.all(np.isfinite(res.mu))


GOOD = "k,t,z,ox,oy,px,vx,py,vy\n0,0,,,,1,0.3,3,0.3\n1,1,1.2,0,0,,,,\n2,2,1.1,0,0,,,,\n"


@pytest.mark.parametrize("text, where", [
    (GOOD.replace("ox,oy", "ox,oz"), "column 5: 'oz', expected 'oy'"),
    (GOOD.replace(",vy\n", "\n", 1), "column 9: missing, expected 'vy'"),
    (GOOD.replace("1,1,1.2", "1,1,abc"), "row 1 (line 3), column 'z': 'abc'"),
    (GOOD.replace("2,2,1.1,0,0", "2,2,1.1,,0"), "row 2 (line 4), column 'ox': empty"),
    (GOOD.replace("2,2,1.1,0,0,", "2,2,1.1,0,0"), "row 2 (line 4): 8 fields, expected 9"),
    (GOOD.replace("2,2,1.1", "3,2,1.1"), "row 2 (line 4), column 'k': 3, expected 2"),
    (GOOD.replace("2,2,1.1", "2,2.5,1.1"), "row 2 (line 4), column 't'"),
    (GOOD.replace("1,1,1.2", "1,1,inf"), "row 1 (line 3), column 'z': 'inf'"),
    ("# dt: -1\n" + GOOD, "line 1: metadata dt"),
    ("k,t,z\n", "column 4: missing, expected 'ox'"),
    ("# just a comment\n", "no header row"),
])
def test_malformed_csv_is_one_clear_line(tmp_path: Path, text: str, where: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        read_csv(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and where in message, message


def test_same_seed_same_output() -> None:
    def once(seed: int):
        s = uav_flight(UAV, 30, seed)
        return s, FloatGPF(UAV, 128).run(s, rng=np.random.default_rng(seed))

    (s1, r1), (s2, r2), (_, r3) = once(9), once(9), once(10)
    assert np.array_equal(s1.truth, s2.truth) and np.array_equal(s1.mu0, s2.mu0)
    assert np.array_equal(s1.inputs["omega"], s2.inputs["omega"], equal_nan=True)
    assert np.array_equal(r1.mu, r2.mu) and np.array_equal(r1.Sigma, r2.Sigma)
    assert not np.array_equal(r1.mu, r3.mu)
    given = np.random.default_rng(9).standard_normal((30, 128, 13))  # the same stream, up front
    assert np.array_equal(FloatGPF(UAV, 128).run(s1, draws=given).mu, r1.mu)
    b1 = bot_manoeuvring_observer(BOT, 20, 4)
    b2 = bot_fixed_observer(BOT, 20, 4)
    assert np.array_equal(b1.truth, b2.truth)    # the same target for both observers

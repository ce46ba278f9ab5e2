"""Quality, not only equality: the fixed-point filter judged against float64 by Monte Carlo (a
short version of the README's robustness table; `make regress` runs the RTL over a long uav
flight with its bound), and the two failures the robustness work removed, reverted in the model,
caught: weights that all underflow, and a collapsed covariance kept for the next step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gpf.config import load_config
from gpf.model import blocks
from gpf.model.blocks import Flag
from gpf.model.fixed_gpf import FixedGPF, step_results
from gpf.model.scenarios import bot_bearing_glitch
from gpf.study.montecarlo import monte_carlo

BOT = load_config("configs/bot.toml")
RATIO_MAX = 1.02      # SPEC 9: RMSE(fixed) / RMSE(float64) for bot


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["bot_manoeuvring_observer", "bot_fixed_observer"])
def test_bot_quality(scenario: str) -> None:
    """30 runs at N = 256: the ratio within the bar and no run that lost track."""
    mc = monte_carlo(BOT, runs=30, particles=256, scenario=scenario, progress=False)
    ratio, noise = mc.ratio_and_noise()
    assert ratio <= RATIO_MAX, f"{scenario}: fixed/float {ratio:.4f} +- {noise:.4f}"
    assert mc.lost_tracks() == [], f"{scenario}: runs {mc.lost_tracks()} lost track"


def glitch_step(gpf: FixedGPF):
    """Step 3 of bot_bearing_glitch (a bearing 10 sigma off): its result and the Sigma it
    sampled from."""
    sc = bot_bearing_glitch(gpf.cfg, 3, 1)
    results = list(step_results(gpf, sc, gpf.draws(3, seed=1)))
    return results[2], results[1].sigma


def test_weights_never_all_underflow() -> None:
    """The glitch: the best particle still weighs at least 1/2, so the estimate moves toward
    the measurement; absolute weights 2^-t (the model reverted) all underflow there."""
    gpf = FixedGPF(BOT, particles=128)
    res, _ = glitch_step(gpf)
    assert not res.flags & Flag.ZERO_WEIGHTS and gpf.dp.ess.to_real(res.ess) >= 1


def test_absolute_weights_are_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    def absolute(dp, t, lanes):
        return dp.exp2(t), np.zeros(t.shape[:-1] + (t.shape[-1] // lanes,), np.int64)

    monkeypatch.setattr(blocks, "relative_weights", absolute)
    with pytest.raises(ValueError, match="denominator"):   # W = 0: nothing to divide by
        test_weights_never_all_underflow()


def test_degenerate_step_samples_from_the_prediction() -> None:
    """After the glitch's collapse (ESS below N / 32) the covariance that feeds the next step
    is the prediction of the previous one: at least as wide as it, plus the process noise."""
    gpf = FixedGPF(BOT, particles=128)
    res, prev = glitch_step(gpf)
    assert res.flags & Flag.LOW_ESS
    new, old = gpf.to_real_sigma(res.sigma), gpf.to_real_sigma(prev)
    grow = np.diag(new) - np.diag(old)
    q = BOT.app_params["process_var"]
    assert np.all(grow[[1, 3]] >= q * BOT.dt**2 * (1 - 1e-3))     # velocity: Gamma Q Gamma^T
    assert np.all(grow[[0, 2]] > 0)                                # position: Phi Sigma Phi^T
    assert math.isfinite(float(new.sum()))


def test_frozen_posterior_is_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    def frozen(dp, sigma, pairs):
        return sigma.copy(), np.zeros(len(sigma), np.int64)

    monkeypatch.setattr(blocks, "predicted_sigma", frozen)
    with pytest.raises(AssertionError):
        test_degenerate_step_samples_from_the_prediction()

"""Statistical quality of the GRNG model: 2 x 10^6 samples per lane of `bot` with 2 lanes.

Every check is a plain function returning (statistic, bound, ok). Each bound comes from the
statistic's sampling distribution under a correct N(0,1) generator (iid lanes and draws) and is
set so that one call of a check fails with probability at most ALPHA = 1e-8 (checks that look at
several statistics share ALPHA between them, Bonferroni). This file makes 17 check calls on
correct data, so a correct generator fails it with probability < 2e-7; the samples come from
fixed seeds, so a run is repeatable.

The model's own deviations from N(0,1) are far below these bounds: its output is quantised
to 2^-14 (variance + 2^-28/12), its inverse CDF is within 0.54 LSB of exact (a CDF shift of at
most phi(0) * 0.54 * 2^-14 = 1.3e-5, against a KS bound of 2.2e-3) and it clamps at 7.87 sigma
(a tail mass of 3.6e-15). test_checks_reject_bad_generators proves the checks can fail.
"""

from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from gpf.config import load_config
from gpf.model.grng import GrngModel

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
N = 2_000_000  # samples per lane
LANES = 2
SEED = 20240611
CLI_SAMPLES, CLI_SEED = 1_000_000, 7
ALPHA = 1e-8  # false-alarm probability of one check call on a correct generator

Result = tuple[float, float | tuple[float, float], bool]


def _z(alpha: float) -> float:
    """Two-sided normal quantile: P(|N(0,1)| > _z(alpha)) = alpha."""
    return float(stats.norm.isf(alpha / 2))


# ---- the checks ----------------------------------------------------------------------------
def check_mean(x: np.ndarray) -> Result:
    # The mean of n iid N(0,1) is N(0, 1/n): |mean| < z(ALPHA) / sqrt(n) (5.73 sigma).
    stat = abs(float(np.mean(x)))
    bound = _z(ALPHA) / math.sqrt(x.size)
    return stat, bound, stat < bound


def check_variance(x: np.ndarray) -> Result:
    # With the mean known (0), mean(x^2) - 1 has variance (E x^4 - 1) / n = 2 / n.
    stat = abs(float(np.mean(np.square(x))) - 1.0)
    bound = _z(ALPHA) * math.sqrt(2.0 / x.size)
    return stat, bound, stat < bound


def dequantise(x: np.ndarray, lsb: float, seed: int = 0) -> np.ndarray:
    """Spread each quantised value uniformly over its LSB, so a continuous cdf applies.

    Against the continuous cdf, the raw sample's empirical cdf jumps by phi * LSB at every
    output code: an offset of up to ~phi(0) * 2^-14 / 2 in KS D and a bias in bin counts.
    Adding U(-LSB/2, LSB/2) noise (the output is |z| rounded to nearest) removes it.
    """
    rng = np.random.default_rng(seed)
    return x + rng.uniform(-lsb / 2, lsb / 2, size=x.shape)


def check_ks(x: np.ndarray) -> Result:
    # Dvoretzky-Kiefer-Wolfowitz (Massart's constant), valid for every n:
    # P(D > eps) <= 2 exp(-2 n eps^2), so eps = sqrt(ln(2 / ALPHA) / (2 n)).
    stat = float(stats.kstest(x, "norm").statistic)
    bound = math.sqrt(math.log(2 / ALPHA) / (2 * x.size))
    return stat, bound, stat < bound


def check_chi_square(x: np.ndarray, bins: int = 100) -> Result:
    # Counts in `bins` equiprobable bins of N(0,1): the Pearson statistic is chi^2(bins - 1)
    # (expected count per bin 10^4, far above the usual >= 5).
    edges = stats.norm.ppf(np.arange(1, bins) / bins)
    counts = np.bincount(np.searchsorted(edges, x), minlength=bins)
    expected = x.size / bins
    stat = float(np.sum((counts - expected) ** 2) / expected)
    bound = float(stats.chi2.isf(ALPHA, bins - 1))
    return stat, bound, stat < bound


def check_tail_count(x: np.ndarray, t: float = 4.0) -> Result:
    # The count beyond +-t is Binomial(n, 2 Q(t)), at most as spread as Poisson(n 2 Q(t))
    # (2 Q(4) = 63.34 per 10^6): accept [ppf(ALPHA / 2), isf(ALPHA / 2)] of that Poisson.
    # (A sample exactly at +-4.0 is one code in 2^14: ~0.03 expected counts, negligible.)
    count = int(np.count_nonzero(np.abs(x) > t))
    lam = x.size * 2 * stats.norm.sf(t)
    lo, hi = stats.poisson.ppf(ALPHA / 2, lam), stats.poisson.isf(ALPHA / 2, lam)
    return count, (float(lo), float(hi)), bool(lo <= count <= hi)


def check_beyond(x: np.ndarray, t: float = 4.5) -> Result:
    # Presence of |z| > t: P(none) = (1 - 2 Q(t))^n <= exp(-n 2 Q(t)); 2 Q(4.5) = 6.8e-6, so
    # with 4 x 10^6 samples P(none) <= exp(-27) = 1.5e-12.
    lam = x.size * 2 * stats.norm.sf(t)
    if math.exp(-lam) > ALPHA:
        raise ValueError(f"{x.size} samples are too few to expect a value beyond {t} sigma")
    count = int(np.count_nonzero(np.abs(x) > t))
    return count, 1, count >= 1


def check_autocorrelation(x: np.ndarray, lags: range = range(1, 9)) -> Result:
    # For iid x, sqrt(n) r_k -> N(0, 1) for each lag (Bartlett); Bonferroni over the lags.
    xc = x - x.mean()
    den = float(np.dot(xc, xc))
    stat = max(abs(float(np.dot(xc[:-k], xc[k:])) / den) for k in lags)
    bound = _z(ALPHA / len(lags)) / math.sqrt(x.size)
    return stat, bound, stat < bound


def check_cross_correlation(a: np.ndarray, b: np.ndarray, lags: range = range(-2, 3)) -> Result:
    # Independent series: sqrt(n) corr(a_t, b_{t+k}) -> N(0, 1) for each k; Bonferroni.
    ac, bc = a - a.mean(), b - b.mean()
    den = math.sqrt(float(np.dot(ac, ac)) * float(np.dot(bc, bc)))
    n, stat = a.size, 0.0
    for k in lags:
        dot = np.dot(ac[: n - k], bc[k:]) if k >= 0 else np.dot(ac[-k:], bc[: n + k])
        stat = max(stat, abs(float(dot)) / den)
    bound = _z(ALPHA / len(lags)) / math.sqrt(a.size)
    return stat, bound, stat < bound


def check_normaltest(x: np.ndarray) -> Result:
    # D'Agostino-Pearson K^2 (skewness and kurtosis): chi^2(2) under normality, so
    # P(K^2 > 2 ln(1 / ALPHA) = 36.8) = ALPHA.
    stat = float(stats.normaltest(x).statistic)
    bound = float(stats.chi2.isf(ALPHA, 2))
    return stat, bound, stat < bound


# Each check applied to an (n, lanes) sample of real values with output LSB `lsb`.
Check = Callable[[np.ndarray, float], list[Result]]
CHECKS: dict[str, Check] = {
    "mean": lambda z, lsb: [check_mean(z[:, i]) for i in range(z.shape[1])],
    "variance": lambda z, lsb: [check_variance(z[:, i]) for i in range(z.shape[1])],
    "ks": lambda z, lsb: [check_ks(dequantise(z[:, i], lsb, i)) for i in range(z.shape[1])],
    "chi_square": lambda z, lsb: [check_chi_square(dequantise(z[:, i], lsb, i))
                                  for i in range(z.shape[1])],
    "tails_4_sigma": lambda z, lsb: [check_tail_count(z.ravel())],
    "beyond_4_5_sigma": lambda z, lsb: [check_beyond(z.ravel())],
    "autocorrelation": lambda z, lsb: [check_autocorrelation(z[:, i]) for i in range(z.shape[1])],
    "cross_lane": lambda z, lsb: [check_cross_correlation(z[:, 0], z[:, 1])],
    "normaltest": lambda z, lsb: [check_normaltest(z[:, i]) for i in range(z.shape[1])],
}


# ---- samples -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def samples() -> tuple[np.ndarray, float]:
    model = GrngModel(load_config(ROOT / "configs" / "bot.toml", {"filter.lanes": LANES}))
    return model.normals(N, seed=SEED), model.out.lsb


@pytest.fixture(scope="module")
def cli_samples(tmp_path_factory) -> np.ndarray:
    out = tmp_path_factory.mktemp("grng") / "z.npy"
    gpf = Path(sys.executable).with_name("gpf")
    cmd = [str(gpf)] if gpf.exists() else [sys.executable, "-m", "gpf.cli"]
    subprocess.run([*cmd, "model", "grng", "--config", "configs/bot.toml", "--samples",
                    str(CLI_SAMPLES), "--seed", str(CLI_SEED), "--out", str(out)],
                   cwd=ROOT, check=True, capture_output=True, text=True, timeout=120)
    return np.load(out)


def _describe(results: list[Result]) -> str:
    return "; ".join(f"stat {s:.6g} bound {b} ok {ok}" for s, b, ok in results)


# ---- a correct generator passes ------------------------------------------------------------
@pytest.mark.parametrize("name", CHECKS)
def test_model_passes(samples, name):
    z, lsb = samples
    assert z.shape == (N, LANES)
    results = CHECKS[name](z, lsb)
    assert all(ok for _, _, ok in results), f"{name}: {_describe(results)}"


def test_command_line_output_is_normal(cli_samples):
    z = cli_samples
    assert z.shape == (CLI_SAMPLES, 1)
    cfg = load_config(ROOT / "configs" / "bot.toml")
    # the command line writes the model's samples, unchanged
    assert np.array_equal(z, GrngModel(cfg).normals(CLI_SAMPLES, seed=CLI_SEED))
    results = [check_normaltest(z[:, 0]),
               check_chi_square(dequantise(z[:, 0], cfg.noise.lsb, 99))]
    assert all(ok for _, _, ok in results), _describe(results)


# ---- a wrong generator fails ---------------------------------------------------------------
def _lag1(z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    a = 0.012  # y_t = (z_t + a z_{t-1}) / sqrt(1 + a^2): N(0,1) marginals, r_1 = 0.012
    return (z + a * np.roll(z, 1, axis=0)) / math.sqrt(1 + a * a)


def _cross(z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    a = 0.012  # lane 0 leaks into lane 1: correlation 0.012 at lag 0
    out = z.copy()
    out[:, 1] = (z[:, 1] + a * z[:, 0]) / math.sqrt(1 + a * a)
    return out


def _irwin_hall(z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    # the classic cheap GRNG: the sum of 12 uniforms minus 6 (mean 0, variance 1, but
    # |z| > 4 has probability 1.7e-5 instead of 6.3e-5, and excess kurtosis -0.1)
    return sum(rng.random(z.shape) for _ in range(12)) - 6.0


# (sample from the good one, checks that must reject it). Not here: flipping the sign of
# every 50th sample, which leaves an iid symmetric sequence iid N(0,1), so no test can see it.
BAD: dict[str, tuple[Callable[[np.ndarray, np.random.Generator], np.ndarray], list[str]]] = {
    "mean_plus_0.02": (lambda z, rng: z + 0.02, ["mean", "ks", "chi_square"]),
    "variance_1.02": (lambda z, rng: z * math.sqrt(1.02), ["variance", "chi_square"]),
    "lag1_correlated": (_lag1, ["autocorrelation"]),
    "lanes_correlated": (_cross, ["cross_lane"]),
    "sum_of_12_uniforms": (_irwin_hall, ["tails_4_sigma", "normaltest"]),
    "tails_cut_at_4.4": (lambda z, rng: np.clip(z, -4.4, 4.4), ["beyond_4_5_sigma"]),
}


@pytest.mark.parametrize("bad", BAD)
def test_checks_reject_bad_generators(samples, bad):
    z, lsb = samples
    make, rejecting = BAD[bad]
    wrong = make(z, np.random.default_rng(1))
    for name in rejecting:
        results = CHECKS[name](wrong, lsb)
        assert not all(ok for _, _, ok in results), f"{bad} passed {name}: {_describe(results)}"

"""Monte Carlo runs of the fixed-point and float64 GPFs on the same scenarios and draws, and
the word-length study built on them.

Run r uses scenario seed `seed + r` (unless a scenario file is given) and GRNG seed `seed + r`;
the float64 filter is fed the fixed-point filter's own draws (as reals), so the difference of the
two is the quantisation error alone.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from gpf.config import Config
from gpf.model import scenarios
from gpf.model.blocks import Flag
from gpf.model.fixed_gpf import FixedGPF, run
from gpf.model.float_gpf import FloatGPF, attitude_error_deg, position_error

SCENARIOS: dict[str, Callable[..., scenarios.Scenario]] = {
    "bot_fixed_observer": scenarios.bot_fixed_observer,
    "bot_manoeuvring_observer": scenarios.bot_manoeuvring_observer,
    "uav_flight": scenarios.uav_flight,
    # faults: flagged and survived
    "bot_outlier": scenarios.bot_outlier,
    "uav_gps_glitch": scenarios.uav_gps_glitch,
    "bot_far_target": scenarios.bot_far_target,
}
DEFAULT_SCENARIO = {"bot": "bot_fixed_observer", "uav": "uav_flight"}


def error_per_step(app: str, est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """bot: position error in metres; uav: attitude error in degrees (rows k = 0..steps)."""
    return position_error(est, truth) if app == "bot" else attitude_error_deg(est, truth)


def flag_names(bits: int) -> list[str]:
    return [f.name.lower() for f in Flag if bits & f]


@dataclass
class MonteCarlo:
    app: str
    steps: int
    particles: int
    runs: int
    seed: int
    word: int | None
    scenario: str
    # float: fed the GRNG model's draws; float_numpy: numpy's own generator (independent draws)
    sq_err: dict[str, list[np.ndarray]] = field(
        default_factory=lambda: {"float": [], "fixed": [], "float_numpy": []})
    first: dict[str, Any] = field(default_factory=dict)
    flag_counts: dict[str, int] = field(default_factory=dict)

    def rmse(self, which: str) -> float:
        """Root mean square error over every run and every step k >= 1."""
        return float(math.sqrt(np.mean(np.concatenate(self.sq_err[which]))))

    def ratio_and_noise(self, boot: int = 400) -> tuple[float, float]:
        """RMSE(fixed)/RMSE(float) and its standard error (bootstrap over runs)."""
        fx = np.array([e.mean() for e in self.sq_err["fixed"]])
        fl = np.array([e.mean() for e in self.sq_err["float"]])
        ratio = math.sqrt(fx.mean() / fl.mean())
        rng = np.random.default_rng(0)
        idx = rng.integers(0, len(fx), size=(boot, len(fx)))
        samples = np.sqrt(fx[idx].mean(axis=1) / fl[idx].mean(axis=1))
        return ratio, float(samples.std()) if len(fx) > 1 else float("nan")

    def summary(self) -> dict[str, Any]:
        ratio, noise = self.ratio_and_noise()
        unit = "m (position)" if self.app == "bot" else "deg (attitude)"
        return {
            "app": self.app, "scenario": self.scenario, "steps": self.steps,
            "particles": self.particles, "runs": self.runs, "seed": self.seed,
            "word": self.word, "rmse_unit": unit,
            "rmse": {"float": self.rmse("float"), "fixed": self.rmse("fixed"),
                     "float_numpy_draws": self.rmse("float_numpy")},
            "ratio_fixed_float": ratio, "ratio_std_error": noise,
            "flag_steps": self.flag_counts, "per_step": self.first,
        }


def monte_carlo(cfg: Config, runs: int = 10, steps: int | None = None,
                particles: int | None = None, seed: int = 1, word: int | None = None,
                scenario: str | scenarios.Scenario | None = None,
                progress: bool = True) -> MonteCarlo:
    if isinstance(scenario, scenarios.Scenario):
        if steps is not None and steps != scenario.steps:
            raise ValueError(f"--steps {steps}: the scenario file has {scenario.steps} steps")
        steps = scenario.steps
    steps = steps or cfg.steps
    gpf = FixedGPF(cfg, particles=particles, word=word)
    flt = FloatGPF(cfg, gpf.particles)
    name = scenario if isinstance(scenario, str) else (
        "file" if scenario is not None else DEFAULT_SCENARIO[cfg.app])
    if name != "file" and name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}: choose one of {', '.join(SCENARIOS)} "
                         "or give a CSV file")
    out = MonteCarlo(cfg.app, steps, gpf.particles, runs, seed, word, name)
    counts = dict.fromkeys((f.name.lower() for f in Flag), 0)
    bar = tqdm(range(runs), desc=f"{cfg.name} {name} N={gpf.particles}", unit="run",
               disable=not progress, leave=False)
    for r in bar:
        sc = scenario if isinstance(scenario, scenarios.Scenario) else \
            SCENARIOS[name](cfg, steps, seed + r)
        if sc.app != cfg.app:
            raise ValueError(f"scenario is for app {sc.app!r}, config {cfg.name} is {cfg.app!r}")
        fixed = run(gpf, sc, seed=seed + r)
        real_draws = gpf.dp.noise.to_real(fixed.draws)
        floating = flt.run(sc, draws=real_draws)
        independent = flt.run(sc, rng=np.random.default_rng([seed, r]))
        err_fixed = error_per_step(cfg.app, fixed.mu, sc.truth)
        err_float = error_per_step(cfg.app, floating.mu, sc.truth)
        out.sq_err["float_numpy"].append(
            error_per_step(cfg.app, independent.mu, sc.truth)[1:] ** 2)
        out.sq_err["fixed"].append(err_fixed[1:] ** 2)
        out.sq_err["float"].append(err_float[1:] ** 2)
        for bits in fixed.flags[1:]:
            for fname in flag_names(int(bits)):
                counts[fname] += 1
        if r == 0:
            out.first = {
                "truth": sc.truth.tolist(), "float": floating.mu.tolist(),
                "fixed": fixed.mu.tolist(), "error_float": err_float.tolist(),
                "error_fixed": err_fixed.tolist(),
                "flags": [flag_names(int(b)) for b in fixed.flags],
            }
            if cfg.app == "bot":
                out.first["observer"] = sc.inputs["observer"].tolist()
    out.flag_counts = counts
    return out


def plot(mc: MonteCarlo, directory: str) -> list[str]:
    """PNGs like seed 002's figures 3-4: truth vs estimates, and the error per step."""
    import matplotlib

    matplotlib.use("Agg")  # files only, no display needed
    import matplotlib.pyplot as plt

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    first = mc.first
    truth, fl, fx = (np.array(first[k]) for k in ("truth", "float", "fixed"))
    files = []
    fig, ax = plt.subplots(figsize=(7, 5))
    if mc.app == "bot":
        ax.plot(truth[:, 0], truth[:, 2], "k-", label="truth")
        ax.plot(fl[:, 0], fl[:, 2], "b--", label="float64 GPF")
        ax.plot(fx[:, 0], fx[:, 2], "r:", label="fixed-point GPF")
        obs = np.array(first["observer"])
        ax.plot(obs[1:, 0], obs[1:, 1], "g.", ms=3, label="observer")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"bot: track, first run (N = {mc.particles})")
    else:
        t = np.arange(len(truth))
        for i, name in enumerate(("q0", "q1", "q2", "q3")):
            ax.plot(t, truth[:, i], "k-", lw=1, label="truth" if i == 0 else None)
            ax.plot(t, fx[:, i], "r:", label="fixed-point" if i == 0 else None)
            ax.text(t[-1], truth[-1, i], name)
        ax.set_xlabel("step")
        ax.set_title(f"uav: attitude quaternion, first run (N = {mc.particles})")
    ax.legend()
    files.append(str(out / f"{mc.app}_estimate.png"))
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(7, 4))
    unit = "position error (m)" if mc.app == "bot" else "attitude error (deg)"
    ax.plot(first["error_float"], "b-", label="float64")
    ax.plot(first["error_fixed"], "r:", label="fixed point")
    ax.set_xlabel("step")
    ax.set_ylabel(unit)
    ax.set_title(f"{mc.app}: error per step, first run; RMSE over {mc.runs} runs "
                 f"float {mc.rmse('float'):.4g}, fixed {mc.rmse('fixed'):.4g}")
    ax.legend()
    files.append(str(out / f"{mc.app}_error.png"))
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)
    return files

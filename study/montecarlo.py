"""Monte Carlo runs of the fixed-point and float64 GPFs on the same scenarios and draws.

Run r uses scenario seed `seed + r` (unless a scenario file is given) and GRNG seed `seed + r`;
the float64 filter is fed the fixed-point filter's own draws (as reals), so the difference of
the two is the quantisation error alone; a third filter, float64 on numpy's independent draws,
shows how much the draws themselves matter. All runs of a batch step together (the models are
vectorised over runs and particles) and the draws stream in chunks of steps, so a 6000-step
flight needs no more memory than a short run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from gpf.config import Config
from gpf.model import scenarios
from gpf.model.blocks import Flag
from gpf.model.fixed_gpf import FixedGPF
from gpf.model.float_gpf import FLAGS, FloatGPF, cholesky
from gpf.study.metrics import (
    LOST_FACTOR,
    METRICS,
    PRIMARY,
    TRACKED,
    last_window,
    lost_track,
    metric,
)

SCENARIOS: dict[str, Callable[..., scenarios.Scenario]] = {
    "bot_fixed_observer": scenarios.bot_fixed_observer,
    "bot_manoeuvring_observer": scenarios.bot_manoeuvring_observer,
    "uav_flight": scenarios.uav_flight,
    # faults: flagged and survived
    "bot_outlier": scenarios.bot_outlier,
    "bot_bearing_glitch": scenarios.bot_bearing_glitch,
    "uav_gps_glitch": scenarios.uav_gps_glitch,
    "bot_far_target": scenarios.bot_far_target,
}
DEFAULT_SCENARIO = {"bot": "bot_fixed_observer", "uav": "uav_flight"}
FILTERS = ("fixed", "float", "float_numpy")   # float: the GRNG's draws; float_numpy: numpy's
BATCH_PARTICLES = 1 << 17   # particles of all runs stepped together (memory, not speed)
CHUNK_DRAWS = 1 << 22       # draws generated at once


def flag_names(bits: int) -> list[str]:
    return [f.name.lower() for f in Flag if bits & f]


@dataclass
class MonteCarlo:
    """Estimates of every run and filter, and the figures drawn from them."""

    app: str
    steps: int
    particles: int
    runs: int
    seed: int
    word: int | None
    scenario: str
    truth: np.ndarray                                   # (R, steps+1, n)
    est: dict[str, np.ndarray]                          # filter -> (R, steps+1, n)
    flags: np.ndarray                                   # (R, steps+1) fixed point's Flag bits
    float_flags: dict[str, np.ndarray]                  # name -> (R, steps+1) float64's
    ess: dict[str, np.ndarray]                          # fixed, float -> (R, steps+1)
    observer: np.ndarray | None = None                  # bot: (steps+1, 2) of the first run
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def has_truth(self) -> bool:
        return bool(np.all(np.isfinite(self.truth[:, 1:])))

    def errors(self, which: str, name: str | None = None) -> np.ndarray:
        """(R, steps+1) error of a filter's estimates in metric `name` (default primary)."""
        m = metric(self.app, name or PRIMARY[self.app])
        return m.error(self.est[which], self.truth)

    def _mse(self, which: str, name: str | None, window: slice) -> np.ndarray:
        """Mean square error per run over the window's steps."""
        return np.mean(self.errors(which, name)[:, window] ** 2, axis=1)

    def rmse(self, which: str, name: str | None = None, window: slice | None = None) -> float:
        """Root mean square error over every run and every step of the window (default: all
        steps k >= 1)."""
        return float(math.sqrt(np.mean(self._mse(which, name, window or slice(1, None)))))

    def ratio_and_noise(self, name: str | None = None, window: slice | None = None,
                        boot: int = 400) -> tuple[float, float]:
        """RMSE(fixed)/RMSE(float) and its standard error (bootstrap over runs)."""
        window = window or slice(1, None)
        fx, fl = self._mse("fixed", name, window), self._mse("float", name, window)
        ratio = math.sqrt(fx.mean() / fl.mean())
        if len(fx) < 2:
            return ratio, float("nan")
        idx = np.random.default_rng(0).integers(0, len(fx), size=(boot, len(fx)))
        samples = np.sqrt(fx[idx].mean(axis=1) / fl[idx].mean(axis=1))
        return ratio, float(samples.std())

    def lost_tracks(self) -> list[int]:
        """Runs whose error over the last 20 % exceeds LOST_FACTOR x the float64 filter's on
        the same draws, in any tracked metric."""
        last = last_window(self.steps)
        rms = {which: {name: np.sqrt(self._mse(which, name, last)) for name in TRACKED[self.app]}
               for which in ("fixed", "float")}
        return [int(r) for r in np.flatnonzero(lost_track(self.app, rms["fixed"], rms["float"]))]

    def quantisation_max(self) -> float:
        """The largest distance, in the primary metric, between the fixed-point and the float64
        estimates on the same draws (every run, steps 1..steps): the quantisation error, known
        with or without truth."""
        m = metric(self.app, PRIMARY[self.app])
        return float(np.max(m.error(self.est["fixed"][:, 1:], self.est["float"][:, 1:])))

    def flag_counts(self) -> dict[str, int]:
        """Steps (over all runs) that raised each flag, fixed point."""
        return {f.name.lower(): int(np.count_nonzero(self.flags[:, 1:] & f)) for f in Flag}

    def float_flag_counts(self) -> dict[str, int]:
        return {name: int(np.count_nonzero(v[:, 1:])) for name, v in self.float_flags.items()}

    def metric_table(self) -> dict[str, Any]:
        """Per metric: RMSE of each filter and the ratio, over all steps and the last 20 %."""
        out: dict[str, Any] = {}
        if not self.has_truth:
            return out
        for m in METRICS[self.app]:
            entry: dict[str, Any] = {"unit": m.unit}
            for label, window in (("all", slice(1, None)), ("last20", last_window(self.steps))):
                ratio, noise = self.ratio_and_noise(m.name, window)
                entry[label] = {**{w: self.rmse(w, m.name, window) for w in FILTERS},
                                "ratio": ratio, "ratio_std_error": _finite(noise)}
            out[m.name] = entry
        return out

    def summary(self) -> dict[str, Any]:
        primary = metric(self.app, PRIMARY[self.app])
        out: dict[str, Any] = {
            "app": self.app, "scenario": self.scenario, "steps": self.steps,
            "particles": self.particles, "runs": self.runs, "seed": self.seed,
            "word": self.word, "primary_metric": primary.name,
            "rmse_unit": primary.unit, "metrics": self.metric_table(),
            "flag_steps": self.flag_counts(), "float_flag_steps": self.float_flag_counts(),
            "ess_mean": {k: float(np.mean(v[:, 1:])) for k, v in self.ess.items()},
            "quantisation_max": self.quantisation_max(),
        }
        if self.has_truth:
            ratio, noise = self.ratio_and_noise()
            out.update({"rmse": {"float": self.rmse("float"), "fixed": self.rmse("fixed"),
                                 "float_numpy_draws": self.rmse("float_numpy")},
                        "ratio_fixed_float": ratio, "ratio_std_error": _finite(noise),
                        "lost_tracks": len(self.lost_tracks()),
                        "lost_runs": self.lost_tracks(), "lost_factor": LOST_FACTOR})
        else:   # a recording: what needs truth cannot be computed (null, "n/a" in text)
            out.update({"rmse": dict.fromkeys(("float", "fixed", "float_numpy_draws")),
                        "ratio_fixed_float": None, "ratio_std_error": None,
                        "lost_tracks": None, "lost_runs": None, "lost_factor": LOST_FACTOR})
        if self.has_truth:
            out["per_run_last20"] = self.per_run_last20()
        out["per_step"] = self.first_run()
        return out

    def per_run_last20(self) -> dict[str, dict[str, list[float]]]:
        """Each run's RMSE over its last 20 %, per tracked metric and filter (lost tracks are
        judged on these)."""
        last = last_window(self.steps)
        return {name: {w: np.sqrt(self._mse(w, name, last)).round(6).tolist()
                       for w in ("fixed", "float")} for name in TRACKED[self.app]}

    def first_run(self) -> dict[str, Any]:
        """Truth, estimates, flags and ESS of run 0, for plots and scripts."""
        first: dict[str, Any] = {
            "truth": _json_rows(self.truth[0]),
            **{k: self.est[k][0].tolist() for k in ("float", "fixed")},
            "flags": [flag_names(int(b)) for b in self.flags[0]],
            "ess_fixed": _json_rows(self.ess["fixed"][0]),
            "ess_float": _json_rows(self.ess["float"][0]),
        }
        if self.has_truth:
            first.update({f"error_{k}": self.errors(k)[0].tolist() for k in ("float", "fixed")})
        if self.observer is not None:
            first["observer"] = _json_rows(self.observer)
        return first


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _json_rows(a: np.ndarray) -> list:
    """NaN (unknown) as null: JSON has no NaN."""
    return [None if not np.all(np.isfinite(v)) else v for v in np.asarray(a).tolist()] \
        if np.ndim(a) > 1 else [v if math.isfinite(v) else None for v in np.asarray(a).tolist()]


def resolve(cfg: Config, steps: int | None, scenario: str | scenarios.Scenario | None
            ) -> tuple[str, int]:
    """The scenario's name (or "file") and the run length: a recording's own, or its first
    `steps` (more than it has: a ValueError)."""
    if isinstance(scenario, scenarios.Scenario):
        if scenario.app != cfg.app:
            raise ValueError(f"scenario is for app {scenario.app!r}, config {cfg.name} is "
                             f"{cfg.app!r}")
        if steps is None:
            return "file", scenario.steps
        scenario.first(steps)      # refuses more steps than the recording has
        return "file", steps
    name = scenario or DEFAULT_SCENARIO[cfg.app]
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}: choose one of {', '.join(SCENARIOS)} "
                         "or give a CSV file")
    if not name.startswith(cfg.app + "_"):
        raise ValueError(f"scenario {name} is for app {name.split('_')[0]!r}, config "
                         f"{cfg.name} is {cfg.app!r}")
    return name, steps or cfg.steps


def monte_carlo(cfg: Config, runs: int = 10, steps: int | None = None,
                particles: int | None = None, seed: int = 1, word: int | None = None,
                scenario: str | scenarios.Scenario | None = None,
                progress: bool = True) -> MonteCarlo:
    name, steps = resolve(cfg, steps, scenario)
    if isinstance(scenario, scenarios.Scenario) and steps < scenario.steps:
        scenario = scenario.first(steps)     # a recording filtered in part: its first steps
    fixed = FixedGPF(cfg, particles=particles, word=word)
    flt = FloatGPF(cfg, fixed.particles)
    n, count = fixed.dp.n, fixed.particles
    batch = max(1, min(runs, BATCH_PARTICLES // count))
    est = {k: np.empty((runs, steps + 1, n)) for k in FILTERS}
    truth = np.empty((runs, steps + 1, n))
    flags = np.zeros((runs, steps + 1), dtype=np.int64)
    float_flags = {f: np.zeros((runs, steps + 1), dtype=bool) for f in FLAGS}
    ess = {k: np.full((runs, steps + 1), np.nan) for k in ("fixed", "float")}
    observer = None
    bar = tqdm(total=runs * steps, desc=f"{cfg.name} {name} N={count}", unit="step",
               disable=None if progress else True, leave=False, unit_scale=True)  # a terminal only
    for first in range(0, runs, batch):
        ids = list(range(first, min(runs, first + batch)))
        scs = [scenario if isinstance(scenario, scenarios.Scenario)
               else SCENARIOS[name](cfg, steps, seed + r) for r in ids]
        if observer is None and cfg.app == "bot":
            observer = scs[0].inputs["observer"]
        batch_runs = _BatchRuns(fixed, flt, scs, seed, ids)
        truth[ids] = np.stack([sc.truth for sc in scs])
        for k, res in batch_runs.steps(bar):
            for key, value in res.est.items():
                est[key][ids, k] = value
            flags[ids, k] = res.flags
            for f, on in res.float_flags.items():
                float_flags[f][ids, k] = on
            for key, value in res.ess.items():
                ess[key][ids, k] = value
    bar.close()
    return MonteCarlo(cfg.app, steps, count, runs, seed, word, name, truth, est, flags,
                      float_flags, ess, observer)


@dataclass
class _Record:
    est: dict[str, np.ndarray]
    flags: np.ndarray
    float_flags: dict[str, np.ndarray]
    ess: dict[str, np.ndarray]


class _BatchRuns:
    """A batch of runs of the three filters, stepped together."""

    def __init__(self, fixed: FixedGPF, flt: FloatGPF, scs: list[scenarios.Scenario],
                 seed: int, ids: list[int]):
        self.fixed, self.flt, self.scs = fixed, flt, scs
        inits = [flt.initial(sc) for sc in scs]
        raw = [fixed.init(mu0, sigma0) for mu0, sigma0 in inits]
        self.f_mu = np.stack([m for m, _ in raw]).astype(np.int64)
        self.f_chol = np.stack([c for _, c in raw]).astype(np.int64)
        sig = [fixed.quantise_sigma(s) for _, s in inits]
        self.f_sigma = np.array([[s[p] for p in fixed.pairs] for s in sig], dtype=np.int64)
        self.mu0 = np.stack([m for m, _ in inits])
        chol0 = cholesky(np.stack([s for _, s in inits]))[0]
        sigma0 = np.stack([s for _, s in inits])
        self.g_mu, self.g_chol, self.g_sigma = self.mu0.copy(), chol0, sigma0  # GRNG draws
        self.n_mu, self.n_chol, self.n_sigma = self.mu0.copy(), chol0, sigma0  # numpy draws
        # every step's inputs of every run: reals (R, steps+1, ...) and raw (R, steps, ...)
        self.real_inputs = {key: np.stack([{**sc.inputs, **sc.measurements}[key] for sc in scs])
                            for key in {**scs[0].inputs, **scs[0].measurements}}
        self.raw_inputs = fixed.quantise_batch({key: a[:, 1:]
                                                for key, a in self.real_inputs.items()})
        self.streams = [fixed.draw_stream(seed + r) for r in ids]
        self.rngs = [np.random.default_rng([seed, r]) for r in ids]

    def steps(self, bar: tqdm):
        fixed, flt, scs = self.fixed, self.flt, self.scs
        runs, count, d = len(scs), fixed.particles, fixed.dp.draws()
        steps = scs[0].steps
        yield 0, self._record0()
        chunk = max(1, CHUNK_DRAWS // (runs * count * d))
        for start in range(1, steps + 1, chunk):
            todo = min(chunk, steps + 1 - start)
            raw = np.stack([s.next(todo) for s in self.streams], axis=1)   # (c, R, N, D)
            real = fixed.dp.noise.to_real(raw)
            for j in range(todo):
                k = start + j
                f = fixed.step_batch(self.f_mu, self.f_chol, self.f_sigma,
                                     {key: a[:, k - 1] for key, a in self.raw_inputs.items()},
                                     raw[j])
                self.f_mu, self.f_chol, self.f_sigma = f.mu, f.chol, f.sigma
                stacked = {key: a[:, k] for key, a in self.real_inputs.items()}
                g = flt.step_batch(self.g_mu, self.g_chol, stacked, real[j], self.g_sigma)
                self.g_mu, self.g_chol, self.g_sigma = g.mu, g.L, g.Sigma
                numpy_draws = np.stack([rng.standard_normal((count, d)) for rng in self.rngs])
                h = flt.step_batch(self.n_mu, self.n_chol, stacked, numpy_draws, self.n_sigma)
                self.n_mu, self.n_chol, self.n_sigma = h.mu, h.L, h.Sigma
                bar.update(runs)
                yield k, _Record({"fixed": fixed.to_real_mu(f.mu), "float": g.mu,
                                  "float_numpy": h.mu}, f.flags, g.flags,
                                 {"fixed": fixed.to_real_ess(f.ess), "float": g.ess})

    def _record0(self) -> _Record:
        fixed = self.fixed
        runs = len(self.scs)
        mu = fixed.to_real_mu(self.f_mu)
        return _Record({"fixed": mu, "float": self.mu0, "float_numpy": self.mu0},
                       np.zeros(runs, dtype=np.int64),
                       {f: np.zeros(runs, dtype=bool) for f in FLAGS},
                       {"fixed": np.full(runs, np.nan), "float": np.full(runs, np.nan)})

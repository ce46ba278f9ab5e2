"""The bit-exact fixed-point GPF: the blocks of blocks.py chained as the hardware chains them,
with the normal draws of the GRNG model.

Draws: the filter's GRNG has D x LANES lanes (D draws per particle, see Datapath.draws); the
beat at clock t gives particles t*LANES .. t*LANES+LANES-1 their D draws each, lane p*D + d to
draw d of particle p. The GRNG runs on across steps (N / LANES beats per step, no reseed).

`step_batch` filters R independent runs at once (Monte Carlo): their particles are stacked and
every line-rate block runs once over all of them; `step` is the same for one run.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gpf.config import Config
from gpf.model import blocks
from gpf.model.blocks import Flag
from gpf.model.formats import Datapath, datapath
from gpf.model.grng import GrngModel, GrngStream


@dataclass
class StepResult:
    mu: np.ndarray                        # raw, state formats
    sigma: dict[tuple[int, int], int]     # raw, fraction dp.cov_frac(i, j)
    chol: np.ndarray                      # raw L, chol formats
    flags: int
    ess: int = 0                          # raw, dp.ess: W^2 / sum w^2 of the step's weights
    particles: dict[str, np.ndarray] = field(default_factory=dict)  # debug tap (optional)


@dataclass
class BatchStep:
    """One step of R runs: the state that feeds the next step, and what the step reports."""

    mu: np.ndarray          # (R, n) raw
    sigma: np.ndarray       # (R, P) raw, the covariance pairs' order
    chol: np.ndarray        # (R, n, n) raw
    flags: np.ndarray       # (R,) Flag bits
    ess: np.ndarray         # (R,) raw, dp.ess
    taps: dict[str, np.ndarray] = field(default_factory=dict)   # (R, N, ...) when kept


class FixedGPF:
    def __init__(self, cfg: Config, particles: int | None = None, word: int | None = None,
                 covariance: str | None = None):
        self.cfg = cfg
        self.dp: Datapath = datapath(cfg, word)
        self.particles = particles or cfg.particles
        if self.particles % cfg.lanes:
            raise ValueError(f"particles = {self.particles}: must be a multiple of "
                             f"lanes = {cfg.lanes}")
        self.covariance = covariance or cfg.covariance
        self.pairs = blocks.cov_pairs(self.dp, self.covariance)
        self.ess_min = ess_threshold(self.dp, self.particles)

    # ---- draws -----------------------------------------------------------------------------
    def grng(self) -> GrngModel:
        """The filter's GRNG model: D x LANES lanes."""
        return GrngModel(self.cfg, lanes=self.dp.draws() * self.cfg.lanes)

    def draws(self, steps: int, seed: int | None = None) -> np.ndarray:
        """Raw normal draws (steps, N, D) from the GRNG model, in the hardware's order."""
        return self.draw_stream(seed).next(steps)

    def draw_stream(self, seed: int | None = None) -> DrawStream:
        """The same draws a chunk of steps at a time (long runs need not hold them all)."""
        return DrawStream(GrngStream(self.grng(), seed), self.particles, self.dp.draws(),
                          self.cfg.lanes)

    # ---- quantisation of inputs ----------------------------------------------------------
    def quantise_state(self, values: np.ndarray) -> np.ndarray:
        return np.array([fmt.from_real(float(v))[0] for fmt, v in zip(self.dp.x, values,
                                                                       strict=True)])

    def init(self, mu0: np.ndarray, sigma0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw (mu, L) from real mu0 and Sigma0 (exact Cholesky of the quantised Sigma0)."""
        chol, _ = blocks.cholesky(self.dp, self.quantise_sigma(sigma0))
        return self.quantise_state(mu0), chol

    def quantise_sigma(self, sigma0: np.ndarray) -> dict[tuple[int, int], int]:
        """Raw Sigma entries (the covariance pairs) of a real matrix, rounded half up."""
        frac = self.dp.cov_frac
        return {(i, j): math.floor(float(sigma0[i, j]) * 2.0 ** frac(i, j) + 0.5)
                for i, j in self.pairs}

    def quantise_inputs(self, raw_inputs: dict) -> dict:
        """Real per-step inputs -> raw: bot z (rad) in turns, observer in the state format;
        uav omega, accel, v_gps in their formats."""
        raw = self.quantise_batch({k: np.asarray(v, dtype=float) for k, v in raw_inputs.items()})
        if self.dp.app == "bot":
            return {"z": int(raw["z"]), "observer": tuple(int(v) for v in raw["observer"])}
        return raw

    def quantise_batch(self, real: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """quantise_inputs of arrays with any leading axes (runs, steps): bot z (...),
        observer (..., 2); uav omega, accel, v_gps (..., 3)."""
        dp = self.dp
        if dp.app == "bot":
            turns = np.asarray(real["z"], dtype=float) / (2 * math.pi)
            z = blocks.wrap_angle(np.floor(turns * 2.0**dp.angle_frac + 0.5).astype(np.int64),
                                  dp.angle_frac)
            obs = np.asarray(real["observer"], dtype=float)
            return {"z": z, "observer": np.stack([dp.x[0].from_real(obs[..., 0])[0],
                                                   dp.x[2].from_real(obs[..., 1])[0]], axis=-1)}
        v = np.asarray(real["v_gps"], dtype=float)
        return {"omega": np.asarray(dp.gyro.from_real(real["omega"])[0]),
                "accel": np.asarray(dp.accel.from_real(real["accel"])[0]),
                "v_gps": np.stack([dp.x[4 + k].from_real(v[..., k])[0] for k in range(3)],
                                  axis=-1)}

    @staticmethod
    def stack_inputs(inputs: list[dict]) -> dict[str, np.ndarray]:
        """Raw inputs of R runs (quantise_inputs each) as arrays with a leading run axis."""
        return {key: np.array([np.asarray(i[key], dtype=np.int64) for i in inputs])
                for key in inputs[0]}

    # ---- one step ----------------------------------------------------------------------------
    def _propagate(self, x: np.ndarray, e: np.ndarray, inputs: dict, rows: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        if self.dp.app == "bot":
            return blocks.propagate_bot(self.dp, x, e, per_particle=True)
        return blocks.propagate_uav(self.dp, x, e, inputs["omega"][rows], inputs["accel"][rows],
                                    per_particle=True)

    def _exponent(self, x: np.ndarray, inputs: dict, rows: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        if self.dp.app == "bot":
            obs = inputs["observer"][rows]
            return blocks.exponent_bot(self.dp, x, inputs["z"][rows], (obs[:, 0], obs[:, 1]))
        return blocks.exponent_uav(self.dp, x, inputs["v_gps"][rows])

    def step_batch(self, mu: np.ndarray, chol: np.ndarray, sigma_prev: np.ndarray,
                   inputs: dict[str, np.ndarray], e: np.ndarray,
                   keep_particles: bool = False) -> BatchStep:
        """One filter step of R runs. mu (R, n), chol (R, n, n), sigma_prev (R, P): the state
        the step samples from; inputs: stack_inputs of the runs' raw inputs; e (R, N, D) raw.
        keep_particles: the debug taps' particles, weights and each one's SAT flag per block."""
        dp, n, lanes = self.dp, self.dp.n, self.cfg.lanes
        runs, count, d = e.shape
        rows = np.repeat(np.arange(runs), count)            # each particle's run
        flat = e.reshape(runs * count, d)
        cond, m1 = blocks.sample_cond(dp, mu[rows], chol[rows], flat[:, :n], self.pairs,
                                      per_particle=True)
        prop, m2 = self._propagate(cond, flat[:, n:], inputs, rows)
        own = np.arange(runs)
        ref, m3 = self._propagate(mu, np.zeros((runs, d - n), np.int64), inputs, own)
        t, m4 = self._exponent(prop, inputs, rows)
        w, shift = blocks.relative_weights(dp, t.reshape(runs, count), lanes)
        mom = blocks.moments_batch(dp, prop.reshape(runs, count, n), w, shift, ref, self.pairs)
        line = (m1 | m2 | m4).reshape(runs, count)
        flags = np.bitwise_or.reduce(line, axis=1) | m3 | mom.flags
        # degenerate weights: sample the next step from the predicted covariance instead
        sigma, low = mom.sigma, mom.ess < self.ess_min
        if np.any(low):
            pred, f = blocks.predicted_sigma(dp, sigma_prev, self.pairs)
            sigma = np.where(low[:, None], pred, sigma)
            flags = flags | np.where(low, f | np.int64(Flag.LOW_ESS), np.int64(0))
        chol_out, f = blocks.cholesky_batch(dp, sigma, self.pairs)
        flags = flags | f
        taps = {}
        if keep_particles:
            def per_run(a: np.ndarray) -> np.ndarray:
                return a.reshape(runs, count, *a.shape[1:])
            taps = {"cond": per_run(cond), "cond_sat": per_run(m1 != 0),
                    "prop": per_run(prop), "prop_sat": per_run(m2 != 0), "weight": w,
                    "shift": shift, "weight_sat": per_run(m4 != 0)}
        return BatchStep(mom.mu, sigma, chol_out, flags, mom.ess, taps)

    def step(self, mu: np.ndarray, chol: np.ndarray, sigma_prev: dict, inputs: dict,
             e: np.ndarray, keep_particles: bool = False) -> StepResult:
        """One filter step of one run. inputs: raw per-step inputs (quantise_inputs); e: (N, D)
        raw. keep_particles: the debug tap's particles and each one's SAT flag per block."""
        prev = np.array([[sigma_prev[pr] for pr in self.pairs]], dtype=np.int64)
        res = self.step_batch(np.asarray(mu, np.int64)[None], np.asarray(chol, np.int64)[None],
                              prev, self.stack_inputs([inputs]), e[None], keep_particles)
        sigma = dict(zip(self.pairs, (int(v) for v in res.sigma[0]), strict=True))
        taps = {k: v[0] for k, v in res.taps.items()}
        return StepResult(res.mu[0], sigma, res.chol[0], int(res.flags[0]), int(res.ess[0]),
                          taps)

    def to_real_mu(self, mu: np.ndarray) -> np.ndarray:
        """Raw mu (..., n) as reals."""
        mu = np.asarray(mu)
        return np.stack([fmt.to_real(mu[..., i]) for i, fmt in enumerate(self.dp.x)], axis=-1)

    def to_real_sigma(self, sigma: dict | np.ndarray) -> np.ndarray:
        """Raw Sigma (a dict by pair, or (..., P) in the pairs' order) as (..., n, n) reals."""
        if isinstance(sigma, dict):
            sigma = np.array([sigma[pr] for pr in self.pairs], dtype=np.int64)
        sigma = np.asarray(sigma)
        out = np.zeros(sigma.shape[:-1] + (self.dp.n, self.dp.n))
        for q, (i, j) in enumerate(self.pairs):
            out[..., i, j] = out[..., j, i] = sigma[..., q] / 2.0 ** self.dp.cov_frac(i, j)
        return out

    def to_real_ess(self, ess: Any) -> np.ndarray:
        return np.asarray(ess, dtype=float) / 2.0 ** self.dp.ess.frac_bits


def ess_threshold(dp: Datapath, particles: int) -> int:
    """The raw ESS below which a step of N particles counts as degenerate: (N << ESS_FRAC) >>
    ess_shift, what ctrl computes from the run-time N (0: never)."""
    if dp.ess_shift is None:
        return 0
    return (particles << dp.ess.frac_bits) >> dp.ess_shift


class DrawStream:
    """The filter's draws (steps, N, D) a chunk of steps at a time, continuing one GRNG stream."""

    def __init__(self, grng: GrngStream, particles: int, draws: int, lanes: int):
        self.grng, self.particles, self.d, self.lanes = grng, particles, draws, lanes

    def next(self, steps: int) -> np.ndarray:
        raw = self.grng.next(steps * self.particles // self.lanes)     # (beats, lanes * D)
        return raw.reshape(steps, self.particles, self.d)


@dataclass
class FixedRun:
    """Estimates of a whole run as reals, index k = 0..steps (row 0: the initial estimate)."""

    mu: np.ndarray               # (steps+1, n)
    sigma: np.ndarray            # (steps+1, n, n)
    flags: np.ndarray            # (steps+1,) Flag bits per step
    draws: np.ndarray            # raw (steps, N, D) draws used
    ess: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (steps+1,), NaN at k = 0


def step_results(gpf: FixedGPF, scenario, draws: np.ndarray,
                 keep_particles: bool = False) -> Iterator[StepResult]:
    """Each step's result over a whole scenario, from the float model's initial estimate."""
    from gpf.model.float_gpf import FloatGPF

    mu0, sigma0 = FloatGPF(gpf.cfg, gpf.particles).initial(scenario)
    mu, chol = gpf.init(mu0, sigma0)
    sigma = gpf.quantise_sigma(sigma0)
    for k in range(1, scenario.steps + 1):
        res = gpf.step(mu, chol, sigma, gpf.quantise_inputs(scenario.step_inputs(k)),
                       draws[k - 1], keep_particles=keep_particles)
        mu, chol, sigma = res.mu, res.chol, res.sigma
        yield res


def run(gpf: FixedGPF, scenario, draws: np.ndarray | None = None,
        seed: int | None = None) -> FixedRun:
    """Filter a whole scenario (see scenarios.py); draws default to the GRNG model's (seed)."""
    from gpf.model.float_gpf import FloatGPF

    steps, n = scenario.steps, gpf.dp.n
    if draws is None:
        draws = gpf.draws(steps, seed)
    mu0, sigma0 = FloatGPF(gpf.cfg, gpf.particles).initial(scenario)
    out_mu = np.empty((steps + 1, n))
    out_sigma = np.empty((steps + 1, n, n))
    flags = np.zeros(steps + 1, dtype=np.int64)
    ess = np.full(steps + 1, np.nan)
    out_mu[0] = gpf.to_real_mu(gpf.init(mu0, sigma0)[0])
    out_sigma[0] = gpf.to_real_sigma(gpf.quantise_sigma(sigma0))
    for k, res in enumerate(step_results(gpf, scenario, draws), start=1):
        out_mu[k], out_sigma[k], flags[k] = (gpf.to_real_mu(res.mu), gpf.to_real_sigma(res.sigma),
                                             res.flags)
        ess[k] = gpf.to_real_ess(res.ess)
    return FixedRun(out_mu, out_sigma, flags, draws, ess)


__all__ = ["BatchStep", "DrawStream", "Flag", "FixedGPF", "FixedRun", "StepResult", "run",
           "step_results"]

"""The bit-exact fixed-point GPF: the blocks of blocks.py chained as the hardware chains them,
with the normal draws of the GRNG model.

Draws: the filter's GRNG has D x LANES lanes (D draws per particle, see Datapath.draws); the
beat at clock t gives particles t*LANES .. t*LANES+LANES-1 their D draws each, lane p*D + d to
draw d of particle p. The GRNG runs on across steps (N / LANES beats per step, no reseed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gpf.config import Config
from gpf.model import blocks
from gpf.model.blocks import Flag
from gpf.model.formats import Datapath, datapath
from gpf.model.grng import GrngModel


@dataclass
class StepResult:
    mu: np.ndarray                        # raw, state formats
    sigma: dict[tuple[int, int], int]     # raw, fraction dp.cov_frac(i, j)
    chol: np.ndarray                      # raw L, chol formats
    flags: int
    particles: dict[str, np.ndarray] = field(default_factory=dict)  # debug tap (optional)


class FixedGPF:
    def __init__(self, cfg: Config, particles: int | None = None, word: int | None = None,
                 covariance: str | None = None):
        self.cfg = cfg
        self.dp: Datapath = datapath(cfg, word)
        self.particles = particles or cfg.particles
        if self.particles % cfg.lanes:
            raise ValueError(f"particles = {self.particles}: must be a multiple of "
                             f"lanes = {cfg.lanes}")
        self.covariance = covariance or cfg.app_params.get("covariance", "full")
        self.pairs = blocks.cov_pairs(self.dp, self.covariance)

    # ---- draws -----------------------------------------------------------------------------
    def draws(self, steps: int, seed: int | None = None) -> np.ndarray:
        """Raw normal draws (steps, N, D) from the GRNG model, in the hardware's order."""
        d, lanes = self.dp.draws(), self.cfg.lanes
        grng = GrngModel(self.cfg, lanes=d * lanes)
        beats = steps * self.particles // lanes
        raw = grng.normals_raw(beats, seed=seed)                  # (beats, lanes * D)
        return raw.reshape(steps, self.particles, d)

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

    # ---- one step ----------------------------------------------------------------------------
    def propagate(self, x: np.ndarray, e: np.ndarray, inputs: dict,
                  per_particle: bool = False) -> tuple[np.ndarray, np.ndarray | int]:
        if self.dp.app == "bot":
            return blocks.propagate_bot(self.dp, x, e, per_particle)
        return blocks.propagate_uav(self.dp, x, e, inputs["omega"], inputs["accel"],
                                    per_particle)

    def weight(self, x: np.ndarray, inputs: dict,
               per_particle: bool = False) -> tuple[np.ndarray, np.ndarray | int]:
        if self.dp.app == "bot":
            return blocks.weight_bot(self.dp, x, inputs["z"], inputs["observer"], per_particle)
        return blocks.weight_uav(self.dp, x, inputs["v_gps"], per_particle)

    def step(self, mu: np.ndarray, chol: np.ndarray, sigma_prev: dict, inputs: dict,
             e: np.ndarray, keep_particles: bool = False) -> StepResult:
        """One filter step. inputs: raw per-step inputs (see quantise_inputs); e: (N, D) raw.
        keep_particles: the debug tap's particles and each one's SAT flag per block."""
        dp, n = self.dp, self.dp.n
        cond, f1 = blocks.sample_cond(dp, mu, chol, e[:, :n], per_particle=True)
        prop, f2 = self.propagate(cond, e[:, n:], inputs, per_particle=True)
        ref, f3 = self.propagate(mu[None, :], np.zeros((1, e.shape[1] - n), np.int64), inputs)
        ref = ref[0]
        w, f4 = self.weight(prop, inputs, per_particle=True)
        new_mu, sigma, f5 = blocks.moments(dp, prop, w, ref, self.pairs)
        flags = _or(f1) | _or(f2) | f3 | _or(f4) | f5
        if f5 & Flag.ZERO_WEIGHTS:  # every weight underflowed: keep the prediction and spread
            sigma, chol_out = dict(sigma_prev), chol
        else:
            chol_out, f6 = blocks.cholesky(dp, sigma)
            flags |= f6
        taps = {"cond": cond, "cond_sat": f1 != 0, "prop": prop, "prop_sat": f2 != 0,
                "weight": w, "weight_sat": f4 != 0} if keep_particles else {}
        return StepResult(new_mu, sigma, chol_out, int(flags), taps)

    def quantise_inputs(self, raw_inputs: dict) -> dict:
        """Real per-step inputs -> raw: bot z (rad) in turns, observer in the state format;
        uav omega, accel, v_gps in their formats."""
        dp = self.dp
        if dp.app == "bot":
            turns = float(raw_inputs["z"]) / (2 * math.pi)
            z = blocks.wrap_angle(np.int64(math.floor(turns * 2**dp.angle_frac + 0.5)),
                                  dp.angle_frac)
            obs = [int(dp.x[k].from_real(float(v))[0]) for k, v in
                   zip((0, 2), raw_inputs["observer"], strict=True)]
            return {"z": int(z), "observer": tuple(obs)}
        return {
            "omega": np.array([dp.gyro.from_real(float(v))[0] for v in raw_inputs["omega"]]),
            "accel": np.array([dp.accel.from_real(float(v))[0] for v in raw_inputs["accel"]]),
            "v_gps": np.array([dp.x[4 + k].from_real(float(v))[0]
                               for k, v in enumerate(raw_inputs["v_gps"])]),
        }

    def to_real_mu(self, mu: np.ndarray) -> np.ndarray:
        return np.array([float(fmt.to_real(int(v))) for fmt, v in zip(self.dp.x, mu,
                                                                       strict=True)])

    def to_real_sigma(self, sigma: dict) -> np.ndarray:
        out = np.zeros((self.dp.n, self.dp.n))
        for (i, j), v in sigma.items():
            out[i, j] = out[j, i] = v / 2.0 ** self.dp.cov_frac(i, j)
        return out


def _or(flags: np.ndarray) -> int:
    return int(np.bitwise_or.reduce(flags)) if len(flags) else 0


@dataclass
class FixedRun:
    """Estimates of a whole run as reals, index k = 0..steps (row 0: the initial estimate)."""

    mu: np.ndarray               # (steps+1, n)
    sigma: np.ndarray            # (steps+1, n, n)
    flags: np.ndarray            # (steps+1,) Flag bits per step
    draws: np.ndarray            # raw (steps, N, D) draws used


def run(gpf: FixedGPF, scenario, draws: np.ndarray | None = None,
        seed: int | None = None) -> FixedRun:
    """Filter a whole scenario (see scenarios.py); draws default to the GRNG model's (seed)."""
    from gpf.model.float_gpf import FloatGPF

    steps, n = scenario.steps, gpf.dp.n
    if draws is None:
        draws = gpf.draws(steps, seed)
    mu0, sigma0 = FloatGPF(gpf.cfg, gpf.particles).initial(scenario)
    mu, chol = gpf.init(mu0, sigma0)
    sigma = gpf.quantise_sigma(sigma0)
    out_mu = np.empty((steps + 1, n))
    out_sigma = np.empty((steps + 1, n, n))
    flags = np.zeros(steps + 1, dtype=np.int64)
    out_mu[0], out_sigma[0] = gpf.to_real_mu(mu), gpf.to_real_sigma(sigma)
    for k in range(1, steps + 1):
        res = gpf.step(mu, chol, sigma, gpf.quantise_inputs(scenario.step_inputs(k)),
                       draws[k - 1])
        mu, chol, sigma = res.mu, res.chol, res.sigma
        out_mu[k], out_sigma[k], flags[k] = gpf.to_real_mu(mu), gpf.to_real_sigma(sigma), res.flags
    return FixedRun(out_mu, out_sigma, flags, draws)

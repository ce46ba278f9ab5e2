"""float64 Gaussian particle filter: the accuracy yardstick of the fixed-point model.

The block functions (same boundaries as the hardware blocks) live in `float_blocks` and are
re-exported here. A step consumes one array of N(0, 1) draws of shape (N, D), per particle in
this order: bot D = 6: [e_cond(4), e_proc(2)]; uav D = 13: [e_cond(7), e_gyro(3), e_acc(3)].
Feeding the hardware's own draws gives the quantisation error of each step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gpf.model.float_blocks import (
    FLAGS,
    GRAVITY,
    LOW_ESS,
    NOT_PD,
    ZERO_WEIGHTS,
    Array,
    cholesky,
    effective_sample_size,
    exponent_bot,
    exponent_uav,
    moments,
    omega_matrix,
    predicted_covariance,
    propagate_bot,
    propagate_uav,
    relative_weights,
    rotation_matrix,
    sample_cond,
    weight_bot,
    weight_uav,
    wrap_angle,
)
from gpf.model.scenarios import Scenario

__all__ = [
    "FLAGS", "GRAVITY", "LOW_ESS", "NOT_PD", "ZERO_WEIGHTS", "BatchStep", "FloatGPF", "RunResult",
    "StepResult", "attitude_error_deg", "cholesky", "draw_count", "moments", "omega_matrix",
    "position_error", "position_rmse", "propagate_bot", "propagate_uav", "rotation_matrix",
    "sample_cond", "stack_inputs", "state_size", "weight_bot", "weight_uav", "wrap_angle",
]


def state_size(app: str) -> int:
    return {"bot": 4, "uav": 7}[app]


def draw_count(app: str) -> int:
    """D, the N(0, 1) draws per particle and step."""
    return {"bot": 6, "uav": 13}[app]


@dataclass
class StepResult:
    """One filter step. `Sigma` is the moments output; `L` its (regularised) Cholesky factor."""

    mu: Array            # (n,)
    Sigma: Array         # (n, n)
    L: Array             # (n, n) lower triangular
    flags: set[str]      # subset of FLAGS
    ref: Array           # (n,) propagated previous mean, the moments' reference
    x_cond: Array        # (N, n) conditioning particles
    x: Array             # (N, n) propagated particles
    w: Array             # (N,) weights
    W: float             # sum of the weights

    @property
    def ess(self) -> float:
        """Effective sample size (sum w)^2 / sum w^2; 0 when every weight is zero."""
        s2 = float(self.w @ self.w)
        return self.W * self.W / s2 if s2 > 0 else 0.0


@dataclass
class BatchStep:
    """One step of R runs (leading axis R everywhere)."""

    mu: Array                       # (R, n)
    Sigma: Array                    # (R, n, n)
    L: Array                        # (R, n, n)
    flags: dict[str, np.ndarray]    # name -> (R,) bool
    ess: Array                      # (R,)
    ref: Array                      # (R, n)
    x_cond: Array                   # (R, N, n)
    x: Array                        # (R, N, n)
    w: Array                        # (R, N)


def stack_inputs(inputs: list[Mapping[str, Any]]) -> dict[str, Array]:
    """Per-step inputs of R runs (Scenario.step_inputs each) as arrays with a run axis."""
    return {key: np.array([np.asarray(i[key], dtype=float) for i in inputs]) for key in inputs[0]}


@dataclass
class RunResult:
    """Estimates of a whole run, index k = 0..steps (row 0: the initial mu0, Sigma0)."""

    mu: Array                      # (steps+1, n)
    Sigma: Array                   # (steps+1, n, n)
    flags: dict[str, np.ndarray]   # name -> bool (steps+1,)
    ess: Array                     # (steps+1,), NaN at k = 0
    meta: dict[str, Any] = field(default_factory=dict)


class FloatGPF:
    """The float64 GPF for cfg.app with `particles` particles (default cfg.particles)."""

    def __init__(self, cfg: Any, particles: int | None = None) -> None:
        self.cfg = cfg
        self.app: str = cfg.app
        self.particles = int(particles if particles is not None else cfg.particles)
        self.n = state_size(self.app)
        self.draws_per_particle = draw_count(self.app)
        self.covariance: str = cfg.covariance

    def initial(self, scenario: Scenario | None = None) -> tuple[Array, Array]:
        """(mu0, Sigma0): the scenario's initial estimate, else the config's (bot: x0; uav:
        the truth at k = 0), and Sigma0 = diag(sigma0_diag) from the config."""
        p = self.cfg.app_params
        if scenario is not None and scenario.mu0 is not None:
            mu0 = np.array(scenario.mu0, dtype=float)
        elif self.app == "bot":
            mu0 = np.array(p["x0"], dtype=float)
        elif scenario is not None and np.all(np.isfinite(scenario.truth[0])):
            mu0 = np.array(scenario.truth[0], dtype=float)
        else:
            raise ValueError("uav: no initial estimate (scenario.mu0 and truth at k = 0 missing)")
        return mu0, np.diag(np.array(p["sigma0_diag"], dtype=float))

    def step_batch(self, mu: Array, L: Array, inputs: Mapping[str, Array],  # noqa: N803
                   draws: Array, sigma_prev: Array | None = None) -> BatchStep:
        """One filter step of R runs from (mu, L) (R, n), (R, n, n) with their inputs stacked
        (stack_inputs) and draws (R, N, D). sigma_prev (R, n, n): the covariance the step
        samples from (default L L^T); its prediction replaces the weighted covariance of a step
        whose effective sample size is below cfg.ess_min N (flag "low_ess")."""
        n, cfg = self.n, self.cfg
        draws = np.asarray(draws, dtype=float)
        if draws.ndim != 3 or draws.shape[2] != self.draws_per_particle:
            raise ValueError(f"draws: shape {draws.shape}, expected (R, N, "
                             f"{self.draws_per_particle})")
        x_cond = sample_cond(mu, L, draws[..., :n])
        if self.app == "bot":
            x = propagate_bot(x_cond, draws[..., 4:6], cfg)
            ref = propagate_bot(mu, np.zeros(mu.shape[:-1] + (2,)), cfg)
            t = exponent_bot(x, inputs["z"], inputs["observer"], cfg)
        else:
            omega, accel = inputs["omega"], inputs["accel"]
            x = propagate_uav(x_cond, draws[..., 7:10], draws[..., 10:13], omega, accel, cfg)
            zero = np.zeros(mu.shape[:-1] + (1, 3))
            ref = propagate_uav(mu[..., None, :], zero, zero, omega, accel, cfg)[..., 0, :]
            t = exponent_uav(x, inputs["v_gps"], cfg)
        w, out_of_reach = relative_weights(t)
        mu_k, sigma_k = moments(x, w, ref, self.app, self.covariance)
        ess = effective_sample_size(w)
        low = ess < cfg.ess_min * x.shape[-2]      # a fraction of N
        if np.any(low):
            prev = L @ np.swapaxes(L, -1, -2) if sigma_prev is None else sigma_prev
            sigma_k = np.where(low[..., None, None], predicted_covariance(prev, cfg), sigma_k)
        chol_k, not_pd = cholesky(sigma_k)
        return BatchStep(mu_k, sigma_k, chol_k,
                         {ZERO_WEIGHTS: out_of_reach, NOT_PD: not_pd, LOW_ESS: low}, ess, ref,
                         x_cond, x, w)

    def step(self, mu: Array, L: Array, inputs_k: Mapping[str, Any],  # noqa: N803
             draws: Array, sigma_prev: Array | None = None) -> StepResult:
        """One filter step from (mu_{k-1}, L_{k-1}) with the step's inputs and draws (N, D).

        inputs_k: bot {"z": bearing, "observer": (ox, oy)}; uav {"omega": (3,), "accel": (3,),
        "v_gps": (3,)} (Scenario.step_inputs(k) builds it).
        """
        draws = np.asarray(draws, dtype=float)
        if draws.ndim != 2 or draws.shape[1] != self.draws_per_particle:
            raise ValueError(f"draws: shape {draws.shape}, expected (N, {self.draws_per_particle})")
        prev = None if sigma_prev is None else np.asarray(sigma_prev, float)[None]
        res = self.step_batch(np.asarray(mu, float)[None], np.asarray(L, float)[None],
                              stack_inputs([inputs_k]), draws[None], prev)
        flags = {name for name, on in res.flags.items() if on[0]}
        return StepResult(res.mu[0], res.Sigma[0], res.L[0], flags, res.ref[0], res.x_cond[0],
                          res.x[0], res.w[0], float(np.sum(res.w[0])))

    def run(self, scenario: Scenario, draws: Array | None = None,
            rng: np.random.Generator | None = None) -> RunResult:
        """Filter the whole scenario. draws: (steps, N, D), row k-1 feeds step k (N may differ
        from self.particles); else they come from rng (default: numpy's PCG64 seeded with
        cfg.grng.seed), one (N, D) block a step."""
        if scenario.app != self.app:
            raise ValueError(f"scenario is for app {scenario.app!r}, the filter for {self.app!r}")
        steps, n = scenario.steps, self.n
        shape = (self.particles, self.draws_per_particle)
        if draws is not None:
            draws = np.asarray(draws, dtype=float)
            if draws.ndim != 3 or draws.shape[0] != steps or draws.shape[2] != shape[1]:
                raise ValueError(f"draws: shape {draws.shape}, expected (steps = {steps}, N, "
                                 f"D = {shape[1]})")
        elif rng is None:
            rng = np.random.default_rng(self.cfg.grng.seed)
        mu, sigma = self.initial(scenario)
        chol, _ = cholesky(sigma)
        out_mu = np.empty((steps + 1, n))
        out_sigma = np.empty((steps + 1, n, n))
        flags = {name: np.zeros(steps + 1, dtype=bool) for name in FLAGS}
        ess = np.full(steps + 1, np.nan)
        out_mu[0], out_sigma[0] = mu, sigma
        for k in range(1, steps + 1):
            block = draws[k - 1] if draws is not None else rng.standard_normal(shape)
            res = self.step(mu, chol, scenario.step_inputs(k), block, sigma)
            mu, chol, sigma = res.mu, res.L, res.Sigma
            out_mu[k], out_sigma[k], ess[k] = res.mu, res.Sigma, res.ess
            for name in res.flags:
                flags[name][k] = True
        return RunResult(out_mu, out_sigma, flags, ess,
                         meta={"particles": self.particles if draws is None else draws.shape[1],
                               "config": self.cfg.name})


def position_error(est: Array, truth: Array) -> Array:
    """bot: Euclidean (px, py) error in metres of every row of (..., 4) arrays."""
    est, truth = np.asarray(est, dtype=float), np.asarray(truth, dtype=float)
    return np.hypot(est[..., 0] - truth[..., 0], est[..., 2] - truth[..., 2])


def position_rmse(est: Array, truth: Array, axis: int | tuple[int, ...] | None = None) -> Array:
    """bot: root mean square of the (px, py) error in metres over `axis` (None: all rows)."""
    err = position_error(est, truth)
    return np.sqrt(np.mean(err * err, axis=axis))


def attitude_error_deg(q_est: Array, q_true: Array) -> Array:
    """uav: rotation angle in degrees between two attitudes (..., 4) or full states (..., 7);
    insensitive to the sign and norm of either quaternion."""
    a = np.asarray(q_est, dtype=float)[..., :4]
    b = np.asarray(q_true, dtype=float)[..., :4]
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    # error quaternion conj(a) (x) b; atan2 of its vector and scalar parts stays accurate for
    # small angles, where acos(dot) would lose half the digits
    scalar = np.abs(np.sum(a * b, axis=-1))
    vec = a[..., :1] * b[..., 1:] - b[..., :1] * a[..., 1:] - np.cross(a[..., 1:], b[..., 1:])
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(vec, axis=-1), scalar))

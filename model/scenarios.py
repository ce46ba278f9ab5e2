"""Scenarios (inputs, measurements, truth) for the GPF models, and their CSV files.

Index k = 0..steps everywhere: row k of every array belongs to time t_k = k dt; row 0 holds the
initial truth and NaN inputs/measurements; the inputs and measurement of row k >= 1 feed filter
step k (from k-1 to k).

CSV file: optional metadata lines `# key: <JSON>` (app, dt, mu0 = the filter's initial
estimate, meta), then a header row, then one row per k = 0..steps. An empty field is "not
given" (NaN): inputs and measurements in row 0, and truth anywhere (recorded data may have none).

bot columns (2-D bearing-only tracking, seed 003):
    k   -      step index, 0, 1, 2, ...
    t   s      time t_k (uniform steps dt)
    z   rad    bearing measured at t_k, atan2(py - oy, px - ox) + noise, in (-pi, pi]
    ox  m      observer x at t_k
    oy  m      observer y at t_k
    px  m      truth: target x at t_k
    vx  m/s    truth: target x velocity
    py  m      truth: target y
    vy  m/s    truth: target y velocity
uav columns (quaternion attitude and ENU velocity, seed 002; body axes x forward, y left, z up):
    k            -       step index
    t            s       time t_k
    wx, wy, wz   rad/s   gyro: body rate averaged over [t_{k-1}, t_k], plus noise
    ax, ay, az   m/s^2   accelerometer: specific force (body) averaged over the same interval
    vgE,vgN,vgU  m/s     GPS velocity at t_k (east, north, up), plus noise
    q0..q3       -       truth: attitude quaternion at t_k, scalar first, body to ENU
    vE, vN, vU   m/s     truth: velocity at t_k (east, north, up)
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gpf.config import ConfigError
from gpf.model import flight
from gpf.model.float_blocks import Array, bot_matrices, wrap_angle

# per app: CSV columns in order, and which array each group of columns fills
COLUMNS = {
    "bot": ("k", "t", "z", "ox", "oy", "px", "vx", "py", "vy"),
    "uav": ("k", "t", "wx", "wy", "wz", "ax", "ay", "az", "vgE", "vgN", "vgU",
            "q0", "q1", "q2", "q3", "vE", "vN", "vU"),
}
INPUTS = {"bot": {"observer": ("ox", "oy")},
          "uav": {"omega": ("wx", "wy", "wz"), "accel": ("ax", "ay", "az")}}
MEASUREMENTS = {"bot": {"z": ("z",)}, "uav": {"v_gps": ("vgE", "vgN", "vgU")}}
TRUTH = {"bot": ("px", "vx", "py", "vy"), "uav": ("q0", "q1", "q2", "q3", "vE", "vN", "vU")}
# manoeuvring observer: escorts the target's nominal track (x0's velocity) and weaves across
# the initial line of sight (origin to x0's position), one leg each way in turn
OBSERVER_WEAVE = 3.0  # m/s across the line of sight
OBSERVER_LEG = 3.0    # s per leg


@dataclass
class Scenario:
    """Inputs, measurements and truth of one run; every array has steps + 1 rows."""

    app: str                              # "bot" or "uav"
    dt: float                             # s
    t: Array                              # (steps+1,)
    inputs: dict[str, Array]              # bot: observer (.., 2); uav: omega, accel (.., 3)
    measurements: dict[str, Array]        # bot: z (steps+1,); uav: v_gps (.., 3)
    truth: Array                          # (steps+1, n), NaN where unknown
    mu0: Array | None = None              # the filter's initial estimate, if the scenario has one
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def steps(self) -> int:
        return len(self.t) - 1

    def first(self, steps: int, name: str = "the recording") -> Scenario:
        """The scenario's first `steps` steps (rows k = 0..steps): a recording filtered in part.
        More steps than it has: a ValueError naming both (and the file, as `name`)."""
        if not 1 <= steps <= self.steps:
            raise ValueError(f"--steps {steps}: {name} has {self.steps} steps (k = 1.."
                             f"{self.steps}); give --steps 1 to {self.steps}, or leave it out "
                             "to filter them all")
        rows = slice(0, steps + 1)
        return Scenario(self.app, self.dt, self.t[rows].copy(),
                        {k: a[rows].copy() for k, a in self.inputs.items()},
                        {k: a[rows].copy() for k, a in self.measurements.items()},
                        self.truth[rows].copy(), None if self.mu0 is None else self.mu0.copy(),
                        dict(self.meta))

    def step_inputs(self, k: int) -> dict[str, Any]:
        """What filter step k (1..steps) consumes, as FloatGPF.step takes it."""
        out = {name: a[k] for name, a in self.inputs.items()}
        out.update({name: a[k] for name, a in self.measurements.items()})
        return out


def _for_app(cfg: Any, app: str, name: str) -> None:
    """A named scenario builds only for a config of its app: one line, not a KeyError."""
    if cfg.app != app:
        raise ConfigError(f"scenario {name} is for app {app!r}; config {cfg.name!r} is "
                          f"{cfg.app!r}")


def _bot(cfg: Any, steps: int, seed: int, observer: Array, name: str,
         x0: Array | None = None) -> Scenario:
    """Truth x_0 ~ N(x0, diag(sigma0_diag)) (x0 is the seed's initial *mean*, the config's
    unless given), then x_k = Phi x_{k-1} + Gamma w; bearings with noise N(0, R) seen from
    observer[k]."""
    p = cfg.app_params
    x0 = np.array(p["x0"] if x0 is None else x0, dtype=float)
    rng = np.random.default_rng(seed)
    phi, gamma = bot_matrices(cfg.dt)
    truth = np.empty((steps + 1, 4))
    truth[0] = x0 + np.sqrt(np.array(p["sigma0_diag"])) * rng.standard_normal(4)
    w = math.sqrt(p["process_var"]) * rng.standard_normal((steps, 2))
    for k in range(1, steps + 1):
        truth[k] = phi @ truth[k - 1] + gamma @ w[k - 1]
    z = np.full(steps + 1, np.nan)
    noise = math.sqrt(p["bearing_var"]) * rng.standard_normal(steps)
    rel = truth[1:, [0, 2]] - observer[1:]
    z[1:] = wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) + noise)
    return Scenario("bot", cfg.dt, np.arange(steps + 1) * cfg.dt, {"observer": observer},
                    {"z": z}, truth, x0,
                    {"generator": name, "seed": int(seed), "config": cfg.name})


def bot_still_observer(cfg: Any, steps: int, seed: int, name: str,
                       mean: Array | None = None, observer: Array = (0.0, 0.0)) -> Scenario:
    """A target drawn around `mean` (x, vx, y, vy; the config's x0 unless given) seen from an
    observer standing at `observer`: seed 003's scenario, and the edge cases tests build."""
    _for_app(cfg, "bot", name)
    where = np.tile(np.asarray(observer, dtype=float), (steps + 1, 1))
    where[0] = np.nan
    return _bot(cfg, steps, seed, where, name, None if mean is None else np.asarray(mean))


def bot_fixed_observer(cfg: Any, steps: int, seed: int) -> Scenario:
    """Seed 003's scenario: observer at the origin, so the range is unobservable."""
    return bot_still_observer(cfg, steps, seed, "bot_fixed_observer")


def observer_path(t: Array, base: Array, cross: Array, weave: float = OBSERVER_WEAVE,
                  leg: float = OBSERVER_LEG) -> Array:
    """Observer positions (.., 2) at times t: from the origin with velocity base + weave cross,
    then base - weave cross, alternating every `leg` seconds."""
    legs = int(np.ceil(max(float(np.max(t)), 0.0) / leg)) + 1
    signs = np.where(np.arange(legs) % 2 == 0, 1.0, -1.0)
    vel = np.asarray(base) + weave * signs[:, None] * np.asarray(cross)
    knots = np.vstack([np.zeros(2), np.cumsum(leg * vel, axis=0)])
    knots_t = leg * np.arange(legs + 1)
    return np.stack([np.interp(t, knots_t, knots[:, 0]), np.interp(t, knots_t, knots[:, 1])], -1)


def bot_manoeuvring_observer(cfg: Any, steps: int, seed: int) -> Scenario:
    """The same target (same seed: same truth and noise) seen from an observer that moves with
    the nominal target velocity (x0's) and weaves at OBSERVER_WEAVE m/s across the initial line
    of sight in OBSERVER_LEG s legs (2.8-3.2 m/s for seed 003's x0): the observer's
    accelerations make the range observable."""
    _for_app(cfg, "bot", "bot_manoeuvring_observer")
    x0 = np.array(cfg.app_params["x0"], dtype=float)
    los = x0[[0, 2]] / np.hypot(x0[0], x0[2])
    observer = observer_path(np.arange(steps + 1) * cfg.dt, x0[[1, 3]],
                             np.array([los[1], -los[0]]))
    observer[0] = np.nan
    return _bot(cfg, steps, seed, observer, "bot_manoeuvring_observer")


def uav_flight(cfg: Any, steps: int, seed: int) -> Scenario:
    """`flight`'s profile (climb, coordinated turns, level flight at 15-17 m/s) with exact truth,
    IMU noise N(0, sigma_w^2) and N(0, sigma_a^2) per sample, GPS velocity noise N(0, sigma_v^2)
    every step. mu0 is the truth at k = 0 plus a draw from N(0, diag(sigma0_diag)), q normalised.
    """
    _for_app(cfg, "uav", "uav_flight")
    p = cfg.app_params
    rng = np.random.default_rng(seed)
    truth, omega, accel = flight.integrate(steps, cfg.dt)
    mu0 = truth[0] + np.sqrt(np.array(p["sigma0_diag"])) * rng.standard_normal(7)
    mu0[:4] /= np.linalg.norm(mu0[:4])

    def noisy(clean: Array, sigma: float) -> Array:
        out = np.full((steps + 1, 3), np.nan)
        out[1:] = clean + sigma * rng.standard_normal((steps, 3))
        return out

    inputs = {"omega": noisy(omega, math.radians(p["sigma_omega_deg"])),
              "accel": noisy(accel, p["sigma_a"])}
    v_gps = noisy(truth[1:, 4:], p["sigma_v"])
    return Scenario("uav", cfg.dt, np.arange(steps + 1) * cfg.dt, inputs, {"v_gps": v_gps},
                    truth, mu0, {"generator": "uav_flight", "seed": int(seed), "config": cfg.name,
                                 "profile": flight.PHASES})


def _column_arrays(s: Scenario) -> dict[str, Array]:
    cols: dict[str, Array] = {"k": np.arange(s.steps + 1), "t": s.t}
    for group in (INPUTS[s.app], MEASUREMENTS[s.app], {"truth": TRUTH[s.app]}):
        for name, names in group.items():
            a = s.truth if name == "truth" else {**s.inputs, **s.measurements}[name]
            a = a.reshape(len(s.t), -1)
            cols.update({c: a[:, i] for i, c in enumerate(names)})
    return cols


def write_csv(scenario: Scenario, path: str | Path) -> None:
    """Write the metadata lines, the header and one row per k (floats exact: shortest repr)."""
    cols = _column_arrays(scenario)
    names = COLUMNS[scenario.app]
    lines = [f"# app: {json.dumps(scenario.app)}", f"# dt: {json.dumps(float(scenario.dt))}"]
    if scenario.mu0 is not None:
        lines.append(f"# mu0: {json.dumps([float(x) for x in scenario.mu0])}")
    lines += [f"# meta: {json.dumps(scenario.meta)}", ",".join(names)]
    for k in range(scenario.steps + 1):
        fields = [str(k)] + ["" if math.isnan(v := float(cols[c][k])) else repr(v)
                             for c in names[1:]]
        lines.append(",".join(fields))
    Path(path).write_text("\n".join(lines) + "\n")


def read_csv(path: str | Path, cfg: Any = None) -> Scenario:
    """Read a scenario CSV; a malformed file raises a one-line ConfigError (a ValueError) naming
    the file, the row (k, and its line number) and the column. Given the config it is to be
    filtered with, the recording is checked against it too (check_recording)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    header_at = 0
    info: dict[str, Any] = {}
    while header_at < len(lines) and (lines[header_at].startswith("#")
                                      or not lines[header_at].strip()):
        _read_meta(path, header_at + 1, lines[header_at], info)
        header_at += 1
    if header_at == len(lines):
        raise ConfigError(f"{path}: no header row")
    app = _read_header(path, header_at + 1, lines[header_at])
    if info.get("app", app) != app:
        raise ConfigError(f"{path}: metadata app {info['app']!r} but the columns are {app}'s")
    names = COLUMNS[app]
    required = {c for group in (INPUTS[app], MEASUREMENTS[app]) for cs in group.values()
                for c in cs}
    rows: list[list[float]] = []
    line_of: list[int] = []      # the file's line number of each row
    for ln, text in enumerate(lines[header_at + 1:], start=header_at + 2):
        if not text.strip():
            continue
        fields = next(csv.reader([text]))
        r = len(rows)
        line_of.append(ln)
        where = f"{path}: row {r} (line {ln})"
        if len(fields) != len(names):
            raise ConfigError(f"{where}: {len(fields)} fields, expected {len(names)}: "
                              + ",".join(names))
        row = []
        for c, f in zip(names, fields, strict=True):
            f = f.strip()
            if not f and c not in ("k", "t") and (r == 0 or c not in required):
                row.append(math.nan)
                continue
            try:
                v = float(f)
            except ValueError:
                v = math.nan
            if not f:
                raise ConfigError(f"{where}, column '{c}': empty, a number is required here")
            if not math.isfinite(v):
                raise ConfigError(f"{where}, column '{c}': {f!r} is not a finite number")
            if c == "k" and v != r:
                raise ConfigError(f"{where}, column 'k': {f}, expected {r}")
            row.append(v)
        rows.append(row)
    if len(rows) < 2:
        raise ConfigError(f"{path}: {len(rows)} data rows; need k = 0 and at least one step")
    cols = dict(zip(names, np.array(rows).T, strict=True))
    t = cols["t"]
    dt = float(info.get("dt", t[1] - t[0]))
    source = "the metadata" if "dt" in info else "rows 0 and 1"
    if not dt > 0:
        raise ConfigError(f"{path}: row 1 (line {line_of[1]}), column 't': {_num(t[1])} after "
                          f"t_0 = {_num(t[0])}: the step dt = {_num(dt)} (from {source}) "
                          "must be > 0")
    expected = t[0] + np.arange(len(t)) * dt
    bad = np.flatnonzero(np.abs(t - expected) > 1e-9 * np.maximum(1, np.abs(t)))
    if len(bad):
        r = int(bad[0])
        raise ConfigError(f"{path}: row {r} (line {line_of[r]}), column 't': {_num(t[r])}, "
                          f"expected t_0 + k dt = {_num(expected[r])} (uniform steps, dt = "
                          f"{_num(dt)} s from {source})")
    mu0 = info.get("mu0")
    if mu0 is not None and len(mu0) != len(TRUTH[app]):
        raise ConfigError(f"{path}: metadata mu0 has {len(mu0)} numbers, {app} needs "
                          f"{len(TRUTH[app])}")

    def group(cs: tuple[str, ...]) -> Array:
        return cols[cs[0]].copy() if len(cs) == 1 else np.stack([cols[c] for c in cs], axis=1)

    sc = Scenario(app, dt, t, {n: group(cs) for n, cs in INPUTS[app].items()},
                  {n: group(cs) for n, cs in MEASUREMENTS[app].items()}, group(TRUTH[app]),
                  None if mu0 is None else np.array(mu0, dtype=float), info.get("meta", {}))
    if cfg is not None:
        check_recording(sc, cfg, path, cols, line_of, "dt" in info)
    return sc


def _num(x: Any) -> str:
    """A number for a message: the shortest repr of its float, never numpy's
    `np.float64(2.5)`."""
    return repr(float(x))


def check_recording(sc: Scenario, cfg: Any, path: str | Path, cols: dict[str, Array],
                    line_of: list[int], dt_given: bool) -> None:
    """A recording against the config it is filtered with (gpf.limits): its app, its step,
    every input and measurement within the format it is quantised to, every truth quaternion
    and the initial estimate's of unit norm, the initial estimate with bot.x0's headroom.
    One ConfigError line naming the row (k), its line and the column."""
    from gpf.limits import initial_state_problem, input_limits, quaternion_problem

    if sc.app != cfg.app:
        raise ConfigError(f"{path}: a {sc.app} recording (its columns), config {cfg.name!r} is "
                          f"{cfg.app}: give a {cfg.app} scenario")
    if abs(sc.dt - cfg.dt) > 1e-9 * max(1.0, cfg.dt):
        where = "metadata dt" if dt_given else "column 't' (its step)"
        raise ConfigError(f"{path}: {where} = {_num(sc.dt)}, config filter.dt = "
                          f"{_num(cfg.dt)}: the filter propagates with filter.dt; record at that "
                          "step")
    for c, (lo, hi, what) in input_limits(cfg).items():
        values = cols[c]
        bad = np.flatnonzero(~((values >= lo) & (values <= hi)) & ~np.isnan(values))
        if len(bad):
            r = int(bad[0])
            raise ConfigError(f"{path}: row {r} (line {line_of[r]}), column '{c}': "
                              f"{_num(values[r])} is outside [{lo:g}, {hi:g}], {what}")
    if sc.app == "uav":
        for r, q in enumerate(sc.truth[:, :4]):
            if np.all(np.isfinite(q)):
                bad = quaternion_problem(q)
                if bad:
                    raise ConfigError(f"{path}: row {r} (line {line_of[r]}), columns q0..q3: "
                                      f"{bad}")
    columns = None
    if sc.mu0 is not None:
        mu, name = sc.mu0, "metadata mu0"
    elif sc.app == "bot":
        return      # the config's x0, checked with the config
    elif np.all(np.isfinite(sc.truth[0])):
        mu, name = sc.truth[0], f"row 0 (line {line_of[0]}, the initial estimate)"
        columns = TRUTH[sc.app]
    else:
        raise ConfigError(f"{path}: no initial estimate: give metadata mu0 or the whole truth "
                          f"of row 0 (line {line_of[0]})")
    bad = initial_state_problem(cfg, [float(v) for v in mu], name, columns)
    if bad:
        raise ConfigError(f"{path}: {bad}")


def _read_meta(path: Path, ln: int, text: str, info: dict[str, Any]) -> None:
    """`# key: <JSON>` for key in app, dt, mu0, meta; other comment lines are ignored."""
    key, sep, value = text.lstrip("#").partition(":")
    key = key.strip()
    if not sep or key not in ("app", "dt", "mu0", "meta"):
        return
    try:
        val = json.loads(value)
    except json.JSONDecodeError:
        val = None
    ok = {"app": lambda v: v in COLUMNS, "meta": lambda v: isinstance(v, dict),
          "dt": lambda v: isinstance(v, int | float) and math.isfinite(v) and v > 0,
          "mu0": lambda v: isinstance(v, list) and all(
              isinstance(x, int | float) and math.isfinite(x) for x in v)}[key]
    if val is None or isinstance(val, bool) or not ok(val):
        raise ConfigError(f"{path}: line {ln}: metadata {key} = {value.strip()!r} is not valid")
    info[key] = val


def _read_header(path: Path, ln: int, text: str) -> str:
    """The app whose columns the header names; else an error naming the first wrong column."""
    header = [h.strip() for h in next(csv.reader([text]))]
    for app, names in COLUMNS.items():
        if tuple(header) == names:
            return app
    app = "uav" if len(header) > 2 and header[2] == "wx" else "bot"
    names = COLUMNS[app]
    j = next((j for j, (got, want) in enumerate(zip(header, names, strict=False))
              if got != want), min(len(header), len(names)))
    got = repr(header[j]) if j < len(header) else "missing"
    want = repr(names[j]) if j < len(names) else "no more columns"
    raise ConfigError(f"{path}: line {ln} (header), column {j + 1}: {got}, expected {want} "
                      f"({app} columns: {','.join(names)})")


# ---- fault scenarios: situations the filter must flag and survive (README, "Faults") -------
FAULT_STEP = 3   # the step with the fault (or the last step of a shorter run)


def _fault_step(steps: int) -> int:
    return min(FAULT_STEP, steps)


def bot_outlier(cfg: Any, steps: int, seed: int) -> Scenario:
    """bot_fixed_observer with one bearing a quarter turn off at step FAULT_STEP: no particle
    within the exponent's reach (flag ZERO_WEIGHTS: every weight in (1/2, 1], the step a
    prediction); the bearings after it are normal again."""
    sc = bot_fixed_observer(cfg, steps, seed)
    k = _fault_step(steps)
    sc.measurements["z"][k] = wrap_angle(sc.measurements["z"][k] + math.pi / 2)
    sc.meta.update(generator="bot_outlier", fault_step=k)
    return sc


def bot_bearing_glitch(cfg: Any, steps: int, seed: int) -> Scenario:
    """bot_fixed_observer with one bearing 10 sigma off at step FAULT_STEP: within the
    exponent's reach, so a few particles take all the weight (LOW_ESS: the next step samples
    from the predicted covariance, not the collapsed one); normal bearings follow."""
    sc = bot_fixed_observer(cfg, steps, seed)
    k = _fault_step(steps)
    sc.measurements["z"][k] = wrap_angle(sc.measurements["z"][k]
                                         + 10 * math.sqrt(cfg.app_params["bearing_var"]))
    sc.meta.update(generator="bot_bearing_glitch", fault_step=k)
    return sc


def uav_gps_glitch(cfg: Any, steps: int, seed: int) -> Scenario:
    """uav_flight with the GPS velocity 5 m/s off (250 sigma) at step FAULT_STEP: no particle
    within reach (ZERO_WEIGHTS); normal fixes follow."""
    sc = uav_flight(cfg, steps, seed)
    k = _fault_step(steps)
    sc.measurements["v_gps"][k] += np.array([5.0, 0.0, 0.0])
    sc.meta.update(generator="uav_gps_glitch", fault_step=k)
    return sc


def bot_far_target(cfg: Any, steps: int, seed: int) -> Scenario:
    """A target 6 m inside the edge of the position format, moving out at 3 m/s: positions
    saturate (flag SAT) from about step 2 on, and the filter keeps running."""
    _for_app(cfg, "bot", "bot_far_target")
    edge = float(cfg.formats["state"].max_real)
    x0 = np.array(cfg.app_params["x0"], dtype=float)
    x0[0], x0[1] = edge - 6.0, 3.0
    observer = np.zeros((steps + 1, 2))
    observer[0] = np.nan
    return _bot(cfg, steps, seed, observer, "bot_far_target", x0)

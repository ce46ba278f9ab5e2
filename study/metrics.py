"""How far an estimate is from the truth: the figures of merit of both applications.

bot: position error (m). uav: tilt (the roll/pitch part of the attitude error, which GPS
velocity makes observable), heading (the yaw part, observable only in turns), velocity (m/s)
and the whole attitude error (deg). Arrays are (..., n) estimates and truths; errors (...).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from gpf.model.float_gpf import attitude_error_deg, position_error, rotation_matrix

Array = np.ndarray


def _rotation(state: Array) -> Array:
    q = np.asarray(state, dtype=float)[..., :4]
    return rotation_matrix(q / np.linalg.norm(q, axis=-1, keepdims=True))


def euler_deg(state: Array) -> Array:
    """(..., 3) roll, pitch, yaw in degrees of the attitude C = Rz(yaw) Ry(-pitch) Rx(roll)
    (body FLU to ENU, yaw counter-clockwise from East; see model/flight.py)."""
    c = _rotation(state)
    roll = np.arctan2(c[..., 2, 1], c[..., 2, 2])
    pitch = np.arcsin(np.clip(c[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(c[..., 1, 0], c[..., 0, 0])
    return np.degrees(np.stack([roll, pitch, yaw], axis=-1))


def tilt_error_deg(est: Array, truth: Array) -> Array:
    """Angle between the vertical as each attitude sees it in the body frame: the attitude
    error without its rotation about the vertical."""
    up_est = _rotation(est)[..., 2, :]       # C^T e_z: the third row of C
    up_true = _rotation(truth)[..., 2, :]
    cross = np.linalg.norm(np.cross(up_est, up_true), axis=-1)
    return np.degrees(np.arctan2(cross, np.sum(up_est * up_true, axis=-1)))


def heading_error_deg(est: Array, truth: Array) -> Array:
    """|yaw difference|, wrapped into [0, 180] degrees."""
    diff = euler_deg(est)[..., 2] - euler_deg(truth)[..., 2]
    return np.abs((diff + 180.0) % 360.0 - 180.0)


def velocity_error(est: Array, truth: Array) -> Array:
    """|v_est - v_true| in m/s."""
    return np.linalg.norm(np.asarray(est)[..., 4:7] - np.asarray(truth)[..., 4:7], axis=-1)


@dataclass(frozen=True)
class Metric:
    name: str
    unit: str
    error: Callable[[Array, Array], Array]


METRICS = {
    "bot": (Metric("position", "m", position_error),),
    "uav": (Metric("tilt", "deg", tilt_error_deg), Metric("heading", "deg", heading_error_deg),
            Metric("velocity", "m/s", velocity_error),
            Metric("attitude", "deg", attitude_error_deg)),
}
PRIMARY = {"bot": "position", "uav": "tilt"}
# a run has lost track when one of these errors, over its last 20 %, exceeds LOST_FACTOR times
# the float64 filter's on the same draws
TRACKED = {"bot": ("position",), "uav": ("tilt", "velocity")}
LOST_FACTOR = 3.0
LAST_FRACTION = 0.2


def metric(app: str, name: str) -> Metric:
    return next(m for m in METRICS[app] if m.name == name)


def last_window(steps: int) -> slice:
    """Rows k of the last 20 % of a run's steps 1..steps (at least one)."""
    count = max(1, round(steps * LAST_FRACTION))
    return slice(steps - count + 1, steps + 1)


def lost_track(app: str, judged: dict[str, Any], flt: dict[str, Any]) -> Any:
    """Lost track: in a tracked metric, the RMS error over the last 20 % (per metric name; a
    float, or an array over runs) above LOST_FACTOR x the float64 filter's on the same draws."""
    lost = np.zeros(np.shape(flt[TRACKED[app][0]]), dtype=bool)
    for name in TRACKED[app]:
        lost |= np.asarray(judged[name]) > LOST_FACTOR * np.asarray(flt[name])
    return lost


def primary_error(app: str, est: Array, truth: Array) -> Array:
    """The application's primary error per row: bot position (m), uav tilt (deg)."""
    return metric(app, PRIMARY[app]).error(est, truth)


def rms(err: Array) -> float:
    return float(np.sqrt(np.mean(np.asarray(err) ** 2)))


@dataclass(frozen=True)
class RunReport:
    """One run of several filters on the same draws (rows k = 0..steps)."""

    rmse: dict[str, float | None]   # the primary metric over steps 1..steps, per filter
    metrics: dict[str, dict]        # metric -> unit, and per window (all, last20) per filter
    lost: bool | None               # "rtl" (else "fixed") > LOST_FACTOR x "float", last 20 %;
                                    # None without truth (unknown)
    quantisation: list[float]       # primary error of the first filter against "float"


def run_metrics(app: str, truth: Array, est: dict[str, Array]) -> RunReport:
    """Every metric of every filter's estimates of one run; without truth (a recording) only
    the quantisation error, the distance between the first filter and float64."""
    names = list(est)
    steps = len(truth) - 1
    quantisation = primary_error(app, est[names[0]], est["float"])[1:].tolist()
    if not np.all(np.isfinite(np.asarray(truth, float)[1:])):
        return RunReport(dict.fromkeys(names), {}, None, quantisation)
    windows = {"all": slice(1, None), "last20": last_window(steps)}
    table: dict[str, dict] = {}
    for m in METRICS[app]:
        err = {name: m.error(e, truth) for name, e in est.items()}
        table[m.name] = {"unit": m.unit, **{w: {name: rms(e[sl]) for name, e in err.items()}
                                           for w, sl in windows.items()}}
    last = {name: table[name]["last20"] for name in TRACKED[app]}
    lost = bool(lost_track(app, {name: v[names[0]] for name, v in last.items()},
                           {name: v["float"] for name, v in last.items()}))
    return RunReport({name: table[PRIMARY[app]]["all"][name] for name in names}, table, lost,
                     quantisation)

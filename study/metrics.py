"""How far an estimate is from the truth: the figures of merit of both applications.

bot: position error (m). uav: tilt (the roll/pitch part of the attitude error, which GPS
velocity makes observable), heading (the yaw part, observable only in turns), velocity (m/s)
and the whole attitude error (deg). Arrays are (..., n) estimates and truths; errors (...).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

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

"""A smooth synthetic UAV flight and its exact truth, for `scenarios.uav_flight`.

Frames: navigation ENU; body FLU (x forward, y left, z up); q scalar-first, body to navigation;
attitude C = Rz(yaw) Ry(-pitch) Rx(roll), yaw counter-clockwise from East, pitch nose-up,
roll right-wing-down. The aircraft flies with no angle of attack and no sideslip, so its velocity
is V C e_x and the flight-path angle equals the pitch.

The profile (period 60 s, then repeated) is given by smooth (C2, quintic smoothstep) roll,
pitch and airspeed schedules; yaw rate is that of a coordinated turn, -g tan(roll) / V. From
these the body rate omega(t) and the specific force f(t) follow in closed form; the truth is
then the RK4 integral, on sub-steps, of q_dot = 1/2 q (x) [0, omega] and v_dot = C(q) f + g.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

G = 9.8
PERIOD = 60.0
SPEED0 = 15.0                     # m/s
YAW0 = math.radians(60.0)         # initial heading: 60 deg from East (compass 030)
# (start s, duration s, change): each a quintic smoothstep; every schedule returns to its start
ROLL = [(20.0, 2.0, 25.0), (32.0, 2.0, -25.0), (38.0, 2.0, -25.0), (50.0, 2.0, 25.0)]  # deg
PITCH = [(5.0, 2.0, 6.0), (17.0, 2.0, -6.0)]                                          # deg
SPEED = [(34.0, 4.0, 2.0), (54.0, 4.0, -2.0)]                                         # m/s
PHASES = "0-5 s level; 5-19 s climb at 6 deg; 20-34 s right turn, 25 deg bank; 34-38 s level, " \
         "accelerating to 17 m/s; 38-52 s left turn, 25 deg bank; 54-58 s back to 15 m/s"


def _schedule(t: Array, ramps: list[tuple[float, float, float]]) -> tuple[Array, Array, Array]:
    """Value, first and second derivative of a sum of quintic smoothstep ramps."""
    val, d1, d2 = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
    for start, dur, amp in ramps:
        u = np.clip((t - start) / dur, 0.0, 1.0)
        val += amp * u**3 * (10 - 15 * u + 6 * u * u)
        d1 += amp / dur * 30 * u * u * (1 - u) ** 2
        d2 += amp / dur**2 * 60 * u * (1 - u) * (1 - 2 * u)
    return val, d1, d2


def body_signals(t: Array) -> tuple[Array, Array]:
    """True body rate omega (T, 3) in rad/s and specific force f (T, 3) in m/s^2 at times t."""
    tm = np.mod(t, PERIOD)
    roll, roll_d, _ = (np.radians(a) for a in _schedule(tm, ROLL))
    pitch, pitch_d, _ = (np.radians(a) for a in _schedule(tm, PITCH))
    dv, speed_d, _ = _schedule(tm, SPEED)
    speed = SPEED0 + dv
    yaw_d = -G * np.tan(roll) / speed  # coordinated turn: right wing down turns clockwise
    sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
    # omega = roll_d e_x + Rx^T (-pitch_d e_y) + Rx^T Ry(-pitch)^T (yaw_d e_z)
    omega = np.stack([roll_d + yaw_d * sp,
                      -pitch_d * cr + yaw_d * sr * cp,
                      pitch_d * sr + yaw_d * cr * cp], axis=-1)
    # f = C^T (dv/dt - g) with v = V C e_x: V_dot e_x + V omega x e_x + G C^T e_z
    force = np.stack([speed_d + G * sp,
                      speed * omega[:, 2] + G * sr * cp,
                      -speed * omega[:, 1] + G * cr * cp], axis=-1)
    return omega, force


def initial_state() -> Array:
    """Truth at t = 0: level, heading YAW0, speed SPEED0; [q0..q3, vE, vN, vU]."""
    return np.array([math.cos(YAW0 / 2), 0.0, 0.0, math.sin(YAW0 / 2),
                     SPEED0 * math.cos(YAW0), SPEED0 * math.sin(YAW0), 0.0])


def _deriv(s: list[float], w: Array, f: Array) -> list[float]:
    q0, q1, q2, q3 = s[0], s[1], s[2], s[3]
    wx, wy, wz = float(w[0]), float(w[1]), float(w[2])
    fx, fy, fz = float(f[0]), float(f[1]), float(f[2])
    c = [[q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
         [2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)],
         [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3]]
    return [0.5 * (-wx * q1 - wy * q2 - wz * q3), 0.5 * (wx * q0 + wz * q2 - wy * q3),
            0.5 * (wy * q0 - wz * q1 + wx * q3), 0.5 * (wz * q0 + wy * q1 - wx * q2),
            c[0][0] * fx + c[0][1] * fy + c[0][2] * fz,
            c[1][0] * fx + c[1][1] * fy + c[1][2] * fz,
            c[2][0] * fx + c[2][1] * fy + c[2][2] * fz - G]


def integrate(steps: int, dt: float, substeps: int = 4) -> tuple[Array, Array, Array]:
    """As _integrate (computed once per arguments: every run of a Monte Carlo study flies the
    same profile); the arrays are the caller's own copies."""
    return tuple(a.copy() for a in _integrate(steps, dt, substeps))


@functools.lru_cache(maxsize=4)
def _integrate(steps: int, dt: float, substeps: int) -> tuple[Array, Array, Array]:
    """Truth (steps+1, 7) by RK4 on `substeps` sub-steps per dt, and the body rate and specific
    force averaged over each interval [t_{k-1}, t_k] (steps, 3) (Simpson on the RK4 nodes), as
    an integrating IMU reports them (delta-angle / dt, delta-velocity / dt, no coning or
    sculling terms)."""
    h = dt / substeps
    nodes = np.arange(2 * substeps * steps + 1) * (h / 2)  # every RK4 stage time
    omega, force = body_signals(nodes)
    truth = np.empty((steps + 1, 7))
    truth[0] = initial_state()
    s = truth[0].tolist()
    for j in range(substeps * steps):
        a, m, b = 2 * j, 2 * j + 1, 2 * j + 2
        k1 = _deriv(s, omega[a], force[a])
        k2 = _deriv([x + 0.5 * h * d for x, d in zip(s, k1, strict=True)], omega[m], force[m])
        k3 = _deriv([x + 0.5 * h * d for x, d in zip(s, k2, strict=True)], omega[m], force[m])
        k4 = _deriv([x + h * d for x, d in zip(s, k3, strict=True)], omega[b], force[b])
        s = [x + h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
             for x, d1, d2, d3, d4 in zip(s, k1, k2, k3, k4, strict=True)]
        norm = math.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2 + s[3] ** 2)  # truth is a rotation
        s[:4] = [x / norm for x in s[:4]]
        if (j + 1) % substeps == 0:
            truth[(j + 1) // substeps] = s
    weights = np.tile([1.0, 4.0, 1.0], substeps) / (6 * substeps)

    def mean(sig: Array) -> Array:
        idx = (np.arange(steps)[:, None] * 2 * substeps
               + (2 * np.arange(substeps)[:, None] + np.arange(3)).ravel())
        return np.einsum("kj,kjc->kc", np.broadcast_to(weights, idx.shape), sig[idx])

    return truth, mean(omega), mean(force)

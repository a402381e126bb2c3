"""Closed-form motions whose IMU increments and truth are known exactly.

Each function returns a :class:`Motion`: sample times, exact increments
(``dtheta = int w_ib^b dt``, ``dv = int f^b dt`` over (t[i-1], t[i]]) and
the true attitude at every sample. They are the textbook test cases of
[TW11] 11.2 (constant rate, coning), 11.3 (sculling) and the stationary
vehicle on the rotating Earth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mavins.core import earth
from mavins.core.rotation import euler_to_dcm, euler_to_quat, rotvec_to_quat


@dataclass(frozen=True)
class Motion:
    """Exact IMU increments and truth on a sample grid.

    ``t0`` is the initial time; ``t[i]`` ends interval i. ``q`` is the true
    ``q_nb`` at each ``t`` ([w, x, y, z]); ``v`` the true NED velocity (m/s)
    where the motion defines one (else None).
    """

    t0: float
    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    q: np.ndarray
    v: np.ndarray | None = None


def _grid(dt: float, n: int, t0: float = 0.0) -> np.ndarray:
    return t0 + dt * np.arange(1, n + 1, dtype=np.float64)


def stationary(lat_deg: float, h: float, roll_deg: float, pitch_deg: float, yaw_deg: float, dt: float, n: int) -> Motion:
    """Vehicle at rest on the rotating WGS-84 Earth.

    ``w_ib^b = C_n^b w_ie^n`` and ``f^b = -C_n^b [0, 0, gamma_h]`` are constant,
    so ``dtheta = w dt`` and ``dv = f dt`` are exact.
    """
    lat = np.radians(lat_deg)
    c_bn = euler_to_dcm(np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_deg))
    w_b = c_bn.T @ earth.earth_rate_n(lat)
    f_b = c_bn.T @ np.array([0.0, 0.0, -earth.gravity(lat, h)])
    t = _grid(dt, n)
    q0 = euler_to_quat(np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_deg))
    return Motion(0.0, t, np.tile(w_b * dt, (n, 1)), np.tile(f_b * dt, (n, 1)), np.tile(q0, (n, 1)), np.zeros((n, 3)))


def constant_rate(w_b: np.ndarray, dt: float, n: int, f_b: np.ndarray | None = None) -> Motion:
    """Constant body rate (rad/s) in a non-rotating frame, from the identity attitude.

    Truth ``q(t) = exp(w t)``; with a constant body specific force ``f_b`` the
    exact increment is ``f_b dt`` (no gravity is implied).
    """
    w_b = np.asarray(w_b, dtype=np.float64)
    f = np.zeros(3) if f_b is None else np.asarray(f_b, dtype=np.float64)
    t = _grid(dt, n)
    q = np.array([rotvec_to_quat(w_b * ti) for ti in t])
    return Motion(0.0, t, np.tile(w_b * dt, (n, 1)), np.tile(f * dt, (n, 1)), q)


def classic_coning(half_angle_rad: float, freq_hz: float, dt: float, n: int) -> Motion:
    """Pure coning: the body z axis sweeps a cone of half-angle beta at frequency f.

    Attitude ``q(t) = [cos(beta/2), sin(beta/2) cos Wt, sin(beta/2) sin Wt, 0]``
    gives the body rate ``w = [-W sin(beta) sin Wt, W sin(beta) cos Wt,
    -W (1 - cos beta)]`` ([TW11] 11.2.3 coning motion with equal amplitudes
    sin(beta) and 90 deg phase), whose increments integrate in closed form:
    ``dtheta_x = sin(beta) [cos Wt]``, ``dtheta_y = sin(beta) [sin Wt]``,
    ``dtheta_z = -W (1 - cos beta) dt``. Non-rotating frame, no forces.
    """
    w = 2.0 * np.pi * freq_hz
    t = _grid(dt, n)
    tp = np.concatenate(([0.0], t))
    sb = np.sin(half_angle_rad)
    c, s = np.cos(w * tp), np.sin(w * tp)
    dth = np.empty((n, 3))
    dth[:, 0] = sb * np.diff(c)
    dth[:, 1] = sb * np.diff(s)
    dth[:, 2] = -w * (1.0 - np.cos(half_angle_rad)) * np.diff(tp)
    hb = 0.5 * half_angle_rad
    q = np.column_stack([np.full(n, np.cos(hb)), np.sin(hb) * c[1:], np.sin(hb) * s[1:], np.zeros(n)])
    return Motion(0.0, t, dth, np.zeros((n, 3)), q)


def classic_sculling(theta_rad: float, accel: float, freq_hz: float, dt: float, n: int) -> Motion:
    """Sculling: angular oscillation about body x in phase with a body-y specific force.

    ``roll(t) = theta sin Wt`` (so ``w_x = theta W cos Wt``) and
    ``f^b = [0, A sin Wt, 0]`` in a non-rotating frame without gravity.
    Increments: ``dtheta_x = theta [sin Wt]``, ``dv_y = -A/W [cos Wt]``.
    The true velocity has the rectified drift ``dv_D/dt = A J1(theta)`` and no
    mean along N or E ([TW11] 11.3 dynamic term); its value at whole periods is
    returned in ``v`` only at those samples (NaN elsewhere).
    """
    w = 2.0 * np.pi * freq_hz
    t = _grid(dt, n)
    tp = np.concatenate(([0.0], t))
    dth = np.zeros((n, 3))
    dth[:, 0] = theta_rad * np.diff(np.sin(w * tp))
    dv = np.zeros((n, 3))
    dv[:, 1] = -accel / w * np.diff(np.cos(w * tp))
    roll = theta_rad * np.sin(w * t)
    q = np.column_stack([np.cos(0.5 * roll), np.sin(0.5 * roll), np.zeros(n), np.zeros(n)])
    periods = t * freq_hz
    whole = np.abs(periods - np.round(periods)) < 1e-9
    v = np.full((n, 3), np.nan)
    v[whole] = 0.0
    v[whole, 2] = accel * bessel_j1(theta_rad) * t[whole]
    return Motion(0.0, t, dth, dv, q, v)


def bessel_j1(x: float) -> float:
    """Bessel function J1 by its power series (|x| < 1 here, 12 terms reach round-off)."""
    total = 0.0
    term = x / 2.0
    for m in range(12):
        total += term
        term *= -(x * x / 4.0) / ((m + 1) * (m + 2))
    return total


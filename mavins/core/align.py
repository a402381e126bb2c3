"""Static coarse alignment: level from specific force, heading from a chosen source.

Pure functions over window means (FRD body, NED navigation frame). At rest the
accelerometers measure ``f^b = -C_n^b [0, 0, g]`` and the gyros ``w^b = C_n^b
w_ie^n`` ([ZS1] ch. 1 basic navigation equation; its contents' alignment
chapter follows the same analytic coarse alignment).
"""

from __future__ import annotations

import math

import numpy as np

from .rotation import euler_to_dcm


def level(f_mean: np.ndarray) -> tuple[float, float]:
    """Roll and pitch (rad) from the mean specific force at rest.

    With ``f^b = -g [-sin p, sin r cos p, cos r cos p]``:
    ``roll = atan2(-f_y, -f_z)``, ``pitch = atan2(f_x, sqrt(f_y^2 + f_z^2))``.
    """
    fx, fy, fz = float(f_mean[0]), float(f_mean[1]), float(f_mean[2])
    return math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))


def _levelled(v_b: np.ndarray, roll: float, pitch: float) -> np.ndarray:
    """A body vector expressed in the level (heading-only) frame."""
    return euler_to_dcm(roll, pitch, 0.0) @ np.asarray(v_b, dtype=float)


def gyrocompass(w_mean: np.ndarray, roll: float, pitch: float) -> float:
    """Heading (rad) from the horizontal Earth rate seen by levelled gyros.

    In the level frame the gyros read ``Rz(-yaw) [Omega cos L, 0, .]``, so
    ``yaw = atan2(-w_y, w_x)``. Needs gyro bias well below Omega cos L
    (about 0.01 deg/s at mid latitudes): navigation or tactical grade.
    """
    w = _levelled(w_mean, roll, pitch)
    return math.atan2(-w[1], w[0])


def mag_heading(m_mean: np.ndarray, roll: float, pitch: float, declination: float = 0.0) -> float:
    """Heading (rad) from the levelled magnetic field plus declination (rad, east positive)."""
    m = _levelled(m_mean, roll, pitch)
    return math.atan2(-m[1], m[0]) + declination

"""Records passed between the rooms: an IMU sample in, a solution out.

Plain data, no MAVLink or Rerun: ingest builds :class:`ImuSample`, the engine
consumes it and produces :class:`Solution`, which publishing, recording and
files read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ImuSample:
    """One IMU sample: sensor time (s), gyro w_ib^b (rad/s), specific force f^b (m/s^2), FRD.

    ``mag`` is the magnetic field in the body frame (gauss) when the message
    carries one, else None.
    """

    t: float
    gyro: tuple[float, float, float]
    accel: tuple[float, float, float]
    mag: tuple[float, float, float] | None
    sysid: int
    compid: int


@dataclass
class Solution:
    """One output set: the solution row (radians, docs/conventions.md navigation-solution
    columns), the latest bias-corrected body rate (rad/s, FRD), the origin of the local
    frame (deg, deg, m) and whether the solution is degraded."""

    row: np.ndarray
    gyro: np.ndarray
    origin: tuple[float, float, float]
    degraded: bool

"""Records passed between the rooms: an IMU sample in, a solution out.

Plain data, no MAVLink or Rerun: ingest builds :class:`ImuSample`, the engine
consumes it and produces :class:`Solution`, which publishing, recording and
files read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class ImuSample(NamedTuple):
    """One IMU sample: sensor time (s), gyro w_ib^b (rad/s), specific force f^b (m/s^2), FRD.

    ``mag`` is the magnetic field in the body frame (gauss) when the message
    carries one, else None. A named tuple: one is built per sample at kHz rates,
    at a fifth of a frozen dataclass's cost.
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
    unc: "Uncertainty | None" = None


@dataclass
class Uncertainty:
    """What the error-state filter says about a solution (docs/filter.md).

    1-sigma of position (m, NED), velocity (m/s, NED) and attitude error phi
    (rad, NED) from the covariance; the latest test ratios of each
    measurement kind (normalised innovation squared over the gate squared:
    below 1 passes, NaN before the first one); and what is aided.
    """

    sigma_pos: np.ndarray
    sigma_vel: np.ndarray
    sigma_att: np.ndarray
    sigma_gyro: np.ndarray  # rad/s, body: 1-sigma of the gyro bias estimate (the published rates' error)
    vel_ratio: float = float("nan")
    pos_ratio: float = float("nan")
    hgt_ratio: float = float("nan")
    mag_ratio: float = float("nan")
    abs_pos: bool = False  # a GNSS position was accepted within the aiding timeout
    abs_hgt: bool = False  # a GNSS or barometric height was accepted within the timeout
    glitch: bool = False  # the latest GNSS fix was rejected by the gate
    resets: int = 0  # discontinuities of the published solution so far

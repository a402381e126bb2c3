"""Whole-array strapdown runs: arrays and an initial state in, solution rows out.

A thin shell over the compiled kernels of strapdown.py; it converts units at
the edge (degrees in, degrees out, as the contract's files carry them).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from . import strapdown as sd
from .jit import kernel


def initial_state(init: Mapping[str, float]) -> np.ndarray:
    """Kernel state from a contract initial state (degrees, m, m/s)."""
    v = np.array([init["vn"], init["ve"], init["vd"]], dtype=np.float64)
    return sd.init_state(
        float(init["t"]),
        np.radians(init["lat"]),
        np.radians(init["lon"]),
        float(init["h"]),
        v,
        np.radians(init["roll"]),
        np.radians(init["pitch"]),
        np.radians(init["yaw"]),
    )


REST = {"t": 0.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0,
        "pitch": 0.0, "yaw": 0.0}  # a level vehicle at rest: what the kernel warm-ups start from


def rest_state() -> np.ndarray:
    """Kernel state of :data:`REST` (for loading or compiling kernels before real data)."""
    return initial_state(REST)


def to_file_units(rows: np.ndarray, copy: bool = True) -> np.ndarray:
    """Kernel solution rows (radians) to file units (degrees for lat, lon, Euler); ``copy=False``
    converts ``rows`` in place (a buffer of the caller's own)."""
    out = rows.copy() if copy else rows
    degrees_in_place(out, DEGREE_COLUMNS)
    return out


DEGREE_COLUMNS = np.array([1, 2, 7, 8, 9])  # lat, lon, roll, pitch, yaw of a solution row
RAD_TO_DEG = 180.0 / np.pi  # as numpy's degrees()


@kernel
def degrees_in_place(rows: np.ndarray, columns: np.ndarray) -> None:
    """``rows[:, c] *= 180/pi`` for each c in ``columns``, one pass over the rows."""
    for i in range(rows.shape[0]):
        for c in columns:
            rows[i, c] = rows[i, c] * RAD_TO_DEG


def navigate(
    t: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    init: Mapping[str, float],
    *,
    data: str = "increments",
    **options: object,
) -> np.ndarray:
    """Run the strapdown solution over a whole recording.

    ``data`` is ``increments`` (gyro, accel are dtheta rad, dv m/s per row) or
    ``rates`` (rad/s, m/s^2; ``imu_rates`` option says averaged or sampled).
    Other keyword options are those of :func:`strapdown.make_config`.
    Returns solution rows ``t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz``
    in file units, one row per attitude update.
    """
    cfg = sd.make_config(**options)  # type: ignore[arg-type]
    state = initial_state(init)
    t = np.ascontiguousarray(t, dtype=np.float64)
    gyro = np.ascontiguousarray(gyro, dtype=np.float64)
    accel = np.ascontiguousarray(accel, dtype=np.float64)
    n_out = t.shape[0] // int(cfg[sd.CFG_SAMPLES]) + 1
    out = np.empty((n_out, sd.OUT_SIZE))
    if data == "increments":
        m = sd.run_increments(state, cfg, t, gyro, accel, out)
    elif data == "rates":
        m = sd.run_rates(state, cfg, t, gyro, accel, out)
    else:
        raise ValueError(f"data must be increments or rates, got {data!r}")
    return to_file_units(out[:m], copy=False)

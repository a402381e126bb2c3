"""Reference strapdown integration with pyins (PyPI package ``python-ins``).

Runs the pyins 1.0.x strapdown integrator on the same increment input as our
integrator, so both can be compared for accuracy and speed in one run.

pyins conventions (checked against python-ins 1.0.1):

* angles, latitude and longitude in degrees; heading is the yaw angle with
  ``C_b^n = Rz(heading) Ry(pitch) Rx(roll)``, output heading in (-180, 180];
* velocity in NED, body axes forward-right-down;
* ``compute_increments_from_imu(imu, "increment")`` applies the 2-sample
  (one previous increment) coning and sculling corrections and the
  ``0.5 * dtheta x dv`` rotation compensation;
* the Earth ellipsoid is WGS-84, but gravity is Somigliana with only the
  linear height term ``(1 - 2 h / a)``.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

SOLUTION_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")


def _import_pyins() -> tuple[Any, Any]:
    """Return the ``pandas`` and ``pyins.strapdown`` modules, imported lazily."""
    try:
        import pandas as pd
        from pyins import strapdown
    except ImportError as exc:
        raise ImportError(
            "The pyins baseline needs the 'python-ins' package: pip install python-ins"
        ) from exc
    return pd, strapdown


def _initial_pva(pd: Any, init: dict) -> Any:
    """Build a pyins ``Pva`` series from our ``init`` dictionary."""
    values = [init[key] for key in ("lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")]
    columns = ["lat", "lon", "alt", "VN", "VE", "VD", "roll", "pitch", "heading"]
    return pd.Series(np.asarray(values, dtype=float), index=columns, name=float(init["t"]))


def _imu_frame(pd: Any, t0: float, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray) -> Any:
    """Build a pyins increment-type ``Imu`` frame.

    pyins needs one sample before the first increment; the first increment is
    repeated there, which makes the first coning and sculling terms zero.
    """
    index = np.concatenate(([t0], t))
    data = np.hstack((np.vstack((dtheta[:1], dtheta)), np.vstack((dv[:1], dv))))
    columns = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    return pd.DataFrame(data, index=index, columns=columns)


def _integrate(strapdown: Any, imu: Any, pva: Any) -> Any:
    """Apply coning/sculling, then integrate with ``pyins.strapdown.Integrator``."""
    increments = strapdown.compute_increments_from_imu(imu, "increment")
    integrator = strapdown.Integrator(pva, with_altitude=True)
    integrator.integrate(increments)
    return integrator.trajectory


def run_pyins(
    t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, init: dict
) -> tuple[float, np.ndarray]:
    """Integrate IMU increments with pyins.

    Parameters
    ----------
    t : ndarray, shape (n,)
        End time of each increment in seconds; row ``i`` covers
        ``(t[i-1], t[i]]`` with ``t[-1] = init["t"]``.
    dtheta, dv : ndarray, shape (n, 3)
        Angle (rad) and velocity (m/s) increments in the FRD body frame.
    init : dict
        Initial state with keys ``t``, ``lat``, ``lon``, ``h``, ``vn``, ``ve``,
        ``vd``, ``roll``, ``pitch``, ``yaw`` (angles, lat and lon in degrees).

    Returns
    -------
    seconds : float
        ``time.perf_counter`` duration of coning/sculling plus integration,
        after a small warm-up run that excludes numba compilation.
    solution : ndarray, shape (n + 1, 10)
        Columns ``SOLUTION_COLUMNS`` in degrees, metres and m/s; row 0 is the
        initial state at ``init["t"]``.
    """
    pd, strapdown = _import_pyins()
    t = np.asarray(t, dtype=float)
    dtheta = np.asarray(dtheta, dtype=float)
    dv = np.asarray(dv, dtype=float)
    if dtheta.shape != (len(t), 3) or dv.shape != (len(t), 3):
        raise ValueError("dtheta and dv must have shape (len(t), 3)")

    pva = _initial_pva(pd, init)
    t0 = float(init["t"])
    _integrate(strapdown, _imu_frame(pd, t0, t[:2], dtheta[:2], dv[:2]), pva)

    imu = _imu_frame(pd, t0, t, dtheta, dv)
    start = time.perf_counter()
    trajectory = _integrate(strapdown, imu, pva)
    seconds = time.perf_counter() - start

    solution = np.column_stack((trajectory.index.to_numpy(dtype=float), trajectory.to_numpy()))
    return seconds, solution

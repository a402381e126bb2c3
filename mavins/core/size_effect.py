"""Compensation of the size effect: accelerometers at different points of the IMU.

The axis-i accelerometer sits at ``r_i`` (m, body FRD) from the reference point
and senses component i of ``f_0 + dw/dt x r_i + w x (w x r_i)`` (rigid-body
kinematics; Groves, *Principles of GNSS, Inertial, and Multisensor Integrated
Navigation Systems*, 2nd ed., 2013, chapter 2, kinematics). Over sample k the
compensation removes, from the gyros' own increments,

    dv_i -= [ (w(t_k) - w(t_{k-1})) x r_i ]_i + [ w_k x (w_k x r_i) ]_i dt_k

with ``w_k = dtheta_k / dt_k`` the interval's mean rate and the rate at a
sample boundary the mean of the two intervals beside it (the first and last
boundaries take their one interval). It uses the next sample, so it runs on
whole recordings (batch). Residual for a rate vibrating at W rad/s sampled
every h seconds: of relative order (W h)^2 / 12 (the rate's variation inside
an interval that the mean does not see).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def compensate(t0: float, t: ArrayLike, dtheta: ArrayLike, dv: ArrayLike, arms: ArrayLike) -> NDArray[np.float64]:
    """``dv`` (n, 3, m/s) with the size effect of accelerometers at ``arms`` (3x3, row i = r_i, m) removed.

    ``t`` (n,) sample end times (s), ``t0`` the start of the first interval;
    ``dtheta`` (n, 3) angle increments (rad), FRD.
    """
    r = np.asarray(arms, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError(f"arms must be a finite 3x3 array (row i: axis-i accelerometer position, m), got {arms!r}")
    t = np.asarray(t, dtype=np.float64)
    dth = np.asarray(dtheta, dtype=np.float64)
    out = np.array(dv, dtype=np.float64)
    dt = np.diff(np.concatenate(([t0], t)))[:, None]
    w = dth / dt
    wb = np.empty((len(t) + 1, 3))
    wb[1:-1] = 0.5 * (w[:-1] + w[1:])
    wb[0], wb[-1] = w[0], w[-1]
    d_w = wb[1:] - wb[:-1]
    for i in range(3):
        out[:, i] -= np.cross(d_w, r[i])[:, i] + np.cross(w, np.cross(w, r[i]))[:, i] * dt[:, 0]
    return out

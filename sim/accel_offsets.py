"""The size effect: accelerometers at different points of the IMU (the issue's textbook 6.4).

The three accelerometers of a real IMU cannot sit at one point: the one of axis
i is at ``r_i`` (m, body frame FRD) from the reference point whose specific
force the navigation wants (where the simulator's truth is). A point fixed in
a rigid body at r senses (rigid-body kinematics; Groves, *Principles of GNSS,
Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed., 2013,
chapter 2, kinematics: the transport theorem applied twice)

    f_r = f_0 + dw/dt x r + w x (w x r),   w = w_ib^b

and accelerometer i measures only component i of it. Over a sample
interval the added velocity increment of axis i is

    dv_i += [ (w(t_k) - w(t_{k-1})) x r_i ]_i + [ integral of w x (w x r_i) dt ]_i

The first term is exact (the angular acceleration integrates to the change
of rate); the second is taken with 3-point Gauss-Legendre quadrature on the
true instantaneous rates (exact for rates that are polynomials of degree 2
over the interval, error ~(W h)^6 for a vibration at W rad/s).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import kinematics as kin
from .trajectory import SimResult

_GL_U = (0.5 - 0.5 * math.sqrt(0.6), 0.5, 0.5 + 0.5 * math.sqrt(0.6))  # Gauss-Legendre nodes on [0, 1]
_GL_W = (5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0)


def _rates(res: SimResult, times: NDArray[np.float64], rows: NDArray[np.int64]) -> NDArray[np.float64]:
    """True w_ib^b (rad/s) at ``times``, with the latitude and height of truth rows ``rows``."""
    sp = res.spec
    lat = np.radians(res.truth[rows, 1])
    h = res.truth[rows, 3]
    out = np.empty((len(times), 3))
    for k, tk in enumerate(times):
        out[k] = kin.imu_rates(float(tk), float(lat[k]), float(h[k]), sp.starts, sp.durs, sp.coefs, sp.counts,
                               sp.vib, sp.consts, sp.linvib, sp.use_earth)[0]
    return out


def size_effect_dv(res: SimResult, arms: ArrayLike) -> NDArray[np.float64]:
    """Velocity increments (n, 3) (m/s, FRD) that accelerometers at ``arms`` add to ``res.dv``.

    ``arms`` (3, 3): row i is the position r_i (m, body FRD) of the axis-i
    accelerometer from the reference point. Add the result to the ideal
    increments before sim/errors.apply (the sensor errors act on what the
    accelerometer senses).
    """
    r = np.asarray(arms, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError(f"arms must be a finite 3x3 array (row i: axis-i accelerometer position, m), got {arms!r}")
    n = len(res.t)
    tb = np.concatenate(([res.t0], res.t))
    dt = np.diff(tb)
    w_b = _rates(res, tb, np.arange(n + 1))
    d_w = w_b[1:] - w_b[:-1]
    out = np.empty((n, 3))
    mid_rows = np.arange(1, n + 1)
    cent = np.zeros((n, 3))
    for u, wt in zip(_GL_U, _GL_W):
        w = _rates(res, tb[:-1] + u * dt, mid_rows)
        for i in range(3):
            cent[:, i] += wt * np.cross(w, np.cross(w, r[i]))[:, i]
    for i in range(3):
        out[:, i] = np.cross(d_w, r[i])[:, i] + cent[:, i] * dt
    return out

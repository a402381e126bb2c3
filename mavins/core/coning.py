"""Coning, sculling and rotation compensation of IMU increments (pure, compiled).

Two families, chosen by what the sensor delivers:

* **Increments** (or interval-averaged rates, which are increments divided by
  the interval): the N-sample algorithms ``dphi = [sum_{i<N} k_{N-i} dtheta_i]
  x dtheta_N`` with the optimal coefficients of CONVENTIONS.md ``--samples``
  (Lee, Yoon et al. 1990; Ignagni 1996). Sculling uses the same coefficients
  (Ignagni 1998, "duality of optimal sculling and coning algorithms"):
  ``dv_scul = sum_{i<N} k_{N-i} (dtheta_i x dv_N + dv_i x dtheta_N)``.
* **Instantaneous rate samples**: rates linear between samples. For one
  sample interval h with end rates ``w0, w1`` and forces ``f0, f1`` the exact
  second-order terms are ``h^2/12 w0 x w1`` (coning) and
  ``h^2/12 (w0 x f1 + f0 x w1)`` (sculling), accumulated recursively with
  ``1/2 alpha_{j-1} x dtheta_j`` and ``1/2 (alpha_{j-1} x dv_j + v_{j-1} x
  dtheta_j)`` (derivation in docs/algorithms.md, from [TW11] 11.2.2 rotation
  vector ``sigma = alpha + 1/2 int alpha x w dt`` and 11.3 dynamic term
  ``1/2 int (alpha x f - w x v) dt``).
"""

from __future__ import annotations

import numpy as np

from .jit import kernel
from .rotation import cross

#: ``CONING_COEFFS[N, :N-1]`` are the N-sample coefficients, oldest sample first
#: (CONVENTIONS.md ``--samples``). Row 1 (and row 0) are unused.
CONING_COEFFS = np.zeros((7, 5))
CONING_COEFFS[2, :1] = [2.0 / 3.0]
CONING_COEFFS[3, :2] = [9.0 / 20.0, 27.0 / 20.0]
CONING_COEFFS[4, :3] = [54.0 / 105.0, 92.0 / 105.0, 214.0 / 105.0]
CONING_COEFFS[5, :4] = [250.0 / 504.0, 525.0 / 504.0, 650.0 / 504.0, 1375.0 / 504.0]
CONING_COEFFS[6, :5] = [
    2315.0 / 4620.0,
    4558.0 / 4620.0,
    7296.0 / 4620.0,
    7834.0 / 4620.0,
    15797.0 / 4620.0,
]
MAX_SAMPLES = 6


@kernel
def nsample_coning(dtheta: np.ndarray, n: int) -> np.ndarray:
    """N-sample coning correction ``[sum_{i<N} k_{N-i} dtheta_i] x dtheta_N`` (rad).

    ``dtheta`` holds at least ``n`` rows of angle increments, oldest first.
    """
    ax = ay = az = 0.0
    for i in range(n - 1):
        k = CONING_COEFFS[n, i]
        ax += k * dtheta[i, 0]
        ay += k * dtheta[i, 1]
        az += k * dtheta[i, 2]
    bx, by, bz = dtheta[n - 1, 0], dtheta[n - 1, 1], dtheta[n - 1, 2]
    out = np.empty(3)
    out[0] = ay * bz - az * by
    out[1] = az * bx - ax * bz
    out[2] = ax * by - ay * bx
    return out


@kernel
def nsample_sculling(dtheta: np.ndarray, dv: np.ndarray, n: int) -> np.ndarray:
    """N-sample sculling correction ``sum_{i<N} k_{N-i} (dth_i x dv_N + dv_i x dth_N)``."""
    tx = ty = tz = vx = vy = vz = 0.0
    for i in range(n - 1):
        k = CONING_COEFFS[n, i]
        tx += k * dtheta[i, 0]
        ty += k * dtheta[i, 1]
        tz += k * dtheta[i, 2]
        vx += k * dv[i, 0]
        vy += k * dv[i, 1]
        vz += k * dv[i, 2]
    thx, thy, thz = dtheta[n - 1, 0], dtheta[n - 1, 1], dtheta[n - 1, 2]
    dvx, dvy, dvz = dv[n - 1, 0], dv[n - 1, 1], dv[n - 1, 2]
    out = np.empty(3)
    out[0] = (ty * dvz - tz * dvy) + (vy * thz - vz * thy)
    out[1] = (tz * dvx - tx * dvz) + (vz * thx - vx * thz)
    out[2] = (tx * dvy - ty * dvx) + (vx * thy - vy * thx)
    return out


@kernel
def rotation_compensation(phi: np.ndarray, dv: np.ndarray) -> np.ndarray:
    """Savage's closed-form rotation term of the velocity increment (m/s).

    ``(1 - cos p)/p^2 (phi x dv) + (1 - sin(p)/p)/p^2 phi x (phi x dv)``,
    ``p = |phi|`` (CONVENTIONS.md ``--samples``; Savage, Strapdown Analytics
    section 7.2.2.2). Its first term is the ``1/2 alpha x v`` rotation
    correction of [TW11] 11.3.
    """
    p2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    if p2 < 1e-8:
        a = 0.5 - p2 / 24.0 + p2 * p2 / 720.0
        b = 1.0 / 6.0 - p2 / 120.0 + p2 * p2 / 5040.0
    else:
        p = np.sqrt(p2)
        a = (1.0 - np.cos(p)) / p2
        b = (1.0 - np.sin(p) / p) / p2
    px, py, pz = phi[0], phi[1], phi[2]
    c1x = py * dv[2] - pz * dv[1]
    c1y = pz * dv[0] - px * dv[2]
    c1z = px * dv[1] - py * dv[0]
    out = np.empty(3)
    out[0] = a * c1x + b * (py * c1z - pz * c1y)
    out[1] = a * c1y + b * (pz * c1x - px * c1z)
    out[2] = a * c1z + b * (px * c1y - py * c1x)
    return out


@kernel
def rate_coning(w0: np.ndarray, w1: np.ndarray, h: float) -> np.ndarray:
    """Coning inside one interval for linearly varying rate: ``h^2/12 w0 x w1``."""
    return (h * h / 12.0) * cross(w0, w1)


@kernel
def rate_sculling(w0: np.ndarray, f0: np.ndarray, w1: np.ndarray, f1: np.ndarray, h: float) -> np.ndarray:
    """Sculling inside one interval for linear rate and force: ``h^2/12 (w0 x f1 + f0 x w1)``."""
    return (h * h / 12.0) * (cross(w0, f1) + cross(f0, w1))

"""Coning, sculling and rotation compensation of IMU increments (pure, compiled).

Two families, chosen by what the sensor delivers:

* **Increments** (or interval-averaged rates, which are increments divided by
  the interval): the N-sample algorithms ``dphi = [sum_{i<N} k_{N-i} dtheta_i]
  x dtheta_N`` with the optimal coefficients of docs/conventions.md ``--samples``
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

from .jit import inline_kernel, kernel

#: ``CONING_COEFFS[N, :N-1]`` are the N-sample coefficients, oldest sample first
#: (docs/conventions.md ``--samples``). Row 1 (and row 0) are unused.
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


Vec3 = tuple[float, float, float]


@inline_kernel
def nsample_coning(buf: np.ndarray, off: int, n: int) -> Vec3:
    """N-sample coning correction ``[sum_{i<N} k_{N-i} dtheta_i] x dtheta_N`` (rad).

    ``buf[off + 3 i + a]`` is axis a of angle increment i, oldest first.
    """
    ax = ay = az = 0.0
    for i in range(n - 1):
        k = CONING_COEFFS[n, i]
        j = off + 3 * i
        ax += k * buf[j]
        ay += k * buf[j + 1]
        az += k * buf[j + 2]
    j = off + 3 * (n - 1)
    bx, by, bz = buf[j], buf[j + 1], buf[j + 2]
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@inline_kernel
def nsample_sculling(buf: np.ndarray, off_th: int, off_dv: int, n: int) -> Vec3:
    """N-sample sculling correction ``sum_{i<N} k_{N-i} (dth_i x dv_N + dv_i x dth_N)`` (m/s).

    Angle increments at ``buf[off_th + 3 i + a]``, velocity increments at ``buf[off_dv + 3 i + a]``.
    """
    tx = ty = tz = vx = vy = vz = 0.0
    for i in range(n - 1):
        k = CONING_COEFFS[n, i]
        j = off_th + 3 * i
        m = off_dv + 3 * i
        tx += k * buf[j]
        ty += k * buf[j + 1]
        tz += k * buf[j + 2]
        vx += k * buf[m]
        vy += k * buf[m + 1]
        vz += k * buf[m + 2]
    j = off_th + 3 * (n - 1)
    m = off_dv + 3 * (n - 1)
    thx, thy, thz = buf[j], buf[j + 1], buf[j + 2]
    dvx, dvy, dvz = buf[m], buf[m + 1], buf[m + 2]
    return ((ty * dvz - tz * dvy) + (vy * thz - vz * thy),
            (tz * dvx - tx * dvz) + (vz * thx - vx * thz),
            (tx * dvy - ty * dvx) + (vx * thy - vy * thx))


@kernel
def rotation_compensation(px: float, py: float, pz: float, dvx: float, dvy: float, dvz: float) -> Vec3:
    """Savage's closed-form rotation term of the velocity increment (m/s).

    ``(1 - cos p)/p^2 (phi x dv) + (1 - sin(p)/p)/p^2 phi x (phi x dv)``,
    ``p = |phi|`` (docs/conventions.md ``--samples``; Savage, Strapdown Analytics
    section 7.2.2.2). Its first term is the ``1/2 alpha x v`` rotation
    correction of [TW11] 11.3.
    """
    p2 = px * px + py * py + pz * pz
    if p2 < 1e-4:  # series to p^6: the first omitted term is below 1e-21
        a = 0.5 - p2 / 24.0 + p2 * p2 / 720.0 - p2 * p2 * p2 / 40320.0
        b = 1.0 / 6.0 - p2 / 120.0 + p2 * p2 / 5040.0 - p2 * p2 * p2 / 362880.0
    else:
        p = np.sqrt(p2)
        a = (1.0 - np.cos(p)) / p2
        b = (1.0 - np.sin(p) / p) / p2
    c1x = py * dvz - pz * dvy
    c1y = pz * dvx - px * dvz
    c1z = px * dvy - py * dvx
    return (a * c1x + b * (py * c1z - pz * c1y),
            a * c1y + b * (pz * c1x - px * c1z),
            a * c1z + b * (px * c1y - py * c1x))


@kernel
def rate_coning(w0x: float, w0y: float, w0z: float, w1x: float, w1y: float, w1z: float, h: float) -> Vec3:
    """Coning inside one interval for linearly varying rate: ``h^2/12 w0 x w1``."""
    k = h * h / 12.0
    return k * (w0y * w1z - w0z * w1y), k * (w0z * w1x - w0x * w1z), k * (w0x * w1y - w0y * w1x)


@kernel
def rate_sculling(w0x: float, w0y: float, w0z: float, f0x: float, f0y: float, f0z: float,
                  w1x: float, w1y: float, w1z: float, f1x: float, f1y: float, f1z: float, h: float) -> Vec3:
    """Sculling inside one interval for linear rate and force: ``h^2/12 (w0 x f1 + f0 x w1)``."""
    k = h * h / 12.0
    return (k * ((w0y * f1z - w0z * f1y) + (f0y * w1z - f0z * w1y)),
            k * ((w0z * f1x - w0x * f1z) + (f0z * w1x - f0x * w1z)),
            k * ((w0x * f1y - w0y * f1x) + (f0x * w1y - f0y * w1x)))

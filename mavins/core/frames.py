"""Conversions between the contract's frames that more than one room needs."""

from __future__ import annotations

import math

import numpy as np

from . import earth
from .jit import kernel


def local_ned(lat: float, lon: float, h: float, origin: tuple[float, float, float]) -> np.ndarray:
    """NED offset (m) of a point (rad, rad, m) from the origin (deg, deg, m): :func:`local_ned_s`."""
    return np.array(local_ned_s(lat, lon, h, math.radians(origin[0]), math.radians(origin[1]), origin[2]))


@kernel
def local_ned_s(lat: float, lon: float, h: float, lat0: float, lon0: float, h0: float) -> tuple[float, float, float]:
    """NED offset (m) of a point from an origin, both (rad, rad, m), as a 3-tuple.

    The exact ECEF difference rotated into the origin's NED frame:
    ``p^n = C_e^n(origin) (r^e(p) - r^e(origin))`` (WGS-84 geodetic to ECEF,
    NIMA TR8350.2 eq. 4-14; C_n^e as in earth.py).
    """
    x, y, z = earth.lla_to_ecef_s(lat, lon, h)
    x0, y0, z0 = earth.lla_to_ecef_s(lat0, lon0, h0)
    dx, dy, dz = x - x0, y - y0, z - z0
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = earth.cne_from_latlon_s(lat0, lon0)
    return c00 * dx + c10 * dy + c20 * dz, c01 * dx + c11 * dy + c21 * dz, c02 * dx + c12 * dy + c22 * dz


def north_east_error(lat: float, lon: float, lat_ref: float, lon_ref: float) -> tuple[float, float]:
    """North and east offset (m) of (lat, lon) from (lat_ref, lon_ref), all rad, through the
    reference point's radii (small offsets: metres to kilometres)."""
    r_n, r_e = earth.radii(lat_ref)
    return (lat - lat_ref) * r_n, (lon - lon_ref) * r_e * math.cos(lat_ref)


def nav_errors(sol: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Errors (estimate minus truth) of solution rows against truth rows, both in the contract's
    solution columns (file units: degrees); returns (n, 9): position N, E, D (m), velocity N, E, D
    (m/s), attitude phi N, E, D (rad).

    Attitude: the contract's ``C_b^n(true) = (I - [phi x]) C_b^n(est)``, i.e.
    ``q(est) = q(phi) (x) q(true)`` and phi the rotation vector of ``q(est) (x) q(true)^*``.
    Position: ``dp_N = (R_N + h) dL``, ``dp_E = (R_E + h) cos L dlambda``, ``dp_D = -dh`` with the
    radii of the true position (errmodel.py's definitions).
    """
    qe = sol[:, 10:14]
    qt = truth[:, 10:14] * np.array([1.0, -1.0, -1.0, -1.0])
    w = qe[:, 0] * qt[:, 0] - np.sum(qe[:, 1:] * qt[:, 1:], axis=1)
    vec = qe[:, :1] * qt[:, 1:] + qt[:, :1] * qe[:, 1:] + np.cross(qe[:, 1:], qt[:, 1:])
    sign = np.where(w < 0.0, -1.0, 1.0)
    w, vec = w * sign, vec * sign[:, None]
    norm = np.linalg.norm(vec, axis=1)
    scale = np.where(norm > 1e-12, 2.0 * np.arctan2(norm, w) / np.maximum(norm, 1e-300), 2.0 / w)
    lat = np.radians(truth[:, 1])
    h = truth[:, 3]
    r_n, r_e = np.vectorize(earth.radii)(lat)
    dp = np.column_stack([np.radians(sol[:, 1] - truth[:, 1]) * (r_n + h),
                          np.radians(sol[:, 2] - truth[:, 2]) * (r_e + h) * np.cos(lat),
                          -(sol[:, 3] - truth[:, 3])])
    return np.column_stack([dp, sol[:, 4:7] - truth[:, 4:7], vec * scale[:, None]])

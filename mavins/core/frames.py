"""Conversions between the contract's frames that more than one room needs."""

from __future__ import annotations

import math

import numpy as np

from . import earth


def local_ned(lat: float, lon: float, h: float, origin: tuple[float, float, float]) -> np.ndarray:
    """NED offset (m) of a point (rad, rad, m) from the origin (deg, deg, m).

    The exact ECEF difference rotated into the origin's NED frame:
    ``p^n = C_e^n(origin) (r^e(p) - r^e(origin))`` (WGS-84 geodetic to ECEF,
    NIMA TR8350.2 eq. 4-14; C_n^e as in earth.py).
    """
    lat0, lon0, h0 = math.radians(origin[0]), math.radians(origin[1]), origin[2]
    d = earth.lla_to_ecef(lat, lon, h) - earth.lla_to_ecef(lat0, lon0, h0)
    return earth.cne_from_latlon(lat0, lon0).T @ d


def north_east_error(lat: float, lon: float, lat_ref: float, lon_ref: float) -> tuple[float, float]:
    """North and east offset (m) of (lat, lon) from (lat_ref, lon_ref), all rad, through the
    reference point's radii (small offsets: metres to kilometres)."""
    r_n, r_e = earth.radii(lat_ref)
    return (lat - lat_ref) * r_n, (lon - lon_ref) * r_e * math.cos(lat_ref)

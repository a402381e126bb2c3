"""WGS-84 Earth model exactly as CONVENTIONS.md "Earth model" fixes it.

Navigation frame n is local North-East-Down. Position is carried as the DCM
``C_n^e`` (n to Earth-fixed e) plus ellipsoidal height h, so that the
representation itself has no singularity at the poles ([TW11] 11.4, "position
DCM and height": ``dC_n^e/dt = C_n^e [w_en^n x]``, ``dh/dt = -v_D``).
"""

from __future__ import annotations

import numpy as np

from .jit import kernel

A = 6378137.0  # semi-major axis (m)
F = 1.0 / 298.257223563  # flattening
E2 = F * (2.0 - F)  # first eccentricity squared
OMEGA = 7.292115e-5  # Earth rate (rad/s)
GM = 3.986004418e14  # gravitational constant (m^3/s^2)
GAMMA_E = 9.7803253359  # normal gravity at the equator (m/s^2)
K_SOMIGLIANA = 0.00193185265241
M_RATIO = 0.00344978650684  # omega^2 a^2 b / GM


@kernel
def radii(lat: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii ``(R_N, R_E)`` (m) at latitude (rad).

    ``R_N = a(1-e^2)/(1-e^2 sin^2 L)^1.5``, ``R_E = a/(1-e^2 sin^2 L)^0.5``
    (CONVENTIONS.md "Radii"; WGS-84, NIMA TR8350.2).
    """
    s = np.sin(lat)
    d = 1.0 - E2 * s * s
    r_e = A / np.sqrt(d)
    r_n = r_e * (1.0 - E2) / d
    return r_n, r_e


@kernel
def gravity(lat: float, h: float) -> float:
    """Normal gravity ``gamma_h`` (m/s^2, positive down) at latitude and height.

    Somigliana ``gamma = gamma_e (1 + k sin^2 L)/sqrt(1 - e^2 sin^2 L)`` with
    the height term ``gamma_h = gamma [1 - 2/a (1 + f + m - 2 f sin^2 L) h
    + 3 h^2/a^2]`` (CONVENTIONS.md "Gravity"; plumb-bob gravity, centrifugal
    term included, [ZS1] ch. 1 gravity/gravitation relation).
    """
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2 * s2)
    return g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))


@kernel
def earth_rate_n(lat: float) -> np.ndarray:
    """Earth rate in n: ``w_ie^n = [Omega cos L, 0, -Omega sin L]`` (rad/s).

    [TW11] 11.2.4 / 11.4 "navigation algorithm" component form.
    """
    out = np.empty(3)
    out[0] = OMEGA * np.cos(lat)
    out[1] = 0.0
    out[2] = -OMEGA * np.sin(lat)
    return out


@kernel
def transport_rate(lat: float, h: float, v: np.ndarray) -> np.ndarray:
    """Transport rate ``w_en^n = [v_E/(R_E+h), -v_N/(R_N+h), -v_E tan L/(R_E+h)]``.

    [TW11] 11.4 component form with the ellipsoid radii of CONVENTIONS.md.
    The down component is the NED frame's own pole singularity (tan L); the
    position DCM ``C_n^e`` stays regular.
    """
    r_n, r_e = radii(lat)
    out = np.empty(3)
    out[0] = v[1] / (r_e + h)
    out[1] = -v[0] / (r_n + h)
    out[2] = -v[1] * np.tan(lat) / (r_e + h)
    return out


@kernel
def cne_from_latlon(lat: float, lon: float) -> np.ndarray:
    """``C_n^e`` for the NED frame at geodetic latitude/longitude (rad)."""
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    c = np.empty((3, 3))
    c[0, 0] = -sl * co
    c[0, 1] = -so
    c[0, 2] = -cl * co
    c[1, 0] = -sl * so
    c[1, 1] = co
    c[1, 2] = -cl * so
    c[2, 0] = cl
    c[2, 1] = 0.0
    c[2, 2] = -sl
    return c


@kernel
def latlon_from_cne(c: np.ndarray) -> tuple[float, float]:
    """Geodetic latitude and longitude (rad) from ``C_n^e``.

    Latitude from the Earth-z row (``C[2,0] = cos L``, ``C[2,2] = -sin L``),
    longitude from the east column, which stays defined at the poles.
    """
    lat = np.arctan2(-c[2, 2], np.hypot(c[2, 0], c[2, 1]))
    lon = np.arctan2(-c[0, 1], c[1, 1])
    return lat, lon


@kernel
def lla_to_ecef(lat: float, lon: float, h: float) -> np.ndarray:
    """Earth-fixed Cartesian position (m) of a geodetic point (WGS-84, NIMA TR8350.2)."""
    r_n, r_e = radii(lat)
    cl = np.cos(lat)
    out = np.empty(3)
    out[0] = (r_e + h) * cl * np.cos(lon)
    out[1] = (r_e + h) * cl * np.sin(lon)
    out[2] = (r_e * (1.0 - E2) + h) * np.sin(lat)
    return out


@kernel
def ecef_to_lla(p: np.ndarray) -> tuple[float, float, float]:
    """Geodetic latitude, longitude (rad) and height (m) of an ECEF point.

    Fixed-point iteration on latitude; converges to round-off in a few steps
    for any height below a few thousand km.
    """
    lon = np.arctan2(p[1], p[0])
    rho = np.hypot(p[0], p[1])
    lat = np.arctan2(p[2], rho * (1.0 - E2))
    h = 0.0
    for _ in range(8):
        r_n, r_e = radii(lat)
        s = np.sin(lat)
        c = np.cos(lat)
        if abs(c) > 1e-8:
            h = rho / c - r_e
        else:
            h = abs(p[2]) - r_e * (1.0 - E2)
        lat = np.arctan2(p[2], rho * (1.0 - E2 * r_e / (r_e + h)))
    return lat, lon, h


def schuler_period(lat: float, h: float = 0.0) -> float:
    """Schuler period ``2 pi sqrt(R/g)`` (s) with ``R = sqrt(R_N R_E) + h``.

    [ZS1] ch. 1, Schuler tuning (84.4 min).
    """
    r_n, r_e = radii(lat)
    return float(2.0 * np.pi * np.sqrt((np.sqrt(r_n * r_e) + h) / gravity(lat, h)))

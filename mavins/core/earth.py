"""WGS-84 Earth model exactly as docs/conventions.md "Earth model" fixes it.

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
    (docs/conventions.md "Radii"; WGS-84, NIMA TR8350.2).
    """
    return radii_sin(np.sin(lat))


@kernel
def radii_sin(sl: float) -> tuple[float, float]:
    """:func:`radii` from the sine of the latitude."""
    d = 1.0 - E2 * sl * sl
    r_e = A / np.sqrt(d)
    return r_e * (1.0 - E2) / d, r_e


@kernel
def gravity(lat: float, h: float) -> float:
    """Normal gravity ``gamma_h`` (m/s^2, positive down) at latitude and height.

    Somigliana ``gamma = gamma_e (1 + k sin^2 L)/sqrt(1 - e^2 sin^2 L)`` with
    the height term ``gamma_h = gamma [1 - 2/a (1 + f + m - 2 f sin^2 L) h
    + 3 h^2/a^2]`` (docs/conventions.md "Gravity"; plumb-bob gravity, centrifugal
    term included, [ZS1] ch. 1 gravity/gravitation relation).
    """
    sl = np.sin(lat)
    return gravity_sin(sl, radii_sin(sl)[1], h)


@kernel
def gravity_sin(sl: float, r_e: float, h: float) -> float:
    """:func:`gravity` from the sine of the latitude and the prime-vertical radius, using
    ``1/sqrt(1 - e^2 sin^2 L) = R_E / a``."""
    s2 = sl * sl
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) * (r_e / A)
    return g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))


@kernel
def earth_rate_n(lat: float) -> np.ndarray:
    """Earth rate in n: ``w_ie^n = [Omega cos L, 0, -Omega sin L]`` (rad/s).

    [TW11] 11.2.4 / 11.4 "navigation algorithm" component form.
    """
    out = np.empty(3)
    out[0], out[1], out[2] = earth_rate_s(lat)
    return out


@kernel
def earth_rate_s(lat: float) -> tuple[float, float, float]:
    """:func:`earth_rate_n` as a 3-tuple (allocation-free)."""
    return OMEGA * np.cos(lat), 0.0, -OMEGA * np.sin(lat)


@kernel
def nav_terms(lat: float, h: float) -> tuple[float, float, float, float, float, float]:
    """What the navigation equations need at one point, from one sine, one cosine and one
    square root: the transport-rate coefficients ``k_N = 1/(R_N+h)``, ``k_E = 1/(R_E+h)``,
    ``k_T = tan L/(R_E+h)`` (1/m; ``w_en^n = [v_E k_E, -v_N k_N, -v_E k_T]``, see
    :func:`transport_rate`), the Earth rate's north and down components (rad/s, see
    :func:`earth_rate_n`) and gravity (m/s^2, see :func:`gravity`)."""
    sl, cl = np.sin(lat), np.cos(lat)
    r_n, r_e = radii_sin(sl)
    ke = 1.0 / (r_e + h)
    return 1.0 / (r_n + h), ke, sl / cl * ke, OMEGA * cl, -OMEGA * sl, gravity_sin(sl, r_e, h)


@kernel
def transport_rate(lat: float, h: float, v: np.ndarray) -> np.ndarray:
    """Transport rate ``w_en^n = [v_E/(R_E+h), -v_N/(R_N+h), -v_E tan L/(R_E+h)]``.

    [TW11] 11.4 component form with the ellipsoid radii of docs/conventions.md.
    The down component is the NED frame's own pole singularity (tan L); the
    position DCM ``C_n^e`` stays regular.
    """
    out = np.empty(3)
    out[0], out[1], out[2] = transport_rate_s(lat, h, v[0], v[1])
    return out


@kernel
def transport_rate_s(lat: float, h: float, vn: float, ve: float) -> tuple[float, float, float]:
    """:func:`transport_rate` from the north and east velocity (m/s), as a 3-tuple."""
    kn, ke, kt, wn, wd, g = nav_terms(lat, h)
    return transport_rate_k(kn, ke, kt, vn, ve)


@kernel
def transport_rate_k(kn: float, ke: float, kt: float, vn: float, ve: float) -> tuple[float, float, float]:
    """:func:`transport_rate` from :func:`nav_terms`' coefficients ``k_N``, ``k_E``, ``k_T`` (1/m) and the
    north and east velocity (m/s): ``[v_E k_E, -v_N k_N, -v_E k_T]``."""
    return ve * ke, -vn * kn, -ve * kt


@kernel
def cne_from_latlon(lat: float, lon: float) -> np.ndarray:
    """``C_n^e`` for the NED frame at geodetic latitude/longitude (rad)."""
    c = np.empty((3, 3))
    c[0, 0], c[0, 1], c[0, 2], c[1, 0], c[1, 1], c[1, 2], c[2, 0], c[2, 1], c[2, 2] = cne_from_latlon_s(lat, lon)
    return c


@kernel
def cne_from_latlon_s(lat: float, lon: float) -> tuple[float, float, float, float, float, float, float, float,
                                                        float]:
    """:func:`cne_from_latlon` as a row-major 9-tuple."""
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    return -sl * co, -so, -cl * co, -sl * so, co, -cl * so, cl, 0.0, -sl


@kernel
def latlon_from_cne(c: np.ndarray) -> tuple[float, float]:
    """Geodetic latitude and longitude (rad) from ``C_n^e``.

    Latitude from the Earth-z row (``C[2,0] = cos L``, ``C[2,2] = -sin L``),
    longitude from the east column, which stays defined at the poles.
    """
    return latlon_from_cne_s(c[0, 1], c[1, 1], c[2, 0], c[2, 1], c[2, 2])


@kernel
def latlon_from_cne_s(c01: float, c11: float, c20: float, c21: float, c22: float) -> tuple[float, float]:
    """:func:`latlon_from_cne` from the elements it needs."""
    return np.arctan2(-c22, np.hypot(c20, c21)), np.arctan2(-c01, c11)


@kernel
def lla_to_ecef(lat: float, lon: float, h: float) -> np.ndarray:
    """Earth-fixed Cartesian position (m) of a geodetic point (WGS-84, NIMA TR8350.2)."""
    out = np.empty(3)
    out[0], out[1], out[2] = lla_to_ecef_s(lat, lon, h)
    return out


@kernel
def lla_to_ecef_s(lat: float, lon: float, h: float) -> tuple[float, float, float]:
    """:func:`lla_to_ecef` as a 3-tuple: ``x = (R_E + h) cos L cos l``, ``y = (R_E + h) cos L sin l``,
    ``z = (R_E (1 - e^2) + h) sin L`` (NIMA TR8350.2 eq. 4-14)."""
    r_n, r_e = radii(lat)
    cl = np.cos(lat)
    return (r_e + h) * cl * np.cos(lon), (r_e + h) * cl * np.sin(lon), (r_e * (1.0 - E2) + h) * np.sin(lat)


@kernel
def geodetic_from_ecef_s(x: float, y: float, z: float) -> tuple[float, float, float, float]:
    """``(sin L, cos L, h, R_E)`` of an ECEF point (m), regular at the poles.

    ``sin L`` by fixed-point iteration of ``tan L = (z + e^2 R_E sin L)/rho`` (each step shrinks
    the error by about e^2, seven steps reach round-off from the ``h = 0`` start), and
    ``h = rho cos L + z sin L - a sqrt(1 - e^2 sin^2 L)``, which needs no division by cos L
    (the ECEF/geodetic relation of docs/algorithms.md, solved for h). With ``rho =
    (R_E + h) cos L`` the outward normal is ``[x/(R_E + h), y/(R_E + h), sin L]``.
    """
    rho = np.hypot(x, y)
    d = np.hypot(rho, z / (1.0 - E2))
    sl = z / (1.0 - E2) / d if d > 0.0 else 1.0
    for _ in range(7):
        r_e = A / np.sqrt(1.0 - E2 * sl * sl)
        zz = z + E2 * r_e * sl
        d = np.hypot(rho, zz)
        sl = zz / d
    cl = rho / d
    r_e = A / np.sqrt(1.0 - E2 * sl * sl)
    return sl, cl, rho * cl + z * sl - r_e * (1.0 - E2 * sl * sl), r_e


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

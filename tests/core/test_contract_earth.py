"""The WGS-84 Earth model against values typed from its published source.

Nothing expected here is imported from ``mavins.core.earth``: every constant
and closed form is typed in this file from NIMA TR8350.2 (3rd ed., 2000,
"Department of Defense World Geodetic System 1984") and docs/conventions.md
"Earth model", and the functions of the module are *called* and compared.

* Defining parameters (TR8350.2 table 3.1): a = 6378137 m,
  1/f = 298.257223563, GM = 3.986004418e14 m^3/s^2, omega = 7.292115e-5 rad/s.
* Derived constants used as published pins (tables 3.3-3.5): b = 6356752.3142 m,
  e^2 = 6.69437999014e-3, polar radius of curvature c = a^2/b = 6399593.6258 m,
  meridian quadrant 10001965.7293 m, gamma_e = 9.7803253359 m/s^2,
  gamma_p = 9.8321849378 m/s^2, mean normal gravity 9.7976432222 m/s^2,
  k = 0.00193185265241, m = omega^2 a^2 b / GM = 0.00344978650684.
* Closed forms (conventions.md): Somigliana, the height series of TR8350.2
  eq. 4-3, the radii, Earth rate and transport rate in NED, C_n^e and ECEF.

Tolerances: the module and this file evaluate the same closed forms in double
precision in a different order, so they agree to a few ulp of the result:
``REL`` = 1e-14 relative (gravity ~10 m/s^2: 1e-13 m/s^2; radii ~6.4e6 m:
6e-8 m). A published value carries its printed digits: half a unit of the last
printed digit is the tolerance against it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import earth

# --- typed from NIMA TR8350.2 / docs/conventions.md ------------------------------
A = 6378137.0
INV_F = 298.257223563
F = 1.0 / INV_F
E2 = F * (2.0 - F)
GM = 3.986004418e14
OMEGA = 7.292115e-5
GAMMA_E = 9.7803253359
K_SOM = 0.00193185265241
M_RATIO = 0.00344978650684
# published derived values (table 3.3-3.5), printed digits
B_PUB = 6356752.3142  # semi-minor axis, m
E2_PUB = 6.69437999014e-3
C_PUB = 6399593.6258  # polar radius of curvature a^2/b, m
QUADRANT_PUB = 10001965.7293  # meridian quadrant, m
GAMMA_P_PUB = 9.8321849378  # normal gravity at the pole, m/s^2
GAMMA_MEAN_PUB = 9.7976432222  # mean normal gravity over the ellipsoid, m/s^2

REL = 1e-14
# gamma_p from the formula carries the rounding of the published gamma_e and k (gamma_p/gamma_e times
# half a unit of their last digits) on top of its own printed rounding: 5.0e-11 + 5.03e-11 + 5e-14
GAMMA_P_TOL = 0.5e-10 + (GAMMA_P_PUB / GAMMA_E) * 0.5e-10 + GAMMA_P_PUB * 0.5e-14


def half_unit(value_text: str) -> float:
    """Half a unit of the last printed digit of a published number (its rounding)."""
    mant = value_text.lower().split("e")[0]
    exp = int(value_text.lower().split("e")[1]) if "e" in value_text.lower() else 0
    decimals = len(mant.split(".")[1]) if "." in mant else 0
    return 0.5 * 10.0 ** (exp - decimals)


def somigliana(lat: float) -> float:
    s2 = math.sin(lat) ** 2
    return GAMMA_E * (1.0 + K_SOM * s2) / math.sqrt(1.0 - E2 * s2)


def gamma_h(lat: float, h: float) -> float:
    """TR8350.2 eq. 4-3: gamma [1 - 2/a (1 + f + m - 2 f sin^2 L) h + 3 h^2/a^2]."""
    s2 = math.sin(lat) ** 2
    return somigliana(lat) * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))


def r_meridian(lat: float) -> float:
    return A * (1.0 - E2) / (1.0 - E2 * math.sin(lat) ** 2) ** 1.5


def r_prime(lat: float) -> float:
    return A / math.sqrt(1.0 - E2 * math.sin(lat) ** 2)


# --- the typed model itself against the published derived values -----------------
def test_typed_formulas_reproduce_the_published_derived_values() -> None:
    """Pins the closed forms typed above (so that the comparisons below mean something):
    b, e^2, c, the meridian quadrant, gamma_p, the mean normal gravity and m from GM
    are the published ones to their printed digits."""
    b = A * (1.0 - F)
    assert abs(b - B_PUB) <= half_unit("6356752.3142")
    assert abs(E2 - E2_PUB) <= half_unit("6.69437999014e-3")
    assert abs(A * A / b - C_PUB) <= half_unit("6399593.6258")
    assert abs(somigliana(math.pi / 2) - GAMMA_P_PUB) <= GAMMA_P_TOL
    assert abs(OMEGA**2 * A**2 * b / GM - M_RATIO) <= half_unit("0.00344978650684")
    # quadrant and surface mean by Gauss-Legendre quadrature (exact to round-off for these smooth integrands)
    x, w = np.polynomial.legendre.leggauss(200)
    lat, w = (x + 1.0) * math.pi / 4.0, w * math.pi / 4.0  # [0, pi/2]
    s2 = np.sin(lat) ** 2
    rn = A * (1 - E2) / (1 - E2 * s2) ** 1.5
    re = A / np.sqrt(1 - E2 * s2)
    assert abs(float(np.sum(w * rn)) - QUADRANT_PUB) <= half_unit("10001965.7293")
    g = GAMMA_E * (1 + K_SOM * s2) / np.sqrt(1 - E2 * s2)
    ds = rn * re * np.cos(lat)  # surface element per dlat dlon
    # the published mean is rounded to 1e-10 and derived from the closed (not series) ellipsoid potential:
    # allow one more unit of the last digit
    assert abs(float(np.sum(w * g * ds) / np.sum(w * ds)) - GAMMA_MEAN_PUB) <= 1.5e-10


# --- the module ----------------------------------------------------------------------
def test_defining_constants() -> None:
    """The four defining parameters of WGS-84, exactly as TR8350.2 table 3.1 prints them."""
    assert earth.A == 6378137.0
    assert 1.0 / earth.F == pytest.approx(298.257223563, rel=REL)
    assert earth.GM == 3.986004418e14
    assert earth.OMEGA == 7.292115e-5
    assert earth.E2 == pytest.approx(E2_PUB, abs=half_unit("6.69437999014e-3"))


@pytest.mark.parametrize("lat_deg", [-60.0, 0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 89.0, 90.0])
@pytest.mark.parametrize("h", [-400.0, 0.0, 1000.0, 10000.0, 30000.0])
def test_normal_gravity_closed_form(lat_deg: float, h: float) -> None:
    """gravity(L, h) is the typed Somigliana + height series.

    What each point kills: latitudes 15..90 make every Somigliana constant (gamma_e,
    k, e^2) visible, h = 1 km the first-order height term (2/a (1 + f + m - 2 f
    sin^2 L): m alone is 2/a m h = 1.1e-6 relative = 1e-5 m/s^2 at 1 km, 1e8 times
    ``REL``), 10-30 km the 3 h^2/a^2 term (7e-6..7e-5 relative). Tolerance ``REL``.
    """
    lat = math.radians(lat_deg)
    expected = gamma_h(lat, h)
    assert earth.gravity(lat, h) == pytest.approx(expected, rel=REL)


def test_normal_gravity_published_values() -> None:
    """TR8350.2 table 3.5: gamma_e = 9.7803253359, gamma_p = 9.8321849378 m/s^2. gamma_e is a
    defining input of the formula (exact to its printed digits); gamma_p is reached through the
    rounded gamma_e and k, hence ``GAMMA_P_TOL`` (their roundings plus its own)."""
    assert abs(earth.gravity(0.0, 0.0) - 9.7803253359) <= half_unit("9.7803253359")
    assert abs(earth.gravity(math.pi / 2, 0.0) - 9.8321849378) <= GAMMA_P_TOL
    assert abs(earth.gravity(-math.pi / 2, 0.0) - 9.8321849378) <= GAMMA_P_TOL


def test_free_air_gradient_sign_and_size() -> None:
    """d gamma/dh = -2 gamma/a (1 + f + m - 2 f sin^2 L) + 6 gamma h / a^2: at 45 deg, h = 0,
    -3.0862e-6 s^-2 (the free-air gradient). A centred difference over +-10 m has error
    (10 m)^2/6 * d3gamma/dh3 = 0, the series being quadratic in h."""
    lat = math.radians(45.0)
    g0 = somigliana(lat)
    grad = -2.0 * g0 / A * (1.0 + F + M_RATIO - F)
    measured = (earth.gravity(lat, 10.0) - earth.gravity(lat, -10.0)) / 20.0
    # two gravities each within REL (1e-13 m/s^2) differenced over 20 m
    assert measured == pytest.approx(grad, abs=2 * REL * 10 / 20.0)
    assert -3.09e-6 < measured < -3.08e-6


@pytest.mark.parametrize("lat_deg", [0.0, 45.0, 90.0, -30.0])
def test_radii_closed_form(lat_deg: float) -> None:
    """R_N = a(1 - e^2)/(1 - e^2 sin^2 L)^1.5, R_E = a/(1 - e^2 sin^2 L)^0.5 (conventions.md).

    At 0 deg: R_E = a, R_N = b^2/a; at 90 deg both are c = a^2/b (published 6399593.6258 m).
    """
    lat = math.radians(lat_deg)
    r_n, r_e = earth.radii(lat)
    assert r_n == pytest.approx(r_meridian(lat), rel=REL)
    assert r_e == pytest.approx(r_prime(lat), rel=REL)
    if lat_deg == 0.0:
        assert r_e == pytest.approx(A, rel=REL)
        assert r_n == pytest.approx(B_PUB**2 / A, abs=2 * B_PUB / A * half_unit("6356752.3142"))
    if lat_deg == 90.0:
        assert abs(r_n - C_PUB) <= half_unit("6399593.6258")
        assert abs(r_e - C_PUB) <= half_unit("6399593.6258")


@pytest.mark.parametrize("lat_deg", [60.0, -60.0, 0.0, 90.0])
def test_earth_rate_vector_and_signs(lat_deg: float) -> None:
    """w_ie^n = [Omega cos L, 0, -Omega sin L]: north positive, down negative in the north
    (the Earth turns east, its axis points up out of the north pole), positive in the south."""
    lat = math.radians(lat_deg)
    w = np.asarray(earth.earth_rate_n(lat))
    expected = np.array([OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)])
    np.testing.assert_allclose(w, expected, rtol=0, atol=OMEGA * REL)
    if lat_deg == 60.0:
        assert w[0] == pytest.approx(7.292115e-5 * 0.5, rel=1e-15)
        assert w[2] == pytest.approx(-7.292115e-5 * math.sqrt(3.0) / 2.0, rel=1e-15)
        assert w[0] > 0 and w[2] < 0
    if lat_deg == -60.0:
        assert w[2] > 0


def test_transport_rate_components_and_signs() -> None:
    """Lat 60 deg, h = 500 m: v_E = 100 m/s gives [100/(R_E+h), 0, -100 tan 60/(R_E+h)] (the frame
    tilts about north as it moves east; its down component is negative going east in the north);
    v_N = 100 m/s gives [0, -100/(R_N+h), 0] (it tilts back about east going north)."""
    lat, h = math.radians(60.0), 500.0
    re, rn = r_prime(lat) + h, r_meridian(lat) + h
    w_e = np.asarray(earth.transport_rate(lat, h, np.array([0.0, 100.0, 0.0])))
    np.testing.assert_allclose(w_e, [100.0 / re, 0.0, -100.0 * math.tan(lat) / re], rtol=0, atol=1e-5 * REL)
    assert w_e[0] > 0 and w_e[2] < 0
    assert w_e[2] == pytest.approx(-100.0 * math.sqrt(3.0) / re, rel=1e-13)
    w_n = np.asarray(earth.transport_rate(lat, h, np.array([100.0, 0.0, 0.0])))
    np.testing.assert_allclose(w_n, [0.0, -100.0 / rn, 0.0], rtol=0, atol=1e-5 * REL)
    assert w_n[1] < 0
    # a down velocity turns nothing
    np.testing.assert_array_equal(np.asarray(earth.transport_rate(lat, h, np.array([0.0, 0.0, 7.0]))), 0.0)
    # southern hemisphere: the down component changes sign with tan L
    w_s = np.asarray(earth.transport_rate(-lat, h, np.array([0.0, 100.0, 0.0])))
    assert w_s[2] == pytest.approx(+100.0 * math.sqrt(3.0) / re, rel=1e-13)


def cne_typed(lat: float, lon: float) -> np.ndarray:
    """Columns: north, east and down unit vectors of the local NED frame in ECEF."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    north = [-sl * co, -sl * so, cl]
    east = [-so, co, 0.0]
    down = [-cl * co, -cl * so, -sl]
    return np.array([north, east, down]).T


@pytest.mark.parametrize("lat_deg,lon_deg", [(30.0, 45.0), (-50.0, -120.0), (0.0, 0.0), (89.0, 170.0)])
def test_cne_columns_are_north_east_down(lat_deg: float, lon_deg: float) -> None:
    """C_n^e maps NED into ECEF: its columns are the typed north, east and down vectors. A
    transposed matrix fails at every point listed (at (0, 0) C_n^e = [[0, 0, -1], [0, 1, 0],
    [1, 0, 0]] is not symmetric either); 1e-15 is a few ulp of unit components."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    c = np.asarray(earth.cne_from_latlon(lat, lon))
    np.testing.assert_allclose(c, cne_typed(lat, lon), rtol=0, atol=1e-15)
    lat2, lon2 = earth.latlon_from_cne(c)
    assert lat2 == pytest.approx(lat, abs=1e-15)
    assert lon2 == pytest.approx(lon, abs=1e-15)


def ecef_typed(lat: float, lon: float, h: float) -> np.ndarray:
    """TR8350.2 eq. 4-14: X = (R_E + h) cos L cos l, Y = (R_E + h) cos L sin l, Z = (R_E (1 - e^2) + h) sin L."""
    n = r_prime(lat)
    return np.array([(n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
                     (n * (1.0 - E2) + h) * math.sin(lat)])


@pytest.mark.parametrize("lat_deg,lon_deg,h", [(0.0, 0.0, 0.0), (90.0, 0.0, 0.0), (45.0, 45.0, 1000.0),
                                               (-33.9, 151.2, 58.0), (47.397742, 8.545594, 488.0)])
def test_ecef_closed_form_and_inverse(lat_deg: float, lon_deg: float, h: float) -> None:
    """lla_to_ecef is the typed closed form (1e-14 relative of ~6.4e6 m: 1e-7 m); ecef_to_lla
    inverts it: latitude to 1e-12 rad (6 um), height to 1e-6 m. Pins: (0, 0, 0) -> (a, 0, 0) and
    the pole -> (0, 0, b)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    p = np.asarray(earth.lla_to_ecef(lat, lon, h))
    np.testing.assert_allclose(p, ecef_typed(lat, lon, h), rtol=0, atol=A * REL * 2)
    if (lat_deg, h) == (0.0, 0.0):
        np.testing.assert_allclose(p, [A, 0.0, 0.0], rtol=0, atol=1e-8)
    if lat_deg == 90.0:
        assert abs(p[2] - B_PUB) <= half_unit("6356752.3142") + 1e-7
        assert abs(p[0]) < 1e-8 and abs(p[1]) < 1e-8
    lat2, lon2, h2 = earth.ecef_to_lla(ecef_typed(lat, lon, h))
    assert lat2 == pytest.approx(lat, abs=1e-12)
    assert h2 == pytest.approx(h, abs=1e-6)
    if abs(lat_deg) < 90.0:
        assert lon2 == pytest.approx(lon, abs=1e-12)

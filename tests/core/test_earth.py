"""WGS-84 model against independently known values and identities.

Also the rest of mavins/core/earth.py (docs/testing.md), beside
tests/core/test_contract_earth.py, which pins the defining constants, gravity, the radii,
the Earth and transport rates, C_n^e and the ECEF conversions.

Here: what the navigation kernel calls besides those (``nav_terms``, the ``*_s``
forms, ``geodetic_from_ecef_s``), the polar branch of ``ecef_to_lla``, the Schuler
period and the derived module constants. Every expected value is typed from NIMA
TR8350.2 (3rd ed., 2000) and docs/conventions.md "Earth model", never taken from
the module: a = 6378137 m, f = 1/298.257223563, e^2 = f (2 - f), Omega =
7.292115e-5 rad/s, gamma_e = 9.7803253359 m/s^2, k = 0.00193185265241, m =
0.00344978650684; Somigliana and its height series as in conventions.md.

In-process and fast; under ``./dev mutate`` the kernels run as plain Python.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mavins.core import earth
from support import A, E2, F, GAMMA_E, K_SOM, M_RATIO, OMEGA


def test_normal_gravity_reference_values():
    # WGS-84 (NIMA TR8350.2): gamma_e = 9.7803253359, gamma_p = 9.8321849378 m/s^2
    assert earth.gravity(0.0, 0.0) == 9.7803253359
    assert abs(earth.gravity(np.pi / 2, 0.0) - 9.8321849378) < 1e-9


def test_gravity_height_term_free_air_gradient():
    # d gamma / dh ~ -3.086e-6 s^-2 near the surface at mid latitude
    g0 = earth.gravity(np.radians(45), 0.0)
    g1 = earth.gravity(np.radians(45), 100.0)
    assert abs((g1 - g0) / 100.0 + 3.086e-6) < 0.01e-6


def test_radii_equator_pole():
    r_n, r_e = earth.radii(0.0)
    assert r_e == earth.A
    assert abs(r_n - earth.A * (1 - earth.E2)) < 1e-6
    r_n, r_e = earth.radii(np.pi / 2)
    assert abs(r_n - r_e) < 1e-6  # both equal a^2/b at the pole


@given(st.floats(-np.pi / 2, np.pi / 2), st.floats(-np.pi + 1e-9, np.pi), st.floats(-500.0, 20000.0))
def test_ecef_round_trip(lat, lon, h):
    p = earth.lla_to_ecef(lat, lon, h)
    lat2, lon2, h2 = earth.ecef_to_lla(p)
    assert abs(lat2 - lat) < 1e-12
    assert abs(h2 - h) < 1e-6
    if abs(np.cos(lat)) > 1e-9:
        assert abs(np.angle(np.exp(1j * (lon2 - lon)))) < 1e-11


@given(st.floats(-np.pi / 2, np.pi / 2), st.floats(-np.pi + 1e-9, np.pi))
def test_cne_orthonormal_and_invertible(lat, lon):
    c = earth.cne_from_latlon(lat, lon)
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-15)
    lat2, lon2 = earth.latlon_from_cne(c)
    assert abs(lat2 - lat) < 1e-14
    # the down axis points to the ellipsoid normal's opposite (towards the inside)
    up = -c[:, 2]
    assert abs(up[2] - np.sin(lat)) < 1e-15


def test_cne_regular_at_the_pole():
    c = earth.cne_from_latlon(np.pi / 2, 0.7)
    lat, lon = earth.latlon_from_cne(c)
    assert lat == np.pi / 2 and abs(lon - 0.7) < 1e-15


def test_earth_rate_and_transport_rate():
    lat = np.radians(30)
    np.testing.assert_allclose(earth.earth_rate_n(lat), [earth.OMEGA * np.cos(lat), 0, -earth.OMEGA * np.sin(lat)])
    v = np.array([10.0, 20.0, 1.0])
    r_n, r_e = earth.radii(lat)
    w = earth.transport_rate(lat, 100.0, v)
    np.testing.assert_allclose(w, [20 / (r_e + 100), -10 / (r_n + 100), -20 * np.tan(lat) / (r_e + 100)])


def test_schuler_period_84_minutes():
    assert abs(earth.schuler_period(np.radians(45)) / 60 - 84.4) < 0.1


GM = 3.986004418e14  # the other WGS-84 constants: tests/support.py (typed, never imported from mavins)
REL = 1e-14

# latitudes that make every term visible (sin^2 L from 0 to 1, both hemispheres) and heights
# from below the geoid to the stratosphere (the h^2 term is 7e-5 relative at 30 km)
POINTS = [(lat, h) for lat in (0.0, 12.5, -33.9, 45.0, 47.397742, 60.0, -75.0, 89.0)
          for h in (-400.0, 0.0, 488.0, 10000.0, 30000.0)]


def r_n(lat: float) -> float:
    return A * (1.0 - E2) / (1.0 - E2 * math.sin(lat) ** 2) ** 1.5


def r_e(lat: float) -> float:
    return A / math.sqrt(1.0 - E2 * math.sin(lat) ** 2)


def gamma_h(lat: float, h: float) -> float:
    s2 = math.sin(lat) ** 2
    g = GAMMA_E * (1.0 + K_SOM * s2) / math.sqrt(1.0 - E2 * s2)
    return g * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))


def test_derived_module_constants():
    """e^2 = f (2 - f) = 6.69437999014e-3 (TR8350.2 table 3.3), and the gravity constants
    exactly as printed (table 3.4/3.5)."""
    assert earth.E2 == pytest.approx(E2, rel=REL, abs=0)
    assert earth.F == pytest.approx(F, rel=REL, abs=0)
    assert earth.GAMMA_E == 9.7803253359
    assert earth.K_SOMIGLIANA == 0.00193185265241
    assert earth.M_RATIO == 0.00344978650684


@pytest.mark.parametrize("lat_deg, h", POINTS)
def test_nav_terms_are_the_closed_forms(lat_deg, h):
    """``(1/(R_N+h), 1/(R_E+h), tan L/(R_E+h), Omega cos L, -Omega sin L, gamma_h)``."""
    lat = math.radians(lat_deg)
    kn, ke, kt, wn, wd, g = earth.nav_terms(lat, h)
    assert kn == pytest.approx(1.0 / (r_n(lat) + h), rel=REL)
    assert ke == pytest.approx(1.0 / (r_e(lat) + h), rel=REL)
    assert kt == pytest.approx(math.tan(lat) / (r_e(lat) + h), rel=REL, abs=1e-30)
    assert wn == pytest.approx(OMEGA * math.cos(lat), rel=REL, abs=0)
    assert wd == pytest.approx(-OMEGA * math.sin(lat), rel=REL, abs=1e-30)
    assert g == pytest.approx(gamma_h(lat, h), rel=REL, abs=0)


@pytest.mark.parametrize("lat_deg, h", POINTS)
def test_sine_forms_agree_with_the_closed_forms(lat_deg, h):
    lat = math.radians(lat_deg)
    sl = math.sin(lat)
    rn, re = earth.radii_sin(sl)
    assert rn == pytest.approx(r_n(lat), rel=REL, abs=0)
    assert re == pytest.approx(r_e(lat), rel=REL, abs=0)
    assert earth.gravity_sin(sl, r_e(lat), h) == pytest.approx(gamma_h(lat, h), rel=REL, abs=0)
    w = earth.earth_rate_s(lat)
    np.testing.assert_allclose(w, [OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)], rtol=0, atol=OMEGA * REL)
    assert w[1] == 0.0


@pytest.mark.parametrize("lat_deg, h", [(45.0, 488.0), (-33.9, 10000.0), (75.0, 0.0)])
def test_transport_rate_s(lat_deg, h):
    """``[v_E/(R_E+h), -v_N/(R_N+h), -v_E tan L/(R_E+h)]`` with both velocity components set."""
    lat = math.radians(lat_deg)
    vn, ve = 37.0, -81.0
    w = earth.transport_rate_s(lat, h, vn, ve)
    re, rn = r_e(lat) + h, r_n(lat) + h
    np.testing.assert_allclose(w, [ve / re, -vn / rn, -ve * math.tan(lat) / re], rtol=1e-13, atol=0)


def ecef(lat, lon, h):
    n = r_e(lat)
    return ((n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
            (n * (1.0 - E2) + h) * math.sin(lat))


@pytest.mark.parametrize("lat_deg, lon_deg, h", [(0.0, 0.0, 0.0), (45.0, 10.0, 488.0), (-33.9, 151.2, 58.0),
                                                 (89.9, -120.0, 1000.0), (90.0, 0.0, 300.0),
                                                 (-90.0, 0.0, -200.0), (60.0, 30.0, 400e3),
                                                 (-5.0, 170.0, -50.0)])
def test_geodetic_from_ecef_s(lat_deg, lon_deg, h):
    """``(sin L, cos L, h, R_E)`` of a point built by the typed TR8350.2 eq. 4-14."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl, h2, re = earth.geodetic_from_ecef_s(*ecef(lat, lon, h))
    assert sl == pytest.approx(math.sin(lat), abs=1e-15)
    assert cl == pytest.approx(math.cos(lat), abs=1e-15)
    assert h2 == pytest.approx(h, abs=1e-8)
    assert re == pytest.approx(r_e(lat), rel=REL, abs=0)


def test_geodetic_from_ecef_s_at_the_centre():
    """The centre of the Earth (no direction at all) counts as the north pole: sin L = 1, and h =
    -b, the distance down to the pole (b = a sqrt(1 - e^2) = 6356752.3142 m, TR8350.2 table 3.3)."""
    sl, cl, h, re = earth.geodetic_from_ecef_s(0.0, 0.0, 0.0)
    assert sl == 1.0 and cl == 0.0
    assert h == pytest.approx(-A * math.sqrt(1.0 - E2), abs=1e-6)
    assert re == pytest.approx(A / math.sqrt(1.0 - E2), rel=REL, abs=0)


@pytest.mark.parametrize("lat_deg, h", [(90.0, 300.0), (-90.0, 1500.0), (90.0, -100.0)])
def test_ecef_to_lla_on_the_axis(lat_deg, h):
    """On the axis ``cos L`` vanishes and the height is ``|z| - R_E (1 - e^2)`` (the polar branch)."""
    z = (A / math.sqrt(1.0 - E2) * (1.0 - E2) + h) * math.copysign(1.0, lat_deg)
    lat, lon, h2 = earth.ecef_to_lla(np.array([0.0, 0.0, z]))
    assert lat == pytest.approx(math.radians(lat_deg), abs=1e-15)
    assert h2 == pytest.approx(h, abs=1e-8)


@pytest.mark.parametrize("lat_deg, lon_deg, h", [(45.0, 10.0, 488.0), (-33.9, 151.2, 58.0), (60.0, -30.0, 400e3),
                                                 (89.99, 5.0, 100.0)])
def test_ecef_to_lla(lat_deg, lon_deg, h):
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    lat2, lon2, h2 = earth.ecef_to_lla(np.array(ecef(lat, lon, h)))
    assert lat2 == pytest.approx(lat, abs=1e-13)
    assert lon2 == pytest.approx(lon, abs=1e-13)
    assert h2 == pytest.approx(h, abs=1e-7)


def test_lla_to_ecef_all_components():
    lat, lon, h = math.radians(-33.9), math.radians(151.2), 58.0
    np.testing.assert_allclose(earth.lla_to_ecef(lat, lon, h), ecef(lat, lon, h), rtol=0, atol=1e-7)


@pytest.mark.parametrize("lat_deg, h", [(0.0, 0.0), (45.0, 0.0), (45.0, 10000.0), (-70.0, 2000.0)])
def test_schuler_period(lat_deg, h):
    """``2 pi sqrt((sqrt(R_N R_E) + h)/gamma_h)`` ([ZS1] ch. 1): 84.4 min at the surface."""
    lat = math.radians(lat_deg)
    expected = 2.0 * math.pi * math.sqrt((math.sqrt(r_n(lat) * r_e(lat)) + h) / gamma_h(lat, h))
    assert earth.schuler_period(lat, h) == pytest.approx(expected, rel=REL, abs=0)
    assert 84.0 * 60 < earth.schuler_period(lat, h) < 84.7 * 60


def test_schuler_period_height_defaults_to_zero():
    lat = math.radians(45.0)
    expected = 2.0 * math.pi * math.sqrt(math.sqrt(r_n(lat) * r_e(lat)) / gamma_h(lat, 0.0))
    assert earth.schuler_period(lat) == pytest.approx(expected, rel=REL, abs=0)


def test_latlon_from_cne_s():
    """``L = atan2(-C22, hypot(C20, C21))``, ``l = atan2(-C01, C11)`` of the typed NED columns."""
    lat, lon = math.radians(-41.0), math.radians(-100.0)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    c01, c11, c20, c21, c22 = -so, co, cl, 0.0, -sl
    lat2, lon2 = earth.latlon_from_cne_s(c01, c11, c20, c21, c22)
    assert lat2 == pytest.approx(lat, abs=1e-15)
    assert lon2 == pytest.approx(lon, abs=1e-15)
    # a tilted Earth-z row (C21 != 0, as after numerical drift) still gives the latitude of its z
    lat3, _ = earth.latlon_from_cne_s(c01, c11, cl * 0.6, cl * 0.8, c22)
    assert lat3 == pytest.approx(lat, abs=1e-15)
    c = earth.cne_from_latlon_s(lat, lon)
    np.testing.assert_allclose(c, [-sl * co, -so, -cl * co, -sl * so, co, -cl * so, cl, 0.0, -sl], rtol=0, atol=1e-15)


@pytest.mark.parametrize("lat_deg", [45.0, -20.0])
def test_earth_rate_n_sets_every_component(lat_deg):
    """The output is allocated uninitialised (np.empty): each component must be written. numpy
    hands a freed small buffer back to the next allocation of its size, so fill one with a
    marker first; a component left unwritten then shows the marker instead of its value."""
    lat = math.radians(lat_deg)
    for _ in range(3):
        junk = np.full(3, 123.0)
        del junk
        w = earth.earth_rate_n(lat)
        np.testing.assert_allclose(w, [OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)], rtol=0,
                                   atol=OMEGA * REL)

"""WGS-84 model against independently known values and identities."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mavins.core import earth


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

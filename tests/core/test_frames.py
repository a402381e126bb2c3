"""What the mutation runs found unchecked in mavins/core/frames.py (docs/testing.md): the error conventions of the
analysis and the benchmarks, against values typed here.

Radii: WGS-84 meridian and prime-vertical radii, R_N = a (1 - e^2) / (1 - e^2 sin^2 L)^1.5 and
R_E = a / sqrt(1 - e^2 sin^2 L) (NIMA TR8350.2 eq. 4-18, 4-15); attitude error: docs/conventions.md
"Aided navigation", ``q(est) = q(phi) (x) q(true)`` with q(phi) = [cos |phi|/2, sin(|phi|/2) phi/|phi|]
(Hamilton, [w x y z]). Local NED offset: geodetic to ECEF (NIMA TR8350.2 eq. 4-14) differenced and rotated by
C_e^n of the origin, whose rows are the north, east and down unit vectors in ECEF.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from support import A, E2, quat_zyx

from mavins.core import frames


def radii(lat: float) -> tuple[float, float]:
    w = 1.0 - E2 * math.sin(lat) ** 2
    return A * (1.0 - E2) / w**1.5, A / math.sqrt(w)


def hamilton(p, q) -> np.ndarray:
    """p (x) q, both [w x y z]."""
    pw, pv, qw, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + np.cross(pv, qv)])


def ecef(lat: float, lon: float, h: float) -> np.ndarray:
    r_e = A / math.sqrt(1.0 - E2 * math.sin(lat) ** 2)
    return np.array([(r_e + h) * math.cos(lat) * math.cos(lon), (r_e + h) * math.cos(lat) * math.sin(lon),
                     (r_e * (1.0 - E2) + h) * math.sin(lat)])


@pytest.mark.parametrize("origin, point", [
    ((0.8, 0.15, 400.0), (0.8 + 1e-4, 0.15 - 2e-4, 425.0)),  # hundreds of metres: a vehicle near its origin
    ((-0.6, 2.5, -30.0), (-0.55, 2.6, 9000.0)),  # hundreds of kilometres and 9 km up: the earth's curvature shows
    ((1.5, -3.0, 0.0), (1.4999, 3.1, 10.0)),  # near the pole, across the antimeridian
    ((0.7, 0.2, 100.0), (0.7, 0.21, 100.0)),  # along the parallel: the same ECEF z, a zero difference
])
def test_local_ned_is_the_ecef_difference_on_the_origins_north_east_and_down(origin, point) -> None:
    lat0, lon0, h0 = origin
    north = np.array([-math.sin(lat0) * math.cos(lon0), -math.sin(lat0) * math.sin(lon0), math.cos(lat0)])
    east = np.array([-math.sin(lon0), math.cos(lon0), 0.0])
    down = -np.array([math.cos(lat0) * math.cos(lon0), math.cos(lat0) * math.sin(lon0), math.sin(lat0)])
    d = ecef(*point) - ecef(*origin)
    want = (north @ d, east @ d, down @ d)
    got = frames.local_ned_s(*point, *origin)
    # ECEF coordinates of ~6.4e6 m carry ~1e-9 m of rounding each: 1e-7 m leaves a hundredfold margin
    assert got == pytest.approx(want, rel=0, abs=1e-7)
    deg = (math.degrees(lat0), math.degrees(lon0), h0)
    assert frames.local_ned(*point, deg) == pytest.approx(want, rel=0, abs=1e-7)  # the origin in degrees


def test_north_east_error_through_the_reference_radii() -> None:
    lat_ref, lon_ref = 0.75, -1.25  # binary-exact, with offsets of 2^-15 rad: the differences are exact
    d = 2.0**-15
    r_n, r_e = radii(lat_ref)
    dn, de = frames.north_east_error(lat_ref + d, lon_ref - d, lat_ref, lon_ref)
    assert dn == pytest.approx(d * r_n, rel=1e-14, abs=0)  # lat's own radii would be 1e-7 relative off
    assert de == pytest.approx(-d * r_e * math.cos(lat_ref), rel=1e-14, abs=0)


def _row(t, lat, lon, h, v, q) -> np.ndarray:
    return np.concatenate([[t, lat, lon, h], v, [0.0, 0.0, 0.0], q])


@pytest.mark.parametrize("phi", [(1e-3, -2e-3, 3e-3), (0.0, 0.0, 0.0), (2.0, -1.0, 0.5), (3.1, 0.0, 0.0)])
def test_nav_errors_position_velocity_and_attitude(phi) -> None:
    """Two rows at different points: position errors through the true point's radii and height, velocity
    differences, and phi back from q(est) = q(phi) (x) q(true), also when q(est) has a negative scalar part (the
    same rotation) and for angles up to nearly a half turn."""
    phi = np.array(phi)
    ang = float(np.linalg.norm(phi))
    q_phi = np.concatenate([[math.cos(ang / 2)], math.sin(ang / 2) * phi / ang]) if ang else np.array([1.0, 0, 0, 0])
    q1, q2 = quat_zyx(0.1, -0.2, 2.5), quat_zyx(-0.3, 0.05, -1.0)
    truth = np.vstack([_row(1.0, 47.0, 8.5, 400.0, [1.0, 2.0, 3.0], q1), _row(2.0, -33.0, 151.0, -20.0, [0.0, -5.0, 0.5], q2)])
    e1, e2 = hamilton(q_phi, q1), -hamilton(q_phi, q2)  # the second with the opposite sign: the same rotation
    sol = np.vstack([_row(1.0, 47.0 + 1e-5, 8.5 - 2e-5, 398.5, [1.5, 1.0, 3.25], e1),
                     _row(2.0, -33.0 - 3e-5, 151.0 + 1e-5, -19.0, [0.0, -5.0, 0.0], e2)])
    err = frames.nav_errors(sol, truth)
    assert err.shape == (2, 9)
    for i, (dlat, dlon, dh) in enumerate([(1e-5, -2e-5, -1.5), (-3e-5, 1e-5, 1.0)]):
        lat = math.radians(truth[i, 1])
        r_n, r_e = radii(lat)
        h = truth[i, 3]
        np.testing.assert_allclose(err[i, 0:3], [math.radians(dlat) * (r_n + h),
                                                 math.radians(dlon) * (r_e + h) * math.cos(lat), -dh],
                                   rtol=1e-9, atol=0)
        np.testing.assert_allclose(err[i, 6:9], phi, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(err[:, 3:6], sol[:, 4:7] - truth[:, 4:7])


def test_nav_errors_of_wider_rows_and_of_a_tiny_rotation() -> None:
    """Rows may carry more columns than the 14 of the solution (the aided rows, the simulator's truth): only
    columns 10..13 are the quaternion. A rotation of 1e-13 rad takes the branch below |vec| 1e-12, where
    phi = 2 vec / w, to the digit."""
    q = quat_zyx(0.4, 0.3, -2.0)
    phi = np.array([1e-13, -2e-13, 5e-14])
    q_est = hamilton(np.concatenate([[1.0], phi / 2]), q)
    truth = np.concatenate([_row(0.5, 10.0, 20.0, 30.0, [0.0, 0.0, 0.0], q), [0.9, -0.9, 7.0]])[None, :]
    sol = np.concatenate([_row(0.5, 10.0, 20.0, 30.0, [0.0, 0.0, 0.0], q_est), [5.0, 6.0]])[None, :]
    err = frames.nav_errors(sol, truth)
    np.testing.assert_allclose(err[0, 6:9], phi, rtol=1e-3, atol=0)  # vec to round-off of q (1e-16 of 1)
    np.testing.assert_array_equal(err[0, 0:6], np.zeros(6))

"""Redundant sensors (core/redundancy.py, core/fdi.py): every expected value comes from theory or a
published table, never from the code under test."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from mavins.core import redundancy as rd
from mavins.core.errmodel import ImuSpec
from mavins.core.fdi import ImuSetMonitor, ParityMonitor


def _random_h(rng: np.random.Generator, n: int) -> np.ndarray:
    h = rng.standard_normal((n, 3))
    return h / np.linalg.norm(h, axis=1, keepdims=True)


@pytest.mark.parametrize("n", [4, 5, 6, 9, 12])
def test_parity_matrix_annihilates_h_and_has_orthonormal_rows(n: int) -> None:
    rng = np.random.default_rng(n)
    H = _random_h(rng, n)
    sigma = rng.uniform(0.5, 2.0, n)
    for s in (None, sigma):
        V = rd.parity_matrix(H, s)
        W = np.eye(n) if s is None else np.diag(1.0 / s)
        assert V.shape == (n - 3, n)
        # V W H = 0 and V V^T = I to rounding: entries of order 1, so a few ulp times n
        np.testing.assert_allclose(V @ W @ H, 0.0, atol=1e-13)
        np.testing.assert_allclose(V @ V.T, np.eye(n - 3), atol=1e-13)


def test_parity_matrix_refuses_axes_that_do_not_span_3d() -> None:
    H = np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 1.0, 0], [1.0, -1.0, 0]]) / np.array([[1], [1], [2**0.5], [2**0.5]])
    with pytest.raises(ValueError, match="span"):
        rd.parity_matrix(H)


def test_fused_estimate_equals_hand_solution() -> None:
    # x, y, z and (1,1,1)/sqrt 3: H^T H = I + 1 1^T / 3, inverse by Sherman-Morrison I - 1 1^T / 6,
    # so x = (I - 1 1^T/6) (m_xyz + m_4 (1,1,1)/sqrt 3)
    H = np.vstack([np.eye(3), np.ones(3) / math.sqrt(3.0)])
    m = np.array([0.3, -1.2, 2.0, 0.7])
    expect = (np.eye(3) - np.ones((3, 3)) / 6.0) @ (m[:3] + m[3] * np.ones(3) / math.sqrt(3.0))
    np.testing.assert_allclose(rd.fuse(H, m), expect, rtol=1e-14, atol=1e-15)
    # two triads in one frame with sigmas s1, s2: the inverse-variance weighted mean of each axis
    H2 = rd.triad_rows([np.eye(3), np.eye(3)])
    m2 = np.array([1.0, 2.0, 3.0, 1.5, 1.0, 2.0])
    s = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    expect2 = (m2[:3] / 1.0 + m2[3:] / 4.0) / (1.0 + 0.25)
    np.testing.assert_allclose(rd.fuse(H2, m2, s), expect2, rtol=1e-14)


# Upper critical values chi^2_{1-a}(nu), P(X > x) = a, as printed (3 decimals) in the NIST/SEMATECH
# e-Handbook of Statistical Methods, table 1.3.6.7.4 "Critical values of the chi-square distribution".
UPPER = {
    1: {0.10: 2.706, 0.05: 3.841, 0.025: 5.024, 0.01: 6.635, 0.001: 10.828},
    2: {0.10: 4.605, 0.05: 5.991, 0.025: 7.378, 0.01: 9.210, 0.001: 13.816},
    3: {0.10: 6.251, 0.05: 7.815, 0.025: 9.348, 0.01: 11.345, 0.001: 16.266},
    6: {0.10: 10.645, 0.05: 12.592, 0.025: 14.449, 0.01: 16.812, 0.001: 22.458},
    10: {0.10: 15.987, 0.05: 18.307, 0.025: 20.483, 0.01: 23.209, 0.001: 29.588},
}
# Lower critical values, P(X < x) = a, same table.
LOWER = {
    6: {0.10: 2.204, 0.05: 1.635, 0.025: 1.237, 0.01: 0.872, 0.001: 0.381},
    10: {0.10: 4.865, 0.05: 3.940, 0.025: 3.247, 0.01: 2.558, 0.001: 1.479},
}


@pytest.mark.parametrize("dof", sorted(UPPER))
def test_chi2_quantiles_match_published_table(dof: int) -> None:
    for a, x in UPPER[dof].items():
        # the table rounds to 3 decimals: half a unit of the last place
        assert rd.chi2_quantile(a, dof, upper=True) == pytest.approx(x, abs=5e-4)
        assert rd.chi2_sf(x, dof) == pytest.approx(a, rel=2e-3)
    for a, x in LOWER.get(dof, {}).items():
        assert rd.chi2_quantile(a, dof) == pytest.approx(x, abs=5e-4)


@pytest.mark.parametrize("p", [1e-3, 1e-6, 1e-9, 1e-12])
def test_chi2_far_tail_against_closed_forms(p: float) -> None:
    # nu = 2: Q = exp(-x/2), so x = -2 ln p; nu = 4: Q = exp(-x/2) (1 + x/2) (A&S 26.4.21)
    assert rd.chi2_quantile(p, 2, upper=True) == pytest.approx(-2.0 * math.log(p), rel=1e-12)
    x4 = rd.chi2_quantile(p, 4, upper=True)
    assert math.exp(-x4 / 2.0) * (1.0 + x4 / 2.0) == pytest.approx(p, rel=1e-10)
    # nu = 1: X = Z^2, P(X > x) = erfc(sqrt(x/2))
    x1 = rd.chi2_quantile(p, 1, upper=True)
    assert math.erfc(math.sqrt(x1 / 2.0)) == pytest.approx(p, rel=1e-10)


def test_noncentral_chi2_against_closed_form_for_one_dof() -> None:
    # nu = 1: X = (Z + sqrt(lam))^2, P(X <= x) = Phi(sqrt x - sqrt lam) - Phi(-sqrt x - sqrt lam)
    def phi(z: float) -> float:
        return 0.5 * math.erfc(-z / math.sqrt(2.0))

    for lam in (0.5, 4.0, 30.0, 400.0):
        for x in (0.3, 3.0, 25.0, 500.0):
            expect = phi(math.sqrt(x) - math.sqrt(lam)) - phi(-math.sqrt(x) - math.sqrt(lam))
            assert rd.ncx2_cdf(x, 1, lam) == pytest.approx(expect, abs=1e-12)


def test_dodecahedron_and_cone_are_optimal() -> None:
    for H in (rd.dodecahedron_axes(), rd.cone_axes(6)):
        np.testing.assert_allclose(np.linalg.norm(H, axis=1), 1.0, rtol=1e-15)
        np.testing.assert_allclose(H.T @ H, 2.0 * np.eye(3), atol=1e-14)  # N/3 I, N = 6
        assert rd.gdop(H) == pytest.approx(3.0 / math.sqrt(6.0), rel=1e-14)  # sqrt(trace(I/2)) = sqrt(3/2)
    # dodecahedron: every pair of axes at arccos(1/sqrt 5) = 63.4349 deg
    D = rd.dodecahedron_axes()
    cos = np.abs(D @ D.T)[~np.eye(6, dtype=bool)]
    np.testing.assert_allclose(cos, 1.0 / math.sqrt(5.0), rtol=1e-14)
    # cone of half-angle a: H^T H = diag(N/2 sin^2 a, N/2 sin^2 a, N cos^2 a), so
    # GDOP^2 = 4 / (N sin^2 a) + 1 / (N cos^2 a), least at tan^2 a = 2
    for a_deg in (30.0, 45.0, 54.7356103172, 70.0):
        a = math.radians(a_deg)
        expect = math.sqrt(4.0 / (6 * math.sin(a) ** 2) + 1.0 / (6 * math.cos(a) ** 2))
        assert rd.gdop(rd.cone_axes(6, a)) == pytest.approx(expect, rel=1e-13)
    assert math.degrees(rd.OPTIMAL_CONE_HALF_ANGLE) == pytest.approx(54.7356103172, abs=1e-9)
    # three orthogonal axes: sqrt 3
    assert rd.gdop(np.eye(3)) == pytest.approx(math.sqrt(3.0), rel=1e-15)


@pytest.mark.parametrize("H", [rd.dodecahedron_axes(), rd.cone_axes(6)], ids=["dodecahedron", "cone"])
def test_six_sensor_sets_isolate_any_single_failure_and_detect_any_two(H: np.ndarray) -> None:
    rng = np.random.default_rng(6)
    V = rd.parity_matrix(H)
    assert rd.isolable(V).all()
    thr = rd.chi2_quantile(1e-6, 3, upper=True)
    x = np.array([0.3, -0.2, 0.5])
    for j in range(6):
        # a fault of f sigma on sensor j moves p by f v_j; |v_j|^2 = 1 - h_j^T (H^T H)^-1 h_j = 1/2, so
        # f = 20 gives a non-centrality of 200, far over the threshold (31.0), and the test statistic of
        # sensor j exceeds every other one's by (f |v_j|)^2 (1 - cos^2) >> noise
        for trial in range(20):
            m = H @ x + rng.standard_normal(6)
            m[j] += 20.0
            p = rd.parity_vector(V, m)
            assert rd.test_statistic(p) > thr
            assert rd.isolate(V, p) == j
    for j, k in itertools.combinations(range(6), 2):
        for sj, sk in ((1, 1), (1, -1)):
            m = H @ x
            m[j] += 20.0 * sj
            m[k] += 20.0 * sk
            # V^T V = I - H H^T / 2, so |v_j|^2 = 1/2 and v_j.v_k = -h_j.h_k / 2: the noise-free
            # statistic |f_j v_j + f_k v_k|^2 = 400 (1 +- h_j.h_k) >= 400 (1 - 2/3) = 133 (|h_j.h_k| is
            # 1/sqrt 5 in the dodecahedron, at most 2/3 in the cone), over the threshold 31.0
            assert rd.test_statistic(rd.parity_vector(V, m)) > thr


def test_two_triads_detect_without_isolating() -> None:
    H = rd.triad_rows([np.eye(3), np.eye(3)])
    V = rd.parity_matrix(H)
    # each axis has two measurements: a one-dimensional parity per axis whose two columns are opposite
    assert not rd.isolable(V).any()
    m = H @ np.array([1.0, 2.0, 3.0])
    m[4] += 10.0
    p = rd.parity_vector(V, m)
    assert rd.test_statistic(p) == pytest.approx(50.0, rel=1e-12)  # 10^2 |v|^2, |v|^2 = 1/2
    assert rd.isolate(V, p) == -1
    # three triads: every column isolable; four single axes: parity of one dimension, none isolable
    assert rd.isolable(rd.parity_matrix(rd.triad_rows([np.eye(3)] * 3))).all()
    assert not rd.isolable(rd.parity_matrix(np.vstack([np.eye(3), np.ones(3) / math.sqrt(3)]))).any()


WHITE_SPEC = ImuSpec(gyro_arw=1e-3, accel_vrw=1e-2)


def test_monitor_with_two_imus_detects_and_never_isolates() -> None:
    dt = 0.01
    n = 6000
    t = dt * np.arange(1, n + 1)
    rng = np.random.default_rng(2)
    dth = 1e-3 * math.sqrt(dt) * rng.standard_normal((n, 2, 3))
    dv = 1e-2 * math.sqrt(dt) * rng.standard_normal((n, 2, 3))
    dth[t > 30.0, 1, 0] += 0.02 * dt  # 0.02 rad/s against a window sigma of 1e-3/sqrt(0.5) = 1.4e-3
    mon = ImuSetMonitor(2, WHITE_SPEC, dt)
    _, _, events = mon.process(t, dth, dv, np.full(n, dt))
    assert [e.event for e in events] == ["detected"]
    assert events[0].sensor == "gyro" and events[0].imu is None and events[0].axis == ""
    assert 30.0 < events[0].t <= 31.0


def test_parity_monitor_rejects_a_noiseless_model() -> None:
    with pytest.raises(ValueError, match="no noise"):
        ParityMonitor(rd.triad_rows([np.eye(3)] * 2), 0.0, window=10, window_s=0.1, false_alarm=1e-6)


def test_rotated_imus_fuse_to_the_body_vector_and_isolate_in_their_own_axes() -> None:
    # IMU 1 turned 90 deg about z: its x axis is body y (R maps body to IMU axes)
    rz = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    rots = [np.eye(3), rz, np.eye(3)]
    H = rd.triad_rows(rots)
    x = np.array([0.1, -0.2, 0.3])
    m = H @ x
    np.testing.assert_allclose(rd.fuse(H, m), x, rtol=1e-14)
    m[3] += 5.0  # IMU 1, its own x axis
    V = rd.parity_matrix(H)
    assert rd.isolate(V, rd.parity_vector(V, m)) == 3
    # the fused vector is off along body y by 1/3 of the fault: the mean of three measurements of y
    np.testing.assert_allclose(rd.fuse(H, m), x + np.array([0.0, 5.0 / 3.0, 0.0]), rtol=1e-13)


def test_monitor_isolates_a_noise_burst_and_takes_the_sensor_back() -> None:
    dt = 0.01
    n = 5000
    t = dt * np.arange(1, n + 1)
    rng = np.random.default_rng(8)
    dth = 1e-3 * math.sqrt(dt) * rng.standard_normal((n, 3, 3))
    dv = 1e-2 * math.sqrt(dt) * rng.standard_normal((n, 3, 3))
    burst = (t > 20.0) & (t <= 25.0)
    # 0.5 m/s^2 per sample for 5 s: window-mean sigma 0.5 / sqrt(50) = 0.07 against the window noise
    # 1e-2 / sqrt(0.5) = 0.014: non-centrality about (0.07/0.014)^2 (2/3) = 17 per window on average
    # with a chi-square(6) spread, far over 38 in some window of the ten
    dv[burst, 0, 2] += 0.5 * dt * rng.standard_normal(int(burst.sum()))
    mon = ImuSetMonitor(3, WHITE_SPEC, dt)
    _, _, events = mon.process(t, dth, dv, np.full(n, dt))
    kinds = [(e.event, e.sensor, e.imu, e.axis) for e in events]
    assert kinds[:2] == [("detected", "accel", None, ""), ("isolated", "accel", 0, "z")]
    assert 20.0 < events[1].t <= 25.0
    # taken back after 20 windows (10 s) in a row of agreement: not before 10 s after the isolation
    # (burst windows may pass the 1-dof test by chance), and at the latest 10 s after the burst, when
    # every clean window passes (each fails with probability 1e-6)
    assert kinds[2] == ("recovered", "accel", 0, "z")
    assert events[1].t + 10.0 - 1e-9 <= events[2].t <= 35.0 + 1e-9
    assert len(events) == 3

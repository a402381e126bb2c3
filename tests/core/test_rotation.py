"""Attitude representations: round trips, orthogonality, kinematics consistency."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mavins.core import rotation as rot
from support import quat_angle, quat_error, wrap_rad

angle = st.floats(-np.pi, np.pi, allow_nan=False)
pitch_angle = st.floats(-1.55, 1.55, allow_nan=False)
vec = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3).map(np.array)
EPS = 1e-12  # a few ulps of O(1) numbers through ~10 flops


def rand_quat(v: np.ndarray) -> np.ndarray:
    return rot.rotvec_to_quat(v)


@given(angle, pitch_angle, angle)
def test_euler_dcm_round_trip(r, p, y):
    c = rot.euler_to_dcm(r, p, y)
    e = rot.dcm_to_euler(c)
    np.testing.assert_allclose(rot.euler_to_dcm(*e), c, atol=EPS)
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=EPS)
    assert -np.pi < e[0] <= np.pi and -np.pi / 2 <= e[1] <= np.pi / 2 and -np.pi < e[2] <= np.pi


@given(angle, pitch_angle, angle)
def test_euler_quat_matches_dcm(r, p, y):
    q = rot.euler_to_quat(r, p, y)
    np.testing.assert_allclose(rot.quat_to_dcm(q), rot.euler_to_dcm(r, p, y), atol=EPS)
    assert q[0] >= 0


@given(vec)
def test_quat_dcm_round_trip(v):
    q = rot.quat_canonical(rand_quat(v))
    np.testing.assert_allclose(rot.dcm_to_quat(rot.quat_to_dcm(q)), q, atol=EPS)


@given(vec)
def test_rotvec_quat_dcm_agree(v):
    np.testing.assert_allclose(rot.quat_to_dcm(rot.rotvec_to_quat(v)), rot.rotvec_to_dcm(v), atol=EPS)


@given(vec)
def test_rotvec_round_trip(v):
    # angles within (0, pi) map back to themselves
    if np.linalg.norm(v) >= np.pi - 1e-6:
        return
    np.testing.assert_allclose(rot.quat_to_rotvec(rot.rotvec_to_quat(v)), v, atol=1e-11)
    np.testing.assert_allclose(rot.dcm_to_rotvec(rot.rotvec_to_dcm(v)), v, atol=1e-11)


def test_small_angle_series_is_continuous():
    """The series branch and the closed form agree at the switch angle to round-off."""
    axis = np.array([0.3, -0.5, 0.81])
    axis /= np.linalg.norm(axis)
    for s in (rot.SMALL_ANGLE * (1 - 1e-9), rot.SMALL_ANGLE * (1 + 1e-9)):
        q = rot.rotvec_to_quat(s * axis)
        assert abs(q[0] - np.cos(s / 2)) < 1e-16
        np.testing.assert_allclose(q[1:], np.sin(s / 2) * axis, rtol=1e-15, atol=1e-20)
        np.testing.assert_allclose(rot.quat_to_rotvec(q), s * axis, rtol=1e-12)


@given(vec, vec)
def test_quat_product_is_composition(a, b):
    p, q = rand_quat(a), rand_quat(b)
    np.testing.assert_allclose(
        rot.quat_to_dcm(rot.quat_mul(p, q)), rot.quat_to_dcm(p) @ rot.quat_to_dcm(q), atol=EPS
    )
    x = np.array([0.2, -1.0, 0.7])
    np.testing.assert_allclose(rot.quat_rotate(p, x), rot.quat_to_dcm(p) @ x, atol=EPS)


def test_euler_axes_match_the_contract():
    """Yaw 90 deg maps body forward onto east; roll 90 deg maps body right onto down."""
    c = rot.euler_to_dcm(0.0, 0.0, np.pi / 2)
    np.testing.assert_allclose(c @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    c = rot.euler_to_dcm(np.pi / 2, 0.0, 0.0)
    np.testing.assert_allclose(c @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    c = rot.euler_to_dcm(0.0, np.pi / 6, 0.0)  # nose up: forward gets a negative down component
    assert (c @ [1, 0, 0])[2] < 0


@settings(max_examples=50)
@given(angle, st.floats(-1.2, 1.2), angle, vec)
def test_three_kinematic_equations_agree(r, p, y, w):
    """Euler-rate, DCM and quaternion kinematics describe the same motion."""
    h = 1e-6
    c0 = rot.euler_to_dcm(r, p, y)
    q0 = rot.euler_to_quat(r, p, y)
    e0 = np.array([r, p, y])
    cdot = rot.dcm_rate(c0, w)
    qdot = rot.quat_rate(q0, w)
    edot = rot.euler_rates(e0, w)
    # central difference of the Euler-angle DCM along edot
    c_plus = rot.euler_to_dcm(*(e0 + h * edot))
    c_minus = rot.euler_to_dcm(*(e0 - h * edot))
    np.testing.assert_allclose((c_plus - c_minus) / (2 * h), cdot, atol=1e-7)
    # the quaternion derivative maps to the same DCM derivative
    dq = (rot.quat_to_dcm(q0 + h * qdot) - rot.quat_to_dcm(q0 - h * qdot)) / (2 * h)
    np.testing.assert_allclose(dq, cdot, atol=1e-7)


def test_orthonormalize_removes_first_order_defect():
    c = rot.euler_to_dcm(0.3, -0.2, 1.0)
    s = 1e-4 * np.array([[1.0, 0.5, -0.3], [0.5, -2.0, 0.1], [-0.3, 0.1, 0.7]])
    bad = c @ (np.eye(3) + s)
    fixed = rot.orthonormalize(bad)
    before = np.linalg.norm(bad @ bad.T - np.eye(3))
    after = np.linalg.norm(fixed @ fixed.T - np.eye(3))
    assert after < 3 * before**2 + 1e-15  # second order in the defect


def test_angle_between_small_and_large():
    a = 1e-9
    q = rot.rotvec_to_quat(np.array([0.0, 0.0, a]))
    assert abs(rot.quat_angle_between(np.array([1.0, 0, 0, 0]), q) - a) < 1e-20
    assert abs(rot.quat_angle_between(q, -q)) < 1e-15  # q and -q are the same rotation


def test_wrap_pi_agrees_with_the_tests_own_wrap():
    """rotation.wrap_pi against support.wrap_rad (written apart from it), the +-pi edges included."""
    rng = np.random.default_rng(20)
    edges = [0.0, np.pi, -np.pi, 2 * np.pi, -2 * np.pi, 3 * np.pi, -3 * np.pi, 1e-300, -1e-300]
    edges += [np.nextafter(e, d) for e in (np.pi, -np.pi) for d in (-4.0, 4.0)]
    a = np.concatenate([rng.uniform(-60.0, 60.0, 3000), rng.uniform(-4.0, 4.0, 3000), edges])
    got = np.array([rot.wrap_pi(x) for x in a])
    want = wrap_rad(a)
    assert np.all((got > -np.pi) & (got <= np.pi)) and np.all((want > -np.pi) & (want <= np.pi))
    inside = np.abs(want) < np.pi - 1e-12  # at +-pi one rounding may land either side of the cut
    np.testing.assert_allclose(got[inside], want[inside], rtol=0, atol=1e-13)
    np.testing.assert_allclose(wrap_rad(got - want), 0.0, rtol=0, atol=1e-13)
    assert rot.wrap_pi(np.pi) == wrap_rad(np.pi) == np.pi
    assert rot.wrap_pi(-np.pi) == wrap_rad(-np.pi) == np.pi


def test_quat_angle_agrees_with_the_tests_own_metric():
    """quat_angle_between and quat_angle_rows against support.quat_angle: random pairs, the same
    attitude, its negative, half turns (p.q = 0), near half turns and tiny angles."""
    rng = np.random.default_rng(21)

    def unit(x: np.ndarray) -> np.ndarray:
        return x / np.linalg.norm(x, axis=-1, keepdims=True)

    p = unit(rng.standard_normal((600, 4)))
    q = unit(rng.standard_normal((600, 4)))
    ortho = unit(q - np.sum(q * p, axis=1, keepdims=True) * p)  # p^-1 (x) ortho has w = 0: a half turn
    q[100:200] = ortho[100:200]
    q[200:300] = unit(ortho[200:300] + 1e-9 * p[200:300])  # a half turn less about 2e-9 rad
    q[300:400] = unit(p[300:400] + 1e-9 * ortho[300:400])  # about 2e-9 rad
    q[400:450] = p[400:450]
    q[450:500] = -p[450:500]  # the same rotation
    q[500:550] = -ortho[500:550]
    want = quat_angle(p, q)
    rows = rot.quat_angle_rows(p, q)
    one = np.array([rot.quat_angle_between(a, b) for a, b in zip(p, q)])
    np.testing.assert_allclose(rows, want, rtol=1e-12, atol=2e-15)
    np.testing.assert_allclose(one, want, rtol=1e-12, atol=2e-15)
    np.testing.assert_allclose(want[100:200], np.pi, rtol=0, atol=2e-15)
    np.testing.assert_allclose(rows[100:200], np.pi, rtol=0, atol=2e-15)
    assert np.all(rows[400:500] <= 2e-15) and np.all(want[400:500] <= 2e-15)
    err = rot.quat_error_rows(q, p)
    np.testing.assert_allclose(np.linalg.norm(err, axis=1), want, rtol=1e-12, atol=4e-15)
    away = np.r_[0:100, 300:500, 550:600]  # at a half turn +phi and -phi are the same rotation
    np.testing.assert_allclose(err[away], quat_error(q, p)[away], rtol=1e-12, atol=4e-15)

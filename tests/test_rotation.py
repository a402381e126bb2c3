"""Attitude representations: round trips, orthogonality, kinematics consistency."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mavins.core import rotation as rot

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

"""Attitude representations: round trips, orthogonality, kinematics consistency.

Also the rest of mavins/core/rotation.py (docs/testing.md).

Every expected value is built here from the contract (docs/conventions.md "Frames and
attitude": Hamilton quaternions, scalar first, ``v_n = C(q) v_b``; ZYX Euler angles,
``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)``, roll and yaw in (-pi, pi]) and textbook closed
forms: Rodrigues' rotation ``C = I + sin s [u x] + (1 - cos s) [u x]^2`` for a
rotation s about the unit axis u, whose quaternion is ``[cos s/2, sin s/2 u]``; the
Hamilton product in vector form ``(p0 q0 - p.q, p0 q + q0 p + p x q)``; the kinematics
``dC/dt = C [w x]``, ``dq/dt = 1/2 q (x) [0, w]`` and the Euler-rate matrix of
[TW11]. Products by numpy; the half-angle coefficients from their Taylor series in
exact rational arithmetic. Nothing is taken from the module.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
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


RNG = np.random.default_rng(7)
TOL = 1e-14


def K(v) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rodrigues(axis, s) -> np.ndarray:
    u = np.asarray(axis, dtype=float)
    u = u / np.linalg.norm(u)
    return np.eye(3) + math.sin(s) * K(u) + (1.0 - math.cos(s)) * K(u) @ K(u)


def quat_axis(axis, s) -> np.ndarray:
    u = np.asarray(axis, dtype=float)
    u = u / np.linalg.norm(u)
    return np.concatenate([[math.cos(s / 2)], math.sin(s / 2) * u])


def hamilton(p, q) -> np.ndarray:
    p, q = np.asarray(p, float), np.asarray(q, float)
    return np.concatenate([[p[0] * q[0] - p[1:] @ q[1:]], p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:])])


def c_bn(roll, pitch, yaw) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), \
        math.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def m9(c) -> tuple:
    return tuple(np.asarray(c).ravel())


AXES = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 2, -2), (-3, 1, 0.5)]
ANGLES = [0.3, 1.7, -2.6, 3.1]


def test_skew_cross_mat_mul_mat_vec():
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    m, n = RNG.normal(size=(3, 3)), RNG.normal(size=(3, 3))
    np.testing.assert_array_equal(rot.skew(a), K(a))
    np.testing.assert_allclose(rot.cross(a, b), np.cross(a, b), rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.mat_mul(m, n), m @ n, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.mat_vec(m, a), m @ a, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.mat3_mul_s(m9(m), m9(n)), m9(m @ n), rtol=0, atol=TOL)


def test_quaternion_algebra():
    p, q = RNG.normal(size=4), RNG.normal(size=4)
    np.testing.assert_allclose(rot.quat_mul(p, q), hamilton(p, q), rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.quat_mul_s(tuple(p), tuple(q)), hamilton(p, q), rtol=0, atol=TOL)
    np.testing.assert_array_equal(rot.quat_conj(p), [p[0], -p[1], -p[2], -p[3]])
    np.testing.assert_allclose(rot.quat_normalize(p), p / np.linalg.norm(p), rtol=0, atol=1e-15)
    neg = np.array([-0.5, 0.5, -0.5, 0.5])
    np.testing.assert_array_equal(rot.quat_canonical(neg), -neg)
    pos = np.array([0.5, 0.5, -0.5, 0.5])
    out = rot.quat_canonical(pos)
    np.testing.assert_array_equal(out, pos)
    out[0] = 9.0  # a copy, not the input
    assert pos[0] == 0.5
    zero = np.array([0.0, 0.0, 0.0, -1.0])
    np.testing.assert_array_equal(rot.quat_canonical(zero), zero)


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("s", ANGLES)
def test_quaternion_to_dcm_and_rotate(axis, s):
    q = quat_axis(axis, s)
    c = rodrigues(axis, s)
    np.testing.assert_allclose(rot.quat_to_dcm(q), c, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.quat_to_dcm_s(tuple(q)), m9(c), rtol=0, atol=TOL)
    v = np.array([0.3, -1.2, 2.0])
    np.testing.assert_allclose(rot.quat_rotate(q, v), c @ v, rtol=0, atol=TOL)


# Shepperd's four branches: the trace largest (small rotation), or C00, C11, C22 largest
# (rotations near 180 deg about x, y, z), each with both signs of the off-axis part
SHEPPERD = [((1, 2, 3), 0.4), ((1, 2, 3), -0.4), ((1, 0.1, 0.2), 2.9), ((1, -0.1, 0.2), -2.9),
            ((0.1, 1, -0.2), 2.9), ((-0.1, 1, 0.2), -2.9), ((0.2, 0.1, 1), 2.9), ((0.2, -0.1, 1), -2.9),
            ((1, 0, 0), math.pi), ((0, 1, 0), math.pi), ((0, 0, 1), math.pi)]


@pytest.mark.parametrize("axis, s", SHEPPERD)
def test_dcm_to_quat_every_branch(axis, s):
    c = rodrigues(axis, s)
    q = quat_axis(axis, s)
    if q[0] < 0:
        q = -q
    np.testing.assert_allclose(rot.dcm_to_quat(c), q, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.dcm_to_quat_s(m9(c)), q, rtol=0, atol=TOL)
    got = rot.dcm_to_quat(c)
    assert got[0] >= 0.0
    assert np.linalg.norm(got) == pytest.approx(1.0, abs=1e-15)


def test_dcm_to_quat_normalises():
    """A slightly non-orthonormal DCM (scaled) still gives a unit quaternion."""
    c = rodrigues((1, 2, 3), 0.4) * (1.0 + 1e-6)
    assert np.linalg.norm(rot.dcm_to_quat(c)) == pytest.approx(1.0, abs=1e-15)
    for axis in ((1, 0.1, 0.2), (0.1, 1, -0.2), (0.2, 0.1, 1)):
        c = rodrigues(axis, 2.9) * (1.0 + 1e-6)
        assert np.linalg.norm(rot.dcm_to_quat(c)) == pytest.approx(1.0, abs=1e-15)


EULERS = [(0.3, -0.2, 1.1), (-2.5, 0.7, -3.0), (3.0, -1.4, 0.2), (0.0, 0.0, 0.0), (-0.4, 0.1, 2.9)]


@pytest.mark.parametrize("r, p, y", EULERS)
def test_euler_forms(r, p, y):
    c = c_bn(r, p, y)
    np.testing.assert_allclose(rot.euler_to_dcm(r, p, y), c, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.euler_to_dcm_s(r, p, y), m9(c), rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.dcm_to_euler(c), [r, p, y], rtol=0, atol=1e-13)
    np.testing.assert_allclose(rot.dcm_to_euler_s(c[0, 0], c[0, 1], c[1, 0], c[1, 1], c[2, 0], c[2, 1], c[2, 2]),
                               [r, p, y], rtol=0, atol=1e-13)
    q = hamilton(hamilton(quat_axis((0, 0, 1), y), quat_axis((0, 1, 0), p)), quat_axis((1, 0, 0), r))
    if q[0] < 0:
        q = -q
    np.testing.assert_allclose(rot.euler_to_quat(r, p, y), q, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.quat_to_euler(q), [r, p, y], rtol=0, atol=1e-13)


@pytest.mark.parametrize("p", [math.pi / 2, -math.pi / 2])
@pytest.mark.parametrize("yaw", [0.4, -2.0])
def test_dcm_to_euler_at_the_gimbal_lock(p, yaw):
    """At pitch +-90 deg roll is set to 0 and the whole rotation about the vertical goes to yaw;
    C20 just beyond -+1 (round-off) is clamped."""
    c = c_bn(0.0, p, yaw)
    got = rot.dcm_to_euler(c)
    assert got[0] == 0.0
    assert got[1] == pytest.approx(p, abs=1e-7)
    assert got[2] == pytest.approx(yaw, abs=1e-7)
    c[2, 0] = -math.copysign(1.0 + 1e-12, p)
    got = rot.dcm_to_euler(c)
    assert got[1] == math.copysign(math.pi / 2, p)
    assert got[0] == 0.0
    assert got[2] == pytest.approx(yaw, abs=1e-7)


@pytest.mark.parametrize("r, y", [(0.3, 1.1), (-2.0, 0.4)])
def test_dcm_to_euler_at_an_exact_gimbal_lock(r, y):
    """With cos(pitch) exactly 0 (pitch +-90 deg typed), ``Rz(y) Ry(+-90) Rx(r)`` depends on y -+ r
    only: ``C01 = -sin(y -+ r)``, ``C11 = cos(y -+ r)``, ``C21 = C22 = C00 = C10 = 0``. Roll 0, the whole
    rotation about the vertical in yaw."""
    for sp, yaw in ((1.0, y - r), (-1.0, y + r)):
        cr, sr, cy, sy = math.cos(r), math.sin(r), math.cos(y), math.sin(y)
        c = np.array([[0.0, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy],
                      [0.0, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy],
                      [-sp, 0.0, 0.0]])
        got = rot.dcm_to_euler(c)
        assert got[0] == 0.0
        assert got[1] == sp * math.pi / 2
        assert math.remainder(got[2] - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-15)


def test_dcm_to_euler_near_the_gimbal_lock_keeps_roll():
    r, p, y = 0.3, math.pi / 2 - 1e-6, 0.2
    got = rot.dcm_to_euler(c_bn(r, p, y))
    assert got[0] == pytest.approx(r, abs=1e-6)
    assert got[2] == pytest.approx(y, abs=1e-6)


def test_euler_ranges_at_pi():
    """Roll and yaw of +-180 deg come out as +180 (the range is (-pi, pi]), also for -0.0 inputs."""
    c = c_bn(math.pi, 0.2, -math.pi)
    got = rot.dcm_to_euler(c)
    assert got[0] == pytest.approx(math.pi, abs=1e-12) and got[2] == pytest.approx(math.pi, abs=1e-12)
    assert rot._atan2_half_open(-0.0, -1.0) == math.pi
    assert rot._atan2_half_open(0.0, -1.0) == math.pi
    assert rot._atan2_half_open(-1e-6, -1.0) == pytest.approx(-math.pi + 1e-6, abs=1e-15)
    assert rot._atan2_half_open(1.0, 1.0) == pytest.approx(math.pi / 4, abs=1e-16)


@pytest.mark.parametrize("a, want", [(0.5, 0.5), (-0.5, -0.5), (math.pi, math.pi), (-math.pi, math.pi),
                                     (1.5 * math.pi, -0.5 * math.pi), (-1.5 * math.pi, 0.5 * math.pi),
                                     (2.0 * math.pi + 0.25, 0.25), (-2.0 * math.pi - 0.25, -0.25),
                                     (7.0 * math.pi, math.pi), (-3.0 * math.pi, math.pi), (0.0, 0.0)])
def test_wrap_pi(a, want):
    assert rot.wrap_pi(a) == pytest.approx(want, abs=1e-14)
    assert -math.pi < rot.wrap_pi(a) <= math.pi


def half_angle(s2: float) -> tuple[float, float]:
    """``cos(s/2) = sum (-1)^j s^2j/(4^j (2j)!)``, ``sin(s/2)/s = sum (-1)^j s^2j/(2^(2j+1) (2j+1)!)``,
    summed exactly for the double s^2 and rounded once."""
    x = Fraction(s2)
    c = sum(Fraction((-1) ** j) * x ** j / (4 ** j * math.factorial(2 * j)) for j in range(40))
    k = sum(Fraction((-1) ** j) * x ** j / (2 ** (2 * j + 1) * math.factorial(2 * j + 1)) for j in range(40))
    return float(c), float(k)


# below the series limit (s < 1e-2), on it, and above (closed form)
ROTVECS = [(1e-7, 0.0, -2e-7), (0.004, -0.005, 0.006), (0.0099, 0.0, 0.0), (0.01, 0.0, 0.0),
           (0.3, -0.2, 0.25), (1.2, 0.9, -1.5), (0.0, 0.0, 3.0)]


@pytest.mark.parametrize("phi", ROTVECS)
def test_exp_map(phi):
    phi = np.array(phi)
    s2 = float(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
    c, k = half_angle(s2)
    got_c, got_k = rot.half_angle_coeffs(s2)
    assert got_c == pytest.approx(c, rel=2e-16, abs=0)
    assert got_k == pytest.approx(k, rel=4e-16, abs=0)
    q = np.array([c, k * phi[0], k * phi[1], k * phi[2]])
    np.testing.assert_allclose(rot.rotvec_to_quat(phi), q, rtol=0, atol=1e-16)
    np.testing.assert_allclose(rot.rotvec_to_quat_s(*phi), q, rtol=0, atol=1e-16)
    np.testing.assert_allclose(rot.quat_from_coeffs(phi, c, k), q, rtol=0, atol=0)
    # I + sin s/s [phi x] + (1 - cos s)/s^2 [phi x]^2 with sin s/s = 2ck, (1 - cos s)/s^2 = 2k^2
    dcm = np.eye(3) + 2 * c * k * K(phi) + 2 * k * k * K(phi) @ K(phi)
    np.testing.assert_allclose(rot.rotvec_to_dcm(phi), dcm, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rot.rotvec_to_dcm_s(*phi), m9(dcm), rtol=0, atol=1e-15)
    s = math.sqrt(s2)
    np.testing.assert_allclose(rot.rotvec_to_dcm(phi), rodrigues(phi, s), rtol=0, atol=1e-15)


def test_dcm_from_coeffs():
    phi = np.array([0.3, -0.7, 0.2])
    a1, a2 = 0.93, 0.41
    want = np.eye(3) + a1 * K(phi) + a2 * K(phi) @ K(phi)
    np.testing.assert_allclose(rot.dcm_from_coeffs(phi, a1, a2), want, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.dcm_from_coeffs_s(*phi, a1, a2), m9(want), rtol=0, atol=TOL)


@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("s", [1e-9, 5e-5, 2e-4, 0.3, 2.5, math.pi - 1e-9])
def test_log_map(axis, s):
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    q = quat_axis(axis, s)
    np.testing.assert_allclose(rot.quat_to_rotvec(q), s * u, rtol=0, atol=1e-15 * max(1.0, s))
    # the same rotation with a negative scalar part
    np.testing.assert_allclose(rot.quat_to_rotvec(-q), s * u, rtol=0, atol=1e-15 * max(1.0, s))
    np.testing.assert_allclose(rot.dcm_to_rotvec(rodrigues(axis, s)), s * u, rtol=0, atol=2e-14 * max(1.0, s)
                               if s > 1e-3 else 1e-16)


def atan_over_x(x: Fraction) -> Fraction:
    return sum(Fraction((-1) ** j) * x ** (2 * j) / (2 * j + 1) for j in range(20))


@pytest.mark.parametrize("v", [9.99e-5, 5e-5, 2e-4])
def test_log_map_exactly(v):
    """``2 atan(v/w)/v`` for q = [w, v, 0, 0], summed exactly: the result is within one ulp of the
    correctly rounded rotation vector, on both sides of the series limit (|v| = 1e-4)."""
    w = math.sqrt(1.0 - v * v)
    k = 2 / Fraction(w) * atan_over_x(Fraction(v) / Fraction(w))
    want = float(k * Fraction(v))
    got = rot.quat_to_rotvec(np.array([w, v, 0.0, 0.0]))[0]
    assert abs(got - want) <= 1.0 * math.ulp(want)


def test_log_map_series_to_fifth_order():
    """Below 1e-4 the rotation vector comes from ``2/w (1 - x^2/3 + x^4/5)``, x = |v|/w: at
    |v| = 9e-5 the x^2 term is 2.7e-9 relative."""
    v = 9e-5
    q = np.array([math.sqrt(1 - v * v), v, 0.0, 0.0])
    x = v / q[0]
    want = 2.0 * math.atan(x) / v * v
    assert rot.quat_to_rotvec(q)[0] == pytest.approx(want, rel=1e-16, abs=0)


def test_orthonormalize():
    c = rodrigues((1, 2, 3), 0.7) + 1e-4 * RNG.normal(size=(3, 3))
    want = c - 0.5 * (c @ c.T - np.eye(3)) @ c
    np.testing.assert_allclose(rot.orthonormalize(c), want, rtol=0, atol=TOL)
    np.testing.assert_allclose(rot.orthonormalize_s(m9(c)), m9(want), rtol=0, atol=TOL)


@pytest.mark.parametrize("r, p", [(0.3, -0.4), (-2.0, 1.0)])
def test_kinematics(r, p):
    w = np.array([0.11, -0.23, 0.37])
    m = np.array([[1.0, 0.0, -math.sin(p)], [0.0, math.cos(r), math.sin(r) * math.cos(p)],
                  [0.0, -math.sin(r), math.cos(r) * math.cos(p)]])
    np.testing.assert_allclose(rot.euler_rates(np.array([r, p, 0.9]), w), np.linalg.solve(m, w), rtol=0,
                               atol=1e-14)
    c = c_bn(r, p, 0.9)
    np.testing.assert_allclose(rot.dcm_rate(c, w), c @ K(w), rtol=0, atol=TOL)
    q = quat_axis((1, 2, 3), 0.8)
    np.testing.assert_allclose(rot.quat_rate(q, w), 0.5 * hamilton(q, [0.0, *w]), rtol=0, atol=TOL)


def test_angles_between():
    p = quat_axis((1, 2, 3), 0.8)
    d = quat_axis((-1, 0.5, 2), 0.05)
    q = hamilton(p, d)  # p^-1 q = d: 0.05 rad
    assert rot.quat_angle_between(p, q) == pytest.approx(0.05, abs=1e-15)
    assert rot.quat_angle_between(p, -q) == pytest.approx(0.05, abs=1e-15)
    big = hamilton(p, quat_axis((0, 1, 0), 3.0))
    assert rot.quat_angle_between(p, big) == pytest.approx(3.0, abs=1e-14)
    ps, qs = np.array([p, p]), np.array([q, big])
    np.testing.assert_allclose(rot.quat_angle_rows(ps, qs), [0.05, 3.0], rtol=0, atol=1e-14)
    # q_est = exp(phi) q_true: the error is phi, in the reference frame
    phi = np.array([0.01, -0.02, 0.03])
    est = hamilton(quat_axis(phi, np.linalg.norm(phi)), p)
    np.testing.assert_allclose(rot.quat_error_rows(np.array([est, p]), np.array([p, p])), [phi, [0, 0, 0]],
                               rtol=0, atol=1e-15)


def test_half_turns_have_the_positive_axis():
    """Roll and yaw range over (-180, 180]: +180 deg is the rotation +pi about +x (+z), whose quaternion
    is [cos 90deg, sin 90deg u] = [0, 1, 0, 0] ([0, 0, 0, 1]). Typed exactly, the scalar part is exactly
    0, and the vector part must keep the sign of the positive axis, as euler_to_quat gives it."""
    for c, q in ((np.diag([1.0, -1.0, -1.0]), [0.0, 1.0, 0.0, 0.0]), (np.diag([-1.0, -1.0, 1.0]), [0.0, 0.0, 0.0, 1.0])):
        np.testing.assert_array_equal(rot.dcm_to_quat(c), q)
    np.testing.assert_allclose(rot.euler_to_quat(math.pi, 0.0, 0.0), [0.0, 1.0, 0.0, 0.0], rtol=0, atol=1e-16)
    np.testing.assert_allclose(rot.euler_to_quat(0.0, 0.0, math.pi), [0.0, 0.0, 0.0, 1.0], rtol=0, atol=1e-16)

"""A camera's pose in its own frame (core/kalman.py: vision_position, vision_attitude, vision_place): the
models by hand, their H against the change of the innovation when the state is moved by a small error (the
filter's own feedback, central differences), and the frame's placement (augmentation) against a Monte Carlo
of the truth it is placed from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.jit import for_frame
from support import cbn

VP = slice(em.X_VP, em.X_VP + 3)
REF = np.array([0.8, 0.1, 90.0])  # lat, lon (rad), h (m) of the reference point


def rz(psi: float) -> np.ndarray:
    """The rotation about down by psi: a vector in the camera's frame to NED."""
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def radii(lat: float) -> tuple[float, float]:
    a, e2 = 6378137.0, (1 / 298.257223563) * (2 - 1 / 298.257223563)
    w = 1.0 - e2 * math.sin(lat) ** 2
    return a * (1 - e2) / w ** 1.5, a / math.sqrt(w)


def turned(off: float = 1e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A state turned every way (roll 15, pitch -10, yaw 120 deg) ``off`` rad north and east of the reference
    and 30 m above it, moving (8, -3, 0.5) m/s; a vision frame at heading 40 deg with its origin at (5, -7, 2) m:
    the state, the bias vector, C_b^n (support.cbn) and the body's NED metres from the reference (by hand)."""
    att = [math.radians(x) for x in (15.0, -10.0, 120.0)]
    s = sd.init_state(0.0, REF[0] + off, REF[1] + off, REF[2] + 30.0, np.array([8.0, -3.0, 0.5]), *att)
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_VP:kf.B_VP + 3] = (5.0, -7.0, 2.0)
    bias[kf.B_VY] = math.radians(40.0)
    r_n, r_e = radii(REF[0] + off)
    p = np.array([off * (r_n + REF[2] + 30.0), off * (r_e + REF[2] + 30.0) * math.cos(REF[0] + off), -30.0])
    return s, bias, cbn(*att), p


def test_the_position_model_by_hand() -> None:
    """Predicted ``Rz(psi)^T (p - v dt - o)`` less the measurement; H: Rz^T on dp, -dt Rz^T on dv, -Rz^T on the
    origin, ``-Rz^T (z x d)`` on the heading; R the sigmas squared."""
    s, bias, _, p = turned()
    v = np.array([8.0, -3.0, 0.5])
    p_v, sig = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.2, 0.3])
    nu, H, R = kf.vision_position(s, sd.make_config(), bias, REF, p_v, 0.02, sig)
    d = p - 0.02 * v - np.array([5.0, -7.0, 2.0])
    rt = rz(math.radians(40.0)).T
    np.testing.assert_allclose(nu, rt @ d - p_v, rtol=0, atol=1e-6)
    np.testing.assert_allclose(H[:, em.X_DP:em.X_DP + 3], rt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(H[:, em.X_DV:em.X_DV + 3], -0.02 * rt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(H[:, VP], -rt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(H[:, em.X_VY], -rt @ np.array([-d[1], d[0], 0.0]), rtol=0, atol=1e-6)
    others = np.setdiff1d(np.arange(em.NX), np.r_[em.X_DP:em.X_DP + 3, em.X_DV:em.X_DV + 3, em.X_VP:em.X_VY + 1])
    assert not H[:, others].any()
    np.testing.assert_allclose(R, np.diag(sig ** 2), rtol=1e-15)


def test_the_attitude_model_by_hand() -> None:
    """The camera sees ``Rz(psi)^T C`` turned by 0.01 rad about body y: nu is the rotation vector of
    ``C (Rz c_vb)^T`` (by hand: -0.01 C e_y), H is I on phi and -z on the heading, R is C diag(sigma^2) C^T."""
    s, bias, c, _ = turned()
    e = 0.01
    turn = np.array([[math.cos(e), 0.0, math.sin(e)], [0.0, 1.0, 0.0], [-math.sin(e), 0.0, math.cos(e)]])
    c_vb = rz(math.radians(40.0)).T @ c @ turn
    sig = np.array([0.01, 0.02, 0.03])
    nu, H, R = kf.vision_attitude(s, bias, np.ascontiguousarray(c_vb), sig)
    np.testing.assert_allclose(nu, -e * c[:, 1], rtol=0, atol=1e-12)
    want = np.zeros((3, em.NX))
    want[:, em.X_PHI:em.X_PHI + 3] = np.eye(3)
    want[2, em.X_VY] = -1.0
    np.testing.assert_array_equal(H, want)
    np.testing.assert_allclose(R, c @ np.diag(sig ** 2) @ c.T, rtol=0, atol=1e-18)


def moved(s: np.ndarray, bias: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The state and biases less the error x (the filter's feedback: what the estimate would be were x its
    error)."""
    s1, b1 = s.copy(), bias.copy()
    kf.feedback(s1, sd.make_config(), b1, x.copy())
    return s1, b1


@pytest.mark.parametrize("model", ["position", "attitude"])
def test_h_is_the_innovations_change_with_the_error(model: str) -> None:
    """For a small error x on every state the models read, ``nu(est) - nu(est - x)`` is H x to first order:
    by central differences ``(nu(+x) - nu(-x)) / 2`` (error O(x^3)) within 1e-6 of H x for x of 1e-4 (phi,
    rad; heading rad) and 1e-2 (m, m/s), less what H leaves out by design."""
    s, bias, c, _ = turned()
    cfg = sd.make_config()
    c_vb = np.ascontiguousarray(rz(math.radians(40.0)).T @ c)  # about a zero innovation, where H is its Jacobian
    rng = np.random.default_rng(5)
    x = np.zeros(em.NX)
    x[em.X_PHI:em.X_PHI + 3] = rng.normal(0.0, 1e-4, 3)
    x[em.X_DV:em.X_DV + 3] = rng.normal(0.0, 1e-2, 3)
    x[em.X_DP:em.X_DP + 3] = rng.normal(0.0, 1e-2, 3)
    x[VP] = rng.normal(0.0, 1e-2, 3)
    x[em.X_VY] = 1e-4

    def nu(sign: float) -> np.ndarray:
        s1, b1 = moved(s, bias, sign * x)  # est - (sign x): nu(est - sign x)
        if model == "position":
            return kf.vision_position(s1, cfg, b1, REF, np.array([1.0, 2.0, 3.0]), 0.02, np.ones(3))[0]
        return kf.vision_attitude(s1, b1, c_vb, np.ones(3))[0]

    if model == "position":
        H = kf.vision_position(s, cfg, bias, REF, np.array([1.0, 2.0, 3.0]), 0.02, np.ones(3))[1]
    else:
        H = kf.vision_attitude(s, bias, c_vb, np.ones(3))[1]
    # H leaves out the change of the metres per radian with height (as gnss_position): over the body's
    # 0.001 rad from the reference a height error dh moves d by 0.001 dh per axis, at most this much
    neglected = 2e-3 * abs(x[em.X_DP + 2]) if model == "position" else 0.0
    np.testing.assert_allclose((nu(-1.0) - nu(1.0)) / 2.0, H @ x, rtol=0, atol=1e-9 + neglected)


def place(s: np.ndarray, bias: np.ndarray, P: np.ndarray, p_v, c_vb, sig_p, sig_a, dt: float = 0.0) -> None:
    kf.vision_place(s, sd.make_config(), bias, P, REF, np.asarray(p_v, dtype=float), np.ascontiguousarray(c_vb),
                    dt, np.asarray(sig_p, dtype=float), np.asarray(sig_a, dtype=float))


def test_placing_the_frame_zeroes_its_innovations() -> None:
    """After placing from a pose, that pose's position innovation and its heading component are zero, whatever
    the frame was placed at before (a reset)."""
    s, bias, c, _ = turned()
    P = np.eye(em.NX) * 1e-4
    c_vb = rz(-0.7).T @ c @ np.array([[1.0, 0.0, 0.0], [0.0, math.cos(0.01), -math.sin(0.01)],
                                      [0.0, math.sin(0.01), math.cos(0.01)]])  # 0.01 rad of roll noise
    place(s, bias, P, (3.0, -4.0, 1.0), c_vb, (0.1,) * 3, (0.01,) * 3, 0.02)
    nu_p = kf.vision_position(s, sd.make_config(), bias, REF, np.array([3.0, -4.0, 1.0]), 0.02, np.ones(3))[0]
    nu_a = kf.vision_attitude(s, bias, np.ascontiguousarray(c_vb), np.ones(3))[0]
    np.testing.assert_allclose(nu_p, 0.0, atol=1e-9)
    assert abs(nu_a[2]) < 1e-12 and abs(bias[kf.B_VY] + 0.7) < 0.02  # c_vb = Rz(0.7) C: the frame at -0.7 rad
    np.testing.assert_allclose(P, P.T, rtol=0, atol=0)
    assert np.all(np.linalg.eigvalsh(P) > -1e-12)


def test_the_placed_frames_covariance_by_hand() -> None:
    """Level, heading 70 deg, the camera's pose 0.01 s old: the frame's heading error is ``phi_D + n_z`` and its
    origin's ``dp - dt dv - (z x Rz p_v) e + Rz n_p`` (docs/filter.md, with d = Rz p_v after placing), so with
    P holding phi_D, dv and dp variances (and one dp-dv correlation) the placed rows are those sums' variances
    and covariances, written out here with numpy."""
    s = sd.init_state(0.0, REF[0], REF[1], REF[2], np.array([3.0, -1.0, 0.2]), 0.0, 0.0, math.radians(70.0))
    bias = np.zeros(kf.B_SIZE)
    P = np.zeros((em.NX, em.NX))
    P[em.X_PHI + 2, em.X_PHI + 2] = 0.01
    for i, (vp, vv) in enumerate(((4.0, 0.04), (9.0, 0.09), (1.0, 0.01))):
        P[em.X_DP + i, em.X_DP + i] = vp
        P[em.X_DV + i, em.X_DV + i] = vv
    P[em.X_DP, em.X_DV] = P[em.X_DV, em.X_DP] = 0.3 * math.sqrt(4.0 * 0.04)
    P0 = P.copy()
    p_v, dt = np.array([2.0, -3.0, 0.5]), 0.01
    sig_p, sig_a = np.array([0.1, 0.2, 0.3]), np.array([0.01, 0.02, 0.03])
    psi = 0.4
    c_vb = rz(psi).T @ cbn(0.0, 0.0, math.radians(70.0))
    place(s, bias, P, p_v, c_vb, sig_p, sig_a, dt)
    assert bias[kf.B_VY] == pytest.approx(psi, abs=1e-12)
    rp = rz(psi) @ p_v
    k = np.array([-rp[1], rp[0], 0.0])  # z x (Rz p_v)
    # the errors as linear maps of (phi_D, dv, dp, n_p, n_z)
    n = em.NX + 4
    E_psi = np.zeros(n)
    E_psi[em.X_PHI + 2] = 1.0
    E_psi[em.NX + 3] = 1.0
    E_o = np.zeros((3, n))
    for i in range(3):
        E_o[i, em.X_DP + i] = 1.0
        E_o[i, em.X_DV + i] = -dt
        E_o[i] -= k[i] * E_psi
    E_o[:, em.NX:em.NX + 3] = rz(psi)
    Q = np.zeros((n, n))
    Q[:em.NX, :em.NX] = P0
    Q[em.NX:em.NX + 3, em.NX:em.NX + 3] = np.diag(sig_p ** 2)
    Q[em.NX + 3, em.NX + 3] = sig_a[2] ** 2  # level: the body's z axis is down
    E = np.vstack((E_o, E_psi))
    np.testing.assert_allclose(P[em.X_VP:em.X_VY + 1, em.X_VP:em.X_VY + 1], E @ Q @ E.T, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(P[em.X_VP:em.X_VY + 1, :em.X_VP], (E @ Q)[:, :em.X_VP], rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(P[:em.X_VP, :em.X_VP], P0[:em.X_VP, :em.X_VP])
    np.testing.assert_array_equal(P, P.T)


def test_placing_again_forgets_the_old_frame() -> None:
    """A new reset_counter places the frame again: the rows it writes are those of a first placement, whatever
    the old frame's origin, heading and correlations were."""
    s, bias, c, _ = turned(2e-6)
    rng = np.random.default_rng(2)
    a = rng.normal(size=(em.NX, em.NX)) * 0.1
    P = a @ a.T  # every state correlated with every other, the old frame included
    fresh = P.copy()
    fresh[em.X_VP:, :] = 0.0
    fresh[:, em.X_VP:] = 0.0
    p_v, c_vb = (1.0, -2.0, 0.5), rz(0.3).T @ c
    s2, b2 = s.copy(), bias.copy()
    place(s, bias, P, p_v, c_vb, (0.1,) * 3, (0.02,) * 3)
    place(s2, b2, fresh, p_v, c_vb, (0.1,) * 3, (0.02,) * 3)
    np.testing.assert_array_equal(bias, b2)
    np.testing.assert_allclose(P[em.X_VP:, :], fresh[em.X_VP:, :], rtol=1e-13, atol=1e-16)
    np.testing.assert_array_equal(P, P.T)


@pytest.mark.plain_python_slow  # 3,000 placements: minutes as plain Python (mutation runs use the test above)
def test_the_placed_frames_covariance_matches_a_monte_carlo() -> None:
    """The frame placed from a pose of a true vehicle drawn from P (errors on attitude, velocity and position;
    0.2 m, as good as the camera's 0.1 m, so that the camera's noise is a fifth of the origin's variance; 1.5 m
    from the frame's origin) seen by a camera with noise (0.1 m, 0.02 rad): the neglected second order
    (0.03^2 1.5 m / 2) is 1.5 % of the first; over 3,000 draws the sample covariance of the placed
    origin's and heading's errors with each other and with the heading and position errors equals what
    vision_place put in P, within 4.5 standard errors per element (sample covariance of Gaussians:
    ``sqrt((P_aa P_bb + P_ab^2) / n)``)."""
    rng = np.random.default_rng(11)
    s, bias0, c, _ = turned(2e-6)
    cfg = sd.make_config()
    P0 = np.zeros((em.NX, em.NX))
    for i, sig in enumerate((0.01, 0.01, 0.03, 0.1, 0.1, 0.1, 0.2, 0.2, 0.1)):
        P0[i, i] = sig ** 2
    psi, origin = 0.6, np.array([11.7, 9.9, -30.5])  # 1.5 m from the body
    sig_p, sig_a = np.array([0.1, 0.1, 0.1]), np.array([0.02, 0.02, 0.02])
    n, errs = 3000, []
    P = None
    for _ in range(n):
        x = np.zeros(em.NX)
        x[:9] = rng.normal(0.0, np.sqrt(np.diag(P0)[:9]))
        st, bt = moved(s, bias0, x)  # the truth: the estimate less its error
        lat, lon, h = for_frame(sd.position, sd.GEOGRAPHIC)(st, cfg)  # compiled once, not per call
        r_n, r_e = radii(lat)
        p_true = np.array([(lat - REF[0]) * (r_n + h), (lon - REF[1]) * (r_e + h) * math.cos(lat), REF[2] - h])
        c_true = st[sd.S.C:sd.S.C + 9].reshape(3, 3)
        n_b = rng.normal(0.0, sig_a)
        noisy = c_true @ (np.eye(3) + np.array([[0, -n_b[2], n_b[1]], [n_b[2], 0, -n_b[0]], [-n_b[1], n_b[0], 0]]))
        u, _, vt = np.linalg.svd(noisy)
        p_v = rz(psi).T @ (p_true - origin) + rng.normal(0.0, sig_p)
        sp, bp, P = s.copy(), bias0.copy(), P0.copy()
        place(sp, bp, P, p_v, rz(psi).T @ (u @ vt), sig_p, sig_a)
        errs.append(np.r_[x[em.X_PHI + 2], x[em.X_DP:em.X_DP + 3], bp[kf.B_VP:kf.B_VP + 3] - origin,
                          math.remainder(bp[kf.B_VY] - psi, 2 * math.pi)])
    e = np.array(errs)
    idx = [em.X_PHI + 2, em.X_DP, em.X_DP + 1, em.X_DP + 2, em.X_VP, em.X_VP + 1, em.X_VP + 2, em.X_VY]
    want = P[np.ix_(idx, idx)]
    got = e.T @ e / n
    se = np.sqrt((np.outer(np.diag(want), np.diag(want)) + want ** 2) / n)
    z = np.abs(got - want) / se
    assert z[4:, :].max() < 4.5, np.round(z, 1)
    assert want[7, 7] > P0[2, 2] and want[4, 4] > P0[6, 6]  # placed no better than the solution it is tied to

"""What the mutation runs found unchecked in the filter: mavins/core/errmodel.py and mavins/core/kalman.py (docs/testing.md).

The kernels are called directly, on small matrices or one 22-state model at a time, so that
each test stays well under a second as plain Python (NUMBA_DISABLE_JIT=1). Expected values are
typed here from the textbook equations, never taken from the code under test:

* the SINS error model in NED with the phi-angle attitude error (P. D. Groves, *Principles of
  GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed., 2013, section 14.2.4,
  his F_11 .. F_23 written with the position error in NED metres: dp_N = (R_N + h) dL,
  dp_E = (R_E + h) cos L dlambda, dp_D = -dh), first-order Gauss-Markov biases (-1/tau), the
  second-order transition and trapezoidal Qd (Groves 3.2.3);
* the Kalman update K = P H^T (H P H^T + R)^-1, Joseph's form (I - K H) P (I - K H)^T + K R K^T,
  the Schmidt ("consider") update (D. Simon, *Optimal State Estimation*, 2006, sections 5.1, 7.4),
  with integer Cholesky factors so that the hand-worked numbers are binary-exact;
* the measurement models of docs/filter.md "Measurements" (innovation = predicted minus measured).

The state layout (X_*, B_*, SP_*, S_*) is used only to address elements. WGS-84 and C_b^n are the
typed ones of tests/support.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.jit import for_frame
from support import A, E2, OMEGA, cbn, gamma, quat_zyx

DEG = math.pi / 180.0
CFG = sd.make_config(samples=2)  # WGS-84 Earth
CFG_LAB = sd.make_config(samples=2, earth_model="none")  # laboratory mode
NO_BIAS = np.zeros(kf.B_SIZE)  # the filter's sensor-error estimates, all zero
position = for_frame(sd.position, sd.GEOGRAPHIC)


def radii(lat: float) -> tuple[float, float]:
    """R_N, R_E (m), WGS-84 (docs/conventions.md "Radii")."""
    d = 1.0 - E2 * math.sin(lat) ** 2
    return A * (1.0 - E2) / d**1.5, A / math.sqrt(d)


def skew(v) -> np.ndarray:  # [v x]
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rodrigues(r) -> np.ndarray:
    """exp([r x]) = I + sin(t)/t [r x] + (1 - cos t)/t^2 [r x]^2 (Rodrigues)."""
    t = math.sqrt(float(np.dot(r, r)))
    k = skew(r)
    return np.eye(3) + math.sin(t) / t * k + (1.0 - math.cos(t)) / (t * t) * (k @ k)


def hamilton(p, q) -> np.ndarray:
    p0, pv, q0, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.concatenate([[p0 * q0 - pv @ qv], p0 * qv + q0 * pv + np.cross(pv, qv)])


def cne(lat: float, lon: float) -> np.ndarray:
    """C_n^e of the NED frame at (lat, lon) (Groves 2.4.2 / docs/conventions.md)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])


# ============================================================== errmodel.py: the spec


def test_imu_spec_is_checked_and_made_float() -> None:
    s = em.ImuSpec(gyro_arw=1, gyro_tau=2)  # ints become floats
    assert type(s.gyro_arw) is float and s.gyro_arw == 1.0 and type(s.gyro_tau) is float
    assert type(s.accel_rrw) is float and s.accel_rrw == 0.0
    assert s.gyro_tau == 2.0 and s.accel_tau == 3600.0
    for name in ("gyro_arw", "gyro_bias", "gyro_gm", "gyro_rrw", "accel_vrw", "accel_bias", "accel_gm",
                 "accel_rrw", "gyro_tau", "accel_tau"):
        with pytest.raises(ValueError, match=rf"^{name} must be finite and >= 0, got -1\.0$"):
            em.ImuSpec(**{name: -1.0})
        with pytest.raises(ValueError, match=rf"^{name} must be finite and >= 0, got inf$"):
            em.ImuSpec(**{name: math.inf})
        with pytest.raises(ValueError, match=rf"^{name} must be finite and >= 0, got nan$"):
            em.ImuSpec(**{name: math.nan})
    em.ImuSpec(gyro_arw=0.0, accel_vrw=0.0)  # zero is allowed
    for name in ("gyro_tau", "accel_tau"):
        with pytest.raises(ValueError, match=rf"^{name} must be > 0$"):
            em.ImuSpec(**{name: 0.0})
    assert em.ImuSpec(gyro_tau=1e-9, accel_tau=1e-9).accel_tau == 1e-9


def test_as_array_puts_each_figure_at_its_index() -> None:
    s = em.ImuSpec(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 12.0, 13.0, 14.0, 15.0)
    sp = s.as_array(11.0)
    assert sp.shape == (em.SP_SIZE,) and em.SP_SIZE == 18 and sp[em.SP_WHEEL_SCALE] == 0.0
    assert sp[em.SP_VISION_DRIFT] == sp[em.SP_VISION_YAW_DRIFT] == 0.0
    expect = {em.SP_GYRO_ARW: 1.0, em.SP_GYRO_BIAS: 2.0, em.SP_GYRO_GM: 3.0, em.SP_GYRO_TAU: 4.0,
              em.SP_GYRO_RRW: 5.0, em.SP_ACC_VRW: 6.0, em.SP_ACC_BIAS: 7.0, em.SP_ACC_GM: 8.0,
              em.SP_ACC_TAU: 9.0, em.SP_ACC_RRW: 10.0, em.SP_BARO_DRIFT: 11.0, em.SP_GYRO_SCALE: 12.0,
              em.SP_ACC_SCALE: 13.0, em.SP_GYRO_MIS: 14.0, em.SP_ACC_MIS: 15.0}
    for i, v in expect.items():
        assert sp[i] == v
    assert s.as_array()[em.SP_BARO_DRIFT] == 0.0  # default: no baro drift
    # ImuSpec's defaults: no noise, no bias, tau 3600 s
    np.testing.assert_array_equal(em.ImuSpec().as_array(), [0, 0, 0, 3600.0, 0, 0, 0, 0, 3600.0] + [0] * 9)
    assert s.as_array(3)[em.SP_BARO_DRIFT] == 3.0


def test_spec_from_contract_keys_units() -> None:
    """docs/conventions.md spec keys: deg/sqrt(h), deg/h, m/s/sqrt(h), m/s^2, s -> SI."""
    keys = {"gyro_arw": 0.3, "gyro_bias": 36.0, "gyro_bias_instability": 7.2, "gyro_bias_tau": 120.0,
            "accel_vrw": 0.06, "accel_bias": 0.02, "accel_bias_instability": 0.003, "accel_bias_tau": 240.0,
            "gyro_scale_factor": 500.0}  # not part of the model: ignored
    s = em.spec_from_keys(keys)
    assert s.gyro_arw == pytest.approx(0.3 * math.pi / 180.0 / 60.0, rel=1e-15, abs=0)  # deg/sqrt(h) -> rad/sqrt(s)
    assert s.gyro_bias == pytest.approx(36.0 * math.pi / 180.0 / 3600.0, rel=1e-15, abs=0)  # deg/h -> rad/s
    assert s.gyro_gm == pytest.approx(7.2 * math.pi / 180.0 / 3600.0, rel=1e-15, abs=0)
    assert s.gyro_tau == 120.0 and s.accel_tau == 240.0
    assert s.accel_vrw == pytest.approx(0.001, rel=1e-15, abs=0)  # m/s/sqrt(h) / 60
    assert s.accel_bias == 0.02 and s.accel_gm == 0.003
    assert s.gyro_rrw == 0.0 and s.accel_rrw == 0.0  # not among the contract's keys
    # a missing key is 0; without an instability the bias is constant and tau is ImuSpec's 3600 s
    s = em.spec_from_keys({"gyro_arw": 0.3})
    assert (s.gyro_bias, s.gyro_gm, s.accel_vrw, s.accel_bias, s.accel_gm) == (0.0,) * 5
    assert s.gyro_tau == 3600.0 and s.accel_tau == 3600.0
    s = em.spec_from_keys({"gyro_bias_tau": 50.0, "accel_bias_tau": 60.0})  # a tau without an instability
    assert s.gyro_tau == 3600.0 and s.accel_tau == 3600.0
    for triad in ("gyro", "accel"):
        inst, tau = f"{triad}_bias_instability", f"{triad}_bias_tau"
        for bad in ({inst: 1.0}, {inst: 1.0, tau: 0.0}, {inst: 1.0, tau: -5.0}):
            with pytest.raises(ValueError, match=rf"^{inst} needs {tau} > 0 \(s\)$"):
                em.spec_from_keys(bad)
        assert getattr(em.spec_from_keys({inst: 1.0, tau: 1e-3}), f"{triad}_tau") == 1e-3


def test_spec_to_keys_is_the_inverse() -> None:
    s = em.ImuSpec(gyro_arw=0.3 * DEG / 60.0, gyro_bias=36.0 * DEG / 3600.0, gyro_gm=7.2 * DEG / 3600.0,
                   gyro_tau=120.0, gyro_rrw=1.0, accel_vrw=0.001, accel_bias=0.02, accel_gm=0.003, accel_tau=240.0,
                   gyro_scale=1.5e-3, accel_scale=2.5e-4, gyro_misalignment=DEG / 36.0,
                   accel_misalignment=DEG / 3600.0)
    k = em.spec_to_keys(s)
    expect = {"gyro_arw": 0.3, "gyro_bias": 36.0, "gyro_bias_instability": 7.2, "gyro_bias_tau": 120.0,
              "accel_vrw": 0.06, "accel_bias": 0.02, "accel_bias_instability": 0.003, "accel_bias_tau": 240.0,
              "gyro_scale": 1500.0, "accel_scale": 250.0, "gyro_misalignment": 100.0, "accel_misalignment": 1.0}
    assert list(k) == list(expect) == list(em.SPEC_KEYS)
    for name, v in expect.items():
        assert k[name] == pytest.approx(v, rel=1e-15, abs=0), name


def test_spec_from_grade_tactical() -> None:
    """The tactical grade's datasheet figures (core/grades.py table, HG1700-AG58): gyro ARW 0.125 deg/sqrt(h),
    turn-on 1 deg/h, B 1 deg/h, tau_c 300 s; accelerometer VRW 0.065 ft/s/sqrt(h), turn-on 1 mg, B 50 ug,
    tau_c 300 s. Gauss-Markov sigma B / 0.6173642831 (IEEE Std 952-1997 annex C), rate random walk
    K = B sqrt(3 / (10 tau_c))."""
    s = em.spec_from_grade("tactical")
    b_g, b_a = 1.0 * DEG / 3600.0, 50e-6 * 9.80665
    assert s.gyro_arw == pytest.approx(0.125 * DEG / 60.0, rel=1e-15, abs=0)
    assert s.gyro_bias == pytest.approx(DEG / 3600.0, rel=1e-15, abs=0)
    assert s.gyro_gm == pytest.approx(b_g / 0.6173642831, rel=1e-15, abs=0)
    assert s.gyro_tau == 300.0 and s.accel_tau == 300.0
    assert s.gyro_rrw == pytest.approx(b_g * math.sqrt(3.0 / 3000.0), rel=1e-15, abs=0)
    assert s.accel_vrw == pytest.approx(0.065 * 0.3048 / 60.0, rel=1e-15, abs=0)
    assert s.accel_bias == pytest.approx(1e-3 * 9.80665, rel=1e-15, abs=0)
    assert s.accel_gm == pytest.approx(b_a / 0.6173642831, rel=1e-15, abs=0)
    assert s.accel_rrw == pytest.approx(b_a * math.sqrt(3.0 / 3000.0), rel=1e-15, abs=0)


def test_make_spec_takes_a_grade_a_spec_or_keys() -> None:
    np.testing.assert_array_equal(em.make_spec("tactical"), em.spec_from_grade("tactical").as_array())
    s = em.ImuSpec(gyro_arw=1.0, accel_vrw=2.0)
    np.testing.assert_array_equal(em.make_spec(s, 0.5), s.as_array(0.5))
    sp = em.make_spec({"gyro_arw": 60.0 / DEG}, 0.25)  # 60/DEG deg/sqrt(h) = 1 rad/sqrt(s)
    assert sp[em.SP_GYRO_ARW] == pytest.approx(1.0, rel=1e-15, abs=0) and sp[em.SP_BARO_DRIFT] == 0.25
    assert em.make_spec("tactical")[em.SP_BARO_DRIFT] == 0.0
    assert em.make_spec("tactical", 0.125)[em.SP_BARO_DRIFT] == 0.125


# ============================================================== errmodel.py: linear algebra


def test_matmul_by_hand() -> None:
    a = np.array([[1.0, 0.0, 2.0], [-3.0, 4.0, 0.5]])  # 2x3, with a zero to be skipped
    b = np.array([[2.0, -1.0, 0.0, 1.0], [0.5, 3.0, 1.0, 0.0], [1.0, 0.0, -2.0, 4.0]])  # 3x4
    expect = np.array([[4.0, -1.0, -4.0, 9.0], [-3.5, 15.0, 3.0, -1.0]])
    np.testing.assert_array_equal(em.matmul(a, b), expect)
    bt = np.ascontiguousarray(b.T)  # 4x3: a @ bt.T = a @ b
    np.testing.assert_array_equal(em.matmul_bt(a, bt), expect)


def test_set_block_and_set_skew_write_the_whole_block() -> None:
    """The helpers write all nine elements of their 3x3 block (the zeros of [v x] too) and nothing else."""
    m = np.full((5, 6), np.nan)
    em._set_skew(m, 1, 2, np.array([1.0, 2.0, 3.0]), -2.0)  # -2 [v x]
    np.testing.assert_array_equal(m[1:4, 2:5], [[0.0, 6.0, -4.0], [-6.0, 0.0, 2.0], [4.0, -2.0, 0.0]])
    m[1:4, 2:5] = np.nan
    assert np.all(np.isnan(m))
    em._set_block(m, 2, 3, np.arange(9.0).reshape(3, 3), -0.5)
    np.testing.assert_array_equal(m[2:5, 3:6], -0.5 * np.arange(9.0).reshape(3, 3))
    m[2:5, 3:6] = np.nan
    assert np.all(np.isnan(m))


def test_transition_is_second_order() -> None:
    """Phi = I + F T + (F T)^2 / 2 (Groves 3.2.3): F = [[0, 1], [-4, 0]], T = 0.5: F T = [[0, .5], [-2, 0]],
    (F T)^2 = -I."""
    phi = em.transition(np.array([[0.0, 1.0], [-4.0, 0.0]]), 0.5)
    np.testing.assert_array_equal(phi, [[0.5, 0.5], [-2.0, 0.5]])
    # 3x3, upper triangular (nilpotent): F T = [[0,1,2],[0,0,3],[0,0,0]] with T = 1, (F T)^2 = 3 at (0, 2)
    phi = em.transition(np.array([[1.0, 1.0, 2.0], [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]]) - np.diag([1.0, 0, 0]), 1.0)
    np.testing.assert_array_equal(phi, [[1.0, 1.0, 3.5], [0.0, 1.0, 3.0], [0.0, 0.0, 1.0]])


def test_discretise_density_by_hand() -> None:
    """Qd = (Phi Qc Phi^T + Qc) T / 2 (trapezoidal rule, Groves 3.2.3; docs/filter.md "Model")."""
    F = np.array([[0.0, 1.0], [-4.0, 0.0]])
    q = np.array([2.0, 8.0])
    phi, qd = em.discretise_density(F, q, 0.5)
    np.testing.assert_array_equal(phi, [[0.5, 0.5], [-2.0, 0.5]])
    # Phi diag(q) Phi^T = [[.5*.5*2 + .5*.5*8, .5*-2*2 + .5*.5*8], [., 4*2 + .25*8]] = [[2.5, 0], [0, 10]]
    # (that + Qc) T / 2 = [[4.5, 0], [0, 18]] / 4
    np.testing.assert_array_equal(qd, [[1.125, 0.0], [0.0, 4.5]])
    F = np.array([[0.0, 1.0], [0.0, 0.0]])  # an integrator: Phi = [[1, T], [0, 1]]
    phi, qd = em.discretise_density(F, np.array([0.0, 4.0]), 2.0)
    # Phi Qc Phi^T = [[T^2 q, T q], [T q, q]] = [[16, 8], [8, 4]]; + Qc = [[16, 8], [8, 8]]; * T / 2 = same
    np.testing.assert_array_equal(phi, [[1.0, 2.0], [0.0, 1.0]])
    np.testing.assert_array_equal(qd, [[16.0, 8.0], [8.0, 8.0]])


def test_discretise_density_is_exactly_symmetric() -> None:
    """Qd is symmetric to the last bit (the filter's P stays symmetric): generic numbers, where Phi Qc Phi^T
    computed row by row differs in the last bits between (i, j) and (j, i)."""
    rng = np.random.default_rng(7)
    F = rng.standard_normal((4, 4)) * 0.37
    q = rng.random(4) * 0.9 + 0.1
    phi, qd = em.discretise_density(F, q, 0.13)
    assert np.array_equal(qd, qd.T)
    ft = F * 0.13
    np.testing.assert_allclose(phi, np.eye(4) + ft + ft @ ft / 2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(qd, (phi @ np.diag(q) @ phi.T + np.diag(q)) * 0.065, rtol=0, atol=1e-15)


def test_noise_density() -> None:
    """G Qc G^T diagonal: ARW^2, VRW^2, K^2 (rate random walks), 2 sigma^2 / tau (Gauss-Markov), drift^2."""
    spec = em.ImuSpec(gyro_arw=2.0, gyro_bias=9.0, gyro_gm=3.0, gyro_tau=4.0, gyro_rrw=5.0, accel_vrw=6.0,
                      accel_bias=9.0, accel_gm=7.0, accel_tau=8.0, accel_rrw=0.5).as_array(1.5)
    q = em.noise_density(spec)
    expect = np.zeros(em.NX)
    expect[em.X_PHI : em.X_PHI + 3] = 4.0
    expect[em.X_DV : em.X_DV + 3] = 36.0
    expect[em.X_BG : em.X_BG + 3] = 25.0
    expect[em.X_BA : em.X_BA + 3] = 0.25
    expect[em.X_GG : em.X_GG + 3] = 2.0 * 9.0 / 4.0
    expect[em.X_GA : em.X_GA + 3] = 2.0 * 49.0 / 8.0
    expect[em.X_BARO] = 2.25
    np.testing.assert_array_equal(q, expect)
    # no instability: the Gauss-Markov states are not driven; small figures (below 1) still count
    q = em.noise_density(em.ImuSpec(gyro_tau=4.0, accel_tau=8.0).as_array())
    assert np.all(q == 0.0)
    q = em.noise_density(em.ImuSpec(gyro_gm=0.5, gyro_tau=0.25, accel_gm=0.25, accel_tau=0.5).as_array())
    np.testing.assert_array_equal(q[em.X_GG : em.X_GG + 3], 2.0)
    np.testing.assert_array_equal(q[em.X_GA : em.X_GA + 3], 0.25)


def test_gravity_gradient_is_the_height_derivative_of_normal_gravity() -> None:
    """-d gamma_h/dh of the contract's normal gravity (NIMA TR8350.2 Somigliana with its second-order height
    series, typed in tests/support.py); gamma_h is quadratic in h, so a central difference is exact up to
    round-off (1e-15 g / 2 km ~ 5e-18 /s^2 against ~3e-6 /s^2)."""
    for lat_deg, h in ((0.0, 0.0), (30.0, 1000.0), (60.0, 1.0e5), (-80.0, -300.0)):
        lat = lat_deg * DEG
        d = 1000.0
        expect = -(gamma(lat, h + d) - gamma(lat, h - d)) / (2.0 * d)
        assert em.gravity_gradient(lat, h) == pytest.approx(expect, rel=1e-11, abs=0)
    # at the equator on the ellipsoid: 2 gamma_e (1 + f + m) / a (about 2 g / R)
    assert em.gravity_gradient(0.0, 0.0) == pytest.approx(2 * 9.7803253359 * (1 + 1 / 298.257223563 + 0.00344978650684)
                                                          / 6378137.0, rel=1e-15, abs=0)


# ============================================================== errmodel.py: the system matrix F


def expected_F(c, v, lat, h, f_n, tau_g=None, tau_a=None) -> np.ndarray:
    """Groves 14.2.4 (F_11 .. F_23), NED, with dp in metres (the latitude column / (R_N + h), the height
    column negated for dp_D = -dh); F_p,p from differentiating dp's definitions (errmodel docstring);
    biases -C, Gauss-Markov -1/tau."""
    r_n, r_e = radii(lat)
    rn, re = r_n + h, r_e + h
    vn, ve, vd = v
    s, co, t = math.sin(lat), math.cos(lat), math.tan(lat)
    W = OMEGA
    w_in = np.array([W * co + ve / re, -vn / rn, -W * s - ve * t / re])
    F = np.zeros((em.NX, em.NX))
    P, V, D = 0, 3, 6  # phi, dv, dp blocks
    F[P:P + 3, P:P + 3] = -skew(w_in)  # F_11
    F[P:P + 3, V:V + 3] = [[0, -1 / re, 0], [1 / rn, 0, 0], [0, t / re, 0]]  # F_12
    # F_13 columns dL, dh -> dp_N = dL rn, dp_D = -dh
    f13_L = np.array([W * s, 0.0, W * co + ve / (re * co * co)])
    f13_h = np.array([ve / re**2, -vn / rn**2, -ve * t / re**2])
    F[P:P + 3, D] = f13_L / rn
    F[P:P + 3, D + 2] = -f13_h
    F[V:V + 3, P:P + 3] = -skew(f_n)  # F_21
    F[V:V + 3, V:V + 3] = [  # F_22
        [vd / rn, -2 * ve * t / re - 2 * W * s, vn / rn],
        [ve * t / re + 2 * W * s, (vn * t + vd) / re, ve / re + 2 * W * co],
        [-2 * vn / rn, -2 * ve / re - 2 * W * co, 0.0]]
    f23_L = np.array([-ve * ve / (re * co * co) - 2 * ve * W * co,
                      vn * ve / (re * co * co) + 2 * vn * W * co - 2 * vd * W * s,
                      2 * ve * W * s])
    g_grad = -(gamma(lat, h + 1000.0) - gamma(lat, h - 1000.0)) / 2000.0  # -d gamma/dh, exact (quadratic in h)
    f23_h = np.array([ve * ve * t / re**2 - vn * vd / rn**2,
                      -(vn * ve * t + ve * vd) / re**2,
                      ve * ve / re**2 + vn * vn / rn**2 - g_grad])  # d(dv_D)/dh = d gamma/dh
    F[V:V + 3, D] = f23_L / rn
    F[V:V + 3, D + 2] = -f23_h
    F[D:D + 3, V:V + 3] = np.eye(3)
    F[D, D], F[D, D + 2] = -vd / rn, vn / rn
    F[D + 1, D], F[D + 1, D + 1], F[D + 1, D + 2] = ve * t / rn, -vd / re - vn * t / rn, ve / re
    F[P:P + 3, 9:12] = F[P:P + 3, 15:18] = -c
    F[V:V + 3, 12:15] = F[V:V + 3, 18:21] = -c
    if tau_g:
        F[15:18, 15:18] = -np.eye(3) / tau_g
    if tau_a:
        F[18:21, 18:21] = -np.eye(3) / tau_a
    return F


C_TEST = cbn(10 * DEG, -20 * DEG, 135 * DEG)
F_N = np.array([0.7, -1.3, -9.6])


@pytest.mark.parametrize("lat_deg,h,v", [(52.0, 1200.0, (35.0, -20.0, 4.0)), (-30.0, 300.0, (-12.0, 60.0, -2.5))])
def test_system_matrix_is_grovess_model(lat_deg: float, h: float, v: tuple) -> None:
    """F element by element against Groves's local-navigation-frame model, each element to a few ulps of its
    own size (the same sums in another order)."""
    lat = lat_deg * DEG
    spec = em.ImuSpec(gyro_gm=1e-5, gyro_tau=250.0, accel_gm=1e-3, accel_tau=125.0).as_array()
    F = em.system_matrix(C_TEST, np.array(v), lat, h, F_N, spec, True)
    E = expected_F(C_TEST, v, lat, h, F_N, 250.0, 125.0)
    assert F.shape == (em.NX, em.NX)
    assert np.array_equal(F == 0.0, E == 0.0), np.argwhere((F == 0.0) != (E == 0.0))
    nz = E != 0.0
    rel = np.abs(F[nz] - E[nz]) / np.abs(E[nz])
    worst = np.argwhere(nz)[np.argmax(rel)]
    assert rel.max() < 1e-11, (worst, F[tuple(worst)], E[tuple(worst)])


def test_system_matrix_addresses() -> None:
    """The blocks sit where the state layout says (errmodel docstring): a few elements at hand-typed indices."""
    lat = 52.0 * DEG
    spec = em.ImuSpec(gyro_gm=1e-5, gyro_tau=250.0, accel_gm=1e-3, accel_tau=125.0).as_array()
    F = em.system_matrix(C_TEST, np.array([35.0, -20.0, 4.0]), lat, 1200.0, F_N, spec, True)
    assert F[3, 1] == F_N[2] and F[5, 0] == F_N[1]  # phi x f^n: dv_N from phi_E is f_D, dv_D from phi_N is f_E
    assert F[6, 3] == F[7, 4] == F[8, 5] == 1.0
    assert F[0, 9] == -C_TEST[0, 0] and F[2, 17] == -C_TEST[2, 2] and F[4, 12] == -C_TEST[1, 0]
    assert F[5, 20] == -C_TEST[2, 2]
    assert F[15, 15] == F[17, 17] == -1.0 / 250.0 and F[18, 18] == F[20, 20] == -1.0 / 125.0
    assert np.all(F[21] == 0.0) and np.all(F[:, 21] == 0.0)  # the baro offset: a random walk
    assert np.all(F[9:15] == 0.0)  # the constant biases: random walks


def test_system_matrix_laboratory_mode() -> None:
    """earth_on False (docs/conventions.md laboratory mode): no Earth rate, transport rate or gravity gradient:
    only -[f^n x], the identity dp/dv and the bias blocks remain; without an instability no -1/tau."""
    spec = em.ImuSpec(gyro_tau=250.0, accel_tau=125.0).as_array()
    F = em.system_matrix(C_TEST, np.array([35.0, -20.0, 4.0]), 52.0 * DEG, 1200.0, F_N, spec, False)
    E = np.zeros((em.NX, em.NX))
    E[3:6, 0:3] = -skew(F_N)
    E[6:9, 3:6] = np.eye(3)
    E[0:3, 9:12] = E[0:3, 15:18] = -C_TEST
    E[3:6, 12:15] = E[3:6, 18:21] = -C_TEST
    np.testing.assert_array_equal(F, E)


def test_system_matrix_gauss_markov_below_one() -> None:
    """Each Gauss-Markov part on its own, with small sigmas: -1/tau on its own states only."""
    for gm, tau, rows, other in (("gyro_gm", "gyro_tau", slice(15, 18), slice(18, 21)),
                                 ("accel_gm", "accel_tau", slice(18, 21), slice(15, 18))):
        spec = em.ImuSpec(**{gm: 1e-6, tau: 0.5}).as_array()
        F = em.system_matrix(np.eye(3), np.zeros(3), 0.0, 0.0, np.zeros(3), spec, False)
        np.testing.assert_array_equal(F[rows, rows], -2.0 * np.eye(3))
        assert np.all(F[other, other] == 0.0)


def test_discretise_of_the_system_matrix() -> None:
    """discretise(F, spec, T) is discretise_density with the spec's densities: laboratory F, T = 0.5 s.
    Phi: I + F T + (F T)^2/2; (F T)^2 is nonzero only through dp <- dv <- phi and dv <- ba."""
    spec = em.ImuSpec(gyro_arw=0.5, gyro_tau=250.0, accel_vrw=0.25, accel_tau=125.0).as_array(2.0)
    F = em.system_matrix(np.eye(3), np.zeros(3), 0.0, 0.0, np.array([0.0, 0.0, -8.0]), spec, False)
    phi, qd = em.discretise(F, spec, 0.5)
    ft = F * 0.5
    np.testing.assert_array_equal(phi, np.eye(em.NX) + ft + ft @ ft / 2)
    q = np.zeros(em.NX)
    q[0:3], q[3:6], q[21] = 0.25, 0.0625, 4.0
    np.testing.assert_array_equal(qd, (phi @ np.diag(q) @ phi.T + np.diag(q)) * 0.25)
    assert qd[21, 21] == 2.0 and qd[0, 0] == 0.125


# ============================================================== kalman.py: predict, update


def test_symmetrise() -> None:
    P = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    kf.symmetrise(P)
    np.testing.assert_array_equal(P, [[1.0, 3.0, 5.0], [3.0, 5.0, 7.0], [5.0, 7.0, 9.0]])


def test_predict_by_hand() -> None:
    """P <- Phi P Phi^T + Qd: Phi = [[1, 2], [0, 1]], P = [[4, 1], [1, 3]]: Phi P = [[6, 7], [1, 3]],
    Phi P Phi^T = [[6 + 14, 7], [1 + 6, 3]] = [[20, 7], [7, 3]]; Qd = [[1, .5], [.5, 2]]."""
    P = np.array([[4.0, 1.0], [1.0, 3.0]])
    kf.predict(P, np.array([[1.0, 2.0], [0.0, 1.0]]), np.array([[1.0, 0.5], [0.5, 2.0]]))
    np.testing.assert_array_equal(P, [[21.0, 7.5], [7.5, 5.0]])
    rng = np.random.default_rng(3)
    a = rng.standard_normal((4, 4))
    P = a @ a.T
    phi = np.eye(4) + 0.1 * rng.standard_normal((4, 4))
    kf.predict(P, phi, np.zeros((4, 4)))
    assert np.array_equal(P, P.T)  # symmetrised to the bit


def testspd_inverse_exact() -> None:
    """S = L L^T with L = [[2, 0, 0], [1, 2, 0], [1, 1, 2]]: S = [[4, 2, 2], [2, 5, 3], [2, 3, 6]], det 64,
    S^-1 = adj(S) / 64 = [[21, -6, -4], [-6, 20, -8], [-4, -8, 16]] / 64 (every step binary-exact)."""
    inv, ok = kf.spd_inverse(np.array([[4.0, 2.0, 2.0], [2.0, 5.0, 3.0], [2.0, 3.0, 6.0]]))
    assert ok
    np.testing.assert_array_equal(inv, np.array([[21.0, -6.0, -4.0], [-6.0, 20.0, -8.0], [-4.0, -8.0, 16.0]]) / 64)
    inv, ok = kf.spd_inverse(np.array([[4.0]]))
    assert ok and inv[0, 0] == 0.25


@pytest.mark.parametrize("S", [[[0.0]], [[-1.0]], [[4.0, 2.0], [2.0, 1.0]], [[4.0, 2.0], [2.0, 0.5]],
                               [[4.0, 2.0, 2.0], [2.0, 5.0, 3.0], [2.0, 3.0, 2.0]], [[math.nan]]])
def test_cholesky_refuses_what_is_not_positive_definite(S) -> None:
    """A zero or negative pivot (singular or indefinite S), or NaN: not SPD."""
    inv, ok = kf.spd_inverse(np.array(S))
    assert not ok and np.all(inv == 0.0) and inv.shape == np.array(S).shape


def test_update_one_dimension_by_hand() -> None:
    """n = 2, H = [1, 0], P = [[3, 1], [1, 2]], R = 1: S = 4, K = [3/4, 1/4];
    y = nu - H x = 3 - 0.5 = 2.5, x+ = x + K y = [0.5 + 1.875, -1 + 0.625];
    P+ = P - K S K^T = [[3 - 9/4, 1 - 3/4], [., 2 - 1/4]] (Simon 5.1); nis = y^2 / S; ratio |y| / sqrt(S) / N."""
    x = np.array([0.5, -1.0])
    P = np.array([[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, np.array([[1.0, 0.0]]), np.array([3.0]), np.array([[1.0]]), 5.0, np.ones(2))
    assert ok
    assert nis == 6.25 / 4.0 and ratio == 1.25 / 5.0
    np.testing.assert_array_equal(x, [2.375, -0.375])
    np.testing.assert_array_equal(P, [[0.75, 0.25], [0.25, 1.75]])


def test_update_two_dimensions_by_hand() -> None:
    """n = m = 2, H = I, P = [[3, 2], [2, 4]], R = I: S = [[4, 2], [2, 5]] (L = [[2, 0], [1, 2]]),
    S^-1 = [[5, -2], [-2, 4]] / 16; y = [2, 1]: nis = (20 - 8 + 4) / 16 = 1;
    K = P S^-1 = [[11, 2], [2, 12]] / 16, x = K y = [1.5, 1]; P+ = P - K P = [[11, 2], [2, 12]] / 16 (= K R:
    H = R = I). Normalised components |2| / 2 = 1 and |1| / sqrt(5): the ratio is the first over N."""
    R = np.eye(2)
    for nu, worst in (([2.0, 1.0], 1.0), ([1.0, 2.0], 2.0 / math.sqrt(5.0)), ([-2.0, -1.0], 1.0)):
        x = np.zeros(2)
        P = np.array([[3.0, 2.0], [2.0, 4.0]])
        nis, ratio, ok = kf.update(x, P, np.eye(2), np.array(nu), R, 4.0, np.ones(2))
        assert ok
        S_inv = np.array([[5.0, -2.0], [-2.0, 4.0]]) / 16
        assert nis == pytest.approx(np.array(nu) @ S_inv @ np.array(nu), rel=1e-15, abs=0)
        assert ratio == pytest.approx(worst / 4.0, rel=1e-15, abs=0)
        K = np.array([[11.0, 2.0], [2.0, 12.0]]) / 16
        np.testing.assert_allclose(x, K @ np.array(nu), rtol=0, atol=1e-15)
        np.testing.assert_allclose(P, K, rtol=0, atol=1e-15)
    # a full R adds into S off the diagonal too: P = [[3, 1], [1, 4]], R = [[1, 1], [1, 1]] gives the same S
    x = np.zeros(2)
    P = np.array([[3.0, 1.0], [1.0, 4.0]])
    nis, ratio, ok = kf.update(x, P, np.eye(2), np.array([2.0, 1.0]), np.ones((2, 2)), 4.0, np.ones(2))
    assert ok and nis == 1.0


def test_update_consider_state_uses_joseph() -> None:
    """free = [1, 0] (Schmidt update, Simon 7.4): K = [3/4, 0]; Joseph's form with that gain:
    A = I - K H = [[1/4, 0], [0, 1]], A P A^T = [[3/16, 1/4], [1/4, 2]], K R K^T = [[9/16, 0], [0, 0]]:
    P+ = [[3/4, 1/4], [1/4, 2]] (the short form (I - K H) P would give [[3/4, 1/4], [1, 2]])."""
    x = np.zeros(2)
    P = np.array([[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, np.array([[1.0, 0.0]]), np.array([2.0]), np.array([[1.0]]), 5.0,
                               np.array([1.0, 0.0]))
    assert ok
    np.testing.assert_array_equal(x, [1.5, 0.0])
    np.testing.assert_array_equal(P, [[0.75, 0.25], [0.25, 2.0]])
    # the other way round: only the unmeasured state is corrected, K = [0, 1/4]
    x = np.zeros(2)
    P = np.array([[3.0, 1.0], [1.0, 2.0]])
    kf.update(x, P, np.array([[1.0, 0.0]]), np.array([2.0]), np.array([[1.0]]), 5.0, np.array([0.0, 1.0]))
    # A = [[1, 0], [-1/4, 1]]: A P A^T = [[3, 1/4], [1/4, 2 - 1/2 + 3/16 ... ]] worked out: P+ = A P A^T + K R K^T
    np.testing.assert_array_equal(x, [0.0, 0.5])
    np.testing.assert_array_equal(P, [[3.0, 0.25], [0.25, 2.0 - 0.5 + 3.0 / 16 + 1.0 / 16]])


def test_gate_at_n_sigma() -> None:
    """--gate N: rejected when a normalised component exceeds N (docs/conventions.md); S = 4 (sigma 2),
    N = 3: |y| = 6 is exactly 3 sigma (passes), 6.001 fails, 5.999 passes. A rejection leaves x and P."""
    H, R = np.array([[1.0, 0.0]]), np.array([[1.0]])
    for y, accepted in ((6.0, True), (-6.0, True), (5.999, True), (6.001, False), (-6.001, False)):
        x = np.zeros(2)
        P = np.array([[3.0, 1.0], [1.0, 2.0]])
        nis, ratio, ok = kf.update(x, P, H, np.array([y]), R, 3.0, np.ones(2))
        assert bool(ok) is accepted
        assert ratio == pytest.approx(abs(y) / 2.0 / 3.0, rel=1e-15, abs=0)
        assert nis == pytest.approx(y * y / 4.0, rel=1e-15, abs=0)
        if not accepted:
            assert np.all(x == 0.0) and np.array_equal(P, [[3.0, 1.0], [1.0, 2.0]])
        else:
            assert x[0] == pytest.approx(0.75 * y, rel=1e-15, abs=0)
    # gate 1/2 sigma: 0.999 sigma is rejected; the ratio is over N
    x, P = np.zeros(2), np.array([[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, H, np.array([1.998]), R, 0.5, np.ones(2))
    assert not ok and ratio == pytest.approx(0.999 / 0.5, rel=1e-15, abs=0)
    x, P = np.zeros(2), np.array([[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, H, np.array([0.998]), R, 0.5, np.ones(2))
    assert ok and ratio == pytest.approx(0.499 / 0.5, rel=1e-15, abs=0)
    # gate 0 or below: no gating; the ratio is the largest normalised component itself
    for gate in (0.0, -1.0):
        x, P = np.zeros(2), np.array([[3.0, 1.0], [1.0, 2.0]])
        nis, ratio, ok = kf.update(x, P, H, np.array([100.0]), R, gate, np.ones(2))
        assert ok and ratio == 50.0 and x[0] == 75.0
    # a small innovation: the ratio is not floored
    x, P = np.zeros(2), np.array([[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, H, np.array([0.02]), R, 5.0, np.ones(2))
    assert ratio == pytest.approx(0.002, rel=1e-15, abs=0)


def test_update_refuses_nan_and_a_singular_s() -> None:
    H = np.array([[1.0, 0.0]])
    x, P = np.zeros(2), np.array([[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, H, np.array([math.nan]), np.array([[1.0]]), 5.0, np.ones(2))
    assert not ok and math.isnan(nis) and math.isnan(ratio)
    nis, ratio, ok = kf.update(x, P, H, np.array([math.nan]), np.array([[1.0]]), 0.0, np.ones(2))
    assert not ok  # not finite: refused even without a gate
    assert np.all(x == 0.0) and np.array_equal(P, [[3.0, 1.0], [1.0, 2.0]])
    nis, ratio, ok = kf.update(x, P, H, np.array([1.0]), np.array([[-3.0]]), 5.0, np.ones(2))  # S = 0
    assert not ok and nis == math.inf and ratio == math.inf
    assert np.all(x == 0.0) and np.array_equal(P, [[3.0, 1.0], [1.0, 2.0]])


# ============================================================== kalman.py: feedback

LAT, LON, H0 = 40.0 * DEG, -75.0 * DEG, 250.0
ATT = (5.0 * DEG, -8.0 * DEG, 200.0 * DEG)
V0 = np.array([12.0, -7.0, 1.5])


def state(cfg=CFG) -> np.ndarray:
    s = sd.init_state(3.0, LAT, LON, H0, V0, *ATT)
    if cfg is CFG_LAB:
        s[sd.S.PF : sd.S.PF + 3] = [40.0, -25.0, 6.0]
    s[sd.S.VP : sd.S.VP + 3] = [11.0, -6.0, 1.0]  # the previous update's velocity
    return s


def test_yaw_reset_turns_the_heading_and_puts_position_and_velocity_on_the_fix() -> None:
    """kalman.yaw_reset by 150 deg onto a fix 120 m north and 80 m west (WGS-84 radii at the state's position)
    with velocity (3, -4) m/s: the yaw 200 -> 350 deg with roll and pitch kept (a turn about the vertical),
    the horizontal velocity is the fix's (the vertical and the previous update's vertical kept), the position
    is the fix's and the height kept; the rows and columns of phi_D, dp_N, dp_E, dv_N, dv_E in P are the given
    variances alone, every other entry of P unchanged; the biases untouched."""
    s = state()
    rng = np.random.default_rng(5)
    a = rng.normal(size=(em.NX, em.NX))
    P = a @ a.T
    P0 = P.copy()
    bias = np.arange(kf.B_SIZE, dtype=float)
    d = 1.0 - E2 * math.sin(LAT) ** 2
    r_n, r_e = A * (1.0 - E2) / d ** 1.5 + H0, (A / math.sqrt(d) + H0) * math.cos(LAT)
    lat_fix, lon_fix = LAT + 120.0 / r_n, LON - 80.0 / r_e
    kf.yaw_reset(s, CFG, bias, P, math.radians(150.0), 0.01, lat_fix, lon_fix, 4.0, 3.0, -4.0, 0.09)
    row = np.zeros(sd.OUT_SIZE)
    sd.solution_row(s, CFG, row, sd.GEOGRAPHIC)
    np.testing.assert_allclose(np.degrees(row[7:10]), [5.0, -8.0, -10.0], atol=1e-9)
    np.testing.assert_allclose(row[4:7], [3.0, -4.0, V0[2]], atol=1e-9)
    np.testing.assert_allclose(s[sd.S.VP + 2], 1.0, atol=0)
    assert abs(row[1] - lat_fix) * r_n < 1e-6 and abs(row[2] - lon_fix) * r_e < 1e-6 and abs(row[3] - H0) < 1e-6
    reset = [em.X_PHI + 2, em.X_DP, em.X_DP + 1, em.X_DV, em.X_DV + 1]
    for j, var in zip(reset, (0.01, 4.0, 4.0, 0.09, 0.09)):
        want = np.zeros(em.NX)
        want[j] = var
        np.testing.assert_array_equal(P[j], want)
        np.testing.assert_array_equal(P[:, j], want)
    keep = [i for i in range(em.NX) if i not in reset]
    np.testing.assert_array_equal(P[np.ix_(keep, keep)], P0[np.ix_(keep, keep)])
    np.testing.assert_array_equal(bias, np.arange(kf.B_SIZE, dtype=float))


def test_feedback_corrects_attitude_velocity_position_and_biases() -> None:
    """C <- exp(-[phi x]) C and q <- q(-phi) (x) q (docs/filter.md "Measurements"); v and v_prev -= dv;
    C_n^e <- C_n^e exp([xi x]), xi the transport rotation of (-dp_N, -dp_E) (Groves 5.4.1:
    w_en = [v_E/(R_E+h), -v_N/(R_N+h), -v_E tan L/(R_E+h)]); h += dp_D; bias -= x[X_BG:]; x = 0."""
    s = state()
    x = np.zeros(em.NX)
    phi = np.array([0.01, -0.02, 0.03])
    x[em.X_PHI : em.X_PHI + 3] = phi
    x[em.X_DV : em.X_DV + 3] = [0.5, -0.25, 0.125]
    dp = np.array([30.0, -20.0, 4.0])
    x[em.X_DP : em.X_DP + 3] = dp
    x[em.X_BG:] = np.arange(1.0, em.NX - em.X_BG + 1.0)
    bias = np.full(kf.B_SIZE, 100.0)
    kf.feedback(s, CFG, bias, x)
    assert np.all(x == 0.0)
    c_exp = rodrigues(-phi) @ cbn(*ATT)
    np.testing.assert_allclose(s[sd.S.C : sd.S.C + 9], c_exp.ravel(), rtol=0, atol=1e-15)
    t = np.linalg.norm(phi)
    q_exp = hamilton(np.concatenate([[math.cos(t / 2)], -math.sin(t / 2) * phi / t]), quat_zyx(*ATT))
    q_exp *= np.sign(q_exp @ s[sd.S.Q : sd.S.Q + 4])  # q and -q are the same attitude
    np.testing.assert_allclose(s[sd.S.Q : sd.S.Q + 4], q_exp, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(s[sd.S.V : sd.S.V + 3], [11.5, -6.75, 1.375])
    np.testing.assert_array_equal(s[sd.S.VP : sd.S.VP + 3], [10.5, -5.75, 0.875])
    r_n, r_e = radii(LAT)
    xi = np.array([dp[1] / (r_e + H0), -dp[0] / (r_n + H0), -dp[1] * math.tan(LAT) / (r_e + H0)])
    cne_exp = cne(LAT, LON) @ rodrigues(-xi)  # the transport rotation of -dp: -xi of +dp
    np.testing.assert_allclose(s[sd.S.CNE : sd.S.CNE + 9], cne_exp.ravel(), rtol=0, atol=2e-16)
    assert s[sd.S.H] == H0 + 4.0
    # to first order the point moved by -dp (second order: (dp / R)^2 ~ 3e-11 rad)
    lat, lon, h = position(s, CFG)
    assert lat == pytest.approx(LAT - dp[0] / (r_n + H0), rel=0, abs=3e-11)
    assert lon == pytest.approx(LON - dp[1] / ((r_e + H0) * math.cos(LAT)), rel=0, abs=3e-11)
    lat_c = math.atan2(-cne_exp[2, 2], math.hypot(cne_exp[2, 0], cne_exp[2, 1]))
    assert s[sd.S.LATC] == pytest.approx(lat_c, rel=0, abs=1e-15)  # kept beside C_n^e
    assert s[sd.S.LONC] == pytest.approx(lon, rel=0, abs=1e-15) and s[sd.S.LATC] == lat
    np.testing.assert_array_equal(bias, 100.0 - np.arange(1.0, em.NX - em.X_BG + 1.0))
    assert s[sd.S.T] == 3.0 and np.all(s[sd.S.PF : sd.S.PF + 3] == 0.0)


def test_feedback_laboratory_mode() -> None:
    """earth = none: the flat NED offset moves by -dp, h by +dp_D; the latitude/longitude kept beside it
    are the offset's through the start point's radii."""
    s = state(CFG_LAB)
    s0 = s.copy()
    x = np.zeros(em.NX)
    x[em.X_DP : em.X_DP + 3] = [10.0, -4.0, 2.0]
    x[em.X_BG : em.X_BG + 3] = [1e-3, 2e-3, 3e-3]  # the states after dp: not positions
    x[em.X_BARO] = 0.5
    bias = np.zeros(kf.B_SIZE)
    kf.feedback(s, CFG_LAB, bias, x)
    np.testing.assert_array_equal(s[sd.S.PF : sd.S.PF + 3], [30.0, -21.0, 4.0])
    assert s[sd.S.H] == H0 + 2.0
    # nothing else but the attitude (rewritten from q: round-off) and the lat/lon kept beside the position
    same = np.ones(sd.S_SIZE, bool)
    same[sd.S.PF : sd.S.PF + 3] = same[sd.S.H] = same[sd.S.LATC] = same[sd.S.LONC] = False
    same[sd.S.Q : sd.S.Q + 4] = same[sd.S.C : sd.S.C + 9] = False
    np.testing.assert_array_equal(s[same], s0[same])
    np.testing.assert_array_equal(bias[0:3], [-1e-3, -2e-3, -3e-3])
    r_n, r_e = radii(LAT)
    assert s[sd.S.LATC] == pytest.approx(LAT + 30.0 / (r_n + H0), rel=0, abs=1e-16)
    assert s[sd.S.LONC] == pytest.approx(LON - 21.0 / ((r_e + H0) * math.cos(LAT)), rel=0, abs=1e-16)
    assert bias[kf.B_BARO] == -0.5 and np.all(bias[3:12] == 0.0)
    np.testing.assert_allclose(s[sd.S.C : sd.S.C + 9], cbn(*ATT).ravel(), rtol=0, atol=1e-15)


def test_feedback_renormalises_the_quaternion() -> None:
    """q is unit after feedback (it is renormalised), with C its DCM, even from a quaternion 2^-20 off unit."""
    s = state()
    s[sd.S.Q : sd.S.Q + 4] *= 1.0 + 2.0**-20
    x = np.zeros(em.NX)
    x[em.X_PHI + 2] = 0.001
    kf.feedback(s, CFG, np.zeros(kf.B_SIZE), x)
    q = s[sd.S.Q : sd.S.Q + 4]
    assert abs(q @ q - 1.0) < 4.5e-16
    q_exp = hamilton([math.cos(0.0005), 0.0, 0.0, -math.sin(0.0005)], quat_zyx(*ATT))
    q_exp *= np.sign(q_exp @ q)  # q and -q are the same attitude
    np.testing.assert_allclose(q, q_exp, rtol=0, atol=1e-15)
    np.testing.assert_allclose(s[sd.S.C : sd.S.C + 9], (rodrigues(np.array([0, 0, -0.001])) @ cbn(*ATT)).ravel(),
                               rtol=0, atol=1e-15)


def test_apply_update_feeds_back_only_what_is_accepted() -> None:
    """A ZUPT on the 22 states with P diagonal: v moves by P/(P + R) of itself (Simon 5.1 with H = [0 I 0]);
    a rejected one changes nothing."""
    s = state()
    P = np.diag(np.full(em.NX, 1.0))
    P[3:6, 3:6] = np.eye(3) * 3.0
    nu, H, R = kf.zupt(s, 1.0)
    bias = np.zeros(kf.B_SIZE)
    nis, ratio, ok = kf.apply_update(s, CFG, bias, P, H, nu, R, 0.0, kf.ALL)
    assert ok
    np.testing.assert_allclose(s[sd.S.V : sd.S.V + 3], V0 / 4.0, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(np.diag(P)[3:6], 0.75)
    assert nis == pytest.approx(V0 @ V0 / 4.0, rel=1e-15, abs=0) and ratio == pytest.approx(6.0, rel=1e-15, abs=0)
    s0, P0 = s.copy(), P.copy()
    nis, ratio, ok = kf.apply_update(s, CFG, bias, P, H, s[sd.S.V : sd.S.V + 3] * 100.0, R, 5.0, kf.ALL)
    assert not ok
    np.testing.assert_array_equal(s, s0)
    np.testing.assert_array_equal(P, P0)


# ============================================================== kalman.py: measurement models


def test_metres_per_radian() -> None:
    """(R_N + h, (R_E + h) cos L) at the solution's point; in laboratory mode at the start point."""
    r_n, r_e = radii(LAT)
    mn, me = kf.metres_per_radian(state(), CFG)
    assert mn == pytest.approx(r_n + H0, rel=1e-15, abs=0)
    assert me == pytest.approx((r_e + H0) * math.cos(LAT), rel=1e-14, abs=0)
    # the solution 0.1 rad north of its start and 600 m higher: its own point, not the start's
    s = state()
    s[sd.S.CNE : sd.S.CNE + 9] = cne(LAT + 0.1, LON).ravel()
    s[sd.S.H] = H0 + 600.0
    for_frame(sd.sync_position, sd.GEOGRAPHIC)(s, CFG)
    r_n2, r_e2 = radii(LAT + 0.1)
    mn, me = kf.metres_per_radian(s, CFG)
    assert mn == pytest.approx(r_n2 + H0 + 600.0, rel=1e-15, abs=0)
    assert me == pytest.approx((r_e2 + H0 + 600.0) * math.cos(LAT + 0.1), rel=1e-14, abs=0)
    s = state(CFG_LAB)
    s[sd.S.H] = 9000.0  # not used in laboratory mode
    mn, me = kf.metres_per_radian(s, CFG_LAB)
    assert mn == pytest.approx(r_n + H0, rel=1e-15, abs=0)
    assert me == pytest.approx((r_e + H0) * math.cos(LAT), rel=1e-15, abs=0)


def test_gnss_position_with_lever_arm_and_latency() -> None:
    """nu = (p + C l - v dt) - p_m in NED metres, H = [-[(C l) x], -dt I, I] (docs/filter.md; C(est) l - C l =
    phi x (C l)); R = diag(sh^2, sh^2, sv^2). The fix: 100 m north, 50 m west and 3 m above the solution."""
    s = state()
    r_n, r_e = radii(LAT)
    mn, me = r_n + H0, (r_e + H0) * math.cos(LAT)
    lever = np.array([0.5, -0.25, -1.0])
    dt = 0.02
    lat_m, lon_m, h_m = LAT + 100.0 / mn, LON - 50.0 / me, H0 + 3.0
    nu, H, R = kf.gnss_position(s, CFG, lat_m, lon_m, h_m, lever, dt, 1.5, 4.0)
    la = cbn(*ATT) @ lever
    expect = np.array([-100.0, 50.0, 3.0]) + la - V0 * dt
    np.testing.assert_allclose(nu, expect, rtol=0, atol=2e-8)  # lat/lon through C_n^e: 1e-16 rad ~ 1e-9 m
    He = np.zeros((3, em.NX))
    He[:, 0:3] = -skew(la)
    He[:, 3:6] = -dt * np.eye(3)
    He[:, 6:9] = np.eye(3)
    np.testing.assert_allclose(H, He, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(R, np.diag([2.25, 2.25, 16.0]))


def test_gnss_position_across_the_date_line() -> None:
    """The longitude difference is wrapped: a fix 0.00002 deg east across +-180 deg is 0.00002 deg east."""
    s = sd.init_state(0.0, LAT, 179.99999 * DEG, H0, np.zeros(3), 0.0, 0.0, 0.0)
    nu, _, _ = kf.gnss_position(s, CFG, LAT, -179.99999 * DEG, H0, np.zeros(3), 0.0, 1.0, 1.0)
    r_n, r_e = radii(LAT)
    assert nu[1] == pytest.approx(-0.00002 * DEG * (r_e + H0) * math.cos(LAT), rel=1e-6, abs=0)
    assert abs(nu[0]) < 1e-8 and nu[2] == 0.0


def test_gnss_velocity_with_lever_arm_and_latency() -> None:
    """nu = v(t_m) + C (w x l) - v_m, v(t_m) = v - (dt/T)(v - v_prev); H = [-[(C (w x l)) x], I, 0, C [l x], 0,
    C [l x]] (docs/filter.md; a gyro bias error db lowers the rate by db: C (l x db))."""
    s = state()
    lever = np.array([0.5, -0.25, -1.0])
    w = np.array([0.1, -0.2, 0.3])
    v_m = np.array([10.0, -5.0, 2.0])
    c = cbn(*ATT)
    cwl = c @ np.cross(w, lever)
    nu, H, R = kf.gnss_velocity(s, v_m, w, lever, 0.005, 0.02, 0.2)
    v_prev = np.array([11.0, -6.0, 1.0])
    v_tm = V0 - 0.25 * (V0 - v_prev)
    np.testing.assert_allclose(nu, v_tm + cwl - v_m, rtol=0, atol=4e-15)
    He = np.zeros((3, em.NX))
    He[:, 0:3] = -skew(cwl)
    He[:, 3:6] = np.eye(3)
    He[:, 9:12] = He[:, 15:18] = c @ skew(lever)
    np.testing.assert_allclose(H, He, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(R, np.diag([0.04000000000000001] * 3))
    # T = 0 (no interval yet): v(t_m) = v
    nu, _, _ = kf.gnss_velocity(s, v_m, w, lever, 0.005, 0.0, 0.2)
    np.testing.assert_allclose(nu, V0 + cwl - v_m, rtol=0, atol=4e-15)


def test_baro_height_with_offset_and_latency() -> None:
    """nu = h + v_D dt + offset - h_m; H: -1 on dp_D, dt on dv_D, 1 on the offset (docs/filter.md)."""
    s = state()
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_BARO] = 7.0
    nu, H, R = kf.baro_height(s, bias, 240.0, 0.5, 0.75)
    assert nu.shape == (1,) and nu[0] == 250.0 + 1.5 * 0.5 + 7.0 - 240.0
    He = np.zeros((1, em.NX))
    He[0, 8], He[0, 5], He[0, 21] = -1.0, 0.5, 1.0
    np.testing.assert_array_equal(H, He)
    np.testing.assert_array_equal(R, [[0.5625]])


def test_heading() -> None:
    """nu = wrap(yaw - yaw_m); d yaw = phi_D + tan(pitch)(phi_N cos yaw + phi_E sin yaw) (derivative of
    atan2(C_21, C_11) under C(est) = (I + [phi x]) C)."""
    s = state()
    roll, pitch, yaw = ATT
    nu, H, R = kf.heading(s, 195.0 * DEG, 0.1)
    assert nu.shape == (1,) and H.shape == (1, em.NX) and R.shape == (1, 1)
    assert nu[0] == pytest.approx(5.0 * DEG, rel=1e-13, abs=0)
    He = np.zeros((1, em.NX))
    He[0, 0:3] = [math.tan(pitch) * math.cos(yaw), math.tan(pitch) * math.sin(yaw), 1.0]
    np.testing.assert_allclose(H, He, rtol=0, atol=1e-15)
    np.testing.assert_allclose(R, [[0.01]], rtol=1e-15, atol=0)
    nu, _, _ = kf.heading(s, -150.0 * DEG, 0.1)  # 200 deg is -160 deg: 10 deg short of -150
    assert nu[0] == pytest.approx(-10.0 * DEG, rel=1e-13, abs=0)


def mag_nu(s: np.ndarray, cfg: np.ndarray, m_b: np.ndarray, w: np.ndarray, dt: float, dec: float) -> np.ndarray:
    """The magnetometer innovation of sample m_b, dt old, body rate w (kalman.mag_level then mag_heading)."""
    return kf.mag_heading(s, kf.mag_level(s, cfg, NO_BIAS, m_b, w, dt), dec, 1.0, 1.0, 0.02)[0]


def test_mag_level_and_inclination() -> None:
    """A current sample (dt = 0) levelled with the state's attitude is the field in NED: ``C m_b``; tan I is its
    down part over its horizontal part."""
    s = state()
    inc, dec = 60.0 * DEG, 10.0 * DEG
    m_n = 48.0 * np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    m = kf.mag_level(s, CFG, NO_BIAS, cbn(*ATT).T @ m_n, np.array([0.1, 0.2, 0.3]), 0.0)
    np.testing.assert_allclose(m, m_n, rtol=0, atol=1e-12)
    assert kf.mag_tan_inclination(m) == pytest.approx(math.tan(inc), rel=1e-12)
    assert kf.mag_tan_inclination(np.array([-3.0, 4.0, -10.0])) == pytest.approx(-2.0, rel=1e-15)


def test_mag_inclination_is_the_mean_of_the_accepted_samples() -> None:
    """Before any accepted sample the model's tan I and horizontal strength are the sample's own;
    mag_accept adds each accepted one to [sum tan I, count, sum |m_h|], and the model's figures are then
    their means, whatever the sample at hand."""
    incl = np.zeros(kf.MAG_STATS)
    a, b, c = np.array([3.0, 4.0, 10.0]), np.array([0.0, 2.0, 1.0]), np.array([1.0, 0.0, 7.0])
    assert kf.mag_inclination(incl, a) == pytest.approx(2.0, rel=1e-15)
    assert kf.mag_horizontal(incl, a) == pytest.approx(5.0, rel=1e-15)
    kf.mag_accept(incl, a)
    np.testing.assert_allclose(incl[:3], [2.0, 1.0, 5.0], rtol=1e-15)
    assert kf.mag_inclination(incl, b) == pytest.approx(2.0, rel=1e-15)
    assert kf.mag_horizontal(incl, b) == pytest.approx(5.0, rel=1e-15)
    kf.mag_accept(incl, b)
    np.testing.assert_allclose(incl[:3], [2.5, 2.0, 7.0], rtol=1e-15)
    assert kf.mag_inclination(incl, c) == pytest.approx(1.25, rel=1e-15)
    assert kf.mag_horizontal(incl, c) == pytest.approx(3.5, rel=1e-15)


def test_mag_heading_with_declination() -> None:
    """The levelled field's angle east of north minus the declination D; H_phi = [-tan I cos D, -tan I sin D, 1]
    (docs/filter.md, the derivative of atan2(m_E, m_N) under m(est) = m + phi x m) at the field the model
    predicts: D and the tan I passed in, not the sample's. Here the sample's horizontal part lies 0.05 rad east
    of D (its noise, or a heading error) and its own tan I is tan 60 deg; H follows D and the tan I given."""
    inc, dec = 60.0 * DEG, 10.0 * DEG
    m_n = 48.0 * np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    s = state()
    nu, H, R = kf.mag_heading(s, m_n, dec - 0.05, 1.7, 24.0, 0.02)
    assert nu[0] == pytest.approx(0.05, rel=1e-12, abs=0)
    He = np.zeros((1, em.NX))
    He[0, 0:3] = [-1.7 * math.cos(dec - 0.05), -1.7 * math.sin(dec - 0.05), 1.0]
    np.testing.assert_allclose(H[:, : em.X_MB], He[:, : em.X_MB], rtol=0, atol=1e-15)
    np.testing.assert_allclose(R, [[0.0004]], rtol=1e-15, atol=0)
    # wrapped: a declination of 10 deg against a field seen at 10 deg - 2 pi + 0.1
    nu, _, _ = kf.mag_heading(s, m_n, dec + 2 * math.pi - 0.1, 1.7, 24.0, 0.02)
    assert nu[0] == pytest.approx(0.1, rel=1e-12, abs=0)


def test_mag_heading_noise_does_not_move_the_tilt_on_average() -> None:
    """N = 4000 samples of the true field plus white noise (0.3 uT per axis on 48 uT at I = 63 deg, D = 2 deg:
    the simulator's field), each an update of the same zero error state (1-sigma 0.05 deg tilt, 0.1 deg
    heading, biases 1e-2): the corrections are zero-mean (noise in, noise out), so each state's mean
    correction lies within 4.5 standard errors of zero (all 22 states: 1e-4 overall). A Jacobian built along
    the noisy sample rectifies the noise across the field into a one-signed east-tilt correction,
    ``tan(I) sigma^2 / B_h^2`` times the gain: about 20 standard errors here."""
    s = state()
    inc, dec = 63.0 * DEG, 2.0 * DEG
    m_n = 48.0 * np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    c_nb = cbn(*ATT).T
    sigma = 0.3 / (48.0 * math.cos(inc))
    P0 = np.diag(np.r_[np.array([0.05, 0.05, 0.1]) * DEG, np.full(em.NX - 3, 1e-2)] ** 2)
    rng = np.random.default_rng(7)
    n = 4000
    dx = np.empty((n, em.NX))
    for k in range(n):
        m_b = c_nb @ m_n + 0.3 * rng.standard_normal(3)
        nu, H, R = kf.mag_heading(s, kf.mag_level(s, CFG, NO_BIAS, m_b, np.zeros(3), 0.0), dec, math.tan(inc),
                                  48.0 * math.cos(inc), sigma)
        x = np.zeros(em.NX)
        kf.update(x, P0.copy(), H, nu, R, 0.0, kf.ALL)
        dx[k] = x
    se = dx.std(axis=0, ddof=1) / math.sqrt(n)
    z = np.divide(dx.mean(axis=0), se, out=np.zeros(em.NX), where=se > 0)
    assert np.all(np.abs(z) < 4.5), z
    assert np.all(dx[:, 3:9] == 0.0) and np.all(dx[:, 12:15] == 0.0)  # uncorrelated with the heading: no gain


def test_mag_heading_carries_a_late_sample_to_the_solution_time() -> None:
    """A sample dt old while the body turns at w (body axes): truth ``C_b^n(t_k) = C`` and
    ``C_b^n(t_k - dt) = C exp(-[w dt x])``, so the sample is ``exp([w dt x]) C^T m^n``. Carried by
    ``-dt (w x m_b)``, the innovation is at most the first-order carry's error ``|w dt|^2 |m| / 2`` over
    the horizontal field; uncarried it is of the order of ``|w dt|`` (0.7 deg here). Each rate component
    matters (the attitude is tilted)."""
    s = state()
    inc, dec = 60.0 * DEG, 10.0 * DEG
    m_n = 48.0 * np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    c = cbn(*ATT)
    dt = 0.02
    bound_of = lambda w: 0.5 * (np.linalg.norm(w) * dt) ** 2 / math.cos(inc)  # noqa: E731
    for w in (np.array([0.15, -0.25, 0.35]), np.array([0.4, 0.0, 0.0]), np.array([0.0, -0.4, 0.0]),
              np.array([0.0, 0.0, 0.4])):
        m_b = rodrigues(w * dt) @ c.T @ m_n
        nu = mag_nu(s, CFG_LAB, m_b, w, dt, dec)
        assert abs(nu[0]) < bound_of(w), w
        nu_0 = mag_nu(s, CFG_LAB, m_b, w, 0.0, dec)
        assert abs(nu_0[0]) > 20.0 * bound_of(w), w
    nu = mag_nu(s, CFG_LAB, c.T @ m_n, np.array([0.15, -0.25, 0.35]), 0.0, dec)
    assert abs(nu[0]) < 1e-12


def test_mag_heading_carries_with_the_rate_against_the_navigation_frame() -> None:
    """The navigation frame turns with the Earth and, moving, with the transport rate: a body fixed in it has
    w_ib = C^T (w_ie + w_en) and sees the field unchanged, so a sample dt old needs no carry: with the WGS-84
    Earth (rates typed here: Omega [cos L, 0, -sin L], w_en = [v_E/(R_E+h), -v_N/(R_N+h), -v_E tan L/(R_E+h)])
    the innovation is zero; carried by w_ib itself (laboratory mode, where the frame does not turn) it is off by
    about |w_in| dt (1e-6 rad in 20 ms here)."""
    s = state()
    inc, dec = 60.0 * DEG, 10.0 * DEG
    m_n = 48.0 * np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    c = cbn(*ATT)
    r_n, r_e = radii(LAT)
    vn, ve, _ = V0
    w_in = OMEGA * np.array([math.cos(LAT), 0.0, -math.sin(LAT)]) + np.array(
        [ve / (r_e + H0), -vn / (r_n + H0), -ve * math.tan(LAT) / (r_e + H0)])
    w_ib = c.T @ w_in
    m_b = c.T @ m_n
    nu = mag_nu(s, CFG, m_b, w_ib, 0.02, dec)
    assert abs(nu[0]) < 1e-12
    nu_lab = mag_nu(s, CFG_LAB, m_b, w_ib, 0.02, dec)
    assert abs(nu_lab[0]) > 0.1 * np.linalg.norm(w_in) * 0.02


def test_zupt() -> None:
    s = state()
    nu, H, R = kf.zupt(s, 0.02)
    np.testing.assert_array_equal(nu, V0)
    He = np.zeros((3, em.NX))
    He[:, 3:6] = np.eye(3)
    np.testing.assert_array_equal(H, He)
    np.testing.assert_array_equal(R, np.eye(3) * 0.0004)


def test_zaru() -> None:
    """z = w_raw - C^T w_ie^n; nu = b(est) - z; H = I on both gyro-bias parts and C^T [w_ie x] on phi
    (docs/filter.md: C(true) = (I - [phi x]) C gives w_raw = b + C^T w_ie - C^T [w_ie x] phi);
    w_ie^n = Omega [cos L, 0, -sin L]. Laboratory mode: no Earth rate."""
    s = state()
    c = cbn(*ATT)
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_BG : kf.B_BG + 3] = [1e-3, -2e-3, 3e-3]
    bias[kf.B_GG : kf.B_GG + 3] = [4e-4, 5e-4, -6e-4]
    w_raw = np.array([2e-3, 1e-3, -4e-3])
    w_ie = OMEGA * np.array([math.cos(LAT), 0.0, -math.sin(LAT)])
    nu, H, R = kf.zaru(s, CFG, bias, w_raw, 1e-4)
    b = np.array([1.4e-3, -1.5e-3, 2.4e-3])
    np.testing.assert_allclose(nu, b - (w_raw - c.T @ w_ie), rtol=0, atol=4e-18)
    He = np.zeros((3, em.NX))
    He[:, 0:3] = c.T @ skew(w_ie)
    He[:, 9:12] = He[:, 15:18] = np.eye(3)
    np.testing.assert_allclose(H, He, rtol=0, atol=1e-19)
    np.testing.assert_allclose(R, np.eye(3) * 1e-8, rtol=1e-15, atol=0)
    s = state(CFG_LAB)
    nu, H, R = kf.zaru(s, CFG_LAB, bias, w_raw, 1e-4)
    np.testing.assert_allclose(nu, b - w_raw, rtol=0, atol=4e-18)
    assert np.all(H[:, 0:3] == 0.0)


def test_initial_covariance() -> None:
    """Diagonal: position, velocity, level, yaw, the spec's bias sigmas, baro offset (kalman docstring)."""
    spec = em.ImuSpec(gyro_bias=2.0, gyro_gm=3.0, gyro_tau=1.0, accel_bias=5.0, accel_gm=7.0, accel_tau=1.0).as_array()
    P = kf.initial_covariance(spec, 10.0, 0.5, 0.25, 4.0, 6.0, 0.0)
    d = np.array([0.0625, 0.0625, 16.0] + [0.25] * 3 + [100.0] * 3 + [4.0] * 3 + [25.0] * 3 + [9.0] * 3 + [49.0] * 3
                 + [36.0] + [0.0] * 26)
    np.testing.assert_array_equal(P, np.diag(d))
    # the scale factors and misalignments take the spec's 1-sigma, the hard iron the sigma passed in
    spec = em.ImuSpec(gyro_scale=2e-3, accel_scale=3e-3, gyro_misalignment=4e-3, accel_misalignment=5e-3).as_array()
    P = kf.initial_covariance(spec, 10.0, 0.5, 0.25, 4.0, 6.0, 0.5)
    np.testing.assert_allclose(np.diag(P)[22:], [4e-6] * 3 + [9e-6] * 3 + [16e-6] * 6 + [25e-6] * 6 + [0.25] * 3
                               + [0.0] * 5, rtol=1e-15)  # the odometer, and a camera frame until it is placed
    # the wheel odometer's scale factor takes the spec's SP_WHEEL_SCALE
    spec = em.make_spec(em.ImuSpec(), wheel_scale=0.02)
    assert kf.initial_covariance(spec, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0)[em.X_WS, em.X_WS] == pytest.approx(4e-4,
                                                                                                       rel=1e-15)
    np.testing.assert_array_equal(P, np.diag(np.diag(P)))


def test_module_level_layout() -> None:
    """The constants mutmut does not mutate (module level), pinned by value: the state layout of docs/filter.md
    "State", the process-model vector of errmodel's docstring, and the bias vector of kalman's docstring."""
    assert (em.X_PHI, em.X_DV, em.X_DP, em.X_BG, em.X_BA, em.X_GG, em.X_GA, em.X_BARO) == (0, 3, 6, 9, 12, 15, 18, 21)
    assert (em.X_SG, em.X_SA, em.X_MG, em.X_MA, em.X_MB, em.X_WS, em.X_VP, em.X_VY) == (22, 25, 28, 34, 40, 43, 44, 47)
    assert em.NX == 48 and em.N_CONTRACT == 15
    assert (em.SP_GYRO_ARW, em.SP_GYRO_BIAS, em.SP_GYRO_GM, em.SP_GYRO_TAU, em.SP_GYRO_RRW, em.SP_ACC_VRW,
            em.SP_ACC_BIAS, em.SP_ACC_GM, em.SP_ACC_TAU, em.SP_ACC_RRW, em.SP_BARO_DRIFT, em.SP_GYRO_SCALE,
            em.SP_ACC_SCALE, em.SP_GYRO_MIS, em.SP_ACC_MIS, em.SP_WHEEL_SCALE, em.SP_VISION_DRIFT,
            em.SP_VISION_YAW_DRIFT, em.SP_SIZE) == tuple(range(19))
    assert (kf.B_BG, kf.B_BA, kf.B_GG, kf.B_GA, kf.B_BARO, kf.B_SG, kf.B_SA, kf.B_MG, kf.B_MA, kf.B_MB, kf.B_WS,
            kf.B_VP, kf.B_VY, kf.B_SIZE) == (0, 3, 6, 9, 12, 13, 16, 19, 25, 31, 34, 35, 38, 39)
    assert em.OFF_DIAGONAL == ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
    np.testing.assert_array_equal(kf.ALL, np.ones(em.NX))
    np.testing.assert_array_equal(kf.ALL_BUT_HEADING, np.r_[1.0, 1.0, 0.0, np.ones(em.NX - 3)])  # phi_D held back


def test_the_state_is_declared_once() -> None:
    """errmodel.STATE is the one declaration: its blocks in the order and sizes of docs/filter.md "State",
    each X_<NAME> its running offset, NX their sum, the sensor errors (kept as estimates by the feedback)
    the blocks from the gyro bias on, and kalman's bias vector those blocks at the same places."""
    assert [(b.name, b.size) for b in em.STATE] == [("PHI", 3), ("DV", 3), ("DP", 3), ("BG", 3), ("BA", 3),
                                                    ("GG", 3), ("GA", 3), ("BARO", 1), ("SG", 3), ("SA", 3),
                                                    ("MG", 6), ("MA", 6), ("MB", 3), ("WS", 1), ("VP", 3),
                                                    ("VY", 1)]
    assert [b.name for b in em.STATE if b.sensor] == ["BG", "BA", "GG", "GA", "BARO", "SG", "SA", "MG", "MA", "MB",
                                                      "WS", "VP", "VY"]
    assert em.X_SENSORS == 9 and kf.B_SIZE == em.NX - em.X_SENSORS
    for b in em.STATE:
        assert getattr(em, f"X_{b.name}") == em.OFFSET[b.name]
        if b.sensor:
            assert getattr(kf, f"B_{b.name}") == em.OFFSET[b.name] - em.X_SENSORS


def test_calibrated_gyro_bias_sets_the_estimate_and_an_uncorrelated_variance() -> None:
    """A zero-rate calibration: the constant gyro bias takes the measured value, its rows and columns of P are
    cleared and the diagonal set to the given variance; the rest of P (and the Gauss-Markov part) stays; a
    variance of 0 leaves P as it was."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(em.NX, em.NX))
    P = a @ a.T
    P0 = P.copy()
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_GG:kf.B_GG + 3] = (1e-5, 2e-5, 3e-5)
    kf.calibrated_gyro_bias(P, bias, np.array([1e-4, -2e-4, 3e-4]), 4e-10)
    g = slice(em.X_BG, em.X_BG + 3)
    np.testing.assert_array_equal(bias[kf.B_BG:kf.B_BG + 3], [1e-4, -2e-4, 3e-4])
    np.testing.assert_array_equal(kf.gyro_bias_total(bias), np.array([1e-4, -2e-4, 3e-4]) + [1e-5, 2e-5, 3e-5])
    np.testing.assert_array_equal(P[g, g], 4e-10 * np.eye(3))
    others = np.r_[0:em.X_BG, em.X_BG + 3:em.NX]
    assert not P[g][:, others].any() and not P[others][:, g].any()
    np.testing.assert_array_equal(P[np.ix_(others, others)], P0[np.ix_(others, others)])
    P1 = P0.copy()
    kf.calibrated_gyro_bias(P1, bias, np.zeros(3), 0.0)
    np.testing.assert_array_equal(P1, P0)


def test_bias_totals_add_the_constant_and_gauss_markov_parts() -> None:
    bias = np.arange(1.0, kf.B_SIZE + 1.0)
    np.testing.assert_array_equal(kf.gyro_bias_total(bias), bias[kf.B_BG:kf.B_BG + 3] + bias[kf.B_GG:kf.B_GG + 3])
    np.testing.assert_array_equal(kf.accel_bias_total(bias), bias[kf.B_BA:kf.B_BA + 3] + bias[kf.B_GA:kf.B_GA + 3])
    assert kf.B_BG != kf.B_GG and kf.B_BA != kf.B_GA


def test_wheel_speed_by_hand() -> None:
    """Level, heading east (body x = north-east-down (0, 1, 0)), v = (0, 10, 0) m/s now and (0, 9.8, 0) at the
    update before; a speed measured 0.01 s back over a 0.02 s interval sees v = (0, 9.9, 0); the axle centre at
    l = (-1, 0.5, 0.3) m with a yaw rate of 0.2 rad/s adds (w x l)_x = -w_z l_y = -0.1 m/s: u = 9.8 m/s, and
    with a 2 % scale factor the odometer should read 9.996 m/s; it reads 10. H: 1.02 c_0 on dv, nothing on
    phi (c_0 x v = 0 along the track), (l x db)_x on both gyro-bias parts (-1.02 l_z on y, 1.02 l_y on z), u
    on the scale factor."""
    s = sd.init_state(0.0, 0.8, 0.1, 100.0, np.array([0.0, 10.0, 0.0]), 0.0, 0.0, math.pi / 2)
    s[sd.S.VP:sd.S.VP + 3] = [0.0, 9.8, 0.0]
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_WS] = 0.02
    nu, H, R = kf.wheel_speed(s, bias, 10.0, np.array([0.0, 0.0, 0.2]), np.array([-1.0, 0.5, 0.3]), 0.01, 0.02,
                              0.05)
    assert nu.shape == (1,) and nu[0] == pytest.approx(1.02 * 9.8 - 10.0, abs=1e-12)
    want = np.zeros(em.NX)
    want[em.X_DV + 1] = 1.02
    want[em.X_BG + 1] = want[em.X_GG + 1] = -1.02 * 0.3
    want[em.X_BG + 2] = want[em.X_GG + 2] = 1.02 * 0.5
    want[em.X_WS] = 9.8
    np.testing.assert_allclose(H[0], want, rtol=1e-12, atol=1e-12)
    assert R.shape == (1, 1) and R[0, 0] == pytest.approx(0.0025, rel=1e-15)
    nu0, _, _ = kf.wheel_speed(s, bias, 10.0, np.array([0.0, 0.0, 0.2]), np.array([-1.0, 0.5, 0.3]), 0.01, 0.0,
                               0.05)  # no interval yet: the current velocity
    assert nu0[0] == pytest.approx(1.02 * 9.9 - 10.0, abs=1e-12)


def body_state() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A state turned every way (roll 15, pitch -10, yaw 120 deg) moving (8, -3, 0.5) m/s, with the velocity
    of the update before (7.6, -2.8, 0.3): the state, C_b^n (support.cbn, not the kernel's), v and v_prev."""
    att = [math.radians(x) for x in (15.0, -10.0, 120.0)]
    v, v_prev = np.array([8.0, -3.0, 0.5]), np.array([7.6, -2.8, 0.3])
    s = sd.init_state(0.0, 0.8, 0.1, 100.0, v, *att)
    s[sd.S.VP:sd.S.VP + 3] = v_prev
    return s, cbn(*att), v, v_prev


def test_body_velocity_and_the_constraint_rows_by_hand() -> None:
    """Predicted C^T v less the measurement, H = [C^T [v x] on phi, C^T on dv] row by row, R the sigmas
    squared; the constraint is rows y and z with 0 measured and one sigma."""
    s, c, v, _ = body_state()
    v_m, sig = np.array([7.0, 1.0, -2.0]), np.array([0.1, 0.2, 0.3])
    nu, H, R = kf.body_velocity(s, v_m, sig)
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    np.testing.assert_allclose(nu, c.T @ v - v_m, rtol=0, atol=1e-13)
    np.testing.assert_allclose(H[:, em.X_DV:em.X_DV + 3], c.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(H[:, em.X_PHI:em.X_PHI + 3], c.T @ vx, rtol=0, atol=1e-13)
    assert not H[:, 6:].any()
    np.testing.assert_allclose(R, np.diag(sig ** 2), rtol=1e-15)
    nu2, H2, R2 = kf.nhc(s, 0.25)
    np.testing.assert_allclose(nu2, (c.T @ v)[1:], rtol=0, atol=1e-13)
    np.testing.assert_array_equal(H2, H[1:])
    np.testing.assert_allclose(R2, np.diag([0.0625, 0.0625]), rtol=1e-15)


def test_wheel_speed_on_a_turned_state_by_hand() -> None:
    """Every axis in play: v taken back 0.005 s of a 0.02 s interval (a quarter of the change), the rate
    (0.1, -0.2, 0.3) rad/s at the lever (-1, 0.5, 0.3) m, a 3 % scale factor: the prediction, and H on dv,
    phi (body x's row of the body velocity's, times 1.03), both gyro biases and the scale factor."""
    s, c, v, v_prev = body_state()
    w, lever = np.array([0.1, -0.2, 0.3]), np.array([-1.0, 0.5, 0.3])
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_WS] = 0.03
    nu, H, R = kf.wheel_speed(s, bias, 6.0, w, lever, 0.005, 0.02, 0.05)
    assert nu.shape == (1,) and H.shape == (1, em.NX) and R.shape == (1, 1)
    v_t = v - 0.25 * (v - v_prev)
    u = (c.T @ v_t)[0] + np.cross(w, lever)[0]
    assert nu[0] == pytest.approx(1.03 * u - 6.0, abs=1e-12)
    vx = np.array([[0.0, -v_t[2], v_t[1]], [v_t[2], 0.0, -v_t[0]], [-v_t[1], v_t[0], 0.0]])
    np.testing.assert_allclose(H[0, em.X_DV:em.X_DV + 3], 1.03 * c.T[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(H[0, em.X_PHI:em.X_PHI + 3], 1.03 * (c.T @ vx)[0], rtol=0, atol=1e-13)
    lx = np.array([[0.0, -lever[2], lever[1]], [lever[2], 0.0, -lever[0]], [-lever[1], lever[0], 0.0]])
    np.testing.assert_allclose(H[0, em.X_BG:em.X_BG + 3], 1.03 * lx[0], rtol=0, atol=1e-15)  # (l x db)_x
    np.testing.assert_array_equal(H[0, em.X_BG:em.X_BG + 3], H[0, em.X_GG:em.X_GG + 3])
    assert H[0, em.X_WS] == pytest.approx(u, abs=1e-13)


@pytest.mark.parametrize("name", ["wheel_scale", "vision_drift", "vision_yaw_drift"])
@pytest.mark.parametrize("value", [-1e-3, math.inf, math.nan])
def test_make_spec_refuses_a_negative_or_non_finite_figure_by_name(name: str, value: float) -> None:
    with pytest.raises(ValueError, match=rf"^{name} must be finite and >= 0, got {value!r}$"):
        em.make_spec("consumer", **{name: value})
    sp = em.make_spec("consumer", **{name: 0.25})
    slot = {"wheel_scale": em.SP_WHEEL_SCALE, "vision_drift": em.SP_VISION_DRIFT,
            "vision_yaw_drift": em.SP_VISION_YAW_DRIFT}[name]
    assert sp[slot] == 0.25 and np.count_nonzero(sp[em.SP_WHEEL_SCALE:]) == 1


def test_the_camera_frames_walks_drive_its_states_alone() -> None:
    """noise_density: the camera frame's origin takes its walk squared on each axis (m^2/s), its heading its own
    (rad^2/s); nothing else changes."""
    base = em.noise_density(em.make_spec("consumer"))
    q = em.noise_density(em.make_spec("consumer", vision_drift=0.3, vision_yaw_drift=0.02))
    want = base.copy()
    want[em.X_VP:em.X_VP + 3] = 0.09
    want[em.X_VY] = 0.0004
    np.testing.assert_allclose(q, want, rtol=1e-15, atol=0)

"""The filter's sensor errors beyond the biases: the IMU's scale factors and the magnetometer's hard iron
(mavins/core/errmodel.py, kalman.py, aided.py), and the magnetic disturbance check.

Expected values come from the sensor model itself, ``measured = (1 + s) true + b`` (Titterton & Weston,
2nd ed., ch. 12), closed forms (a constant turn) and numerical derivatives of the measurement.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import aided
from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.rotation import euler_to_dcm

DEG = math.pi / 180.0
CFG_LAB = sd.make_config(samples=1, earth_model="none")


def test_the_corrections_invert_the_sensor_model() -> None:
    """A reading ``(1 + s) w + b`` (rate, or increment ``(1 + s) w dt + b dt``) corrected with the estimates
    s and b = constant + Gauss-Markov part gives back w, per axis."""
    bias = np.zeros(kf.B_SIZE)
    bias[kf.B_BG:kf.B_BG + 3] = [1e-3, -2e-3, 3e-3]
    bias[kf.B_GG:kf.B_GG + 3] = [4e-4, 5e-4, -6e-4]
    bias[kf.B_SG:kf.B_SG + 3] = [2e-3, -3e-3, 5e-4]
    bias[kf.B_BA:kf.B_BA + 3] = [0.02, -0.01, 0.05]
    bias[kf.B_GA:kf.B_GA + 3] = [0.003, 0.004, -0.002]
    bias[kf.B_SA:kf.B_SA + 3] = [-1e-2, 4e-3, 7e-3]
    w, f, dt = np.array([0.3, -0.7, 1.1]), np.array([0.4, -2.0, -9.7]), 0.004
    for a in range(3):
        bg = bias[kf.B_BG + a] + bias[kf.B_GG + a]
        ba = bias[kf.B_BA + a] + bias[kf.B_GA + a]
        raw_w = (1.0 + bias[kf.B_SG + a]) * w[a] + bg
        raw_f = (1.0 + bias[kf.B_SA + a]) * f[a] + ba
        assert kf.correct_gyro(bias, a, raw_w, 1.0) == pytest.approx(w[a], rel=1e-14)
        assert kf.correct_accel(bias, a, raw_f, 1.0) == pytest.approx(f[a], rel=1e-14)
        assert kf.correct_gyro(bias, a, raw_w * dt, dt) == pytest.approx(w[a] * dt, rel=1e-13)
        assert kf.correct_accel(bias, a, raw_f * dt, dt) == pytest.approx(f[a] * dt, rel=1e-13)


def test_scale_factor_columns_are_the_bias_columns_times_the_motion() -> None:
    """``d phi/dt = -C diag(w_b) sg`` and ``d dv/dt = -C diag(f_b) sa`` (module docstring of errmodel), written
    only for the scale factors the spec estimates."""
    c = euler_to_dcm(10.0 * DEG, -20.0 * DEG, 130.0 * DEG)
    w, f = np.array([0.1, -0.2, 0.3]), np.array([1.0, 0.5, -9.5])
    F = np.zeros((em.NX, em.NX))
    em.motion_columns(F, c, w, f, em.ImuSpec(gyro_scale=1e-3, accel_scale=1e-3).as_array())
    np.testing.assert_allclose(F[em.X_PHI:em.X_PHI + 3, em.X_SG:em.X_SG + 3], -c * w[None, :], rtol=1e-15, atol=0)
    np.testing.assert_allclose(F[em.X_DV:em.X_DV + 3, em.X_SA:em.X_SA + 3], -c * f[None, :], rtol=1e-15, atol=0)
    F[em.X_PHI:em.X_PHI + 3, em.X_SG:em.X_SG + 3] = 0.0
    F[em.X_DV:em.X_DV + 3, em.X_SA:em.X_SA + 3] = 0.0
    assert not F.any()
    for spec in (em.ImuSpec(accel_scale=1e-3), em.ImuSpec(gyro_scale=1e-3)):
        F = np.zeros((em.NX, em.NX))
        em.motion_columns(F, c, w, f, spec.as_array())
        assert F[:, em.X_SG:em.X_SG + 3].any() == (spec.gyro_scale > 0.0)
        assert F[:, em.X_SA:em.X_SA + 3].any() == (spec.accel_scale > 0.0)


def test_an_unestimated_gyro_scale_error_turns_the_heading_as_the_model_says() -> None:
    """A level turn at w about down for T with a z gyro reading ``(1 + s) w``: the solution turns by
    ``(1 + s) w T``, so its heading error is ``s w T`` (closed form); the filter's propagation over the same
    turn, from a scale-factor variance s^2 alone, gives phi_D the variance ``(w_m T s)^2`` and the covariance
    ``-w_m T s^2`` with sg (the z column of C is down throughout the turn, so the first-order model is exact
    there; w_m the measured rate)."""
    w, s_true, rate = 0.5, 0.01, 100.0
    spec = em.ImuSpec(gyro_scale=1e-2).as_array()

    def turn(scale: float) -> tuple[float, np.ndarray]:
        st = sd.init_state(0.0, 0.0, 0.0, 0.0, np.zeros(3), 0.0, 0.0, 0.0)
        P = np.zeros((em.NX, em.NX))
        P[em.X_SG + 2, em.X_SG + 2] = s_true ** 2
        bias, acc, sums = np.zeros(kf.B_SIZE), np.zeros(aided.ACC_SIZE), np.zeros(7)
        for k in range(1, 101):
            aided.push_rate_aided(st, CFG_LAB, spec, P, bias, acc, sums, k / rate, 0.0, 0.0, (1.0 + scale) * w,
                                  0.0, 0.0, -9.80665, 1, sd.GEOGRAPHIC)
        c = st[sd.S.C:sd.S.C + 9].reshape(3, 3)
        return math.atan2(c[1, 0], c[0, 0]), P

    turned, _ = turn(0.0)  # w times the time the solution integrated
    assert turned == pytest.approx(w * 0.99, rel=0.02)
    yaw, P = turn(s_true)
    assert yaw - turned == pytest.approx(s_true * turned, rel=1e-9)
    # the covariance of phi_D after the turn is (w_m T)^2 var(sg), the model's column integrated with the
    # rate the solution measured (corrected by the estimate 0): w_m = (1 + s) w
    wt = (1.0 + s_true) * turned
    assert math.sqrt(P[em.X_PHI + 2, em.X_PHI + 2]) == pytest.approx(wt * s_true, rel=1e-9)
    assert P[em.X_PHI + 2, em.X_SG + 2] == pytest.approx(-wt * s_true ** 2, rel=1e-9)


def _mag_innovation(s: np.ndarray, m_b: np.ndarray, bias: np.ndarray, dec: float, tan_i: float,
                    horiz: float) -> tuple[float, np.ndarray]:
    m = kf.mag_level(s, CFG_LAB, bias, m_b, np.zeros(3), 0.0)
    nu, H, _ = kf.mag_heading(s, m, dec, tan_i, horiz, 0.01)
    return float(nu[0]), H[0]


def test_the_hard_iron_column_is_the_derivative_of_the_heading() -> None:
    """``H_mb = -g^T C`` (kalman.mag_heading): with the hard-iron estimate b moved by +-eps on each axis the
    innovation moves by H_mb eps (central difference, error O(eps^2 / B_h^2) ~ 1e-9 relative); and a
    sample carrying hard iron h, corrected by an estimate of h, gives the innovation of a clean sample."""
    s = sd.init_state(0.0, 0.0, 0.0, 0.0, np.zeros(3), 7.0 * DEG, -4.0 * DEG, 200.0 * DEG)
    c = s[sd.S.C:sd.S.C + 9].reshape(3, 3)
    inc, dec = 60.0 * DEG, 10.0 * DEG
    m_n = 48.0 * np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)])
    horiz = 48.0 * math.cos(inc)
    m_b = c.T @ m_n
    _, H = _mag_innovation(s, m_b, np.zeros(kf.B_SIZE), dec, math.tan(inc), horiz)
    eps = 1e-3
    for j in range(3):
        b = np.zeros(kf.B_SIZE)
        b[kf.B_MB + j] = eps
        up, _ = _mag_innovation(s, m_b, b, dec, math.tan(inc), horiz)
        b[kf.B_MB + j] = -eps
        down, _ = _mag_innovation(s, m_b, b, dec, math.tan(inc), horiz)
        assert H[em.X_MB + j] == pytest.approx((up - down) / (2 * eps), rel=1e-6, abs=1e-12), j
    assert np.linalg.norm(H[em.X_MB:em.X_MB + 3]) == pytest.approx(1.0 / horiz, rel=1e-12)  # |g| = 1 / B_h
    h = np.array([5.0, -3.0, 2.0])
    b = np.zeros(kf.B_SIZE)
    b[kf.B_MB:kf.B_MB + 3] = h
    nu, _ = _mag_innovation(s, m_b + h, b, dec, math.tan(inc), horiz)
    assert abs(nu) < 1e-14


def test_a_sample_off_the_models_inclination_or_strength_is_disturbed() -> None:
    """Inclination ``atan2(m_D, |m_h|)`` more than the gate off the model's, or strength more than its gate
    off: disturbed; a NaN model figure is not checked."""
    m = np.array([0.3, 0.0, 0.3 * math.tan(60.0 * DEG)])  # 60 deg, 0.6 gauss
    gi, gs = 20.0 * DEG, 0.2
    assert not kf.mag_disturbed(m, 60.0 * DEG, 0.6, gi, gs)
    assert not kf.mag_disturbed(m, 79.0 * DEG, 0.79, gi, gs)
    assert kf.mag_disturbed(m, 81.0 * DEG, 0.6, gi, gs)
    assert kf.mag_disturbed(m, 39.0 * DEG, 0.6, gi, gs)
    assert kf.mag_disturbed(m, 60.0 * DEG, 0.81, gi, gs)
    assert not kf.mag_disturbed(m, math.nan, math.nan, gi, gs)
    assert kf.mag_disturbed(m, math.nan, 0.3, gi, gs)
    assert kf.mag_disturbed(m, 10.0 * DEG, math.nan, gi, gs)


def test_apply_mag_leaves_the_filter_alone_on_a_disturbed_sample() -> None:
    """aided.apply_mag: a sample 30 deg off the model's inclination returns -1 and changes neither the
    solution, P, the estimates nor the running statistics; a good one is applied (1) and counted into them."""
    s = sd.init_state(0.0, 0.8, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.5)
    c = s[sd.S.C:sd.S.C + 9].reshape(3, 3)
    inc, dec = 60.0 * DEG, 0.05
    m_n = np.array([math.cos(inc) * math.cos(dec), math.cos(inc) * math.sin(dec), math.sin(inc)]) * 0.5
    P = np.eye(em.NX) * 1e-4
    bias, incl = np.zeros(kf.B_SIZE), np.zeros(kf.MAG_STATS)
    before = (s.copy(), P.copy())
    status, nis, _ = aided.apply_mag(s, CFG_LAB, bias, P, incl, c.T @ m_n, np.zeros(3), 0.0, dec, 0.02,
                                     inc + 30.0 * DEG, math.nan, math.nan, 5.0, kf.ALL)
    assert status == -1 and math.isnan(nis)
    np.testing.assert_array_equal(s, before[0])
    np.testing.assert_array_equal(P, before[1])
    assert not bias.any() and not incl.any()
    status, nis, _ = aided.apply_mag(s, CFG_LAB, bias, P, incl, c.T @ m_n, np.zeros(3), 0.0, dec, 0.02,
                                     inc, 0.5, 0.2, 5.0, kf.ALL)
    assert status == 1 and nis >= 0.0 and incl[1] == 1.0
    assert incl[2] == pytest.approx(0.5 * math.cos(inc), rel=1e-12)


def test_file_columns_follow_the_estimated_states() -> None:
    """A solution file has the contract's 35 columns, then six per estimated block: sg with a gyro scale
    sigma, sa with an accelerometer one, mb with a hard-iron sigma; in file units ppm for the scale factors."""
    none = aided.file_columns(em.ImuSpec().as_array(), 0.0)
    assert [aided.ROW_COLUMNS[i] for i in none] == list(aided.OUT_COLUMNS)
    both = aided.file_columns(em.ImuSpec(gyro_scale=1e-3, accel_scale=1e-3).as_array(), 0.1)
    names = [aided.ROW_COLUMNS[i] for i in both]
    assert names[35:] == ["sg_x", "sg_y", "sg_z", "sigma_sg_x", "sigma_sg_y", "sigma_sg_z",
                          "sa_x", "sa_y", "sa_z", "sigma_sa_x", "sigma_sa_y", "sigma_sa_z",
                          "mb_x", "mb_y", "mb_z", "sigma_mb_x", "sigma_mb_y", "sigma_mb_z"]
    mb = aided.file_columns(em.ImuSpec().as_array(), 0.1)
    assert [aided.ROW_COLUMNS[i] for i in mb][35:] == names[47:]
    f = aided.unit_factors(names)
    assert list(f[35:47]) == [1e6] * 12 and list(f[47:]) == [1.0] * 6
    # misalignments: twelve per triad after the scale factors, in arcsec (the spec keys' unit)
    mis = aided.file_columns(em.ImuSpec(accel_scale=1e-3, gyro_misalignment=1e-3, accel_misalignment=1e-3).as_array(),
                             0.0)
    names = [aided.ROW_COLUMNS[i] for i in mis]
    pairs = ["xy", "xz", "yx", "yz", "zx", "zy"]
    assert names[35:] == ["sa_x", "sa_y", "sa_z", "sigma_sa_x", "sigma_sa_y", "sigma_sa_z"] + [
        f"{p}{b}_{a}" for b in ("mg", "ma") for p in ("", "sigma_") for a in pairs]
    f = aided.unit_factors(names)
    assert list(f[35:41]) == [1e6] * 6
    np.testing.assert_allclose(f[41:], 648000.0 / math.pi, rtol=1e-15)  # rad -> arcsec
    only_ma = aided.file_columns(em.ImuSpec(accel_misalignment=1e-3).as_array(), 0.0)
    assert [aided.ROW_COLUMNS[i] for i in only_ma][35:] == names[53:]



def _mag_setup(inc_deg: float = 60.0, strength: float = 0.5, off_deg: float = 0.0):
    """A level solution at yaw 0.5 rad (laboratory frame), P with the heading, the tilt and an uneven hard-iron
    variance (1-sigma 0.01, 0.05, 0.02 per axis, correlated with the heading), and a sample of the field of
    inclination ``inc_deg`` and ``strength``, ``off_deg`` east of D = 0.05 rad."""
    s = sd.init_state(0.0, 0.8, 0.1, 100.0, np.zeros(3), 0.0, 0.0, 0.5)
    c = s[sd.S.C:sd.S.C + 9].reshape(3, 3)
    inc, az = math.radians(inc_deg), 0.05 + math.radians(off_deg)
    m_n = strength * np.array([math.cos(inc) * math.cos(az), math.cos(inc) * math.sin(az), math.sin(inc)])
    P = np.diag([1e-6, 1e-6, 1e-3] + [1e-4] * (em.NX - 3))
    for i, sig in enumerate((0.01, 0.05, 0.02)):
        P[em.X_MB + i, em.X_MB + i] = sig * sig
    P[em.X_PHI + 2, em.X_MB + 1] = P[em.X_MB + 1, em.X_PHI + 2] = 1e-4
    return s, P, np.zeros(kf.B_SIZE), np.zeros(kf.MAG_STATS), c.T @ m_n


def test_apply_mag_takes_the_models_field_where_it_is_known() -> None:
    """The heading update's Jacobian uses the model's tan I and horizontal strength F cos I where both are
    given; the model's tan I and the samples' horizontal strength with the inclination only; the samples'
    own figures (here the first sample's) without a model: each equal, bit for bit, to kalman.mag_heading
    with those figures and one kalman.apply_update."""
    dec, sig = 0.05, 0.02
    inc_m, f_m = math.radians(66.0), 0.45  # the model's, not the sample's (60 deg, 0.5)
    h_sample = 0.5 * math.cos(math.radians(60.0))
    for incl_model, strength_model, tan_i, horiz in ((inc_m, f_m, math.tan(inc_m), f_m * math.cos(inc_m)),
                                                     (inc_m, math.nan, math.tan(inc_m), h_sample),
                                                     (math.nan, math.nan, math.tan(math.radians(60.0)), h_sample)):
        s, P, bias, incl, m_b = _mag_setup(off_deg=1.0)
        s2, P2, b2 = s.copy(), P.copy(), bias.copy()
        m = kf.mag_level(s2, CFG_LAB, b2, m_b, np.zeros(3), 0.0)
        nu, H, R = kf.mag_heading(s2, m, dec, tan_i, horiz, sig)
        kf.apply_update(s2, CFG_LAB, b2, P2, H, nu, R, 5.0, kf.ALL)
        status, _, _ = aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, np.zeros(3), 0.0, dec, sig, incl_model,
                                       strength_model, math.nan, 5.0, kf.ALL)
        assert status == 1
        np.testing.assert_allclose(P, P2, rtol=1e-12, atol=1e-18)
        np.testing.assert_allclose(bias, b2, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("what,delta,disturbed", [
    ("strength", -0.01, False), ("strength", 0.01, True),
    ("inclination", -1.0, False), ("inclination", 1.0, True),
])
def test_the_disturbance_checks_allow_for_the_unlearnt_hard_iron(what: str, delta: float, disturbed: bool) -> None:
    """With the hard iron's largest 1-sigma 0.05 (of 0.01, 0.05, 0.02), the strength check is 0.2 + 0.15 and
    the inclination check 20 deg + atan(0.15 / F) (F = 0.5: 16.7 deg): just inside passes, just outside is
    disturbed (-1, nothing changed)."""
    widen = 3.0 * 0.05
    if what == "strength":
        s, P, bias, incl, m_b = _mag_setup(strength=0.5 + 0.2 + widen + delta)
    else:
        s, P, bias, incl, m_b = _mag_setup(inc_deg=60.0 - (20.0 + math.degrees(math.atan(widen / 0.5)) + delta))
    P0 = P.copy()
    status, _, _ = aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, np.zeros(3), 0.0, 0.05, 10.0,
                                   math.radians(60.0), 0.5, 0.2, 1e9, kf.ALL)
    assert (status == -1) is disturbed
    if disturbed:
        np.testing.assert_array_equal(P, P0)
    # without a strength check (its gate NaN) the strength is not looked at
    if what == "strength":
        s, P, bias, incl, m_b = _mag_setup(strength=3.0)
        status, _, _ = aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, np.zeros(3), 0.0, 0.05, 10.0,
                                       math.radians(60.0), 0.5, math.nan, 1e9, kf.ALL)
        assert status == 1


def test_persistent_rejections_reset_the_hard_iron() -> None:
    """A sample 17 deg off with a 0.6 deg sigma and a tight hard iron fails the gate: MAG_RESET_AFTER - 1
    rejections change nothing but the count; the next resets the hard iron's rows and columns of P to its
    initial variance ``incl[4]`` (status 2) and the count; an accepted sample clears the count; with no
    initial variance (not estimated) there is never a reset."""
    s, P, bias, incl, m_b = _mag_setup(off_deg=17.0)
    for i in range(3):
        P[em.X_MB + i, em.X_MB + i] = 1e-8
    P[em.X_PHI + 2, em.X_MB + 1] = P[em.X_MB + 1, em.X_PHI + 2] = 1e-7
    incl[4] = 0.04
    P0 = P.copy()
    args = (np.zeros(3), 0.0, 0.05, 0.01, math.nan, math.nan, math.nan, 5.0, kf.ALL)
    for k in range(aided.MAG_RESET_AFTER - 1):
        assert aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, *args)[0] == 0
        assert incl[3] == k + 1
    np.testing.assert_array_equal(P, P0)
    assert aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, *args)[0] == 2 and incl[3] == 0.0
    want = P0.copy()
    want[em.X_MB:em.X_MB + 3, :] = 0.0
    want[:, em.X_MB:em.X_MB + 3] = 0.0
    for i in range(3):
        want[em.X_MB + i, em.X_MB + i] = 0.04
    np.testing.assert_array_equal(P, want)
    # an accepted sample clears the count: the hard iron (now 0.2 sigma) explains the 17 deg
    incl[3] = 7.0
    assert aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, *args)[0] == 1 and incl[3] == 0.0
    s, P, bias, incl, m_b = _mag_setup(off_deg=17.0)
    for i in range(3):
        P[em.X_MB + i, em.X_MB + i] = 1e-8
    P0 = P.copy()
    for _ in range(aided.MAG_RESET_AFTER + 3):
        assert aided.apply_mag(s, CFG_LAB, bias, P, incl, m_b, *args)[0] == 0
    np.testing.assert_array_equal(P, P0)


def test_the_disturbance_checks_are_strict_and_use_the_whole_horizontal_field() -> None:
    """Exactly at a gate is not disturbed (binary-exact values: |m| = 1.25 against 1 with a 0.25 gate; an
    inclination of exactly 45 deg against 0 with a 45 deg gate); the horizontal part is the root of both
    horizontal components (a field along east, or split between north and east, is no different)."""
    m = np.array([0.0, 0.75, 1.0])
    assert not kf.mag_disturbed(m, math.nan, 1.0, 1.0, 0.25)
    assert kf.mag_disturbed(m, math.nan, 1.0, 1.0, 0.25 - 1e-12)
    m = np.array([0.0, 1.0, 1.0])
    assert not kf.mag_disturbed(m, 0.0, math.nan, math.atan2(1.0, 1.0), 1.0)
    assert kf.mag_disturbed(m, 0.0, math.nan, math.atan2(1.0, 1.0) - 1e-12, 1.0)
    for m in (np.array([0.3, 0.4, 0.5 * math.tan(math.radians(60.0))]), np.array([0.4, 0.3, 0.5 * math.tan(1.047)])):
        assert not kf.mag_disturbed(m, math.radians(60.0), 1.0, math.radians(1.0), 0.1)  # |m_h| = 0.5, |m| = 1
        assert kf.mag_disturbed(m, math.radians(58.0), 1.0, math.radians(1.0), 0.1)
        assert kf.mag_disturbed(m, math.radians(60.0), 1.15, math.radians(1.0), 0.1)


def test_the_scale_factors_are_estimated_only_when_asked() -> None:
    """errmodel.spec_of: a grade's scale factors (consumer 10000/3 and 10000 ppm) and a spec's ``gyro_scale``/
    ``accel_scale`` keys (ppm) reach the filter only with ``scale_factors`` (``--scale-factors``); one key
    suffices, none is refused with one line; an ImuSpec is taken as it is."""
    assert (em.spec_of("consumer").gyro_scale, em.spec_of("consumer").accel_scale) == (0.0, 0.0)
    on = em.spec_of("consumer", True)
    assert on.gyro_scale == pytest.approx(1e-2 / 3.0, rel=1e-12) and on.accel_scale == pytest.approx(1e-2, rel=1e-12)
    keys = {"gyro_arw": 0.1, "gyro_scale": 100.0, "accel_scale": 250.0}
    off = em.spec_of(keys)
    assert (off.gyro_scale, off.accel_scale) == (0.0, 0.0) and off.gyro_arw > 0.0
    on = em.spec_of(keys, True)
    assert (on.gyro_scale, on.accel_scale) == pytest.approx((1e-4, 2.5e-4), rel=1e-12)
    assert em.spec_of({"gyro_scale": 100.0}, True).gyro_scale == pytest.approx(1e-4, rel=1e-12)
    assert em.spec_of({"accel_scale": 100.0}, True).accel_scale == pytest.approx(1e-4, rel=1e-12)
    with pytest.raises(ValueError, match=r"^--scale-factors with an IMU spec needs gyro_scale and/or accel_scale"):
        em.spec_of({"gyro_arw": 0.1}, True)
    spec = em.ImuSpec(gyro_scale=1e-3)
    assert em.spec_of(spec) is spec and em.spec_of(spec, True) is spec
    sp = em.make_spec("industrial", scale_factors=True)
    assert sp[em.SP_GYRO_SCALE] == pytest.approx(1e-3, rel=1e-12) and sp[em.SP_ACC_SCALE] == pytest.approx(1e-3)


# --- misalignment ------------------------------------------------------------------------------------------------
def _mat(m6) -> np.ndarray:
    """The 3 x 3 misalignment (zero diagonal) of the elements m_xy m_xz m_yx m_yz m_zx m_zy."""
    m = np.zeros((3, 3))
    m[[0, 0, 1, 1, 2, 2], [1, 2, 0, 2, 0, 1]] = m6
    return m


def test_the_misalignment_correction_is_the_first_order_inverse() -> None:
    """A reading ``(I + S)(I + M) w + b`` (the simulator's sensor model, sim/errors.py) corrected with the
    estimates S, M, b gives ``(I - M^2) w``: per axis ``u = (x - b) / (1 + s) = (I + M) w`` exactly, then
    ``u - M u = (I - M)(I + M) w``; the residual is second order in M. Rates and increments alike."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        bias = rng.normal(0.0, 1e-3, kf.B_SIZE)
        w, f, dt = rng.normal(0.0, 1.0, 3), rng.normal(0.0, 5.0, 3), 0.004
        for corr, b0, s0, m0, x in ((kf.correct_gyro3, (kf.B_BG, kf.B_GG), kf.B_SG, kf.B_MG, w),
                                    (kf.correct_accel3, (kf.B_BA, kf.B_GA), kf.B_SA, kf.B_MA, f)):
            b = bias[b0[0]:b0[0] + 3] + bias[b0[1]:b0[1] + 3]
            S, M = np.diag(bias[s0:s0 + 3]), _mat(bias[m0:m0 + 6])
            raw = (np.eye(3) + S) @ (np.eye(3) + M) @ x + b
            want = (np.eye(3) - M @ M) @ x
            np.testing.assert_allclose(corr(bias, *raw, 1.0), want, rtol=0, atol=1e-15 * np.abs(x).max() + 1e-17)
            np.testing.assert_allclose(corr(bias, *(raw * dt), dt), want * dt, rtol=0,
                                       atol=1e-15 * np.abs(x).max() * dt)
    # with no misalignment estimate the triad correction is the per-axis one, to the bit
    bias[kf.B_MG:kf.B_MA + 6] = 0.0
    got = kf.correct_gyro3(bias, 0.3, -0.2, 0.1, 1.0)
    assert got == tuple(kf.correct_gyro(bias, a, x, 1.0) for a, x in enumerate((0.3, -0.2, 0.1)))


def test_misalignment_columns_are_the_bias_columns_times_the_cross_axis_motion() -> None:
    """Element m_ij (row i, column j) enters ``d phi/dt`` as ``-C[:, i] w_j`` (gyro) and ``d dv/dt`` as
    ``-C[:, i] f_j`` (accelerometer), in errmodel.OFF_DIAGONAL order, only when the spec estimates it."""
    c = euler_to_dcm(10.0 * DEG, -20.0 * DEG, 130.0 * DEG)
    w, f = np.array([0.1, -0.2, 0.3]), np.array([1.0, 0.5, -9.5])
    F = np.zeros((em.NX, em.NX))
    em.motion_columns(F, c, w, f, em.ImuSpec(gyro_misalignment=1e-3, accel_misalignment=1e-3).as_array())
    for k, (i, j) in enumerate([(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]):
        np.testing.assert_allclose(F[em.X_PHI:em.X_PHI + 3, em.X_MG + k], -c[:, i] * w[j], rtol=1e-15, atol=0)
        np.testing.assert_allclose(F[em.X_DV:em.X_DV + 3, em.X_MA + k], -c[:, i] * f[j], rtol=1e-15, atol=0)
    F[em.X_PHI:em.X_PHI + 3, em.X_MG:em.X_MG + 6] = 0.0
    F[em.X_DV:em.X_DV + 3, em.X_MA:em.X_MA + 6] = 0.0
    assert not F.any()
    for spec in (em.ImuSpec(accel_misalignment=1e-3), em.ImuSpec(gyro_misalignment=1e-3)):
        F = np.zeros((em.NX, em.NX))
        em.motion_columns(F, c, w, f, spec.as_array())
        assert F[:, em.X_MG:em.X_MG + 6].any() == (spec.gyro_misalignment > 0.0)
        assert F[:, em.X_MA:em.X_MA + 6].any() == (spec.accel_misalignment > 0.0)


def test_an_unestimated_misalignment_tilts_a_turn_as_the_model_says() -> None:
    """A level turn at w about down for T, the x gyro sensing ``m w`` of it (element m_xz): the solution turns
    about the axis (m, 0, 1), and its tilt is exactly ``arccos(1 - (1 - cos th) m^2 / (1 + m^2))`` with th =
    w T sqrt(1 + m^2) (Rodrigues), to first order ``2 m sin(w T / 2)``. The filter's propagation over the
    turn from var(m_xz) = sigma^2 alone: ``phi = -dm (S_c, S_s, 0)`` with ``S_c = sum w dt cos(psi_k)``,
    ``S_s = sum w dt sin(psi_k)`` over the attitude updates (the column -C[:, 0] w_z at each update's
    attitude, errmodel.motion_columns; exact here: the laboratory frame has no other attitude dynamics)."""
    w, m, rate, n = 0.5, 0.01, 100.0, 100
    spec = em.ImuSpec(gyro_misalignment=0.02).as_array()
    sigma = 0.02

    def turn(mis: float) -> tuple[np.ndarray, np.ndarray, list[float]]:
        st = sd.init_state(0.0, 0.0, 0.0, 0.0, np.zeros(3), 0.0, 0.0, 0.0)
        P = np.zeros((em.NX, em.NX))
        P[em.X_MG + 1, em.X_MG + 1] = sigma ** 2
        bias, acc, sums = np.zeros(kf.B_SIZE), np.zeros(aided.ACC_SIZE), np.zeros(7)
        yaws = []
        for k in range(1, n + 1):
            r = aided.push_rate_aided(st, CFG_LAB, spec, P, bias, acc, sums, k / rate, mis * w, 0.0, w,
                                      0.0, 0.0, -9.80665, 1, sd.GEOGRAPHIC)
            if r == 1:
                c = st[sd.S.C:sd.S.C + 9].reshape(3, 3)
                yaws.append(math.atan2(c[1, 0], c[0, 0]))
        return st[sd.S.C:sd.S.C + 9].reshape(3, 3).copy(), P, yaws

    c0, P, yaws = turn(0.0)
    T = n / rate  # the solution starts at t = 0, the first sample's interval included
    c1, _, _ = turn(m)
    th = w * T * math.sqrt(1.0 + m * m)
    tilt = math.acos(min(1.0, c1[2, 2]))
    assert tilt == pytest.approx(math.acos(1.0 - (1.0 - math.cos(th)) * m * m / (1.0 + m * m)), rel=1e-9)
    assert tilt == pytest.approx(2.0 * m * math.sin(w * T / 2.0), rel=2e-2)
    dt = 1.0 / rate
    assert len(yaws) == n
    s_c = sum(w * dt * math.cos(p) for p in yaws)
    s_s = sum(w * dt * math.sin(p) for p in yaws)
    x = em.X_MG + 1
    assert P[em.X_PHI, x] == pytest.approx(-sigma ** 2 * s_c, rel=1e-9)
    assert P[em.X_PHI + 1, x] == pytest.approx(-sigma ** 2 * s_s, rel=1e-9)
    assert P[em.X_PHI, em.X_PHI] == pytest.approx(sigma ** 2 * s_c ** 2, rel=1e-9)
    assert P[em.X_PHI + 1, em.X_PHI + 1] == pytest.approx(sigma ** 2 * s_s ** 2, rel=1e-9)
    assert abs(P[em.X_PHI + 2, em.X_PHI + 2]) < 1e-30 and c0[2, 2] == pytest.approx(1.0, abs=1e-15)


def test_the_misalignments_are_estimated_only_when_asked() -> None:
    """errmodel.spec_of: a grade's misalignment (consumer 2 % / 3, industrial 0.05 deg) and a spec's
    ``gyro_misalignment``/``accel_misalignment`` keys (arcsec) reach the filter only with ``misalignment``
    (``--misalignment``), independently of the scale factors; none of the keys is refused with one line."""
    assert em.spec_of("consumer").gyro_misalignment == 0.0
    on = em.spec_of("consumer", misalignment=True)
    assert on.gyro_misalignment == on.accel_misalignment == pytest.approx(0.02 / 3.0, rel=1e-12)
    assert on.gyro_scale == 0.0
    keys = {"gyro_arw": 0.1, "gyro_misalignment": 36.0, "accel_misalignment": 72.0, "gyro_scale": 10.0}
    off = em.spec_of(keys)
    assert (off.gyro_misalignment, off.accel_misalignment) == (0.0, 0.0)
    on = em.spec_of(keys, misalignment=True)
    assert (on.gyro_misalignment, on.accel_misalignment) == pytest.approx((36.0 * em.ARCSEC, 72.0 * em.ARCSEC),
                                                                          rel=1e-12)
    assert on.gyro_scale == 0.0
    with pytest.raises(ValueError, match=r"^--misalignment with an IMU spec needs gyro_misalignment and/or "
                                         r"accel_misalignment \(arcsec\) in it$"):
        em.spec_of({"gyro_arw": 0.1}, misalignment=True)
    # one of the two keys is enough, whatever its size (1 arcsec is 4.8e-6 rad)
    assert em.spec_of({"accel_misalignment": 1.0}, misalignment=True).accel_misalignment == pytest.approx(em.ARCSEC)
    assert em.spec_of({"gyro_misalignment": 1.0}, misalignment=True).gyro_misalignment == pytest.approx(em.ARCSEC)
    sp = em.make_spec("industrial", misalignment=True)  # 0.05 deg (core/grades.py)
    assert sp[em.SP_GYRO_MIS] == pytest.approx(0.05 * DEG, rel=1e-3) and sp[em.SP_ACC_MIS] == sp[em.SP_GYRO_MIS]
    assert em.ARCSEC == pytest.approx(math.pi / 648000.0, rel=1e-15)


def test_filter_row_writes_each_estimated_block_and_its_sigma_under_its_names() -> None:
    """aided.filter_row on a ROW_SIZE row: after the contract's 35 columns every STATE_BLOCKS block's
    estimate (the bias vector's value) and 1-sigma (root of P's diagonal), at the columns that name them
    (``sg_x`` ... ``sigma_mg_zy`` ... ``sigma_mb_z``), each value distinct so that no column can take
    another's."""
    names = {"SG": "xyz", "SA": "xyz", "MG": ["xy", "xz", "yx", "yz", "zx", "zy"],
             "MA": ["xy", "xz", "yx", "yz", "zx", "zy"], "MB": "xyz"}
    bias = np.arange(kf.B_SIZE, dtype=float) + 0.5
    P = np.diag((np.arange(em.NX, dtype=float) + 1.0) ** 2)
    out = np.zeros(aided.ROW_SIZE)
    aided.filter_row(P, bias, out)
    col = {c: i for i, c in enumerate(aided.ROW_COLUMNS)}
    for blk, axes in names.items():
        x0 = getattr(em, f"X_{blk}")
        for i, a in enumerate(axes):
            assert out[col[f"{blk.lower()}_{a}"]] == bias[x0 - em.X_SENSORS + i], (blk, a)
            assert out[col[f"sigma_{blk.lower()}_{a}"]] == x0 + i + 1.0, (blk, a)

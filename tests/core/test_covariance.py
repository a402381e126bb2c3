"""What the mutation runs found unchecked in mavins/core/covariance.py, the error analysis of `mavins analyze` (docs/testing.md).

Tracks are built here by hand (TrackMeans of a few steps) so that each propagation is a handful of
small matrix products and the file stays fast as plain Python (NUMBA_DISABLE_JIT=1). Expected values
are typed from the model of docs/analysis.md "Model" and the module docstring, never taken from the
code under test:

* laboratory mode (no Earth rate, transport rate or gravity gradient), at rest, level: a random
  constant c drives a chain c -> phi -> dv -> dp. A chain whose F^3 is zero (accelerometer bias,
  scale, misalignment: c -> dv -> dp) is integrated exactly by the second-order transition
  Phi = I + F T + (F T)^2 / 2, so sigma_v = s t and sigma_p = s t^2 / 2 (free-inertial error growth
  from a bias). For the gyro chain (F^4 = 0) Phi^k = I + k F T + k^2/2 (F T)^2 + (k^3 - k)/6 (F T)^3
  (binomial expansion of (I + A)^k, A = F T + (F T)^2 / 2): sigma_phi = eps t, sigma_v = g eps t^2 / 2
  and sigma_p = g eps T^3 (k^3 - k) / 6, the discrete form of g eps t^3 / 6;
* white noise of density q on a state that integrates into the next one (Phi = [[1, 0], [T, 1]],
  Qd = (Phi Qc Phi^T + Qc) T / 2 = [[q T, q T^2/2], [q T^2/2, q T^3/2]]): by induction
  P_11 = q t (random walk, sigma = ARW sqrt(t) or VRW sqrt(t)) and
  P_22 = q T^3 (2 k^3 + k) / 6 = q (t^3 / 3 + T^2 t / 6);
* elsewhere (Earth on, moving, every source, vertical free and held) a reference propagation
  written here with numpy from the documented recursion P <- Phi P Phi^T + Qd, F the filter's
  errmodel.system_matrix (checked element by element in tests/core/test_kalman.py) plus the
  scale/misalignment columns -C[:, i] u_j of the module docstring, rows and columns of dv_D and dp_D
  removed under vertical hold.

Grade figures are docs/simulator.md's; sensor keys and output columns are docs/conventions.md
"Error analysis". C_b^n and its quaternion are the typed ones of tests/support.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core import covariance as cov
from mavins.core import errmodel as em
from support import cbn, quat_zyx

DEG = math.pi / 180.0
G = 9.8  # specific force magnitude of the hand-built tracks (laboratory mode: any value)
NAMES = ("gyro_bias", "gyro_instability", "gyro_rate_random_walk", "gyro_random_walk", "gyro_scale",
         "gyro_misalignment", "accel_bias", "accel_instability", "accel_rate_random_walk", "accel_random_walk",
         "accel_scale", "accel_misalignment")


def track(t, c, f_b, w_b, v=(0.0, 0.0, 0.0), lat=0.0, h=0.0) -> cov.TrackMeans:
    """A TrackMeans with the same C, body specific force and rate over every step (cw = C[r, i] w_j)."""
    t = np.asarray(t, dtype=float)
    k = len(t) - 1
    c = np.asarray(c, dtype=float)
    f_b, w_b = np.asarray(f_b, dtype=float), np.asarray(w_b, dtype=float)
    cw = np.einsum("ri,j->rij", c, w_b)
    cf = np.einsum("ri,j->rij", c, f_b)
    return cov.TrackMeans(t=t, c=np.repeat(c[None], k, 0), v=np.repeat(np.array([v], float), k, 0),
                          lat=np.full(k, lat), h=np.full(k, h), f_n=np.repeat((c @ f_b)[None], k, 0),
                          cw=np.repeat(cw[None], k, 0), cf=np.repeat(cf[None], k, 0))


def lab(k: int, T: float, yaw: float = 0.0, f_b=(0.0, 0.0, -G), w_b=(0.0, 0.0, 0.0)) -> cov.TrackMeans:
    """k steps of T seconds, level, heading ``yaw`` (rad)."""
    return track(np.arange(k + 1) * T, cbn(0.0, 0.0, yaw), f_b, w_b)


def sig(P: np.ndarray) -> dict[str, np.ndarray]:
    """1-sigma per navigation state from (n, 9, 9) covariances (error-state order: phi, dv, dp)."""
    d = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    return {"att": d[:, 0:3], "vel": d[:, 3:6], "pos": d[:, 6:9]}


def typed_sources(s: cov.AnalysisSpec) -> dict[str, tuple[tuple[int, ...], tuple[float, ...], tuple[float, ...]]]:
    """(states, p0, q) of each source, from the layout of the module docstring: bg 9-11, ba 12-14, gg 15-17,
    ga 18-20, K_g[i, j] at 48 + 3 i + j, K_a[i, j] at 57 + 3 i + j; q over the nine navigation states then the
    source's own (white noise on phi for the gyro, on dv for the accelerometer)."""
    i = s.imu
    z9 = (0.0,) * 9
    return {
        "gyro_bias": ((9, 10, 11), (i.gyro_bias**2,) * 3, (0.0,) * 12),
        "gyro_instability": ((15, 16, 17), (i.gyro_gm**2,) * 3, z9 + (2.0 * i.gyro_gm**2 / i.gyro_tau,) * 3),
        "gyro_rate_random_walk": ((9, 10, 11), (0.0,) * 3, z9 + (i.gyro_rrw**2,) * 3),
        "gyro_random_walk": ((), (), (i.gyro_arw**2,) * 3 + (0.0,) * 6),
        "gyro_scale": ((48, 52, 56), (s.gyro_scale**2,) * 3, (0.0,) * 12),
        "gyro_misalignment": ((49, 50, 51, 53, 54, 55), (s.gyro_misalignment**2,) * 6, (0.0,) * 15),
        "accel_bias": ((12, 13, 14), (i.accel_bias**2,) * 3, (0.0,) * 12),
        "accel_instability": ((18, 19, 20), (i.accel_gm**2,) * 3, z9 + (2.0 * i.accel_gm**2 / i.accel_tau,) * 3),
        "accel_rate_random_walk": ((12, 13, 14), (0.0,) * 3, z9 + (i.accel_rrw**2,) * 3),
        "accel_random_walk": ((), (), (0.0,) * 3 + (i.accel_vrw**2,) * 3 + (0.0,) * 3),
        "accel_scale": ((57, 61, 65), (s.accel_scale**2,) * 3, (0.0,) * 12),
        "accel_misalignment": ((58, 59, 60, 62, 63, 64), (s.accel_misalignment**2,) * 6, (0.0,) * 15),
    }


FULL = cov.AnalysisSpec(
    em.ImuSpec(gyro_arw=3e-4, gyro_bias=2e-5, gyro_gm=4e-5, gyro_tau=0.7, gyro_rrw=5e-5, accel_vrw=2e-3,
               accel_bias=3e-3, accel_gm=5e-3, accel_tau=0.9, accel_rrw=7e-3),
    gyro_scale=3e-3, accel_scale=2e-3, gyro_misalignment=1e-3, accel_misalignment=4e-3,
)
"""Every source active, each with its own size; Gauss-Markov times of the order of the track, so they matter."""


def moving_track() -> cov.TrackMeans:
    """Six steps of unequal length on a moving, turning, climbing vehicle at 50-52 deg N (Earth on)."""
    rng = np.random.default_rng(7)
    t = np.array([100.0, 100.1, 100.3, 100.4, 100.6, 100.65, 100.85])
    k = len(t) - 1
    c = np.array([cbn(0.1 + 0.05 * j, -0.2 + 0.03 * j, 1.0 + 0.2 * j) for j in range(k)])
    v = np.array([[60.0 + 3 * j, -25.0 + 2 * j, 4.0 - 1.5 * j] for j in range(k)])
    lat = np.radians(50.0 + 0.4 * np.arange(k))
    h = 800.0 + 150.0 * np.arange(k)
    f_b = np.array([[1.5 + 0.3 * j, -0.8 + 0.2 * j, -9.6 - 0.1 * j] for j in range(k)])
    w_b = np.array([[0.1 - 0.02 * j, 0.05 + 0.01 * j, -0.3 + 0.07 * j] for j in range(k)])
    cw = np.einsum("kri,kj->krij", c, w_b) + 1e-3 * rng.standard_normal((k, 3, 3, 3))  # vibration's mean
    cf = np.einsum("kri,kj->krij", c, f_b) + 1e-2 * rng.standard_normal((k, 3, 3, 3))
    return cov.TrackMeans(t=t, c=c, v=v, lat=lat, h=h, f_n=np.einsum("krii->kr", cf), cw=cw, cf=cf)


def reference(tr: cov.TrackMeans, s: cov.AnalysisSpec, states, p0, q, earth_on: bool, hold: bool,
              every: int) -> np.ndarray:
    """P <- Phi P Phi^T + Qd on the navigation states plus ``states`` (docs/analysis.md "Model"), with numpy."""
    idx = list(range(9)) + list(states)
    m = len(idx)
    P = np.diag(np.concatenate([np.zeros(9), p0]))
    qc = np.diag(np.asarray(q, dtype=float))
    keep = np.ones(m)
    if hold:
        keep[5] = keep[8] = 0.0  # dv_D, dp_D
    qc = qc * np.outer(keep, keep)
    out = [P[:9, :9].copy()]
    for k in range(len(tr.t) - 1):
        F = np.zeros((em.NX + 18, em.NX + 18))
        F[:em.NX, :em.NX] = em.system_matrix(tr.c[k], tr.v[k], tr.lat[k], tr.h[k], tr.f_n[k], s.imu.as_array(), earth_on)
        F[0:3, em.NX:em.NX + 9] = -tr.cw[k].reshape(3, 9)  # d(phi)/dt += -C[:, i] w_j K_g[i, j]
        F[3:6, em.NX + 9:em.NX + 18] = -tr.cf[k].reshape(3, 9)  # d(dv)/dt += -C[:, i] f_j K_a[i, j]
        Fs = F[np.ix_(idx, idx)] * np.outer(keep, keep)
        T = tr.t[k + 1] - tr.t[k]
        phi = np.eye(m) + Fs * T + (Fs * T) @ (Fs * T) / 2.0
        P = phi @ P @ phi.T + (phi @ qc @ phi.T + qc) * T / 2.0
        if (k + 1) % every == 0:
            out.append(P[:9, :9].copy())
    return np.array(out)


# ============================================================== contract: names, units, spec


def test_layout_units_and_column_names() -> None:
    """The augmented layout of the module docstring (K_g at 48.., K_a at 57.., 66 states: after the filter's 48),
    the ppm and arcsec units and the contract's source and column names in their documented order."""
    assert (cov.NNAV, cov.X_KG, cov.X_KA, cov.NA) == (9, 48, 57, 66)
    assert cov.PPM == 1e-6
    assert cov.ARCSEC == pytest.approx(math.pi / 648000.0, rel=1e-15, abs=0)  # 1/3600 deg
    assert cov.ANALYSIS_KEYS == ("gyro_misalignment", "accel_misalignment")
    assert em.SPEC_KEYS[-4:] == ("gyro_scale", "accel_scale") + cov.ANALYSIS_KEYS
    assert cov.SOURCES == NAMES
    assert cov.SIGMA_COLUMNS == ("sigma_n", "sigma_e", "sigma_d", "sigma_vn", "sigma_ve", "sigma_vd",
                                 "sigma_att_n", "sigma_att_e", "sigma_att_d")
    assert cov.BUDGET_COLUMNS == ("pos_h", "pos_v", "vel_h", "att_level", "att_yaw")


def test_analysis_spec_is_checked_and_made_float() -> None:
    """Each scale/misalignment figure is a float >= 0 (zero allowed); negative, infinite and NaN are refused."""
    s = cov.AnalysisSpec(em.ImuSpec(), gyro_scale=1, accel_scale=2, gyro_misalignment=3, accel_misalignment=4)
    names = ("gyro_scale", "accel_scale") + cov.ANALYSIS_KEYS
    assert [type(getattr(s, n)) for n in names] == [float] * 4
    assert (s.gyro_scale, s.accel_scale, s.gyro_misalignment, s.accel_misalignment) == (1.0, 2.0, 3.0, 4.0)
    zero = cov.AnalysisSpec(em.ImuSpec(), 0.0, 0.0, 0.0, 0.0)
    assert (zero.gyro_scale, zero.accel_scale, zero.gyro_misalignment, zero.accel_misalignment) == (0.0,) * 4
    for name in names:
        for bad, text in ((-1e-300, r"-1e-300"), (math.inf, "inf"), (math.nan, "nan")):
            with pytest.raises(ValueError, match=rf"^{name} must be finite and >= 0, got {text}$"):
                cov.AnalysisSpec(em.ImuSpec(), **{name: bad})


def test_spec_from_keys_units_and_absent_keys() -> None:
    """ppm -> 1e-6, arcsec -> pi/648000 rad (docs/conventions.md); the filter's keys go to ImuSpec; absent = 0."""
    s = cov.spec_from_keys({"gyro_scale": 300.0, "accel_scale": 150.0, "gyro_misalignment": 60.0,
                            "accel_misalignment": 36.0, "gyro_bias": 2.0, "accel_vrw": 0.06})
    assert s.gyro_scale == pytest.approx(3e-4, rel=1e-15, abs=0)
    assert s.accel_scale == pytest.approx(1.5e-4, rel=1e-15, abs=0)
    assert s.gyro_misalignment == pytest.approx(60.0 * math.pi / 648000.0, rel=1e-15, abs=0)
    assert s.accel_misalignment == pytest.approx(36.0 * math.pi / 648000.0, rel=1e-15, abs=0)
    assert s.imu.gyro_bias == pytest.approx(2.0 * math.pi / 180.0 / 3600.0, rel=1e-15, abs=0)  # deg/h
    assert s.imu.accel_vrw == pytest.approx(1e-3, rel=1e-15, abs=0)  # m/s/sqrt(h)
    empty = cov.spec_from_keys({})
    assert (empty.gyro_scale, empty.accel_scale, empty.gyro_misalignment, empty.accel_misalignment) == (0.0,) * 4
    assert empty.imu == em.ImuSpec()


def test_spec_from_grade_takes_the_magnitudes_as_one_sigma() -> None:
    """docs/simulator.md model values: tactical 150 / 300 ppm and 1e-4 rad, navigation 5 / 100 ppm and 2e-5 rad."""
    for grade, gs, as_, mis in (("tactical", 150.0, 300.0, 1e-4), ("navigation", 5.0, 100.0, 2e-5)):
        s = cov.spec_from_grade(grade)
        assert s.gyro_scale == pytest.approx(gs * 1e-6, rel=1e-15, abs=0)
        assert s.accel_scale == pytest.approx(as_ * 1e-6, rel=1e-15, abs=0)
        assert s.gyro_misalignment == pytest.approx(mis, rel=1e-12, abs=0)
        assert s.accel_misalignment == pytest.approx(mis, rel=1e-12, abs=0)
        assert s.imu == em.spec_from_grade(grade, scale_factors=True)


def test_source_index_and_activity() -> None:
    """A source's sub-system is the nine navigation states then its own; it is active when any initial
    variance or noise density is positive, however small (zero figures give an inactive source)."""
    src = cov.Source("x", (22, 26), (1.0, 0.0), (0.0,) * 11)
    assert src.index.tolist() == [0, 1, 2, 3, 4, 5, 6, 7, 8, 22, 26]
    assert src.index.dtype == np.int64
    assert cov.Source("w", (), (), (0.0,) * 9).index.tolist() == list(range(9))
    assert not cov.Source("z", (9,), (0.0,), (0.0,) * 10).active
    assert cov.Source("p", (9,), (5e-324,), (0.0,) * 10).active
    assert cov.Source("q", (9,), (0.0,), (0.0,) * 9 + (5e-324,)).active
    assert cov.Source("n", (), (), (0.0,) * 8 + (5e-324,)).active


def test_sources_states_initial_variances_and_noise() -> None:
    """Each source of the budget, in the contract's row order, with the states, 1-sigma squared and densities
    of the module docstring (Gauss-Markov stationary from the start, driven by 2 sigma^2 / tau)."""
    got = cov.sources(FULL)
    assert [s.name for s in got] == list(NAMES)
    want = typed_sources(FULL)
    for s in got:
        states, p0, q = want[s.name]
        assert s.states == states, s.name
        assert s.p0 == pytest.approx(p0, rel=1e-15, abs=0), s.name
        assert len(s.p0) == len(states) and len(s.q) == 9 + len(states), s.name
        assert s.q == pytest.approx(q, rel=1e-15, abs=0), s.name
        assert s.active
    quiet = cov.sources(cov.AnalysisSpec(em.ImuSpec(accel_bias=1e-3)))
    assert [s.name for s in quiet if s.active] == ["accel_bias"]


# ============================================================== the track's step means


def test_quaternion_to_dcm_is_hamilton_c_b_n() -> None:
    """C_b^n from [w, x, y, z] equals Rz(yaw) Ry(pitch) Rx(roll) of the same attitude (docs/conventions.md)."""
    att = [(0.3, -0.5, 2.0), (-1.2, 0.4, -2.9), (0.0, 0.0, 0.0), (2.5, 1.1, 0.7)]
    q = np.array([quat_zyx(*a) for a in att])
    got = cov._quat_to_dcm_rows(q)
    for c, a in zip(got, att):
        np.testing.assert_allclose(c, cbn(*a), rtol=0, atol=4e-16)


def test_track_means_by_hand() -> None:
    """Seven samples of unequal length, three per step: two steps, the last sample left out. Step means of
    C at each sample's mid-time, of velocity, latitude (deg -> rad) and height at the sample mid-times,
    and of C[r, i] w_j, C[r, i] f_j (increment sums over the step's length); f^n = sum_i C[r, i] f_i."""
    t0 = 10.0
    t = np.array([10.1, 10.3, 10.6, 10.8, 11.0, 11.5, 12.0])
    rng = np.random.default_rng(3)
    dth = rng.standard_normal((7, 3)) * 1e-2
    dv = rng.standard_normal((7, 3)) * 0.1
    att = [(0.1 * j, -0.05 * j, 0.3 + 0.2 * j) for j in range(8)]
    truth = np.zeros((8, 19))  # the simulator's truth: the 14 solution columns, then 5 more
    truth[:, 0] = np.concatenate(([t0], t))
    truth[:, 1] = 45.0 + 0.01 * np.arange(8) ** 2  # lat (deg)
    truth[:, 2] = 7.0 + 0.5 * np.arange(8)  # lon
    truth[:, 3] = 100.0 + 3.0 * np.arange(8) ** 2  # h
    truth[:, 4:7] = np.arange(24).reshape(8, 3) ** 1.5
    truth[:, 7:10] = np.degrees(np.array(att))
    truth[:, 10:14] = [quat_zyx(*a) for a in att]
    truth[:, 14:] = 1e3 * rng.standard_normal((8, 5))
    tm = cov.track_means(t0, t, dth, dv, truth, 3)

    np.testing.assert_array_equal(tm.t, [10.0, 10.6, 11.5])
    c = [cbn(*a) for a in att]
    for k, rows in enumerate(((0, 1, 2), (3, 4, 5))):
        T = tm.t[k + 1] - tm.t[k]
        cmid = [0.5 * (c[m] + c[m + 1]) for m in rows]
        np.testing.assert_allclose(tm.c[k], sum(cmid) / 3.0, rtol=0, atol=1e-15)
        mid = [0.5 * (truth[m] + truth[m + 1]) for m in rows]
        np.testing.assert_allclose(tm.v[k], sum(r[4:7] for r in mid) / 3.0, rtol=1e-14)
        assert tm.lat[k] == pytest.approx(math.radians(sum(r[1] for r in mid) / 3.0), rel=1e-14, abs=0)
        assert tm.h[k] == pytest.approx(sum(r[3] for r in mid) / 3.0, rel=1e-14, abs=0)
        cw = sum(np.einsum("ri,j->rij", cm, dth[m]) for cm, m in zip(cmid, rows)) / T
        cf = sum(np.einsum("ri,j->rij", cm, dv[m]) for cm, m in zip(cmid, rows)) / T
        np.testing.assert_allclose(tm.cw[k], cw, rtol=0, atol=1e-15)
        np.testing.assert_allclose(tm.cf[k], cf, rtol=0, atol=1e-14)
        np.testing.assert_allclose(tm.f_n[k], sum(cm @ dv[m] for cm, m in zip(cmid, rows)) / T, rtol=0, atol=1e-14)
    assert (tm.c.shape, tm.v.shape, tm.lat.shape, tm.h.shape, tm.f_n.shape, tm.cw.shape, tm.cf.shape) == (
        (2, 3, 3), (2, 3), (2,), (2,), (2, 3), (2, 3, 3, 3), (2, 3, 3, 3))


def test_track_means_needs_one_whole_step() -> None:
    """Exactly ``step`` samples make one step; one fewer is refused with the documented message."""
    t = np.array([0.5, 1.0, 1.5])
    truth = np.zeros((4, 14))
    truth[:, 10] = 1.0
    tm = cov.track_means(0.0, t, np.zeros((3, 3)), np.zeros((3, 3)), truth, 3)
    np.testing.assert_array_equal(tm.t, [0.0, 1.5])
    with pytest.raises(ValueError, match=r"^fewer than 4 samples: nothing to propagate$"):
        cov.track_means(0.0, t, np.zeros((3, 3)), np.zeros((3, 3)), truth, 4)


# ============================================================== F of the augmented model


def test_analysis_matrix_is_the_filters_f_plus_the_k_columns() -> None:
    """F[:em.NX, :em.NX] is errmodel.system_matrix (Earth on and off, spec passed on: a Gauss-Markov -1/tau);
    K_g[i, j] enters d(phi_r)/dt as -cw[r, i, j], K_a[i, j] enters d(dv_r)/dt as -cf[r, i, j]; nothing
    else couples to or from the 18 random constants."""
    rng = np.random.default_rng(5)
    c = cbn(0.2, -0.3, 1.9)
    v = np.array([40.0, -12.0, 3.0])
    f_n = np.array([0.7, -0.4, -9.9])
    cw, cf = rng.standard_normal((3, 3, 3)), rng.standard_normal((3, 3, 3))
    sp = em.ImuSpec(gyro_gm=1e-5, gyro_tau=250.0).as_array()
    for earth_on in (True, False):
        F = cov.analysis_matrix(c, v, math.radians(52.0), 300.0, f_n, cw, cf, sp, earth_on)
        assert F.shape == (em.NX + 18, em.NX + 18)
        np.testing.assert_array_equal(F[:em.NX, :em.NX], em.system_matrix(c, v, math.radians(52.0), 300.0, f_n, sp, earth_on))
        assert F[15, 15] == -1.0 / 250.0
        for r in range(3):
            for i in range(3):
                for j in range(3):
                    assert F[r, em.NX + 3 * i + j] == -cw[r, i, j]
                    assert F[3 + r, em.NX + 9 + 3 * i + j] == -cf[r, i, j]
        rest = F.copy()
        rest[:em.NX, :em.NX] = 0.0
        rest[0:3, em.NX:em.NX + 9] = 0.0
        rest[3:6, em.NX + 9:em.NX + 18] = 0.0
        assert not rest.any()
    assert F[0, 1] == 0.0  # laboratory mode: no Earth rate
    assert cov.analysis_matrix(c, v, math.radians(52.0), 300.0, f_n, cw, cf, sp, True)[0, 1] != 0.0


# ============================================================== propagation: closed forms


def test_accelerometer_bias_grows_as_b_t_and_b_t2_over_2() -> None:
    """Laboratory mode, level, heading 30 deg, b = 0.01 m/s^2 on each axis: sigma_v = b t, sigma_p = b t^2 / 2
    on north, east and down (exact: F^3 = 0 on bias -> dv -> dp), attitude untouched; every other source zero."""
    b, T, k = 0.01, 0.2, 5
    out = cov.propagate(lab(k, T, yaw=30 * DEG), cov.AnalysisSpec(em.ImuSpec(accel_bias=b)), earth=False)
    assert list(out) == list(NAMES)
    s = sig(out["accel_bias"])
    tt = np.arange(k + 1) * T
    np.testing.assert_allclose(s["vel"], np.repeat((b * tt)[:, None], 3, 1), rtol=1e-13, atol=0)
    np.testing.assert_allclose(s["pos"], np.repeat((b * tt**2 / 2)[:, None], 3, 1), rtol=1e-13, atol=0)
    assert not s["att"].any()
    for name in NAMES:
        if name != "accel_bias":
            assert out[name].shape == (k + 1, 9, 9) and not out[name].any(), name


def test_gyro_bias_discrete_cubic_growth() -> None:
    """Laboratory mode, level, f^n = [0, 0, -g], eps = 1e-4 rad/s on each axis, T = 0.5 s: sigma_phi = eps t,
    sigma_vn = sigma_ve = g eps t^2 / 2, sigma_n = sigma_e = g eps T^3 (k^3 - k) / 6 (0 after one step), and
    nothing vertical (f^n has no horizontal part to tilt into down)."""
    eps, T, k = 1e-4, 0.5, 6
    P = cov.propagate(lab(k, T, yaw=-70 * DEG), cov.AnalysisSpec(em.ImuSpec(gyro_bias=eps)), earth=False)["gyro_bias"]
    s = sig(P)
    j = np.arange(k + 1)
    np.testing.assert_allclose(s["att"], np.repeat((eps * j * T)[:, None], 3, 1), rtol=1e-13, atol=0)
    vh = G * eps * (j * T) ** 2 / 2
    np.testing.assert_allclose(s["vel"][:, :2], np.column_stack([vh, vh]), rtol=1e-13, atol=0)
    ph = G * eps * T**3 * (j**3 - j) / 6
    np.testing.assert_allclose(s["pos"][:, :2], np.column_stack([ph, ph]), rtol=1e-13, atol=1e-20)
    assert s["pos"][1, 0] == 0.0 and s["pos"][2, 0] > 0.0
    assert not s["vel"][:, 2].any() and not s["pos"][:, 2].any()


def test_angle_random_walk_is_arw_sqrt_t() -> None:
    """ARW q on phi (laboratory mode, no attitude dynamics): sigma_phi = ARW sqrt(t) exactly on all three axes,
    and the tilt integrated by g: P_vn = g^2 q T^3 (2 k^3 + k) / 6; no vertical velocity."""
    arw, T, k = 2e-3, 0.25, 4
    P = cov.propagate(lab(k, T), cov.AnalysisSpec(em.ImuSpec(gyro_arw=arw)), earth=False)["gyro_random_walk"]
    s = sig(P)
    j = np.arange(k + 1)
    np.testing.assert_allclose(s["att"], np.repeat((arw * np.sqrt(j * T))[:, None], 3, 1), rtol=1e-13, atol=0)
    pv = G**2 * arw**2 * T**3 * (2 * j**3 + j) / 6
    np.testing.assert_allclose(s["vel"][:, :2] ** 2, np.column_stack([pv, pv]), rtol=1e-13, atol=0)
    assert not s["vel"][:, 2].any()


def test_velocity_random_walk_free_and_held() -> None:
    """VRW q on dv: sigma_v = VRW sqrt(t), P_p = q T^3 (2 k^3 + k) / 6 = q (t^3/3 + T^2 t/6), attitude untouched.
    Vertical hold keeps dv_D and dp_D at zero and leaves north and east as they were."""
    vrw, T, k = 0.03, 0.4, 5
    spec = cov.AnalysisSpec(em.ImuSpec(accel_vrw=vrw))
    j = np.arange(k + 1)
    sv = vrw * np.sqrt(j * T)
    pp = vrw**2 * T**3 * (2 * j**3 + j) / 6
    free = sig(cov.propagate(lab(k, T), spec, earth=False)["accel_random_walk"])
    np.testing.assert_allclose(free["vel"], np.repeat(sv[:, None], 3, 1), rtol=1e-13, atol=0)
    np.testing.assert_allclose(free["pos"] ** 2, np.repeat(pp[:, None], 3, 1), rtol=1e-13, atol=0)
    assert not free["att"].any()
    held = sig(cov.propagate(lab(k, T), spec, earth=False, vertical="hold")["accel_random_walk"])
    np.testing.assert_allclose(held["vel"][:, :2], np.repeat(sv[:, None], 2, 1), rtol=1e-13, atol=0)
    np.testing.assert_allclose(held["pos"][:, :2] ** 2, np.repeat(pp[:, None], 2, 1), rtol=1e-13, atol=0)
    assert not held["vel"][:, 2].any() and not held["pos"][:, 2].any()


def test_accelerometer_scale_and_misalignment() -> None:
    """dv = -C K_a f^b t: each K_a element independent with variance s^2, so Var(dv_r) = s^2 t^2 sum C[r, i]^2 f_j^2
    over the source's (i, j) (diagonal for scale, off-diagonal for misalignment); sigma_p = sigma_v t / 2
    (exact, F^3 = 0); no attitude error. Vertical hold leaves north and east alone."""
    f_b = np.array([1.2, -0.7, -G])
    c = cbn(0.0, 0.0, 0.6)
    T, k = 0.3, 4
    tt = np.arange(k + 1) * T
    spec = cov.AnalysisSpec(em.ImuSpec(), accel_scale=2e-3, accel_misalignment=5e-3)
    for vertical in ("free", "hold"):
        out = cov.propagate(lab(k, T, yaw=0.6, f_b=f_b), spec, earth=False, vertical=vertical)
        diagonal, off = [(i, i) for i in range(3)], [(i, j) for i in range(3) for j in range(3) if i != j]
        for name, sigma, pairs in (("accel_scale", 2e-3, diagonal), ("accel_misalignment", 5e-3, off)):
            rate = np.sqrt([sum((c[r, i] * f_b[j] * sigma) ** 2 for i, j in pairs) for r in range(3)])
            s = sig(out[name])
            axes = 3 if vertical == "free" else 2
            np.testing.assert_allclose(s["vel"][:, :axes], np.outer(tt, rate)[:, :axes], rtol=1e-13, atol=0)
            np.testing.assert_allclose(s["pos"][:, :axes], np.outer(tt**2 / 2, rate)[:, :axes], rtol=1e-13, atol=0)
            assert not s["att"].any()
            if vertical == "hold":
                assert not s["vel"][:, 2].any() and not s["pos"][:, 2].any()


def test_gyro_scale_and_misalignment() -> None:
    """phi = -C K_g w^b t: Var(phi_r) = s^2 t^2 sum C[r, i]^2 w_j^2 over the source's (i, j); the tilt then
    moves north and east as a gyro bias does (dv_N = -g phi_E, dv_E = g phi_N; sigma_p from the discrete
    cubic (k^3 - k) T^3 / 6)."""
    w_b = np.array([0.3, -0.2, 0.5])
    c = cbn(0.0, 0.0, -2.2)
    T, k = 0.5, 4
    j = np.arange(k + 1)
    spec = cov.AnalysisSpec(em.ImuSpec(), gyro_scale=3e-3, gyro_misalignment=1e-3)
    out = cov.propagate(lab(k, T, yaw=-2.2, w_b=w_b), spec, earth=False)
    for name, sigma, pairs in (("gyro_scale", 3e-3, [(i, i) for i in range(3)]),
                               ("gyro_misalignment", 1e-3, [(i, jj) for i in range(3) for jj in range(3) if i != jj])):
        rate = np.sqrt([sum((c[r, i] * w_b[jj] * sigma) ** 2 for i, jj in pairs) for r in range(3)])
        s = sig(out[name])
        np.testing.assert_allclose(s["att"], np.outer(j * T, rate), rtol=1e-13, atol=0)
        tilt = np.array([rate[1], rate[0]])  # north from phi_E, east from phi_N
        np.testing.assert_allclose(s["vel"][:, :2], G * np.outer((j * T) ** 2 / 2, tilt), rtol=1e-13, atol=0)
        np.testing.assert_allclose(s["pos"][:, :2], G * np.outer(T**3 * (j**3 - j) / 6, tilt), rtol=1e-13, atol=1e-20)
        assert not s["vel"][:, 2].any() and not s["pos"][:, 2].any()


def test_output_every_n_steps_and_arguments_checked() -> None:
    """Rows at steps 0, every, 2 every, ... (a partial last group is not output); every >= 1 and vertical
    free|hold are the only accepted values; ``only`` propagates that one source."""
    b, T, k = 0.02, 0.1, 7
    tr = lab(k, T)
    spec = cov.AnalysisSpec(em.ImuSpec(accel_bias=b))
    for every, steps in ((1, range(8)), (3, (0, 3, 6)), (7, (0, 7)), (8, (0,))):
        out = cov.propagate(tr, spec, every=every, earth=False)
        P = out["accel_bias"]
        assert P.shape == (len(steps), 9, 9), every
        assert out["gyro_bias"].shape == P.shape
        tt = np.array(steps) * T
        np.testing.assert_allclose(sig(P)["pos"], np.repeat((b * tt**2 / 2)[:, None], 3, 1), rtol=1e-13, atol=0)
    with pytest.raises(ValueError, match=r"^every must be >= 1$"):
        cov.propagate(tr, spec, every=0)
    with pytest.raises(ValueError, match=r"^vertical must be free or hold, got 'Hold'$"):
        cov.propagate(tr, spec, vertical="Hold")
    north = cov.Source("north accel bias", (12,), (b**2,), (0.0,) * 10)
    out = cov.propagate(tr, spec, earth=False, only=north)
    assert list(out) == ["north accel bias"]
    s = sig(out["north accel bias"])
    np.testing.assert_allclose(s["pos"][:, 0], b * (np.arange(k + 1) * T) ** 2 / 2, rtol=1e-13, atol=0)
    assert not s["pos"][:, 1:].any()


# ============================================================== propagation: the general case


@pytest.mark.parametrize("vertical", ["free", "hold"])
def test_every_source_matches_the_documented_recursion_on_a_moving_track(vertical: str) -> None:
    """Earth on (the default), a turning, climbing, accelerating vehicle, steps of unequal length, every
    second step output: each source equals P <- Phi P Phi^T + Qd written out with numpy (module docstring).
    Both sum the same products in another order, so they agree to rounding (1e-16 per operation over a few
    hundred operations); 1e-11 relative to the largest element leaves a wide margin."""
    tr = moving_track()
    out = cov.propagate(tr, FULL, every=2, vertical=vertical)
    want = typed_sources(FULL)
    for name in NAMES:
        states, p0, q = want[name]
        ref = reference(tr, FULL, states, p0, q, True, vertical == "hold", 2)
        assert out[name].shape == ref.shape == (4, 9, 9), name
        scale = np.abs(ref).max()
        assert scale > 0.0, name
        np.testing.assert_allclose(out[name], ref, rtol=0, atol=1e-11 * scale, err_msg=name)
        np.testing.assert_array_equal(out[name], np.transpose(out[name], (0, 2, 1)), err_msg=name)
        if vertical == "hold":
            assert not out[name][:, [5, 8], :].any() and not out[name][:, :, [5, 8]].any(), name


# ============================================================== the output rows


def test_sigma_rows_and_budget_row_by_hand() -> None:
    """SIGMA_COLUMNS order (position m, velocity m/s, attitude deg) from the diagonal; the budget's horizontal
    and level figures are root sums of squares of north and east (3-4-5 triangles); off-diagonal terms are
    ignored and a negative rounding residue on the diagonal reads as 0, not NaN."""
    diag = np.array([3e-3, 4e-3, 2e-3, 0.6, 0.8, 0.5, 30.0, 40.0, 7.0]) ** 2
    P = np.diag(diag) + 1e-9 * (np.ones((9, 9)) - np.eye(9))
    rows = cov.sigma_rows(np.stack([P, np.zeros((9, 9))]))
    expect = [30.0, 40.0, 7.0, 0.6, 0.8, 0.5] + [math.degrees(x) for x in (3e-3, 4e-3, 2e-3)]
    np.testing.assert_allclose(rows[0], expect, rtol=1e-15, atol=0)
    assert rows.shape == (2, 9) and not rows[1].any()
    np.testing.assert_allclose(cov.budget_row(P), [50.0, 7.0, 1.0, math.degrees(5e-3), math.degrees(2e-3)],
                               rtol=1e-15, atol=0)
    neg = np.diag([-1e-30] * 9)
    assert cov.budget_row(neg).tolist() == [0.0] * 5
    assert cov.sigma_rows(neg[None]).tolist() == [[0.0] * 9]
    tiny = np.diag([1e-6] * 9)  # sigma 1e-3: a clip at anything above 0 would show
    np.testing.assert_allclose(cov.budget_row(tiny), [math.sqrt(2e-6), 1e-3, math.sqrt(2e-6),
                                                      math.degrees(math.sqrt(2e-6)), math.degrees(1e-3)], rtol=1e-15)
    np.testing.assert_allclose(cov.sigma_rows(tiny[None])[0], [1e-3] * 6 + [math.degrees(1e-3)] * 3, rtol=1e-15)

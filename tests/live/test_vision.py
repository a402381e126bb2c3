"""External vision on the live path: VISION_SPEED_ESTIMATE and ODOMETRY velocities from a camera or motion
capture (live/pipeline.py) fused by the filter (kalman.gnss_velocity for NED, kalman.body_velocity for the body
frame); ODOMETRY and VISION_POSITION_ESTIMATE poses in the camera's own frame, placed and then fused
(kalman.vision_place, vision_position, vision_attitude) with a Monte Carlo of their consistency; a start
without GNSS (GPS_GLOBAL_ORIGIN, the heading from the camera); and the loop guard: our own ODOMETRY coming back
is never fused."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mavins.core import kalman as kf
from mavins.core.records import ImuSample
from mavins.core.rotation import quat_to_dcm
from mavins.link.mavlink import mavlink
from mavins.live.engine import Engine, EngineConfig
from mavins.live.livefilter import VISION_HEADING, FilterSettings
from mavins.live.pipeline import VISION_SIGMA_ATT, VISION_SIGMA_POS, VISION_SIGMA_VEL, Pipeline
from sim import errors
from sim.aiding import GnssConfig, VisionConfig, camera_pose, simulate_aiding, truth_at, vision
from sim.generate import generate
from sim.scenarios import Scenario, load
from support import Z995, cbn, chi2_quantile, consumer_stochastic, feed_engine

NAN = math.nan
OWN = 191  # our component id (Pipeline.own_component, docs/service.md)


def encoded(make, component: int = 197) -> object:  # type: ignore[no-untyped-def]
    """A message built by ``make(encoder)`` from system 1, ``component`` (197: MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY),
    as the link decodes it."""
    enc, dec = mavlink.MAVLink(None, srcSystem=1, srcComponent=component), mavlink.MAVLink(None)
    return dec.parse_char(make(enc).pack(enc))


def odometry(enc, child: int, vel, vcov0: float = NAN, reset: int = 0):  # type: ignore[no-untyped-def]
    cov = [0.0] * 21
    cov[0], cov[6], cov[11] = vcov0, 0.04, 0.09
    return enc.odometry_encode(2_000_000, mavlink.MAV_FRAME_LOCAL_NED, child, 1.0, 2.0, 3.0, [1.0, 0.0, 0.0, 0.0],
                               *vel, 0.0, 0.0, 0.0, [NAN] + [0.0] * 20, cov, reset, mavlink.MAV_ESTIMATOR_TYPE_VIO, 100)


@pytest.fixture
def pipeline():  # type: ignore[no-untyped-def]
    """A pipeline whose engine's vision entry point is watched (the arithmetic of the messages, not the filter)."""
    p = Pipeline(EngineConfig(filter=FilterSettings(aiding=("vision",))), own_component=OWN)
    seen: list[tuple] = []
    p.engine.on_vision_velocity = lambda t, v, s, b: seen.append((t, v, s, b))  # type: ignore[method-assign]
    return p, seen


def test_our_own_odometry_is_never_fused(pipeline) -> None:  # type: ignore[no-untyped-def]
    """The loop guard: an ODOMETRY from our own component (what we publish, come back through a router) is
    dropped and counted; the same message from the camera's component is used."""
    p, seen = pipeline
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 0.0, 0.0)), component=OWN))
    assert seen == [] and p.counters["own_odometry_ignored"] == 1
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 0.0, 0.0))))
    assert len(seen) == 1 and p.counters["own_odometry_ignored"] == 1


def test_vision_messages_become_velocities_with_their_sigmas(pipeline) -> None:  # type: ignore[no-untyped-def]
    """ODOMETRY in BODY_FRD: a body velocity with a sigma per axis from the velocity covariance's diagonal (its
    upper-triangle indices 0, 6, 11), the default where the first is NaN; in LOCAL_NED: NED with the largest;
    VISION_SPEED_ESTIMATE: NED, covariance row-major 3 x 3 (0, 4, 8); another frame, a NaN velocity or a
    non-positive variance counted and not used (an unknown velocity, NaN vx, is not counted: the message
    carries its pose alone); a new reset_counter counted."""
    p, seen = pipeline
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), 0.01)))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0))))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_LOCAL_NED, (1.0, 2.0, 3.0), 0.01, reset=1)))
    p.handle(encoded(lambda e: e.vision_speed_estimate_encode(3_000_000, 0.5, -0.5, 0.25,
                                                               [0.01, 0, 0, 0, 0.16, 0, 0, 0, 0.04], 1)))
    p.handle(encoded(lambda e: e.vision_speed_estimate_encode(3_000_000, 0.5, -0.5, 0.25, [NAN] + [0.0] * 8, 1)))
    assert [s[1:] for s in seen] == [((1.0, 2.0, 3.0), pytest.approx((0.1, 0.2, 0.3)), True),
                                     ((1.0, 2.0, 3.0), (VISION_SIGMA_VEL,) * 3, True),
                                     ((1.0, 2.0, 3.0), pytest.approx(0.3), False),
                                     ((0.5, -0.5, 0.25), pytest.approx(0.4), False),
                                     ((0.5, -0.5, 0.25), VISION_SIGMA_VEL, False)]
    assert p.counters["vision_resets"] == 1
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0))))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (NAN, 2.0, 3.0))))  # no velocity: pose only
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), -0.01)))
    p.handle(encoded(lambda e: e.vision_position_estimate_encode(3_000_000, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0,
                                                                  [NAN] + [0.0] * 20, 0)))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0))))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, NAN, 3.0))))  # NaN again: counted
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), 0.0)))  # a zero variance
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), 0.01, reset=2)))
    assert len(seen) == 6
    assert (p.counters["vision_frame_unsupported"], p.counters["vision_invalid"],
            p.counters["vision_resets"]) == (2, 3, 3)  # resets 0-1-0-2


def pose_odometry(enc, frame: int, pos, q, pcov=None, reset: int = 0, vel=(NAN, NAN, NAN)):  # type: ignore[no-untyped-def]
    """An ODOMETRY with a pose (position, quaternion w x y z) in ``frame`` and the pose covariance's diagonal
    ``pcov`` (x y z roll pitch yaw variances; None: unknown, NaN first)."""
    return enc.odometry_encode(4_000_000, frame, mavlink.MAV_FRAME_BODY_FRD, *pos, list(q), *vel, 0.0, 0.0, 0.0,
                               upper(pcov), [NAN] + [0.0] * 20, reset, mavlink.MAV_ESTIMATOR_TYPE_VIO, 100)


def upper(diag) -> list[float]:  # type: ignore[no-untyped-def]
    """A 6 x 6 covariance's upper triangle, row-major (21 values), with the diagonal ``diag`` (None: unknown, the
    first value NaN): the diagonal sits at 0, 6, 11, 15, 18, 20 (row i starts at 6 i - i (i - 1) / 2)."""
    if diag is None:
        return [NAN] + [0.0] * 20
    cov = [0.0] * 21
    for i, v in enumerate(diag):
        cov[6 * i - i * (i - 1) // 2] = v
    return cov


@pytest.fixture
def poses():  # type: ignore[no-untyped-def]
    """A pipeline whose engine's pose entry point is watched."""
    p = Pipeline(EngineConfig(filter=FilterSettings(aiding=("vision",))), own_component=OWN)
    seen: list[tuple] = []
    p.engine.on_vision_pose = lambda *a: seen.append(a)  # type: ignore[method-assign]
    return p, seen


def test_vision_poses_with_their_frames_and_sigmas(poses) -> None:  # type: ignore[no-untyped-def]
    """ODOMETRY in LOCAL_FRD or LOCAL_NED: the position, the attitude from q (body to the frame; normalised),
    sigmas from the pose covariance's diagonal (upper-triangle indices 0, 6, 11, 15, 18, 20), the defaults
    where its first element is NaN, the reset_counter passed on; VISION_POSITION_ESTIMATE: roll, pitch, yaw
    (ZYX, support.cbn) with its covariance; a NaN quaternion: the position without an attitude; another frame,
    a NaN or infinite position, a non-positive variance counted and not used; no pose and no velocity
    (NaN x and vx) counted as empty."""
    p, seen = poses
    half = math.radians(15.0)
    q30 = (2.0 * math.cos(half), 0.0, 0.0, 2.0 * math.sin(half))  # 30 deg of yaw, not normalised
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), q30,
                                             (0.01, 0.04, 0.09, 1e-4, 4e-4, 9e-4), reset=3)))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_NED, (4.0, 5.0, 6.0), (1.0, 0.0, 0.0, 0.0))))
    p.handle(encoded(lambda e: e.vision_position_estimate_encode(
        5_000_000, 7.0, 8.0, 9.0, 0.1, -0.2, 0.3, upper((0.25, 0.25, 0.25, 1e-4, 1e-4, 1e-4)), 3)))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), (NAN, 0, 0, 0))))
    assert len(seen) == 4
    t, pos, c, sp, sa, reset = seen[0]
    assert t is None and pos == (1.0, 2.0, 3.0) and reset == 3  # no IMU yet: taken as of the latest sample
    np.testing.assert_allclose(c, cbn(0.0, 0.0, math.radians(30.0)), rtol=0, atol=1e-7)
    assert sp == pytest.approx((0.1, 0.2, 0.3)) and sa == pytest.approx((0.01, 0.02, 0.03))
    assert seen[1][1] == (4.0, 5.0, 6.0) and seen[1][3:] == ((VISION_SIGMA_POS,) * 3, (VISION_SIGMA_ATT,) * 3, 0)
    np.testing.assert_array_equal(seen[1][2], np.eye(3))
    assert seen[2][1] == (7.0, 8.0, 9.0) and seen[2][3] == pytest.approx((0.5,) * 3) and seen[2][5] == 3
    assert seen[2][4] == pytest.approx((0.01,) * 3)
    np.testing.assert_allclose(seen[2][2], cbn(0.1, -0.2, 0.3), rtol=0, atol=1e-7)
    assert seen[3][2] is None and seen[3][1] == (1.0, 2.0, 3.0)
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FLU, (1.0, 2.0, 3.0), q30)))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, math.inf, 3.0), q30)))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), q30,
                                             (0.01, 0.04, 0.0, 1e-4, 4e-4, 9e-4))))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), q30,
                                             (0.01, 0.04, 0.09, 1e-4, -4e-4, 9e-4))))
    p.handle(encoded(lambda e: e.vision_position_estimate_encode(5_000_000, 7.0, NAN, 9.0, 0.1, -0.2, 0.3,
                                                                  [NAN] + [0.0] * 20, 3)))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (NAN, 2.0, 3.0), q30)))
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FLU, (1.0, 2.0, 3.0), q30)))  # counted again
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), q30,
                                             (0.01, 0.04, 0.09, 0.0, 4e-4, 9e-4))))  # a zero roll variance
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), q30,
                                             (0.01, 0.04, 0.09, -1e-4, 4e-4, 9e-4))))  # a negative one
    assert len(seen) == 4
    assert (p.counters["vision_frame_unsupported"], p.counters["vision_invalid"], p.counters["vision_empty"]) == (2, 6, 1)
    # no attitude (a NaN quaternion, a NaN yaw): the position with its sigmas, the attitude's not read
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), (NAN, 0, 0, 0),
                                             (0.01, 0.04, 0.09, 0.0, 0.0, 0.0))))
    p.handle(encoded(lambda e: e.vision_position_estimate_encode(5_000_000, 7.0, 8.0, 9.0, 0.1, -0.2, NAN,
                                                                  upper((0.25, 0.25, 0.25, 1e-4, 1e-4, 1e-4)), 3)))
    assert len(seen) == 6 and p.counters["vision_invalid"] == 6
    assert seen[4][2] is None and seen[4][3] == pytest.approx((0.1, 0.2, 0.3)) and seen[4][4] == (VISION_SIGMA_ATT,) * 3
    assert seen[5][2] is None and seen[5][1] == (7.0, 8.0, 9.0) and seen[5][4] == (VISION_SIGMA_ATT,) * 3


def test_vision_poses_are_stamped_on_the_imu_clock(poses) -> None:  # type: ignore[no-untyped-def]
    """A pose stamped within 2 s of the IMU's time keeps its own time (s, from microseconds)."""
    p, seen = poses
    p.last_sample = ImuSample(4.5, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8), None, 1, 1)
    p.handle(encoded(lambda e: pose_odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0))))
    p.handle(encoded(lambda e: e.vision_position_estimate_encode(5_000_000, 7.0, 8.0, 9.0, 0.1, -0.2, 0.3,
                                                                  upper(None), 0)))
    assert [x[0] for x in seen] == [pytest.approx(4.0, abs=1e-12), pytest.approx(5.0, abs=1e-12)]


def test_a_global_origin_is_the_initial_position() -> None:
    """GPS_GLOBAL_ORIGIN (or SET_GPS_GLOBAL_ORIGIN: degE7, mm above mean sea level) gives the engine its initial
    position (the geoid height added), as a vehicle that navigates without GNSS reports its local frame's
    origin; a later one does not move it."""
    p = Pipeline(EngineConfig(filter=FilterSettings(aiding=("vision",)), geoid_height=47.0), own_component=OWN)
    p.handle(encoded(lambda e: e.gps_global_origin_encode(473977420, 85455940, 488000, 0), component=1))
    p.handle(encoded(lambda e: e.set_gps_global_origin_encode(1, 100000000, 200000000, 0, 0), component=1))
    assert p.engine.origin == pytest.approx((47.397742, 8.545594, 535.0))
    q = Pipeline(EngineConfig(filter=FilterSettings(aiding=("vision",))), own_component=OWN)
    q.handle(encoded(lambda e: e.set_gps_global_origin_encode(1, 100000000, 200000000, 1500, 0), component=1))
    assert q.engine.origin == pytest.approx((10.0, 20.0, 1.5))


def test_vision_is_stamped_on_the_imu_clock() -> None:
    """A camera's message stamped within 2 s of the IMU's time keeps its own time (s, from microseconds)."""
    from mavins.core.records import ImuSample

    p = Pipeline(EngineConfig(filter=FilterSettings(aiding=("vision",))), own_component=OWN)
    seen: list[tuple] = []
    p.engine.on_vision_velocity = lambda t, v, s, b: seen.append(t)  # type: ignore[method-assign]
    p.last_sample = ImuSample(2.5, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8), None, 1, 1)
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0))))
    p.handle(encoded(lambda e: e.vision_speed_estimate_encode(3_000_000, 0.5, -0.5, 0.25, [NAN] + [0.0] * 8, 0)))
    assert seen == [pytest.approx(2.0, abs=1e-12), pytest.approx(3.0, abs=1e-12)]


OUTAGE = (30.0, 90.0)


def fly(seed: int, vision: bool):  # type: ignore[no-untyped-def]
    """The consumer flight through the engine, fixes cut for a minute; with ``vision`` a camera's NED velocity
    at 30 Hz (truth plus 0.05 m/s noise, stated as 0.05): (end-of-outage horizontal error m, the engine)."""
    run = generate(load("flight"), duration=100.0, rate=100.0, grade="consumer", seed=seed)
    g = simulate_aiding(run, GnssConfig(rate=5.0), None, None).gnss
    g = g[(g[:, 0] < OUTAGE[0]) | (g[:, 0] >= OUTAGE[1])]
    rows = None
    if vision:
        t = np.arange(1.0, 99.0, 1.0 / 30.0)
        _, vel, _, _ = truth_at(run, t)
        noise = np.random.default_rng(seed).standard_normal(vel.shape) * 0.05
        rows = np.column_stack([t, vel + noise, np.full(t.size, 0.05)])
    init = run.init()
    eng = Engine(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading=float(init.yaw), align=5.0,
                              filter=FilterSettings(aiding=("gnss", "vision"))))
    out = np.array(feed_engine(eng, run, g, row=lambda sol: (sol.row[0], sol.row[1], sol.row[2]), vision=rows))
    truth = run.exact.truth
    i = int(np.searchsorted(out[:, 0], OUTAGE[1])) - 1
    k = int(np.searchsorted(truth[:, 0], out[i, 0]))
    lat = math.radians(truth[k, 1])
    a, e2 = 6378137.0, (1 / 298.257223563) * (2 - 1 / 298.257223563)
    r_n = a * (1 - e2) / (1 - e2 * math.sin(lat) ** 2) ** 1.5
    r_e = a / math.sqrt(1 - e2 * math.sin(lat) ** 2)
    dn = (out[i, 1] - lat) * r_n
    de = (out[i, 2] - math.radians(truth[k, 2])) * r_e * math.cos(lat)
    return math.hypot(dn, de), eng


@pytest.mark.plain_python_slow  # the flight through the engine: minutes as plain Python (mutation runs)
def test_a_cameras_velocity_holds_a_gnss_outage() -> None:
    """A minute without fixes: with the camera's velocity the horizontal error at its end is below a fifth of
    the fixes-alone run's (over three seeds, RMS), and every camera velocity was accepted."""
    with_v = [fly(s, True) for s in (1, 2, 3)]
    alone = [fly(s, False) for s in (1, 2, 3)]
    rms = [math.sqrt(np.mean([e ** 2 for e, _ in runs])) for runs in (with_v, alone)]
    assert rms[0] < rms[1] / 5.0, rms
    for _, eng in with_v:
        assert eng.filter.counters["vision_vel_rejected"] == 0 and eng.filter.counters["vision_vel_accepted"] > 2500


# -- a camera's pose: the frame placed, then fused (kalman.vision_place, vision_position, vision_attitude) ----------
POSE_RUNS = 16
MODEL = consumer_stochastic()  # the consumer grade without the errors outside the filter's model
CAMERA = VisionConfig(rate=30.0)  # 5 cm, 1 deg, a frame turned 30 deg from north, its origin at the start


def pose_run(trajectory, seed: int):  # type: ignore[no-untyped-def]
    """The quiet flight (100 s) through the engine with the consumer IMU's modelled errors (test_aided_filter's
    MODEL) and a camera's pose alone (``--aiding vision``, no GNSS: the start from the given position, the
    heading from the camera): at each output after the alignment the camera-frame position and attitude errors
    (vision_position and vision_attitude's innovations against the true pose, noise-free) and their covariance
    ``H P H^T``; and the engine."""
    ex = trajectory.exact
    t, dth, dv, _ = errors.apply(MODEL, ex.t, ex.dtheta, ex.dv, seed, t_start=ex.t0)
    run = dataclasses.replace(trajectory, seed=seed, t=t, dtheta=dth, dv=dv)
    cam = vision(run, CAMERA)
    init = run.init()
    eng = Engine(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, align=5.0,
                              filter=FilterSettings(spec="consumer", aiding=("vision",), vision_drift=0.0,
                                                    vision_yaw_drift=0.0)))
    sig_p, sig_a = (CAMERA.sigma_pos,) * 3, (CAMERA.sigma_att,) * 3
    start = (math.radians(ex.truth[0, 1]), math.radians(ex.truth[0, 2]), ex.truth[0, 3])
    truth_cfg = dataclasses.replace(CAMERA, sigma_pos=0.0, sigma_att=0.0, sigma_vel=0.0)
    w, f = run.rates()
    z2, m, next_t = [], 0, 10.0
    for i, ti in enumerate(t.tolist()):
        while m < len(cam) and cam[m, 0] <= ti:
            r = cam[m]
            eng.on_vision_pose(float(r[0]), tuple(r[1:4]), quat_to_dcm(np.ascontiguousarray(r[4:8])), sig_p, sig_a, 0)
            m += 1
        sol = eng.on_imu(ImuSample(ti, tuple(w[i].tolist()), tuple(f[i].tolist()), None, 1, 1))
        if sol is None or ti < next_t or ti > ex.truth[-1, 0]:  # (the last sample's time jitters past the end)
            continue
        next_t += 1.0
        llh, vel, q, _ = truth_at(run, np.array([ti]))
        true = camera_pose(llh, q, vel, start, truth_cfg, np.random.default_rng(0))[0]
        flt, s = eng.filter, eng._s
        nu_p, H_p, _ = kf.vision_position(s, eng._kcfg, flt.bias, flt.vision_ref, true[0:3], 0.0, np.ones(3))
        nu_a, H_a, _ = kf.vision_attitude(s, flt.bias, np.ascontiguousarray(quat_to_dcm(true[3:7])), np.ones(3))
        e, H = np.r_[nu_p, nu_a], np.vstack((H_p, H_a))
        z2.append(float(e @ np.linalg.solve(H @ flt.P @ H.T, e)))
    return np.array(z2), eng


@pytest.fixture(scope="module")
def quiet_flight():  # type: ignore[no-untyped-def]
    sc = load("flight")
    doc = {k: v for k, v in sc.doc.items() if k != "perturbations"}
    return generate(Scenario("flight_quiet", sc.source, doc), duration=100.0, rate=100.0, seed=0, grade="ideal")


@pytest.mark.plain_python_slow  # the flight through the engine, 16 times: minutes as plain Python (mutation runs)
def test_a_cameras_pose_alone_is_fused_consistently(quiet_flight) -> None:  # type: ignore[no-untyped-def]
    """16 runs of the quiet flight with the camera's pose as the only aiding: every pose after the first (which
    places the frame) is accepted; the normalised squared error of the camera-frame pose (position and
    attitude, 6 degrees of freedom) averaged over the runs lies in the 99 % band of chi2(6N)/N at every
    second (Wilson-Hilferty), and its mean over the run in that band too (the time average has the same
    mean and at most that spread)."""
    runs = [pose_run(quiet_flight, 900 + r) for r in range(POSE_RUNS)]
    for _, eng in runs:
        c = eng.filter.counters
        assert eng.heading_used == VISION_HEADING and c["vision_frame_placed"] == 1 and c["vision_pose_rejected"] == 0
        assert c["vision_pose_accepted"] > 30 * 90
    z2 = np.array([z for z, _ in runs])
    k = 6 * POSE_RUNS
    lo, hi = (chi2_quantile(z, k) / POSE_RUNS for z in (-Z995, Z995))
    per_epoch = z2.mean(axis=0)
    assert lo < per_epoch.mean() < hi, (per_epoch.mean(), lo, hi)
    assert np.mean((per_epoch < lo) | (per_epoch > hi)) < 0.05, (np.round(per_epoch, 2), lo, hi)


def test_the_live_filter_places_a_frame_once_per_reset_counter() -> None:
    """The first pose of a reset_counter places the frame (its states then have variance, its origin is the
    pose's position less the solution's; the smoother's log starts again), the next ones are fused (accepted),
    a new reset_counter places it again, and a pose without an attitude cannot place one (counted)."""
    from mavins.core import errmodel as em
    from mavins.core import strapdown as sd
    from mavins.core.runner import rest_state
    from mavins.live.livefilter import LiveFilter

    cfg = sd.make_config()
    s = rest_state()
    f = LiveFilter(FilterSettings(aiding=("vision",), smooth=True))
    f.start(s, cfg, np.zeros(3), 0.01)
    t = sd.state_time(s)
    sig = ((0.1,) * 3, (0.02,) * 3)
    f.measure(s, cfg, t, "vision_pose", (1.0, 2.0, 3.0), None, *sig, 0)
    f.measure(s, cfg, t, "vision_pose", (1.0, 2.0, 3.0), None, *sig, 0)
    assert f.counters["vision_pose_unplaced"] == 2 and f.vision_frame is None and f.P[em.X_VY, em.X_VY] == 0.0
    generation = f.epochs.generation  # type: ignore[union-attr]
    f.measure(s, cfg, t, "vision_pose", (1.0, 2.0, 3.0), np.eye(3), *sig, 0)
    assert f.counters["vision_frame_placed"] == 1 and f.vision_frame == 0
    assert f.epochs.generation == generation + 1  # type: ignore[union-attr]
    np.testing.assert_allclose(f.bias[kf.B_VP:kf.B_VP + 3], -np.array([1.0, 2.0, 3.0]), atol=1e-6)  # rest, yaw 0
    assert f.P[em.X_VY, em.X_VY] > 0.0 and np.all(np.diag(f.P)[em.X_VP:em.X_VP + 3] > 0.0)
    for _ in range(3):
        f.measure(s, cfg, t, "vision_pose", (1.0, 2.0, 3.0), np.eye(3), *sig, 0)
    assert f.counters["vision_pose_accepted"] == 3 and f.counters["vision_frame_placed"] == 1
    assert set(f.ratios) == {"pos", "hgt"}  # published as ESTIMATOR_STATUS's position test ratios
    # a placed frame takes a pose without an attitude (its position alone) and one turned 0.01 rad in yaw
    # (both the solution's heading and the frame's take a share of it: their sum moves by less than 0.01)
    f.measure(s, cfg, t, "vision_pose", (1.0, 2.0, 3.0), None, *sig, 0)
    assert f.counters["vision_pose_accepted"] == 4
    def yaw() -> float:
        return math.atan2(s[sd.S.C + 3], s[sd.S.C])  # C_b^n row-major: atan2(C21, C11)

    yaw0, psi0 = yaw(), f.bias[kf.B_VY]
    turn = np.array([[math.cos(0.01), -math.sin(0.01), 0.0], [math.sin(0.01), math.cos(0.01), 0.0], [0.0, 0.0, 1.0]])
    f.measure(s, cfg, t, "vision_pose", (1.0, 2.0, 3.0), turn, *sig, 0)
    moved = (yaw() - yaw0) - (f.bias[kf.B_VY] - psi0)
    assert f.counters["vision_pose_accepted"] == 5 and 0.001 < moved < 0.01
    f.measure(s, cfg, t, "vision_pose", (5.0, 2.0, 3.0), np.eye(3), *sig, 1)
    assert f.counters["vision_frame_placed"] == 2 and f.vision_frame == 1
    assert f.bias[kf.B_VP] == pytest.approx(-5.0, abs=1e-3)
    f.start(s, cfg, np.zeros(3), 0.01)  # a new start forgets the frame
    assert f.vision_frame is None and f.vision_ref is None


def test_the_camera_frames_walk_is_in_the_model_only_with_vision_aiding() -> None:
    """--vision-drift and --vision-yaw-drift (m/sqrt(s), deg/sqrt(h)) enter the process model with vision
    aiding; without it the frame's states have no noise and stay out of the propagation."""
    from mavins.core import errmodel as em
    from mavins.live.livefilter import LiveFilter

    on = LiveFilter(FilterSettings(aiding=("vision",), vision_drift=0.02, vision_yaw_drift=3.0)).spec
    assert on[em.SP_VISION_DRIFT] == 0.02 and on[em.SP_VISION_YAW_DRIFT] == pytest.approx(math.radians(3.0) / 60.0)
    off = LiveFilter(FilterSettings(aiding=("gnss",), vision_drift=0.02, vision_yaw_drift=3.0)).spec
    assert off[em.SP_VISION_DRIFT] == off[em.SP_VISION_YAW_DRIFT] == 0.0


def test_the_settings_pick_the_errors_the_live_filter_estimates() -> None:
    """--scale-factors, --misalignment and wheel aiding put their initial 1-sigmas into the process model (0
    without them); the wheel's lever arm is kept as floats."""
    from mavins.core import errmodel as em
    from mavins.live.livefilter import LiveFilter

    f = LiveFilter(FilterSettings(spec="consumer", aiding=("gnss", "wheel"), scale_factors=True, misalignment=True,
                                  wheel_scale=0.03, wheel_lever_arm=(1, -2, 3)))
    assert f.spec[em.SP_GYRO_SCALE] > 0.0 and f.spec[em.SP_ACC_SCALE] > 0.0
    assert f.spec[em.SP_GYRO_MIS] > 0.0 and f.spec[em.SP_ACC_MIS] > 0.0 and f.spec[em.SP_WHEEL_SCALE] == 0.03
    assert f.wheel_lever.dtype == np.float64 and f.wheel_lever.tolist() == [1.0, -2.0, 3.0]
    g = LiveFilter(FilterSettings(spec="consumer", aiding=("gnss",), wheel_scale=0.03))
    assert g.spec[em.SP_GYRO_SCALE] == g.spec[em.SP_ACC_SCALE] == g.spec[em.SP_GYRO_MIS] == 0.0
    assert g.spec[em.SP_ACC_MIS] == g.spec[em.SP_WHEEL_SCALE] == 0.0

"""External vision on the live path: VISION_SPEED_ESTIMATE and ODOMETRY velocities from a camera or motion
capture (live/pipeline.py) fused by the filter (kalman.gnss_velocity for NED, kalman.body_velocity for the body
frame), and the loop guard: our own ODOMETRY coming back is never fused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.link.mavlink import mavlink
from mavins.live.engine import Engine, EngineConfig
from mavins.live.livefilter import FilterSettings
from mavins.live.pipeline import VISION_SIGMA_VEL, Pipeline
from sim.aiding import GnssConfig, simulate_aiding, truth_at
from sim.generate import generate
from sim.scenarios import load
from support import feed_engine

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
    non-positive variance counted and not used; a new reset_counter counted; a position not used (counted)."""
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
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (NAN, 2.0, 3.0))))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), -0.01)))
    p.handle(encoded(lambda e: e.vision_position_estimate_encode(3_000_000, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0,
                                                                  [NAN] + [0.0] * 20, 0)))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_LOCAL_FRD, (1.0, 2.0, 3.0))))
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, NAN, 3.0))))  # NaN again: counted
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), 0.0)))  # a zero variance
    p.handle(encoded(lambda e: odometry(e, mavlink.MAV_FRAME_BODY_FRD, (1.0, 2.0, 3.0), 0.01, reset=2)))
    assert len(seen) == 6
    assert (p.counters["vision_frame_unsupported"], p.counters["vision_invalid"],
            p.counters["vision_position_unused"], p.counters["vision_resets"]) == (2, 4, 1, 3)  # resets 0-1-0-2


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

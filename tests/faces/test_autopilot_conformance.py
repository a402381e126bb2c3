"""What PX4, ArduPilot and ground stations do with the service's output, checked on a live run.

Each rule below is read from the consumer's own source (docs/autopilots.md):

* PX4 ``src/modules/mavlink/mavlink_receiver.cpp`` (ODOMETRY handler): only
  ``estimator_type`` UNKNOWN, NAIVE, VISION or VIO reach EKF2's external
  vision; ``frame_id`` must be LOCAL_NED, LOCAL_FRD, ENU or FLU and the
  velocity frame LOCAL_* or BODY_FRD; only the covariance diagonals are read;
  a ``reset_counter`` change is a reset; ``quality`` is gated by EKF2_EV_QMIN.
* ArduPilot ``AP_VisualOdom`` (MAVLink backend): LOCAL_FRD / BODY_FRD; errors
  from the covariance; data ignored for 1 s after a reset_counter change;
  ``AP_GPS_MAV`` (GPS_TYPE 14) takes GPS_INPUT with fix type, accuracies, yaw.
* QGroundControl reads ESTIMATOR_STATUS flags, ratios and accuracies;
  MAVProxy's console colours its EKF light from EKF_STATUS_REPORT's largest
  variance (green below 0.5).
* TIMESYNC: a request (tc1 = 0) must be answered with tc1 != 0 and ts1 echoed.

The simulator streams HIGHRES_IMU at 200 Hz and GPS_RAW_INT at 5 Hz of a
vehicle at rest (heading 30 deg) for 45 s of sensor time; the checks use the
last 20 s. Rates are per second of sensor time (the messages' own stamps), so
the test does not depend on the machine's speed.
"""

from __future__ import annotations

import math
import socket
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from support import ENV, MAVINS, free_udp_port, running_service, wait_for_line, wrap_deg
from mavins.link.mavlink import mavlink
from mavins.link.publish import PublishConfig

DURATION_S = 45.0
WINDOW_S = 20.0  # the last 20 s
HEADING_DEG = 30.0  # sim/scenarios/static.toml
DIAG = (0, 6, 11, 15, 18, 20)
START = ("47.397742", "8.545594", "488.0")


@dataclass
class Received:
    msgs: dict[str, list] = field(default_factory=dict)
    sync_window_ns: tuple[int, int] = (0, 0)  # CLOCK_MONOTONIC (ns) before the TIMESYNC request, after the run
    nav: Path | None = None  # the service's own solution file (-o): the filter's sigmas row by row

    def of(self, name: str) -> list:
        return self.msgs.get(name, [])


def _listen(sock: socket.socket, into: Received, stop: threading.Event) -> None:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    sock.settimeout(0.1)
    while not stop.is_set():
        try:
            data = sock.recv(65535)
        except socket.timeout:
            continue
        for m in parser.parse_buffer(data) or []:
            into.msgs.setdefault(m.get_type(), []).append(m)


def _run(tmp: Path, *extra: str) -> tuple[Received, str]:
    """Serve a 45 s rest stream (at 5x real time); ask for TIMESYNC once navigating."""
    port = free_udp_port()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    client.bind(("127.0.0.1", 0))
    got, stop = Received(), threading.Event()
    th = threading.Thread(target=_listen, args=(client, got, stop), daemon=True)
    th.start()
    log_path = tmp / "svc.log"
    try:
        got.nav = tmp / "nav.csv"
        with running_service(log_path, "--master", f"udpin:127.0.0.1:{port}", "-o", str(got.nav), "--out",
                             f"udpout:127.0.0.1:{client.getsockname()[1]}", "--lat", START[0], "--lon", START[1],
                             "--alt", START[2], "--heading", "vehicle", "--align", "5", "--rate", "10",
                             "--grade", "tactical", *extra, cwd=tmp) as svc:
            sim = subprocess.Popen([*MAVINS, "sim", "static", "--rate", "200", "--grade", "tactical", "--duration",
                                    str(DURATION_S), "--speed", "5", "--stream", f"udpout:127.0.0.1:{port}"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV, cwd=tmp, text=True)
            wait_for_line(log_path, "NAVIGATING", svc)
            req = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
            t_req = time.monotonic_ns()
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs:
                gcs.sendto(req.timesync_encode(0, 123456789).pack(req), ("127.0.0.1", port))
                # a response to someone's request (tc1 != 0): never answered
                gcs.sendto(req.timesync_encode(555, 987654321).pack(req), ("127.0.0.1", port))
            _, err = sim.communicate(timeout=600)
            assert sim.returncode == 0, err
            got.sync_window_ns = (t_req, time.monotonic_ns())
    finally:
        stop.set()
        th.join(5)
        client.close()
    text = log_path.read_text()
    assert svc.returncode == 0, text
    return got, text


def _last(msgs: list, t_end: float, stamp: str = "time_usec") -> list:
    return [m for m in msgs if getattr(m, stamp) * 1e-6 > t_end - WINDOW_S]


def _per_second(msgs: list, t_end: float, stamp: str = "time_usec") -> list[int]:
    t = np.array([getattr(m, stamp) * 1e-6 for m in msgs])
    # whole seconds strictly inside the window, edges half a second off the stamps' whole seconds
    starts = np.arange(t_end - WINDOW_S + 0.5, t_end - 1.0, 1.0)
    return [int(np.sum((t > a) & (t <= a + 1.0))) for a in starts]


def _window(got: Received, log: str, name: str, per_second: int) -> list:
    """The messages ``name`` of the last WINDOW_S of sensor time, after checking their rate both ways:
    ``per_second`` in each whole second of it, give or take the one whose stamp (the attitude update
    after the multiple of 1/rate, jittering with the samples) falls either side of a second's edge, and
    ``per_second`` times the seconds over them all, give or take one. The rates are per second of sensor
    time, so neither a missing nor an extra message is explained by the machine's speed."""
    msgs = got.of(name)
    assert msgs, log
    t_end = max(m.time_usec for m in msgs) * 1e-6
    last = _last(msgs, t_end)
    counts = _per_second(last, t_end)
    assert all(abs(c - per_second) <= 1 for c in counts), (name, counts)
    assert abs(sum(counts) - per_second * len(counts)) <= 1, (name, counts)
    return last


@pytest.fixture(scope="module")
def aided(tmp_path_factory: pytest.TempPathFactory) -> tuple[Received, str]:
    return _run(tmp_path_factory.mktemp("aided"), "--gps-input")


@pytest.fixture(scope="module")
def free(tmp_path_factory: pytest.TempPathFactory) -> tuple[Received, str]:
    return _run(tmp_path_factory.mktemp("free"), "--aiding", "none")


def test_odometry_is_what_ekf2_and_ekf3_fuse(aided: tuple[Received, str]) -> None:
    got, log = aided
    last = _window(got, log, "ODOMETRY", 10)  # --rate 10
    for m in last:
        assert m.frame_id == mavlink.MAV_FRAME_LOCAL_FRD and m.child_frame_id == mavlink.MAV_FRAME_BODY_FRD
        assert m.estimator_type == mavlink.MAV_ESTIMATOR_TYPE_VIO  # PX4 drops GPS/GPS_INS
        for cov in (m.pose_covariance, m.velocity_covariance):
            assert all(math.isfinite(cov[i]) and cov[i] > 0.0 for i in DIAG)
        assert math.sqrt(0.5 * (m.pose_covariance[0] + m.pose_covariance[6])) <= 5.0
        assert 1 <= m.quality <= 100
    assert len({m.reset_counter for m in last}) == 1  # no reset at rest with steady GNSS


def test_odometry_covariances_are_the_filters_sigmas(aided: tuple[Received, str]) -> None:
    """Each ODOMETRY's pose covariance holds the variances of the solution file's own row of the same
    time (docs/conventions.md ODOMETRY): sigma_n^2, sigma_e^2, sigma_d^2 (m^2), roll and pitch the mean
    of the north and east attitude variances, yaw the down one (the file's deg as rad^2); float32 on the
    wire (relative 1e-6). The body velocity variances are the diagonal of C_n^b P_v C_b^n with C_b^n from
    the row's own quaternion (the contract's q_nb, Hamilton, scalar first): at rest with yaw 30 deg they mix
    north and east, vx about cos^2 30 sigma_vn^2 + sin^2 30 sigma_ve^2."""
    got, log = aided
    header = got.nav.read_text().splitlines()[0].split(",")  # type: ignore[union-attr]
    nav = np.loadtxt(got.nav, delimiter=",", skiprows=1, ndmin=2)
    col = {k: header.index(k) for k in header}
    by_t = {round(r[0] * 1e6): r for r in nav}
    checked = 0
    for m in got.of("ODOMETRY"):
        r = by_t.get(m.time_usec)
        if r is None:
            continue
        att = np.radians([r[col["sigma_att_n"]], r[col["sigma_att_e"]], r[col["sigma_att_d"]]]) ** 2
        want = [r[col["sigma_n"]] ** 2, r[col["sigma_e"]] ** 2, r[col["sigma_d"]] ** 2,
                0.5 * (att[0] + att[1]), 0.5 * (att[0] + att[1]), att[2]]
        np.testing.assert_allclose([m.pose_covariance[i] for i in DIAG], want, rtol=1e-6)
        w, x, y, z = (r[col[k]] for k in ("qw", "qx", "qy", "qz"))
        c_bn = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        var_n = np.array([r[col["sigma_vn"]], r[col["sigma_ve"]], r[col["sigma_vd"]]]) ** 2
        np.testing.assert_allclose([m.velocity_covariance[i] for i in DIAG[:3]], (c_bn ** 2).T @ var_n, rtol=1e-6)
        checked += 1
    assert checked > 100, (checked, log)


def test_estimator_status_and_ekf_status_report(aided: tuple[Received, str]) -> None:
    got, log = aided
    last = _window(got, log, "ESTIMATOR_STATUS", 1)
    need = (mavlink.ESTIMATOR_ATTITUDE | mavlink.ESTIMATOR_VELOCITY_HORIZ | mavlink.ESTIMATOR_VELOCITY_VERT
            | mavlink.ESTIMATOR_POS_HORIZ_ABS)
    for m in last:
        assert m.flags & need == need, bin(m.flags)
        assert not m.flags & mavlink.ESTIMATOR_CONST_POS_MODE
        assert not m.flags & mavlink.ESTIMATOR_GPS_GLITCH
        assert 0.0 <= m.pos_horiz_ratio < 1.0 and 0.0 <= m.pos_vert_ratio < 1.0
        assert 0.0 < m.pos_horiz_accuracy <= 5.0 and 0.0 < m.pos_vert_accuracy <= 5.0
    ekf = got.of("EKF_STATUS_REPORT")
    assert len(ekf) >= len(last)  # sent with each ESTIMATOR_STATUS
    for m in ekf[-len(last):]:
        assert m.flags & (mavlink.EKF_ATTITUDE | mavlink.EKF_POS_HORIZ_ABS) == (mavlink.EKF_ATTITUDE
                                                                                  | mavlink.EKF_POS_HORIZ_ABS)
        assert max(m.velocity_variance, m.pos_horiz_variance, m.pos_vert_variance, m.compass_variance) < 0.5


def test_gps_input_carries_the_solution(aided: tuple[Received, str]) -> None:
    got, log = aided
    last = _window(got, log, "GPS_INPUT", 5)
    for m in last:
        assert m.fix_type == 3 and m.gps_id == 0
        assert 0.0 < m.horiz_accuracy <= 5.0 and 0.0 < m.vert_accuracy <= 5.0
        assert abs(wrap_deg(m.yaw / 100.0 - HEADING_DEG)) < 1.0  # cdeg, the true heading
        assert abs(m.lat * 1e-7 - float(START[0])) < 1e-4 and abs(m.lon * 1e-7 - float(START[1])) < 1e-4


def test_timesync_request_is_answered(aided: tuple[Received, str]) -> None:
    """A request (tc1 = 0, ts1 = 123456789) is answered once with ts1 echoed and tc1 the service's clock in
    nanoseconds (common.xml TIMESYNC; its clock is CLOCK_MONOTONIC, the same on the whole machine, so tc1
    lies between this test's monotonic ns before the request and after the run: a clock in us or ms would be
    1e3 to 1e6 too small). The response (tc1 = 555) to somebody else's request is left unanswered."""
    got, log = aided
    answers = [m for m in got.of("TIMESYNC") if m.ts1 == 123456789]
    lo, hi = got.sync_window_ns
    assert len(answers) == 1 and lo <= answers[0].tc1 <= hi, (answers, lo, hi, log)
    assert not [m for m in got.of("TIMESYNC") if m.ts1 == 987654321]


def test_free_inertial_is_flagged_and_its_uncertainty_grows(free: tuple[Received, str]) -> None:
    got, log = free
    est = got.of("ESTIMATOR_STATUS")
    assert est, log
    for m in est:
        assert m.flags & mavlink.ESTIMATOR_ATTITUDE
        assert not m.flags & mavlink.ESTIMATOR_POS_HORIZ_ABS
        assert m.flags & mavlink.ESTIMATOR_CONST_POS_MODE
    acc = [m.pos_horiz_accuracy for m in est]
    assert all(b >= a for a, b in zip(acc, acc[1:])) and acc[-1] > acc[0]
    odo = got.of("ODOMETRY")
    assert all(math.isfinite(m.pose_covariance[i]) for m in odo for i in DIAG)
    assert odo[-1].pose_covariance[0] > odo[0].pose_covariance[0]
    assert not got.of("GPS_INPUT")  # only with --gps-input


def _rest_imu(mav: mavlink.MAVLink, t_us: int) -> bytes:
    """A HIGHRES_IMU frame of a level board at rest."""
    return bytes(mavlink.MAVLink_highres_imu_message(t_us, 0.0, 0.0, -9.806, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                                     0.0, 0.0, 0.0, 20.0, 0b111111, 0).pack(mav))


def _serve_in_process(publish: PublishConfig, frames: list[bytes], done: Callable[[Received], bool]) -> Received:
    """An in-process service (position typed, heading 30 deg, 1 s alignment, 10 Hz output) on
    127.0.0.1, fed ``frames`` (paced: 10 ms every 50), until ``done`` holds for what came back."""
    from mavins.live.engine import EngineConfig
    from mavins.link.ingest import IngestConfig
    from mavins.service import Service, ServiceConfig

    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    client.bind(("127.0.0.1", 0))
    port = free_udp_port()
    svc = Service(EngineConfig(lat=47.0, lon=8.0, alt=400.0, heading=30.0, align=1.0, rate=10.0), IngestConfig(),
                  ServiceConfig(master=f"udpin:127.0.0.1:{port}", outs=[f"udpout:127.0.0.1:{client.getsockname()[1]}"],
                                publish=publish))
    got, stop_rx, stop_svc = Received(), threading.Event(), threading.Event()
    rx = threading.Thread(target=_listen, args=(client, got, stop_rx), daemon=True)
    rx.start()
    runner = threading.Thread(target=svc.run, args=(stop_svc,), daemon=True)
    runner.start()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for i, f in enumerate(frames):
            tx.sendto(f, ("127.0.0.1", port))
            if i % 50 == 49:
                threading.Event().wait(0.01)
    for _ in range(600):  # wait on the event, not on a duration
        if done(got):
            break
        threading.Event().wait(0.05)
    stop_svc.set()
    runner.join(30)
    stop_rx.set()
    rx.join(5)
    client.close()
    return got


def test_realignment_increments_reset_counter_once(tmp_path: Path) -> None:
    """An autopilot restart (sensor time back to boot) re-aligns: ODOMETRY's reset_counter grows by
    exactly one (PX4 and ArduPilot reset their fusion on a change), nothing is published while
    re-aligning, and the estimator flags come back with attitude."""
    mav = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    frames = [_rest_imu(mav, 1_000_000 + 5000 * i) for _ in range(2) for i in range(600)]  # 3 s, restart, 3 s
    got = _serve_in_process(PublishConfig(), frames,
                            lambda g: sum(1 for m in g.of("ODOMETRY") if m.time_usec >= 3_900_000) >= 2)
    odo = got.of("ODOMETRY")
    counters = [m.reset_counter for m in odo]
    changes = [i for i in range(1, len(counters)) if counters[i] != counters[i - 1]]
    assert len(changes) == 1 and counters[changes[0]] == counters[0] + 1, counters
    k = changes[0]
    # the new run starts after its 1 s re-alignment, at its own sensor time
    assert odo[k].time_usec < odo[k - 1].time_usec and odo[k].time_usec >= 2_000_000
    est = got.of("ESTIMATOR_STATUS")
    assert est and est[-1].flags & mavlink.ESTIMATOR_ATTITUDE


def test_origin_system_time_and_ned_frame(tmp_path: Path) -> None:
    """``--set-origin``: SET_GPS_GLOBAL_ORIGIN once, to the vehicle, with the origin (AMSL mm);
    SYSTEM_TIME once a GPS_RAW_INT carries UNIX time, equal to that time plus the sensor time
    elapsed; ``--odometry-frame ned``: ODOMETRY in MAV_FRAME_LOCAL_NED."""
    geoid = 47.5
    mav = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    utc0_us = 1_764_000_000_000_000  # 2025-11-24, UNIX microseconds
    frames = []
    for i in range(800):  # 4 s at 200 Hz; a GPS_RAW_INT stamped in UTC at every 100th sample
        t_us = 1_000_000 + 5000 * i
        frames.append(_rest_imu(mav, t_us))
        if i % 100 == 50:
            frames.append(bytes(mavlink.MAVLink_gps_raw_int_message(
                utc0_us + t_us, 3, 470000000, 80000000, 400000 - int(geoid * 1000), 80, 120, 0, 0, 12, 400000,
                500, 800, 50, 100, 0).pack(mav)))  # alt AMSL, alt_ellipsoid
    got = _serve_in_process(PublishConfig(geoid_height=geoid, set_origin=True,
                                          odometry_frame=mavlink.MAV_FRAME_LOCAL_NED), frames,
                            lambda g: any(m.time_usec >= 4_900_000 for m in g.of("ODOMETRY")))
    origin = got.of("SET_GPS_GLOBAL_ORIGIN")
    assert len(origin) == 1
    o = origin[0]
    assert (o.target_system, o.latitude, o.longitude) == (7, 470000000, 80000000)
    assert o.altitude == round((400.0 - geoid) * 1000)  # AMSL mm
    times = got.of("SYSTEM_TIME")
    assert times
    for m in times:  # UTC of the solution = UTC of the fixes' clock at the sensor time it carries
        assert abs(m.time_unix_usec - (utc0_us + m.time_boot_ms * 1000)) <= 1000
    assert got.of("ODOMETRY") and all(m.frame_id == mavlink.MAV_FRAME_LOCAL_NED for m in got.of("ODOMETRY"))

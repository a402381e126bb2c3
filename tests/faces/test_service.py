"""mavins/service.py in this process: the live loop's own duties, over real UDP sockets on 127.0.0.1.

The service runs in a thread of the test (so a mutation run sees its code); a
pymavlink encoder feeds its listening link paced by the kernel's queue
(support.Feed), and a plain pymavlink client is its ``--out``. A test ends on
events: everything sent has been read, then the service is stopped and its
summary taken. Expected values come from what the test sent: the frames, their
sensor times and the UTC the GPS carried (GPS time from the calendar).
"""

from __future__ import annotations

import struct
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from support import EVENT_TIMEOUT_S, Feed, StampedReceiver, free_udp_port, udp_stats, wait_until

from mavins.live.livefilter import FilterSettings
from mavins.link import publish
from mavins.link.ingest import IngestConfig
from mavins.live.engine import EngineConfig
from mavins.service import Service, ServiceConfig, Summary

LAT, LON, ALT = 47.3977, 8.5456, 488.0
VEHICLE = 7  # the autopilot's system id
UNIX_2025 = 1735689600  # 2025-01-01T00:00:00Z
WEEK_2025, MS_2025 = 2347, 259_218_000  # GPS week and ms of week at that instant (18 leap seconds): the calendar


class Received(StampedReceiver):
    """Every message the service sent to its --out, in order."""

    def __init__(self) -> None:
        self.msgs: list[mavlink.MAVLink_message] = []
        self.groups: list[list[str]] = []  # the message names of each datagram, in order
        self.sizes: list[int] = []  # bytes of each datagram
        super().__init__()

    def datagram(self, arrival: float, data: bytes, msgs: list[mavlink.MAVLink_message]) -> None:
        self.sizes.append(len(data))
        self.groups.append([m.get_type() for m in msgs])
        super().datagram(arrival, data, msgs)

    def take(self, arrival: float, m: mavlink.MAVLink_message) -> None:
        if m.get_type() != "BAD_DATA":
            self.msgs.append(m)

    def of(self, name: str) -> list[mavlink.MAVLink_message]:
        return [m for m in list(self.msgs) if m.get_type() == name]


class Running:
    """A Service in a thread with a feed to its master link and a receiver on its --out."""

    def __init__(self, engine: EngineConfig | None = None, **cfg: object) -> None:
        self.port = free_udp_port()
        self.out = Received()
        engine = engine or EngineConfig(lat=LAT, lon=LON, alt=ALT, heading=30.0, align=0.5, rate=10.0,
                                        filter=FilterSettings(aiding=()))
        self.svc = Service(engine, IngestConfig(), ServiceConfig(
            master=f"udpin:127.0.0.1:{self.port}", outs=[f"udpout:127.0.0.1:{self.out.port}"], **cfg))  # type: ignore[arg-type]
        self.feed = Feed(self.port)
        self.sent: list[bytes] = []
        self.stop_event = threading.Event()
        self.failure: list[BaseException] = []
        self.summary: Summary | None = None
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        try:
            self.summary = self.svc.run(self.stop_event)
        except BaseException as exc:  # surfaced by stop()
            self.failure.append(exc)

    def mav(self, sysid: int = VEHICLE, compid: int = 1) -> mavlink.MAVLink:
        """An encoder whose frames go to the service (and are kept in ``sent``)."""
        run = self

        class Keep:
            def write(self, buf: bytes) -> None:
                run.sent.append(bytes(buf))
                run.feed.write(buf)

        return mavlink.MAVLink(Keep(), srcSystem=sysid, srcComponent=compid)

    def raw(self, data: bytes) -> None:
        """A datagram as it is, not a frame the encoder made."""
        self.feed.write(data)

    def read_all(self) -> None:
        """Wait until the service has read everything sent; a service thread that died fails at once."""
        def read() -> bool:
            if self.failure or not self.thread.is_alive():
                raise AssertionError(f"service thread died: {self.failure[0]!r}" if self.failure
                                     else "service thread ended")
            st = udp_stats(self.port)
            return st is None or st[0] == 0

        wait_until(read, f"everything sent to port {self.port} read")

    def stop(self) -> Summary:
        try:
            self.read_all()
        finally:
            self.stop_event.set()
            self.thread.join(EVENT_TIMEOUT_S)
            self.feed.sock.close()
            time.sleep(0.05)  # what the service sent last is on loopback already; let the reader take it
            self.out.close()
        assert not self.failure, f"service thread died: {self.failure[0]!r}"
        assert self.summary is not None
        return self.summary


def imu(mav: mavlink.MAVLink, t: float) -> None:
    """A level, resting HIGHRES_IMU at sensor time t (s)."""
    mav.highres_imu_send(int(round(t * 1e6)), 0.0, 0.0, -9.807, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4, 0.0, 0.0, 0.0, 20.0,
                         0b111111111, 0)


def autopilot_heartbeat(mav: mavlink.MAVLink) -> None:
    mav.heartbeat_send(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, mavlink.MAV_STATE_ACTIVE)


def test_frames_that_prove_nothing_are_counted_by_reason_and_kept_out_of_the_tlog(tmp_path: Path) -> None:
    run = Running(tlog=tmp_path / "in.tlog")
    mav = run.mav()
    autopilot_heartbeat(mav)
    good = run.sent[-1]
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    run.raw(bytes(bad_crc))
    run.raw(good[:-4])  # truncated: the length byte promises more than came
    run.raw(b"\x01\x02\x03 no frame here")
    unknown = bytearray(good)  # a MAVLink 2 frame with an id outside the dialect: its CRC cannot be checked
    unknown[7:10] = (0xABCDE).to_bytes(3, "little")
    run.raw(bytes(unknown))
    autopilot_heartbeat(mav)
    t0 = time.time()
    s = run.stop()
    t1 = time.time()
    c = s.counters
    assert c.get("rejected_bad_crc") == 1, c
    assert c.get("rejected_unknown_message") == 1, c
    assert c.get("rejected_truncated", 0) + c.get("rejected_garbage", 0) >= 1, c
    assert "rejected_bad_crc: 1" in s.lines()
    # the tlog: exactly the two heartbeats, each after an 8-byte big-endian UNIX stamp in microseconds
    data = (tmp_path / "in.tlog").read_bytes()
    frames = []
    while data:
        (stamp,) = struct.unpack(">Q", data[:8])
        n = len(good)
        frames.append((stamp, data[8:8 + n]))
        data = data[8 + n:]
    assert [f for _, f in frames] == [run.sent[0], run.sent[1]]
    assert all(1e6 * (t0 - 60.0) < st <= 1e6 * t1 for st, _ in frames)


def test_nothing_is_sent_until_an_autopilot_names_the_vehicle() -> None:
    """A GCS's or another companion's HEARTBEAT names no vehicle: until an autopilot's does (or its IMU
    stream), the service sends nothing, not even a TIMESYNC answer; then everything comes from its id."""
    run = Running()
    gcs = run.mav(sysid=255, compid=190)
    gcs.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    other = run.mav(sysid=42, compid=191)
    other.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    gcs.timesync_send(0, 1111)
    run.read_all()
    assert not run.svc._sysid_known
    mav = run.mav()
    autopilot_heartbeat(mav)
    gcs.timesync_send(0, 2222)
    for k in range(1, 101):
        imu(mav, k * 0.01)
    s = run.stop()
    msgs = list(run.out.msgs)
    assert {m.get_srcSystem() for m in msgs} == {VEHICLE}
    assert [m.ts1 for m in run.out.of("TIMESYNC")] == [2222]
    texts = [m.text for m in run.out.of("STATUSTEXT")]
    assert any("ALIGNING" in t for t in texts) and any("NAVIGATING" in t for t in texts), texts
    assert s.messages == 105 and s.state == "NAVIGATING"
    assert s.counters["imu_accepted"] == 100


def test_timesync_requests_are_answered_with_our_clock_in_ns_and_responses_are_not() -> None:
    run = Running()
    mav = run.mav()
    autopilot_heartbeat(mav)
    run.read_all()
    before = time.monotonic_ns()
    mav.timesync_send(0, 123_456_789)  # a request
    mav.timesync_send(555, 987_654_321)  # a response to someone: never answered
    mav.timesync_send(0, 31_415_926)
    run.read_all()
    after = time.monotonic_ns()
    run.stop()
    replies = run.out.of("TIMESYNC")
    assert [m.ts1 for m in replies] == [123_456_789, 31_415_926]
    assert all(before <= m.tc1 <= after for m in replies)


def test_status_utc_and_gps_time_follow_sensor_time_and_the_origin_goes_once() -> None:
    """ESTIMATOR_STATUS and SYSTEM_TIME once per second of sensor time, GPS_INPUT five times; UTC from the
    GPS's UNIX time; GPS week and milliseconds as the calendar gives them; one SET_GPS_GLOBAL_ORIGIN."""
    engine = EngineConfig(lat=LAT, lon=LON, alt=ALT, heading=30.0, align=0.5, rate=10.0)
    pub = publish.PublishConfig(gps_input=True, set_origin=True)
    run = Running(engine, publish=pub)
    mav = run.mav()
    autopilot_heartbeat(mav)
    t_end = 2.5
    for k in range(1, int(t_end * 100) + 1):
        t = k * 0.01
        imu(mav, t)
        if k % 20 == 0:  # 5 Hz GPS at rest, its time UNIX (UTC) microseconds: 2025-01-01 + t
            mav.gps_raw_int_send(int(round((UNIX_2025 + t) * 1e6)), 3, int(LAT * 1e7), int(LON * 1e7),
                                 int(ALT * 1e3), 100, 100, 0, 0, 12, int(ALT * 1e3), 500, 500, 300, 0, 0)
    run.stop()
    att = run.out.of("ATTITUDE")
    t_out = np.array([m.time_boot_ms for m in att]) * 1e-3
    assert len(att) > 10
    status = run.out.of("ESTIMATOR_STATUS")
    seconds = sorted({int(t) for t in t_out})
    assert [int(m.time_usec // 1_000_000) for m in status] == seconds
    times = run.out.of("SYSTEM_TIME")
    assert times, "no SYSTEM_TIME though the GPS carried UTC"
    for m in times:
        assert m.time_unix_usec == pytest.approx((UNIX_2025 + m.time_boot_ms * 1e-3) * 1e6, abs=2.0)
    fifths = sorted({int(t * 5.0) for t in t_out})
    gps = run.out.of("GPS_INPUT")
    assert [int(m.time_usec * 5 // 1_000_000) for m in gps] == fifths
    with_time = [m for m in gps if m.time_week != 0]
    assert with_time, "GPS_INPUT never carried the GPS time"
    for m in with_time:
        assert m.time_week == WEEK_2025
        assert m.time_week_ms == pytest.approx(MS_2025 + m.time_usec * 1e-3, abs=1.0)
    origin = run.out.of("SET_GPS_GLOBAL_ORIGIN")
    assert len(origin) == 1
    o = origin[0]
    assert o.target_system == VEHICLE
    assert (o.latitude, o.longitude, o.altitude) == (round(LAT * 1e7), round(LON * 1e7), round(ALT * 1e3))


def test_solution_file_and_summary_count_every_published_set(tmp_path: Path) -> None:
    run = Running(solution=tmp_path / "nav.csv")
    mav = run.mav()
    autopilot_heartbeat(mav)
    for k in range(1, 201):
        imu(mav, k * 0.01)
    s = run.stop()
    rows = np.loadtxt(tmp_path / "nav.csv", delimiter=",", skiprows=1, ndmin=2)
    att = run.out.of("ATTITUDE")
    # aligned over 0.5 s, then 10 Hz of sensor time up to 2.0 s
    assert s.outputs == len(rows) == len(att) == pytest.approx(15, abs=1)
    assert np.allclose(rows[:, 0], [m.time_boot_ms * 1e-3 for m in att], atol=1e-3)
    assert s.lines()[:3] == [f"messages received: {s.messages}", f"output sets published: {s.outputs}",
                             "final state: NAVIGATING"]


def test_the_solution_file_is_written_while_the_service_runs(tmp_path: Path) -> None:
    """Rows are kept in blocks and flushed with each heartbeat (once a second of wall time): a reader of
    the file sees every published set without waiting for the service to stop."""
    nav = tmp_path / "nav.csv"
    run = Running(solution=nav)
    mav = run.mav()
    autopilot_heartbeat(mav)
    for k in range(1, 201):
        imu(mav, k * 0.01)
    run.read_all()
    att = wait_until(lambda: len(run.out.of("ATTITUDE")) >= 14 and run.out.of("ATTITUDE"), "the output sets")
    rows = wait_until(lambda: nav.exists() and nav.read_text().count("\n") - 1 >= len(att) and nav.read_text(),
                      "every published set in the file while the service runs")
    assert run.thread.is_alive()  # still serving: the rows came from the flush, not from closing
    s = run.stop()
    assert rows.count("\n") - 1 == s.outputs


def test_an_output_set_goes_out_as_one_datagram_in_the_documented_order() -> None:
    run = Running()
    mav = run.mav()
    autopilot_heartbeat(mav)
    for k in range(1, 201):
        imu(mav, k * 0.01)
    s = run.stop()
    sets = [g for g in run.out.groups if "ATTITUDE" in g]
    assert len(sets) == s.outputs == pytest.approx(15, abs=1)
    five = ["ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ODOMETRY"]
    assert all(g[:5] == five for g in sets)  # the whole set, in one datagram (docs/service.md)
    assert max(run.out.sizes) <= 1472  # an Ethernet frame's UDP payload: never fragmented


def test_sys_status_reports_the_imu_healthy_once_navigating_and_the_rejections() -> None:
    run = Running()
    mav = run.mav()
    autopilot_heartbeat(mav)
    bad = bytearray(run.sent[-1])
    bad[-2] ^= 0x55
    for _ in range(3):
        run.raw(bytes(bad))
    for k in range(1, 101):
        imu(mav, k * 0.01)
    run.read_all()
    imu_bits = mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    mark = len(run.out.msgs)

    def status_after() -> list:
        return [m for m in list(run.out.msgs)[mark:] if m.get_type() == "SYS_STATUS"]

    got = wait_until(status_after, "a SYS_STATUS after the input was read", timeout=30.0)  # it comes every 1 s
    run.stop()
    m = got[0]
    assert m.onboard_control_sensors_present == imu_bits
    assert m.onboard_control_sensors_health == imu_bits
    assert m.errors_comm == 3  # rejected frames (docs/service.md)
    assert m.drop_rate_comm == 0 and m.errors_count1 == 0 and m.errors_count3 == 0
    assert 0 <= m.load <= 1000

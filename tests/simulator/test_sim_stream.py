"""The simulator's MAVLink stream (sim.stream), decoded by plain pymavlink.

* End to end over UDP on localhost: ``sim.stream.stream`` (udpout) paced at
  20x real time into ``mavutil.mavlink_connection("udpin:...")``; every
  message is checked against the run it came from: ids, units, scaling,
  timestamps (sensor time), rates (per second of sensor time) and order, and
  no message leaves before its time at 20x (a bound a busy machine can only
  widen). The receiving socket has room for the whole stream; should the
  kernel still drop a datagram there (its drop counter says so), the run is
  repeated, since that loss is the test's, not the stream's.
* Values through ``sim.stream.frames`` packed to bytes and parsed back by a
  separate pymavlink parser: RAW_IMU scaling, rounding and clipping, and
  instantaneous ('sampled') against interval-averaged HIGHRES_IMU against
  closed forms.

Units (MAVLink common dialect): HIGHRES_IMU m/s^2 and rad/s (float32), RAW_IMU
mG and mrad/s (int16, ArduPilot's scaling, G0 = 9.80665), SIM_STATE
quaternion w,x,y,z, lat/lon float degrees and lat_int/lon_int degE7.
"""

from __future__ import annotations

import dataclasses
import math
import os
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink2  # noqa: E402

from mavins.cli import main as cli_main  # noqa: E402
from support import EVENT_TIMEOUT_S, kernel_drops, roomy  # noqa: E402
from sim import errors  # noqa: E402
from sim.generate import SimRun, generate  # noqa: E402
from sim.scenarios import load  # noqa: E402
from sim.stream import StreamOptions, frames, stream  # noqa: E402
from sim.trajectory import instant_rates  # noqa: E402

G0 = 9.80665
A_WGS, F_WGS = 6378137.0, 1.0 / 298.257223563
E2 = F_WGS * (2.0 - F_WGS)

MOVING = """
description = "turning, climbing, vibrating: every stream field changes"
[start]
lat = 47.397742
lon = 8.545594
h = 488.0
yaw = 20.0
speed = 12.0
[imu]
rate = 100.0
[[segments]]
kind = "turn"
angle = 60.0
rate = 30.0
ramp = 0.5
[[segments]]
kind = "climb"
height = 3.0
rate = 2.0
accel = 2.0
[[perturbations]]
kind = "angular_vibration"
axis = [1.0, 0.0, 0.0]
amplitude = 0.3
freq = 4.0
"""

VIBRATION_LAB = """
description = "laboratory mode: level, static, pitch vibration"
[start]
lat = 45.0
lon = 7.0
h = 100.0
[imu]
rate = 100.0
earth = "none"
[[segments]]
kind = "static"
duration = 1.0
[[perturbations]]
kind = "angular_vibration"
axis = [0.0, 1.0, 0.0]
amplitude = 1.0
freq = 5.0
"""


def f32(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float32)


@pytest.fixture(scope="module")
def scenario_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("scenarios")
    (d / "moving.toml").write_text(MOVING)
    (d / "vibration_lab.toml").write_text(VIBRATION_LAB)
    return d


@pytest.fixture(scope="module")
def moving(scenario_dir) -> SimRun:
    return generate(load(str(scenario_dir / "moving.toml")), duration=3.0)


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclasses.dataclass
class Received:
    msgs: list  # every message, in order of arrival
    out: object  # what send() returned
    elapsed: list[float]  # per message: monotonic seconds from just before send() started to its receipt
    dropped: int  # datagrams the kernel dropped at the receiving socket (the test's own loss)


def _receive(send, port: int, timeout: float = EVENT_TIMEOUT_S) -> Received:
    """Run send() in a thread while a plain pymavlink udpin connection collects every message."""
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="ardupilotmega")
    roomy(rx.port)
    result: dict = {}
    th = threading.Thread(target=lambda: result.setdefault("out", send()), daemon=True)
    msgs, elapsed = [], []
    t0 = time.monotonic()
    th.start()
    deadline = t0 + timeout
    try:
        while time.monotonic() < deadline:
            m = rx.recv_match(blocking=True, timeout=0.3)
            if m is None:
                if not th.is_alive():
                    break
                continue
            assert m.get_type() != "BAD_DATA", m
            msgs.append(m)
            elapsed.append(time.monotonic() - t0)
        dropped = kernel_drops(port)
    finally:
        th.join(timeout=EVENT_TIMEOUT_S)
        rx.close()
    assert not th.is_alive(), "the sender did not finish"
    return Received(msgs, result.get("out"), elapsed, dropped)


def _sensor_times(msgs: list, kind: str) -> np.ndarray:
    """time_usec of the IMU message sent at the same instant as each message of `kind`.

    frames() sends, per instant: HEARTBEAT, the IMU message, SIM_STATE, ATTITUDE,
    GPS_RAW_INT, SCALED_PRESSURE (those due). HEARTBEAT comes before its IMU message.
    """
    out = []
    for i, m in enumerate(msgs):
        if m.get_type() != kind:
            continue
        step = 1 if kind == "HEARTBEAT" else -1
        j = i + step
        while msgs[j].get_type() not in ("HIGHRES_IMU", "RAW_IMU"):
            j += step
        out.append(msgs[j].time_usec)
    return np.array(out, dtype=np.int64)


def _every_usec(t_usec: np.ndarray, rate: float) -> np.ndarray:
    """First sample, then the first sample at or after each multiple of 1/rate (integer arithmetic)."""
    period = int(round(1e6 / rate))
    k = t_usec // period
    return t_usec[np.concatenate(([True], k[1:] != k[:-1]))]


def test_udp_stream_end_to_end(moving: SimRun) -> None:
    opts = StreamOptions(speed=20.0, sysid=42)
    for _ in range(3):
        port = _free_udp_port()
        rec = _receive(lambda: stream(moving, f"udpout:127.0.0.1:{port}", opts), port)
        # everything sent arrived, or the kernel counted what the test's socket lost
        assert rec.out.messages == len(rec.msgs) + rec.dropped
        if rec.dropped == 0:
            break
    assert rec.dropped == 0, "the test's receiving socket lost datagrams in three runs (kernel drop count)"
    msgs, stats = rec.msgs, rec.out
    n = len(moving.t)
    t_usec = np.round(moving.t * 1e6).astype(np.int64)
    by = lambda kind: [m for m in msgs if m.get_type() == kind]  # noqa: E731

    # nothing lost, in order, MAVLink 2, identity
    assert stats.messages == len(msgs) and stats.imu_messages == n
    seq = np.array([m.get_seq() for m in msgs])
    assert np.all(np.diff(seq) % 256 == 1)
    assert all(m.get_srcSystem() == 42 and m.get_srcComponent() == mavlink2.MAV_COMP_ID_AUTOPILOT1 for m in msgs)
    assert all(m.get_msgbuf()[0] == mavlink2.PROTOCOL_MARKER_V2 for m in msgs)
    # paced on sensor time at 20x: no sample leaves before (t - t0) / 20 after the stream started
    # (received later than sent; a busy machine only delays)
    due = np.array([(m.time_usec * 1e-6 - moving.exact.t0) / 20.0 for m in msgs if m.get_type() == "HIGHRES_IMU"])
    got = np.array([e for e, m in zip(rec.elapsed, msgs) if m.get_type() == "HIGHRES_IMU"])
    assert np.all(got >= due - 1e-5), float(np.min(got - due))

    # HIGHRES_IMU: one per sample, time_usec = round(t * 1e6), averaged rates as float32, SI units
    imu = by("HIGHRES_IMU")
    assert len(imu) == n
    assert np.array_equal([m.time_usec for m in imu], t_usec)
    w, f = moving.rates()
    got = np.array([[m.xacc, m.yacc, m.zacc, m.xgyro, m.ygyro, m.zgyro] for m in imu])
    assert np.array_equal(got.astype(np.float32), f32(np.column_stack([f, w])))
    assert all(m.fields_updated == 0b111111 and m.id == 0 for m in imu)
    # specific force in FRD: -g on z level, -g/cos(32 deg) = -11.6 in the banked turn, -(g + 2) climbing
    assert np.all((got[:, 2] < -9.7) & (got[:, 2] > -12.0))

    # HEARTBEAT at 1 Hz of sensor time
    hb = by("HEARTBEAT")
    assert np.array_equal(_sensor_times(msgs, "HEARTBEAT"), _every_usec(t_usec, 1.0))
    assert len(hb) == 4  # t = 0.01, 1, 2, 3 s
    assert all(m.type == mavlink2.MAV_TYPE_QUADROTOR and m.autopilot == mavlink2.MAV_AUTOPILOT_GENERIC for m in hb)

    # SIM_STATE straight after the IMU message of the same instant, at 50 Hz, carrying that instant's truth
    idx = [i for i, m in enumerate(msgs) if m.get_type() == "SIM_STATE"]
    assert all(msgs[i - 1].get_type() == "HIGHRES_IMU" for i in idx)
    assert np.array_equal(_sensor_times(msgs, "SIM_STATE"), _every_usec(t_usec, 50.0))
    assert stats.truth_messages == len(idx) == 151
    truth = moving.exact.truth
    for i in idx:
        s, m_imu = msgs[i], msgs[i - 1]
        k = int(np.searchsorted(t_usec, m_imu.time_usec)) + 1  # truth row (row 0 = initial state)
        row = truth[k]
        assert np.array_equal(f32([s.q1, s.q2, s.q3, s.q4]), f32(row[10:14]))
        assert np.array_equal(f32([s.roll, s.pitch, s.yaw]), f32(np.radians(row[7:10])))
        assert np.array_equal(f32([s.lat, s.lon, s.alt]), f32(row[1:4]))  # degrees, degrees, m
        assert (s.lat_int, s.lon_int) == (round(row[1] * 1e7), round(row[2] * 1e7))
        assert np.array_equal(f32([s.vn, s.ve, s.vd]), f32(row[4:7]))
        assert np.array_equal(f32([s.xacc, s.yacc, s.zacc, s.xgyro, s.ygyro, s.zgyro]),
                              f32([m_imu.xacc, m_imu.yacc, m_imu.zacc, m_imu.xgyro, m_imu.ygyro, m_imu.zgyro]))
    # quaternion order w, x, y, z: q1 is the scalar part
    s0 = msgs[idx[0]]
    assert abs(s0.q1) > 0.9 and np.isclose(np.hypot(s0.q1, s0.q4), 1.0, atol=0.01)  # level, yawed 20 deg

    # ATTITUDE at 10 Hz: the vehicle's attitude, time_boot_ms = time_usec // 1000
    att = by("ATTITUDE")
    times = _sensor_times(msgs, "ATTITUDE")
    assert np.array_equal(times, _every_usec(t_usec, 10.0)) and len(att) == 31
    for m, tu in zip(att, times):
        row = truth[int(np.searchsorted(t_usec, tu)) + 1]
        assert m.time_boot_ms == tu // 1000
        assert np.array_equal(f32([m.roll, m.pitch, m.yaw]), f32(np.radians(row[14:17])))

    # GPS_RAW_INT at 5 Hz, 3D fix, degE7 / mm / cm/s / cdeg, noise 0.5 m horizontal and 1 m vertical (1 sigma)
    gps = by("GPS_RAW_INT")
    times = _sensor_times(msgs, "GPS_RAW_INT")
    assert np.array_equal(times, _every_usec(t_usec, 5.0)) and len(gps) == 16
    for m, tu in zip(gps, times):
        row = truth[int(np.searchsorted(t_usec, tu)) + 1]
        assert m.time_usec == tu and m.fix_type == 3 and m.satellites_visible == 12
        lat = math.radians(row[1])
        rn = A_WGS * (1 - E2) / (1 - E2 * math.sin(lat) ** 2) ** 1.5
        re = A_WGS / math.sqrt(1 - E2 * math.sin(lat) ** 2)
        assert abs(math.radians(m.lat * 1e-7 - row[1]) * rn) < 5 * 0.5 + 0.02
        assert abs(math.radians(m.lon * 1e-7 - row[2]) * re * math.cos(lat)) < 5 * 0.5 + 0.02
        assert abs(m.alt / 1000 - row[3]) < 5 * 1.0 and m.alt_ellipsoid == m.alt
        assert m.vel == round(math.hypot(row[4], row[5]) * 100)
        assert m.cog == round(((math.degrees(math.atan2(row[5], row[4])) + 360) % 360) * 100) % 36000
        assert (m.eph, m.epv) == (80, 120)

    # SCALED_PRESSURE at 10 Hz: standard atmosphere at the truth height, hPa, 0.012 hPa noise
    baro = by("SCALED_PRESSURE")
    times = _sensor_times(msgs, "SCALED_PRESSURE")
    assert np.array_equal(times, _every_usec(t_usec, 10.0)) and len(baro) == 31
    for m, tu in zip(baro, times):
        row = truth[int(np.searchsorted(t_usec, tu)) + 1]
        assert m.time_boot_ms == tu // 1000 and m.temperature == 2000
        assert abs(m.press_abs - 1013.25 * (1 - 2.25577e-5 * row[3]) ** 5.25588) < 5 * 0.012


def _decode(mav_msgs: list) -> list:
    """Pack with one MAVLink 2 instance and parse back with a separate, plain pymavlink parser."""
    tx = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    rx = mavlink2.MAVLink(None)
    out = []
    for m in mav_msgs:
        out.extend(rx.parse_buffer(m.pack(tx)) or [])
    return out


def test_raw_imu_scaling_rounding_clipping(moving: SimRun) -> None:
    """RAW_IMU: int16 mG (G0 = 9.80665) and mrad/s, rounded to nearest, clipped at the int16 range."""
    # first row set to values straddling the rounding points, and beyond the int16 range
    dt0 = moving.t[0] - moving.exact.t0
    f_mg = np.array([0.49, -0.51, 40000.0])
    w_mrad = np.array([1.5001, -2.4999, -50000.0])
    dv = moving.dv.copy()
    dth = moving.dtheta.copy()
    dv[0] = f_mg * G0 / 1000 * dt0
    dth[0] = w_mrad / 1000 * dt0
    run = dataclasses.replace(moving, dv=dv, dtheta=dth)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    sent = [m for _, ms in frames(run, mav, StreamOptions(msg="raw", speed=None)) for m in ms]
    raw = [m for m in _decode(sent) if m.get_type() == "RAW_IMU"]
    assert len(raw) == len(run.t)
    assert (raw[0].xacc, raw[0].yacc, raw[0].zacc) == (0, -1, 32767)
    assert (raw[0].xgyro, raw[0].ygyro, raw[0].zgyro) == (2, -2, -32768)
    w, f = run.rates()
    acc = np.array([[m.xacc, m.yacc, m.zacc] for m in raw[1:]])
    gyr = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in raw[1:]])
    assert np.all(np.abs(acc - f[1:] / (G0 / 1000)) <= 0.5 + 1e-9)
    assert np.all(np.abs(gyr - w[1:] * 1000) <= 0.5 + 1e-9)
    assert np.all((acc[:, 2] <= -990) & (acc[:, 2] > -12.0 / G0 * 1000))  # -1 g .. -1.22 g, as above
    assert np.array_equal([m.time_usec for m in raw], np.round(run.t * 1e6).astype(np.int64))
    assert all(m.id == 0 and (m.xmag, m.ymag, m.zmag) == (0, 0, 0) for m in raw)
    assert not any(m.get_type() == "HIGHRES_IMU" for m in _decode(sent))


def test_sampled_and_averaged_highres_imu(scenario_dir) -> None:
    """'sampled' HIGHRES_IMU = the instantaneous rates at the sample time; 'averaged' = increment / dt.

    Pitch vibration phi = A sin(Wt) in laboratory mode: sampled ygyro = A W cos(Wt),
    averaged ygyro = A [sin(Wt)] / dt; f = [g sin(phi), 0, -g cos(phi)] at the instant.
    They differ by about A W (W dt / 2) = 0.086 rad/s here.
    """
    run = generate(load(str(scenario_dir / "vibration_lab.toml")))
    amp, w = math.radians(1.0), 2 * math.pi * 5.0
    lat = math.radians(45.0)
    s2 = math.sin(lat) ** 2
    g = 9.7803253359 * (1 + 0.00193185265241 * s2) / math.sqrt(1 - E2 * s2)
    g *= 1 - 2 / A_WGS * (1 + F_WGS + 0.00344978650684 - 2 * F_WGS * s2) * 100.0 + 3 * 100.0**2 / A_WGS**2
    t = run.t
    tp = np.concatenate(([run.exact.t0], t))
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    decoded = {}
    for mode in ("sampled", "averaged"):
        sent = [m for _, ms in frames(run, mav, StreamOptions(imu_rates=mode, speed=None)) for m in ms]
        imu = [m for m in _decode(sent) if m.get_type() == "HIGHRES_IMU"]
        decoded[mode] = np.array([[m.xacc, m.yacc, m.zacc, m.xgyro, m.ygyro, m.zgyro] for m in imu])
    samp, avg = decoded["sampled"], decoded["averaged"]
    phi = amp * np.sin(w * t)
    assert np.allclose(samp[:, 4], amp * w * np.cos(w * t), rtol=0, atol=2e-8)  # float32 of ~0.55 rad/s
    assert np.allclose(samp[:, [0, 2]], np.column_stack([g * np.sin(phi), -g * np.cos(phi)]), rtol=0, atol=1e-6)
    w_inst, f_inst = instant_rates(run.exact)
    assert np.array_equal(samp.astype(np.float32), f32(np.column_stack([f_inst, w_inst])))
    assert np.allclose(avg[:, 4], amp * np.diff(np.sin(w * tp)) / np.diff(tp), rtol=0, atol=2e-8)
    assert np.max(np.abs(samp[:, 4] - avg[:, 4])) == pytest.approx(amp * w * (w * 0.01 / 2), rel=0.02)


def test_sampled_rates_carry_the_sensor_errors(moving: SimRun, scenario_dir) -> None:
    """Noisy grade: timestamps carry the jitter (time_usec = round(t * 1e6) of the reported times);
    sampled rates = instantaneous truth + the increments' error / the true interval."""
    run = generate(load(str(scenario_dir / "moving.toml")), duration=1.0, grade="tactical", seed=5)
    assert run.kept.all() and not np.array_equal(run.t, run.exact.t)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    sent = [m for _, ms in frames(run, mav, StreamOptions(imu_rates="sampled", speed=None)) for m in ms]
    imu = [m for m in _decode(sent) if m.get_type() == "HIGHRES_IMU"]
    assert np.array_equal([m.time_usec for m in imu], np.round(run.t * 1e6).astype(np.int64))
    w_inst, f_inst = instant_rates(run.exact)
    dt = np.diff(np.concatenate(([run.exact.t0], run.exact.t)))[:, None]
    expect = np.column_stack([f_inst + (run.dv - run.exact.dv) / dt, w_inst + (run.dtheta - run.exact.dtheta) / dt])
    got = np.array([[m.xacc, m.yacc, m.zacc, m.xgyro, m.ygyro, m.zgyro] for m in imu])
    assert np.array_equal(got.astype(np.float32), f32(expect))


def test_averaged_rate_after_a_drop(moving: SimRun) -> None:
    model = errors.ImuErrorModel(drop_probability=0.2)
    t, dth, dv, kept = errors.apply(model, moving.exact.t, moving.exact.dtheta, moving.exact.dv, 1,
                                    t_start=moving.exact.t0)
    assert not kept.all()
    run = dataclasses.replace(moving, t=t, dtheta=dth, dv=dv, kept=kept)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    imu = [m for _, ms in frames(run, mav, StreamOptions(speed=None)) for m in ms if m.get_type() == "HIGHRES_IMU"]
    zacc = np.array([m.zacc for m in imu])
    dt = np.diff(np.concatenate(([moving.exact.t0], moving.exact.t)))[kept]
    assert np.allclose(zacc, f32(moving.exact.dv[kept, 2] / dt), rtol=1e-6)


def test_cli_stream_raw(tmp_path) -> None:
    """`mavins sim static --stream udpout:... --msg raw --speed max --sysid 7`: every sample arrives as RAW_IMU."""
    port = _free_udp_port()
    argv = ["sim", "static", "--stream", f"udpout:127.0.0.1:{port}", "--duration", "1", "--rate", "100",
            "--msg", "raw", "--speed", "max", "--sysid", "7"]
    rec = _receive(lambda: cli_main(argv), port)
    msgs, rc = rec.msgs, rec.out
    assert rc == 0 and rec.dropped == 0
    raw = [m for m in msgs if m.get_type() == "RAW_IMU"]
    assert len(raw) == 100 and all(m.get_srcSystem() == 7 for m in msgs)
    assert [m.time_usec for m in raw] == [10000 * (k + 1) for k in range(100)]
    assert not any(m.get_type() == "HIGHRES_IMU" for m in msgs)


def test_extra_imus_and_the_service_selects_one() -> None:
    """--imus 3: HIGHRES_IMU ids 0, 1, 2 (or RAW_IMU + SCALED_IMU2/3), each with its own errors;
    the service's ingest picks one IMU by message and id and navigates on it."""
    from mavins.live.engine import EngineConfig
    from mavins.link.ingest import IngestConfig
    from mavins.live.pipeline import Pipeline

    run = generate(load("static"), duration=12.0, rate=100.0, grade="industrial", seed=3)
    for msg, names in (("highres", {"HIGHRES_IMU"}), ("raw", {"RAW_IMU", "SCALED_IMU2", "SCALED_IMU3"})):
        enc = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        out = [m for _, ms in frames(run, enc, StreamOptions(msg=msg, imus=3)) for m in ms]
        imu = [m for m in out if m.get_type() in names]
        assert len(imu) == 3 * len(run.t)
        if msg == "highres":
            by_id = {k: np.array([[m.xgyro, m.ygyro, m.zgyro] for m in imu if m.id == k]) for k in (0, 1, 2)}
            assert all(len(v) == len(run.t) for v in by_id.values())
            # same motion, independent errors: different draws, same order of magnitude
            assert not np.array_equal(by_id[1], by_id[2])
            assert np.max(np.abs(by_id[1] - by_id[0])) < 0.05
        else:
            s2 = [m for m in imu if m.get_type() == "SCALED_IMU2"]
            assert len(s2) == len(run.t) and all(isinstance(m.xacc, int) for m in s2)
            assert abs(np.mean([m.zacc for m in s2]) + 1000 * 9.8 / 9.80665) < 30  # about -1 g in mG
        init = run.init()
        for message, imu_id in (("HIGHRES_IMU", 1), ("SCALED_IMU2", None)):
            if (message == "HIGHRES_IMU") != (msg == "highres"):
                continue
            p = Pipeline(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading=init.yaw, align=2.0),
                         IngestConfig(message=message, imu_id=imu_id))
            dec = mavlink2.MAVLink(None)
            outs = [o for m in out for mm in dec.parse_buffer(m.pack(enc)) or [] if (o := p.handle(mm)) is not None]
            assert p.ingest.locked_message == message and p.ingest.locked_id == (imu_id or 0)
            assert p.ingest.accepted == len(run.t) and p.ingest.rejected["other_imu"] == 2 * len(run.t)
            assert outs and abs(math.degrees(outs[-1].row[7])) < 1.0  # levelled, static: roll stays near 0


def test_highres_imu_carries_the_magnetometer_at_its_rate(moving: SimRun) -> None:
    """With mag_rate 10 Hz the first HIGHRES_IMU (id 0) of every 0.1 s carries the magnetometer in gauss with
    fields_updated bits 6-8 set (PX4's mark of a new sample); the others carry zeros without those bits. The
    field is the simulator's 48 uT at declination 2 deg and inclination 63 deg (NED), seen through the truth
    attitude, C_n^b m^n, plus 0.3 uT (0.003 G) of noise per axis: the residual's RMS lies within 20 % of it."""
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    sent = [m for _, ms in frames(moving, mav, StreamOptions(speed=None, mag_rate=10.0)) for m in ms]
    hi = [m for m in _decode(sent) if m.get_type() == "HIGHRES_IMU"]
    assert len(hi) == len(moving.t)
    with_mag = [k for k, m in enumerate(hi) if m.fields_updated & 0b111000000]
    assert all(hi[k].fields_updated == 0b111111111 for k in with_mag)
    assert all(m.fields_updated == 0b111111 and (m.xmag, m.ymag, m.zmag) == (0, 0, 0)
               for k, m in enumerate(hi) if k not in set(with_mag))
    t = moving.t[with_mag]
    assert len(with_mag) == len(np.unique(np.floor(moving.t * 10.0 + 1e-9)))  # one per 0.1 s of sensor time
    assert np.all(np.diff(np.floor(t * 10.0 + 1e-9)) == 1)
    d, i = math.radians(2.0), math.radians(63.0)
    m_n = 48.0 * np.array([math.cos(i) * math.cos(d), math.cos(i) * math.sin(d), math.sin(i)])
    res = []
    for k in with_mag:
        w, x, y, z = moving.exact.truth[1:][moving.kept][k, 10:14]
        c = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])  # C_b^n
        m = hi[k]
        res.append(np.array([m.xmag, m.ymag, m.zmag]) * 100.0 - c.T @ m_n)  # gauss -> uT
    rms = math.sqrt(np.mean(np.array(res) ** 2))
    assert 0.8 * 0.3 < rms < 1.2 * 0.3, rms


def test_the_service_aids_with_the_streamed_magnetometer() -> None:
    """The streamed magnetometer reaches the live filter: a Pipeline (ingest, engine and filter, as `mavins run`
    builds it) fed the decoded stream of the flight's first 4 s (at rest) with --aiding mag applies every
    streamed sample (10 Hz: each one is on the live path's 20 ms grid) after navigation starts (the first solution;
    the one at that instant may come before the filter does), all accepted; without mag_rate none."""
    from mavins.live.livefilter import FilterSettings
    from mavins.live.engine import EngineConfig
    from mavins.live.pipeline import Pipeline

    run = generate(load("flight"), duration=4.0, usec_grid=True)
    init = run.init()
    counts = []
    for rate in (10.0, 0.0):
        mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        sent = [m for _, ms in frames(run, mav, StreamOptions(speed=None, mag_rate=rate)) for m in ms]
        p = Pipeline(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading=init.yaw, align=1.0,
                                  declination=2.0, filter=FilterSettings(spec="navigation", aiding=("mag",))))
        first = None  # sensor time (s) of the first solution: navigation, and the filter, from there
        mags = []
        for m in _decode(sent):
            if m.get_type() == "HIGHRES_IMU" and m.fields_updated & 0b111000000:
                mags.append(m.time_usec * 1e-6)
            sol = p.handle(m)
            if sol is not None and first is None:
                first = m.time_usec * 1e-6
        f = p.engine.filter.counters
        counts.append((f["mag_accepted"], f["mag_rejected"], sum(t > first for t in mags)))
    assert counts[1][:2] == (0, 0)
    accepted, rejected, after = counts[0]
    assert rejected == 0 and after >= 10 and after - 1 <= accepted <= after, counts


def test_pieces_stream_the_messages_of_the_whole_run(scenario_dir) -> None:
    """A run made in pieces (generate_chunks: 4,096 rows, then 16,384) gives frames() the same messages,
    byte for byte, as the run made at once: sensor errors, drops, extra IMUs, magnetometer, GPS and baro
    noise and the message rates carried across the pieces' seams (consumer grade: jitter and drops)."""
    from sim.generate import generate_chunks

    sc = load(str(scenario_dir / "moving.toml"))
    kw = dict(duration=250.0, grade="consumer", seed=1, usec_grid=True, imus=2)  # seed 1 drops 4 rows
    opts = StreamOptions(speed=None, imus=2, mag_rate=7.0, gps_rate=3.0)
    pieces = list(generate_chunks(sc, **kw))
    assert [len(p.exact.t) for p in pieces] == [4096, 16384, 4520]
    whole = generate(sc, **kw)
    assert np.count_nonzero(~whole.kept) > 0

    def packed(src) -> list[bytes]:
        mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        return [m.pack(mav) for _, ms in frames(src, mav, opts) for m in ms]

    assert packed(iter(pieces)) == packed(whole)


def test_gnss_latency_sends_each_fix_late_and_stamps_it_when_sent(scenario_dir) -> None:
    """StreamOptions.gnss_latency (``--gnss-latency MS``): every fix of the run without latency comes, with
    the same content (the same noise draws), in the frame of the first IMU sample at or after its own time
    plus the latency, stamped with that sample's time; none is lost across the pieces' seams; 0 changes
    nothing."""
    from sim.generate import generate_chunks

    sc = load(str(scenario_dir / "moving.toml"))
    kw = dict(duration=60.0, grade="ideal", seed=1, usec_grid=True)  # 6,000 rows: two pieces

    def gps(src, latency: float) -> list[tuple[float, object]]:
        mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        opts = StreamOptions(speed=None, gnss_latency=latency)
        return [(t, m) for t, ms in frames(src, mav, opts) for m in ms if m.get_type() == "GPS_RAW_INT"]

    run = generate(sc, **kw)
    on_time, late = gps(run, 0.0), gps(run, 0.2)
    assert [m.time_usec for t, m in on_time] == [int(round(t * 1e6)) for t, _ in on_time]
    t_imu = run.t
    due = [t + 0.2 for t, _ in on_time if t + 0.2 <= t_imu[-1] + 1e-9]
    assert len(late) == len(due) > 100
    for (t_sent, m), (_, m0), d in zip(late, on_time, due):
        first = t_imu[np.searchsorted(t_imu, d - 1e-9)]
        assert t_sent == first and m.time_usec == int(round(first * 1e6))
        assert (m.lat, m.lon, m.alt, m.vel, m.cog) == (m0.lat, m0.lon, m0.alt, m0.vel, m0.cog)
    chunks = list(generate_chunks(sc, **kw))
    assert len(chunks) > 1  # seams to cross
    pieces = gps(iter(chunks), 0.2)
    assert [(t, m.time_usec, m.lat) for t, m in pieces] == [(t, m.time_usec, m.lat) for t, m in late]


def test_gnss_heading_is_the_vehicles_yaw_plus_its_stated_noise(scenario_dir) -> None:
    """StreamOptions.gnss_heading (``--gnss-heading SIGMA_DEG``): each GPS_RAW_INT's ``yaw`` (cdeg, 36000 for
    north, 0 never) is the vehicle's true yaw plus N(0, sigma) and ``hdg_acc`` states sigma in degE5; the
    errors' sample sigma lies in its chi band (two-sided 1e-3); the fixes themselves are those of a stream
    without it (their noise is drawn apart); without it ``yaw`` is 0, not available."""
    sc = load(str(scenario_dir / "moving.toml"))
    run = generate(sc, duration=300.0, grade="ideal", seed=2, usec_grid=True)

    def gps(opts: StreamOptions) -> list[tuple[float, object]]:
        mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        return [(t, m) for t, ms in frames(run, mav, opts) for m in ms if m.get_type() == "GPS_RAW_INT"]

    sigma = 0.5
    with_h = gps(StreamOptions(speed=None, gnss_heading=math.radians(sigma)))
    plain = gps(StreamOptions(speed=None))
    assert [(m.lat, m.lon, m.alt, m.vel, m.cog) for _, m in with_h] == [(m.lat, m.lon, m.alt, m.vel, m.cog)
                                                                          for _, m in plain]
    assert all(m.yaw == 0 for _, m in plain)
    assert all(0 < m.yaw <= 36000 and m.hdg_acc == 50000 for _, m in with_h)
    truth = run.exact.truth
    t_all = np.concatenate(([run.exact.t0], run.exact.t))
    true = np.interp([t for t, _ in with_h], t_all, np.unwrap(np.radians(truth[:, 16])))
    err = np.degrees(np.angle(np.exp(1j * (np.radians([m.yaw / 100.0 for _, m in with_h]) - true))))
    n = len(err)
    assert n > 1000
    c_lo, c_hi = 2.0 / (9.0 * (n - 1)), 3.290526731491926  # Wilson-Hilferty; z of 1e-3 two-sided
    lo = math.sqrt((1.0 - c_lo - c_hi * math.sqrt(c_lo)) ** 3)
    hi = math.sqrt((1.0 - c_lo + c_hi * math.sqrt(c_lo)) ** 3)
    assert lo < np.std(err, ddof=1) / sigma < hi, np.std(err, ddof=1)
    assert abs(np.mean(err)) < 4.0 * sigma / math.sqrt(n)


def test_stream_sends_before_the_last_piece_is_made(scenario_dir) -> None:
    """stream() of pieces sends the first piece's messages while the next ones are still being made: the
    pieces' source here refuses to make its last piece until a message has arrived at the receiver, so a
    stream that waited for every piece first would never send one (the wait would time out)."""
    from sim.generate import generate_chunks

    sc = load(str(scenario_dir / "moving.toml"))
    arrived = threading.Event()
    made_after_arrival: list[bool] = []

    def source():
        pieces = list(generate_chunks(sc, duration=200.0, usec_grid=True))
        yield from pieces[:-1]
        made_after_arrival.append(arrived.wait(EVENT_TIMEOUT_S))
        yield pieces[-1]

    port = _free_udp_port()
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="ardupilotmega")
    roomy(rx.port)
    result: dict = {}
    th = threading.Thread(target=lambda: result.setdefault(
        "stats", stream(source(), f"udpout:127.0.0.1:{port}", StreamOptions(speed=None))), daemon=True)
    th.start()
    try:
        first = rx.recv_match(blocking=True, timeout=EVENT_TIMEOUT_S)
        assert first is not None
        arrived.set()
        th.join(EVENT_TIMEOUT_S)
    finally:
        rx.close()
    assert made_after_arrival == [True]
    assert result["stats"].imu_messages == 20000


def test_ahead_raises_the_error_of_a_later_piece_after_the_earlier_ones() -> None:
    """An error while making a piece reaches the consumer after the pieces made before it; closing the
    iterator early stops the maker."""
    from sim.stream import ahead

    def source():
        yield 1
        yield 2
        raise ValueError("piece 3 failed")

    got = []
    with pytest.raises(ValueError, match="piece 3 failed"):
        for item in ahead(source()):  # type: ignore[arg-type]
            got.append(item)
    assert got == [1, 2]
    made = []

    def endless():
        k = 0
        while True:
            made.append(k)
            yield k
            k += 1

    it = ahead(endless(), depth=2)  # type: ignore[arg-type]
    assert next(it) == 0
    it.close()
    deadline = time.monotonic() + EVENT_TIMEOUT_S
    while any(th.name == "sim-pieces" for th in threading.enumerate()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(th.name == "sim-pieces" for th in threading.enumerate())  # the maker thread ended
    assert len(made) <= 4  # the one taken, the depth ahead, and the one it was putting

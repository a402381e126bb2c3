"""What the mutation runs found unchecked in mavins/link/publish.py (docs/testing.md).

In-process and fast: every message is encoded, packed to bytes and parsed
back with pymavlink, then compared field by field with values typed from the
contract (docs/conventions.md "MAVLink", docs/service.md, docs/autopilots.md)
and the MAVLink definitions (units, enum bit values), never from publish.py.
Attitudes and the body-frame velocity are built from a DCM typed here
(C_b^n = Rz(yaw) Ry(pitch) Rx(roll), FRD body, NED).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavins.core.records import Solution, Uncertainty
from mavins.link import publish
from mavins.link.mavlink import mavlink

NAN = float("nan")
# WGS-84 (NIMA TR8350.2), typed
A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
# MAVLink enum values, typed from common.xml / ardupilotmega.xml
MAV_FRAME_BODY_FRD = 12
MAV_FRAME_LOCAL_FRD = 20
MAV_FRAME_LOCAL_NED = 1
MAV_ESTIMATOR_TYPE_VIO = 3
EST = dict(ATTITUDE=1, VELOCITY_HORIZ=2, VELOCITY_VERT=4, POS_HORIZ_REL=8, POS_HORIZ_ABS=16, POS_VERT_ABS=32,
           POS_VERT_AGL=64, CONST_POS_MODE=128, PRED_POS_HORIZ_REL=256, PRED_POS_HORIZ_ABS=512, GPS_GLITCH=1024)
EKF_GPS_GLITCHING = 32768
GPS_INPUT_IGNORE_FLAG_HDOP = 2
GPS_INPUT_IGNORE_FLAG_VDOP = 4
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4
SEV = dict(ERROR=3, WARNING=4, NOTICE=5, INFO=6)


def c_bn(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]]) @ np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
            @ np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]]))


def quat(roll, pitch, yaw):
    """Hamilton quaternion (w, x, y, z) of the ZYX Euler angles (body to NED)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2),
                              math.cos(yaw / 2), math.sin(yaw / 2))
    return [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy]


def roundtrip(msgs):
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    rx = mavlink.MAVLink(None)
    out = []
    for m in msgs:
        d = rx.decode(bytearray(m.pack(tx)))
        out.append(d)
    return out


def by_type(msgs):
    return {m.get_type(): m for m in roundtrip(msgs)}


def f32(x, y, rel=2e-7, abs_=1e-9):
    assert x == pytest.approx(y, rel=rel, abs=abs_), (x, y)


ORIGIN = (47.0, 8.0, 400.0)  # deg, deg, m
DN, DE, UP = 120.0, -80.0, 25.0  # m from the origin
ROLL, PITCH, YAW = 0.1, -0.2, 2.0
VN, VE, VD = 1.5, -2.25, 0.5
GYRO = (0.01, -0.02, 0.03)


def point():
    lat0 = math.radians(ORIGIN[0])
    w = math.sqrt(1 - E2 * math.sin(lat0) ** 2)
    m_r = A * (1 - E2) / w ** 3  # meridian radius
    n_r = A / w  # prime vertical radius
    return lat0 + DN / (m_r + ORIGIN[2]), math.radians(ORIGIN[1]) + DE / ((n_r + ORIGIN[2]) * math.cos(lat0)), \
        ORIGIN[2] + UP


def solution(t=12.3456789, yaw=YAW, unc=None, vel=(VN, VE, VD)):
    lat, lon, h = point()
    row = np.array([t, lat, lon, h, *vel, ROLL, PITCH, yaw, *quat(ROLL, PITCH, yaw)])
    return Solution(row=row, gyro=np.array(GYRO), origin=ORIGIN, degraded=False, unc=unc)


def uncertainty(**kw):
    base = dict(sigma_pos=np.array([3.0, 4.0, 5.0]), sigma_vel=np.array([0.1, 0.2, 0.3]),
                sigma_att=np.array([0.01, 0.02, 0.03]), sigma_gyro=np.array([1e-3, 2e-3, 3e-3]))
    base.update(kw)
    return Uncertainty(**base)


def expected_quality(sigma_h):
    """docs/autopilots.md "Quality": 100 at <= 0.1 m, one third less per decade, never below 1."""
    return int(min(100, max(1, round(100 * (1 - math.log10(max(sigma_h, 0.1) / 0.1) / 3)))))


# --- the output set -------------------------------------------------------------------------

def test_output_set_fields():
    cfg = publish.PublishConfig(geoid_height=47.5)
    msgs = publish.encode(mavlink.MAVLink(None), solution(), cfg, reset_counter=257)
    assert [m.get_type() for m in msgs] == ["ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED",
                                            "GLOBAL_POSITION_INT", "ODOMETRY"]
    m = by_type(msgs)
    ms, usec = 12345, 12345679  # time_boot_ms = time_usec // 1000

    a = m["ATTITUDE"]
    assert a.time_boot_ms == ms
    for got, want in ((a.roll, ROLL), (a.pitch, PITCH), (a.yaw, YAW), (a.rollspeed, GYRO[0]),
                      (a.pitchspeed, GYRO[1]), (a.yawspeed, GYRO[2])):
        f32(got, want)

    aq = m["ATTITUDE_QUATERNION"]
    assert aq.time_boot_ms == ms
    for got, want in zip((aq.q1, aq.q2, aq.q3, aq.q4), quat(ROLL, PITCH, YAW)):
        f32(got, want)
    for got, want in zip((aq.rollspeed, aq.pitchspeed, aq.yawspeed), GYRO):
        f32(got, want)
    assert list(aq.repr_offset_q) == [0.0, 0.0, 0.0, 0.0]

    lp = m["LOCAL_POSITION_NED"]
    assert lp.time_boot_ms == ms
    assert (lp.x, lp.y, lp.z) == (pytest.approx(DN, abs=0.01), pytest.approx(DE, abs=0.01),
                                  pytest.approx(-UP, abs=0.01))
    for got, want in zip((lp.vx, lp.vy, lp.vz), (VN, VE, VD)):
        f32(got, want)

    g = m["GLOBAL_POSITION_INT"]
    lat, lon, h = point()
    assert g.time_boot_ms == ms
    assert g.lat == round(math.degrees(lat) * 1e7) and g.lon == round(math.degrees(lon) * 1e7)
    assert g.alt == 377500  # (425 m - 47.5 m geoid) in mm: AMSL
    assert g.relative_alt == 25000  # above the initial point, mm
    assert (g.vx, g.vy, g.vz) == (150, -225, 50)  # cm/s
    assert g.hdg == 11459  # 2 rad = 114.59 deg, cdeg

    o = m["ODOMETRY"]
    assert o.time_usec == usec
    assert o.frame_id == MAV_FRAME_LOCAL_FRD and o.child_frame_id == MAV_FRAME_BODY_FRD
    assert (o.x, o.y, o.z) == (pytest.approx(DN, abs=0.01), pytest.approx(DE, abs=0.01),
                               pytest.approx(-UP, abs=0.01))
    for got, want in zip(o.q, quat(ROLL, PITCH, YAW)):
        f32(got, want)
    v_b = c_bn(ROLL, PITCH, YAW).T @ np.array([VN, VE, VD])
    for got, want in zip((o.vx, o.vy, o.vz), v_b):
        f32(got, want, rel=1e-6)
    for got, want in zip((o.rollspeed, o.pitchspeed, o.yawspeed), GYRO):
        f32(got, want)
    assert all(math.isnan(x) for x in o.pose_covariance)
    assert all(math.isnan(x) for x in o.velocity_covariance)
    assert o.quality == 0  # no filter: unknown
    assert o.reset_counter == 1  # 257 mod 256
    assert o.estimator_type == MAV_ESTIMATOR_TYPE_VIO


def test_body_velocity_heading_east():
    # yaw 90 deg, level: forward is east, right is south
    sol = solution(yaw=math.pi / 2)
    sol.row[7] = sol.row[8] = 0.0
    sol.row[10:14] = quat(0.0, 0.0, math.pi / 2)
    o = by_type(publish.encode(mavlink.MAVLink(None), sol, publish.PublishConfig()))["ODOMETRY"]
    f32(o.vx, VE, rel=1e-6)
    f32(o.vy, -VN, rel=1e-6)
    f32(o.vz, VD, rel=1e-6)


def test_default_config():
    cfg = publish.PublishConfig()
    assert cfg.geoid_height == 0.0
    assert cfg.odometry_frame == MAV_FRAME_LOCAL_FRD and cfg.estimator_type == MAV_ESTIMATOR_TYPE_VIO
    assert cfg.gps_input is False and cfg.set_origin is False
    g = by_type(publish.encode(mavlink.MAVLink(None), solution(), cfg))["GLOBAL_POSITION_INT"]
    assert g.alt == 425000


def test_odometry_frame_is_a_setting():
    cfg = publish.PublishConfig(odometry_frame=MAV_FRAME_LOCAL_NED, estimator_type=2)
    o = by_type(publish.encode(mavlink.MAVLink(None), solution(), cfg))["ODOMETRY"]
    assert o.frame_id == MAV_FRAME_LOCAL_NED and o.estimator_type == 2 and o.reset_counter == 0


@pytest.mark.parametrize("yaw, hdg", [(0.0, 0), (-math.pi / 2, 27000), (-2.0, 24541), (math.pi, 18000),
                                      (math.radians(359.996), 0)])
def test_heading_is_cdeg_0_to_35999(yaw, hdg):
    g = by_type(publish.encode(mavlink.MAVLink(None), solution(yaw=yaw), publish.PublishConfig()))
    assert g["GLOBAL_POSITION_INT"].hdg == hdg


def test_time_boot_ms_wraps_at_32_bits():
    t = 2 ** 32 / 1000 + 1.5  # s
    m = by_type(publish.encode(mavlink.MAVLink(None), solution(t=t), publish.PublishConfig()))
    for k in ("ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"):
        assert m[k].time_boot_ms == 1500
    assert m["ODOMETRY"].time_usec == 2 ** 32 * 1000 + 1_500_000


def test_time_rounds_to_the_microsecond():
    m = by_type(publish.encode(mavlink.MAVLink(None), solution(t=0.0019996), publish.PublishConfig()))
    assert m["ODOMETRY"].time_usec == 2000
    assert m["ATTITUDE"].time_boot_ms == 2


def test_velocity_saturates_in_int16_cm_s():
    m = by_type(publish.encode(mavlink.MAVLink(None), solution(vel=(400.0, -400.0, 327.67)), publish.PublishConfig()))
    g = m["GLOBAL_POSITION_INT"]
    assert (g.vx, g.vy, g.vz) == (32767, -32768, 32767)
    m = by_type(publish.encode(mavlink.MAVLink(None), solution(vel=(-327.68, 327.664, -0.004)),
                               publish.PublishConfig()))
    g = m["GLOBAL_POSITION_INT"]
    assert (g.vx, g.vy, g.vz) == (-32768, 32766, 0)


@pytest.mark.parametrize("geoid, alt", [(-3e6, 2 ** 31 - 1), (3e6, -(2 ** 31))])
def test_altitude_saturates_in_int32_mm(geoid, alt):
    g = by_type(publish.encode(mavlink.MAVLink(None), solution(), publish.PublishConfig(geoid_height=geoid)))
    assert g["GLOBAL_POSITION_INT"].alt == alt


# --- covariance and quality -----------------------------------------------------------------

def test_odometry_covariances_and_quality_from_the_filter():
    unc = uncertainty()
    o = by_type(publish.encode(mavlink.MAVLink(None), solution(unc=unc), publish.PublishConfig()))["ODOMETRY"]
    pose = [0.0] * 21
    for k, v in zip((0, 6, 11, 15, 18, 20), (9.0, 16.0, 25.0, 0.5 * (1e-4 + 4e-4), 0.5 * (1e-4 + 4e-4), 9e-4)):
        pose[k] = v
    for got, want in zip(o.pose_covariance, pose):
        f32(got, want, abs_=0.0)
    c = c_bn(ROLL, PITCH, YAW)
    var_b = [sum(c[j, i] ** 2 * s ** 2 for j, s in enumerate((0.1, 0.2, 0.3))) for i in range(3)]
    vel = [0.0] * 21
    for k, v in zip((0, 6, 11, 15, 18, 20), (*var_b, 1e-6, 4e-6, 9e-6)):
        vel[k] = v
    for got, want in zip(o.velocity_covariance, vel):
        f32(got, want, rel=1e-6, abs_=0.0)
    assert o.quality == 48  # sigma_h = sqrt((9 + 16) / 2) = 3.54 m: 100 (1 - log10(35.4) / 3)
    assert o.quality == expected_quality(math.sqrt(12.5))


def test_odometry_covariance_without_filter_is_nan():
    pose, vel, q = publish.odometry_covariance(None, tuple(np.eye(3).ravel()))
    assert len(pose) == 21 and len(vel) == 21
    assert all(math.isnan(x) for x in pose + vel) and q == 0


@pytest.mark.parametrize("sigma, q", [(0.0, 100), (0.05, 100), (0.1, 100), (0.2, 90), (1.0, 67), (10.0, 33),
                                      (100.0, 1), (1e9, 1), (float("inf"), 1), (NAN, 1)])
def test_quality_scale(sigma, q):
    assert publish.quality(sigma) == q


def test_quality_follows_the_documented_formula():
    for s in (0.15, 0.3, 0.7, 2.0, 5.0, 31.0, 99.0):
        assert publish.quality(s) == expected_quality(s)


def test_horizontal_sigma_is_the_rms_of_north_and_east():
    assert publish.horizontal_sigma(uncertainty(sigma_pos=np.array([3.0, 4.0, 100.0]))) == \
        pytest.approx(math.sqrt(12.5), rel=1e-15)


# --- estimator status -----------------------------------------------------------------------

def flags(*names):
    return sum(EST[n] for n in names)


ALWAYS = ("ATTITUDE", "PRED_POS_HORIZ_REL", "PRED_POS_HORIZ_ABS")


def test_flags_free_inertial_and_good():
    f, ekf = publish.estimator_flags(uncertainty(sigma_vel=np.array([0.5, 0.5, 0.5])))
    want = flags(*ALWAYS, "VELOCITY_HORIZ", "VELOCITY_VERT", "POS_HORIZ_REL", "CONST_POS_MODE")
    assert f == want and ekf == want


def test_flags_thresholds_are_strict():
    # horizontal velocity 1-sigma hypot(1, 0) = 1 m/s, vertical 1 m/s, horizontal position 10 m
    unc = uncertainty(sigma_vel=np.array([1.0, 0.0, 1.0]), sigma_pos=np.array([10.0, 10.0, 1.0]))
    f, ekf = publish.estimator_flags(unc)
    assert f == flags(*ALWAYS, "CONST_POS_MODE") and ekf == f
    unc = uncertainty(sigma_vel=np.array([0.0, 0.999, 0.999]), sigma_pos=np.array([9.99, 9.99, 1.0]))
    f, _ = publish.estimator_flags(unc)
    assert f == flags(*ALWAYS, "VELOCITY_HORIZ", "VELOCITY_VERT", "POS_HORIZ_REL", "CONST_POS_MODE")


def test_flags_horizontal_velocity_uses_both_axes():
    f, _ = publish.estimator_flags(uncertainty(sigma_vel=np.array([0.8, 0.8, 0.1])))  # hypot 1.13
    assert not f & EST["VELOCITY_HORIZ"] and f & EST["VELOCITY_VERT"]
    f, _ = publish.estimator_flags(uncertainty(sigma_vel=np.array([0.1, 0.1, 1.5])))
    assert f & EST["VELOCITY_HORIZ"] and not f & EST["VELOCITY_VERT"]


def test_flags_with_gnss_and_glitch():
    unc = uncertainty(sigma_vel=np.array([2.0, 2.0, 2.0]), sigma_pos=np.array([20.0, 20.0, 20.0]),
                      abs_pos=True, abs_hgt=True, glitch=True)
    f, ekf = publish.estimator_flags(unc)
    assert f == flags(*ALWAYS, "POS_HORIZ_ABS", "POS_VERT_ABS", "GPS_GLITCH")
    assert ekf == flags(*ALWAYS, "POS_HORIZ_ABS", "POS_VERT_ABS") | EKF_GPS_GLITCHING
    f, ekf = publish.estimator_flags(uncertainty(sigma_vel=np.array([2.0, 2.0, 2.0]), abs_hgt=True))
    assert f == flags(*ALWAYS, "POS_HORIZ_REL", "CONST_POS_MODE", "POS_VERT_ABS") and ekf == f


def test_estimator_status_messages():
    unc = uncertainty(vel_ratio=0.25, pos_ratio=0.5, hgt_ratio=NAN, mag_ratio=0.125,
                      sigma_vel=np.array([0.5, 0.5, 0.5]))
    msgs = publish.estimator_status(mavlink.MAVLink(None), solution(unc=unc))
    assert [m.get_type() for m in msgs] == ["ESTIMATOR_STATUS", "EKF_STATUS_REPORT"]
    es, ekf = roundtrip(msgs)
    want = flags(*ALWAYS, "VELOCITY_HORIZ", "VELOCITY_VERT", "POS_HORIZ_REL", "CONST_POS_MODE")
    assert es.time_usec == 12345679 and es.flags == want
    assert (es.vel_ratio, es.pos_horiz_ratio, es.pos_vert_ratio, es.mag_ratio) == (0.25, 0.5, 0.0, 0.125)
    assert es.hagl_ratio == 0.0 and es.tas_ratio == 0.0
    f32(es.pos_horiz_accuracy, math.sqrt(12.5))
    f32(es.pos_vert_accuracy, 5.0)
    assert ekf.flags == want
    assert (ekf.velocity_variance, ekf.pos_horiz_variance, ekf.pos_vert_variance, ekf.compass_variance,
            ekf.terrain_alt_variance) == (0.25, 0.5, 0.0, 0.125, 0.0)
    assert ekf.airspeed_variance == 0.0


def test_estimator_status_without_filter_is_nothing():
    assert publish.estimator_status(mavlink.MAVLink(None), solution()) == []


# --- GPS_INPUT ------------------------------------------------------------------------------

def test_gps_input_fields():
    unc = uncertainty(sigma_vel=np.array([0.3, 0.4, 0.1]))
    m = roundtrip([publish.gps_input(mavlink.MAVLink(None), solution(unc=unc),
                                     publish.PublishConfig(geoid_height=47.5), gps_time=(2300, 123456789))])[0]
    lat, lon, h = point()
    assert m.time_usec == 12345679 and m.gps_id == 0
    assert m.ignore_flags == GPS_INPUT_IGNORE_FLAG_HDOP | GPS_INPUT_IGNORE_FLAG_VDOP
    assert (m.time_week, m.time_week_ms) == (2300, 123456789)
    assert m.fix_type == 3  # 3.54 m < 5 m
    assert m.lat == round(math.degrees(lat) * 1e7) and m.lon == round(math.degrees(lon) * 1e7)
    f32(m.alt, 377.5)
    assert m.hdop == 0.0 and m.vdop == 0.0
    for got, want in zip((m.vn, m.ve, m.vd), (VN, VE, VD)):
        f32(got, want)
    f32(m.speed_accuracy, 0.5)  # hypot(0.3, 0.4)
    f32(m.horiz_accuracy, math.sqrt(12.5))
    f32(m.vert_accuracy, 5.0)
    assert m.satellites_visible == 0
    assert m.yaw == 11459


def test_gps_input_without_filter_or_time():
    m = roundtrip([publish.gps_input(mavlink.MAVLink(None), solution(yaw=0.0), publish.PublishConfig())])[0]
    assert (m.time_week, m.time_week_ms) == (0, 0)
    assert m.fix_type == 1
    assert (m.speed_accuracy, m.horiz_accuracy, m.vert_accuracy) == (1000.0, 10000.0, 10000.0)
    assert m.yaw == 36000  # north
    f32(m.alt, 425.0)


def test_gps_input_fix_threshold_is_strict_and_yaw_wraps():
    unc = uncertainty(sigma_pos=np.array([5.0, 5.0, 1.0]))  # exactly 5 m
    m = roundtrip([publish.gps_input(mavlink.MAVLink(None), solution(unc=unc, yaw=-math.pi / 2),
                                     publish.PublishConfig())])[0]
    assert m.fix_type == 1 and m.yaw == 27000
    unc = uncertainty(sigma_pos=np.array([4.99, 4.99, 1.0]))
    m = roundtrip([publish.gps_input(mavlink.MAVLink(None), solution(unc=unc), publish.PublishConfig())])[0]
    assert m.fix_type == 3


def test_gps_input_accuracies_are_capped():
    unc = uncertainty(sigma_pos=np.array([2e4, 2e4, 2e4]), sigma_vel=np.array([2e3, 0.0, 0.0]))
    m = roundtrip([publish.gps_input(mavlink.MAVLink(None), solution(unc=unc), publish.PublishConfig())])[0]
    assert (m.speed_accuracy, m.horiz_accuracy, m.vert_accuracy) == (1000.0, 10000.0, 10000.0)


# --- the small messages ---------------------------------------------------------------------

def test_timesync_reply():
    m = roundtrip([publish.timesync_reply(mavlink.MAVLink(None), 123456789012, 987654321098)])[0]
    assert (m.tc1, m.ts1) == (987654321098, 123456789012)


def test_system_time():
    m = roundtrip([publish.system_time(mavlink.MAVLink(None), 1_700_000_000_123_456, 12.3456)])[0]
    assert m.time_unix_usec == 1_700_000_000_123_456 and m.time_boot_ms == 12345
    m = roundtrip([publish.system_time(mavlink.MAVLink(None), 1, 2 ** 32 / 1000 + 2.5)])[0]
    assert m.time_boot_ms == 2500


def test_set_gps_global_origin():
    m = roundtrip([publish.set_gps_global_origin(mavlink.MAVLink(None), 7, (47.1234567, -8.7654321, 400.25), 47.5)])[0]
    assert m.target_system == 7
    assert (m.latitude, m.longitude, m.altitude) == (471234567, -87654321, 352750)


@pytest.mark.parametrize("navigating, state", [(True, MAV_STATE_ACTIVE), (False, MAV_STATE_STANDBY)])
def test_heartbeat(navigating, state):
    m = roundtrip([publish.heartbeat(mavlink.MAVLink(None), navigating)])[0]
    assert (m.type, m.autopilot, m.base_mode, m.custom_mode, m.system_status) == \
        (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, state)


@pytest.mark.parametrize("level", ["INFO", "WARNING", "ERROR", "DEBUG"])
def test_statustext_severity_and_short_text(level):
    msgs = publish.statustext(mavlink.MAVLink(None), level, "aligned", text_id=9)
    (m,) = roundtrip(msgs)
    assert m.severity == SEV.get(level, SEV["NOTICE"])
    assert m.text == "mavins: aligned" and m.id == 0 and m.chunk_seq == 0


def test_statustext_of_exactly_50_bytes_is_one_message():
    (m,) = roundtrip(publish.statustext(mavlink.MAVLink(None), "INFO", "x" * 42))
    assert m.text == "mavins: " + "x" * 42 and m.id == 0


def test_statustext_chunks():
    text = "y" * 60  # 68 bytes with the prefix: 50 + 18
    ms = roundtrip(publish.statustext(mavlink.MAVLink(None), "WARNING", text, text_id=4))
    assert [m.chunk_seq for m in ms] == [0, 1] and {m.id for m in ms} == {5}
    assert "".join(m.text for m in ms) == "mavins: " + text
    assert all(m.severity == SEV["WARNING"] for m in ms)
    assert len(ms[0].text) == 50


def test_statustext_multiple_of_50_ends_with_an_empty_chunk_and_ids_wrap():
    ms = roundtrip(publish.statustext(mavlink.MAVLink(None), "INFO", "z" * 92, text_id=65535))  # 100 bytes
    assert [m.chunk_seq for m in ms] == [0, 1, 2] and {m.id for m in ms} == {1}
    assert [len(m.text) for m in ms] == [50, 50, 0]
    ms = roundtrip(publish.statustext(mavlink.MAVLink(None), "INFO", "z" * 92, text_id=65534))
    assert {m.id for m in ms} == {65535}


def test_statustext_of_51_bytes_is_two_chunks():
    # one byte over the 50-byte field: a single message would lose the last character
    ms = roundtrip(publish.statustext(mavlink.MAVLink(None), "INFO", "w" * 42 + "!", text_id=0))
    assert [m.chunk_seq for m in ms] == [0, 1] and {m.id for m in ms} == {1}
    assert [m.text for m in ms] == ["mavins: " + "w" * 42, "!"]


def test_covariances_are_6x6_upper_triangles():
    pose, vel, _ = publish.odometry_covariance(uncertainty(), tuple(np.eye(3).ravel()))
    assert len(pose) == 21 and len(vel) == 21  # MAVLink ODOMETRY float[21]
    assert [k for k, v in enumerate(pose) if v] == [0, 6, 11, 15, 18, 20]
    assert [k for k, v in enumerate(vel) if v] == [0, 6, 11, 15, 18, 20]

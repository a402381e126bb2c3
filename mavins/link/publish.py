"""Output sets to MAVLink messages (docs/conventions.md "MAVLink" outputs).

Every message is stamped with the sensor time of the solution it carries
(``time_boot_ms = time_usec // 1000``). LOCAL_POSITION_NED and ODOMETRY use
the initial position as origin (exact ECEF difference rotated into the
origin's NED frame). GLOBAL_POSITION_INT's ``alt`` is AMSL: ellipsoidal height
minus the configured constant geoid height.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from ..core.frames import local_ned_s
from ..core.records import Solution, Uncertainty
from ..core.rotation import quat_to_dcm_s
from .mavlink import mavlink

NAN21 = [float("nan")] * 21
COV_DIAG = (0, 6, 11, 15, 18, 20)  # diagonal of a 6x6 upper triangle, row-major (MAVLink ODOMETRY)
QUALITY_BEST_M = 0.1  # ODOMETRY quality 100 at or below this horizontal 1-sigma (docs/autopilots.md)


@dataclass(frozen=True)
class PublishConfig:
    """Identity and frames of what is published."""

    geoid_height: float = 0.0
    odometry_frame: int = mavlink.MAV_FRAME_LOCAL_FRD
    estimator_type: int = mavlink.MAV_ESTIMATOR_TYPE_VIO
    gps_input: bool = False  # also publish GPS_INPUT at 5 Hz (--gps-input)
    set_origin: bool = False  # send SET_GPS_GLOBAL_ORIGIN to the vehicle once aligned (--set-origin)


def encode(mav: mavlink.MAVLink, out: Solution, cfg: PublishConfig, reset_counter: int = 0) -> list[mavlink.MAVLink_message]:
    """ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED, GLOBAL_POSITION_INT and ODOMETRY.

    Python floats throughout (one ``tolist`` of the row): an output set is made at up to the IMU rate."""
    t, lat, lon, h, vn, ve, vd, roll, pitch, yaw, q0, q1, q2, q3 = out.row.tolist()  # strapdown.OUT_COLUMNS
    q = [q0, q1, q2, q3]
    p, qr, rr = out.gyro.tolist()
    usec = int(round(t * 1e6))
    ms = (usec // 1000) % (2**32)
    o = out.origin
    north, east, down = local_ned_s(lat, lon, h, math.radians(o[0]), math.radians(o[1]), o[2])
    c = quat_to_dcm_s((q0, q1, q2, q3))  # C_b^n, row-major
    # v^b = C_n^b v^n = (C_b^n)^T v^n
    vx = c[0] * vn + c[3] * ve + c[6] * vd
    vy = c[1] * vn + c[4] * ve + c[7] * vd
    vz = c[2] * vn + c[5] * ve + c[8] * vd
    pose_cov, vel_cov, quality = odometry_covariance(out.unc, c)
    hdg = int(round(math.degrees(yaw) * 100)) % 36000
    return [
        mav.attitude_encode(ms, roll, pitch, yaw, p, qr, rr),
        mav.attitude_quaternion_encode(ms, q0, q1, q2, q3, p, qr, rr, [0.0, 0.0, 0.0, 0.0]),
        mav.local_position_ned_encode(ms, north, east, down, vn, ve, vd),
        mav.global_position_int_encode(
            ms,
            int(round(math.degrees(lat) * 1e7)),
            int(round(math.degrees(lon) * 1e7)),
            _i32((h - cfg.geoid_height) * 1000),
            _i32((h - o[2]) * 1000),
            _cms(vn),
            _cms(ve),
            _cms(vd),
            hdg,
        ),
        mav.odometry_encode(
            usec,
            cfg.odometry_frame,
            mavlink.MAV_FRAME_BODY_FRD,
            north,
            east,
            down,
            q,
            vx,
            vy,
            vz,
            p,
            qr,
            rr,
            pose_cov,
            vel_cov,
            reset_counter % 256,
            cfg.estimator_type,
            quality,
        ),
    ]


def horizontal_sigma(unc: Uncertainty) -> float:
    """Horizontal 1-sigma (m): the RMS of the north and east 1-sigma."""
    return math.sqrt(0.5 * (unc.sigma_pos[0] ** 2 + unc.sigma_pos[1] ** 2))


def quality(sigma_h: float) -> int:
    """ODOMETRY ``quality`` from the horizontal 1-sigma (m): 100 at or below 0.1 m, one third
    less per decade above it (67 at 1 m, 33 at 10 m), never below 1 (docs/autopilots.md)."""
    if not math.isfinite(sigma_h):
        return 1
    q = 100.0 - 100.0 / 3.0 * math.log10(max(sigma_h, QUALITY_BEST_M) / QUALITY_BEST_M)
    return int(min(100, max(1, round(q))))


def odometry_covariance(unc: Uncertainty | None, c_bn: Sequence[float]) -> tuple[list[float], list[float], int]:
    """ODOMETRY ``pose_covariance``, ``velocity_covariance`` (upper triangles, diagonals only,
    off-diagonals 0) and ``quality``; ``c_bn`` is C_b^n as a row-major 9-sequence. Pose: NED
    position variances, then roll/pitch from the level attitude error and yaw from its down
    component (rad^2). Velocity: the NED velocity covariance rotated into the body frame
    (``C_n^b P_v C_b^n``, diagonal: ``var_j = sum_i C_ij^2 var_i``), then the body rates'
    variances from the gyro-bias uncertainty. Without a filter: NaN (unknown), quality 0."""
    if unc is None:
        return NAN21, NAN21, 0
    pn, pe, pd = unc.sigma_pos.tolist()
    vn, ve, vd = (x * x for x in unc.sigma_vel.tolist())
    an, ae, ad = unc.sigma_att.tolist()
    gx, gy, gz = unc.sigma_gyro.tolist()
    level = 0.5 * (an * an + ae * ae)
    pose = [0.0] * 21
    vel = [0.0] * 21
    for k, var in zip(COV_DIAG, (pn * pn, pe * pe, pd * pd, level, level, ad * ad)):
        pose[k] = var
    c = c_bn
    var_b = (c[0] ** 2 * vn + c[3] ** 2 * ve + c[6] ** 2 * vd,
             c[1] ** 2 * vn + c[4] ** 2 * ve + c[7] ** 2 * vd,
             c[2] ** 2 * vn + c[5] ** 2 * ve + c[8] ** 2 * vd)
    for k, var in zip(COV_DIAG, (*var_b, gx * gx, gy * gy, gz * gz)):
        vel[k] = var
    return pose, vel, quality(horizontal_sigma(unc))


def _ratio(r: float) -> float:
    return float(r) if math.isfinite(r) else 0.0


VEL_VALID_MS = 1.0  # m/s: horizontal/vertical velocity is flagged valid while its 1-sigma is below this
POS_VALID_M = 10.0  # m: relative horizontal position likewise


def estimator_flags(unc: Uncertainty) -> tuple[int, int]:
    """ESTIMATOR_STATUS and EKF_STATUS_REPORT flags (MAV ESTIMATOR_STATUS_FLAGS, ArduPilot
    EKF_STATUS_FLAGS; the same bit values up to PRED_POS_HORIZ_ABS): attitude always while
    navigating; velocities and relative position while their 1-sigma is below
    ``VEL_VALID_MS`` / ``POS_VALID_M``; absolute position and height only while GNSS (or
    baro) measurements are being accepted; CONST_POS_MODE while nothing bounds the position
    (free inertial); predicted positions always; GPS_GLITCH while fixes are rejected."""
    e = mavlink
    f = e.ESTIMATOR_ATTITUDE | e.ESTIMATOR_PRED_POS_HORIZ_REL | e.ESTIMATOR_PRED_POS_HORIZ_ABS
    if math.hypot(unc.sigma_vel[0], unc.sigma_vel[1]) < VEL_VALID_MS:
        f |= e.ESTIMATOR_VELOCITY_HORIZ
    if unc.sigma_vel[2] < VEL_VALID_MS:
        f |= e.ESTIMATOR_VELOCITY_VERT
    if horizontal_sigma(unc) < POS_VALID_M:
        f |= e.ESTIMATOR_POS_HORIZ_REL
    if unc.abs_pos:
        f |= e.ESTIMATOR_POS_HORIZ_ABS
    else:
        f |= e.ESTIMATOR_CONST_POS_MODE
    if unc.abs_hgt:
        f |= e.ESTIMATOR_POS_VERT_ABS
    ekf = f & 0x3FF  # the bits both enums share
    if unc.glitch:
        f |= e.ESTIMATOR_GPS_GLITCH
        ekf |= e.EKF_GPS_GLITCHING
    return f, ekf


def estimator_status(mav: mavlink.MAVLink, out: Solution) -> list[mavlink.MAVLink_message]:
    """ESTIMATOR_STATUS (QGroundControl) and EKF_STATUS_REPORT (MAVProxy's EKF light) from
    the filter: flags, test ratios (EKF_STATUS_REPORT's variances are the same ratios) and
    the horizontal and vertical 1-sigma (m) as accuracies."""
    unc = out.unc
    if unc is None:
        return []
    usec = int(round(float(out.row[0]) * 1e6))
    f, ekf = estimator_flags(unc)
    vel, pos, hgt, mag = (_ratio(r) for r in (unc.vel_ratio, unc.pos_ratio, unc.hgt_ratio, unc.mag_ratio))
    return [
        mav.estimator_status_encode(usec, f, vel, pos, hgt, mag, 0.0, 0.0, horizontal_sigma(unc),
                                    float(unc.sigma_pos[2])),
        mav.ekf_status_report_encode(ekf, vel, pos, hgt, mag, 0.0, 0.0),
    ]


GPS_FIX_MAX_SIGMA_M = 5.0  # GPS_INPUT says 3D fix while the horizontal 1-sigma is below this


def gps_input(mav: mavlink.MAVLink, out: Solution, cfg: PublishConfig,
              gps_time: tuple[int, int] | None = None) -> mavlink.MAVLink_message:
    """GPS_INPUT carrying the solution (ArduPilot GPS_TYPE 14): fix 3 while the horizontal
    1-sigma is below ``GPS_FIX_MAX_SIGMA_M``, else 1; accuracies are the 1-sigma; GPS week and
    milliseconds when known (``gps_time``), else ignored; yaw in cdeg, 36000 for north."""
    r = out.row
    unc = out.unc
    sig_h = horizontal_sigma(unc) if unc is not None else float("inf")
    sig_v = float(unc.sigma_pos[2]) if unc is not None else float("inf")
    sig_s = float(math.hypot(unc.sigma_vel[0], unc.sigma_vel[1])) if unc is not None else float("inf")
    ignore = mavlink.GPS_INPUT_IGNORE_FLAG_HDOP | mavlink.GPS_INPUT_IGNORE_FLAG_VDOP
    week, week_ms = gps_time if gps_time is not None else (0, 0)  # week 0: time unknown
    yaw_cd = int(round(math.degrees(float(r[9])) * 100.0)) % 36000
    return mav.gps_input_encode(
        int(round(float(r[0]) * 1e6)), 0, ignore, week_ms, week, 3 if sig_h < GPS_FIX_MAX_SIGMA_M else 1,
        int(round(math.degrees(float(r[1])) * 1e7)), int(round(math.degrees(float(r[2])) * 1e7)),
        float(r[3]) - cfg.geoid_height, 0.0, 0.0, float(r[4]), float(r[5]), float(r[6]),
        min(sig_s, 1e3), min(sig_h, 1e4), min(sig_v, 1e4), 0, yaw_cd if yaw_cd else 36000)


def timesync_reply(mav: mavlink.MAVLink, ts1: int, now_ns: int) -> mavlink.MAVLink_message:
    """TIMESYNC answer to a request (tc1 = 0): our clock in ns as tc1, theirs echoed as ts1."""
    return mav.timesync_encode(now_ns, ts1)


def system_time(mav: mavlink.MAVLink, unix_usec: int, sensor_t: float) -> mavlink.MAVLink_message:
    """SYSTEM_TIME: UTC (us since the UNIX epoch) and the sensor time (ms) it corresponds to."""
    return mav.system_time_encode(unix_usec, (int(round(sensor_t * 1e6)) // 1000) % (2**32))  # as encode's stamps


def set_gps_global_origin(mav: mavlink.MAVLink, target: int, origin: tuple[float, float, float],
                          geoid_height: float) -> mavlink.MAVLink_message:
    """SET_GPS_GLOBAL_ORIGIN for the vehicle (ArduPilot without GPS needs an EKF origin):
    the local frame's origin (deg, deg, ellipsoidal m) with AMSL altitude in mm."""
    return mav.set_gps_global_origin_encode(target, int(round(origin[0] * 1e7)), int(round(origin[1] * 1e7)),
                                            int(round((origin[2] - geoid_height) * 1000.0)))


def _cms(v: float) -> int:
    """m/s to int16 cm/s, saturated."""
    return max(-32768, min(32767, int(round(v * 100))))


def _i32(v: float) -> int:
    """A value for an int32 field, saturated."""
    return max(-(2**31), min(2**31 - 1, int(round(v))))


def heartbeat(mav: mavlink.MAVLink, navigating: bool) -> mavlink.MAVLink_message:
    """HEARTBEAT of an onboard controller with no autopilot of its own."""
    status = mavlink.MAV_STATE_ACTIVE if navigating else mavlink.MAV_STATE_STANDBY
    return mav.heartbeat_encode(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, status)


def statustext(mav: mavlink.MAVLink, level: str, text: str, text_id: int = 0) -> list[mavlink.MAVLink_message]:
    """STATUSTEXT with a MAV_SEVERITY from an event level.

    Texts over 50 bytes go out in MAVLink 2 chunks sharing ``id`` (1..65535)
    with ``chunk_seq`` 0, 1, ...; a single chunk carries ``id`` 0.
    """
    sev = {"INFO": mavlink.MAV_SEVERITY_INFO, "WARNING": mavlink.MAV_SEVERITY_WARNING,
           "ERROR": mavlink.MAV_SEVERITY_ERROR}.get(level, mavlink.MAV_SEVERITY_NOTICE)
    data = ("mavins: " + text).encode("utf-8")
    if len(data) <= 50:
        return [mav.statustext_encode(sev, data)]
    chunks = [data[i : i + 50] for i in range(0, len(data), 50)]
    if len(chunks[-1]) == 50:
        chunks.append(b"")  # an empty chunk ends a text whose length is a multiple of 50
    tid = text_id % 65535 + 1
    return [mav.statustext_encode(sev, c, tid, k) for k, c in enumerate(chunks)]

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

import numpy as np

from ..core.frames import local_ned
from ..core.records import Solution
from ..core.rotation import quat_to_dcm
from .mavlink import mavlink

NAN21 = [float("nan")] * 21


@dataclass(frozen=True)
class PublishConfig:
    """Identity and frames of what is published."""

    geoid_height: float = 0.0
    odometry_frame: int = mavlink.MAV_FRAME_LOCAL_FRD
    estimator_type: int = mavlink.MAV_ESTIMATOR_TYPE_UNKNOWN


def encode(mav: mavlink.MAVLink, out: Solution, cfg: PublishConfig, reset_counter: int = 0) -> list[mavlink.MAVLink_message]:
    """ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED, GLOBAL_POSITION_INT and ODOMETRY."""
    r = out.row
    t = float(r[0])
    usec = int(round(t * 1e6))
    ms = (usec // 1000) % (2**32)
    lat, lon, h = float(r[1]), float(r[2]), float(r[3])
    vn, ve, vd = float(r[4]), float(r[5]), float(r[6])
    roll, pitch, yaw = float(r[7]), float(r[8]), float(r[9])
    q = [float(x) for x in r[10:14]]
    p, qr, rr = (float(x) for x in out.gyro)
    ned = local_ned(lat, lon, h, out.origin)
    v_body = quat_to_dcm(np.asarray(q)).T @ np.array([vn, ve, vd])
    hdg = int(round(math.degrees(yaw) * 100)) % 36000
    return [
        mav.attitude_encode(ms, roll, pitch, yaw, p, qr, rr),
        mav.attitude_quaternion_encode(ms, q[0], q[1], q[2], q[3], p, qr, rr, [0.0, 0.0, 0.0, 0.0]),
        mav.local_position_ned_encode(ms, float(ned[0]), float(ned[1]), float(ned[2]), vn, ve, vd),
        mav.global_position_int_encode(
            ms,
            int(round(math.degrees(lat) * 1e7)),
            int(round(math.degrees(lon) * 1e7)),
            _i32((h - cfg.geoid_height) * 1000),
            _i32((h - out.origin[2]) * 1000),
            _cms(vn),
            _cms(ve),
            _cms(vd),
            hdg,
        ),
        mav.odometry_encode(
            usec,
            cfg.odometry_frame,
            mavlink.MAV_FRAME_BODY_FRD,
            float(ned[0]),
            float(ned[1]),
            float(ned[2]),
            q,
            float(v_body[0]),
            float(v_body[1]),
            float(v_body[2]),
            p,
            qr,
            rr,
            NAN21,
            NAN21,
            reset_counter % 256,
            cfg.estimator_type,
            0,
        ),
    ]


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

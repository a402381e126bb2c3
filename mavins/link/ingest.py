"""MAVLink IMU messages in, validated IMU samples out (or a counted rejection).

Accepted inputs (docs/conventions.md "MAVLink"): HIGHRES_IMU (SI units, ``id``),
RAW_IMU (int16 counts; ArduPilot: mG and mrad/s, scales are settings, ``id``),
SCALED_IMU / SCALED_IMU2 / SCALED_IMU3 (mG, mrad/s, ``time_boot_ms``).
Every sample is checked before it reaches the strapdown core: selected
message and id, source system, fields present, finite values, sensor range,
and time strictly after the previous sample. Rejections are counted by reason.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from ..core.records import ImuSample

G0 = 9.80665
MG = G0 / 1000.0  # m/s^2 per milli-g
HIGHRES_ACC_GYRO = 0b111111  # fields_updated bits 0-5: x/y/z acc and gyro
HIGHRES_MAG = 0b111000000  # bits 6-8: magnetometer

IMU_MESSAGES = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")


@dataclass
class IngestConfig:
    """Which IMU stream to take and how to read it."""

    message: str = "auto"  # one of IMU_MESSAGES or "auto" (the first one seen)
    imu_id: int | None = None  # id field of HIGHRES_IMU / RAW_IMU; None = the first seen
    target_system: int | None = None  # accept only this source system (None = the first seen)
    raw_acc_scale: float = MG  # m/s^2 per RAW_IMU count
    raw_gyro_scale: float = 1e-3  # rad/s per RAW_IMU count
    raw_mag_scale: float = 1e-3  # gauss per RAW_IMU count (mgauss)
    max_accel: float = 16 * G0  # sensor range (m/s^2)
    max_gyro: float = math.radians(2000.0)  # sensor range (rad/s)
    imus: tuple[int, ...] | None = None  # --imus: IMU numbers to fuse, () = all seen (mavins/live/imuset.py)
    false_alarm: float = 1e-6  # --false-alarm: design probability of each FDI test


@dataclass
class Ingest:
    """Stateful filter: locks onto one IMU stream and checks every sample."""

    cfg: IngestConfig = field(default_factory=IngestConfig)
    rejected: Counter = field(default_factory=Counter)
    accepted: int = 0
    last_t: float | None = None
    locked_message: str | None = None
    locked_id: int | None = None
    locked_system: int | None = None

    last_reason: str | None = None  # why the last message was rejected (None if accepted)

    def reject(self, reason: str) -> None:
        self.rejected[reason] += 1
        self.last_reason = reason

    def reset_time(self) -> None:
        """Forget the last timestamp (after an autopilot restart)."""
        self.last_t = None

    def sample(self, msg: object) -> ImuSample | None:
        """The IMU sample in ``msg``, or None (rejections are counted by reason)."""
        name = msg.get_type()  # type: ignore[attr-defined]
        if name not in IMU_MESSAGES:
            return None
        self.last_reason = None
        cfg = self.cfg
        src_sys = msg.get_srcSystem()  # type: ignore[attr-defined]
        if cfg.target_system is not None and src_sys != cfg.target_system:
            self.reject("other_system")
            return None
        want = cfg.message.upper()
        if want != "AUTO" and name != want:
            self.reject("other_imu")
            return None
        imu_id = getattr(msg, "id", 0) if name in ("HIGHRES_IMU", "RAW_IMU") else 0
        if self.locked_message is None:
            if cfg.imu_id is not None and imu_id != cfg.imu_id:
                self.reject("other_imu")
                return None
            self.locked_message, self.locked_id, self.locked_system = name, imu_id, src_sys
        elif (name, imu_id) != (self.locked_message, self.locked_id):
            self.reject("other_imu")
            return None
        elif src_sys != self.locked_system:
            self.reject("other_system")
            return None

        if name == "HIGHRES_IMU":
            if (msg.fields_updated & HIGHRES_ACC_GYRO) != HIGHRES_ACC_GYRO:  # type: ignore[attr-defined]
                self.reject("fields_missing")
                return None
            t = msg.time_usec * 1e-6  # type: ignore[attr-defined]
            acc = (msg.xacc, msg.yacc, msg.zacc)  # type: ignore[attr-defined]
            gyr = (msg.xgyro, msg.ygyro, msg.zgyro)  # type: ignore[attr-defined]
            mag = (msg.xmag, msg.ymag, msg.zmag) if msg.fields_updated & HIGHRES_MAG == HIGHRES_MAG else None  # type: ignore[attr-defined]
        elif name == "RAW_IMU":
            t = msg.time_usec * 1e-6  # type: ignore[attr-defined]
            acc = tuple(v * cfg.raw_acc_scale for v in (msg.xacc, msg.yacc, msg.zacc))  # type: ignore[attr-defined]
            gyr = tuple(v * cfg.raw_gyro_scale for v in (msg.xgyro, msg.ygyro, msg.zgyro))  # type: ignore[attr-defined]
            mag = tuple(v * cfg.raw_mag_scale for v in (msg.xmag, msg.ymag, msg.zmag))  # type: ignore[attr-defined]
        else:
            t = msg.time_boot_ms * 1e-3  # type: ignore[attr-defined]
            acc = tuple(v * MG for v in (msg.xacc, msg.yacc, msg.zacc))  # type: ignore[attr-defined]
            gyr = tuple(v * 1e-3 for v in (msg.xgyro, msg.ygyro, msg.zgyro))  # type: ignore[attr-defined]
            mag = tuple(v * 1e-3 for v in (msg.xmag, msg.ymag, msg.zmag))  # type: ignore[attr-defined]
        if mag is not None and not any(mag):
            mag = None
        ax, ay, az = acc
        gx, gy, gz = gyr
        isfinite = math.isfinite
        if not (isfinite(ax) and isfinite(ay) and isfinite(az) and isfinite(gx) and isfinite(gy) and isfinite(gz)):
            self.reject("non_finite")
            return None
        ma, mg = cfg.max_accel, cfg.max_gyro
        if abs(ax) > ma or abs(ay) > ma or abs(az) > ma or abs(gx) > mg or abs(gy) > mg or abs(gz) > mg:
            self.reject("out_of_range")
            return None
        if self.last_t is not None:
            if t == self.last_t:
                self.reject("duplicate_time")
                return None
            if t < self.last_t:
                self.reject("time_backwards")
                return None
        self.last_t = t
        self.accepted += 1
        return ImuSample(t, gyr, acc, mag, src_sys, msg.get_srcComponent())  # type: ignore[attr-defined,arg-type]

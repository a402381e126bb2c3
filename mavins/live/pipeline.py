"""The message pipeline shared by ``run``, ``replay`` and ``demo``.

MAVLink message in -> ingest (validate, select the IMU) -> engine (align,
navigate) -> output set out. Position and heading aids (GPS_RAW_INT,
GLOBAL_POSITION_INT, ATTITUDE of the vehicle) are taken here too. Nothing in
it looks at the wall clock, so live and replayed input give identical output.
"""

from __future__ import annotations

import functools
import logging
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ..core import aided
from ..core import strapdown as sd
from ..core.frames import local_ned
from ..core.records import ImuSample, Solution
from ..core.rotation import euler_to_dcm, quat_to_dcm
from .engine import Engine, EngineConfig
from .imuset import ImuSet
from ..link.ingest import IMU_MESSAGES, Ingest, IngestConfig
from ..link.mavlink import mavlink
from ..link.publish import COV_DIAG
from ..record.sink import Sink

log = logging.getLogger("mavins")

RESTART_JUMP = 1.0  # s: sensor time going back further than this is an autopilot restart
CLOCK_MATCH_S = 2.0  # s: an aiding message stamped this close to the IMU time is on the IMU's clock
GNSS_MESSAGES = ("GPS_RAW_INT", "GPS2_RAW", "GPS_INPUT", "HIL_GPS")
MS_WRAP_S = 2**32 * 1e-3  # s: a uint32 millisecond field (time_boot_ms) wraps after this (49.7 days)
# 1-sigma of a fix that gives no accuracy, and of the barometer: the filter's defaults, declared in core.aided
GNSS_SIGMA_H = aided.DEFAULT_SIGMA_H  # m
GNSS_SIGMA_V = aided.DEFAULT_SIGMA_V  # m
GNSS_SIGMA_VEL = aided.DEFAULT_SIGMA_VEL  # m/s
BARO_SIGMA_M = aided.DEFAULT_SIGMA_BARO  # m
GNSS_MAX_SIGMA = 50.0  # m: a fix claiming a worse 1-sigma accuracy is rejected (docs/filter.md)
GNSS_HEIGHT_RANGE = (-1000.0, 50000.0)  # m, ellipsoidal: below the Dead Sea's shore, above stratospheric balloons
GNSS_MAX_SPEED = 600.0  # m/s horizontal: above the receivers' export limit (1,000 knots, 514 m/s)
GPS_FIX_3D, GPS_FIX_PPP = 3, 8  # GPS_FIX_TYPE: 3D fix .. PPP are fixes; other values carry no fix
WHEEL_MAX_GAP_S = 1.0  # s: two WHEEL_DISTANCE messages further apart give no speed (a gap, counted)
VISION_SIGMA_VEL = 0.1  # m/s: a camera's velocity without a covariance (docs/filter.md)
VISION_NED_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED,)  # ODOMETRY velocity frames taken as NED
VISION_POSE_FRAMES = (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_FRD)  # ODOMETRY pose frames: z down
VISION_SIGMA_POS = 0.1  # m: a camera's position without a covariance (docs/filter.md)
VISION_SIGMA_ATT = math.radians(2.0)  # rad: its attitude without one
ORIGIN_MESSAGES = ("GPS_GLOBAL_ORIGIN", "SET_GPS_GLOBAL_ORIGIN")  # the local frame's origin: a start without GNSS


@dataclass
class Pipeline:
    """Ingest + engine, fed one message at a time."""

    engine_cfg: EngineConfig
    ingest_cfg: IngestConfig = field(default_factory=IngestConfig)
    own_component: int = 191
    engine: Engine = field(init=False)
    ingest: Ingest = field(init=False)
    counters: Counter = field(default_factory=Counter)
    last_sample: ImuSample | None = None
    recorder: Sink | None = None
    _outputs: int = 0
    imuset: ImuSet | None = field(init=False, default=None)
    _wheel: tuple[float, float, int] | None = None  # the last WHEEL_DISTANCE: time (s), mean distance (m), count
    _vision_reset: int | None = None  # the last reset_counter of a camera's velocity

    def __post_init__(self) -> None:
        self.engine = Engine(self.engine_cfg)
        self.ingest = Ingest(self.ingest_cfg)
        if self.ingest_cfg.imus is not None:  # --imus: several streams fused (docs/redundancy.md)
            self.imuset = ImuSet(self.ingest_cfg, self.ingest_cfg.imus, self.engine_cfg.filter.spec,
                                 self.ingest_cfg.false_alarm)
            self.ingest = self.imuset.primary

    @property
    def columns(self) -> tuple[str, ...]:
        """A solution file's columns (docs/conventions.md): the 14 solution columns, and the filter's
        sigma and bias columns after them whenever it aids, with the scale-factor and hard-iron columns
        of the states it estimates (as ``mavins nav`` writes them, core.aided.file_columns)."""
        if not self.engine_cfg.filter.aiding:
            return sd.OUT_COLUMNS
        return tuple(aided.ROW_COLUMNS[i] for i in self._file_columns)

    @functools.cached_property
    def _file_columns(self) -> np.ndarray:
        f = self.engine.filter
        return aided.file_columns(f.spec, f.settings.sigma_mag_bias)

    @functools.cached_property
    def _recorded_groups(self) -> tuple[tuple[tuple[str, tuple[str, ...], tuple[int, ...]], ...], np.ndarray]:
        """The filter's column groups of this run's file row (aided.column_groups) and the row's factors to
        file units (aided.unit_factors), for the recording."""
        return aided.column_groups(self.columns), aided.unit_factors(self.columns)

    def file_row(self, out: Solution) -> np.ndarray:
        """The row of ``columns`` for an output set (kernel units), the filter's state as of it."""
        if not self.engine_cfg.filter.aiding:
            return out.row
        return self.engine.filter.output_row(out.row)[self._file_columns]

    @property
    def vehicle_sysid(self) -> int | None:
        return self.ingest.locked_system

    def handle(self, msg: object) -> Solution | None:
        """Process one message; returns an output set when one is due."""
        name = msg.get_type()  # type: ignore[attr-defined]
        if name == "BAD_DATA":
            self.counters["bad_data"] += 1
            return None
        if name in IMU_MESSAGES:
            return self._imu(msg)
        src = msg.get_srcSystem()  # type: ignore[attr-defined]
        if self.ingest.locked_system is not None and src != self.ingest.locked_system:
            return None
        if msg.get_srcComponent() == self.own_component:  # type: ignore[attr-defined]
            # our own output come back (a router, a loop in the links): never fused, counted
            self.counters[f"own_{name.lower()}_ignored"] += 1
            return None
        if name in GNSS_MESSAGES:
            fix = gnss_fix(msg, self.engine_cfg.geoid_height)
            why = "no_fix" if fix is None else gnss_invalid(fix)
            if why is not None:
                self.counters[f"gnss_{why}"] += 1
            else:
                t, lat, lon, h, vel, sig_h, sig_v, sig_vel = fix
                self.engine.on_gnss(self._on_imu_clock(t), lat, lon, h, vel, sig_h, sig_v, sig_vel, name)
                yaw = gnss_heading(msg)
                if yaw is not None:  # a dual-antenna (moving-base) receiver's heading
                    self.engine.on_gnss_yaw(self._on_imu_clock(t), *yaw)
                origin = self.engine.origin
                if self.recorder is not None and origin is not None and self.last_sample is not None:
                    self.recorder.on_gnss(self.last_sample.t, local_ned(math.radians(lat), math.radians(lon), h, origin))
        elif name == "SCALED_PRESSURE" and math.isfinite(msg.press_abs) and msg.press_abs > 0.0:  # type: ignore[attr-defined]
            self.engine.on_baro(self._on_imu_clock(self._unwrap_ms(msg.time_boot_ms)), isa_height(msg.press_abs),  # type: ignore[attr-defined]
                                BARO_SIGMA_M)
        elif name == "WHEEL_DISTANCE":
            self._wheel_distance(msg)
        elif name == "VISION_SPEED_ESTIMATE":
            self._vision_velocity(name, msg)
        elif name == "ODOMETRY":  # a pose, a velocity or both (NaN x, NaN vx: not given)
            self._vision_reset_seen(int(msg.reset_counter))  # type: ignore[attr-defined]
            if math.isnan(msg.x) and math.isnan(msg.vx):  # type: ignore[attr-defined]
                self.counters["vision_empty"] += 1
            if not math.isnan(msg.vx):  # type: ignore[attr-defined]
                self._vision_velocity(name, msg)
            if not math.isnan(msg.x):  # type: ignore[attr-defined]
                self._vision_pose(name, msg)
        elif name == "VISION_POSITION_ESTIMATE":
            self._vision_pose(name, msg)
        elif name in ORIGIN_MESSAGES and (msg.latitude or msg.longitude):  # type: ignore[attr-defined]
            self.engine.set_position(msg.latitude * 1e-7, msg.longitude * 1e-7,  # type: ignore[attr-defined]
                                     msg.altitude / 1000.0 + self.engine_cfg.geoid_height, name)  # type: ignore[attr-defined]
        elif name == "SYSTEM_TIME" and msg.time_unix_usec:  # type: ignore[attr-defined]
            self.engine.set_date(msg.time_unix_usec * 1e-6)  # type: ignore[attr-defined]
        elif name == "GLOBAL_POSITION_INT" and (msg.lat or msg.lon):  # type: ignore[attr-defined]
            self.engine.set_position(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt / 1000.0, "GLOBAL_POSITION_INT")  # type: ignore[attr-defined]
        elif name == "ATTITUDE" and math.isfinite(msg.yaw):  # type: ignore[attr-defined]
            self.engine.set_vehicle_yaw(float(msg.yaw))  # type: ignore[attr-defined]
        return None

    def _imu(self, msg: object) -> Solution | None:
        src: Ingest | ImuSet = self.imuset if self.imuset is not None else self.ingest
        last = src.last_t
        smp = src.sample(msg)
        if smp is None:
            t_new = _msg_time(msg)
            if last is not None and t_new is not None and t_new < last - RESTART_JUMP and \
                    src.last_reason == "time_backwards":
                # the autopilot restarted (its clock went back): start over
                src.reset_time()
                self.engine.restart(f"sensor time went back from {last:.3f} to {t_new:.3f} s")
                smp = src.sample(msg)
            if smp is None:
                return None
        self.last_sample = smp
        out = self.engine.on_imu(smp)
        rec = self.recorder
        if self.imuset is not None:
            for t, sensor, stat, thr, res in self.imuset.take_tests():
                if rec is not None:
                    rec.on_fdi(t, sensor, stat, thr, res)
        if rec is not None:
            rec.on_sample(smp.t, smp.gyro, smp.accel)
            if out is not None:
                r = out.row
                rec.on_output(r, out.origin, local_ned(float(r[1]), float(r[2]), float(r[3]), out.origin))
                if out.unc is not None:
                    rec.on_filter(float(r[0]), out.unc)
                    groups, factors = self._recorded_groups
                    rec.on_states(float(r[0]), groups, self.file_row(out) * factors)
                self._outputs += 1
                if self._outputs % 50 == 1:
                    counts = {f"rejected_{k}": v for k, v in self.ingest.rejected.items()}
                    counts.update({k: v for k, v in self.engine.counters.items() if v})
                    # measurements accepted and rejected by kind (the filter's), and the pipeline's own
                    counts.update({k: v for k, v in self.engine.filter.counters.items() if v})
                    counts.update({k: v for k, v in self.counters.items() if v})
                    if counts:
                        rec.on_counters(float(r[0]), counts)
        return out

    def _unwrap_ms(self, ms: int) -> float:
        """A uint32 ``time_boot_ms`` (ms) as seconds on the IMU's clock: the wrap of 2^32 ms nearest
        the last sample's time. An autopilot whose clock is UNIX time (PX4 SITL: about 1.7e12 ms)
        sends it modulo 2^32, and the IMU's uint64 microseconds tell the lost high part."""
        t = ms * 1e-3
        last = self.last_sample
        if last is None:
            return t
        return t + round((last.t - t) / MS_WRAP_S) * MS_WRAP_S

    def _wheel_distance(self, msg: object) -> None:
        """WHEEL_DISTANCE (time_usec, count, distance[16] m, cumulative per wheel): the forward speed at the
        axle centre is the change of the wheels' mean distance over the time between two messages, stamped
        at the middle of that interval; a first message, a change of wheel count, a step back in time or
        more than WHEEL_MAX_GAP_S between two give none (counted ``wheel_gap``), a non-finite distance is
        counted ``wheel_invalid``."""
        n = int(msg.count)  # type: ignore[attr-defined]
        d = msg.distance[:n] if 0 < n <= len(msg.distance) else ()  # type: ignore[attr-defined]
        if not d or not all(math.isfinite(x) for x in d):
            self.counters["wheel_invalid"] += 1
            return
        t, dist = msg.time_usec * 1e-6, sum(d) / n  # type: ignore[attr-defined]
        prev, self._wheel = self._wheel, (t, dist, n)
        if prev is None:
            return
        dt = t - prev[0]
        if prev[2] != n or not 0.0 < dt <= WHEEL_MAX_GAP_S:
            self.counters["wheel_gap"] += 1
            return
        flt = self.engine_cfg.filter
        self.engine.on_wheel(self._on_imu_clock(t - 0.5 * dt), (dist - prev[1]) / dt, flt.sigma_wheel)

    def _vision_velocity(self, name: str, msg: object) -> None:
        """VISION_SPEED_ESTIMATE (usec, x y z m/s NED, covariance[9] row-major) or ODOMETRY (time_usec, vx vy vz
        in ``child_frame_id``: BODY_FRD or LOCAL_NED, velocity_covariance[21], the upper triangle of 6 x 6)
        as a velocity measurement; a NaN first covariance element means unknown (VISION_SIGMA_VEL). A NED
        velocity takes the largest of the three sigmas. Another frame is counted
        ``vision_frame_unsupported``, a non-finite value ``vision_invalid``; a new ``reset_counter`` is
        counted ``vision_resets`` (it moves a camera's position, not its velocity)."""
        if name == "ODOMETRY":
            t, vel = msg.time_usec * 1e-6, (msg.vx, msg.vy, msg.vz)  # type: ignore[attr-defined]
            cov = msg.velocity_covariance  # type: ignore[attr-defined]
            var = (cov[0], cov[6], cov[11])
            frame = msg.child_frame_id  # type: ignore[attr-defined]
            if frame != mavlink.MAV_FRAME_BODY_FRD and frame not in VISION_NED_FRAMES:
                self.counters["vision_frame_unsupported"] += 1
                return
            body = frame == mavlink.MAV_FRAME_BODY_FRD
        else:
            t, vel = msg.usec * 1e-6, (msg.x, msg.y, msg.z)  # type: ignore[attr-defined]
            cov = msg.covariance  # type: ignore[attr-defined]
            var = (cov[0], cov[4], cov[8])
            body = False
        if not all(math.isfinite(v) for v in vel):
            self.counters["vision_invalid"] += 1
            return
        if name != "ODOMETRY":  # ODOMETRY's is seen once for its pose and velocity (handle)
            self._vision_reset_seen(int(msg.reset_counter))  # type: ignore[attr-defined]
        if math.isfinite(var[0]):
            if not all(math.isfinite(v) and v > 0.0 for v in var):
                self.counters["vision_invalid"] += 1
                return
            sig = tuple(math.sqrt(v) for v in var)
        else:
            sig = (VISION_SIGMA_VEL,) * 3
        self.engine.on_vision_velocity(self._on_imu_clock(t), tuple(float(v) for v in vel),  # type: ignore[arg-type]
                                       sig if body else max(sig), body)

    def _vision_reset_seen(self, reset: int) -> None:
        """Count a camera's ``reset_counter`` change once (``vision_resets``), whichever message brings it."""
        if self._vision_reset is not None and reset != self._vision_reset:
            self.counters["vision_resets"] += 1
        self._vision_reset = reset

    def _vision_pose(self, name: str, msg: object) -> None:
        """VISION_POSITION_ESTIMATE (usec, x y z m, roll pitch yaw rad, covariance[21]) or ODOMETRY (time_usec,
        x y z in ``frame_id`` LOCAL_NED or LOCAL_FRD, q body -> frame w x y z, pose_covariance[21]): a camera's
        pose in its own local frame, whose origin and heading the filter estimates (docs/filter.md). The
        covariances are upper triangles of 6 x 6 (x y z roll pitch yaw), their diagonals used; a NaN first
        element means unknown (VISION_SIGMA_POS, VISION_SIGMA_ATT). An ODOMETRY in another frame counts
        ``vision_frame_unsupported``, a non-finite value or variance ``vision_invalid``; an attitude given as
        unknown (NaN) leaves the position alone (``vision_pose`` with no attitude)."""
        if name == "ODOMETRY":
            pos = (msg.x, msg.y, msg.z)  # type: ignore[attr-defined]
            if msg.frame_id not in VISION_POSE_FRAMES:  # type: ignore[attr-defined]
                self.counters["vision_frame_unsupported"] += 1
                return
            t, q, cov = msg.time_usec * 1e-6, tuple(msg.q), msg.pose_covariance  # type: ignore[attr-defined]
            c_vb = None if math.isnan(q[0]) else quat_to_dcm(np.array(q, dtype=float) / math.sqrt(sum(v * v for v in q)))
        else:
            t, pos, cov = msg.usec * 1e-6, (msg.x, msg.y, msg.z), msg.covariance  # type: ignore[attr-defined]
            e = (msg.roll, msg.pitch, msg.yaw)  # type: ignore[attr-defined]
            c_vb = euler_to_dcm(*e) if all(math.isfinite(v) for v in e) else None
            self._vision_reset_seen(int(msg.reset_counter))  # type: ignore[attr-defined]
        if not all(math.isfinite(v) for v in pos) or (c_vb is not None and not np.all(np.isfinite(c_vb))):
            self.counters["vision_invalid"] += 1
            return
        var = [cov[i] for i in COV_DIAG]
        if math.isfinite(var[0]):
            if not all(math.isfinite(v) and v > 0.0 for v in var[:3]) or (
                    c_vb is not None and not all(math.isfinite(v) and v > 0.0 for v in var[3:])):
                self.counters["vision_invalid"] += 1
                return
            sig_p = tuple(math.sqrt(v) for v in var[:3])
            sig_a = tuple(math.sqrt(v) for v in var[3:]) if c_vb is not None else (VISION_SIGMA_ATT,) * 3
        else:
            sig_p, sig_a = (VISION_SIGMA_POS,) * 3, (VISION_SIGMA_ATT,) * 3
        self.engine.on_vision_pose(self._on_imu_clock(t), tuple(float(v) for v in pos), c_vb,  # type: ignore[arg-type]
                                   sig_p, sig_a, self._vision_reset or 0)

    def _on_imu_clock(self, t: float | None) -> float | None:
        """A message's own time if it is on the IMU's clock (within CLOCK_MATCH_S of the last
        sample), else None: the measurement is then taken as of the latest sample."""
        last = self.last_sample
        if t is None or last is None or abs(t - last.t) > CLOCK_MATCH_S:
            return None
        return t

    def take_events(self) -> list[tuple[str, str]]:
        """State changes and warnings since the last call, drained once (also sent to the recorder)."""
        events = self.engine.take_events()
        if self.imuset is not None:
            events += self.imuset.take_events()
        if self.recorder is not None:
            t = self.last_sample.t if self.last_sample is not None else None
            for level, text in events:
                self.recorder.on_event(t, level, text)
        return events


def _msg_time(msg: object) -> float | None:
    if hasattr(msg, "time_usec"):
        return msg.time_usec * 1e-6  # type: ignore[attr-defined]
    if hasattr(msg, "time_boot_ms"):
        return msg.time_boot_ms * 1e-3  # type: ignore[attr-defined]
    return None


def gnss_fix(msg: object, geoid_height: float) -> tuple[float | None, float, float, float,
                                                          tuple[float, float, float] | None, float, float, float] | None:
    """``(t, lat, lon, h, vel, sigma_h, sigma_v, sigma_vel)`` of a 3D fix in GPS_RAW_INT, GPS_INPUT or
    HIL_GPS (deg, deg, ellipsoidal m, NED m/s or None, 1-sigma m, m, m/s; t in s of the message's
    own clock), or None without a 3D fix. Heights: GPS_RAW_INT's ``alt_ellipsoid`` when given,
    else AMSL plus ``geoid_height``. Accuracies from the message when given, else the defaults."""
    m = msg
    name = m.get_type()  # type: ignore[attr-defined]
    if not GPS_FIX_3D <= m.fix_type <= GPS_FIX_PPP or not (m.lat or m.lon):  # type: ignore[attr-defined]
        return None
    t = m.time_usec * 1e-6 if getattr(m, "time_usec", 0) else None  # type: ignore[attr-defined]
    vel = None
    sig_vel = GNSS_SIGMA_VEL
    if name in ("GPS_RAW_INT", "GPS2_RAW"):
        alt_e = getattr(m, "alt_ellipsoid", 0)
        h = alt_e / 1000.0 if alt_e else m.alt / 1000.0 + geoid_height  # type: ignore[attr-defined]
        sig_h = m.h_acc / 1000.0 if getattr(m, "h_acc", 0) else GNSS_SIGMA_H
        sig_v = m.v_acc / 1000.0 if getattr(m, "v_acc", 0) else GNSS_SIGMA_V
        vel = ground_velocity(m.vel, m.cog)  # type: ignore[attr-defined]
        if vel is not None and getattr(m, "vel_acc", 0):
            sig_vel = m.vel_acc / 1000.0  # type: ignore[attr-defined]
    elif name == "GPS_INPUT":
        ign = m.ignore_flags  # type: ignore[attr-defined]
        h = m.alt + geoid_height  # type: ignore[attr-defined]
        sig_h = float(m.horiz_accuracy) if not ign & mavlink.GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY \
            and m.horiz_accuracy > 0 else GNSS_SIGMA_H  # type: ignore[attr-defined]
        sig_v = float(m.vert_accuracy) if not ign & mavlink.GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY \
            and m.vert_accuracy > 0 else GNSS_SIGMA_V  # type: ignore[attr-defined]
        if not ign & (mavlink.GPS_INPUT_IGNORE_FLAG_VEL_HORIZ | mavlink.GPS_INPUT_IGNORE_FLAG_VEL_VERT):
            vel = (float(m.vn), float(m.ve), float(m.vd))  # type: ignore[attr-defined]
        if not ign & mavlink.GPS_INPUT_IGNORE_FLAG_SPEED_ACCURACY and m.speed_accuracy > 0:  # type: ignore[attr-defined]
            sig_vel = float(m.speed_accuracy)  # type: ignore[attr-defined]
    else:  # HIL_GPS
        h = m.alt / 1000.0 + geoid_height  # type: ignore[attr-defined]
        sig_h = m.eph / 100.0 * GNSS_SIGMA_H if 0 < m.eph < 65535 else GNSS_SIGMA_H  # type: ignore[attr-defined]
        sig_v = m.epv / 100.0 * GNSS_SIGMA_V if 0 < m.epv < 65535 else GNSS_SIGMA_V  # type: ignore[attr-defined]
        vel = (m.vn / 100.0, m.ve / 100.0, m.vd / 100.0)  # type: ignore[attr-defined]
    return t, m.lat * 1e-7, m.lon * 1e-7, h, vel, sig_h, sig_v, sig_vel  # type: ignore[attr-defined]


UINT16_UNKNOWN = 65535  # GPS_RAW_INT / GPS2_RAW eph, epv, vel, cog: "If unknown, set to: UINT16_MAX"


def ground_velocity(vel_cm_s: int, cog_cdeg: int) -> tuple[float, float, float] | None:
    """Horizontal velocity (m/s NED, vertical NaN: not measured) from GPS_RAW_INT's ground speed
    ``vel`` (cm/s) and course over ground ``cog`` (cdeg from true north, clockwise):
    ``v_N = vel cos(cog)``, ``v_E = vel sin(cog)``; None when either is unknown (UINT16_MAX)
    or the course is out of its range (0..35999)."""
    if vel_cm_s == UINT16_UNKNOWN or cog_cdeg == UINT16_UNKNOWN or not 0 <= cog_cdeg < 36000:
        return None
    speed, course = vel_cm_s / 100.0, math.radians(cog_cdeg / 100.0)
    return speed * math.cos(course), speed * math.sin(course), math.nan


GNSS_YAW_SIGMA_DEG = 1.0  # deg: 1-sigma of a GNSS heading whose message gives no accuracy (hdg_acc 0)


def gnss_heading(msg: object) -> tuple[float, float] | None:
    """The heading of a dual-antenna receiver in GPS_RAW_INT, GPS2_RAW or GPS_INPUT (common.xml): ``yaw`` in
    cdeg from true north, clockwise, 0 = not available and 36000 = north; ``hdg_acc`` its 1-sigma in degE5
    (0: unknown; GPS_INPUT has none: GNSS_YAW_SIGMA_DEG). Returns (rad, rad) in (-pi, pi], or None.
    (A GPS_INPUT this service publishes never comes back here: the pipeline drops its own component's.)"""
    if msg.get_type() not in ("GPS_RAW_INT", "GPS2_RAW", "GPS_INPUT"):  # type: ignore[attr-defined]
        return None
    y = getattr(msg, "yaw", 0)
    if not 0 < y <= 36000:
        return None
    acc = getattr(msg, "hdg_acc", 0)
    sigma = acc * 1e-5 if acc > 0 else GNSS_YAW_SIGMA_DEG
    return math.radians(math.remainder(y / 100.0, 360.0)), math.radians(sigma)


def gnss_invalid(fix: tuple) -> str | None:
    """Why a decoded fix cannot be used (``"out_of_range"``, ``"inaccurate"``), or None: latitude
    and longitude within their ranges, the height within GNSS_HEIGHT_RANGE and the horizontal speed
    at most GNSS_MAX_SPEED, every value finite (a NaN vertical velocity means "not measured": ground
    speed and course), accuracies at most GNSS_MAX_SIGMA."""
    _, lat, lon, h, vel, sig_h, sig_v, sig_vel = fix
    values = (lat, lon, h, sig_h, sig_v, sig_vel, *(vel[:2] if vel else ()))  # vel[2] NaN: horizontal only
    if not all(math.isfinite(v) for v in values) or abs(lat) > 90.0 or abs(lon) > 180.0 \
            or (vel is not None and math.isinf(vel[2])):
        return "out_of_range"
    if not GNSS_HEIGHT_RANGE[0] <= h <= GNSS_HEIGHT_RANGE[1] or \
            (vel is not None and math.hypot(vel[0], vel[1]) > GNSS_MAX_SPEED):
        return "out_of_range"
    if not (0.0 < sig_h <= GNSS_MAX_SIGMA and 0.0 < sig_v <= GNSS_MAX_SIGMA and sig_vel > 0.0):
        return "inaccurate"
    return None


def isa_height(press_hpa: float) -> float:
    """Pressure altitude (m) of a static pressure (hPa) in the ICAO standard atmosphere:
    ``h = (1 - (p / 1013.25)^(1 / 5.25588)) / 2.25577e-5`` (troposphere; ICAO Doc 7488).
    Its offset from the ellipsoidal height is a filter state."""
    return (1.0 - (press_hpa / 1013.25) ** (1.0 / 5.25588)) / 2.25577e-5

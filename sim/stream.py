"""Stream a simulated run over MAVLink the way an autopilot does.

Messages (MAVLink 2, common dialect), all stamped with the simulated sensor
time (``time_usec``/``time_boot_ms``):

* HEARTBEAT at 1 Hz (MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_GENERIC);
* HIGHRES_IMU (SI units, ``id`` 0) or RAW_IMU (int16 mG and mrad/s, ArduPilot's
  scaling) for every IMU sample; HIGHRES_IMU carries interval averages (like
  PX4) or instantaneous samples, as chosen; extra IMUs (``imus`` 2 or 3), each
  with its own sensor errors of the same grade, as HIGHRES_IMU ``id`` 1, 2 or,
  with RAW_IMU, as SCALED_IMU2 / SCALED_IMU3 (mG, mrad/s);
* SIM_STATE with the ground truth, sent straight after the IMU message of the
  same instant at ``truth_rate`` (it has no time field: pair it with the IMU
  message before it);
* ATTITUDE (10 Hz): the simulated autopilot's own attitude estimate, taken as
  the vehicle's true attitude;
* GPS_RAW_INT (5 Hz; ``gps_rate`` 0: none) and SCALED_PRESSURE (10 Hz) from the truth with noise;
* with ``vision_rate`` > 0, ODOMETRY from a camera (component 197, MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY):
  frame LOCAL_FRD, child BODY_FRD, the pose and body velocity of sim.aiding.camera_pose (the frame of
  ``vision``, its origin counted from the first sample's position) with their covariances, and
  GPS_GLOBAL_ORIGIN (the first sample's position) with each HEARTBEAT, as an autopilot that navigates
  without GNSS sends its origin;
* with ``mag_rate`` > 0, the magnetometer in the first HIGHRES_IMU of each
  1/mag_rate (gauss, ``fields_updated`` bits 6-8 set, as PX4 marks a new
  magnetometer sample): the Earth field of sim.aiding.MagConfig seen by the
  IMU plus its noise (sim.aiding.body_field, its own random stream).

Pacing: ``speed`` 1 = real time, X = X times faster, None = no pacing.
"""

from __future__ import annotations

import dataclasses
import math
import queue
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator

import numpy as np

from . import errors
from .aiding import MagConfig, VisionConfig, WheelConfig, body_field, camera_pose, forward_speed
from .generate import SimRun
from .trajectory import instant_rates

from mavins.link.mavlink import mavlink, mavutil
from mavins.link.publish import COV_DIAG
from mavins.common.progress import Progress

G0 = 9.80665  # ArduPilot's mG scale (m/s^2 per 1000 mG)
HIGHRES_ACC_GYRO = 0b111111  # fields_updated: x/y/z acc and gyro
HIGHRES_MAG = 0b111000000  # fields_updated: x/y/z magnetometer
GAUSS_PER_UT = 0.01
WHEEL_SCALE = WheelConfig().scale  # the streamed odometer's scale-factor error, as wheel.csv's
CAMERA_COMPONENT = mavlink.MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY  # 197: the camera's ODOMETRY comes from it


@dataclass(frozen=True)
class StreamOptions:
    """How to stream: IMU message, rate semantics, pace and identity."""

    msg: str = "highres"
    imu_rates: str = "averaged"
    speed: float | None = 1.0
    sysid: int = 1
    compid: int = mavlink.MAV_COMP_ID_AUTOPILOT1
    truth_rate: float = 50.0
    gps_rate: float = 5.0
    baro_rate: float = 10.0
    attitude_rate: float = 10.0
    raw_acc_scale: float = G0 / 1000.0  # m/s^2 per RAW_IMU count
    raw_gyro_scale: float = 1e-3  # rad/s per RAW_IMU count
    seed: int = 0
    imus: int = 1  # 1..3; extra IMUs: HIGHRES_IMU id 1, 2 (highres) or SCALED_IMU2/3 (raw)
    gnss_outages: tuple[tuple[float, float], ...] = ()  # (start, end) s of sensor time without GPS_RAW_INT
    gnss_latency: float = 0.0  # s: each GNSS fix is sent this long after it was measured, stamped when sent
    gnss_heading: float = 0.0  # rad: 1-sigma of a dual-antenna heading in GPS_RAW_INT (yaw, hdg_acc); 0 = none
    mag_rate: float = 0.0  # Hz of magnetometer samples in HIGHRES_IMU id 0 (0 = none)
    mag: MagConfig = MagConfig()  # the field and the sensor's noise
    wheel_rate: float = 0.0  # Hz of WHEEL_DISTANCE (one wheel at the IMU: the forward distance, 1 % long; 0 = none)
    vision_rate: float = 0.0  # Hz of ODOMETRY from a camera (pose and body velocity in its frame; 0 = none)
    vision: VisionConfig = VisionConfig()  # the camera's frame and noise


@dataclass
class StreamStats:
    """What was sent."""

    imu_messages: int = 0
    truth_messages: int = 0
    messages: int = 0


def _every(times: np.ndarray, rate: float, last: float | None = None) -> tuple[np.ndarray, float | None]:
    """Boolean mask: the first sample at or after each multiple of 1/rate (``last``: the period index of
    the sample before ``times[0]``, None at the start); and the period index of the last sample."""
    if len(times) == 0:
        return np.zeros(0, bool), last
    k = np.floor(times * rate + 1e-9)
    prev = np.concatenate(([np.nan if last is None else last], k[:-1]))
    return k != prev, float(k[-1])


def frames(run: SimRun | Iterable[SimRun], mav: mavlink.MAVLink, opts: StreamOptions
           ) -> Iterator[tuple[float, list[mavlink.MAVLink_message]]]:
    """Yield (sensor time s, messages) for each IMU sample, in order: of one run, or of the consecutive
    pieces of sim.generate.generate_chunks (each piece's messages made as it arrives)."""
    rng = np.random.default_rng(opts.seed + 1)
    mag_rng = np.random.default_rng([opts.seed, 0x6E3])  # apart from the GPS/baro noise
    heading_rng = np.random.default_rng([opts.seed, 0x4EAD])  # the dual-antenna heading's, likewise
    vision_rng = np.random.default_rng([opts.seed, 0x7150])  # the camera's, likewise
    last: dict[str, float | None] = {}
    pending: list[tuple[float, tuple]] = []  # GNSS fixes measured, not yet sent (gnss_latency), across pieces
    whole = isinstance(run, SimRun)
    for piece in ([run] if whole else run):
        if not whole and len(piece.extra) < opts.imus - 1:
            raise ValueError(f"streaming {opts.imus} IMUs from pieces: make them with generate_chunks(imus={opts.imus})")
        yield from _piece_frames(piece, mav, opts, rng, mag_rng, heading_rng, vision_rng, last, pending)


def _piece_frames(run: SimRun, mav: mavlink.MAVLink, opts: StreamOptions, rng: np.random.Generator,
                  mag_rng: np.random.Generator, heading_rng: np.random.Generator, vision_rng: np.random.Generator,
                  last: dict[str, float | None],
                  pending: list[tuple[float, tuple]]
                  ) -> Iterator[tuple[float, list[mavlink.MAVLink_message]]]:
    """frames() of one run or piece; ``last`` carries the periods of the message rates between pieces,
    ``pending`` the GNSS fixes measured but not yet due (``opts.gnss_latency``): a fix measured at t is sent
    with the first IMU sample at or after t + latency and stamped with that sample's time, as a receiver
    with output latency is stamped by the autopilot that reads it."""
    if opts.imu_rates == "averaged" or opts.msg == "raw":
        # each message averages over its own (true) sample interval, like PX4's
        # integral over the last period: after a dropped sample it does not cover the gap
        dt_true = np.diff(np.concatenate(([run.exact.t0], run.exact.t)))[run.kept][:, None]
        w, f = run.dtheta / dt_true, run.dv / dt_true
    else:
        # instantaneous truth plus the same sensor errors the increments carry
        w_true, f_true = instant_rates(run.exact)
        dt = np.diff(np.concatenate(([run.exact.t0], run.exact.t)))[:, None]
        kept = run.kept
        w = w_true[kept] + (run.dtheta - run.exact.dtheta[kept]) / dt[kept]
        f = f_true[kept] + (run.dv - run.exact.dv[kept]) / dt[kept]
    extra = _extra_imus(run, opts)
    truth = run.exact.truth[1:][run.kept]
    t = run.t

    def every(name: str, rate: float) -> np.ndarray:
        mask, last[name] = _every(t, rate, last.get(name))
        return mask

    send_truth = every("truth", opts.truth_rate)
    send_gps = every("gps", opts.gps_rate) if opts.gps_rate > 0 else np.zeros(len(t), bool)
    send_baro = every("baro", opts.baro_rate)
    send_att = every("attitude", opts.attitude_rate)
    send_hb = every("heartbeat", 1.0)
    send_mag = every("mag", opts.mag_rate) if opts.mag_rate > 0 and opts.msg == "highres" else np.zeros(len(t), bool)
    send_wheel = every("wheel", opts.wheel_rate) if opts.wheel_rate > 0 else np.zeros(len(t), bool)
    if opts.wheel_rate > 0 and len(t):
        # the forward speed at the IMU (wheel.csv's model, lever arm 0), integrated over each sample interval
        u = forward_speed(truth[:, 10:14], truth[:, 4:7], w, (0.0, 0.0, 0.0))
        t0 = last.get("wheel_t")
        t_prev = np.concatenate(([t[0] if t0 is None else t0], t[:-1]))
        d0 = last.get("wheel_d")
        d = (0.0 if d0 is None else d0) + np.cumsum(u * (t - t_prev)) * (1.0 + WHEEL_SCALE)
        last["wheel_t"], last["wheel_d"] = float(t[-1]), float(d[-1])
    camera: dict[int, np.ndarray] = {}
    origin: tuple[int, int, int] | None = None  # GPS_GLOBAL_ORIGIN's degE7, degE7, mm, sent with each HEARTBEAT
    if opts.vision_rate > 0 and len(t):
        if last.get("vision_lat") is None:  # the camera frame's origin is counted from the first sample's position
            last["vision_lat"], last["vision_lon"], last["vision_h"] = (
                math.radians(truth[0, 1]), math.radians(truth[0, 2]), float(truth[0, 3]))
        start = (last["vision_lat"], last["vision_lon"], last["vision_h"])
        origin = (int(round(math.degrees(start[0]) * 1e7)), int(round(math.degrees(start[1]) * 1e7)),  # type: ignore[arg-type]
                  int(round(start[2] * 1000)))  # type: ignore[operator]
        idx = np.flatnonzero(every("vision", opts.vision_rate))
        llh = np.column_stack([np.radians(truth[idx, 1]), np.radians(truth[idx, 2]), truth[idx, 3]])
        camera = dict(zip(idx.tolist(), camera_pose(llh, truth[idx, 10:14], truth[idx, 4:7], start, opts.vision,
                                                    vision_rng)))
    for i in range(len(t)):
        usec = int(round(t[i] * 1e6))
        out: list[mavlink.MAVLink_message] = []
        if send_hb[i]:
            out.append(mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_GENERIC,
                                            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, mavlink.MAV_STATE_ACTIVE))
            if origin is not None:
                out.append(mav.gps_global_origin_encode(*origin, usec))
        if opts.msg == "raw":
            acc = np.clip(np.round(f[i] / opts.raw_acc_scale), -32768, 32767).astype(int)
            gyr = np.clip(np.round(w[i] / opts.raw_gyro_scale), -32768, 32767).astype(int)
            out.append(mav.raw_imu_encode(usec, *acc, *gyr, 0, 0, 0, 0, 0))
        elif send_mag[i]:
            m_b = body_field(truth[i, 10:14], opts.mag, opts.mag.sigma * mag_rng.standard_normal(3), truth[i, 0])
            out.append(mav.highres_imu_encode(usec, *f[i], *w[i], *(m_b * GAUSS_PER_UT), 0.0, 0.0, 0.0, 20.0,
                                              HIGHRES_ACC_GYRO | HIGHRES_MAG, 0))
        else:
            out.append(mav.highres_imu_encode(usec, *f[i], *w[i], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0,
                                              HIGHRES_ACC_GYRO, 0))
        for k, (wk, fk) in enumerate(extra, start=1):
            if opts.msg == "raw":
                acc = [int(v) for v in np.clip(np.round(fk[i] / opts.raw_acc_scale), -32768, 32767)]
                gyr = [int(v) for v in np.clip(np.round(wk[i] / opts.raw_gyro_scale), -32768, 32767)]
                enc = mav.scaled_imu2_encode if k == 1 else mav.scaled_imu3_encode
                out.append(enc(usec // 1000 % (2**32), *acc, *gyr, 0, 0, 0, 2000))
            else:
                out.append(mav.highres_imu_encode(usec, *fk[i], *wk[i], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0,
                                                  HIGHRES_ACC_GYRO, k))
        row = truth[i]
        if send_truth[i]:
            q = row[10:14]
            lat, lon = row[1], row[2]
            out.append(mav.sim_state_encode(
                float(q[0]), float(q[1]), float(q[2]), float(q[3]),
                math.radians(row[7]), math.radians(row[8]), math.radians(row[9]),
                *map(float, f[i]), *map(float, w[i]),
                float(lat), float(lon), float(row[3]), 0.0, 0.0,
                float(row[4]), float(row[5]), float(row[6]),
                int(round(lat * 1e7)), int(round(lon * 1e7)),
            ))
        if send_att[i]:
            e = np.radians(row[14:17])
            out.append(mav.attitude_encode(usec // 1000 % (2**32), float(e[0]), float(e[1]), float(e[2]), 0.0, 0.0, 0.0))
        if send_gps[i] and not any(a <= t[i] < b for a, b in opts.gnss_outages):
            noise = rng.normal(0.0, [0.5, 0.5, 1.0])
            lat = row[1] + math.degrees(noise[0] / 6.371e6)
            lon = row[2] + math.degrees(noise[1] / (6.371e6 * max(math.cos(math.radians(row[1])), 1e-6)))
            vel = math.hypot(row[4], row[5])
            cog = (math.degrees(math.atan2(row[5], row[4])) + 360.0) % 360.0
            yaw_cd, hdg_acc = 0, 100  # no dual-antenna heading (yaw 0: not available)
            if opts.gnss_heading > 0.0:  # the vehicle's true yaw plus N(0, sigma); 36000 for north, 0 = none
                yaw = math.degrees(math.radians(row[16]) + opts.gnss_heading * heading_rng.standard_normal())
                yaw_cd = int(round(yaw * 100.0)) % 36000 or 36000
                hdg_acc = int(round(math.degrees(opts.gnss_heading) * 1e5))
            pending.append((t[i] + opts.gnss_latency, (
                3, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round((row[3] + noise[2]) * 1000)),
                80, 120, int(round(vel * 100)), int(round(cog * 100)) % 36000, 12,
                int(round((row[3] + noise[2]) * 1000)), 500, 800, 50, hdg_acc, yaw_cd,
            )))
        while pending and pending[0][0] <= t[i] + 1e-9:  # due (within rounding of the sample grid)
            out.append(mav.gps_raw_int_encode(usec, *pending.pop(0)[1]))
        if send_wheel[i]:
            out.append(mav.wheel_distance_encode(usec, 1, [float(d[i])] + [0.0] * 15))
        if i in camera:
            out.append(_camera_odometry(camera[i], usec, opts.vision, mav))
        if send_baro[i]:
            press = 1013.25 * (1 - 2.25577e-5 * row[3]) ** 5.25588 + rng.normal(0.0, 0.012)
            out.append(mav.scaled_pressure_encode(usec // 1000 % (2**32), press, 0.0, 2000, 0))
        yield float(t[i]), out


def _camera_odometry(row: np.ndarray, usec: int, cfg: VisionConfig, mav: mavlink.MAVLink) -> mavlink.MAVLink_message:
    """A camera's ODOMETRY (sim.aiding.camera_pose's row), its covariances' diagonals (upper triangles of 6 x 6,
    COV_DIAG) the configured variances, the body rates unknown (NaN); sent from the camera's component
    (``sim_component``: :func:`stream` sends it as that component, not the autopilot's)."""
    pose, vel = [0.0] * 21, [0.0] * 21
    for k, i in enumerate(COV_DIAG):
        pose[i] = cfg.sigma_pos ** 2 if k < 3 else cfg.sigma_att ** 2
        vel[i] = cfg.sigma_vel ** 2 if k < 3 else math.nan
    msg = mav.odometry_encode(usec, mavlink.MAV_FRAME_LOCAL_FRD, mavlink.MAV_FRAME_BODY_FRD, *map(float, row[0:3]),
                              [float(v) for v in row[3:7]], *map(float, row[7:10]), math.nan, math.nan, math.nan,
                              pose, vel, 0, mavlink.MAV_ESTIMATOR_TYPE_VIO, 100)
    msg.sim_component = CAMERA_COMPONENT
    return msg


def _extra_imus(run: SimRun, opts: StreamOptions) -> list[tuple[np.ndarray, np.ndarray]]:
    """Averaged rates of the extra IMUs on the primary's kept samples (own error draws, no drops/jitter);
    those of the run (generate(imus=...), with its faults) when it has them."""
    if not 1 <= opts.imus <= 3:
        raise ValueError(f"imus must be 1..3, got {opts.imus}")
    if len(run.extra) >= opts.imus - 1:
        dt_kept = np.diff(np.concatenate(([run.exact.t0], run.exact.t)))[run.kept][:, None]
        return [(dth / dt_kept, dv / dt_kept) for dth, dv in run.extra[: opts.imus - 1]]
    model = dataclasses.replace(errors.grade(run.grade), jitter_sigma=0.0, drop_probability=0.0)
    dt = np.diff(np.concatenate(([run.exact.t0], run.exact.t)))[:, None]
    out = []
    for k in range(1, opts.imus):
        _, dth, dv, _ = errors.apply(model, run.exact.t, run.exact.dtheta, run.exact.dv, run.seed + 7919 * k,
                                     t_start=run.exact.t0)
        out.append(((dth / dt)[run.kept], (dv / dt)[run.kept]))
    return out


def ahead(pieces: Iterable[SimRun], depth: int = 2) -> Iterator[SimRun]:
    """The pieces, made in a background thread up to ``depth`` ahead of the consumer (the simulator's
    kernels release the GIL, so making the next piece overlaps sending this one). An error while making
    them is raised here, after the pieces made before it; closing the iterator stops the thread."""
    box: queue.Queue = queue.Queue(maxsize=depth)
    end = object()
    quit_ = threading.Event()
    failure: list[BaseException] = []

    def put(item: object) -> bool:
        while not quit_.is_set():
            try:
                box.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for piece in pieces:
                if not put(piece):
                    return
        except BaseException as exc:  # handed to the consumer
            failure.append(exc)
        put(end)

    thread = threading.Thread(target=work, name="sim-pieces", daemon=True)
    thread.start()
    try:
        while True:
            item = box.get()
            if item is end:
                break
            yield item
        if failure:
            raise failure[0]
    finally:
        quit_.set()


def stream(run: SimRun | Iterable[SimRun], url: str, opts: StreamOptions, stop: threading.Event | None = None,
           hold: Callable[[int], None] | None = None, progress: Progress | None = None) -> StreamStats:
    """Send the run to a pymavlink connection URL (e.g. ``udpout:127.0.0.1:14551``): one SimRun, or the
    pieces of sim.generate.generate_chunks, made ahead in a background thread (:func:`ahead`) so that
    the first message leaves as soon as the first piece is made.

    ``hold(n)``, when given, is called before each sample's messages with the number sent so far and may
    block until the receiver has caught up (``mavins demo --speed max``: a UDP socket holds a few hundred
    datagrams, and what overflows it is lost). ``progress`` is updated with the sensor time sent.
    """
    conn = mavutil.mavlink_connection(url, source_system=opts.sysid, source_component=opts.compid, dialect="ardupilotmega")
    stats = StreamStats()
    start: list[float] = []  # the run's start (sensor time) and the wall clock then
    made = None if isinstance(run, SimRun) else ahead(run)

    def paced(source: Iterable[SimRun]) -> Iterator[SimRun]:
        for piece in source:
            if not start:
                start.extend((piece.exact.t0, time.monotonic()))
            yield piece

    if isinstance(run, SimRun):
        start.extend((run.exact.t0, time.monotonic()))
    try:
        for t_s, msgs in frames(run if made is None else paced(made), conn.mav, opts):
            if stop is not None and stop.is_set():
                break
            if hold is not None:
                hold(stats.messages)
            if opts.speed is not None:
                delay = start[1] + (t_s - start[0]) / opts.speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            for m in msgs:
                comp = getattr(m, "sim_component", None)  # another component of the vehicle (the camera's)
                conn.mav.srcComponent = opts.compid if comp is None else comp
                conn.mav.send(m)
                stats.messages += 1
            stats.imu_messages += 1
            stats.truth_messages += sum(1 for m in msgs if m.get_msgId() == mavlink.MAVLINK_MSG_ID_SIM_STATE)
            if progress is not None:
                progress.update(t_s - start[0])
    finally:
        conn.close()
        if made is not None:
            made.close()  # type: ignore[attr-defined]
    return stats

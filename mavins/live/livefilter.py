"""The error-state filter on the live path: a thin stateful shell over mavins.core.

The engine feeds every navigating IMU sample through :meth:`LiveFilter.push`
(bias correction, strapdown, covariance propagation: core/aided.py) and hands
measurements over as they arrive (GNSS, barometric height, magnetometer,
zero velocity). Each measurement is applied at its own time on the IMU clock:
one stamped at or before the last attitude update is taken back along the
velocity (core/kalman.py); one stamped after it waits for the update that
passes its time. Everything numeric happens in the compiled core; this class
keeps the arrays, the counters and what the status messages report.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ..core import aided, earth, errmodel, kalman, smoother
from ..core import strapdown as sd
from ..core.frames import north_east_error
from ..core.jit import for_frame
from ..core.records import Uncertainty
from .smoothing import EpochLog

AIDING_KINDS = ("gnss", "baro", "mag", "zupt", "nhc", "wheel", "vision")
# the --aiding kind a measurement comes with where its name differs (a dual-antenna heading with GNSS)
AIDING_OF = {"gnss_yaw": "gnss", "vision_vel": "vision", "vision_body": "vision", "vision_pose": "vision"}
ABS_TIMEOUT_S = 5.0  # s of sensor time after the last accepted fix during which position counts as absolute
GNSS_LOST_S = 3.0  # s without an accepted fix after which GNSS is reported lost
JUMP_M = 1.0  # m: an accepted position correction above this is a discontinuity (reset_counter)
GNSS_HEADING = "GNSS yaw"  # heading source: a dual-antenna receiver's heading (GPS_RAW_INT yaw)
GNSS_YAW_PENDING = "GNSS velocity (pending)"  # heading source: none yet, found from GNSS velocity once moving
VISION_HEADING = "vision"  # heading source: a camera's attitude in its own frame (its x axis taken as north)


def _column(first: str) -> slice:
    """The three columns of aided.OUT_COLUMNS from ``first`` on (x, y, z or north, east, down)."""
    i = aided.OUT_COLUMNS.index(first)
    return slice(i, i + 3)


@dataclass
class FilterSettings:
    """How the live filter is set up (docs/filter.md)."""

    spec: str | dict = "consumer"  # grade name or the contract's IMU spec keys
    aiding: tuple[str, ...] = ("gnss", "baro", "mag")
    gate: float = 5.0
    lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    declination: float = 0.0  # deg, east positive (the engine sets its --declination here)
    mag_model: tuple[float, float] | None = None  # the model's inclination (deg) and strength (gauss): disturbance gate
    sigma_pos: float = 10.0  # m: initial position 1-sigma without a fix
    sigma_vel: float = 0.1  # m/s: initial velocity 1-sigma (aligned at rest)
    sigma_level: float = 1.0  # deg
    sigma_yaw: float = 10.0  # deg
    sigma_baro_offset: float = 50.0  # m
    sigma_mag: float = math.degrees(aided.DEFAULT_SIGMA_MAG)  # deg of heading (the batch filter's default)
    scale_factors: bool = False  # estimate the gyro and accelerometer scale factors (errmodel.spec_of)
    misalignment: bool = False  # estimate the gyro and accelerometer misalignments (errmodel.spec_of)
    sigma_mag_bias: float = 0.0  # gauss per axis: initial 1-sigma of the hard iron (0: taken as calibrated, not estimated)
    sigma_zupt: float = aided.DEFAULT_SIGMA_ZUPT  # m/s (the batch filter's default)
    wheel_lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, body FRD: the odometer's axle centre
    sigma_wheel: float = aided.DEFAULT_SIGMA_WHEEL  # m/s: the odometer's speed noise
    wheel_scale: float = aided.DEFAULT_WHEEL_SCALE  # its scale factor's initial 1-sigma (estimated with wheel aiding)
    sigma_nhc: float = aided.DEFAULT_SIGMA_NHC  # m/s: the non-holonomic constraint's sideways and vertical body velocity
    vision_drift: float = aided.DEFAULT_VISION_DRIFT  # m/sqrt(s): random walk of a camera frame's origin
    vision_yaw_drift: float = aided.DEFAULT_VISION_YAW_DRIFT  # deg/sqrt(h): random walk of its heading
    predict_dt: float = 0.01  # s: the covariance is propagated at about this interval
    delays: dict[str, float] = field(default_factory=dict)  # s by kind (gnss, baro, mag): measured this long before its stamp
    smooth: bool = False  # keep the smoother's epochs (EpochLog) for a fixed-interval smoothed solution afterwards


@dataclass
class LiveFilter:
    """P, the bias estimates and the bookkeeping of one navigation run.

    ``ratios`` are the published test ratios: the largest normalised innovation
    component over the gate, squared (PX4's convention, innovation^2 / (gate^2
    S); below 1 passes the gate).
    """

    settings: FilterSettings
    counters: Counter = field(default_factory=Counter)
    events: list[tuple[str, str]] = field(default_factory=list)
    resets: int = 0

    def __post_init__(self) -> None:
        for k in self.settings.aiding:
            if k not in AIDING_KINDS:
                raise ValueError(f"aiding kinds are {', '.join(AIDING_KINDS)} (or none), got {k!r}")
        st = self.settings
        self.spec = errmodel.make_spec(st.spec, scale_factors=st.scale_factors, misalignment=st.misalignment,
                                       wheel_scale=st.wheel_scale if "wheel" in st.aiding else 0.0,
                                       # the camera frame's walks only with a camera: else its states stay out
                                       vision_drift=st.vision_drift if "vision" in st.aiding else 0.0,
                                       vision_yaw_drift=math.radians(st.vision_yaw_drift) / 60.0
                                       if "vision" in st.aiding else 0.0)
        self.lever = np.asarray(st.lever_arm, dtype=float).reshape(3)
        self.wheel_lever = np.asarray(st.wheel_lever_arm, dtype=float).reshape(3)
        self.P = np.zeros((errmodel.NX, errmodel.NX))
        self.bias = np.zeros(kalman.B_SIZE)
        self.acc = np.zeros(aided.ACC_SIZE)
        self.sums = np.zeros(7)
        self.predict_every = 1
        self._pending: list[tuple[float, str, tuple]] = []
        self.ratios: dict[str, float] = {}
        self.last_pos_t = -math.inf
        self.last_hgt_t = -math.inf
        self.glitch = False
        self.gnss_seen = False
        self.gnss_lost = False
        self._w_ib = (0.0, 0.0, 0.0)  # body rate (rad/s) at the last attitude update, bias removed
        self._t_prev_k = 0.0
        self._T_k = 0.0  # s: the last attitude interval (velocity fixes are interpolated over it)
        self._incl = np.zeros(kalman.MAG_STATS)  # running sums over the accepted magnetometer samples
        self.free = kalman.ALL  # the states an update may correct (kalman.update); the engine holds the heading back
        self._kept = False  # whether the measurement being applied changed the filter (_apply)
        self.epochs: EpochLog | None = None  # the smoother's epochs since the last start (settings.smooth)
        self.vision_ref: np.ndarray | None = None  # lat, lon (rad), h (m): where the vision frame's origin is counted from
        self.vision_frame: int | None = None  # the reset_counter of the camera frame placed (None: none placed)
        self._placed = False  # whether the measurement being applied placed a camera frame (_apply)
        self._bind(sd.GEOGRAPHIC)

    def _bind(self, frame: int) -> None:
        """The kernels of the live path compiled for ``frame`` (strapdown.kernel_frame), bound once."""
        self._push_kernel = for_frame(aided.push_rate_aided, frame)
        self._flush_kernel = for_frame(aided.flush_propagation, frame)
        self._position_kernel = for_frame(sd.position, frame)

    # -- lifecycle ---------------------------------------------------------------
    def start(self, s: np.ndarray, cfg: np.ndarray, gyro_bias: np.ndarray, dt_sample: float,
              sigma_pos: float | None = None, heading_source: str = "--heading", lat: float = 0.0,
              bias_window_s: float = 0.0) -> None:
        """Begin at the end of the alignment, for the strapdown configuration cfg (its frame and
        samples per update): P from the settings and the alignment's sources,
        the gyro bias from the rest window (``bias_window_s`` > 0: a zero-rate calibration over
        that many seconds, whose 1-sigma replaces the spec's turn-on sigma)."""
        st = self.settings
        sigma_yaw = math.radians(self.yaw_sigma_deg(heading_source, lat))
        self.P = kalman.initial_covariance(self.spec, sigma_pos or st.sigma_pos, st.sigma_vel,
                                           math.radians(self.level_sigma_deg()), sigma_yaw, st.sigma_baro_offset,
                                           st.sigma_mag_bias)
        # a rest window: the window mean's white-noise part ARW / sqrt(T), and the Earth rate misattributed
        # through the heading error (Omega sigma_yaw); the Gauss-Markov part keeps its own state
        var = self.spec[errmodel.SP_GYRO_ARW] ** 2 / bias_window_s + (earth.OMEGA * sigma_yaw) ** 2 \
            if bias_window_s > 0.0 else 0.0
        self.bias[:] = 0.0
        kalman.calibrated_gyro_bias(self.P, self.bias, np.asarray(gyro_bias, dtype=float), var)
        self.acc = np.zeros(aided.ACC_SIZE + (errmodel.NX ** 2 if st.smooth else 0))
        self.sums[:] = 0.0
        self.sums[6] = sd.state_time(s)
        if st.smooth:
            self.restart_epochs(s)
        self._t_prev_k = sd.state_time(s)
        self._T_k = 0.0
        self._incl = aided.mag_stats(self.P)  # running sums of aided.apply_mag
        samples = int(cfg[sd.CFG_SAMPLES])
        self.predict_every = max(1, int(round(st.predict_dt / max(dt_sample * samples, 1e-6))))
        self._bind(sd.kernel_frame(cfg))
        self._pending.clear()
        self.ratios.clear()
        self.last_pos_t = self.last_hgt_t = -math.inf
        self.glitch = False
        self.vision_ref = None
        self.vision_frame = None

    def restart_epochs(self, s: np.ndarray) -> None:
        """A new smoother log from the state s on (at every start, and after a reset that moved the
        solution without an update, such as the heading's): the smoother never reaches across one, and
        the rows written before it keep the forward solution (docs/postprocessing.md)."""
        smoother.reset_transition(self.acc[aided.ACC_SIZE:])
        self.epochs = EpochLog(np.flatnonzero(np.diag(self.P) > 0.0),
                               0 if self.epochs is None else self.epochs.generation + 1)
        self.epochs.record(sd.state_time(s), self.P, self.P, self.acc, np.zeros(errmodel.NX))

    def level_sigma_deg(self) -> float:
        """1-sigma of the coarse level (deg): the accelerometer bias over g (textbook ch. 4 limit),
        never below 0.05 deg nor above the settings' value."""
        limit = math.degrees(math.atan(self.spec[errmodel.SP_ACC_BIAS] / 9.8))
        return min(self.settings.sigma_level, max(0.05, limit))

    def yaw_sigma_deg(self, source: str, lat: float) -> float:
        """1-sigma of the initial heading (deg) by its source: a typed number the settings'
        value; the vehicle's own estimate 1; the magnetometer 5; gyrocompassing the gyro
        bias over the horizontal Earth rate (textbook ch. 4 limit), at most 30."""
        if source == "vehicle ATTITUDE":
            return min(1.0, self.settings.sigma_yaw)  # an autopilot EKF heading: about 1 deg
        if source == "magnetometer":
            return min(5.0, self.settings.sigma_yaw)
        if source == GNSS_HEADING:  # a dual-antenna receiver: about 1 deg
            return min(2.0, self.settings.sigma_yaw)
        if source == VISION_HEADING:  # the camera frame's x axis as north: true only as far as it was set up so
            return self.settings.sigma_yaw
        if source == GNSS_YAW_PENDING:  # any heading, uniform on the circle
            return 180.0 / math.sqrt(3.0)
        if source == "gyrocompass":
            horiz = earth.OMEGA * max(math.cos(lat), 1e-3)
            return min(30.0, max(0.05, math.degrees(math.atan(self.spec[errmodel.SP_GYRO_BIAS] / horiz))))
        return self.settings.sigma_yaw

    def push(self, s: np.ndarray, cfg: np.ndarray, t: float, w: tuple, f: tuple) -> int:
        """One IMU sample (rad/s, m/s^2, FRD, raw): strapdown plus filter; 1 when an attitude
        update completed (pending measurements whose time it passed are then applied)."""
        r = self._push_kernel(s, cfg, self.spec, self.P, self.bias, self.acc, self.sums, t,
                              w[0], w[1], w[2], f[0], f[1], f[2], self.predict_every)
        if r == 1:
            tk = sd.state_time(s)
            ep = self.epochs
            if ep is not None and self.acc[12] == 0.0 and tk - ep.t_last >= aided.SMOOTH_DT:
                ep.record(tk, self.P, self.P, self.acc, np.zeros(errmodel.NX))  # none for a while: one anyway
            T = tk - self._t_prev_k
            self._t_prev_k = tk
            if T > 0.0:
                self._T_k = T
                self._w_ib = self.body_rate(w)
            if self._pending:
                due = [p for p in self._pending if p[0] <= tk]
                self._pending = [p for p in self._pending if p[0] > tk]
                for t_m, kind, args in due:
                    self._apply(s, cfg, t_m, kind, args)
        return r

    @property
    def gyro_bias(self) -> np.ndarray:
        """Gyro bias estimate (rad/s, body): constant plus Gauss-Markov part."""
        return kalman.gyro_bias_total(self.bias)

    def body_rate(self, w: tuple) -> tuple[float, float, float]:
        """A raw gyro reading (rad/s, body) corrected by the estimates (kalman.correct_gyro3), as floats."""
        x, y, z = kalman.correct_gyro3(self.bias, float(w[0]), float(w[1]), float(w[2]), 1.0)
        return float(x), float(y), float(z)

    @property
    def accel_bias(self) -> np.ndarray:
        """Accelerometer bias estimate (m/s^2, body)."""
        return kalman.accel_bias_total(self.bias)

    # -- measurements ---------------------------------------------------------------
    def measure(self, s: np.ndarray, cfg: np.ndarray, t_m: float, kind: str, *args: object) -> None:
        """A measurement stamped t_m (s, IMU clock): applied now if the solution has passed it,
        else when it does. Kinds: ``gnss`` (lat, lon rad, h m, vel NED or None, sigma_h, sigma_v,
        sigma_vel), ``gnss_yaw`` (the vehicle's heading rad, sigma rad; with GNSS aiding), ``baro`` (h m,
        sigma), ``mag`` (m_b body), ``zupt`` (), ``nhc`` (), ``wheel`` (speed m/s, sigma), ``vision_vel`` (NED
        m/s, sigma), ``vision_body`` (body m/s, sigmas), ``vision_pose`` (position m, attitude body -> frame or
        None, sigmas m and rad, reset_counter: :meth:`_vision_pose`). A kind with a delay
        (``--gnss-delay`` ...) was measured that long before t_m and is fused at that time: taken back
        along the solution like any measurement older than the last attitude update (kalman.py)."""
        aid = AIDING_OF.get(kind, kind)
        if aid not in self.settings.aiding:
            return
        t_m -= self.settings.delays.get(aid, 0.0)
        if t_m > sd.state_time(s):
            if len(self._pending) < 64:
                self._pending.append((t_m, kind, args))
            else:
                self.counters[f"{kind}_dropped_pending"] += 1
            return
        self._apply(s, cfg, t_m, kind, args)

    def _apply(self, s: np.ndarray, cfg: np.ndarray, t_m: float, kind: str, args: tuple) -> None:
        """One measurement: P propagated to it, the update(s); a measurement that changed nothing (rejected,
        disturbed) leaves P and the pending propagation as they were (aided.keep_or_undo, as the batch)."""
        ep = self.epochs
        if ep is not None:  # the prior of a smoother epoch: P propagated to now, the nominal before the update
            self._flush_kernel(s, cfg, self.spec, self.P, self.acc)
            s0, b0 = s.copy(), self.bias.copy()
        P0, acc0 = self.P.copy(), self.acc.copy()
        self._kept = self._placed = False
        self._measure(s, cfg, t_m, kind, args)
        aided.keep_or_undo(self._kept, self.P, self.acc, P0, acc0)
        if ep is not None and self._placed:  # new states: the smoother's log starts again from here
            self.restart_epochs(s)
        elif ep is not None and self._kept:
            ep.record(sd.state_time(s), P0, self.P, self.acc, smoother.nominal_difference(s0, b0, s, self.bias, cfg))

    def _measure(self, s: np.ndarray, cfg: np.ndarray, t_m: float, kind: str, args: tuple) -> None:
        tk = sd.state_time(s)
        late = max(0.0, tk - t_m)
        self._flush_kernel(s, cfg, self.spec, self.P, self.acc)
        position = self._position_kernel
        if kind == "gnss":
            lat, lon, h, vel, sig_h, sig_v, sig_vel = args
            lat0, lon0, _ = position(s, cfg)
            v_m = np.full(3, math.nan) if vel is None else np.asarray(vel, dtype=float)
            ps, _, _, pratio, vs, _, _, vratio = aided.apply_gnss(
                s, cfg, self.bias, self.P, lat, lon, h, v_m, np.array(self._w_ib), self.lever, late, self._T_k,
                sig_h, sig_v, sig_vel, self.settings.gate, self.free)
            ok = ps == aided.ACCEPTED
            self._count("gnss_pos", ("pos", "hgt"), ok, pratio)
            if ok:
                lat1, lon1, _ = position(s, cfg)
                if math.hypot(*north_east_error(lat1, lon1, lat0, lon0)) > JUMP_M:
                    self.resets += 1
                if self.gnss_lost:
                    self.events.append(("INFO", "GNSS recovered: position aided again"))
                self.gnss_lost = False
                self.gnss_seen = True
                self.last_pos_t = self.last_hgt_t = t_m
            self.glitch = not ok
            if vs == aided.GLITCH:  # a fix whose position failed the gate is a glitch: its velocity too
                self.counters["gnss_vel_rejected"] += 1
            elif vs != aided.ABSENT:
                self._count("gnss_vel", ("vel",), vs == aided.ACCEPTED, vratio)
        elif kind == "baro":
            h, sigma = args
            if self._update(s, cfg, "baro", ("hgt",), kalman.baro_height(s, self.bias, h, late, sigma)):
                self.last_hgt_t = t_m
        elif kind == "mag":
            (m_b,) = args
            model = self.settings.mag_model
            incl, strength = (math.nan, math.nan) if model is None else (math.radians(model[0]), model[1])
            status, _, ratio = aided.apply_mag(
                s, cfg, self.bias, self.P, self._incl, np.asarray(m_b, dtype=float), np.array(self._w_ib), late,
                math.radians(self.settings.declination), math.radians(self.settings.sigma_mag), incl, strength,
                aided.MAG_STRENGTH_GATE, self.settings.gate, self.free)
            self._kept = status >= 1  # accepted, or rejected with the hard iron reset
            if status < 0:  # a motor, steel, a power cable: the field is not the Earth's (aided.apply_mag)
                self.counters["mag_disturbed"] += 1
            else:
                self.counters[f"mag_{'accepted' if status == 1 else 'rejected'}"] += 1
                self.ratios["mag"] = ratio * ratio
        elif kind == "gnss_yaw":  # the heading of a dual-antenna receiver, the vehicle's (rad, 1-sigma rad)
            yaw, sigma = args
            if self.glitch:  # its fix's position failed the gate (the fix comes first): not used either
                self.counters["gnss_yaw_rejected"] += 1
            else:
                self._update(s, cfg, "gnss_yaw", ("mag",), kalman.heading(s, yaw, sigma))
        elif kind == "zupt":
            self._update(s, cfg, "zupt", ("vel",), kalman.zupt(s, self.settings.sigma_zupt))
        elif kind == "wheel":  # a wheel odometer's forward speed (m/s, 1-sigma m/s) at the axle centre
            speed, sigma = args
            self._update(s, cfg, "wheel", ("vel",), kalman.wheel_speed(
                s, self.bias, speed, np.array(self._w_ib), self.wheel_lever, late, self._T_k, sigma))
        elif kind == "vision_vel":  # a camera's or motion capture's velocity, NED (m/s), its 1-sigma (m/s)
            vel, sigma = args
            self._update(s, cfg, "vision_vel", ("vel",), kalman.gnss_velocity(
                s, np.asarray(vel, dtype=float), np.array(self._w_ib), np.zeros(3), late, self._T_k, sigma))
        elif kind == "vision_body":  # the same in the body frame (ODOMETRY's child frame BODY_FRD), sigma per axis
            vel, sigma = args
            self._update(s, cfg, "vision_vel", ("vel",), kalman.body_velocity(
                s, np.asarray(vel, dtype=float), np.asarray(sigma, dtype=float)))
        elif kind == "vision_pose":
            self._vision_pose(s, cfg, late, *args)
        elif kind == "nhc":  # a wheeled vehicle: no sideways and no vertical body velocity
            self._update(s, cfg, "nhc", ("vel",), kalman.nhc(s, self.settings.sigma_nhc))

    def _vision_pose(self, s: np.ndarray, cfg: np.ndarray, late: float, p_v: tuple, c_vb: np.ndarray | None,
                     sigma_p: tuple, sigma_att: tuple, reset: int) -> None:
        """A camera's pose in its own frame (position m, attitude body -> frame, 1-sigmas m and rad per axis),
        ``reset`` its frame's reset_counter: the first pose of a frame places it (kalman.vision_place: counted
        ``vision_frame_placed``; it needs the attitude), the next ones are fused, position and attitude in one
        update (kalman.vision_position, kalman.vision_attitude); the reference point is the solution's
        position at the first placement."""
        p = np.asarray(p_v, dtype=float)
        sp = np.asarray(sigma_p, dtype=float)
        sa = np.asarray(sigma_att, dtype=float)
        if self.vision_frame != reset:
            if c_vb is None:
                self.counters["vision_pose_unplaced"] += 1  # no attitude to place the frame with: the next pose
                return
            if self.vision_ref is None:
                self.vision_ref = np.array(self._position_kernel(s, cfg))
            kalman.vision_place(s, cfg, self.bias, self.P, self.vision_ref, p, c_vb, late, sp, sa)
            self.vision_frame = reset
            self._kept = self._placed = True
            self.counters["vision_frame_placed"] += 1
            return
        nu, H, R = kalman.vision_position(s, cfg, self.bias, self.vision_ref, p, late, sp)
        if c_vb is not None:
            nu_a, H_a, R_a = kalman.vision_attitude(s, self.bias, c_vb, sa)
            nu, H = np.concatenate((nu, nu_a)), np.vstack((H, H_a))
            R = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), R_a]])
        self._update(s, cfg, "vision_pose", ("pos", "hgt"), (nu, H, R))

    def _update(self, s: np.ndarray, cfg: np.ndarray, kind: str, ratio_keys: tuple[str, ...],
                model: tuple[np.ndarray, np.ndarray, np.ndarray]) -> bool:
        """Apply one measurement model (nu, H, R) with the gate, count it, keep its test ratio."""
        nu, H, R = model
        _, ratio, ok = kalman.apply_update(s, cfg, self.bias, self.P, H, nu, R, self.settings.gate, self.free)
        self._count(kind, ratio_keys, bool(ok), ratio)
        return bool(ok)

    def _count(self, kind: str, ratio_keys: tuple[str, ...], ok: bool, ratio: float) -> None:
        """Count an applied update of ``kind`` and keep its test ratio (squared) under ``ratio_keys``."""
        self._kept = self._kept or ok
        self.counters[f"{kind}_{'accepted' if ok else 'rejected'}"] += 1
        for key in ratio_keys:
            self.ratios[key] = ratio * ratio

    def tick(self, t: float) -> None:
        """Bookkeeping at an output: GNSS loss after GNSS_LOST_S without an accepted fix."""
        if self.gnss_seen and not self.gnss_lost and t - self.last_pos_t > GNSS_LOST_S:
            self.gnss_lost = True
            self.counters["gnss_lost"] += 1
            self.events.append(("WARNING", f"GNSS lost: no accepted fix for {GNSS_LOST_S:.0f} s, free inertial"))

    # -- what is published ------------------------------------------------------------
    def output_row(self, row: np.ndarray) -> np.ndarray:
        """A solution row (kernel units) extended by the filter's columns (core.aided.ROW_COLUMNS:
        1-sigma, bias, scale-factor and hard-iron estimates and their 1-sigma, kernel units), as
        ``mavins nav`` computes them (aided.file_columns picks a file's)."""
        out = np.zeros(aided.ROW_SIZE)
        out[:sd.OUT_SIZE] = row
        aided.filter_row(self.P, self.bias, out)
        return out

    def uncertainty(self, t: float, resets: int) -> Uncertainty:
        """1-sigma, test ratios and aiding flags at sensor time t (s)."""
        row = np.zeros(aided.OUT_SIZE)
        aided.filter_row(self.P, self.bias, row)  # the sigmas as the solution files carry them
        return Uncertainty(
            sigma_pos=row[_column("sigma_n")], sigma_vel=row[_column("sigma_vn")],
            sigma_att=row[_column("sigma_att_n")], sigma_gyro=row[_column("sigma_bg_x")],
            vel_ratio=self.ratios.get("vel", math.nan), pos_ratio=self.ratios.get("pos", math.nan),
            hgt_ratio=self.ratios.get("hgt", math.nan), mag_ratio=self.ratios.get("mag", math.nan),
            abs_pos=t - self.last_pos_t <= ABS_TIMEOUT_S, abs_hgt=t - self.last_hgt_t <= ABS_TIMEOUT_S,
            glitch=self.glitch, resets=resets + self.resets)


def warm_measurements() -> None:
    """Load or compile the kernels of every measurement update and the covariance propagation
    they flush (run in a second process on a cold start: service.warm_up)."""
    from ..core.runner import rest_state

    cfg = sd.make_config()
    s = rest_state()
    f = LiveFilter(FilterSettings(aiding=AIDING_KINDS))
    f.start(s, cfg, np.zeros(3), 0.01)
    for kind, args in (("zupt", ()), ("nhc", ()), ("gnss", (math.radians(45.0), math.radians(7.0), 100.0, (0.0, 0.0, 0.0), 1.0, 2.0, 0.3)),
                       ("gnss", (math.radians(45.0), math.radians(7.0), 100.0, (0.0, 0.0, math.nan), 1.0, 2.0, 0.3)),
                       ("baro", (100.0, 0.5)), ("mag", ((0.2, 0.0, 0.4),)), ("gnss_yaw", (0.1, 0.02)),
                       *[("vision_pose", ((1.0, 2.0, 0.5), np.eye(3), (0.1,) * 3, (0.02,) * 3, 0))] * 2):
        f.measure(s, cfg, 0.0, kind, *args)
    # the heading from GNSS velocity (GNSS_YAW_PENDING): the yaw bank and the reset
    from ..core import yawgsf

    X, P, logw = yawgsf.make(0.0, 0.0)
    yawgsf.predict(X, P, np.array([0.01, 0.0, -0.098]), np.zeros(3), 0.0, 0.0, 0.0, 0.01)
    yawgsf.update(X, P, logw, 0.0, 0.0, 0.3)
    yawgsf.estimate(X, P, logw)
    kalman.yaw_reset(s, cfg, f.bias, f.P, 0.0, 1e-3, math.radians(45.0), math.radians(7.0), 1.0, 0.0, 0.0, 0.1)


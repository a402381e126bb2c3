"""The navigation engine: IMU samples in, output sets out, on sensor time only.

States (announced as events): WAITING (no initial position yet) ->
ALIGNING (static coarse alignment over ``align`` seconds of sensor time) ->
NAVIGATING (strapdown kernel fed sample by sample). The same engine runs
live, in replay and in the demo, so identical input gives bit-identical output.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from dataclasses import dataclass, field
from enum import Enum
from typing import Callable

import numpy as np

from ..core import aided, align, earth, kalman, magmodel, yawgsf
from ..core import strapdown as sd
from ..core.jit import for_frame
from ..core.records import ImuSample, Solution
from ..core.settings import Strapdown, strapdown_of
from .livefilter import GNSS_HEADING, GNSS_YAW_PENDING, VISION_HEADING, FilterSettings, LiveFilter
from ..core.rotation import euler_to_dcm


class State(str, Enum):
    WAITING = "WAITING"
    ALIGNING = "ALIGNING"
    NAVIGATING = "NAVIGATING"


HEADING_WORDS = ("auto", "gyrocompass", "mag", "vehicle", "vision")
GNSS_YAW = "GNSS velocity"  # the heading source once the yaw estimator (core/yawgsf.py) has converged
GSF_RESET_SIGMA_DEG = 5.0  # deg: the estimator's yaw 1-sigma below which the solution's heading is reset to it
GSF_MOVING_MS = 1.0  # m/s: while the yaw is pending, faster fixes are not fused (the heading is unknown)
MAX_HEIGHT = 1.0e6  # m: beyond this (either sign) the solution has diverged
MAX_SPEED = 1.0e4  # m/s: likewise


_SD = Strapdown()


@dataclass
class EngineConfig:
    """Navigation settings (docs/conventions.md ``mavins run``); angles in degrees."""

    lat: float | None = None
    lon: float | None = None
    alt: float | None = None
    heading: float | str = "auto"
    gnss_yaw_offset: float = 0.0  # deg: the GNSS antenna baseline's azimuth in the body (FRD, 0 = along x)
    declination: float | None = None  # deg, east positive; None: the World Magnetic Model's at the position
    mag_year: float | None = None  # decimal year for the magnetic model; None: the stream's SYSTEM_TIME, else today
    align: float = 10.0
    rate: float = 50.0
    # the strapdown settings (mavins/core/settings.py: names, defaults and help defined once)
    samples: int = _SD.samples
    coning: bool = _SD.coning
    imu_rates: str = _SD.imu_rates
    attitude: str = _SD.attitude
    order: str = _SD.order
    earth_model: str = _SD.earth_model
    orthonormalize_every: int = _SD.orthonormalize_every
    vertical: str = _SD.vertical
    position: str = _SD.position
    l_every: int = _SD.l_every
    frame: str = _SD.frame
    motion_gyro: float = 0.1  # rad/s: a sample above this restarts the alignment
    motion_accel: float = 1.5  # m/s^2: |f| - g beyond this restarts the alignment
    max_gap: float = 1.0  # s: a longer gap in sensor time is not integrated; the solution is degraded
    restart_gap: float = 60.0  # s: a longer jump forward (e.g. boot time -> UNIX time) restarts alignment
    gyro_bias: str = "estimate"  # "estimate": mean gyro minus Earth rate over the static window; "none"
    filter: FilterSettings = field(default_factory=FilterSettings)
    geoid_height: float = 0.0  # m: constant geoid undulation, AMSL altitudes of GNSS input + this = ellipsoidal
    zupt_gyro: float = 0.02  # rad/s: below this (bias-corrected) a sample counts as still
    zupt_accel: float = 0.15  # m/s^2: ||f| - g| below this likewise
    zupt_still_s: float = 0.5  # s of still samples before zero-velocity updates start
    zupt_every_s: float = 0.1  # s between zero-velocity updates while still
    nhc_every_s: float = aided.NHC_EVERY  # s between non-holonomic constraints (--aiding ...,nhc), while navigating
    aiding_every_s: float = 0.02  # s between magnetometer updates (a sample up to a quarter of it early is taken)


@dataclass
class Engine:
    """Stateful shell around the strapdown kernel."""

    cfg: EngineConfig
    state: State = State.WAITING
    events: list[tuple[str, str]] = field(default_factory=list)
    counters: Counter = field(default_factory=Counter)
    heading_used: str = ""
    degraded: bool = False
    _kcfg: np.ndarray = field(init=False)
    _solution_row: Callable = field(init=False)  # strapdown.solution_row for the configured frame
    _s: np.ndarray | None = field(init=False, default=None)
    _pos: tuple[float, float, float] | None = field(init=False, default=None)
    _pos_sigma: float | None = field(init=False, default=None)
    _vehicle_yaw: float | None = field(init=False, default=None)
    _acc: list[np.ndarray] = field(init=False, default_factory=list)
    _t_align0: float = field(init=False, default=0.0)
    _next_out: int | None = field(init=False, default=None)
    _last_t: float | None = field(init=False, default=None)
    _dt_nominal: float | None = field(init=False, default=None)
    _gyro_last: tuple[float, float, float] = field(init=False, default=(0.0, 0.0, 0.0))
    gyro_bias: np.ndarray = field(init=False, default_factory=lambda: np.zeros(3))
    filter: LiveFilter = field(init=False)
    _still_since: float | None = field(init=False, default=None)
    _next_zupt: float = field(init=False, default=-math.inf)
    _next_nhc: float = field(init=False, default=-math.inf)
    _next_mag: float = field(init=False, default=-math.inf)
    _row: np.ndarray = field(init=False, default_factory=lambda: np.zeros(sd.OUT_SIZE))
    _unix_date: float | None = field(init=False, default=None)  # s: UNIX time the stream reported (SYSTEM_TIME)
    _antenna_yaw: float | None = field(init=False, default=None)  # rad: the vehicle's heading from the latest GNSS yaw
    _vision_yaw: float | None = field(init=False, default=None)  # rad: the latest camera attitude's heading, in its frame
    declination: float = field(init=False, default=0.0)  # deg: the one used by the alignment and the filter
    _gsf: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(init=False, default=None)  # yaw bank (X, P, logw)
    _last_fix: tuple[float, float, float, float, float, float] | None = field(init=False, default=None)  # while pending
    _gsf_inc: list[float] = field(init=False, default_factory=lambda: [0.0] * 7)  # dv_b, dtheta_b, dt since the update
    _gsf_t: float = field(init=False, default=0.0)  # s: time of the last sample integrated into _gsf_inc

    def __post_init__(self) -> None:
        h = self.cfg.heading
        if isinstance(h, str) and h not in HEADING_WORDS:
            raise ValueError(f"heading must be degrees or one of {', '.join(HEADING_WORDS)}, got {h!r}")
        if self.cfg.gyro_bias not in ("estimate", "none"):
            raise ValueError(f"gyro_bias must be estimate or none, got {self.cfg.gyro_bias!r}")
        # one declination for the alignment and the filter's magnetometer updates (set at each alignment)
        self.declination = self.cfg.declination if self.cfg.declination is not None else 0.0
        self.filter = LiveFilter(dataclasses.replace(self.cfg.filter, declination=self.declination))
        self._kcfg = sd.make_config(**strapdown_of(self.cfg).keywords())
        self._solution_row = for_frame(sd.solution_row, sd.kernel_frame(self._kcfg))
        if self.cfg.frame != "geographic" and self.cfg.filter.aiding:
            raise ValueError(f"--frame {self.cfg.frame} navigates free inertial only (the filter works in the "
                             "geographic frame): add --aiding none")
        if None not in (self.cfg.lat, self.cfg.lon, self.cfg.alt):
            self.set_position(float(self.cfg.lat), float(self.cfg.lon), float(self.cfg.alt), "options")  # type: ignore[arg-type]
        else:
            self._event("INFO", "WAITING: for an initial position (--lat/--lon/--alt, the vehicle's GPS or its "
                                "GPS_GLOBAL_ORIGIN)")

    # -- inputs besides the IMU ------------------------------------------------
    def set_position(self, lat: float, lon: float, alt: float, source: str, sigma: float | None = None) -> None:
        """Initial position (deg, deg, ellipsoidal m; 1-sigma m if known), used at the next alignment."""
        if self._pos is None:
            self._pos = (lat, lon, alt)
            self._pos_sigma = sigma
            self._event("INFO", f"initial position from {source}: {lat:.7f}, {lon:.7f}, {alt:.1f} m")

    def set_date(self, unix_s: float) -> None:
        """The UTC date the vehicle reports (UNIX s, e.g. SYSTEM_TIME.time_unix_usec), for the
        magnetic model; times that cannot be a date (a boot clock) are ignored."""
        if self._unix_date is None and magmodel.plausible_unix(unix_s):
            self._unix_date = float(unix_s)

    def _magnetic_field(self, uses_mag: bool) -> tuple[float, tuple[float, float]]:
        """The declination (deg) for this alignment, ``--declination`` else the World Magnetic Model's at
        the initial position and the date, and the model's inclination (deg) and strength (gauss) for the
        disturbance checks (docs/conventions.md "Magnetic field")."""
        if self.cfg.mag_year is not None:
            year, when = float(self.cfg.mag_year), "the given date"
        elif self._unix_date is not None:
            year, when = magmodel.decimal_year(self._unix_date), "the vehicle's date"
        else:
            year, when = magmodel.this_year(), "today's date (the stream gave none)"
        lat, lon, alt = self._pos  # type: ignore[misc]
        f = magmodel.field_at(lat, lon, alt, year)
        model = (f.inclination, f.intensity * 1e-5)  # gauss: 1 G = 1e5 nT; whatever gives the declination
        if self.cfg.declination is not None:
            return float(self.cfg.declination), model
        if uses_mag:
            self._event("INFO", f"magnetic declination {f.declination:.2f} deg (inclination {f.inclination:.1f} deg, "
                                f"{f.intensity / 1000.0:.1f} uT) from {f.model} at the initial position for {year:.2f}, "
                                f"{when}" + (" (outside the model's years: extrapolated)" if f.extrapolated else ""))
        return f.declination, model

    def on_gnss_yaw(self, t: float | None, yaw: float, sigma: float) -> None:
        """A dual-antenna GNSS heading (rad, of the antenna baseline; 1-sigma rad) stamped t on the IMU
        clock (None: now): the vehicle's heading is it less ``gnss_yaw_offset``. Before navigation it is
        a heading source for the alignment; while navigating, a heading measurement (with GNSS aiding)."""
        vehicle = math.remainder(yaw - math.radians(self.cfg.gnss_yaw_offset), 2.0 * math.pi)
        self._antenna_yaw = vehicle
        if self.state is not State.NAVIGATING or self._s is None:
            return
        if self._gsf is not None:  # the heading was pending: the receiver's ends the wait, on the last fix
            fix = self._last_fix
            if fix is None:
                self.counters["gnss_yaw_held"] += 1  # no fix yet to put the solution on: the next heading
                return
            self._heading_reset(vehicle, sigma * sigma, *fix, GNSS_HEADING,
                                f"heading from the GNSS receiver: {math.degrees(vehicle):.2f} deg (1-sigma "
                                f"{math.degrees(sigma):.2f} deg)")
            return
        t_m = sd.state_time(self._s) if t is None else t
        self.filter.measure(self._s, self._kcfg, t_m, "gnss_yaw", vehicle, sigma)

    def set_vehicle_yaw(self, yaw_rad: float) -> None:
        """The vehicle's own heading (from its ATTITUDE), a heading source for alignment."""
        self._vehicle_yaw = yaw_rad

    @property
    def origin(self) -> tuple[float, float, float] | None:
        """The local frame's origin (deg, deg, ellipsoidal m): the initial position, once known."""
        return self._pos

    @property
    def position_known(self) -> bool:
        return self._pos is not None

    # -- the IMU ---------------------------------------------------------------
    def restart(self, reason: str) -> None:
        """Back to alignment (autopilot restart, sensor time reset)."""
        self._s = None
        self._acc.clear()
        self._last_t = None
        self._dt_nominal = None
        self._next_out = None
        self.counters["restarts"] += 1
        self._set_state(State.WAITING if self._pos is None else State.ALIGNING, reason)

    def on_imu(self, smp: ImuSample) -> Solution | None:
        """Feed one accepted sample; returns an output set when one is due.

        Gaps in sensor time: up to ``max_gap`` they are bridged (counted when
        over twice the nominal interval); longer ones are not integrated (the
        sample covers only the nominal interval) and mark the solution
        degraded; beyond ``restart_gap`` the alignment starts over.
        """
        if self._last_t is not None:
            gap = smp.t - self._last_t
            nominal = self._dt_nominal
            if gap > self.cfg.restart_gap:
                self.counters["time_jumps"] += 1
                self.restart(f"sensor time jumped {gap:.1f} s forward")
            elif gap > self.cfg.max_gap:
                self.counters["gaps_long"] += 1
                if self.state is State.NAVIGATING:
                    if not self.degraded:
                        self.degraded = True
                        self._event("WARNING", f"sensor-time gap of {gap:.3f} s not integrated: solution degraded")
                    self._skip_gap(smp.t - (nominal or 0.0))
                elif self.state is State.ALIGNING and self._acc:
                    self._acc.clear()
                    self._event("WARNING", f"sensor-time gap of {gap:.3f} s during alignment: restarting it")
            elif nominal is not None and gap > 2.0 * nominal:
                self.counters["gaps_bridged"] += 1
            if 0.0 < gap <= self.cfg.max_gap:
                self._dt_nominal = gap if nominal is None else nominal + 0.05 * (gap - nominal)
        self._last_t = smp.t
        if self.state is State.WAITING:
            if self._pos is None:
                return None
            self._set_state(State.ALIGNING, "initial position known")
        if self.state is State.ALIGNING:
            self._align_step(smp)
            return None
        return self._nav_step(smp)

    def _skip_gap(self, t_resume: float) -> None:
        """Move the kernel's clock to ``t_resume`` without integrating the gap."""
        if self._s is not None:
            sd.skip_to(self._s, t_resume)

    def _align_step(self, smp: ImuSample) -> None:
        g = np.asarray(smp.gyro)
        f = np.asarray(smp.accel)
        if not self._acc:
            self._t_align0 = smp.t
        lat, _, alt = self._pos  # type: ignore[misc]
        g_ref = earth.gravity(math.radians(lat), alt)
        if np.linalg.norm(g) > self.cfg.motion_gyro or abs(np.linalg.norm(f) - g_ref) > self.cfg.motion_accel:
            self.counters["align_restarts"] += 1
            if self._acc:
                self._event("WARNING", "motion during alignment: restarting it")
            self._acc.clear()
            return
        mag = np.asarray(smp.mag) if smp.mag is not None else np.full(3, np.nan)
        self._acc.append(np.concatenate([g, f, mag]))
        if smp.t - self._t_align0 >= self.cfg.align:
            self._finish_alignment(smp)

    def _finish_alignment(self, smp: ImuSample) -> None:
        data = np.array(self._acc)
        w_mean, f_mean, m_mean = data[:, 0:3].mean(0), data[:, 3:6].mean(0), data[:, 6:9].mean(0)
        roll, pitch = align.level(f_mean)
        has_mag = bool(np.all(np.isfinite(m_mean)) and np.linalg.norm(m_mean) > 0)
        self.declination, model = self._magnetic_field(has_mag and (
            "mag" in self.cfg.filter.aiding or self.cfg.heading in ("mag", "auto")))
        self.filter.settings = dataclasses.replace(self.filter.settings, declination=self.declination, mag_model=model)
        yaw, source = self._heading(w_mean, m_mean, roll, pitch)
        lat, lon, alt = self._pos  # type: ignore[misc]
        self._s = sd.init_state(smp.t, math.radians(lat), math.radians(lon), alt, np.zeros(3), roll, pitch, yaw)
        self.heading_used = source
        self._acc.clear()
        self.degraded = False
        self.gyro_bias = np.zeros(3)
        if self.cfg.gyro_bias == "estimate" and source != "gyrocompass":
            # at rest the gyros read C_n^b w_ie^n; the rest is bias (zero-rate calibration)
            c_bn = euler_to_dcm(roll, pitch, yaw)
            self.gyro_bias = w_mean - c_bn.T @ earth.earth_rate_n(math.radians(lat))
        self._set_state(
            State.NAVIGATING,
            f"aligned over {smp.t - self._t_align0:.1f} s: roll {math.degrees(roll):.2f} pitch "
            f"{math.degrees(pitch):.2f} heading {math.degrees(yaw):.2f} deg from {source}",
        )
        self.filter.start(self._s, self._kcfg, self.gyro_bias, self._dt_nominal or 0.01, self._pos_sigma, source,
                          math.radians(lat), smp.t - self._t_align0 if self.gyro_bias.any() else 0.0)
        self._gsf = yawgsf.make(0.0, 0.0) if source == GNSS_YAW_PENDING else None
        self._last_fix = None
        # an unknown heading is not learnt by the filter's linear updates (a consider state) until the reset
        self.filter.free = kalman.ALL_BUT_HEADING if self._gsf is not None else kalman.ALL
        self._gsf_inc = [0.0] * 7
        self._gsf_t = smp.t
        if self._gsf is not None:
            self._event("INFO", "heading unknown (no magnetometer, no vehicle heading, gyros too coarse to "
                                "gyrocompass): estimated from GNSS velocity once the vehicle moves")
        self._still_since = None
        self._next_zupt = self._next_mag = self._next_nhc = -math.inf
        if self.gyro_bias.any():
            self._event("INFO", "gyro bias estimated at rest: "
                        + " ".join(f"{math.degrees(b) * 3600:.1f}" for b in self.gyro_bias) + " deg/h")
        if self.cfg.imu_rates == "sampled":
            self.filter.push(self._s, self._kcfg, smp.t, smp.gyro, smp.accel)

    def _heading(self, w_mean: np.ndarray, m_mean: np.ndarray, roll: float, pitch: float) -> tuple[float, str]:
        h = self.cfg.heading
        if not isinstance(h, str):
            return math.radians(float(h)), "--heading"
        has_mag = bool(np.all(np.isfinite(m_mean)) and np.linalg.norm(m_mean) > 0)
        if h == "vehicle" or (h == "auto" and self._vehicle_yaw is not None):
            if self._vehicle_yaw is None:
                self._event("WARNING", "no vehicle ATTITUDE seen: heading from gyrocompass")
            else:
                return self._vehicle_yaw, "vehicle ATTITUDE"
        if h == "auto" and self._antenna_yaw is not None:
            return self._antenna_yaw, GNSS_HEADING
        if h == "vision" or (h == "auto" and not has_mag and self._vision_yaw is not None
                             and "vision" in self.cfg.filter.aiding and "gnss" not in self.cfg.filter.aiding):
            if self._vision_yaw is not None:  # without GNSS or a magnetometer nothing knows north better
                return self._vision_yaw, VISION_HEADING
            self._event("WARNING", "no camera attitude seen: heading from gyrocompass")
        if h == "mag" or (h == "auto" and has_mag):
            if has_mag:
                return align.mag_heading(m_mean, roll, pitch, math.radians(self.declination)), "magnetometer"
            self._event("WARNING", "no magnetometer data: heading from gyrocompass")
        yaw = align.gyrocompass(w_mean, roll, pitch)
        if h == "auto" and "gnss" in self.cfg.filter.aiding and self.cfg.frame == "geographic" \
                and self.filter.yaw_sigma_deg("gyrocompass", math.radians(self._pos[0])) > GSF_RESET_SIGMA_DEG:  # type: ignore[index]
            return yaw, GNSS_YAW_PENDING  # gyrocompassing cannot beat the yaw estimator: it takes over
        return yaw, "gyrocompass"

    def _nav_step(self, smp: ImuSample) -> Solution | None:
        s = self._s
        flt = self.filter
        r = flt.push(s, self._kcfg, smp.t, smp.gyro, smp.accel)  # type: ignore[arg-type]
        self._mag_from_sample(smp)  # any sample may carry one: it waits for the update that passes it
        if self._gsf is not None:
            self._gsf_sample(smp, r == 1)
        if r != 1:
            return None
        self._gyro_last = flt.body_rate(smp.gyro)  # the update's last sample, bias removed (published, ZUPT)
        self._zupt_from_sample(smp)
        self._nhc_now(smp.t)
        t = sd.state_time(s)  # type: ignore[arg-type]
        if not self.degraded and sd.frame_limit(s) is not None:  # type: ignore[arg-type]
            self.degraded = True
            self._event("WARNING", f"geographic frame beyond |lat| {math.degrees(sd.GEO_LAT_LIMIT):g} deg: solution "
                                   "degraded (use --frame wander, free or inertial)")
        flt.tick(t)
        self.events.extend(flt.events)
        flt.events.clear()
        if not self._output_due(t):
            return None
        self._solution_row(s, self._kcfg, self._row)
        r = self._row
        if not np.all(np.isfinite(r)) or abs(r[3]) > MAX_HEIGHT or abs(r[4]) + abs(r[5]) + abs(r[6]) > MAX_SPEED:
            # e.g. hours of extreme input: never publish it, start over
            self.counters["diverged"] += 1
            self._event("ERROR", "solution diverged (non-finite or beyond any vehicle): re-aligning")
            self.restart("solution diverged")
            return None
        return Solution(self._row.copy(), np.array(self._gyro_last), self._pos, self.degraded,  # type: ignore[arg-type]
                        flt.uncertainty(t, self.counters["restarts"]))

    def _gsf_sample(self, smp: ImuSample, update: bool) -> None:
        """Sum the sample's bias-corrected increments (rectangle rule over the interval since the last one)
        for the yaw estimator and propagate it at each attitude update, at the solution's level."""
        dt = smp.t - self._gsf_t
        self._gsf_t = smp.t
        inc = self._gsf_inc
        if 0.0 < dt <= self.cfg.max_gap:
            w = self.filter.body_rate(smp.gyro)
            ba = self.filter.accel_bias
            for i in range(3):
                inc[i] += (smp.accel[i] - ba[i]) * dt
                inc[3 + i] += w[i] * dt
            inc[6] += dt
        if update and inc[6] > 0.0:
            X, P, _ = self._gsf  # type: ignore[misc]
            c = sd.body_to_nav(self._s)  # type: ignore[arg-type]  # C_b^n row-major: roll, pitch from its last row
            roll, pitch = math.atan2(c[7], c[8]), -math.asin(max(-1.0, min(1.0, c[6])))
            lat = math.radians(self._pos[0])  # type: ignore[index]
            yawgsf.predict(X, P, np.array(inc[0:3]), np.array(inc[3:6]), roll, pitch,
                           -earth.OMEGA * math.sin(lat), inc[6])
            self._gsf_inc = [0.0] * 7

    def _mag_from_sample(self, smp: ImuSample) -> None:
        """The magnetometer heading an IMU sample carries, at most one per ``aiding_every_s`` (docs/filter.md);
        taken on whichever sample it rides, the filter applies it at the update that passes its time."""
        t = smp.t
        if "mag" in self.cfg.filter.aiding and smp.mag is not None and t >= self._next_mag and any(smp.mag):
            # on a grid of aiding_every_s (a denser magnetometer is used at that rate on average), with a
            # quarter of the interval's slack: one at exactly that rate, whose samples arrive that far apart
            # give or take rounding and jitter, keeps every sample; after a gap the grid restarts from t
            every = self.cfg.aiding_every_s
            self._next_mag = max(self._next_mag + every, t + 0.75 * every)
            self.filter.measure(self._s, self._kcfg, t, "mag", smp.mag)  # type: ignore[arg-type]

    def _zupt_from_sample(self, smp: ImuSample) -> None:
        """Zero velocity while the standstill detector says the vehicle is still (docs/filter.md), checked at
        each attitude update with its last sample."""
        aiding = self.cfg.filter.aiding
        t = smp.t
        if "zupt" not in aiding:
            return
        g_ref = earth.gravity(math.radians(self._pos[0]), self._pos[2])  # type: ignore[index]
        still = (math.sqrt(sum(x * x for x in self._gyro_last)) < self.cfg.zupt_gyro
                 and abs(math.sqrt(sum(x * x for x in smp.accel)) - g_ref) < self.cfg.zupt_accel)
        if not still:
            self._still_since = None
            return
        if self._still_since is None:
            self._still_since = t
        if t - self._still_since >= self.cfg.zupt_still_s and t >= self._next_zupt:
            self._next_zupt = t + self.cfg.zupt_every_s
            self.filter.measure(self._s, self._kcfg, t, "zupt")  # type: ignore[arg-type]

    def _nhc_now(self, t: float) -> None:
        """The non-holonomic constraint of a wheeled vehicle (``--aiding ...,nhc``): every nhc_every_s of
        sensor time at an attitude update (correlated in time, so not at every update: docs/filter.md)."""
        if "nhc" in self.cfg.filter.aiding and t >= self._next_nhc:
            self._next_nhc = t + self.cfg.nhc_every_s
            self.filter.measure(self._s, self._kcfg, t, "nhc")  # type: ignore[arg-type]

    # -- measurements from other messages ----------------------------------------
    def on_gnss(self, t: float | None, lat: float, lon: float, h: float, vel: tuple[float, float, float] | None,
                sigma_h: float, sigma_v: float, sigma_vel: float, source: str = "GNSS") -> None:
        """A GNSS fix (deg, deg, ellipsoidal m; NED m/s or None; 1-sigma m, m, m/s) stamped t on the
        IMU clock (None: now). Before navigation it gives the initial position."""
        if self.state is not State.NAVIGATING or self._s is None:
            self.set_position(lat, lon, h, source, sigma_h)
            return
        t_m = sd.state_time(self._s) if t is None else t
        if self._gsf is not None and not self._gsf_fix(lat, lon, vel, sigma_h, sigma_vel):
            return
        self.filter.measure(self._s, self._kcfg, t_m, "gnss", math.radians(lat), math.radians(lon), h, vel,
                            sigma_h, sigma_v, sigma_vel)

    def _gsf_fix(self, lat: float, lon: float, vel: tuple[float, float, float] | None, sigma_h: float,
                  sigma_vel: float) -> bool:
        """While the heading is pending: a fix's horizontal velocity updates the yaw estimator; once its
        yaw 1-sigma is below GSF_RESET_SIGMA_DEG the solution's heading, horizontal position and velocity
        are reset to it and the fix (docs/filter.md "Heading from GNSS velocity"). Returns whether the
        filter may take the fix: always after the reset; before, only below GSF_MOVING_MS (moving on an
        unknown heading, the inertial velocity points anywhere)."""
        if vel is None or not (math.isfinite(vel[0]) and math.isfinite(vel[1])):
            return True
        self._last_fix = (lat, lon, float(vel[0]), float(vel[1]), sigma_h, sigma_vel)
        X, P, logw = self._gsf  # type: ignore[misc]
        yawgsf.update(X, P, logw, float(vel[0]), float(vel[1]), float(sigma_vel))
        psi, var = yawgsf.estimate(X, P, logw)
        if var < math.radians(GSF_RESET_SIGMA_DEG) ** 2:
            self._heading_reset(psi, var, *self._last_fix, GNSS_YAW,
                                f"heading from GNSS velocity: {math.degrees(psi):.2f} deg (1-sigma "
                                f"{math.degrees(math.sqrt(var)):.2f} deg)")
            return True
        if math.hypot(vel[0], vel[1]) < GSF_MOVING_MS:
            return True
        self.counters["gnss_held_for_yaw"] += 1
        return False

    def _heading_reset(self, psi: float, var: float, lat: float, lon: float, vn: float, ve: float, sigma_h: float,
                       sigma_vel: float, source: str, text: str) -> None:
        """End a pending heading: the solution turned to ``psi`` (rad, variance ``var``) and put on the fix
        (deg, deg, NED m/s, 1-sigma m and m/s) by kalman.yaw_reset; normal fusion resumes, ``source`` is the
        heading used, and the event says ``text`` and by how much the solution turned."""
        s = self._s
        c = sd.body_to_nav(s)  # type: ignore[arg-type]
        dpsi = math.remainder(psi - math.atan2(c[3], c[0]), 2.0 * math.pi)
        kalman.yaw_reset(s, self._kcfg, self.filter.bias, self.filter.P, dpsi, var, math.radians(lat),
                         math.radians(lon), sigma_h * sigma_h, vn, ve, sigma_vel * sigma_vel)
        self._gsf = None
        self.filter.free = kalman.ALL
        if self.filter.epochs is not None:  # the solution jumped without an update: the smoother starts anew
            self.filter.restart_epochs(s)
        self.heading_used = source
        self.counters["yaw_resets"] += 1
        self._event("INFO", f"{text}, the solution turned by {math.degrees(dpsi):.2f} deg and put on the fix")

    def on_baro(self, t: float | None, h: float, sigma: float) -> None:
        """A barometric height (m, with an unknown offset the filter estimates)."""
        self._measure(t, "baro", h, sigma)

    def on_wheel(self, t: float | None, speed: float, sigma: float) -> None:
        """A wheel odometer's forward speed (m/s, body x at the axle centre; 1-sigma m/s), measured at t."""
        self._measure(t, "wheel", speed, sigma)

    def on_vision_velocity(self, t: float | None, vel: tuple[float, float, float], sigma: float | tuple,
                           body: bool) -> None:
        """A velocity from a camera or motion capture (m/s): NED with one 1-sigma (m/s), or with ``body`` in
        the body frame FRD with a 1-sigma per axis; measured at t."""
        self._measure(t, "vision_body" if body else "vision_vel", vel, sigma)

    def on_vision_pose(self, t: float | None, p_v: tuple[float, float, float], c_vb: np.ndarray | None,
                       sigma_p: tuple[float, float, float], sigma_att: tuple[float, float, float], reset: int) -> None:
        """A camera's pose in its own local frame (position m; attitude ``c_vb`` body FRD -> frame or None;
        1-sigmas m and rad per axis; ``reset`` the frame's reset_counter), measured at t. Before navigation
        its heading is a heading source (``--heading vision``, or ``auto`` with vision and neither GNSS nor
        a magnetometer); while navigating a pose measurement (LiveFilter: the first places the frame)."""
        if c_vb is not None:
            self._vision_yaw = math.atan2(c_vb[1, 0], c_vb[0, 0])
        self._measure(t, "vision_pose", p_v, c_vb, sigma_p, sigma_att, reset)

    def _measure(self, t: float | None, kind: str, *args: object) -> None:
        """A measurement of ``kind`` at t on the IMU clock (None: now) to the filter, while navigating."""
        if self.state is State.NAVIGATING and self._s is not None:
            self.filter.measure(self._s, self._kcfg, sd.state_time(self._s) if t is None else t, kind, *args)

    def _output_due(self, t: float) -> bool:
        """One output set each time sensor time crosses a multiple of 1/rate (docs/conventions.md
        ``--rate``): on the first attitude update at or after it. An update interval that
        spans two multiples (rate close to the update rate, jittery times) yields one set."""
        k = math.floor(t * self.cfg.rate + 1e-9)
        if self._next_out is not None and k < self._next_out:
            return False
        self._next_out = k + 1
        return True

    # -- events ----------------------------------------------------------------
    def _set_state(self, state: State, why: str) -> None:
        if state is not self.state:
            self.state = state
            self._event("INFO", f"{state.value}: {why}")

    def _event(self, level: str, text: str) -> None:
        self.events.append((level, text))

    def take_events(self) -> list[tuple[str, str]]:
        ev, self.events = self.events, []
        return ev

"""Trajectories built from segments, and their exact IMU increments and truth.

A :class:`Trajectory` is a set of smooth channels (roll, pitch, yaw, horizontal
speed, down velocity, turntable angles). Every change is a quintic smoothstep
ramp ``10u^3 - 15u^4 + 6u^5`` of the value, or of the rate for yaw and the
turntable, so angles, rates, velocity and acceleration are continuous and
known in closed form at any time. Superposed primitives (coning, angular and
linear vibration, sculling) and a turntable (rotation-modulated IMU) are
composed on top. :func:`simulate` turns it into increments and truth via the
compiled kernels of sim.kinematics.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from mavins.core import earth
from mavins.common.progress import Progress

from . import kinematics as kin

SMOOTHSTEP_PEAK = 1.875  # max slope of the quintic smoothstep relative to its mean


@dataclass
class Channel:
    """A piecewise polynomial in local time u in [0, 1] per piece (value and rate)."""

    t_end: float
    value: float
    rate: float = 0.0
    pieces: list[tuple[float, float, np.ndarray]] = field(default_factory=list)

    def _add(self, dur: float, coefs: np.ndarray) -> None:
        if dur <= 0:
            return
        self.pieces.append((self.t_end, dur, coefs))
        self.t_end += dur
        self.value = float(np.sum(coefs))
        self.rate = float(np.dot(np.arange(7), coefs)) / dur

    def hold_until(self, t: float) -> None:
        """Continue at the current rate until time t."""
        d = t - self.t_end
        if d > 1e-12:
            self._add(d, np.array([self.value, self.rate * d, 0, 0, 0, 0, 0], dtype=float))

    def ramp_value(self, target: float, dur: float) -> None:
        """Smoothstep from the current value to ``target`` (rate 0 at both ends)."""
        if abs(self.rate) > 1e-12:
            raise ValueError("a value ramp needs the channel at rest (rate 0)")
        d = target - self.value
        self._add(dur, np.array([self.value, 0, 0, 10 * d, -15 * d, 6 * d, 0], dtype=float))
        self.rate = 0.0  # the smoothstep ends at rest exactly (its slope polynomial vanishes at u = 1)

    def ramp_rate(self, target_rate: float, dur: float) -> None:
        """Smoothstep of the rate from its current value to ``target_rate``."""
        r0, dr = self.rate, target_rate - self.rate
        self._add(dur, np.array([self.value, dur * r0, 0, 0, 2.5 * dur * dr, -3 * dur * dr, dur * dr], dtype=float))

    def eval(self, t: np.ndarray) -> np.ndarray:
        """Value at times t (numpy; for planning, not for the increments)."""
        starts, durs, coefs = self.arrays()
        ts = np.ascontiguousarray(np.atleast_1d(t), dtype=float)
        out = np.empty_like(ts)
        kin.channel_values(starts, durs, coefs, len(starts), ts, out)
        return out

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pieces = self.pieces or [(self.t_end, 1.0, np.array([self.value, 0, 0, 0, 0, 0, 0], dtype=float))]
        return (
            np.array([p[0] for p in pieces]),
            np.array([p[1] for p in pieces]),
            np.array([p[2] for p in pieces]),
        )


@dataclass
class MotionSpec:
    """Arrays the kernels need (see sim.kinematics)."""

    t0: float
    t_end: float
    lat: float
    lon: float
    h: float
    starts: np.ndarray
    durs: np.ndarray
    coefs: np.ndarray
    counts: np.ndarray
    vib: np.ndarray
    consts: np.ndarray
    linvib: np.ndarray
    use_earth: bool
    max_freq: float
    breaks: np.ndarray = field(default_factory=lambda: np.empty(0))


class Trajectory:
    """Segment builder. Angles in degrees, speeds in m/s, times in s.

    Position for waypoint planning is tracked on a local flat approximation;
    the exact position comes from the simulation itself.
    """

    def __init__(
        self, lat: float, lon: float, h: float, *, yaw: float = 0.0, roll: float = 0.0, pitch: float = 0.0,
        speed: float = 0.0, t0: float = 0.0, use_earth: bool = True,
    ) -> None:
        self.t0 = t0
        self.t = t0
        self.lat, self.lon, self.h = lat, lon, h
        self.use_earth = use_earth
        init = [math.radians(roll), math.radians(pitch), math.radians(yaw), speed, 0.0, 0.0, 0.0]
        self.ch = [Channel(t0, v) for v in init]
        self.north = 0.0
        self.east = 0.0
        self.up = 0.0
        self.vib: list[list[float]] = []
        self.linvib: list[list[float]] = []
        self.cone = (0.0, 0.0)
        self.max_freq = 0.0

    # -- bookkeeping -------------------------------------------------------
    @property
    def speed(self) -> float:
        return self.ch[kin.CH_SPEED].value

    @property
    def yaw_deg(self) -> float:
        return math.degrees(self.ch[kin.CH_YAW].value)

    def _finish(self, dur: float) -> None:
        """Hold every vehicle channel to t + dur and update the planning position."""
        t1 = self.t + dur
        for i in (kin.CH_ROLL, kin.CH_PITCH, kin.CH_YAW, kin.CH_SPEED, kin.CH_VD):
            self.ch[i].hold_until(t1)
        ts = np.linspace(self.t, t1, max(8, int(dur * 20)))
        spd = self.ch[kin.CH_SPEED].eval(ts)
        yaw = self.ch[kin.CH_YAW].eval(ts)
        vd = self.ch[kin.CH_VD].eval(ts)
        self.north += float(np.trapezoid(spd * np.cos(yaw), ts))
        self.east += float(np.trapezoid(spd * np.sin(yaw), ts))
        self.up -= float(np.trapezoid(vd, ts))
        self.t = t1

    # -- segments ----------------------------------------------------------
    def static(self, duration: float) -> "Trajectory":
        """Hold speed, heading and attitude (a hover when the speed is zero)."""
        _positive("duration", duration, allow_zero=True)
        self._finish(duration)
        return self

    hover = static
    cruise = static

    def accelerate(self, to_speed: float, accel: float = 1.0, tilt: bool = False) -> "Trajectory":
        """Change horizontal speed with peak acceleration ``accel`` (m/s^2).

        ``tilt`` pitches the vehicle like a multicopter, nose down by the
        acceleration's angle ``atan(a/g)`` and back.
        """
        _positive("accel", accel)
        dv = to_speed - self.speed
        if dv == 0:
            return self
        dur = SMOOTHSTEP_PEAK * abs(dv) / accel
        self.ch[kin.CH_SPEED].ramp_value(to_speed, dur)
        if tilt:
            p0 = self.ch[kin.CH_PITCH].value
            ang = -math.atan(math.copysign(abs(dv) / dur, dv) / 9.81)
            self.ch[kin.CH_PITCH].ramp_value(p0 + ang, dur / 2)
            self.ch[kin.CH_PITCH].ramp_value(p0, dur / 2)
        self._finish(dur)
        return self

    decelerate = accelerate

    def turn(self, angle: float, rate: float = 10.0, coordinated: bool = True, ramp: float = 1.0) -> "Trajectory":
        """Turn by ``angle`` degrees (positive right) at ``rate`` deg/s with rate ramps.

        Coordinated turns bank to ``atan(V r / g)`` while turning (level turn).
        """
        _positive("rate", rate)
        _positive("ramp", ramp)
        r = math.radians(math.copysign(abs(rate), angle))
        a = math.radians(angle)
        if a == 0:
            return self
        if abs(a / r) < ramp:
            r = a / ramp  # a small turn keeps its ramps and turns slower instead
        hold = abs(a / r) - ramp
        yaw = self.ch[kin.CH_YAW]
        yaw.ramp_rate(r, ramp)
        yaw.hold_until(yaw.t_end + hold)
        yaw.ramp_rate(0.0, ramp)
        if coordinated and self.speed > 0:
            bank = math.atan(self.speed * r / 9.81)
            roll = self.ch[kin.CH_ROLL]
            roll.ramp_value(bank, ramp)
            roll.hold_until(roll.t_end + hold)
            roll.ramp_value(0.0, ramp)
        self._finish(2 * ramp + hold)
        return self

    def climb(self, height: float, rate: float = 2.0, accel: float = 1.0) -> "Trajectory":
        """Climb (or descend, negative) by ``height`` m at vertical speed ``rate`` m/s."""
        _positive("rate", rate)
        _positive("accel", accel)
        if height == 0:
            return self
        vz = math.copysign(abs(rate), height)
        ramp = SMOOTHSTEP_PEAK * abs(vz) / accel
        hold = abs(height / vz) - ramp
        if hold < 0:
            # too short to reach the speed: the fastest climb the acceleration allows
            vz = math.copysign(math.sqrt(abs(height) * accel / SMOOTHSTEP_PEAK), height)
            ramp = SMOOTHSTEP_PEAK * abs(vz) / accel
            hold = 0.0
        vd = self.ch[kin.CH_VD]
        vd.ramp_value(-vz, ramp)
        vd.hold_until(vd.t_end + hold)
        vd.ramp_value(0.0, ramp)
        self._finish(2 * ramp + hold)
        return self

    def attitude(self, duration: float, roll: float | None = None, pitch: float | None = None) -> "Trajectory":
        """Move roll and/or pitch (deg) to new values over ``duration`` s."""
        _positive("duration", duration)
        if roll is not None:
            self.ch[kin.CH_ROLL].ramp_value(math.radians(roll), duration)
        if pitch is not None:
            self.ch[kin.CH_PITCH].ramp_value(math.radians(pitch), duration)
        self._finish(duration)
        return self

    def waypoints(
        self, points: list[tuple[float, float, float]], speed: float = 10.0, turn_rate: float = 15.0,
        accel: float = 1.5, climb_rate: float = 2.0, coordinated: bool = True,
    ) -> "Trajectory":
        """Fly through local waypoints ``(north m, east m, up m)`` from the start point.

        Turns at most ``turn_rate`` deg/s, along-track accelerations at most
        ``accel`` (the centripetal acceleration of a turn is ``V * turn_rate``),
        climbs at most ``climb_rate`` m/s; each leg turns until on course to the
        point, then flies straight, changing height on the way.
        """
        for n, e, u in points:
            if self.speed < speed:
                self.accelerate(speed, accel)
            # a turn moves the vehicle: turn again towards the point until on course
            for _ in range(8):
                bearing = math.degrees(math.atan2(e - self.east, n - self.north))
                turn = (bearing - self.yaw_deg + 180.0) % 360.0 - 180.0
                if abs(turn) < 1e-3:
                    break
                self.turn(turn, turn_rate, coordinated)
            dist = math.hypot(n - self.north, e - self.east)
            dh = u - self.up
            if abs(dh) > 0.5:
                self.climb(dh, min(climb_rate, max(0.5, abs(dh) * self.speed / max(dist, 1.0))))
            dist = math.hypot(n - self.north, e - self.east)
            self.cruise(max(dist, 0.0) / max(self.speed, 0.1))
        return self

    # -- superposed motion ---------------------------------------------------
    def add_coning(self, half_angle: float, freq: float) -> "Trajectory":
        """Classic coning of the body z axis (half-angle deg, frequency Hz)."""
        self.cone = (math.radians(half_angle), 2 * math.pi * freq)
        self.max_freq = max(self.max_freq, freq)
        return self

    def add_angular_vibration(self, axis: tuple[float, float, float], amplitude: float, freq: float, phase: float = 0.0) -> "Trajectory":
        """Sinusoidal angular vibration ``amplitude`` deg about a body axis."""
        ax = np.asarray(axis, dtype=float)
        ax = ax / np.linalg.norm(ax) * math.radians(amplitude)
        self.vib.append([*ax, 2 * math.pi * freq, phase, 0.0])
        self.max_freq = max(self.max_freq, freq)
        return self

    def add_linear_vibration(self, accel: tuple[float, float, float], freq: float, phase: float = 0.0) -> "Trajectory":
        """Sinusoidal NED acceleration of amplitude ``accel`` (m/s^2 per axis)."""
        self.linvib.append([*accel, 2 * math.pi * freq, phase, 0.0])
        self.max_freq = max(self.max_freq, freq)
        return self

    def add_random_vibration(
        self, angular_psd: float, linear_psd: float, band: tuple[float, float], seed: int, lines: int = 40
    ) -> "Trajectory":
        """Random vibration with flat PSDs over ``band`` Hz, as a sum of sinusoids.

        ``angular_psd`` in rad^2/s^2/Hz of body rate, ``linear_psd`` in
        (m/s^2)^2/Hz of NED acceleration; ``lines`` random-phase lines per axis,
        each carrying PSD * bandwidth / lines of variance.
        """
        rng = np.random.default_rng(seed)
        f = rng.uniform(band[0], band[1], size=(3, lines))
        bw = band[1] - band[0]
        for axis in range(3):
            for k in range(lines):
                w = 2 * math.pi * f[axis, k]
                if angular_psd > 0:
                    amp = math.sqrt(2 * angular_psd * bw / lines) / w  # rate amplitude / w = angle amplitude
                    ax = [0.0, 0.0, 0.0]
                    ax[axis] = amp
                    self.vib.append([*ax, w, rng.uniform(0, 2 * math.pi), 0.0])
                if linear_psd > 0:
                    acc = [0.0, 0.0, 0.0]
                    acc[axis] = math.sqrt(2 * linear_psd * bw / lines)
                    self.linvib.append([*acc, w, rng.uniform(0, 2 * math.pi), 0.0])
        self.max_freq = max(self.max_freq, band[1])
        return self

    def add_sculling(self, angle: float, accel: float, freq: float) -> "Trajectory":
        """Sculling: roll oscillation ``angle`` deg with an in-phase east acceleration ``accel``."""
        self.add_angular_vibration((1.0, 0.0, 0.0), angle, freq)
        self.add_linear_vibration((0.0, accel, 0.0), freq)
        return self

    # -- turntable (rotation-modulated IMU) -----------------------------------
    def turntable_continuous(self, rate: float, until: float, axis: int = 1, ramp: float = 1.0) -> "Trajectory":
        """Rotate the IMU about the vehicle z (axis 1) or the inner x axis (2) at ``rate`` deg/s."""
        ch = self.ch[kin.CH_TT1 if axis == 1 else kin.CH_TT2]
        ch.ramp_rate(math.radians(rate), ramp)
        ch.hold_until(until)
        return self

    def turntable_stop_and_go(
        self, positions: list[float], rate: float, dwell: float, until: float, alternate: bool = True, ramp: float = 0.5,
    ) -> "Trajectory":
        """Stop at each of ``positions`` (deg) for ``dwell`` s, moving between them at ``rate`` deg/s.

        With ``alternate`` the sequence runs forward then back (0, 90, 180, 270,
        180, 90, 0, ...), so rotations of opposite direction follow each other.
        """
        _positive("rate", rate)
        _positive("dwell", dwell)
        ch = self.ch[kin.CH_TT1]
        m = len(positions)
        if alternate and m > 1:
            order = list(positions) + list(positions[-2:0:-1])
            target = lambda k: order[k % len(order)]  # noqa: E731
        else:
            target = lambda k: positions[k % m] + 360.0 * (k // m)  # noqa: E731
        ch.value = math.radians(target(0))
        k = 0
        while ch.t_end < until:
            ch.hold_until(min(ch.t_end + dwell, until))
            if ch.t_end >= until:
                break
            k += 1
            delta = math.radians(target(k)) - ch.value
            if delta == 0.0:
                continue
            r = math.copysign(math.radians(rate), delta)
            tau = min(ramp, abs(delta / r))
            hold = abs(delta / r) - tau
            ch.ramp_rate(r, tau)
            ch.hold_until(ch.t_end + hold)
            ch.ramp_rate(0.0, tau)
            ch.value = math.radians(target(k))  # exact stop despite round-off
        return self

    # -- output --------------------------------------------------------------
    def spec(self, t_end: float | None = None, g_lab: float | None = None) -> MotionSpec:
        """Freeze the builder into kernel arrays, holding every channel to ``t_end``."""
        t_end = self.t if t_end is None else t_end
        for c in self.ch:
            c.hold_until(t_end)
        arrs = [c.arrays() for c in self.ch]
        kmax = max(len(a[0]) for a in arrs)
        starts = np.full((kin.N_CHANNELS, kmax), np.inf)
        durs = np.ones((kin.N_CHANNELS, kmax))
        coefs = np.zeros((kin.N_CHANNELS, kmax, 7))
        counts = np.zeros(kin.N_CHANNELS, dtype=np.int64)
        for i, (s, d, c) in enumerate(arrs):
            starts[i, : len(s)] = s
            durs[i, : len(s)] = d
            coefs[i, : len(s)] = c
            counts[i] = len(s)
        lat = math.radians(self.lat)
        g = earth.gravity(lat, self.h) if g_lab is None else g_lab
        return MotionSpec(
            t0=self.t0, t_end=t_end, lat=lat, lon=math.radians(self.lon), h=self.h,
            starts=starts, durs=durs, coefs=coefs, counts=counts,
            vib=np.array(self.vib, dtype=float).reshape(-1, 6),
            consts=np.array([self.cone[0], self.cone[1], g]),
            linvib=np.array(self.linvib, dtype=float).reshape(-1, 6),
            use_earth=self.use_earth, max_freq=self.max_freq,
            breaks=np.unique(np.concatenate([s for s, _, _ in arrs] + [s + d for s, d, _ in arrs])),
        )


@dataclass(frozen=True)
class SimResult:
    """Exact increments and truth of a simulated run (file units in ``truth``).

    ``truth`` columns: t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz (the IMU
    frame's attitude, degrees) followed by the vehicle's roll, pitch, yaw and
    the turntable angles tt1, tt2 (degrees). Row 0 is the initial state.
    """

    t0: float
    t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    truth: np.ndarray
    spec: MotionSpec

    TRUTH_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz",
                     "veh_roll", "veh_pitch", "veh_yaw", "tt1", "tt2")

    def init(self) -> dict[str, float]:
        """Initial state (contract keys) from the first truth row."""
        r = self.truth[0]
        return dict(t=r[0], lat=r[1], lon=r[2], h=r[3], vn=r[4], ve=r[5], vd=r[6], roll=r[7], pitch=r[8], yaw=r[9])


# Rows per piece of a run made in pieces (simulate_chunks): the first small, so a stream starts at
# once, the others larger; both multiples of sim.errors.BLOCK, so the error streams' pieces line up.
FIRST_ROWS = 4096
CHUNK_ROWS = 16384


def sample_times(t0: float, n: int, rate: float, usec_grid: bool) -> np.ndarray:
    """The n sample times ``t0 + k/rate`` (k = 1..n), rounded to whole microseconds with ``usec_grid``."""
    k = np.arange(1, n + 1)
    return t0 + (np.round(k * (1e6 / rate)) / 1e6 if usec_grid else k / rate)


def chunk_bounds(n: int, first: int = FIRST_ROWS, rows: int = CHUNK_ROWS) -> list[tuple[int, int]]:
    """Row ranges [a, b) of a run of n rows made in pieces: ``first`` rows, then ``rows`` at a time."""
    edges = [0] + list(range(min(first, n), n, rows)) + [n]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a] or [(0, 0)]


def simulate(
    traj: Trajectory | MotionSpec, rate: float, duration: float | None = None, substeps: int | None = None,
    usec_grid: bool = False,
) -> SimResult:
    """Sample a trajectory at ``rate`` Hz: exact increments and truth at every sample.

    Samples lie on the exact grid ``t0 + k/rate``; with ``usec_grid`` they are
    rounded to whole microseconds so that MAVLink's ``time_usec`` carries them
    exactly (for streaming; at rates that do not divide 1 MHz the intervals are
    then slightly uneven, which N-sample algorithms notice).

    Sub-steps default to one per 10 ms; the quadrature takes as many nodes as its
    remainder bound asks for the highest superposed frequency
    (sim.kinematics.quadrature_order). The run is made in the pieces of
    :func:`simulate_chunks` and joined.
    """
    parts = simulate_chunks(traj, rate, duration, substeps, usec_grid)
    done = 0
    out = []
    with Progress("simulate", parts.n) as bar:
        for part in parts:
            out.append(part)
            done += len(part.t)
            bar.update(done)
    return join(out)


def simulate_chunks(traj: Trajectory | MotionSpec, rate: float, duration: float | None = None,
                    substeps: int | None = None, usec_grid: bool = False) -> ChunkedRun:
    """:func:`simulate`'s run in consecutive pieces (:class:`ChunkedRun`)."""
    return ChunkedRun(traj, rate, duration, substeps, usec_grid)


class ChunkedRun:
    """:func:`simulate`'s run in consecutive pieces (rows :func:`chunk_bounds`), each a SimResult of its
    rows whose ``t0`` and truth row 0 are the previous piece's last (the start, for the first);
    ``n`` is the run's number of samples. Nothing is computed before the first piece is asked for."""

    def __init__(self, traj: Trajectory | MotionSpec, rate: float, duration: float | None = None,
                 substeps: int | None = None, usec_grid: bool = False) -> None:
        spec = traj if isinstance(traj, MotionSpec) else traj.spec(None if duration is None else traj.t0 + duration)
        t_end = spec.t_end if duration is None else spec.t0 + duration
        dt = 1.0 / rate
        self.n = int(math.floor((t_end - spec.t0) / dt + 1e-9))
        self.t = sample_times(spec.t0, self.n, rate, usec_grid)
        self.spec = spec
        self.substeps = max(1, math.ceil(dt / 0.01)) if substeps is None else substeps
        self.nodes, self.weights = kin.gauss_legendre(
            kin.quadrature_order(2 * math.pi * spec.max_freq * dt / self.substeps))

    def __iter__(self) -> Iterator[SimResult]:
        spec, t = self.spec, self.t
        p0 = (spec.lat, spec.lon) if spec.use_earth else (0.0, 0.0)
        pos_prev = np.array([p0[0], p0[1], spec.h])
        row_prev = np.empty((1, 13))
        kin.truth(np.array([spec.t0]), spec.starts, spec.durs, spec.coefs, spec.counts, spec.vib, spec.consts,
                  spec.linvib, row_prev)
        t_prev = spec.t0
        for a, b in chunk_bounds(self.n):
            m = b - a
            dtheta, dv, pos = np.empty((m, 3)), np.empty((m, 3)), np.empty((m + 1, 3))
            rows = np.empty((m + 1, 13))
            rows[0], pos[0] = row_prev[-1], pos_prev
            kin.integrate(t_prev, t[a:b], self.substeps, self.nodes, self.weights, pos_prev[0], pos_prev[1],
                          pos_prev[2], spec.starts, spec.durs, spec.coefs, spec.counts, spec.vib, spec.consts,
                          spec.linvib, spec.use_earth, spec.breaks, dtheta, dv, pos[1:], rows[1:])
            tt = np.concatenate(([t_prev], t[a:b]))
            yield SimResult(t_prev, t[a:b].copy(), dtheta, dv, _truth_table(spec, tt, pos, rows), spec)
            t_prev, pos_prev, row_prev = (tt[-1], pos[-1].copy(), rows[-1:].copy())


def _truth_table(spec: MotionSpec, tt: np.ndarray, pos: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """SimResult.TRUTH_COLUMNS at times tt from the positions (lat, lon, h or flat north, east, -h) and
    the kernel's truth rows (sim.kinematics.truth_row)."""
    n = tt.shape[0]
    if spec.use_earth:
        lat, lon = pos[:, 0], pos[:, 1]
    else:
        # flat NED offsets through the start point's radii (docs/conventions.md earth = none)
        r_n, r_e = earth.radii(spec.lat)
        lat = spec.lat + pos[:, 0] / (r_n + spec.h)
        lon = spec.lon + pos[:, 1] / ((r_e + spec.h) * math.cos(spec.lat))
    truth = np.empty((n, 19))
    truth[:, 0] = tt
    truth[:, 1] = np.degrees(lat)
    truth[:, 2] = np.degrees(lon)
    truth[:, 3] = pos[:, 2]
    truth[:, 4:7] = rows[:, 0:3]
    truth[:, 10:14] = rows[:, 3:7]
    euler = np.empty((n, 3))
    kin.euler_rows(np.ascontiguousarray(rows[:, 3:7]), euler)
    truth[:, 7:10] = np.degrees(euler)
    kin.euler_rows(np.ascontiguousarray(rows[:, 7:11]), euler)
    truth[:, 14:17] = np.degrees(euler)
    truth[:, 17] = np.degrees(rows[:, 11])
    truth[:, 18] = np.degrees(rows[:, 12])
    return truth


def join(parts: list[SimResult]) -> SimResult:
    """One SimResult of consecutive pieces (each piece's truth row 0 is the previous piece's last)."""
    first = parts[0]
    return SimResult(first.t0, np.concatenate([p.t for p in parts]), np.concatenate([p.dtheta for p in parts]),
                     np.concatenate([p.dv for p in parts]),
                     np.concatenate([first.truth] + [p.truth[1:] for p in parts[1:]]), first.spec)


def instant_rates(res: SimResult) -> tuple[np.ndarray, np.ndarray]:
    """True instantaneous ``w_is^s`` (rad/s) and ``f^s`` (m/s^2) at every sample time."""
    sp = res.spec
    w = np.empty((len(res.t), 3))
    f = np.empty((len(res.t), 3))
    lat = np.radians(res.truth[1:, 1])
    h = res.truth[1:, 3]
    for i, ti in enumerate(res.t):
        w[i], f[i] = kin.imu_rates(float(ti), float(lat[i]), float(h[i]), sp.starts, sp.durs, sp.coefs, sp.counts,
                                   sp.vib, sp.consts, sp.linvib, sp.use_earth)
    return w, f


def _positive(name: str, value: float, allow_zero: bool = False) -> None:
    """Reject a non-positive (or negative, with allow_zero) segment value."""
    if not (value >= 0 if allow_zero else value > 0):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {value}")

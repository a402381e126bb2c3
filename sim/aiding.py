"""Aiding sensors for a simulated run: GNSS, barometer and magnetometer from the run's truth.

Every generator reads a :class:`sim.generate.SimRun` (truth rows at the IMU
times, columns of SimResult.TRUTH_COLUMNS, attitude of the IMU frame) and
draws its noise from its own numpy Generator seeded from the run's seed
(``SeedSequence(seed, spawn_key=(stream,))``, streams apart from the IMU
error streams of sim/errors.py), so a run and its aiding data are
reproducible and independent.

Files (docs/conventions.md "Aided navigation"), written beside imu.csv:

* ``gnss.csv``: ``t,lat,lon,h,vn,ve,vd,sigma_h,sigma_v,sigma_vel`` (deg, deg,
  ellipsoidal m; m/s; m, m, m/s): the antenna's position and velocity, with
  ``nan`` position and velocity during outages (a row whose position is NaN
  is no fix);
* ``baro.csv``: ``t,h,sigma`` (m): ellipsoidal height of the IMU plus a
  constant offset, a random-walk drift and white noise;
* ``mag.csv``: ``t,mx,my,mz,sigma`` (uT, body FRD; deg): the Earth field of
  the given declination and inclination seen by the IMU, plus hard iron and
  noise; ``sigma`` is the heading noise of one sample (:meth:`MagConfig.heading_sigma`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from mavins.core import earth
from mavins.core.rotation import dcm_to_quat, quat_to_dcm, rotvec_to_dcm

if TYPE_CHECKING:
    from .generate import SimRun

GNSS_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "sigma_h", "sigma_v", "sigma_vel")
BARO_COLUMNS = ("t", "h", "sigma")
MAG_COLUMNS = ("t", "mx", "my", "mz", "sigma")
WHEEL_COLUMNS = ("t", "speed", "sigma")

_STREAMS = {"gnss": 0x6E1, "baro": 0x6E2, "mag": 0x6E3, "wheel": 0x6E4, "vision": 0x6E5}


@dataclass(frozen=True)
class GnssConfig:
    """GNSS receiver model.

    Attributes:
        rate: fixes per second (Hz); fixes at ``t0 + k / rate``, k >= 1.
        sigma_h: 1-sigma of each horizontal position axis (m).
        sigma_v: 1-sigma of the vertical position (m).
        sigma_vel: 1-sigma of each velocity axis (m/s).
        velocity: also report velocity.
        latency: uncompensated latency (s): the fix stamped t describes the
            antenna at ``t - latency`` (an error source; 0 = time of validity).
        lever_arm: antenna position from the IMU in the body frame FRD (m).
        outages: ``(start, end)`` intervals (s) without a fix.
    """

    rate: float = 1.0
    sigma_h: float = 1.0
    sigma_v: float = 1.5
    sigma_vel: float = 0.1
    velocity: bool = True
    latency: float = 0.0
    lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    outages: tuple[tuple[float, float], ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class BaroConfig:
    """Barometric altimeter: rate (Hz), white noise sigma (m), constant offset (m), drift (m/sqrt(s))."""

    rate: float = 10.0
    sigma: float = 0.5
    offset: float = 0.0
    drift: float = 0.0


@dataclass(frozen=True)
class MagConfig:
    """Magnetometer: rate (Hz), field strength (uT), declination and inclination (deg,
    east and down positive), noise sigma per axis (uT), hard-iron offset in FRD (uT),
    disturbances ``(t0, t1, (n, e, d))``: a local field (uT, NED: steel, a power line)
    added to the Earth's from t0 to t1 (s)."""

    rate: float = 10.0
    strength: float = 48.0
    declination: float = 2.0
    inclination: float = 63.0
    sigma: float = 0.3
    hard_iron: tuple[float, float, float] = (0.0, 0.0, 0.0)
    disturbances: tuple[tuple[float, float, tuple[float, float, float]], ...] = ()

    @classmethod
    def at(cls, lat_deg: float, lon_deg: float, h_m: float, year: float, **kw: object) -> "MagConfig":
        """The World Magnetic Model's field (mavins.core.magmodel) at a position (deg, deg, ellipsoidal m)
        and decimal year: its declination, inclination and strength (nT -> uT); ``kw`` sets the rest."""
        from mavins.core.magmodel import field_at

        f = field_at(lat_deg, lon_deg, h_m, year)
        return cls(declination=f.declination, inclination=f.inclination, strength=f.intensity / 1000.0, **kw)

    def heading_sigma(self) -> float:
        """Heading noise of one sample (rad): the noise across the horizontal field over its
        strength, ``sigma / (B cos I)`` (the levelled field's angle moves by its perpendicular part)."""
        return self.sigma / (self.strength * math.cos(math.radians(self.inclination)))

    def field_n(self) -> np.ndarray:
        """The Earth field in NED (uT)."""
        d, i = math.radians(self.declination), math.radians(self.inclination)
        return self.strength * np.array([math.cos(i) * math.cos(d), math.cos(i) * math.sin(d), math.sin(i)])


@dataclass(frozen=True)
class VisionConfig:
    """A camera's pose and velocity (a visual-inertial odometer, motion capture) in its own local frame: z down,
    its x axis ``yaw`` (rad) east of north, its origin ``origin`` (m, NED from the run's first position); white
    noise ``sigma_pos`` (m per axis of the frame), ``sigma_att`` (rad about each body axis), ``sigma_vel`` (m/s
    per body axis); ``rate`` poses a second."""

    rate: float = 30.0
    sigma_pos: float = 0.05
    sigma_att: float = math.radians(1.0)
    sigma_vel: float = 0.05
    yaw: float = math.radians(30.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)


def camera_pose(llh: np.ndarray, q: np.ndarray, vel: np.ndarray, start: Sequence[float], config: VisionConfig,
                rng: np.random.Generator) -> np.ndarray:
    """Rows ``x y z`` (m, in the camera's frame), ``qw qx qy qz`` (body FRD to that frame), ``vx vy vz`` (m/s,
    body FRD) of the truth rows ``llh`` (lat, lon rad, h m), ``q`` (C_b^n, scalar first) and ``vel`` (NED m/s),
    seen from the frame of ``config`` whose origin is counted from ``start`` (lat, lon rad, h m): the NED
    metres from the start (radii at the start: below 2 cm per km of the filter's, kalman.vision_relative)
    less the origin, turned by ``Rz(yaw)^T``; the attitude ``Rz(yaw)^T C exp([n x])`` with n the body-axis
    noise; the velocity ``C^T v`` plus noise."""
    lat0, lon0, h0 = (float(v) for v in start)
    r_n, r_e = earth.radii(lat0)
    c, s = math.cos(config.yaw), math.sin(config.yaw)
    rt = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # Rz(yaw)^T: NED to the camera's frame
    ned = np.column_stack([(llh[:, 0] - lat0) * (r_n + h0), (llh[:, 1] - lon0) * (r_e + h0) * math.cos(lat0),
                           h0 - llh[:, 2]]) - np.asarray(config.origin, dtype=np.float64)
    out = np.empty((len(llh), 10))
    out[:, 0:3] = ned @ rt.T + config.sigma_pos * rng.standard_normal((len(llh), 3))
    for k in range(len(llh)):
        cbn = quat_to_dcm(np.ascontiguousarray(q[k]))
        out[k, 3:7] = dcm_to_quat(rt @ cbn @ rotvec_to_dcm(config.sigma_att * rng.standard_normal(3)))
        out[k, 7:10] = cbn.T @ vel[k] + config.sigma_vel * rng.standard_normal(3)
    return out


def vision(run: "SimRun", config: VisionConfig = VisionConfig()) -> np.ndarray:
    """Camera rows ``t`` and :func:`camera_pose`'s columns at ``config.rate`` over the run, the frame's origin
    counted from the run's first position."""
    t = _epochs(run, config.rate)
    llh, vel, q, _ = truth_at(run, t)
    tr = run.exact.truth[0]
    start = (math.radians(tr[1]), math.radians(tr[2]), tr[3])
    return np.column_stack([t, camera_pose(llh, q, vel, start, config, _rng(run, "vision"))])


@dataclass(frozen=True)
class WheelConfig:
    """A wheel odometer: the forward speed (m/s) at the axle centre ``lever_arm`` (m, body FRD, from the IMU),
    times ``1 + scale`` (its scale-factor error), plus white noise ``sigma`` (m/s), ``rate`` samples a second."""

    rate: float = 10.0
    sigma: float = 0.05
    scale: float = 0.01
    lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Aiding:
    """Aiding rows of one run in file units (None = not generated)."""

    gnss: np.ndarray | None = None
    baro: np.ndarray | None = None
    mag: np.ndarray | None = None
    wheel: np.ndarray | None = None

    def write(self, outdir: Path) -> list[Path]:
        """Write gnss.csv, baro.csv, mag.csv, wheel.csv (those present) into outdir."""
        return write_aiding(outdir, gnss=self.gnss, baro=self.baro, mag=self.mag, wheel=self.wheel)


def _rng(run: "SimRun", stream: str) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(run.seed, spawn_key=(_STREAMS[stream],))))


def _epochs(run: "SimRun", rate: float) -> np.ndarray:
    if not rate > 0.0:
        raise ValueError(f"rate must be positive, got {rate}")
    t0 = float(run.exact.truth[0, 0])
    t_end = float(run.exact.truth[-1, 0])
    n = int(math.floor((t_end - t0) * rate + 1e-9))
    return t0 + np.arange(1, n + 1) / rate


def truth_at(run: "SimRun", times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Truth at arbitrary times inside the run: ``(lat_lon_h (rad, rad, m), v_ned, q_nb, w_ib_b)``.

    Linear interpolation between truth rows (exact at the IMU sample times),
    quaternions normalised after interpolation; the body rate is the
    interval-mean rate of the exact increments, interpolated between interval
    midpoints (rad/s).
    """
    tr = run.exact.truth
    tt = tr[:, 0]
    times = np.asarray(times, dtype=np.float64)
    if times.size and (times.min() < tt[0] - 1e-9 or times.max() > tt[-1] + 1e-9):
        raise ValueError("times outside the run")
    pos = np.column_stack([np.interp(times, tt, np.radians(tr[:, 1])), np.interp(times, tt, np.radians(tr[:, 2])),
                           np.interp(times, tt, tr[:, 3])])
    vel = np.column_stack([np.interp(times, tt, tr[:, c]) for c in (4, 5, 6)])
    q = tr[:, 10:14].copy()
    flip = np.concatenate(([False], np.sum(q[1:] * q[:-1], axis=1) < 0.0))
    q[np.cumsum(flip) % 2 == 1] *= -1.0
    qi = np.column_stack([np.interp(times, tt, q[:, c]) for c in range(4)])
    qi /= np.linalg.norm(qi, axis=1)[:, None]
    t_imu = np.concatenate(([run.exact.t0], run.exact.t))
    dt = np.diff(t_imu)
    w = run.exact.dtheta / dt[:, None]
    mid = 0.5 * (t_imu[:-1] + t_imu[1:])
    wi = np.column_stack([np.interp(times, mid, w[:, c]) for c in range(3)])
    return pos, vel, qi, wi


def gnss(run: "SimRun", config: GnssConfig = GnssConfig()) -> np.ndarray:
    """GNSS rows (GNSS_COLUMNS, file units) for a simulated run.

    Antenna position ``p + C_b^n l`` and velocity ``v + C_b^n (w_ib x l) -
    w_ie^n x (C_b^n l)`` (Earth-referenced lever-arm velocity), plus white
    noise: N(0, sigma_h) per horizontal axis, N(0, sigma_v) vertical (metres,
    mapped to lat/lon through the radii), N(0, sigma_vel) per velocity axis.
    """
    t = _epochs(run, config.rate)
    t_valid = t - config.latency
    t0 = float(run.exact.truth[0, 0])
    t_valid = np.maximum(t_valid, t0)
    pos, vel, q, w = truth_at(run, t_valid)
    lever = np.asarray(config.lever_arm, dtype=np.float64)
    rng = _rng(run, "gnss")
    noise_p = rng.standard_normal((t.size, 3)) * np.array([config.sigma_h, config.sigma_h, config.sigma_v])
    noise_v = rng.standard_normal((t.size, 3)) * config.sigma_vel
    rows = np.empty((t.size, len(GNSS_COLUMNS)))
    for k in range(t.size):
        lat, lon, h = pos[k]
        c = quat_to_dcm(q[k])
        la = c @ lever
        w_ie = earth.earth_rate_n(lat)
        v_ant = vel[k] + c @ np.cross(w[k], lever) - np.cross(w_ie, la)
        r_n, r_e = earth.radii(lat)
        d = la + noise_p[k]
        rows[k, 0] = t[k]
        rows[k, 1] = math.degrees(lat + d[0] / (r_n + h))
        rows[k, 2] = math.degrees(lon + d[1] / ((r_e + h) * math.cos(lat)))
        rows[k, 3] = h - d[2]
        rows[k, 4:7] = v_ant + noise_v[k] if config.velocity else np.nan
    rows[:, 7] = config.sigma_h
    rows[:, 8] = config.sigma_v
    rows[:, 9] = config.sigma_vel
    for start, end in config.outages:
        out = (t >= start) & (t < end)
        rows[out, 1:7] = np.nan
    return rows


def baro(run: "SimRun", config: BaroConfig = BaroConfig()) -> np.ndarray:
    """Barometer rows ``t, h, sigma`` (m): IMU height + offset + random-walk drift + white noise."""
    t = _epochs(run, config.rate)
    pos, _, _, _ = truth_at(run, t)
    rng = _rng(run, "baro")
    dt = np.diff(t, prepend=float(run.exact.truth[0, 0]))
    drift = np.cumsum(config.drift * np.sqrt(dt) * rng.standard_normal(t.size))
    noise = config.sigma * rng.standard_normal(t.size)
    return np.column_stack([t, pos[:, 2] + config.offset + drift + noise, np.full(t.size, config.sigma)])


def magnetometer(run: "SimRun", config: MagConfig = MagConfig()) -> np.ndarray:
    """Magnetometer rows ``t, mx, my, mz`` (uT, FRD): ``C_n^b (m^n + disturbance) + hard iron + noise``."""
    t = _epochs(run, config.rate)
    _, _, q, _ = truth_at(run, t)
    rng = _rng(run, "mag")
    noise = config.sigma * rng.standard_normal((t.size, 3))
    rows = np.empty((t.size, 4))
    rows[:, 0] = t
    for k in range(t.size):
        rows[k, 1:4] = body_field(q[k], config, noise[k], t[k])
    return rows


def wheel(run: "SimRun", config: WheelConfig = WheelConfig()) -> np.ndarray:
    """Odometer rows ``t, speed, sigma`` (m/s): ``(1 + scale) ((C_b^n)^T v + w_ib x l)_x + noise``, the forward
    speed over ground at the axle centre l (kalman.wheel_speed's model; the Earth rate's share through the
    lever arm, below 1e-4 m/s per metre, left out as there)."""
    t = _epochs(run, config.rate)
    _, vel, q, w = truth_at(run, t)
    rng = _rng(run, "wheel")
    rows = np.empty((t.size, 3))
    rows[:, 0] = t
    rows[:, 2] = config.sigma
    rows[:, 1] = (1.0 + config.scale) * forward_speed(q, vel, w, config.lever_arm)
    rows[:, 1] += config.sigma * rng.standard_normal(t.size)
    return rows


def forward_speed(q: np.ndarray, vel: np.ndarray, w: np.ndarray, lever: Sequence[float]) -> np.ndarray:
    """The true forward speed (m/s) at ``lever`` (m, body FRD) of rows of attitude ``q`` (C_b^n, scalar
    first), NED velocity ``vel`` (m/s) and body rate ``w`` (rad/s): ``((C_b^n)^T v + w x l)_x``."""
    lv = np.asarray(lever, dtype=np.float64)
    return np.array([(quat_to_dcm(np.ascontiguousarray(q[k])).T @ vel[k])[0] + np.cross(w[k], lv)[0]
                     for k in range(len(q))])


def body_field(q: np.ndarray, config: MagConfig, noise: np.ndarray, t: float = math.nan) -> np.ndarray:
    """One magnetometer sample (uT, FRD) at time t (s) of an IMU with attitude quaternion ``q`` (C_b^n,
    scalar first): ``C_n^b (m^n + disturbances at t) + hard iron + noise`` (noise in uT, already drawn)."""
    m_n = config.field_n()
    for t0, t1, extra in config.disturbances:
        if t0 <= t <= t1:
            m_n = m_n + np.asarray(extra, dtype=np.float64)
    return quat_to_dcm(q).T @ m_n + np.asarray(config.hard_iron, dtype=np.float64) + noise


def mag_heading(m_b: Sequence[float], roll: float, pitch: float, declination: float) -> float:
    """Yaw (rad) from a calibrated magnetometer sample, tilt-compensated with roll and pitch (rad).

    With ``C_b^n = Rz(yaw) Ry(pitch) Rx(roll)`` the levelled field ``m_l =
    Ry(pitch) Rx(roll) m_b`` points ``declination - yaw`` east of the level
    x axis, so ``yaw = declination - atan2(m_l,y, m_l,x)`` (declination in rad).
    """
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    mx, my, mz = (float(v) for v in m_b)
    y1 = cr * my - sr * mz
    z1 = sr * my + cr * mz
    x2 = cp * mx + sp * z1
    yaw = declination - math.atan2(y1, x2)
    return math.atan2(math.sin(yaw), math.cos(yaw))


def simulate_aiding(
    run: "SimRun",
    gnss_config: GnssConfig | None = GnssConfig(),
    baro_config: BaroConfig | None = BaroConfig(),
    mag_config: MagConfig | None = None,
    wheel_config: WheelConfig | None = None,
) -> Aiding:
    """GNSS, baro, magnetometer and odometer rows for a run (None config = that sensor is absent)."""
    return Aiding(
        gnss=None if gnss_config is None else gnss(run, gnss_config),
        baro=None if baro_config is None else baro(run, baro_config),
        mag=None if mag_config is None else _with_sigma(magnetometer(run, mag_config), mag_config),
        wheel=None if wheel_config is None else wheel(run, wheel_config),
    )


def _with_sigma(rows: np.ndarray, config: MagConfig) -> np.ndarray:
    """Magnetometer rows with the ``sigma`` column of mag.csv (deg of heading per sample)."""
    return np.column_stack([rows, np.full(rows.shape[0], math.degrees(config.heading_sigma()))])


def _write_csv(path: Path, columns: Sequence[str], rows: np.ndarray) -> None:
    """CSV with a header and round-trip floats (``nan`` where there is no value)."""
    rows = np.atleast_2d(np.asarray(rows, dtype=np.float64))
    if rows.size and rows.shape[1] != len(columns):
        raise ValueError(f"{path.name}: rows of {rows.shape[1]} values for the {len(columns)} columns "
                         f"{','.join(columns)}")
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(columns) + "\n")
        for row in rows.tolist():
            fh.write(",".join(map(repr, row)) + "\n")


def write_aiding(
    outdir: Path, *, gnss: np.ndarray | None = None, baro: np.ndarray | None = None, mag: np.ndarray | None = None,
    wheel: np.ndarray | None = None
) -> list[Path]:
    """Write gnss.csv, baro.csv, mag.csv and wheel.csv (those given) into outdir; returns the paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, columns, rows in (("gnss", GNSS_COLUMNS, gnss), ("baro", BARO_COLUMNS, baro), ("mag", MAG_COLUMNS, mag),
                                ("wheel", WHEEL_COLUMNS, wheel)):
        if rows is not None:
            path = outdir / f"{name}.csv"
            _write_csv(path, columns, rows)
            paths.append(path)
    return paths

"""Heading sources of ``mavins run`` and the gyro-bias estimate, against headings typed here.

Every run is the real service (a subprocess listening on 127.0.0.1) fed
HIGHRES_IMU (or RAW_IMU) over UDP by the test. The board rests tilted by a
typed roll and pitch, so that levelling matters; the sensors are built from
typed vectors with the contract's rotation (``C_b^n = Rz(yaw) Ry(pitch)
Rx(roll)``, FRD body, NED navigation frame):

* accelerometers ``f = C_n^b [0, 0, -gamma]`` (typed Somigliana gravity),
* gyros ``w = C_n^b [Omega cos L, 0, -Omega sin L] + bias``,
* magnetometer ``m = C_n^b B [cos I cos D, cos I sin D, sin I]``: a field of
  inclination I whose horizontal part points to magnetic north, D east of true
  north. Its magnetic heading is yaw - D; ``--heading mag --declination D``
  must give the yaw back.

Tolerances: HIGHRES_IMU carries float32, so every field is off by at most
2^-24 of itself (6e-8 relative). Level from the mean force is then good to
~1e-7 rad; a heading from the levelled magnetometer to ~1e-7 rad plus tan(I)
times the level error (~2e-7 rad); a gyrocompass heading to the relative
rounding of the horizontal Earth rate plus tan(L) times the level error
(~3e-7 rad). Anything under 1e-6 rad = 6e-5 deg, so 1e-4 deg is allowed for
headings and attitudes. The mistakes these runs look for are degrees:
a mirrored magnetometer heading gives -60 instead of 80 deg, declination the
wrong way 60 instead of 80, no levelling 15.7 deg off, a mirrored gyrocompass
-120 instead of 120 deg, a bias left in 0.26 deg of yaw in 20 s.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from support import OMEGA, ServiceProcess, cbn, gamma, wrap_deg  # noqa: E402

ANGLE_TOL_DEG = 1e-4
ALL_FIELDS = 0b111111111  # acc, gyro, mag
ACC_GYRO = 0b111111


@dataclass(frozen=True)
class Board:
    """A board at rest: position, attitude (deg), and what its sensors read."""

    lat: float
    h: float
    roll: float
    pitch: float
    yaw: float
    bias_deg_h: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mag_heading: float | None = None  # magnetic heading (deg) the magnetometer shows, None: no magnetometer
    declination: float = 0.0
    inclination: float = 63.0
    field: float = 0.48  # gauss

    def c_nb(self) -> np.ndarray:
        return cbn(*np.radians([self.roll, self.pitch, self.yaw])).T

    def force(self) -> np.ndarray:
        return self.c_nb() @ np.array([0.0, 0.0, -gamma(math.radians(self.lat), self.h)])

    def rate(self) -> np.ndarray:
        lat = math.radians(self.lat)
        bias = np.radians(np.array(self.bias_deg_h) / 3600.0)
        return self.c_nb() @ np.array([OMEGA * math.cos(lat), 0.0, -OMEGA * math.sin(lat)]) + bias

    def mag(self) -> np.ndarray:
        """The field whose magnetic heading, seen from this board, is ``mag_heading``: its horizontal
        part lies at true azimuth yaw - mag_heading (magnetic north), D = that azimuth."""
        assert self.mag_heading is not None
        az = math.radians(self.yaw - self.mag_heading)
        inc = math.radians(self.inclination)
        m_n = self.field * np.array([math.cos(inc) * math.cos(az), math.cos(inc) * math.sin(az), math.sin(inc)])
        return self.c_nb() @ m_n


Service = ServiceProcess  # support.py: `mavins run` fed over UDP


def send_rest(mav: mavlink.MAVLink, board: Board, t0_us: int, seconds: float, rate: float = 100.0) -> int:
    f, w = board.force(), board.rate()
    m = board.mag() if board.mag_heading is not None else np.zeros(3)
    bits = ALL_FIELDS if board.mag_heading is not None else ACC_GYRO
    step = int(round(1e6 / rate))
    n = int(round(seconds * rate))
    for k in range(n + 1):
        mav.highres_imu_send(t0_us + k * step, *f, *w, *m, 0, 0, 0, 0, bits, 0)
    return n + 1


def assert_attitude(rows: np.ndarray, roll: float, pitch: float, yaw: float, tol: float = ANGLE_TOL_DEG) -> None:
    err = np.abs(wrap_deg(rows[:, 7:10] - np.array([roll, pitch, yaw])))
    assert np.all(err <= tol), f"max |roll, pitch, yaw error| = {err.max(0)} deg (first row {rows[0, 7:10]})"


def navigating_lines(log: str) -> list[str]:
    return [ln for ln in log.splitlines() if "NAVIGATING: aligned over" in ln]


# --- --heading mag ---------------------------------------------------------------------------------
MAG_BOARD = Board(lat=47.4, h=500.0, roll=4.0, pitch=-7.0, yaw=80.0, mag_heading=70.0, declination=10.0)


def test_mag_heading_with_declination(tmp_path: Path) -> None:
    """--heading mag --declination 10 on a board tilted by (4, -7) deg whose magnetometer shows a
    magnetic heading of 70 deg: yaw = 70 + 10 = 80 deg, announced by the alignment and then held by
    the solution for 20 s of rest (nothing turns: whatever else uses the magnetometer must use the
    same declination). No levelling at this tilt and 63 deg of inclination would be 15.7 deg off
    (computed below, with the typed field alone); a mirrored heading gives -60, the declination
    the wrong way 60, a magnetometer heading without the declination 70."""
    b = MAG_BOARD
    # what skipping the levelling would give (typed field, typed heading formula of the contract)
    m = b.mag()
    assert abs(wrap_deg(math.degrees(math.atan2(-m[1], m[0])) + b.declination - b.yaw)) > 15.0
    svc = Service(tmp_path, "--lat", str(b.lat), "--lon", "8.5", "--alt", str(b.h), "--heading", "mag",
                  "--declination", str(b.declination), "--align", "2")
    send_rest(svc.mav(), b, 1_000_000, 22.0)
    res = svc.stop()
    lines = navigating_lines(res.log)
    assert len(lines) == 1 and lines[0].endswith("deg from magnetometer"), res.log
    assert "heading 80.00 deg" in lines[0], lines[0]
    assert res.nav[-1, 0] - res.nav[0, 0] > 19.0
    yaw = res.nav[:, 9]
    assert np.all(np.abs(wrap_deg(yaw - b.yaw)) <= ANGLE_TOL_DEG), (
        f"aligned at 80.00 deg (magnetic 70 + declination 10), the solution's yaw then goes "
        f"{yaw[0]:.4f} -> {yaw[-1]:.4f} deg at rest: towards the magnetic heading 70 deg, i.e. something "
        f"after the alignment uses the magnetometer without --declination")
    assert_attitude(res.nav, b.roll, b.pitch, b.yaw)


# --- the default declination: the World Magnetic Model's --------------------------------------------
# NOAA's WMM2025 test values (WMM2025testvalues.pdf) at 80 S, 240 E (= -120), on the ellipsoid: the
# field's north, east and down components (nT, printed to 0.1 nT) and the declination (deg, to 0.01)
NOAA_POINT = {2025.0: ((6117.5, 15751.9, -52022.5), 68.78), 2027.5: ((6200.7, 15730.3, -51783.7), 68.49)}


@dataclass(frozen=True)
class NoaaBoard(Board):
    """A board at rest at NOAA's test point whose magnetometer reads the published field (X, Y, Z)."""

    xyz_nt: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def mag(self) -> np.ndarray:
        return self.c_nb() @ (np.array(self.xyz_nt) * 1e-5)  # nT -> gauss


@pytest.mark.parametrize("year, how", [(2025.0, "--date"), (2027.5, "SYSTEM_TIME")])
def test_mag_heading_without_declination_takes_the_world_magnetic_model(tmp_path: Path, year: float,
                                                                        how: str) -> None:
    """No --declination: the declination is the World Magnetic Model's at the position and date. The
    board (yaw 80, tilted 4, -7 deg) at 80 S, 120 W reads the field NOAA publishes there, whose horizontal
    part lies atan2(Y, X) east of true north (68.78 deg in 2025.0, 68.49 in 2027.5, typed). The date comes
    from --date, or from the vehicle's SYSTEM_TIME (2027-07-02T12:00Z = 2027.5: UNIX 1814529600 s).
    The aligned yaw must be 80 deg to NOAA's rounding of D (0.005 deg) plus the float32 1e-4 deg; the old
    default of 0 would give 80 - 68.8 = 11.2 deg, the other date's model 0.29 deg off."""
    xyz, d_noaa = NOAA_POINT[year]
    b = NoaaBoard(lat=-80.0, h=0.0, roll=4.0, pitch=-7.0, yaw=80.0, mag_heading=0.0, xyz_nt=xyz)
    opts = ["--date", "2025-01-01"] if how == "--date" else []
    svc = Service(tmp_path, "--lat", str(b.lat), "--lon", "-120", "--alt", str(b.h), "--heading", "mag",
                  "--align", "2", "--aiding", "none", *opts)
    mav = svc.mav()
    if how == "SYSTEM_TIME":
        mav.system_time_send(1_814_529_600_000_000, 500)
    send_rest(mav, b, 1_000_000, 4.0)
    res = svc.stop()
    m = re.search(r"magnetic declination (\S+) deg .* from WMM-2025", res.log)
    assert m and abs(float(m.group(1)) - d_noaa) <= 0.01, res.log
    assert abs(wrap_deg(res.nav[0, 9] - b.yaw)) <= 0.005 + ANGLE_TOL_DEG, (res.nav[0, 9], res.log)


def test_declination_option_overrides_the_model(tmp_path: Path) -> None:
    """--declination 0 at the same point: the model is not used (no line about it) and the yaw is the
    magnetic heading of the NOAA field, 80 - atan2(Y, X) (typed components)."""
    xyz, _ = NOAA_POINT[2025.0]
    b = NoaaBoard(lat=-80.0, h=0.0, roll=4.0, pitch=-7.0, yaw=80.0, mag_heading=0.0, xyz_nt=xyz)
    svc = Service(tmp_path, "--lat", str(b.lat), "--lon", "-120", "--alt", str(b.h), "--heading", "mag",
                  "--align", "2", "--aiding", "none", "--declination", "0")
    send_rest(svc.mav(), b, 1_000_000, 4.0)
    res = svc.stop()
    assert "magnetic declination" not in res.log
    want = b.yaw - math.degrees(math.atan2(xyz[1], xyz[0]))
    assert abs(wrap_deg(res.nav[0, 9] - want)) <= ANGLE_TOL_DEG, (res.nav[0, 9], want)


# --- --gyro-bias estimate ------------------------------------------------------------------------------
BIAS_BOARD = Board(lat=47.4, h=500.0, roll=4.0, pitch=-7.0, yaw=80.0, bias_deg_h=(72.0, -108.0, 54.0))


def test_gyro_bias_estimate_removes_a_known_bias(tmp_path: Path) -> None:
    """The gyros carry a constant bias of (72, -108, 54) deg/h = (0.02, -0.03, 0.015) deg/s on top of
    the Earth rate of the tilted board; the heading is a typed number (80), so nothing but the bias
    estimate is at work. ``--gyro-bias estimate`` (the default: mean gyro - C_n^b w_ie^n over the
    window) must announce the typed bias (printed to 0.1 deg/h; the estimate's own error is the
    float32 rounding and the 1e-7 rad level error times Omega: 1e-5 deg/h) and remove it: 20 s later
    the attitude is still (4, -7, 80) within the tolerance. Left in, the bias turns the yaw by
    0.26 deg and the level by 0.37/0.62 deg; with its sign flipped, twice that."""
    b = BIAS_BOARD
    svc = Service(tmp_path, "--lat", str(b.lat), "--lon", "8.5", "--alt", str(b.h), "--heading", str(b.yaw),
                  "--align", "2")
    send_rest(svc.mav(), b, 1_000_000, 22.0)
    res = svc.stop()
    m = re.search(r"gyro bias estimated at rest: (\S+) (\S+) (\S+) deg/h", res.log)
    assert m, res.log
    assert [float(x) for x in m.groups()] == list(b.bias_deg_h)
    assert res.nav[-1, 0] - res.nav[0, 0] > 19.0
    assert_attitude(res.nav, b.roll, b.pitch, b.yaw)


def test_raw_imu_magnetometer_in_milligauss(tmp_path: Path) -> None:
    """RAW_IMU carries the field in mgauss counts (1e-3 gauss, ArduPilot's; the service has no
    option for it). A common scale cannot change a heading (it is a ratio), so what is checked is
    that the three fields are read as x, y, z of the body: --heading mag --declination -5 on a
    board with yaw 25 deg (magnetic heading 30), tilted (-6, 3) deg. The counts are whole, so the
    heading the counts themselves describe is computed here from the contract's formula (level
    from the counted force, then atan2(-m_y, m_x) of the levelled field) and must be met to 1e-6 deg
    (double round-off); it is also within the quantisation of the typed 25 deg: half a count on each
    axis of a 218-count horizontal field, ~0.3 deg. int16 gyros cannot carry the Earth rate: the
    default bias estimate (mean gyro - C_n^b w_ie) puts it back, so the frame does not turn away
    from the aligned yaw before the first output (with ``--gyro-bias none`` it would, by
    Omega sin L T = 5e-5 deg in the first 20 ms)."""
    b = Board(lat=-33.9, h=60.0, roll=-6.0, pitch=3.0, yaw=25.0, mag_heading=30.0, declination=-5.0)
    mg = 9.80665e-3
    acc = np.round(b.force() / mg).astype(int)
    mag = np.round(b.mag() * 1000.0).astype(int)
    # the contract's level (roll = atan2(-f_y, -f_z), pitch = atan2(f_x, hypot(f_y, f_z))) and heading
    fx, fy, fz = acc * mg
    roll, pitch = math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))
    lev = cbn(roll, pitch, 0.0) @ (mag * 1e-3)
    expected = math.degrees(math.atan2(-lev[1], lev[0])) + b.declination
    assert abs(wrap_deg(expected - b.yaw)) < 0.3
    svc = Service(tmp_path, "--lat", str(b.lat), "--lon", "151.2", "--alt", str(b.h), "--heading", "mag",
                  "--declination", str(b.declination), "--align", "1")
    mav = svc.mav()
    for k in range(201):
        mav.raw_imu_send(1_000_000 + 10_000 * k, *acc, 0, 0, 0, *mag)
    res = svc.stop()
    lines = navigating_lines(res.log)
    assert len(lines) == 1 and lines[0].endswith("from magnetometer"), res.log
    assert f"heading {expected:.2f} deg" in lines[0], (lines[0], expected)
    assert abs(wrap_deg(res.nav[0, 9] - expected)) <= 1e-6, (
        f"first solution yaw {res.nav[0, 9]:.5f} deg, aligned at {expected:.5f} (magnetic "
        f"{expected - b.declination:.5f} + declination {b.declination}): moved towards the magnetic heading")
    assert abs(res.nav[0, 7] - math.degrees(roll)) <= 1e-6 and abs(res.nav[0, 8] - math.degrees(pitch)) <= 1e-6


# --- --heading gyrocompass --------------------------------------------------------------------------
GYRO_BOARD = Board(lat=50.0, h=200.0, roll=3.0, pitch=2.0, yaw=120.0)


def test_gyrocompass_heading_and_earth_rate(tmp_path: Path) -> None:
    """--heading gyrocompass: ideal (noise-free, bias-free) gyros at rest read C_n^b w_ie^n; the
    heading they give is the typed 120 deg. Then 20 s of rest: the kernel's Earth rate must cancel
    what the gyros read (the wrong sign would turn the yaw by 2 Omega sin L t = 0.13 deg and tilt
    the level by 2 Omega cos L t = 0.11 deg). No bias is estimated with this source (the Earth rate
    is the measurement), and none is announced."""
    b = GYRO_BOARD
    svc = Service(tmp_path, "--lat", str(b.lat), "--lon", "10", "--alt", str(b.h), "--heading", "gyrocompass",
                  "--align", "2")
    send_rest(svc.mav(), b, 1_000_000, 22.0)
    res = svc.stop()
    lines = navigating_lines(res.log)
    assert len(lines) == 1 and lines[0].endswith("deg from gyrocompass") and "heading 120.00 deg" in lines[0], \
        res.log
    assert "gyro bias estimated" not in res.log
    assert_attitude(res.nav, b.roll, b.pitch, b.yaw)
    assert res.nav[-1, 0] - res.nav[0, 0] > 19.0


# --- --heading auto ------------------------------------------------------------------------------
def test_auto_heading_prefers_vehicle_then_mag_then_gyrocompass(tmp_path: Path) -> None:
    """--heading auto in one service, re-aligned twice by sensor time jumping back (an autopilot
    restart). The three sources are made to disagree so that the yaw says which one was used:
    the gyros' Earth rate says 120 deg, the magnetometer 70 deg (declination 0), the vehicle's
    ATTITUDE -30 deg.

    1. gyros only, no magnetometer bits, no ATTITUDE: gyrocompass, 120;
    2. the magnetometer appears: magnetometer, 70;
    3. an ATTITUDE of the vehicle arrives: vehicle, -30.
    """
    lat, h = 50.0, 200.0
    gyro_only = Board(lat=lat, h=h, roll=3.0, pitch=2.0, yaw=120.0)
    with_mag = Board(lat=lat, h=h, roll=3.0, pitch=2.0, yaw=120.0, mag_heading=70.0)  # the magnetometer says 70
    # --grade navigation: gyros good enough to gyrocompass (with consumer ones, and GNSS aiding, auto waits
    # for the heading from GNSS velocity instead: tests/live/test_heading_from_gnss.py)
    svc = Service(tmp_path, "--lat", str(lat), "--lon", "10", "--alt", str(h), "--align", "1", "--declination", "0",
                  "--grade", "navigation")
    mav = svc.mav()
    send_rest(mav, gyro_only, 300_000_000, 2.0)
    send_rest(mav, with_mag, 200_000_000, 2.0)
    mav.attitude_send(99_000, math.radians(3.0), math.radians(2.0), math.radians(-30.0), 0.0, 0.0, 0.0)
    send_rest(mav, with_mag, 100_000_000, 2.0)
    res = svc.stop()
    lines = navigating_lines(res.log)
    assert len(lines) == 3, res.log
    assert lines[0].endswith("from gyrocompass") and "heading 120.00 deg" in lines[0], lines
    assert lines[1].endswith("from magnetometer") and "heading 70.00 deg" in lines[1], lines
    assert lines[2].endswith("from vehicle ATTITUDE") and "heading -30.00 deg" in lines[2], lines
    assert res.counters.get("restarts") == "2", res.counters
    nav = res.nav
    for t_lo, yaw in ((300.0, 120.0), (200.0, 70.0), (100.0, -30.0)):
        rows = nav[(nav[:, 0] > t_lo) & (nav[:, 0] < t_lo + 3.0)]
        assert len(rows) > 10
        # the vehicle's ATTITUDE is float32 (6e-8 relative of 0.52 rad: 2e-6 deg); the others as above
        assert_attitude(rows[:1], 3.0, 2.0, yaw)

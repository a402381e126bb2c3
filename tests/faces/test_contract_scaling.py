"""Input units of ``mavins run``: RAW_IMU and SCALED_IMU scaling, the scale, range and source
options, and instantaneous (sampled) rates, each on a motion where a 1 % error shows.

Every run is the real service (a subprocess listening on 127.0.0.1) fed over UDP
by the test; the solution is read from its ``-o`` file (full precision).

The motion (closed form, typed here): on the equator, level, nose north
(``--heading 0``), aligned at rest over 2 s, then

* phase A, (4 s, 14 s]: a forward specific force of 510 mG: v_N(14 s) =
  510 x 9.80665e-3 m/s^2 x 10 s = 50.01 m/s (a 1 % scale error: 0.5 m/s);
* phase B, (16 s, 26 s]: a yaw rate of 500 mrad/s: the yaw turns by exactly
  5 rad = 286.48 deg (a 1 % scale error: 2.86 deg).

mG is a thousandth of standard gravity, g_n = 9.80665 m/s^2 (CGPM 1901; what
ArduPilot's RAW_IMU and every SCALED_IMU use), mrad/s a thousandth of rad/s
(docs/conventions.md "MAVLink": int16 mG and mrad/s). The counts are chosen
whole so that the integer fields carry the motion exactly.

What the closed form leaves out, and so the tolerances (derived in
``V_TOL`` and ``YAW_TOL_DEG``): int16 rates cannot carry the Earth rate
(0.073 mrad/s) nor the transport rate, so the solution's frame turns against
the truth's by Omega t about north (roll; it feeds gravity into the east, not
the north) and by the transport rate v/R about east while moving north, which
tilts the forward axis and feeds gravity into the north speed:
``g a T^3/(6 R)`` = 1.3e-3 m/s over phase A. The yaw is the rotation about the
vertical, where the Earth rate has no component at the equator and the
transport rate none for northward motion; only the square of the tilts
(Omega t + v t/R ~ 2e-3 rad) reaches it: 4e-6 rad.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")

from support import RunResult as Result, ServiceProcess, wrap_deg  # noqa: E402

G_N = 9.80665  # standard gravity (m/s^2): 1 mG = G_N / 1000
MG = G_N / 1000.0
MRAD = 1e-3
A = 6378137.0
OMEGA = 7.292115e-5
GAMMA_E = 9.7803253359  # normal gravity on the equator (TR8350.2)

RATE = 100.0
T0_US = 1_000_000
END_US = 27_000_000
ACC_COUNTS, GYRO_COUNTS = 510, 500
ACC_US = (4_000_000, 14_000_000)
GYRO_US = (16_000_000, 26_000_000)
V_EXPECTED = ACC_COUNTS * MG * (ACC_US[1] - ACC_US[0]) * 1e-6  # 50.0139 m/s
YAW_TURN = GYRO_COUNTS * MRAD * (GYRO_US[1] - GYRO_US[0]) * 1e-6  # 5 rad
_T_A = (ACC_US[1] - ACC_US[0]) * 1e-6
V_TOL = 2 * GAMMA_E * (ACC_COUNTS * MG) * _T_A**3 / (6 * A) + 1e-4  # twice the transport-tilt leak, + 0.1 mm/s
YAW_TOL_DEG = 1e-3  # 4e-6 rad second-order tilt (2.3e-4 deg), rounded up


Service = ServiceProcess  # support.py: `mavins run` fed over UDP


def counts_at(usec: int, scale: int = 1) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
    """(acc, gyro) counts of the sample ending at ``usec`` (averages over its 10 ms interval; the
    phases start and end on sample instants, so every count is whole)."""
    ax = ACC_COUNTS * scale if ACC_US[0] < usec <= ACC_US[1] else 0
    gz = GYRO_COUNTS * scale if GYRO_US[0] < usec <= GYRO_US[1] else 0
    return (ax, 0, -round(GAMMA_E / MG * scale)), (0, 0, gz)


BASE_OPTS = ("--lat", "0", "--lon", "0", "--alt", "0", "--heading", "0", "--align", "2", "--gyro-bias", "none")


def check_motion(res: Result, n_samples: int) -> None:
    """The solution against the closed form: v_N at the end of phase A, yaw at the end."""
    nav = res.nav
    assert res.counters["final state"] == "NAVIGATING", res.log
    assert int(res.counters["imu_accepted"]) == n_samples, res.counters
    # the first output set at or after the end of phase A (one 20 ms update later at most: the
    # transport-tilt leak grows by g v (T_A) / R x 0.02 s ~ 1.5e-6 m/s over it)
    at = np.flatnonzero(nav[:, 0] >= ACC_US[1] * 1e-6 - 1e-9)
    assert len(at) and nav[at[0], 0] <= ACC_US[1] * 1e-6 + 0.02 + 1e-9, "an output set at the end of phase A"
    vn = nav[at[0], 4]
    yaw = nav[-1, 9]
    assert END_US * 1e-6 - 0.02 - 1e-9 <= nav[-1, 0] <= END_US * 1e-6 + 1e-9
    print(f"\nv_N {vn:.6f} m/s (closed form {V_EXPECTED:.6f}, tol {V_TOL:.1e}); yaw {yaw:.5f} deg "
          f"(closed form {wrap_deg(math.degrees(YAW_TURN)):.5f})")
    assert vn == pytest.approx(V_EXPECTED, abs=V_TOL)
    assert abs(wrap_deg(yaw - math.degrees(YAW_TURN))) <= YAW_TOL_DEG


def test_raw_imu_default_scales_mg_and_mrad_s(tmp_path: Path) -> None:
    """RAW_IMU with the default scales (ArduPilot's 1 mG, 1 mrad/s per count). A scale 1 % off moves
    v_N by 0.5 m/s (190 x V_TOL) or the yaw by 2.86 deg (2860 x YAW_TOL_DEG)."""
    svc = Service(tmp_path, *BASE_OPTS)
    mav = svc.mav()
    n = 0
    for usec in range(T0_US, END_US + 1, 10_000):
        acc, gyr = counts_at(usec)
        mav.raw_imu_send(usec, *acc, *gyr, 0, 0, 0)
        n += 1
    check_motion(svc.stop(), n)


def test_scaled_imu_fixed_scales_mg_and_mrad_s(tmp_path: Path) -> None:
    """SCALED_IMU (time_boot_ms; always mG and mrad/s, no option): the same motion, the same closed form."""
    svc = Service(tmp_path, *BASE_OPTS)
    mav = svc.mav()
    n = 0
    for usec in range(T0_US, END_US + 1, 10_000):
        acc, gyr = counts_at(usec)
        mav.scaled_imu_send(usec // 1000, *acc, *gyr, 0, 0, 0)
        n += 1
    check_motion(svc.stop(), n)


def test_raw_scale_range_and_source_options(tmp_path: Path) -> None:
    """--raw-acc-scale 4.903325e-3 (0.5 mG) and --raw-gyro-scale 5e-4 with doubled counts: the same
    physical motion, so the same closed form (a scale option ignored: 100 % off). In the same run:

    * --target-system 1: a system 9 sends RAW_IMU first (so without the option the service would
      lock onto it) and then one in every 100 samples, all with 3000-count rates: every one is
      rejected and counted (``rejected_other_system``), none reaches the solution;
    * --max-accel 12 (m/s^2) and --max-gyro 40 (deg/s): four samples from system 1 between the
      regular ones, two with 12.5 m/s^2 on one axis and two with 0.75 rad/s = 43.0 deg/s, are
      rejected and counted (``rejected_out_of_range`` = 4), while the regular ones (9.78 m/s^2 of
      gravity, 0.5 rad/s = 28.6 deg/s) are all accepted. A range read in the wrong unit accepts the
      spikes (not counted, and integrated) or rejects the regular samples (no navigation).
    """
    svc = Service(tmp_path, *BASE_OPTS, "--raw-acc-scale", "4.903325e-3", "--raw-gyro-scale", "5e-4",
                  "--target-system", "1", "--max-accel", "12", "--max-gyro", "40")
    mav, other = svc.mav(1), svc.mav(9)
    spikes = {8_000_000: ((2549, 0, -1995), (0, 0, 0)), 10_000_000: ((0, -2549, -1995), (0, 0, 0)),
              20_000_000: ((0, 0, -1995), (0, 0, 1500)), 22_000_000: ((0, 0, -1995), (-1500, 0, 0))}
    assert 2549 * 4.903325e-3 > 12.0 > GAMMA_E and 1500 * 5e-4 > math.radians(40) > 1000 * 5e-4
    other.raw_imu_send(T0_US - 500_000, 3000, 0, -1995, 0, 0, 3000, 0, 0, 0)
    n, n_other = 0, 1
    for k, usec in enumerate(range(T0_US, END_US + 1, 10_000)):
        acc, gyr = counts_at(usec, scale=2)
        mav.raw_imu_send(usec, *acc, *gyr, 0, 0, 0)
        n += 1
        if k % 100 == 50:
            other.raw_imu_send(usec + 3000, 3000, 0, -1995, 0, 0, 3000, 0, 0, 0)
            n_other += 1
        if usec in spikes:
            mav.raw_imu_send(usec + 5000, *spikes[usec][0], *spikes[usec][1], 0, 0, 0)
    res = svc.stop()
    assert int(res.counters.get("rejected_other_system", 0)) == n_other, res.counters
    assert int(res.counters.get("rejected_out_of_range", 0)) == len(spikes), res.counters
    check_motion(res, n)


def test_sampled_rates_ramp_integrates_exactly(tmp_path: Path) -> None:
    """--imu-rates sampled: HIGHRES_IMU carrying instantaneous rates of a yaw-rate ramp
    w_z = k (t - 4 s), k = 0.2 rad/s^2, for 5 s. Rates linear between samples make the trapezoid
    exact: yaw(t) = 20 deg + k (t - 4)^2/2, 2.5 rad at 9 s. Reading the same samples as interval
    averages would add w(t) h/2 (5e-3 rad = 0.29 deg at the end). The gyros also carry the Earth
    rate C_n^b w_ie^n of the turning body ([Omega cos psi, -Omega sin psi, .] on the equator), so
    the truth is exactly this yaw. Tolerance: the float32 rounding of every rate sent, summed times
    its interval (worst case, ~2e-7 rad), plus 1e-7 rad of interpolating the Earth-rate components
    (their second derivative Omega w^2 over 10 ms intervals)."""
    svc = Service(tmp_path, "--lat", "0", "--lon", "0", "--alt", "0", "--heading", "20", "--align", "2",
                  "--imu-rates", "sampled")
    mav = svc.mav()
    k_ramp, t_r, t_end = 0.2, 4.0, 9.0
    psi0 = math.radians(20.0)
    rounding = 0.0
    f = (0.0, 0.0, -GAMMA_E)
    for usec in range(T0_US, int(t_end * 1e6) + 1, 10_000):
        t = usec * 1e-6
        tau = max(0.0, t - t_r)
        wz = k_ramp * tau
        psi = psi0 + k_ramp * tau * tau / 2
        w = (OMEGA * math.cos(psi), -OMEGA * math.sin(psi), wz)
        rounding += float(np.sum(np.abs(np.asarray(w, np.float32).astype(float) - w))) * 0.01
        mav.highres_imu_send(usec, *f, *w, 0, 0, 0, 0, 0, 0, 0, 0b111111, 0)
    res = svc.stop()
    nav = res.nav
    assert res.counters["final state"] == "NAVIGATING"
    assert t_end - 0.02 - 1e-9 <= nav[-1, 0] <= t_end + 1e-9  # the last update, at most one short of the end
    tn = nav[:, 0]
    tau = np.clip(tn - t_r, 0.0, None)
    expected = np.degrees(psi0 + k_ramp * tau * tau / 2)
    tol = math.degrees(rounding + 1e-7)
    err = np.abs(wrap_deg(nav[:, 9] - expected))
    print(f"\nramp: final yaw {nav[-1, 9]:.6f} deg, closed form {expected[-1]:.6f} deg, max error {err.max():.2e} "
          f"deg (tol {tol:.1e}; averaged reading would be off by {math.degrees(k_ramp * 5 * 0.01 / 2):.3f} deg)")
    assert np.all(err <= tol)
    assert math.degrees(k_ramp * (t_end - t_r) * 0.01 / 2) > 100 * tol

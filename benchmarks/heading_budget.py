"""How well the data of the filter benchmark can determine heading: a linear covariance analysis.

The covariance of the error-state filter (errmodel.system_matrix,
errmodel.discretise, kalman.update) propagated along the *true* trajectory of
bench_filter.py's flight (F, and so the linearisation, at the truth, at every
attitude update of 0.02 s) with the measurements of that benchmark, without
any data: what the first-order model says the measurements can tell about
heading, whatever the estimate. Printed: the RMS of the heading 1-sigma
after the first 60 s and the heading and z-gyro-bias 1-sigma at a few times,
for the IMU as simulated and for what-if cases (a figure left out of the
filter's model and of the truth together). Covariance only: no data are
generated, no filter runs closed loop.

Set-ups:

* ``mc``: bench_filter.py's Monte Carlo and tests/core/test_aided_filter.py (a
  ZUPT at every attitude update in the first 10 s at rest and a zero-rate
  update at its end, then 1 Hz GNSS position 1 m / 1.5 m and velocity
  0.1 m/s);
* ``mc`` with the simulator's magnetometer (10 or 50 Hz) added: what the
  tilt-heading coupling of its measurement leaves;
* ``h2h``: the head-to-head with pyins (10 Hz ZUPTs in the rest window, no
  zero-rate update). ``--pyins`` adds pyins's own error model
  (python-ins 1.0.1 ``InsErrorModel``, the modified phi-angle model, with
  the sensor models bench_filter.py gives it) on the same path, 0.1 s steps:
  the two models are the same filter to first order, and this shows it.

Run from the repository root::

    .venv/bin/python benchmarks/heading_budget.py            # a few seconds
    .venv/bin/python benchmarks/heading_budget.py --pyins    # plus about 40 s
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
for _p in (str(HERE), str(HERE.parent)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

import bench_filter as bf
from sim.aiding import MagConfig

from mavins.core import earth
from mavins.core import errmodel as em
from mavins.core import kalman as kf
from mavins.core import strapdown as sd
from mavins.core.rotation import quat_to_dcm, skew

TIMES = (35.0, 42.0, 46.0, 60.0, 70.0, 76.0, 90.0, 110.0)
CASES: tuple[tuple[str, dict[str, float], float], ...] = (
    # (label, ImuSpec fields replaced, GNSS velocity sigma m/s)
    ("as simulated (consumer grade)", {}, 0.1),
    ("accelerometer biases known", {"accel_bias": 1e-9, "accel_gm": 0.0, "accel_rrw": 0.0}, 0.1),
    ("no gyro bias instability", {"gyro_gm": 0.0}, 0.1),
    ("ideal gyros after the rest (no instability, ARW, RRW)", {"gyro_gm": 0.0, "gyro_arw": 1e-9, "gyro_rrw": 0.0}, 0.1),
    ("GNSS velocity 0.01 m/s", {}, 0.01),
    ("ideal gyros and accelerometer biases known",
     {"gyro_gm": 0.0, "gyro_arw": 1e-9, "gyro_rrw": 0.0, "accel_bias": 1e-9, "accel_gm": 0.0, "accel_rrw": 0.0}, 0.1),
)
MAG_CASES: tuple[tuple[str, dict[str, float], float], ...] = (
    # (label, ImuSpec fields replaced, magnetometer rate Hz)
    ("as simulated, magnetometer 10 Hz", {}, 10.0),
    ("as simulated, magnetometer 50 Hz", {}, 50.0),
    ("accelerometer biases known, magnetometer 10 Hz", {"accel_bias": 1e-9, "accel_gm": 0.0, "accel_rrw": 0.0}, 10.0),
)


def budget(spec: em.ImuSpec, setup: str, sigma_vel: float, mag_rate: float = 0.0) -> np.ndarray:
    """Rows ``t, heading 1-sigma (deg), z gyro bias 1-sigma (deg/s)`` at every attitude update.

    ``mag_rate`` > 0 adds the simulator's magnetometer (sim.aiding.MagConfig:
    0.3 uT per axis in a 48 uT field at 63 deg inclination) from 1 s on at
    that rate, as kalman.mag_heading with the heading noise sigma / H.
    """
    t = bf.taf()
    ex = bf.trajectory().exact
    truth = ex.truth
    sp = spec.as_array()
    s = t.INIT_SIGMA
    P = kf.initial_covariance(sp, s["sigma_pos"], s["sigma_vel"], math.radians(s["sigma_level"]),
                              math.radians(s["sigma_yaw"]), 50.0, 0.0)
    rest_end = t.STATIC[0][1]
    g = t.GNSS
    r_pos = np.diag([g.sigma_h ** 2, g.sigma_h ** 2, g.sigma_v ** 2])
    h_pos = np.zeros((3, em.NX))
    h_pos[:, em.X_DP:em.X_DP + 3] = np.eye(3)
    h_vel = np.zeros((3, em.NX))
    h_vel[:, em.X_DV:em.X_DV + 3] = np.eye(3)
    zero3 = np.zeros(3)
    mag = MagConfig()
    sig_mag = mag.sigma / (mag.strength * math.cos(math.radians(mag.inclination)))
    r_mag = np.array([[sig_mag ** 2]])
    out = []
    for k in range(1, ex.t.size // 2 + 1):
        i = 2 * k  # truth row after samples 2k-1 and 2k
        tk = truth[i, 0]
        c = quat_to_dcm(truth[i, 10:14])
        f_n = c @ (ex.dv[i - 2] + ex.dv[i - 1]) / (ex.t[i - 1] - ex.t[i - 3] if i >= 3 else 0.02)
        lat, h = math.radians(truth[i, 1]), truth[i, 3]
        F = em.system_matrix(c, truth[i, 4:7].copy(), lat, h, f_n, sp, True)
        phi, qd = em.discretise(F, sp, 0.02)
        kf.predict(P, phi, qd)
        x = np.zeros(em.NX)
        in_rest = tk <= rest_end + 1e-9
        if in_rest and (setup == "mc" or abs(tk * bf.ZUPT_RATE - round(tk * bf.ZUPT_RATE)) < 1e-6):
            kf.update(x, P, h_vel, zero3, np.eye(3) * bf.ZUPT_SIGMA ** 2, 0.0, kf.ALL)
        if setup == "mc" and abs(tk - rest_end) < 1e-6:
            # the zero-rate update at the end of the rest window (kalman.zaru, aided.run_aided's variance)
            h_z = np.zeros((3, em.NX))
            h_z[:, em.X_BG:em.X_BG + 3] = np.eye(3)
            h_z[:, em.X_GG:em.X_GG + 3] = np.eye(3)
            h_z[:, em.X_PHI:em.X_PHI + 3] = c.T @ skew(earth.earth_rate_n(lat))
            walk = sp[em.SP_GYRO_RRW] ** 2 + 2.0 * sp[em.SP_GYRO_GM] ** 2 / sp[em.SP_GYRO_TAU]
            var = sp[em.SP_GYRO_ARW] ** 2 / rest_end + walk * rest_end / 3.0
            kf.update(x, P, h_z, zero3, np.eye(3) * var, 0.0, kf.ALL)
        if tk >= 1.0 - 1e-9 and abs(tk * g.rate - round(tk * g.rate)) < 1e-6:
            kf.update(x, P, h_pos, zero3, r_pos, 0.0, kf.ALL)
            kf.update(x, P, h_vel, zero3, np.eye(3) * sigma_vel ** 2, 0.0, kf.ALL)
        if mag_rate > 0.0 and tk >= 1.0 - 1e-9 and abs(tk * mag_rate - round(tk * mag_rate)) < 1e-6:
            f_n = mag.field_n()
            s_nav = np.zeros(sd.S.C + 9)  # mag_heading reads the attitude only
            s_nav[sd.S.C:sd.S.C + 9] = c.ravel()
            _, h_mag, _ = kf.mag_heading(s_nav, f_n, math.radians(mag.declination),
                                         math.tan(math.radians(mag.inclination)), math.hypot(f_n[0], f_n[1]), sig_mag)
            kf.update(x, P, h_mag, np.zeros(1), r_mag, 0.0, kf.ALL)
        bz = P[em.X_BG + 2, em.X_BG + 2] + P[em.X_GG + 2, em.X_GG + 2] + 2.0 * P[em.X_BG + 2, em.X_GG + 2]
        out.append((tk, math.degrees(math.sqrt(P[em.X_PHI + 2, em.X_PHI + 2])), math.degrees(math.sqrt(bz))))
    return np.array(out)


def budget_pyins() -> np.ndarray:
    """The h2h set-up with pyins's InsErrorModel and its filter's matrices, 0.1 s steps (its default)."""
    import pandas as pd
    from pyins import filters, kalman
    from pyins.error_model import InsErrorModel

    t = bf.taf()
    ex = bf.trajectory().exact
    truth = ex.truth
    gyro, accel = bf.pyins_models()
    model = InsErrorModel(True)
    cols = ["lat", "lon", "alt", "VN", "VE", "VD", "roll", "pitch", "heading"]

    def pva(i: int) -> Any:
        return pd.Series(truth[i, 1:10], index=cols)

    s = t.INIT_SIGMA
    P = filters._initialize_covariance(pva(0), s["sigma_pos"], s["sigma_vel"], s["sigma_level"], s["sigma_yaw"],
                                       model, gyro, accel)
    g = t.GNSS
    step = 10  # samples per 0.1 s
    out = []
    for i0 in range(0, ex.t.size, step):
        i1 = i0 + step
        dt = ex.t[i1 - 1] - (ex.t[i0 - 1] if i0 > 0 else truth[0, 0])
        phi, qd = filters._compute_error_propagation_matrices(
            pva((i0 + i1) // 2), ex.dtheta[i0:i1].sum(0) / dt, ex.dv[i0:i1].sum(0) / dt, dt, model, gyro, accel)
        P = phi @ P @ phi.T + qd
        tk = truth[i1, 0]
        p = pva(i1)
        x = np.zeros(len(P))
        h = np.zeros((3, len(P)))
        if tk <= t.STATIC[0][1] + 1e-9:
            h[:, :9] = model.ned_velocity_error_jacobian(p)
            x, P, _ = kalman.correct(x, P, np.zeros(3), h, np.eye(3) * bf.ZUPT_SIGMA ** 2)
        if tk >= 1.0 - 1e-9 and abs(tk * g.rate - round(tk * g.rate)) < 1e-6:
            h[:, :9] = model.position_error_jacobian(p)
            x, P, _ = kalman.correct(x, P, np.zeros(3), h, np.diag([g.sigma_h ** 2, g.sigma_h ** 2, g.sigma_v ** 2]))
            h[:, :9] = model.ned_velocity_error_jacobian(p)
            x, P, _ = kalman.correct(x, P, np.zeros(3), h, np.eye(3) * g.sigma_vel ** 2)
        tm = model.transform_to_output(p)
        out.append((tk, math.sqrt((tm @ P[:9, :9] @ tm.T)[8, 8]), math.degrees(math.sqrt(P[11, 11]))))
    return np.array(out)


def summary(label: str, rows: np.ndarray) -> str:
    late = rows[:, 0] >= bf.SETTLE_S
    at = ", ".join(f"{T:g} s {rows[np.searchsorted(rows[:, 0], T), 1]:.3f}/{rows[np.searchsorted(rows[:, 0], T), 2]:.4f}"
                   for T in TIMES)
    return f"{label}: {math.sqrt(np.mean(rows[late, 1] ** 2)):.3f} deg  | heading deg / z gyro bias deg/s at {at}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pyins", action="store_true", help="also pyins's error model on the head-to-head set-up")
    args = p.parse_args()
    base = em.spec_from_grade("consumer")
    print(f"RMS of the heading 1-sigma after {bf.SETTLE_S:.0f} s (linear covariance along the true trajectory)")
    print("set-up mc (rest window with ZUPT and ZARU, as the Monte Carlo and the tests):")
    for label, repl, sv in CASES:
        print("  " + summary(label, budget(dataclasses.replace(base, **repl), "mc", sv)))
    print("set-up mc with the simulator's magnetometer (GNSS velocity 0.1 m/s):")
    for label, repl, rate in MAG_CASES:
        print("  " + summary(label, budget(dataclasses.replace(base, **repl), "mc", 0.1, rate)))
    print("set-up h2h (10 Hz ZUPT at rest, no ZARU, as the pyins comparison):")
    print("  " + summary("mavins's model (phi-angle)", budget(base, "h2h", 0.1)))
    if args.pyins:
        print("  " + summary("pyins's model (modified phi-angle)", budget_pyins()))


if __name__ == "__main__":
    main()

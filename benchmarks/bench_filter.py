"""The error-state filter: against pyins on the same data, its cost per IMU sample, its consistency.

Three parts, one run (Issue "Aided navigation", "Done when"; issue "Performance",
the filter's cost per IMU sample):

1. **pyins side by side.** The simulator's flight (take-off, hover, four legs
   at 10 m/s with coordinated turns, its random vibration off), 120 s at
   100 Hz, consumer grade with the errors the 15-state model holds (the set-up
   of tests/core/test_aided_filter.py, whose helpers are imported), 1 Hz GNSS with
   1 m horizontal noise. mavins (``navigate_aided``) and pyins
   (``filters.run_feedback_filter`` of python-ins) get the same IMU
   increments, the same perturbed initial state and initial sigmas, the same
   GNSS position and velocity fixes and the same zero-velocity updates during
   the first 10 s at rest (10 Hz, 0.01 m/s); pyins's sensor model is the
   grade's figures in its terms (below). Printed per filter: horizontal and
   vertical position RMS and roll/pitch/heading RMS after the first 60 s
   (pooled over ``--compare-runs`` seeds), seconds per IMU sample (warm), and
   the targets with PASS/MISS: mavins at least as accurate, at least 5x
   faster per IMU sample. A third column is mavins with the rest window as
   the tests use it (ZUPT at every attitude update and a zero-rate update,
   which pyins's measurement interface cannot express: its H covers only the
   9 navigation states).
2. **Cost per IMU sample.** Batch (``navigate_aided``) at 100 Hz and at
   1 kHz; live: ``mavins.live.pipeline.Pipeline.handle`` fed MAVLink 2 HIGHRES_IMU
   frames at 1 kHz of sensor time with GPS_RAW_INT at 5 Hz (sim/stream.py,
   which builds them with mavins/link/mavlink.py), the filter on, with and
   without parsing the frames; the same figure as a share of one core at
   1 kHz input, against the service's CPU goal (10 % of a core at 1 kHz,
   docs/performance.md). Optionally the whole ``mavins run`` process at 1 kHz
   (benchmarks/bench_latency.cpu_run: a static IMU over UDP, filter on).
   Compile times are separate rows: a fresh interpreter with an empty numba
   cache, one with the cache, and pyins's first call (its numba functions
   are not cached).
3. **Consistency.** ``--runs`` (50) Monte Carlo runs of the set-up of
   tests/core/test_aided_filter.py: average NEES of position, velocity and
   attitude against the two-sided 95 % chi-square band for that many runs,
   bias NEES at the end, GNSS NIS, and the RMS of the normalised error of
   every one of the 15 contract states (target below 1.5); the runs go
   through mavins/common/parallel.py (``--jobs``).

pyins's sensor model: ``EstimationModel(bias_sd, noise, bias_walk)`` per
triad, a random-constant bias with random walk. The grade's bias is a
turn-on constant plus a first-order Gauss-Markov part plus a rate random
walk; pyins gets ``bias_sd = sqrt(turn_on^2 + sigma_gm^2)``, ``noise`` = the
ARW / VRW, and ``bias_walk = sqrt(K^2 + 2 sigma_gm^2 / tau)`` (the
Gauss-Markov driving noise; over spans short against tau = 50 s it is a
random walk). Its covariance is propagated every 0.1 s (its default
``time_step``); mavins propagates at every attitude update (0.02 s).

Run from the repository root::

    .venv/bin/python benchmarks/bench_filter.py            # full run
    .venv/bin/python benchmarks/bench_filter.py --quick    # a few minutes less: 1 pyins run, 10 MC runs

See benchmarks/README.md ("bench_filter") for what each row means.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(HERE), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

SEED0 = 1000  # seeds SEED0, SEED0 + 1, ...: the first 20 are those of tests/core/test_aided_filter.py
SETTLE_S = 60.0  # accuracy after the first 60 s
REST = (0.0, 10.0)  # s: the flight's static start
ZUPT_RATE = 10.0  # Hz: zero-velocity updates given to both filters in the rest window
ZUPT_SIGMA = 0.01  # m/s (aided.DEFAULT_SIGMA_ZUPT)
SPEED_TARGET = 5.0  # mavins at least 5x faster per IMU sample (issue)
LIVE_RATE = 1000.0  # Hz: the live path's input rate
LIVE_GNSS_RATE = 5.0  # Hz
LIVE_PREDICT_EVERY = 5  # attitude updates (2 samples each) per propagation: the live path's 10 ms at 1 kHz
LIVE_WARM_S = 2.0  # s of sensor time fed before timing (1 s alignment, kernel load)
CPU_BUDGET = 0.10  # share of one core at 1 kHz input (docs/performance.md, service CPU goal)
NORM_TARGET = 1.5  # RMS of each state's normalised error (issue)
STATE_NAMES = ("att_n", "att_e", "att_d", "vn", "ve", "vd", "pn", "pe", "pd",
               "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z")

#: Lines printed under the rows (the detailed tables); filled by main().
NOTES: list[str] = []
BASELINE = "pyins run_feedback_filter, same data, same run"

_TAF: Any = None
_TRAJ: Any = None


# --- shared set-up -----------------------------------------------------------------
def taf() -> Any:
    """tests/core/test_aided_filter.py as a module (its simulation and error helpers).

    Imported the way pytest imports it: its folder on the path, for the
    tests' own helpers (tests/support.py).
    """
    global _TAF
    if _TAF is None:
        path = ROOT / "tests" / "core" / "test_aided_filter.py"
        for folder in (path.parent, ROOT / "tests"):
            if str(folder) not in sys.path:
                sys.path.append(str(folder))
        spec = importlib.util.spec_from_file_location("_bench_test_aided_filter", path)
        mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
        sys.modules[spec.name] = mod  # type: ignore[union-attr]
        spec.loader.exec_module(mod)  # type: ignore[union-attr]
        _TAF = mod
    return _TAF


def trajectory() -> Any:
    """The tests' trajectory: the flight scenario without its vibration, ideal IMU, DURATION s at RATE Hz."""
    global _TRAJ
    if _TRAJ is None:
        from sim.generate import generate
        from sim.scenarios import Scenario, load

        t = taf()
        sc = load("flight")
        doc = {k: v for k, v in sc.doc.items() if k != "perturbations"}
        _TRAJ = generate(Scenario("flight_quiet", sc.source, doc), duration=t.DURATION, rate=t.RATE, seed=0,
                         grade="ideal")
    return _TRAJ


def load_avg() -> str:
    try:
        with open("/proc/loadavg", encoding="ascii") as fh:
            return " ".join(fh.read().split()[:3])
    except OSError:
        return "unknown"


def log(msg: str) -> None:
    print(f"[bench_filter] {msg}", file=sys.stderr, flush=True)


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """Plain text table; the first column left-aligned, the others right-aligned."""
    cells = [list(map(str, headers))] + [[("-" if c is None else str(c)) for c in r] for r in rows]
    w = [max(len(r[i]) for r in cells) for i in range(len(headers))]

    def line(r: list[str]) -> str:
        return "  ".join(c.ljust(w[i]) if i == 0 else c.rjust(w[i]) for i, c in enumerate(r)).rstrip()

    return [line(cells[0]), "  ".join("-" * x for x in w)] + [line(r) for r in cells[1:]]


# --- errors against the truth ----------------------------------------------------------
def nav_errors_euler(lat: np.ndarray, lon: np.ndarray, h: np.ndarray, rpy: np.ndarray,
                     truth: np.ndarray) -> np.ndarray:
    """(north, east, down) metres and (roll, pitch, heading) degrees, estimate minus truth.

    Estimate in radians and metres; truth rows in file units (degrees).
    North/east through the radii of the true position; angles wrapped.
    """
    from mavins.core import earth

    lat_t = np.radians(truth[:, 1])
    r_n, r_e = earth.radii(lat_t)
    ht = truth[:, 3]
    dn = (lat - lat_t) * (r_n + ht)
    de = (lon - np.radians(truth[:, 2])) * (r_e + ht) * np.cos(lat_t)
    dd = -(h - ht)
    da = (np.degrees(rpy) - truth[:, 7:10] + 180.0) % 360.0 - 180.0
    return np.column_stack([dn, de, dd, da])


def accuracy(err: np.ndarray, t: np.ndarray) -> dict[str, float]:
    """Sums of squares and count after SETTLE_S (pooled over runs by :func:`pooled`)."""
    late = t >= SETTLE_S
    e = err[late]
    return {"n": int(late.sum()), "h2": float(np.sum(e[:, 0] ** 2 + e[:, 1] ** 2)), "v2": float(np.sum(e[:, 2] ** 2)),
            "roll2": float(np.sum(e[:, 3] ** 2)), "pitch2": float(np.sum(e[:, 4] ** 2)),
            "yaw2": float(np.sum(e[:, 5] ** 2))}


def pooled(acc: list[dict[str, float]]) -> dict[str, float]:
    """RMS over every epoch after SETTLE_S of every run: horizontal, vertical (m), roll, pitch, heading (deg)."""
    n = sum(a["n"] for a in acc)
    return {k: math.sqrt(sum(a[k + "2"] for a in acc) / n) for k in ("h", "v", "roll", "pitch", "yaw")}


# --- part 1: mavins and pyins on the same data -------------------------------------------
def zupt_times() -> np.ndarray:
    """Zero-velocity update times inside the rest window (both filters)."""
    k = np.arange(1, round((REST[1] - REST[0]) * ZUPT_RATE))
    return REST[0] + k / ZUPT_RATE


def same_measurements_gnss(gnss: np.ndarray) -> np.ndarray:
    """GNSS rows for navigate_aided holding the fixes plus the zero-velocity updates (velocity-only rows)."""
    tz = zupt_times()
    z = np.full((tz.size, gnss.shape[1]), np.nan)
    z[:, 0] = tz
    z[:, 4:7] = 0.0
    z[:, 7] = gnss[0, 7]
    z[:, 8] = gnss[0, 8]
    z[:, 9] = ZUPT_SIGMA
    rows = np.vstack([z, gnss])
    return rows[np.argsort(rows[:, 0], kind="stable")]


def pyins_models() -> tuple[Any, Any]:
    """pyins EstimationModels (gyro, accel) with the consumer grade's figures (module docstring)."""
    from pyins import inertial_sensor

    from mavins.core import errmodel as em

    s = em.spec_from_grade("consumer")
    gyro = inertial_sensor.EstimationModel(
        bias_sd=math.hypot(s.gyro_bias, s.gyro_gm), noise=s.gyro_arw,
        bias_walk=math.sqrt(s.gyro_rrw ** 2 + 2.0 * s.gyro_gm ** 2 / s.gyro_tau))
    accel = inertial_sensor.EstimationModel(
        bias_sd=math.hypot(s.accel_bias, s.accel_gm), noise=s.accel_vrw,
        bias_walk=math.sqrt(s.accel_rrw ** 2 + 2.0 * s.accel_gm ** 2 / s.accel_tau))
    return gyro, accel


def pyins_inputs(imu: np.ndarray, gnss: np.ndarray, init: dict) -> tuple[Any, Any, list[Any]]:
    """pyins's initial Pva, IMU frame (increment type) and measurement objects for one run.

    The IMU frame has one row before the first increment (the first increment
    repeated: zero first coning term), as pyins's increment convention needs.
    """
    import pandas as pd
    from pyins import measurements

    t0 = float(init["t"])
    index = np.concatenate(([t0], imu[:, 0]))
    data = np.vstack([imu[:1, 1:7], imu[:, 1:7]])
    imu_df = pd.DataFrame(data, index=index, columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    pva = pd.Series([float(init[k]) for k in ("lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")],
                    index=["lat", "lon", "alt", "VN", "VE", "VD", "roll", "pitch", "heading"], name=t0)
    fix = gnss[np.isfinite(gnss[:, 1])]
    pos = measurements.Position(pd.DataFrame(fix[:, 1:4], index=fix[:, 0], columns=["lat", "lon", "alt"]), 1.0)
    pos.R = np.diag([fix[0, 7] ** 2, fix[0, 7] ** 2, fix[0, 8] ** 2])  # 1 m horizontal, 1.5 m vertical
    vel = measurements.NedVelocity(pd.DataFrame(fix[:, 4:7], index=fix[:, 0], columns=["VN", "VE", "VD"]),
                                   float(fix[0, 9]))
    tz = zupt_times()
    zupt = _zero_velocity_class()(pd.DataFrame(np.zeros((tz.size, 3)), index=tz, columns=["VN", "VE", "VD"]),
                                    ZUPT_SIGMA)
    return pva, imu_df, [pos, vel, zupt]


_ZV: Any = None


def _zero_velocity_class() -> Any:
    """pyins's NedVelocity under its own class name: pyins keys innovations by class name, and
    a second NedVelocity instance (GNSS velocity and zero velocity) breaks its result assembly."""
    global _ZV
    if _ZV is None:
        from pyins import measurements

        _ZV = type("ZeroVelocity", (measurements.NedVelocity,), {})
    return _ZV


def run_pyins(imu: np.ndarray, gnss: np.ndarray, init: dict) -> tuple[float, np.ndarray]:
    """pyins's filter on one run: (seconds of coning/sculling + run_feedback_filter, trajectory array).

    Trajectory columns lat, lon (deg), alt, VN, VE, VD, roll, pitch, heading (deg);
    row 0 is the initial state, row i the state after increment i.
    """
    from pyins import filters, strapdown

    pva, imu_df, meas = pyins_inputs(imu, gnss, init)
    gyro, accel = pyins_models()
    start = time.perf_counter()
    inc = strapdown.compute_increments_from_imu(imu_df, "increment")
    res = filters.run_feedback_filter(pva, init["sigma_pos"], init["sigma_vel"], init["sigma_level"],
                                      init["sigma_yaw"], inc, gyro, accel, meas)
    sec = time.perf_counter() - start
    return sec, res.trajectory.to_numpy(dtype=float)


def mavins_rows(imu: np.ndarray, gnss: np.ndarray, init: dict, static: Any, repeat: int) -> tuple[float, np.ndarray]:
    """Best-of-``repeat`` seconds of navigate_aided and its rows (kernel units)."""
    from mavins.core import aided

    best, rows = math.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        rows, _ = aided.navigate_aided(imu, init, gnss, static=static, spec="consumer", file_units=False)
        best = min(best, time.perf_counter() - start)
    return best, rows  # type: ignore[return-value]


def compare(runs: int, repeat: int, first: int = SEED0) -> dict[str, Any]:
    """Part 1: accuracy and seconds per IMU sample of mavins (two set-ups) and pyins, seeds first, first + 1, ...

    Also mavins's own heading 1-sigma (sigma_att_d) after SETTLE_S in the
    head-to-head set-up, pooled as an RMS: the filter's expectation of the
    heading RMS, against which its error shows whether it is consistent.
    """
    t = taf()
    traj = trajectory()
    truth = traj.exact.truth
    acc: dict[str, list] = {"mavins": [], "mavins_rest": [], "pyins": []}
    sec: dict[str, list] = {"mavins": [], "mavins_rest": [], "pyins": []}
    n_samples = 0
    sig2: list[float] = []  # mavins's sigma_att_d^2 after SETTLE_S, head-to-head set-up
    from pyins import filters  # noqa: F401  (import outside the timer)

    log("warming pyins (numba JIT of its integrator) and mavins (kernel load)")
    imu, gnss, init, _, _ = t.simulate_run(traj, SEED0)
    run_pyins(imu[:200], gnss[:1], init)
    mavins_rows(imu[:200], same_measurements_gnss(gnss[:1]), init, None, 1)
    mavins_rows(imu[:200], gnss[:1], init, t.STATIC, 1)
    for r in range(runs):
        seed = first + r
        imu, gnss, init, _, _ = t.simulate_run(traj, seed)
        n_samples = imu.shape[0]
        idx = 2 * (np.arange(n_samples // 2) + 1)  # output row k: after sample 2k+1 = truth row 2(k+1)
        for key, g, static in (("mavins", same_measurements_gnss(gnss), None), ("mavins_rest", gnss, t.STATIC)):
            s, rows = mavins_rows(imu, g, init, static, repeat)
            e = nav_errors_euler(rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 7:10], truth[idx[: rows.shape[0]]])
            acc[key].append(accuracy(e, rows[:, 0]))
            if key == "mavins":
                sig2.extend(np.degrees(rows[rows[:, 0] >= SETTLE_S, 22]) ** 2)
            sec[key].append(s)
        log(f"pyins run {r + 1}/{runs} (seed {seed}), load {load_avg()}")
        s, tr = run_pyins(imu, gnss, init)
        if tr.shape[0] != n_samples + 1:
            raise RuntimeError(f"pyins returned {tr.shape[0]} rows for {n_samples} increments")
        e = nav_errors_euler(np.radians(tr[:, 0]), np.radians(tr[:, 1]), tr[:, 2], np.radians(tr[:, 6:9]),
                             truth[: tr.shape[0]])
        acc["pyins"].append(accuracy(e, truth[: tr.shape[0], 0]))
        sec["pyins"].append(s)
        log(f"  seed {seed}: mavins {sec['mavins'][-1]:.3f} s, pyins {s:.1f} s")
    return {"acc": {k: pooled(v) for k, v in acc.items()}, "per_run": {k: [pooled([a]) for a in v] for k, v in acc.items()},
            "sec": sec, "n": n_samples, "runs": runs, "first": first,
            "sigma_yaw": math.sqrt(float(np.mean(sig2)))}


def compare_notes(c: dict[str, Any]) -> tuple[list[str], list[dict]]:
    """The side-by-side table and its rows for run_all."""
    a = c["acc"]
    n = c["n"]
    per = {k: min(v) / n for k, v in c["sec"].items()}
    med = {k: float(np.median(v)) / n for k, v in c["sec"].items()}
    rows, out = [], []
    for key, label, unit, fmt in (("h", "horizontal position RMS", "m", ".3f"), ("v", "vertical position RMS", "m", ".3f"),
                                  ("roll", "roll RMS", "deg", ".4f"), ("pitch", "pitch RMS", "deg", ".4f"),
                                  ("yaw", "heading RMS", "deg", ".3f")):
        m, p, mr = a["mavins"][key], a["pyins"][key], a["mavins_rest"][key]
        ok = m <= p
        rows.append([f"{label} after {SETTLE_S:.0f} s ({unit})", format(m, fmt), format(p, fmt), f"{m / p:.2f}",
                     "mavins <= pyins", "PASS" if ok else "MISS", format(mr, fmt)])
        out.append({"case": f"filter vs pyins: {label} (after {SETTLE_S:.0f} s)", "value": f"{m:{fmt}} {unit}",
                    "ratio": m / p, "baseline": f"pyins {p:{fmt}} {unit}",
                    "goal": f"<= pyins: {'PASS' if ok else 'MISS'}"})
    speed = per["pyins"] / per["mavins"]
    ok = speed >= SPEED_TARGET
    rows.append(["seconds per IMU sample, warm (best run)", f"{per['mavins'] * 1e6:.2f} us",
                 f"{per['pyins'] * 1e6:.0f} us", f"{speed:.0f}x faster", f">= {SPEED_TARGET:.0f}x faster",
                 "PASS" if ok else "MISS", f"{per['mavins_rest'] * 1e6:.2f} us"])
    rows.append(["seconds per IMU sample, warm (median run)", f"{med['mavins'] * 1e6:.2f} us",
                 f"{med['pyins'] * 1e6:.0f} us", f"{med['pyins'] / med['mavins']:.0f}x faster", "", "",
                 f"{med['mavins_rest'] * 1e6:.2f} us"])
    out.append({"case": "filter vs pyins: per IMU sample (navigate_aided, warm)", "samples": n,
                "seconds": min(c["sec"]["mavins"]), "rate": 1.0 / per["mavins"], "ratio": speed,
                "baseline": "pyins run_feedback_filter", "goal": f">= {SPEED_TARGET:.0f}x: {'PASS' if ok else 'MISS'}",
                "note": f"{per['mavins'] * 1e6:.2f} us vs {per['pyins'] * 1e6:.0f} us"})
    out.append({"case": "pyins run_feedback_filter (baseline)", "samples": n, "seconds": min(c["sec"]["pyins"]),
                "rate": 1.0 / per["pyins"], "ratio": 1.0, "baseline": "(is the baseline)"})
    lines = [(f"mavins against pyins, same data: flight 120 s at 100 Hz ({n:,} IMU samples), consumer grade, "
              f"1 Hz GNSS 1 m; {c['runs']} run(s), seeds {c['first']}..{c['first'] + c['runs'] - 1}, errors pooled over "
              f"every output after {SETTLE_S:.0f} s:")]
    lines += table(["quantity", "mavins", "pyins", "mavins/pyins", "target", "", "mavins, tests' rest set-up"], rows)
    lines.append("mavins and pyins: same increments, initial state, GNSS position+velocity and 10 Hz zero-velocity "
                 "updates at rest; last column: mavins with ZUPT at every update plus a zero-rate update at rest "
                 "(tests/core/test_aided_filter.py), which pyins's interface cannot take.")
    pr = c["per_run"]
    lines.append("per run (seed: mavins / pyins): horizontal RMS m "
                 + ", ".join(f"{c['first'] + i}: {m['h']:.3f}/{p['h']:.3f}" for i, (m, p) in enumerate(zip(pr["mavins"], pr["pyins"])))
                 + "; heading RMS deg "
                 + ", ".join(f"{c['first'] + i}: {m['yaw']:.3f}/{p['yaw']:.3f}"
                             for i, (m, p) in enumerate(zip(pr["mavins"], pr["pyins"]))))
    d = np.array([m["yaw"] - p["yaw"] for m, p in zip(pr["mavins"], pr["pyins"])])
    se = float(d.std(ddof=1) / math.sqrt(d.size)) if d.size > 1 else float("nan")
    lines.append(f"heading, per run: mavins minus pyins RMS {d.mean():+.3f} deg (standard error {se:.3f}), mavins "
                 f"better in {int(np.sum(d < 0))} of {d.size}; mavins's own heading 1-sigma after {SETTLE_S:.0f} s "
                 f"(RMS over the runs) {c['sigma_yaw']:.3f} deg against its error {a['mavins']['yaw']:.3f} deg")
    lines.append("seconds: mavins best of the repeats per run, then the best run; pyins one call per run, the best run "
                 "(coning/sculling + run_feedback_filter; building its DataFrames is outside the timer).")
    return lines, out


# --- part 2: cost per IMU sample, batch and live ---------------------------------------------
def batch_1khz(seconds: float, repeat: int) -> dict[str, float]:
    """navigate_aided on the consumer-grade flight at 1 kHz with 5 Hz GNSS: seconds per IMU sample."""
    from mavins.core import aided
    from sim import aiding
    from sim.generate import generate
    from sim.scenarios import load

    run = generate(load("flight"), duration=seconds, rate=LIVE_RATE, seed=3, grade="consumer")
    imu = np.column_stack([run.t, run.dtheta, run.dv])
    gnss = aiding.gnss(run, aiding.GnssConfig(rate=LIVE_GNSS_RATE))
    init = run.exact.init()
    aided.navigate_aided(imu[:100], init, gnss[:1], spec="consumer")
    out: dict[str, float] = {"n": imu.shape[0]}
    for every in (1, LIVE_PREDICT_EVERY):
        best = math.inf
        for _ in range(repeat):
            start = time.perf_counter()
            aided.navigate_aided(imu, init, gnss, spec="consumer", predict_every=every)
            best = min(best, time.perf_counter() - start)
        out[f"seconds_{every}"] = best
    return out


def live_frames(seconds: float) -> tuple[list[bytes], np.ndarray, dict, Any]:
    """MAVLink 2 frames of the consumer-grade flight at 1 kHz: HIGHRES_IMU and GPS_RAW_INT (5 Hz).

    Built by sim/stream.frames (mavins/link/mavlink.py's dialect), packed to
    bytes as a link delivers them. Returns (frames, sensor time of each frame,
    initial state, run).
    """
    from mavins.link.mavlink import mavlink
    from sim.generate import generate
    from sim.scenarios import load
    from sim.stream import StreamOptions, frames

    run = generate(load("flight"), duration=seconds, rate=LIVE_RATE, seed=5, grade="consumer", usec_grid=True)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    out, times = [], []
    keep = ("HIGHRES_IMU", "GPS_RAW_INT")
    for t, msgs in frames(run, mav, StreamOptions(gps_rate=LIVE_GNSS_RATE, speed=None)):
        for m in msgs:
            if m.get_type() in keep:
                out.append(bytes(m.pack(mav)))
                times.append(t)
    return out, np.asarray(times), run.exact.init(), run


def _pipeline(init: dict, aiding: tuple[str, ...]) -> Any:
    from mavins.live.livefilter import FilterSettings
    from mavins.live.engine import EngineConfig
    from mavins.live.pipeline import Pipeline

    cfg = EngineConfig(lat=init["lat"], lon=init["lon"], alt=init["h"], heading=float(init["yaw"]), align=1.0,
                       rate=50.0, filter=FilterSettings(spec="consumer", aiding=aiding))
    return Pipeline(cfg)


def _messages(frame: bytes, p: Any) -> list:
    """What UdpLink.receive makes of one datagram: decode_one's message, else pymavlink's parser ``p``."""
    from mavins.link.decode import decode_one

    one = decode_one(frame)
    return [one] if one is not None else p.parse_buffer(frame) or []


def live_cost(seconds: float, repeat: int) -> dict[str, Any]:
    """Seconds per IMU sample of Pipeline.handle at 1 kHz (filter on, GNSS 5 Hz), with and without parsing."""
    from mavins.link.mavlink import parser

    log(f"building {seconds:g} s of 1 kHz HIGHRES_IMU + 5 Hz GPS_RAW_INT frames")
    frames, times, init, run = live_frames(seconds)
    p = parser()
    msgs = []
    for b in frames:
        got = p.parse_buffer(b) or []
        if len(got) != 1:
            raise RuntimeError("a frame did not parse to one message")
        msgs.append(got[0])
    k0 = int(np.searchsorted(times, times[0] + LIVE_WARM_S))
    n_imu = sum(1 for m in msgs[k0:] if m.get_type() == "HIGHRES_IMU")
    res: dict[str, Any] = {"n": n_imu}
    for label, aiding in (("gnss", ("gnss",)), ("none", ())):
        best, pipe = math.inf, None
        for _ in range(repeat):
            pipe = _pipeline(init, aiding)
            handle = pipe.handle
            for m in msgs[:k0]:
                handle(m)
            last = None
            start = time.perf_counter()
            for m in msgs[k0:]:
                out = handle(m)
                if out is not None:
                    last = out
            best = min(best, time.perf_counter() - start)
        res[label] = best
        res[label + "_counters"] = dict(pipe.engine.filter.counters)  # type: ignore[union-attr]
        res[label + "_state"] = pipe.engine.state.value  # type: ignore[union-attr]
        if label == "gnss":
            res["final_error_m"] = _final_error(last.row, run)  # type: ignore[union-attr]
    # decode + handle (what the service does per datagram, without the socket: UdpLink.receive
    # decodes a one-frame datagram with decode_one, anything else with pymavlink's parser)
    best = math.inf
    for _ in range(repeat):
        pipe = _pipeline(init, ("gnss",))
        p = parser()
        for b in frames[:k0]:
            for m in _messages(b, p):
                pipe.handle(m)
        start = time.perf_counter()
        handle = pipe.handle
        for b in frames[k0:]:
            for m in _messages(b, p):
                out = handle(m)
                if out is not None:
                    last = out
        best = min(best, time.perf_counter() - start)
    res["parse"] = best
    return res


def _final_error(row: np.ndarray, run: Any) -> float:
    """Horizontal distance (m) of the last published solution row to the truth at its time."""
    from mavins.core import earth

    tr = run.exact.truth
    i = int(np.argmin(np.abs(tr[:, 0] - row[0])))
    lat_t = math.radians(tr[i, 1])
    r_n, r_e = earth.radii(lat_t)
    dn = (row[1] - lat_t) * (r_n + tr[i, 3])
    de = (row[2] - math.radians(tr[i, 2])) * (r_e + tr[i, 3]) * math.cos(lat_t)
    return math.hypot(dn, de)


def cost_notes(b100: dict, b1k: dict, live: dict, service: dict | None) -> tuple[list[str], list[dict]]:
    us100 = b100["seconds"] / b100["n"] * 1e6
    us1k = b1k["seconds_1"] / b1k["n"] * 1e6
    us1k5 = b1k[f"seconds_{LIVE_PREDICT_EVERY}"] / b1k["n"] * 1e6
    n = live["n"]
    us_live = live["gnss"] / n * 1e6
    us_none = live["none"] / n * 1e6
    us_parse = live["parse"] / n * 1e6
    share = us_parse * LIVE_RATE * 1e-6
    rows = [
        ["batch navigate_aided, 100 Hz, GNSS 1 Hz (the comparison's data)", f"{us100:.2f}",
         f"{us100 * LIVE_RATE / 1e4:.2f} %", ""],
        [f"batch navigate_aided, 1 kHz, GNSS 5 Hz, P every 2 ms (default, {b1k['n']:,} samples)", f"{us1k:.2f}",
         f"{us1k * LIVE_RATE / 1e4:.2f} %", ""],
        [f"batch navigate_aided, 1 kHz, GNSS 5 Hz, P every 10 ms (predict_every={LIVE_PREDICT_EVERY}, as live)",
         f"{us1k5:.2f}", f"{us1k5 * LIVE_RATE / 1e4:.2f} %", ""],
        ["live Pipeline.handle, 1 kHz, GNSS 5 Hz (decoded messages)", f"{us_live:.2f}",
         f"{us_live * LIVE_RATE / 1e4:.2f} %", ""],
        ["live Pipeline.handle, 1 kHz, --aiding none (propagation only)", f"{us_none:.2f}",
         f"{us_none * LIVE_RATE / 1e4:.2f} %", ""],
        ["live decode + Pipeline.handle, 1 kHz, GNSS 5 Hz (1 kHz budget row)", f"{us_parse:.2f}",
         f"{share * 100:.2f} %",
         f"<= {CPU_BUDGET * 100:.0f} % of a core: {'PASS' if share <= CPU_BUDGET else 'MISS'}"],
    ]
    if service is not None:
        pct = service["cpu_pct"]
        rows.append([f"whole `mavins run` process, 1 kHz UDP, static IMU, filter on ({service['window_s']:.0f} s)",
                     f"{pct * 10:.1f}", f"{pct:.1f} %",
                     f"<= {CPU_BUDGET * 100:.0f} % of a core: {'PASS' if pct <= CPU_BUDGET * 100 else 'MISS'}"])
        rows.append(["bare Python UDP receiver at 1 kHz (select, recvmsg, parse_buffer; baseline)",
                     f"{service['bare_pct'] * 10:.1f}", f"{service['bare_pct']:.1f} %", ""])
    lines = ["Filter cost per IMU sample (warm, best of the repeats; share of one core at 1,000 samples/s):"]
    lines += table(["path", "us per sample", "core at 1 kHz", "target"], rows)
    c = live["gnss_counters"]
    lines.append(f"live run: {n:,} timed samples after {LIVE_WARM_S:g} s (1 s alignment); GNSS fixes accepted "
                 f"{c.get('gnss_pos_accepted', 0)}, rejected {c.get('gnss_pos_rejected', 0)}; final horizontal "
                 f"error {live['final_error_m']:.2f} m; state {live['gnss_state']}. The budget row leaves out the "
                 "socket, publishing and recording; the whole-process row includes them.")
    out = [
        {"case": "filter cost: batch navigate_aided, 1 kHz", "samples": b1k["n"], "seconds": b1k["seconds_1"],
         "rate": b1k["n"] / b1k["seconds_1"], "note": f"{us1k:.2f} us per sample (P every 2 ms)"},
        {"case": "filter cost: live decode + Pipeline.handle, 1 kHz", "samples": n, "seconds": live["parse"],
         "rate": n / live["parse"], "value": f"{share * 100:.2f} % of a core",
         "goal": f"<= {CPU_BUDGET * 100:.0f} %: {'PASS' if share <= CPU_BUDGET else 'MISS'}",
         "note": f"{us_parse:.2f} us per sample"},
    ]
    return lines, out


#: (label, file suffix, function name) of the parts the live profile reports; suffix "~" is a compiled
#: function, found by a part of its name (the JIT's and the install-built module's names differ).
PROFILE_PARTS = (
    ("decode_one (per frame, as UdpLink.receive)", "mavins/link/decode.py", "decode_one"),
    ("Pipeline.handle", "mavins/live/pipeline.py", "handle"),
    ("  Ingest.sample (validation)", "mavins/link/ingest.py", "sample"),
    ("  Engine.on_imu", "mavins/live/engine.py", "on_imu"),
    ("    LiveFilter.push", "mavins/live/livefilter.py", "push"),
    ("      aided.push_rate_aided (compiled strapdown + filter)", "~", "push_rate_aided"),
    ("    LiveFilter._apply (GNSS updates)", "mavins/live/livefilter.py", "_apply"),
    ("    LiveFilter.uncertainty (per output)", "mavins/live/livefilter.py", "uncertainty"),
)


def profile_live(seconds: float) -> list[str]:
    """cProfile of the budget row's loop (decode + Pipeline.handle at 1 kHz, GNSS 5 Hz): inclusive share per part."""
    import cProfile
    import pstats

    from mavins.link.mavlink import parser

    frames, times, init, _ = live_frames(seconds)
    k0 = int(np.searchsorted(times, times[0] + LIVE_WARM_S))
    pipe = _pipeline(init, ("gnss",))
    p = parser()
    for b in frames[:k0]:
        for m in _messages(b, p):
            pipe.handle(m)
    prof = cProfile.Profile()
    prof.enable()
    for b in frames[k0:]:
        for m in _messages(b, p):
            pipe.handle(m)
    prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    total = sum(v[2] for v in stats.values())
    rows = []
    for label, suffix, name in PROFILE_PARTS:
        ct = sum(v[3] for (f, _, fn), v in stats.items()
                 if (name in fn if suffix == "~" else fn == name) and f.replace(os.sep, "/").endswith(suffix))
        rows.append([label, f"{100.0 * ct / total:.1f} %"])
    n = len(times) - k0
    lines = [(f"cProfile of the budget row's loop ({n:,} frames after {LIVE_WARM_S:g} s; inclusive share of the "
              f"loop, {1e6 * total / n:.1f} us per frame under the profiler):")]
    return lines + table(["part", "inclusive"], rows)


# --- compile times (fresh interpreters) -------------------------------------------------------
def _first_call(which: str) -> dict[str, float]:
    """In this (fresh) process: seconds to import and to run the filter once on a short rest record."""
    t0 = time.perf_counter()
    n = 200
    t = 0.01 * np.arange(1, n + 1)
    g = 9.80
    imu = np.column_stack([t, np.zeros((n, 3)), np.zeros((n, 2)), np.full(n, -g * 0.01)])
    init = {"t": 0.0, "lat": 47.4, "lon": 8.5, "h": 488.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0,
            "pitch": 0.0, "yaw": 0.0, "sigma_pos": 3.0, "sigma_vel": 0.3, "sigma_level": 0.05, "sigma_yaw": 3.0}
    gnss = np.array([[1.0, 47.4, 8.5, 488.0, 0.0, 0.0, 0.0, 1.0, 1.5, 0.1]])
    if which == "mavins":
        from mavins.core import aided

        t1 = time.perf_counter()
        aided.navigate_aided(imu, init, gnss, static=[(0.0, 0.5)], spec="consumer")
    else:
        from pyins import filters  # noqa: F401

        t1 = time.perf_counter()
        run_pyins(imu, gnss, init)
    t2 = time.perf_counter()
    return {"import_s": t1 - t0, "call_s": t2 - t1}


def first_call(which: str, env_extra: dict[str, str] | None = None) -> dict[str, float]:
    env = dict(os.environ)
    env.update(env_extra or {})
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--first-call", which],
                          check=False, capture_output=True, text=True, env=env, cwd=ROOT)
    if proc.returncode != 0:
        raise RuntimeError(f"first-call subprocess failed:\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def compile_notes() -> tuple[list[str], list[dict]]:
    log("first calls in fresh interpreters: mavins with its cache, with an empty cache (built kernels, "
        "then JIT only), pyins")
    warm = first_call("mavins")
    with tempfile.TemporaryDirectory(prefix="bench_filter_numba_") as cache:
        cold = first_call("mavins", {"NUMBA_CACHE_DIR": cache, "MAVINS_AOT": "1"})
    with tempfile.TemporaryDirectory(prefix="bench_filter_numba_") as cache:
        jit = first_call("mavins", {"NUMBA_CACHE_DIR": cache, "MAVINS_AOT": "0"})
    py = first_call("pyins")
    rows = [["mavins, numba cache present (warm start)", f"{warm['import_s']:.2f}", f"{warm['call_s']:.2f}"],
            ["mavins, empty NUMBA_CACHE_DIR, kernels built at install", f"{cold['import_s']:.2f}",
             f"{cold['call_s']:.2f}"],
            ["mavins, empty NUMBA_CACHE_DIR, JIT only (MAVINS_AOT=0: compile of the batch filter)",
             f"{jit['import_s']:.2f}", f"{jit['call_s']:.2f}"],
            ["pyins first call (numba JIT, not cached by pyins)", f"{py['import_s']:.2f}", f"{py['call_s']:.2f}"]]
    lines = ["First call in a fresh interpreter (200-sample record; not part of the per-sample figures):"]
    lines += table(["case", "import s", "first call s"], rows)
    out = [{"case": "filter first call: mavins, empty numba cache, kernels built at install",
            "seconds": cold["import_s"] + cold["call_s"],
            "note": f"import {cold['import_s']:.2f} s + call {cold['call_s']:.2f} s"},
           {"case": "filter first call: mavins, empty numba cache, JIT only (compile)",
            "seconds": jit["import_s"] + jit["call_s"],
            "note": f"import {jit['import_s']:.2f} s + call {jit['call_s']:.2f} s"},
           {"case": "filter first call: mavins warm start", "seconds": warm["import_s"] + warm["call_s"],
            "note": f"import {warm['import_s']:.2f} s + call {warm['call_s']:.2f} s"},
           {"case": "filter first call: pyins", "seconds": py["import_s"] + py["call_s"],
            "note": f"import {py['import_s']:.2f} s + call {py['call_s']:.2f} s"}]
    return lines, out


# --- part 3: Monte Carlo consistency ------------------------------------------------------------
def mc_run(seed: int, mag_rate: float = 0.0) -> dict[str, Any]:
    """One Monte Carlo run of the tests' set-up: NEES per 1 Hz epoch, normalised errors, NIS, accuracy sums.

    ``mag_rate`` > 0 adds the simulator's magnetometer at that rate (Hz), as the tests' second set-up (50 Hz)."""
    from mavins.core import aided

    t = taf()
    traj = trajectory()
    imu, gnss, init, bg, ba = t.simulate_run(traj, seed)
    kw = {"mag": t.magnetometer_rows(traj, seed, mag_rate), "declination": t.MAG.declination} if mag_rate > 0 else {}
    rows, st = aided.navigate_aided(imu, init, gnss, static=t.STATIC, spec="consumer", file_units=False,
                                    covariance_every=t.EVERY, **kw)
    idx = 2 * (np.arange(rows.shape[0]) + 1)
    err = t.nav_errors(rows, traj.exact.truth[idx])
    sel = np.arange(st["P_history"].shape[0]) * t.EVERY + t.EVERY - 1
    ph = st["P_history"]
    nees = {}
    for k, o in (("att", 0), ("vel", 3), ("pos", 6)):
        e = err[sel, o:o + 3]
        nees[k] = np.einsum("ki,kij,kj->k", e, np.linalg.inv(ph[:, o:o + 3, o:o + 3]), e)
    z_nav = err[sel] / np.sqrt(np.diagonal(ph, axis1=1, axis2=2)[:, :9])
    eb = np.column_stack([rows[sel, 23:26] - bg[idx[sel]], rows[sel, 26:29] - ba[idx[sel]]])
    z_bias = eb / rows[sel, 29:35]
    eb_end = np.concatenate([rows[-1, 23:26] - bg[idx[-1]], rows[-1, 26:29] - ba[idx[-1]]])
    pb = t.BIAS_SUM @ st["P"] @ t.BIAS_SUM.T
    late = rows[:, 0] >= SETTLE_S
    e = err[late]
    nis = st["nis"]
    return {
        "nees": nees, "z": np.column_stack([z_nav, z_bias]),
        "bias_nees": float(eb_end @ np.linalg.solve(pb, eb_end)),
        "nis_pos": nis[(nis[:, 1] == aided.K_GNSS_POS) & (nis[:, 4] == 1.0), 2],
        "nis_vel": nis[(nis[:, 1] == aided.K_GNSS_VEL) & (nis[:, 4] == 1.0), 2],
        "n_late": int(late.sum()), "h2": float(np.sum(e[:, 6] ** 2 + e[:, 7] ** 2)), "v2": float(np.sum(e[:, 8] ** 2)),
        "level2": float(np.sum(e[:, 0] ** 2 + e[:, 1] ** 2)), "yaw2": float(np.sum(e[:, 2] ** 2)),
    }


def monte_carlo(runs: int, jobs: int, mag_rate: float = 0.0) -> dict[str, Any]:
    """Part 3 through mavins.common.parallel.run_jobs (sequential when the module is absent)."""
    t = taf()
    trajectory()  # built before the workers fork, so they inherit it
    imu, gnss, init, _, _ = t.simulate_run(trajectory(), SEED0)
    from mavins.core import aided

    aided.navigate_aided(imu[:200], init, gnss[:1], static=t.STATIC, spec="consumer", file_units=False,
                         covariance_every=t.EVERY)  # kernels loaded before the fork
    seeds = [SEED0 + r for r in range(runs)]
    func = functools.partial(mc_run, mag_rate=mag_rate)
    start = time.perf_counter()
    try:
        from mavins.common.parallel import run_jobs
    except ImportError:
        how = "sequential (mavins.common.parallel absent)"
        results = [func(s) for s in seeds]
    else:
        how = f"mavins.common.parallel.run_jobs, jobs={jobs}"
        results = run_jobs(func, seeds, jobs=jobs, label="monte carlo" + (" with magnetometer" if mag_rate > 0 else ""))
    wall = time.perf_counter() - start
    return {"results": results, "wall": wall, "how": how, "runs": runs, "mag": mag_rate}


def mc_notes(mc: dict[str, Any]) -> tuple[list[str], list[dict]]:
    t = taf()
    res = mc["results"]
    n = len(res)
    what = f", GNSS and magnetometer at {mc['mag']:g} Hz" if mc["mag"] else ""
    lo3, hi3 = t.band(3, n)
    rows, out = [], []
    for k, label in (("pos", "position"), ("vel", "velocity"), ("att", "attitude")):
        anees = float(np.mean(np.mean([r["nees"][k] for r in res], axis=0)))
        ok = lo3 < anees < hi3
        rows.append([f"{label} NEES (3 dof), mean over runs and 1 Hz epochs", f"{anees:.2f}",
                     f"{lo3:.2f} - {hi3:.2f}", "PASS" if ok else "MISS"])
        out.append({"case": f"filter consistency: {label} ANEES ({n} runs{what})", "value": f"{anees:.2f}",
                    "goal": f"{lo3:.2f}-{hi3:.2f}: {'PASS' if ok else 'MISS'}"})
    lo6, hi6 = t.band(6, n)
    bn = float(np.mean([r["bias_nees"] for r in res]))
    rows.append(["bias NEES at the end (6 dof)", f"{bn:.2f}", f"{lo6:.2f} - {hi6:.2f}",
                 "PASS" if lo6 < bn < hi6 else "MISS"])
    for k, label in (("nis_pos", "GNSS position NIS"), ("nis_vel", "GNSS velocity NIS")):
        v = np.concatenate([r[k] for r in res])
        lo, hi = t.band(3, v.size)
        rows.append([f"{label} (3 dof, {v.size} fixes)", f"{v.mean():.2f}", f"{lo:.2f} - {hi:.2f}",
                     "PASS" if lo < v.mean() < hi else "MISS"])
    nl = sum(r["n_late"] for r in res)
    hr = math.sqrt(sum(r["h2"] for r in res) / nl)
    vr = math.sqrt(sum(r["v2"] for r in res) / nl)
    lr = math.degrees(math.sqrt(sum(r["level2"] for r in res) / nl))
    yr = math.degrees(math.sqrt(sum(r["yaw2"] for r in res) / nl))
    rows.append([f"horizontal RMS after {SETTLE_S:.0f} s", f"{hr:.3f} m", "< 0.5 m", "PASS" if hr < 0.5 else "MISS"])
    rows.append([f"vertical RMS after {SETTLE_S:.0f} s", f"{vr:.3f} m", "-", ""])
    rows.append([f"level attitude RMS after {SETTLE_S:.0f} s", f"{lr:.3f} deg", "< 0.1 deg",
                 "PASS" if lr < 0.1 else "MISS"])
    rows.append([f"heading RMS after {SETTLE_S:.0f} s", f"{yr:.3f} deg", "< 0.1 deg", "PASS" if yr < 0.1 else "MISS"])
    out.append({"case": f"filter accuracy: horizontal RMS after 60 s ({n} runs{what})", "value": f"{hr:.3f} m",
                "goal": f"< 0.5 m: {'PASS' if hr < 0.5 else 'MISS'}"})
    out.append({"case": f"filter accuracy: heading RMS after 60 s ({n} runs{what})", "value": f"{yr:.3f} deg",
                "goal": f"< 0.1 deg: {'PASS' if yr < 0.1 else 'MISS'}"})
    lines = [(f"Consistency over {n} Monte Carlo runs (tests/core/test_aided_filter.py set-up{what}, seeds {SEED0}.."
              f"{SEED0 + n - 1}; {mc['how']}, {mc['wall']:.1f} s wall):")]
    lines += table(["check", "measured", "95 % band / target", ""], rows)
    z = np.concatenate([r["z"] for r in res])
    rms = np.sqrt(np.mean(z ** 2, axis=0))
    zrows = [[name, f"{v:.2f}", "PASS" if v < NORM_TARGET else "MISS"] for name, v in zip(STATE_NAMES, rms)]
    worst = int(np.argmax(rms))
    ok = bool(np.all(rms < NORM_TARGET))
    lines.append(f"RMS of the normalised error (error / filter 1-sigma) per state, over runs and 1 Hz epochs "
                 f"(target < {NORM_TARGET}; 1.0 for a consistent filter):")
    lines += table(["state", "RMS", ""], zrows)
    out.append({"case": f"filter consistency: worst normalised-error RMS ({n} runs{what})",
                "value": f"{rms[worst]:.2f} ({STATE_NAMES[worst]})",
                "goal": f"< {NORM_TARGET} every state: {'PASS' if ok else 'MISS'}"})
    return lines, out


# --- driver ------------------------------------------------------------------------------------
def main(argv: Sequence[str] = ()) -> list[dict]:
    """Run the parts asked for; returns the rows (run_all) and fills NOTES with the detailed tables."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true",
                   help="short run: 1 pyins comparison run, 10 Monte Carlo runs, 10 s live, no subprocess rows")
    p.add_argument("--compare-runs", type=int, default=None, help="seeds of the pyins comparison (default 5)")
    p.add_argument("--compare-first", type=int, default=SEED0,
                   help=f"first seed of the pyins comparison (default {SEED0})")
    p.add_argument("--runs", type=int, default=None, help="Monte Carlo runs (default 50)")
    p.add_argument("--mag-rate", type=float, default=50.0,
                   help="magnetometer rate (Hz) of the Monte Carlo's second set-up (default 50, the live path's)")
    p.add_argument("--jobs", type=int, default=None, help="worker processes for the Monte Carlo (default: all cores)")
    p.add_argument("--live-seconds", type=float, default=None, help="sensor seconds of the 1 kHz live record (60)")
    p.add_argument("--service-seconds", type=float, default=None,
                   help="CPU window of the whole `mavins run` process at 1 kHz (20; 0 = skip)")
    p.add_argument("--repeat", type=int, default=3, help="repeats of each mavins timing; the best is reported")
    p.add_argument("--no-subprocess", action="store_true", help="skip the first-call (compile) rows")
    p.add_argument("--profile", action="store_true", help="add a cProfile of the live loop (where a sample's time goes)")
    p.add_argument("--skip", action="append", default=[], choices=("compare", "cost", "mc"), help="skip a part")
    args = p.parse_args(list(argv))
    q = args.quick
    compare_runs = args.compare_runs if args.compare_runs is not None else (1 if q else 5)
    runs = args.runs if args.runs is not None else (10 if q else 50)
    live_s = args.live_seconds if args.live_seconds is not None else (10.0 if q else 60.0)
    service_s = args.service_seconds if args.service_seconds is not None else (0.0 if q else 20.0)
    if args.jobs is None:
        try:
            from mavins.common.parallel import default_jobs

            jobs = default_jobs()
        except ImportError:
            jobs = 1
    else:
        jobs = args.jobs
    NOTES.clear()
    NOTES.append(f"load at the start: {load_avg()} (/proc/loadavg, 1/5/15 min), {os.cpu_count()} cores"
                 + (" (--quick: short runs, not the figures of record)" if q else ""))
    cmd = " ".join([".venv/bin/python benchmarks/bench_filter.py", *argv])
    rows: list[dict] = []
    t_start = time.perf_counter()
    comp = None
    if "compare" not in args.skip:
        log(f"part 1: mavins and pyins on the same data, {compare_runs} run(s)")
        comp = compare(compare_runs, args.repeat, args.compare_first)
        lines, r = compare_notes(comp)
        NOTES.extend([""] + lines)
        rows.extend(r)
    if "cost" not in args.skip:
        log("part 2: cost per IMU sample")
        if comp is not None:
            b100 = {"n": comp["n"], "seconds": min(comp["sec"]["mavins_rest"])}
        else:
            t = taf()
            imu, gnss, init, _, _ = t.simulate_run(trajectory(), SEED0)
            mavins_rows(imu[:200], gnss[:1], init, t.STATIC, 1)
            b100 = {"n": imu.shape[0], "seconds": mavins_rows(imu, gnss, init, t.STATIC, args.repeat)[0]}
        b1k = batch_1khz(live_s, args.repeat)
        live = live_cost(live_s, args.repeat)
        service = None
        if service_s > 0:
            log(f"whole `mavins run` process at 1 kHz ({service_s:g} s window)")
            import bench_latency

            service = bench_latency.cpu_run(service_s, None)
            log(f"bare Python UDP receiver at 1 kHz ({service_s:g} s window): the baseline of that row")
            service["bare_pct"] = bench_latency.cpu_bare(service_s)[0]
        lines, r = cost_notes(b100, b1k, live, service)
        NOTES.extend([""] + lines)
        rows.extend(r)
        if args.profile:
            log("cProfile of the live loop")
            NOTES.extend([""] + profile_live(min(live_s, 20.0)))
        if not args.no_subprocess and not q:
            lines, r = compile_notes()
            NOTES.extend([""] + lines)
            rows.extend(r)
    if "mc" not in args.skip:
        log(f"part 3: {runs} Monte Carlo runs, jobs={jobs}")
        for mag_rate in (0.0, args.mag_rate):
            mc = monte_carlo(runs, jobs, mag_rate)
            lines, r = mc_notes(mc)
            NOTES.extend([""] + lines)
            rows.extend(r)
    NOTES.append("")
    NOTES.append(f"load at the end: {load_avg()}; {time.perf_counter() - t_start:.0f} s in all")
    NOTES.append(f"reproduce: {cmd}")
    return rows


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--first-call":
        print(json.dumps(_first_call(sys.argv[2])))
        sys.exit(0)
    from run_all import format_table, machine_info

    header = machine_info()  # before the run: its load line is the load at the start
    result = main(sys.argv[1:])
    print("\n".join(header))
    print()
    print(format_table(result))
    print("\n".join(NOTES))

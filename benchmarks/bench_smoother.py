"""The fixed-interval smoother (``--smooth``): what it costs against the forward filter, in time and memory.

Two parts, one run (issue "Post-processing", point 2: smoothing costs at most twice the forward pass; one
hour at 1 kHz in bounded memory):

1. **In process, warm.** The simulator's flight (tests/core/test_aided_filter.py's set-up: 120 s at 100 Hz,
   consumer grade, 1 Hz GNSS with a 60 s outage, a rest window), ``navigate_aided`` forward and with
   ``smooth=True`` on the same data, the best of 5 of each, interleaved so that the machine's load falls
   on both alike. Ratio: smoothed over forward.
2. **``mavins nav`` end to end on one hour at 1 kHz** (``--quick``: ten minutes): a vehicle at rest,
   level, consumer-grade white noise on the increments, 5 Hz GNSS and 10 Hz baro (written once with
   pyarrow into a temporary folder), navigated with and without ``--smooth`` as a user runs it, each in a
   fresh process (the kernels built ahead of time). Wall seconds and the process's peak resident memory
   (``wait4``'s ``ru_maxrss``, which counts the resident pages of the mapped temporary file too) and its
   peak anonymous memory (``RssAnon``, sampled every 20 ms: what the system cannot page out to a file);
   the temporary file the smoother used is its epochs (stderr) times their
   width plus the rows, computed from the layout (core/smoother.py, aided.ROW_SIZE).

Run from the repository root::

    .venv/bin/python benchmarks/bench_smoother.py [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "tests" / "core")]

NOTES: list[str] = []
LAT, LON, H = 47.397742, 8.545594, 488.0


def in_process() -> list[dict]:
    """Part 1: forward and smoothed navigate_aided on the flight with an outage, best of 5 each."""
    import test_aided_filter as taf  # the Monte Carlo's set-up and helpers
    from mavins.core import aided
    from sim.generate import generate
    from sim.scenarios import Scenario, load

    sc = load("flight")
    doc = {k: v for k, v in sc.doc.items() if k != "perturbations"}
    traj = generate(Scenario("flight_quiet", sc.source, doc), duration=taf.DURATION, rate=taf.RATE, seed=0,
                    grade="ideal")
    imu, gnss, init, _, _ = taf.simulate_run(traj, 2000, dataclasses.replace(taf.GNSS, outages=((40.0, 100.0),)))
    best = {False: math.inf, True: math.inf}
    for smooth in (False, True):  # compiled or loaded here
        aided.navigate_aided(imu, init, gnss, static=taf.STATIC, spec="consumer", smooth=smooth)
    for _ in range(5):
        for smooth in (False, True):
            t0 = time.perf_counter()
            aided.navigate_aided(imu, init, gnss, static=taf.STATIC, spec="consumer", smooth=smooth)
            best[smooth] = min(best[smooth], time.perf_counter() - t0)
    n = imu.shape[0]
    return [
        {"case": "navigate_aided forward (flight, 120 s at 100 Hz, 60 s outage)", "samples": n,
         "seconds": best[False], "rate": n / best[False], "value": f"{1e6 * best[False] / n:.2f} us/sample",
         "ratio": 1.0, "baseline": "(is the baseline)"},
        {"case": "navigate_aided smooth=True (same data)", "samples": n, "seconds": best[True],
         "rate": n / best[True], "value": f"{1e6 * best[True] / n:.2f} us/sample",
         "ratio": best[True] / best[False], "baseline": "forward; goal <= 2"},
    ]


def write_rest(folder: Path, seconds: float) -> Path:
    """One recording at rest (1 kHz increments, 5 Hz GNSS, 10 Hz baro) and its init.json in ``folder``."""
    from mavins.common.files import write_table
    from mavins.core import earth

    rng = np.random.default_rng(1)
    dt, n = 1e-3, int(round(seconds * 1000))
    t = np.arange(1, n + 1) * dt
    lat = math.radians(LAT)
    g = earth.gravity(lat, H)
    w = np.array([earth.OMEGA * math.cos(lat), 0.0, -earth.OMEGA * math.sin(lat)])
    arw, vrw = math.radians(0.3) / 60.0, 0.1 / 60.0  # consumer-like: deg/sqrt(h), m/s/sqrt(h) in SI per sqrt(s)
    dth = w * dt + rng.standard_normal((n, 3)) * arw * math.sqrt(dt)
    dv = np.array([0.0, 0.0, -g]) * dt + rng.standard_normal((n, 3)) * vrw * math.sqrt(dt)
    write_table(folder / "imu.csv", ("t", "dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z"),
                np.column_stack([t, dth, dv]))
    tg = np.arange(0.2, seconds + 1e-9, 0.2)
    r_n, r_e = earth.radii(lat)
    fix = np.column_stack([tg, LAT + np.degrees(rng.standard_normal(tg.size) / (r_n + H)),
                           LON + np.degrees(rng.standard_normal(tg.size) / ((r_e + H) * math.cos(lat))),
                           H + 1.5 * rng.standard_normal(tg.size)])
    write_table(folder / "gnss.csv", ("t", "lat", "lon", "h"), fix)
    tb = np.arange(0.1, seconds + 1e-9, 0.1)
    write_table(folder / "baro.csv", ("t", "h"), np.column_stack([tb, H + 0.5 * rng.standard_normal(tb.size)]))
    (folder / "init.json").write_text(json.dumps({"t": 0.0, "lat": LAT, "lon": LON, "h": H, "vn": 0.0, "ve": 0.0,
                                                  "vd": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0}))
    return folder


def _anon_mb(pid: int) -> float:
    """The process's anonymous resident memory now (MB, /proc: RssAnon), what cannot be paged out to a file;
    NaN once it is gone."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("RssAnon:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


def nav_process(folder: Path, smooth: bool) -> tuple[float, float, float, str]:
    """``mavins nav`` over the folder's files in a fresh process: wall seconds, peak RSS (MB; with the pages of
    mapped files), peak anonymous memory (MB, sampled every 20 ms), stderr."""
    import threading

    mavins = Path(sys.executable).parent / "mavins"
    cmd = [str(mavins) if mavins.is_file() else sys.executable, *([] if mavins.is_file() else ["-m", "mavins"]),
           "nav", str(folder / "imu.csv"), "--init", str(folder / "init.json"), "--gnss", str(folder / "gnss.csv"),
           "--baro", str(folder / "baro.csv"), "-o", str(folder / "nav.csv"), *(["--smooth"] if smooth else [])]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peak = [0.0]
    done = threading.Event()

    def sample() -> None:
        while not done.wait(0.02):
            a = _anon_mb(proc.pid)
            if a == a:
                peak[0] = max(peak[0], a)

    watcher = threading.Thread(target=sample, daemon=True)
    watcher.start()
    err = proc.stderr.read()  # type: ignore[union-attr]
    done.set()
    watcher.join()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"mavins nav failed: {err}")
    return wall, usage.ru_maxrss / 1024.0, peak[0], err


def end_to_end(seconds: float) -> list[dict]:
    """Part 2: mavins nav forward and --smooth on a long recording at rest."""
    from mavins.core import aided, smoother

    with tempfile.TemporaryDirectory(prefix="mavins-bench-") as tmp:
        folder = write_rest(Path(tmp), seconds)
        n = int(round(seconds * 1000))
        nav_process(folder, False)  # the file system's cache warm for both
        fwd_s, fwd_mb, fwd_anon, _ = nav_process(folder, False)
        smo_s, smo_mb, smo_anon, err = nav_process(folder, True)
    m = re.search(r"smoothed over (\d+) epochs", err)
    epochs = int(m.group(1)) if m else 0
    from mavins.core import errmodel as em, kalman as kf

    # the active states of this set-up (those with a variance at the start), as navigate_aided counts them
    P = kf.initial_covariance(em.make_spec("consumer"), 10.0, 1.0, 0.01, 0.1, 50.0, 0.0)
    na = int(np.count_nonzero(np.diag(P) > 0.0))
    temp_mb = (epochs * smoother.store_width(na) + (n // 2 + 1) * aided.ROW_SIZE) * 8 / 2**20
    NOTES.append(f"smoother: {epochs} epochs over {na} active states; its temporary file about {temp_mb:.0f} MB "
                 f"(epochs x {smoother.store_width(na)} values + rows x {aided.ROW_SIZE}, float64)")
    label = f"{seconds / 3600:.2g} h" if seconds >= 3600 else f"{seconds / 60:.3g} min"
    return [
        {"case": f"mavins nav forward ({label} at 1 kHz, GNSS 5 Hz, baro 10 Hz)", "samples": n, "seconds": fwd_s,
         "rate": n / fwd_s, "value": f"RSS {fwd_mb:.0f} / anon {fwd_anon:.0f} MB", "ratio": 1.0, "baseline": "(is the baseline)"},
        {"case": "mavins nav --smooth (same files)", "samples": n, "seconds": smo_s, "rate": n / smo_s,
         "value": f"RSS {smo_mb:.0f} / anon {smo_anon:.0f} MB", "ratio": smo_s / fwd_s, "baseline": "forward; goal <= 2"},
    ]


def main(argv: Sequence[str] = ()) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="ten minutes at 1 kHz instead of one hour")
    args = p.parse_args(list(argv))
    NOTES.clear()
    NOTES.append(f"machine load before the run (1, 5, 15 min): {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return in_process() + end_to_end(600.0 if args.quick else 3600.0)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

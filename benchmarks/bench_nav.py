"""Offline strapdown throughput: mavins against pyins on the same input, same run.

One deterministic 1,000,000-sample increment record (100 Hz, WGS-84, rotating
Earth, gentle rocking so the coning and sculling terms are not zero) is
integrated by

* the mavins kernel alone (``strapdown.run_increments``, 2-sample coning),
* ``mavins.core.runner.navigate()`` (kernel plus unit conversion),
* pyins 1.0 (``benchmarks/pyins_baseline.run_pyins``, its timed part),
* the ``mavins nav --timing`` command on a CSV of the same record,

and the first-call costs of a fresh process are measured in subprocesses:
warm start (numba cache present) and cold start (empty ``NUMBA_CACHE_DIR``), with the kernels
built at install and with the JIT only (``MAVINS_AOT=0``: the compile).
Ratios are pyins seconds divided by our seconds, both measured in this run.

Run from the repository root::

    .venv/bin/python benchmarks/bench_nav.py [--samples N] [--repeat R]

See benchmarks/README.md for what each row means.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(HERE), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

N_SAMPLES = 1_000_000
RATE_HZ = 100.0
SEED = 20250101
#: Initial state of the record (degrees, m, m/s), docs/conventions.md "Initial state".
INIT = {
    "t": 0.0,
    "lat": 45.0,
    "lon": 10.0,
    "h": 100.0,
    "vn": 0.0,
    "ve": 0.0,
    "vd": 0.0,
    "roll": 0.0,
    "pitch": 0.0,
    "yaw": 30.0,
}
#: Rocking of the record: roll and pitch amplitudes (rad) and frequencies (Hz).
ROLL_AMP, ROLL_HZ = 0.01, 0.37
PITCH_AMP, PITCH_HZ = 0.005, 0.23
WARMUP_SAMPLES = 4
SANITY_T = 600.0

#: Footnotes printed under the table (filled by main()).
NOTES: list[str] = []


# --- input -----------------------------------------------------------------
def make_input(n: int = N_SAMPLES, seed: int = SEED) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic increments ``(t, dtheta, dv)`` of a gently rocking vehicle at rest.

    Base: ``sim.motion.stationary`` (Earth rate and gravity at INIT). On top:
    roll and pitch oscillations (body x and y rates, so ``dtheta_i x dtheta_j``
    and the sculling terms are non-zero), the matching first-order tilt of the
    gravity reaction in ``dv``, and a little seeded white noise. The record is
    not exact to the last digit; it is meant for speed, and keeps the solution
    close to the start point so both integrators run ordinary numbers.
    """
    from sim.motion import stationary

    dt = 1.0 / RATE_HZ
    m = stationary(INIT["lat"], INIT["h"], INIT["roll"], INIT["pitch"], INIT["yaw"], dt, n)
    t = m.t
    t0 = t - dt
    wr, wp = 2.0 * np.pi * ROLL_HZ, 2.0 * np.pi * PITCH_HZ
    # Exact integrals over (t0, t] of the rates d/dt [A sin(w t)].
    d_roll = ROLL_AMP * (np.sin(wr * t) - np.sin(wr * t0))
    d_pitch = PITCH_AMP * (np.sin(wp * t) - np.sin(wp * t0))
    dtheta = m.dtheta.copy()
    dtheta[:, 0] += d_roll
    dtheta[:, 1] += d_pitch
    # Gravity reaction [0, 0, -g] seen in a body tilted by (roll, pitch):
    # f_b ~ [g pitch, -g roll, -g] to first order.
    tm = t - 0.5 * dt
    g = -m.dv[0, 2] / dt
    dv = m.dv.copy()
    dv[:, 0] += g * PITCH_AMP * np.sin(wp * tm) * dt
    dv[:, 1] -= g * ROLL_AMP * np.sin(wr * tm) * dt
    rng = np.random.default_rng(seed)
    dtheta += rng.normal(0.0, 1e-7, dtheta.shape)
    dv += rng.normal(0.0, 1e-5, dv.shape)
    return t, np.ascontiguousarray(dtheta), np.ascontiguousarray(dv)


# --- in-process timings ------------------------------------------------------
def time_kernel(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, samples: int, repeat: int) -> float:
    """Best-of-``repeat`` seconds of ``strapdown.run_increments`` alone."""
    from mavins.core import strapdown as sd
    from mavins.core.runner import initial_state

    cfg = sd.make_config(samples=samples)
    out = np.empty((t.shape[0] // samples + 1, sd.OUT_SIZE))
    out.fill(0.0)  # touch the pages outside the timed part
    sd.run_increments(initial_state(INIT), cfg, t[:WARMUP_SAMPLES], dtheta[:WARMUP_SAMPLES], dv[:WARMUP_SAMPLES], out)
    best = np.inf
    for _ in range(repeat):
        state = initial_state(INIT)
        start = time.perf_counter()
        sd.run_increments(state, cfg, t, dtheta, dv, out)
        best = min(best, time.perf_counter() - start)
    return best


def time_navigate(
    t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, samples: int, repeat: int
) -> tuple[float, np.ndarray]:
    """Best-of-``repeat`` seconds of ``navigate()`` and its solution."""
    from mavins.core.runner import navigate

    w = WARMUP_SAMPLES
    navigate(t[:w], dtheta[:w], dv[:w], INIT, data="increments", samples=samples)
    best, sol = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        sol = navigate(t, dtheta, dv, INIT, data="increments", samples=samples)
        best = min(best, time.perf_counter() - start)
    return best, sol


def time_pyins(
    t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, repeat: int
) -> tuple[float | None, np.ndarray | None, str]:
    """Best-of-``repeat`` seconds of pyins' timed part, its solution, and a status text."""
    try:
        from pyins_baseline import run_pyins

        best, sol = np.inf, None
        for _ in range(repeat):
            seconds, sol = run_pyins(t, dtheta, dv, INIT)
            best = min(best, seconds)
    except ImportError as exc:
        return None, None, f"pyins is missing, so there are no ratios: {exc}"
    return best, sol, "ok"


def time_pyins_loop(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, repeat: int) -> float | None:
    """Best-of-``repeat`` seconds of pyins' numba integration loop alone (reference only).

    The same call ``pyins.strapdown.Integrator._integrate`` makes, on arrays
    prepared outside the timer: no pandas, no coning/sculling, no Euler angles.
    Returns None when pyins is missing or its internals differ from 1.0.x.
    """
    try:
        import pyins_baseline as pb

        pd, strapdown = pb._import_pyins()
        pva = pb._initial_pva(pd, INIT)
        inc = strapdown.compute_increments_from_imu(pb._imu_frame(pd, INIT["t"], t, dtheta, dv), "increment")
        theta = np.ascontiguousarray(inc[["theta_x", "theta_y", "theta_z"]])
        dvv = np.ascontiguousarray(inc[["dv_x", "dv_y", "dv_z"]])
        dts = np.ascontiguousarray(inc["dt"], dtype=float)
        best = np.inf
        for k in range(repeat + 1):  # the first pass compiles
            m = len(dts) if k else 2
            integ = strapdown.Integrator(pva, with_altitude=True)
            lla, vel, mat = np.empty((m + 1, 3)), np.empty((m + 1, 3)), np.empty((m + 1, 3, 3))
            lla[0], vel[0], mat[0] = integ.lla[0], integ.velocity_n[0], integ.mat_nb[0]
            for a in (lla, vel, mat):
                a[1:] = 0.0  # touch the pages outside the timed part
            start = time.perf_counter()
            strapdown.integrate(dts[:m], lla, vel, mat, theta[:m], dvv[:m], 0, True)
            if k:
                best = min(best, time.perf_counter() - start)
        return best
    except Exception:  # noqa: BLE001 - reference row only; pyins internals may change
        return None


# --- subprocess timings --------------------------------------------------------
_FIRST_CALL = """
import json, sys, time
t0 = time.perf_counter()
import numpy as np
{imports}
t1 = time.perf_counter()
init = json.loads(sys.argv[1])
n = {n}
t = 0.01 * np.arange(1, n + 1)
dth = np.full((n, 3), 1e-6)
dv = np.tile([0.0, 0.0, -0.0981], (n, 1))
{call}
t2 = time.perf_counter()
print(json.dumps({{"import_s": t1 - t0, "call_s": t2 - t1}}))
"""

_MAVINS_FIRST = _FIRST_CALL.format(
    imports="from mavins.core.runner import navigate",
    n=WARMUP_SAMPLES,
    call="navigate(t, dth, dv, init, data='increments', samples=2)",
)
_PYINS_FIRST = _FIRST_CALL.format(
    imports=f"sys.path.insert(0, {str(HERE)!r})\nfrom pyins_baseline import run_pyins, _import_pyins\n_import_pyins()",
    n=WARMUP_SAMPLES,
    call="run_pyins(t, dth, dv, init)",
)


def first_call(script: str, env_extra: dict[str, str] | None = None) -> dict[str, float]:
    """Run ``script`` in a fresh interpreter; its JSON timings plus the process wall time."""
    env = dict(os.environ)
    env.update(env_extra or {})
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", script, json.dumps(INIT)], capture_output=True, text=True, env=env, cwd=ROOT
    )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"first-call subprocess failed:\n{proc.stderr}")
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    result["wall_s"] = wall
    return result


def time_cli(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, samples: int, workdir: Path) -> dict[str, float]:
    """``mavins nav --timing`` on a CSV of the record: read/compute/write and process wall seconds."""
    from mavins.common import files

    imu = workdir / "imu.csv"
    init = workdir / "init.json"
    out = workdir / "nav.csv"
    files.write_table(imu, files.INCREMENT_COLUMNS, np.column_stack((t, dtheta, dv)))
    files.write_init(init, files.InitialState(**INIT))
    cmd = [sys.executable, "-m", "mavins.cli", "nav", str(imu), "--init", str(init), "-o", str(out)]
    cmd += ["--samples", str(samples), "--timing"]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"mavins nav failed:\n{proc.stderr}")
    m = re.search(r"read_s=([\d.]+) compute_s=([\d.]+) write_s=([\d.]+)", proc.stderr)
    if not m:
        raise RuntimeError(f"mavins nav --timing printed no timing line:\n{proc.stderr}")
    return {
        "read_s": float(m.group(1)),
        "compute_s": float(m.group(2)),
        "write_s": float(m.group(3)),
        "wall_s": wall,
        "csv_mb": imu.stat().st_size / 1e6,
    }


_PYINS_END_TO_END = """
import json, sys
sys.path.insert(0, {here!r})
import numpy as np
from pyins_baseline import _imu_frame, _import_pyins, _initial_pva, _integrate

pd, strapdown = _import_pyins()
imu_path, init_path, out_path = sys.argv[1:4]
init = json.load(open(init_path))
df = pd.read_csv(imu_path)
t = df["t"].to_numpy()
dtheta = df[["dtheta_x", "dtheta_y", "dtheta_z"]].to_numpy()
dv = df[["dv_x", "dv_y", "dv_z"]].to_numpy()
trajectory = _integrate(strapdown, _imu_frame(pd, float(init["t"]), t, dtheta, dv), _initial_pva(pd, init))
trajectory.to_csv(out_path)
"""


def time_pyins_end_to_end(workdir: Path) -> float | None:
    """pyins the way a user runs it on the same files as ``time_cli``: a fresh process that reads imu.csv with
    pandas, applies coning and sculling, integrates (its numba functions compiled on the first call: it keeps
    no cache) and writes the trajectory with pandas; its wall seconds, start to exit. None without pyins."""
    script = workdir / "pyins_nav.py"
    script.write_text(_PYINS_END_TO_END.format(here=str(HERE)), encoding="utf-8")
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, str(script), str(workdir / "imu.csv"), str(workdir / "init.json"),
                           str(workdir / "pyins_nav.csv")], capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        if "python-ins" in proc.stderr:
            return None
        raise RuntimeError(f"pyins end to end failed:\n{proc.stderr}")
    return wall


# --- cross-check -----------------------------------------------------------------
def sanity_note(ours: np.ndarray, theirs: np.ndarray, t_check: float = SANITY_T) -> str:
    """Position and attitude difference of the two solutions at ``t_check`` (both integrate the same record)."""
    i = int(np.argmin(np.abs(ours[:, 0] - t_check)))
    j = int(np.argmin(np.abs(theirs[:, 0] - t_check)))
    a, b = ours[i], theirs[j]
    lat = np.radians(a[1])
    dn = np.radians(a[1] - b[1]) * 6.371e6
    de = np.radians(a[2] - b[2]) * 6.371e6 * np.cos(lat)
    dh = a[3] - b[3]
    dyaw = (a[9] - b[9] + 180.0) % 360.0 - 180.0
    return (
        f"cross-check at t = {a[0]:g} s (ours) / {b[0]:g} s (pyins): horizontal {np.hypot(dn, de):.3g} m, "
        f"height {dh:.3g} m, roll {a[7] - b[7]:.2g} deg, pitch {a[8] - b[8]:.2g} deg, yaw {dyaw:.2g} deg"
    )


# --- driver ------------------------------------------------------------------------
C_LIMIT_SOURCE = ROOT.parent / "shared" / "bench" / "limit_ins.c"


def time_c_limit(n: int, repeat: int) -> tuple[float | None, str]:
    """Seconds of the scalar C 2-sample WGS-84 update (``limit_ins.c``, gcc -O2, one core, in
    memory) on n samples, best of ``repeat``; None with the reason when it is not beside the repo."""
    import shutil

    if not C_LIMIT_SOURCE.is_file():
        return None, f"C limit absent ({C_LIMIT_SOURCE.name} is not beside the repository)"
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        return None, "C limit absent (no C compiler)"
    with tempfile.TemporaryDirectory(prefix="bench_nav_c_") as tmp:
        exe = Path(tmp) / "limit_ins"
        subprocess.run([cc, "-O2", "-o", str(exe), str(C_LIMIT_SOURCE), "-lm"], check=True, capture_output=True)
        best = None
        for _ in range(repeat):
            out = subprocess.run([str(exe), str(n)], check=True, capture_output=True, text=True).stdout
            sec = float(out.split()[2])
            best = sec if best is None else min(best, sec)
    return best, f"gcc -O2 {C_LIMIT_SOURCE.name}"


def _row(case: str, samples: int | None, seconds: float | None, *, rate: bool = True, note: str = "") -> dict:
    return {
        "case": case,
        "samples": samples,
        "seconds": seconds,
        "rate": (samples / seconds) if (rate and samples and seconds) else None,
        "ratio": None,
        "note": note,
    }


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Measure every case once (best of ``--repeat`` in process) and return the table rows."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=N_SAMPLES, help="samples in the record")
    p.add_argument("--samples", type=int, default=2, help="mavins samples per update (coning order)")
    p.add_argument("--repeat", type=int, default=3, help="in-process repeats; the best is reported")
    p.add_argument("--no-cli", action="store_true", help="skip the mavins nav CSV round trip")
    p.add_argument("--no-subprocess", action="store_true", help="skip warm-start and cold-start rows")
    args = p.parse_args(list(argv))
    NOTES.clear()
    n, ns, rep = args.n, args.samples, args.repeat

    def log(msg: str) -> None:
        print(f"[bench_nav] {msg}", file=sys.stderr, flush=True)

    log(f"building {n:,}-sample record")
    t, dtheta, dv = make_input(n)

    rows: list[dict] = []
    compare: list[dict] = []  # rows that get a ratio against pyins' timed part

    log("C limit")
    c_sec, c_note = time_c_limit(n, max(rep, 3))
    rows.append(_row("C limit (scalar 2-sample WGS-84)", n, c_sec, note=c_note))
    log("mavins kernel")
    r = _row(f"mavins compute (kernel, samples={ns})", n, time_kernel(t, dtheta, dv, ns, rep),
             note=f"{n // ns:,} updates")
    rows.append(r)
    compare.append(r)
    if c_sec is not None:
        NOTES.append(f"mavins kernel (samples={ns}) at {c_sec / r['seconds']:.2f} of the C limit's speed "
                     f"({n / c_sec / 1e6:.2f} M samples/s), same run")
    if ns != 1:
        r = _row("mavins compute (kernel, samples=1)", n, time_kernel(t, dtheta, dv, 1, rep),
                 note=f"{n:,} updates, no coning")
        rows.append(r)
        compare.append(r)

    log("mavins navigate()")
    sec, ours = time_navigate(t, dtheta, dv, ns, rep)
    r = _row(f"mavins navigate() total (samples={ns})", n, sec, note="kernel + state/units")
    rows.append(r)
    compare.append(r)

    log("pyins")
    py_sec, theirs, status = time_pyins(t, dtheta, dv, rep)
    if py_sec is None:
        rows.append(_row("pyins compute", n, None, note="pyins missing"))
        NOTES.append(status)
    else:
        r = _row("pyins compute (timed part)", n, py_sec, note=f"{n:,} updates, coning+integrate")
        rows.append(r)
        compare.append(r)
        NOTES.append(sanity_note(ours, theirs))
        log("pyins numba loop alone (reference)")
        loop = time_pyins_loop(t, dtheta, dv, rep)
        if loop is not None:
            r = _row("pyins integrate loop only (reference)", n, loop, note="numba loop; no coning, pandas, Euler")
            rows.append(r)
            compare.append(r)
            NOTES.append(f"mavins kernel (samples={ns}) vs pyins integrate loop alone: {loop / rows[0]['seconds']:.2f}x")

    if not args.no_cli:
        log("mavins nav CLI (writing the CSV first)")
        with tempfile.TemporaryDirectory(prefix="bench_nav_") as tmp:
            cli = time_cli(t, dtheta, dv, ns, Path(tmp))
            log("pyins end to end (a fresh process on the same CSV)")
            py_wall = time_pyins_end_to_end(Path(tmp))
        rows.append(_row("mavins nav CLI: read", n, cli["read_s"], note=f"{cli['csv_mb']:.0f} MB CSV"))
        r = _row("mavins nav CLI: compute", n, cli["compute_s"], note="incl. kernel load")
        rows.append(r)
        compare.append(r)
        rows.append(_row("mavins nav CLI: write", n // ns, cli["write_s"], note="solution CSV"))
        rows.append(_row("mavins nav CLI: process wall", n, cli["wall_s"], note="start to exit"))
        if py_wall is not None:
            rows.append(_row("pyins end to end: process wall", n, py_wall,
                             note="read CSV (pandas), JIT, coning + integrate, write CSV"))
            NOTES.append(f"end to end, process start to exit on the same CSV: mavins nav {cli['wall_s']:.3f} s, "
                         f"pyins {py_wall:.3f} s: {py_wall / cli['wall_s']:.2f}x (goal >= 3x)")

    if not args.no_subprocess:
        log("warm start (fresh process, numba cache present)")
        warm = first_call(_MAVINS_FIRST)
        rows.append(_row("mavins warm start (import + 1st call)", WARMUP_SAMPLES, warm["import_s"] + warm["call_s"],
                         rate=False, note=f"import {warm['import_s']:.2f} s + call {warm['call_s']:.2f} s"))
        for label, aot in (("kernels built at install", "1"), ("JIT only, MAVINS_AOT=0: compile", "0")):
            log(f"cold start (fresh process, empty NUMBA_CACHE_DIR, {label})")
            with tempfile.TemporaryDirectory(prefix="bench_nav_numba_") as cache:
                cold = first_call(_MAVINS_FIRST, {"NUMBA_CACHE_DIR": cache, "MAVINS_AOT": aot})
            rows.append(_row(f"mavins cold start, {label} (import + 1st call)", WARMUP_SAMPLES,
                             cold["import_s"] + cold["call_s"], rate=False,
                             note=f"import {cold['import_s']:.2f} s + call {cold['call_s']:.2f} s"))
        if py_sec is not None:
            log("pyins first call (fresh process; pyins has no numba cache)")
            pyc = first_call(_PYINS_FIRST)
            rows.append(_row("pyins first call (import + JIT)", WARMUP_SAMPLES, pyc["import_s"] + pyc["call_s"],
                             rate=False, note=f"import {pyc['import_s']:.2f} s + call {pyc['call_s']:.2f} s"))

    if py_sec is not None:
        for r in compare:
            r["ratio"] = py_sec / r["seconds"]
        NOTES.insert(0, f"ratio = pyins compute seconds / row seconds, same {n:,}-sample record, this run; "
                        f"in-process rows are the best of {rep}.")
    return rows


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

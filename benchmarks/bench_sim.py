"""The simulator: generation speed against pyins, and how soon `mavins sim --stream` sends.

Generation: every built-in scenario at its own rate and length, made by
``sim.generate.generate`` (exact motion, sensor errors, truth) after a short
warm-up run in the same process (kernels loaded); pyins's ``generate_imu``
(``sensor_type="increment"``) on the same truth (time, position, attitude and
velocity at every sample), so both make the same number of IMU samples of the
same path. pyins models no vibration: where a scenario vibrates (``flight``:
240 sinusoids up to 90 Hz, ``car``), mavins integrates it and pyins does not;
those scenarios are timed once more without their perturbations (the same
path as pyins's model).
The ratio is pyins's seconds over ours (above 1: we are faster); the goal
(issue 33) is at least as fast.

First message: ``mavins sim NAME --stream udpout:127.0.0.1:PORT`` started as a
user starts it (a new process, kernels built at install), seconds from the
process start to the first datagram at a UDP socket of this script. Goal: 1 s.

Run: ``.venv/bin/python benchmarks/bench_sim.py`` (about 1 minute).
"""
from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "pyins generate_imu on the same truth, in the same run (ratio: pyins s / mavins s)"
NOTES: list[str] = []
FIRST_MESSAGE_GOAL_S = 1.0


def generation(name: str, repeat: int, still: bool = False) -> dict:
    """One scenario: mavins's and pyins's seconds (best of ``repeat``) for the same samples; with
    ``still`` the scenario without its perturbations (vibration, coning: what pyins does not model)."""
    import dataclasses

    from sim.generate import generate
    from sim.scenarios import load

    sc = load(name)
    if still:
        sc = dataclasses.replace(sc, doc={k: v for k, v in sc.doc.items() if k != "perturbations"})
    generate(sc, duration=1.0)  # kernels loaded, caches warm
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        run = generate(sc)
        best = min(best, time.perf_counter() - t0)
    n = len(run.t)
    row = {"case": f"generate {name}{' without vibration' if still else ''} ({run.rate:g} Hz)", "samples": n, "seconds": best, "per s": n / best}
    try:
        from pyins import sim as pyins_sim
    except ImportError:
        NOTES.append("pyins (python-ins) is not installed: no ratios")
        return row
    tr = run.exact.truth
    ref = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        pyins_sim.generate_imu(tr[:, 0], tr[:, 1:4], tr[:, 7:10], tr[:, 4:7], sensor_type="increment")
        ref = min(ref, time.perf_counter() - t0)
    row.update(ratio=ref / best, value=f"pyins {ref:.2f} s ({n / ref:,.0f}/s)",
               goal=f">= 1: {'met' if ref / best >= 1.0 else 'not met'}")
    return row


def first_message(name: str, timeout: float = 120.0) -> dict:
    """Seconds from starting ``mavins sim NAME --stream`` to its first datagram."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(timeout)
    port = rx.getsockname()[1]
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "mavins.cli", "sim", name, "--stream", f"udpout:127.0.0.1:{port}"],
                            cwd=ROOT, stderr=subprocess.DEVNULL)
    try:
        rx.recv(65536)
        first = time.perf_counter() - t0
    finally:
        proc.kill()
        proc.wait()
        rx.close()
    return {"case": f"sim {name} --stream: first datagram", "seconds": first,
            "goal": f"<= {FIRST_MESSAGE_GOAL_S:g} s: {'met' if first <= FIRST_MESSAGE_GOAL_S else 'not met'}"}


def main(argv: Sequence[str] = ()) -> list[dict]:
    p = argparse.ArgumentParser(prog="bench_sim", description=__doc__.split("\n")[0])
    p.add_argument("--repeat", type=int, default=3, help="timed repeats per scenario (best reported)")
    p.add_argument("--quick", action="store_true", help="one repeat, three scenarios")
    args = p.parse_args(list(argv))
    from sim.scenarios import builtin_names, load

    names = ["static", "flight", "rins"] if args.quick else builtin_names()
    repeat = 1 if args.quick else args.repeat
    load0 = os.getloadavg()[0]
    NOTES.clear()
    rows = [generation(n, repeat) for n in names]
    rows += [generation(n, repeat, still=True) for n in names if "perturbations" in load(n).doc]
    rows += [first_message(n) for n in names]
    NOTES.append(f"load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end; "
                 f"{os.cpu_count()} cores")
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

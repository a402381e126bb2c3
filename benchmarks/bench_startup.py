"""Start-up of the live path: process start to the first navigated output of ``mavins run``.

Each command is started twice on a new, empty numba cache (cold, then warm),
once taking the kernels the install built ahead of time (mavins/core/aot.py)
and once with ``MAVINS_AOT=0`` (JIT only: what an install without a C
compiler gets). The service loads (built, or warm cache) or compiles (cold,
JIT only) every kernel before it binds its link, prints ``ready: listening on``, then aligns over
0.2 s of sensor time on a static HIGHRES_IMU stream sent by this script as
soon as it reads that line (100 Hz sensor time, sent at 1 kHz), and
publishes. Reported: seconds from process start to ``ready`` and to the first
ATTITUDE it publishes. Then ``mavins demo`` (a 12 s flight, no recording):
seconds from process start to its NAVIGATING line, cold and warm; it
simulates the flight first, then runs the same warm-up as the service, then
aligns over 5 s of sensor time at its default pace (5x). Goal (issue 13): a
cold start under 5 s.
"""
from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "the same command with a warm numba cache, in the same run"
NOTES: list[str] = []
GOAL_S = 5.0


def _port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _env(cache: str, built: bool) -> dict[str, str]:
    """The environment of one start: numba's cache folder, and whether the kernels built at install
    are taken (MAVINS_AOT; without them every kernel compiles or loads from the cache)."""
    return dict(os.environ, NUMBA_CACHE_DIR=cache, MAVINS_AOT="1" if built else "0")


def start_once(cache: str, built: bool, timeout: float = 300.0) -> tuple[float, float]:
    """(s to 'ready', s to the first ATTITUDE) of one `mavins run` with NUMBA_CACHE_DIR=cache."""
    from mavins.link.mavlink import mavlink

    p_in, p_out = _port(), _port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", p_out))
    rx.settimeout(0.2)
    env = _env(cache, built)
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "mavins.cli", "run", "--master", f"udpin:127.0.0.1:{p_in}",
                             "--out", f"udpout:127.0.0.1:{p_out}", "--lat", "45", "--lon", "7", "--alt", "100",
                             "--heading", "0", "--align", "0.2"], env=env, cwd=ROOT, stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True)
    ready = threading.Event()
    t_ready = [float("nan")]

    def watch() -> None:
        for line in proc.stderr:  # type: ignore[union-attr]
            if "ready: listening on" in line and not ready.is_set():
                t_ready[0] = time.perf_counter() - t0
                ready.set()

    threading.Thread(target=watch, daemon=True).start()
    stop = threading.Event()

    def feed() -> None:
        ready.wait(timeout)
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        i = 0
        while not stop.is_set() and i < 100_000:
            i += 1
            msg = mav.highres_imu_encode(10_000 * i, 0.0, 0.0, -9.80665, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4, 1013.0, 0.0,
                                         100.0, 20.0, 0b111111111, 0)
            tx.sendto(msg.pack(mav), ("127.0.0.1", p_in))
            time.sleep(0.001)

    threading.Thread(target=feed, daemon=True).start()
    parser = mavlink.MAVLink(None)
    t_first = float("nan")
    try:
        while time.perf_counter() - t0 < timeout:
            try:
                data = rx.recv(65535)
            except TimeoutError:
                continue
            msgs = parser.parse_buffer(data) or []
            if any(m.get_type() == "ATTITUDE" for m in msgs):
                t_first = time.perf_counter() - t0
                break
    finally:
        stop.set()
        proc.terminate()
        proc.wait(timeout=30)
        rx.close()
    return t_ready[0], t_first


def demo_once(cache: str, built: bool, timeout: float = 600.0) -> float:
    """Seconds from process start to the NAVIGATING line of one ``mavins demo`` (a 12 s flight at
    the default pace, no recording) with NUMBA_CACHE_DIR=cache: what the user waits for the first
    navigated sample (simulation, the service's warm-up, 5 s of alignment at 5x)."""
    env = _env(cache, built)
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "mavins.cli", "demo", "--duration", "12", "--no-rerun"], env=env,
                            cwd=ROOT, stderr=subprocess.STDOUT, stdout=subprocess.PIPE, text=True)
    t_nav = float("nan")
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            if "NAVIGATING:" in line and t_nav != t_nav:
                t_nav = time.perf_counter() - t0
            if time.perf_counter() - t0 > timeout:
                break
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=30)
    return t_nav


def main(argv: Sequence[str] = ()) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="accepted for run_all; the runs are the same")
    p.parse_args(list(argv))
    from mavins.core import aot

    rows = []
    built_ok = all(aot.is_built(p) for p in aot.PACKAGES)
    if not built_ok:
        NOTES.append("the kernels are not built for this source (python -m mavins.core.aot): "
                     "the 'built at install' rows are the JIT's")
    for built, how in ((True, "kernels built at install"), (False, "JIT only (MAVINS_AOT=0)")):
        for command, once in (("mavins run", start_once), ("mavins demo", demo_once)):
            with tempfile.TemporaryDirectory() as cache:
                for case in ("cold (empty numba cache)", "warm (cache from the cold run)"):
                    got = once(cache, built)
                    t_first, value = (got[1], f"ready after {got[0]:.2f} s") if isinstance(got, tuple) else (got, "")
                    goal = f"< {GOAL_S:g} s: {'met' if t_first < GOAL_S else 'MISS'}" \
                        if case.startswith("cold") and built else ""
                    what = "first navigated output" if command == "mavins run" else "first navigated sample"
                    rows.append({"case": f"{command} start-up, {how}, {case}: {what}", "seconds": t_first,
                                 "value": value, "goal": goal})
    return rows


if __name__ == "__main__":
    for r in main(sys.argv[1:]):
        print(f"{r['case']}: {r['seconds']:.2f} s" + (f" ({r['value']})" if r.get("value") else "") + f" {r['goal']}")

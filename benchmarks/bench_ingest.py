"""Sustained UDP ingest of ``mavins run``: the goal rate, then the highest loss-free rate.

A separate sender process sends pre-encoded HIGHRES_IMU frames at a fixed rate (paced in 0.5 ms ticks).
Loss = frames sent - ``imu_accepted`` from the service's exit summary; the socket's kernel drop counter
(``/proc/net/udp``) and the service's ``flood_dropped`` say where a loss happened. The solution must stay
correct: final attitude and position against the known truth of the static record (service_harness).
First the goal rate (10 kHz) for 60 s, then the highest loss-free rate is searched (doubling, then
bisection, 10 s runs) and confirmed with a 60 s run. Baseline, measured in the same run: the pymavlink
parse ceiling (one ``parse_buffer`` call per frame, in process).

Run from the repository root::

    .venv/bin/python benchmarks/bench_ingest.py [--quick]"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from service_harness import (
    ATT_TOL_DEG, GOAL_RATE, HARNESS, NOTES, POS_TOL_M, ROOT, ServiceProc, _row, _verdict, free_udp_port,
    highres_frames, log, proc_cpu_seconds, read_last_row, solution_error, static_imu, udp_socket_stats
)


# --- sustained ingest ------------------------------------------------------------------
@dataclass
class Trial:
    rate: float
    seconds: float
    sent: int = 0
    accepted: int = 0
    kernel_drops: int = 0
    flood_dropped: int = 0
    rejected: int = 0
    max_queue_kb: float = 0.0
    att_err_deg: float = float("inf")
    pos_err_m: float = float("inf")
    achieved_rate: float = 0.0
    sender_cpu_pct: float = 0.0
    service_cpu_pct: float = 0.0
    final_state: str = ""
    error: str = ""

    @property
    def loss(self) -> int:
        return self.sent - self.accepted

    @property
    def sender_ok(self) -> bool:
        return self.achieved_rate >= 0.97 * self.rate

    @property
    def correct(self) -> bool:
        return self.att_err_deg <= ATT_TOL_DEG and self.pos_err_m <= POS_TOL_M

    @property
    def ok(self) -> bool:
        return not self.error and self.sent > 0 and self.loss == 0 and self.correct and self.sender_ok

    def describe(self) -> str:
        if self.error:
            return f"error: {self.error}"
        parts = [f"loss {self.loss:,}"]
        if self.loss:
            parts.append(f"(kernel {self.kernel_drops:,}, flood {self.flood_dropped:,}, rejected {self.rejected:,})")
        parts.append(f"att err {self.att_err_deg:.1e} deg")
        parts.append(f"svc cpu {self.service_cpu_pct:.0f} %")
        if not self.sender_ok:
            parts.append(f"sender reached only {self.achieved_rate:,.0f}/s")
        return ", ".join(parts)


def ingest_trial(rate: float, seconds: float, workdir: Path) -> Trial:
    """One run: the sender at ``rate`` for ``seconds`` into a fresh ``mavins run``."""
    tr = Trial(rate, seconds)
    gyro, accel = static_imu()
    port = free_udp_port()
    out_csv = workdir / f"ingest_{int(rate)}_{int(seconds)}.csv"
    sender = subprocess.Popen(
        [sys.executable, str(HARNESS), "--sender", str(port), repr(rate), repr(seconds),
         *map(repr, gyro), *map(repr, accel)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    svc = ServiceProc(port, ["-o", str(out_csv)], max_duration=seconds + 120)
    try:
        assert sender.stdout is not None and sender.stdin is not None
        if sender.stdout.readline().strip() != "ready":
            raise RuntimeError("sender did not start")
        svc.start()
        cpu0, w0 = proc_cpu_seconds(svc.pid), time.monotonic()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        max_q = 0
        while sender.poll() is None:
            st = udp_socket_stats(port)
            if st is not None:
                max_q = max(max_q, st[0])
            time.sleep(0.1)
        stats = json.loads(sender.stdout.readline())
        svc.drain()
        cpu1, w1 = proc_cpu_seconds(svc.pid), time.monotonic()
        st = udp_socket_stats(port)
        tr.kernel_drops = st[1] if st else 0
        c = svc.stop()
        tr.sent = int(stats["sent"])
        tr.achieved_rate = tr.sent / stats["seconds"] if stats["seconds"] > 0 else 0.0
        tr.sender_cpu_pct = 100.0 * stats["cpu_s"] / stats["seconds"] if stats["seconds"] > 0 else 0.0
        tr.service_cpu_pct = 100.0 * (cpu1 - cpu0) / (w1 - w0)
        tr.accepted = c.get("imu_accepted", 0)
        tr.flood_dropped = c.get("flood_dropped", 0)
        tr.rejected = sum(v for k, v in c.items() if k.startswith("rejected_"))
        tr.max_queue_kb = max_q / 1024.0
        tr.final_state = next((ln.split(": ", 2)[2] for ln in svc.lines if ln.startswith("mavins run: final state")), "")
        tr.att_err_deg, tr.pos_err_m = solution_error(read_last_row(out_csv))
    except Exception as exc:  # noqa: BLE001 - reported in the table
        tr.error = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    finally:
        if sender.poll() is None:
            sender.kill()
        sender.wait()
        svc.stop()
    log(f"  {rate:,.0f}/s x {seconds:g} s: {'OK' if tr.ok else 'FAIL'} - {tr.describe()}")
    return tr


def find_max_rate(start: float, seconds: float, workdir: Path, cap: float, tol: float) -> tuple[float | None, list[Trial]]:
    """Highest loss-free rate by doubling from ``start`` then bisecting to ``tol`` (relative)."""
    trials: list[Trial] = []
    lo: float | None = None
    hi: float | None = None
    r = start
    while True:
        t = ingest_trial(r, seconds, workdir)
        trials.append(t)
        if t.ok:
            lo = r
            if hi is not None or r * 2 > cap:
                break
            r *= 2
        else:
            hi = r
            if lo is not None or r / 2 < 250:
                break
            r /= 2
    while lo is not None and hi is not None and (hi - lo) / lo > tol:
        mid = round((lo + hi) / 2 / 100) * 100
        if mid in (lo, hi):
            break
        t = ingest_trial(mid, seconds, workdir)
        trials.append(t)
        if t.ok:
            lo = mid
        else:
            hi = mid
    return lo, trials


def parse_ceiling(n: int = 200_000) -> float:
    """Frames/s pymavlink parses, one ``parse_buffer`` call per frame (in process, best of 3)."""
    from mavins.link.mavlink import mavlink

    gyro, accel = static_imu()
    frames, _ = highres_frames(n, 1000.0, gyro, accel)
    bufs = [r.tobytes() for r in frames]
    best = math.inf
    for _ in range(3):
        p = mavlink.MAVLink(None)
        p.robust_parsing = True
        parse = p.parse_buffer
        t0 = time.perf_counter()
        for b in bufs:
            parse(b)
        best = min(best, time.perf_counter() - t0)
    return n / best

BASELINE = "pymavlink parse_buffer ceiling (measured in this run)"


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Sustained UDP ingest of ``mavins run`` at the goal rate, then the highest loss-free rate."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="short runs for development (seconds, not minutes)")
    p.add_argument("--goal-seconds", type=float, default=60.0, help="length of the 10 kHz and confirmation runs")
    p.add_argument("--search-seconds", type=float, default=10.0, help="length of each rate-search run")
    p.add_argument("--cap", type=float, default=160_000.0, help="highest rate the search tries")
    p.add_argument("--tol", type=float, default=0.05, help="relative resolution of the rate search")
    p.add_argument("--skip", action="append", default=[], choices=("ingest", "search"),
                   help="leave a part out (repeatable)")
    args = p.parse_args(list(argv))
    if args.quick:
        args.goal_seconds, args.search_seconds, args.tol = 5.0, 3.0, 0.25
    NOTES.clear()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_ingest_") as tmp:
        work = Path(tmp)
        ceiling = None
        if "ingest" not in args.skip or "search" not in args.skip:
            log("pymavlink parse ceiling (in process)")
            ceiling = parse_ceiling(50_000 if args.quick else 200_000)
            rows.append(_row("ingest baseline: pymavlink parse_buffer, 1 frame/call", rate=ceiling,
                             value=f"{1e6 / ceiling:.1f} us/frame", ratio=1.0, baseline="(is the baseline)",
                             note="in process, no socket: the ceiling of any pymavlink receiver"))
        ingest_rows: list[dict] = []
        if "ingest" not in args.skip:
            log(f"sustained ingest at the goal rate, {GOAL_RATE:,.0f}/s for {args.goal_seconds:g} s")
            t = ingest_trial(GOAL_RATE, args.goal_seconds, work)
            ingest_rows.append(_row(f"UDP ingest {GOAL_RATE / 1000:g} kHz x {args.goal_seconds:g} s",
                                    samples=t.sent, seconds=args.goal_seconds, rate=t.achieved_rate,
                                    value=f"loss {t.loss:,}", ratio=(t.achieved_rate / ceiling) if ceiling else None,
                                    baseline="pymavlink parse ceiling",
                                    goal=(f">=10,000/s, 60 s, 0 loss: {_verdict(t.ok)}" if args.goal_seconds >= 60
                                          else f"0 loss: {_verdict(t.ok)} (run < 60 s)"),
                                    note=t.describe()))
        if "search" not in args.skip:
            log(f"highest loss-free rate: {args.search_seconds:g} s runs, doubling then bisecting")
            best, trials = find_max_rate(GOAL_RATE, args.search_seconds, work, args.cap, args.tol)
            tried = ", ".join(f"{t.rate / 1000:g}k {'ok' if t.ok else 'x'}" for t in trials)
            NOTES.append(f"rate search ({args.search_seconds:g} s runs): {tried}")
            for t in trials:
                if not t.ok:
                    NOTES.append(f"  {t.rate:,.0f}/s failed: {t.describe()}, socket queue max {t.max_queue_kb:,.0f} KiB")
            confirmed: Trial | None = None
            r = best
            for _ in range(3):
                if r is None:
                    break
                log(f"confirming {r:,.0f}/s for {args.goal_seconds:g} s")
                t = ingest_trial(r, args.goal_seconds, work)
                if t.ok:
                    confirmed = t
                    break
                NOTES.append(f"confirmation at {r:,.0f}/s failed: {t.describe()}")
                r = round(r * 0.9 / 100) * 100
            if confirmed is not None:
                ingest_rows.append(_row(f"UDP ingest, highest loss-free ({args.goal_seconds:g} s)",
                                        samples=confirmed.sent, seconds=args.goal_seconds,
                                        rate=confirmed.achieved_rate, value=f"{confirmed.rate:,.0f}/s",
                                        ratio=(confirmed.achieved_rate / ceiling) if ceiling else None,
                                        baseline="pymavlink parse ceiling",
                                        goal=f">=10,000/s: {_verdict(confirmed.rate >= GOAL_RATE)}",
                                        note=confirmed.describe()))
                if confirmed.service_cpu_pct > 0:
                    NOTES.append(f"at {confirmed.rate:,.0f}/s the service used {confirmed.service_cpu_pct:.0f} % "
                                 f"of a core ({10 * confirmed.service_cpu_pct / confirmed.rate * 1000:.1f} us "
                                 f"CPU per message); the sender {confirmed.sender_cpu_pct:.0f} %")
            else:
                ingest_rows.append(_row("UDP ingest, highest loss-free", value="none confirmed",
                                        goal=">=10,000/s: NOT met", note=tried))
        rows += ingest_rows
    return rows


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

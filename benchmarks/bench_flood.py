"""``mavins run`` under a flood: 250 Hz, then 200 kHz on a wall-clock schedule for 6 s, then 250 Hz
(sensor time = the schedule): input over what was processed, ATTITUDE per second (of wall time before,
of sensor time during), navigated sensor time over wall time, RSS growth, drops counted, HEARTBEAT
interval. These rows hold the figures tests/faces/test_hardening.py once asserted on timing; the tests
now check the behaviour by events and counts.

Run from the repository root::

    .venv/bin/python benchmarks/bench_flood.py [--quick]"""

from __future__ import annotations

import argparse
import json
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from service_harness import (
    NOTES, ROOT, ServiceProc, T0_USEC, _row, _verdict, free_udp_port, highres_frames, log, proc_rss_mb,
    static_imu, udp_socket_stats
)


# --- flood -------------------------------------------------------------------------------
#: The flood of tests/faces/test_hardening.py's former timed checks: 250 Hz, then FLOOD_HZ, then 250 Hz again,
#: sensor time advancing with the sender's schedule (real time) whatever the rate.
FLOOD_HZ, FLOOD_S, FLOOD_PRE_S, FLOOD_POST_S = 200_000.0, 6.0, 3.0, 3.0


FLOOD_OUT_RATE = 50.0


def flood_schedule(pre_s: float, flood_hz: float, flood_s: float, post_s: float) -> np.ndarray:
    """Send times (s from the start) = sensor times of the flood run's samples."""
    return np.concatenate([np.arange(0, pre_s, 1 / 250), pre_s + np.arange(0, flood_s, 1 / flood_hz),
                           pre_s + flood_s + np.arange(0, post_s, 1 / 250)])


def flood_sender_main(argv: Sequence[str]) -> int:
    """``--flood-sender PORT PRE_S FLOOD_HZ FLOOD_S POST_S GX GY GZ AX AY AZ``: send the flood on schedule."""
    port = int(argv[0])
    pre_s, flood_hz, flood_s, post_s = (float(x) for x in argv[1:5])
    gyro = [float(x) for x in argv[5:8]]
    accel = [float(x) for x in argv[8:11]]
    sched = flood_schedule(pre_s, flood_hz, flood_s, post_s)
    frames, _ = highres_frames(len(sched), 1.0, gyro, accel, times=T0_USEC + np.round(sched * 1e6))
    flen = frames.shape[1]
    mv = memoryview(frames.tobytes())
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)  # replies are not read
    sock.connect(("127.0.0.1", port))
    send = sock.send
    print("ready", flush=True)
    sys.stdin.readline()
    wall0, m0 = time.time(), time.monotonic()
    n, i, errors = len(sched), 0, 0
    while i < n:
        due = int(np.searchsorted(sched, time.monotonic() - m0, side="right"))
        while i < due:
            try:
                send(mv[i * flen:(i + 1) * flen])
            except OSError:
                errors += 1
            i += 1
        if i < n:
            wait = sched[i] - (time.monotonic() - m0)
            if wait > 0.0005:
                time.sleep(min(wait, 0.002))
    elapsed = time.monotonic() - m0
    flood_sent = int(np.sum((sched >= pre_s) & (sched < pre_s + flood_s)))
    print(json.dumps({"sent": n - errors, "flood_sent": flood_sent, "wall0": wall0, "seconds": elapsed}), flush=True)
    return 0


class StampedClient:
    """Receives a service's ``--out`` with kernel stamps: ATTITUDE (arrival, time_boot_ms), HEARTBEAT arrivals,
    SYS_STATUS (arrival, message)."""

    def __init__(self) -> None:
        from mavins.link.mavlink import mavlink

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_TIMESTAMP", 29), 1)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.attitude: list[tuple[float, int]] = []
        self.heartbeat: list[float] = []
        self.sys_status: list[tuple[float, object]] = []
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        so_ts = getattr(socket, "SO_TIMESTAMP", 29)
        while not self._stop.is_set():
            if not select.select([self.sock], [], [], 0.05)[0]:
                continue
            data, anc, _, _ = self.sock.recvmsg(65535, 64)
            arrival = time.time()
            for level, kind, value in anc:
                if level == socket.SOL_SOCKET and kind == so_ts and len(value) >= 16:
                    sec, usec = struct.unpack("qq", value[:16])
                    arrival = sec + usec * 1e-6
            for m in self._parser.parse_buffer(data) or []:
                name = m.get_type()
                if name == "ATTITUDE":
                    self.attitude.append((arrival, m.time_boot_ms))
                elif name == "HEARTBEAT":
                    self.heartbeat.append(arrival)
                elif name == "SYS_STATUS":
                    self.sys_status.append((arrival, m))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


def flood_run(flood_hz: float = FLOOD_HZ, flood_s: float = FLOOD_S, pre_s: float = FLOOD_PRE_S,
              post_s: float = FLOOD_POST_S) -> dict:
    """``mavins run`` through a flood: what it processed, its output rate, memory and HEARTBEAT meanwhile."""
    gyro, accel = static_imu()
    port = free_udp_port()
    client = StampedClient()
    sender = subprocess.Popen(
        [sys.executable, str(Path(__file__).resolve()), "--flood-sender", str(port), repr(pre_s), repr(flood_hz),
         repr(flood_s), repr(post_s), *map(repr, gyro), *map(repr, accel)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    total = pre_s + flood_s + post_s
    svc = ServiceProc(port, ["--rate", str(FLOOD_OUT_RATE), "--out", f"udpout:127.0.0.1:{client.port}"],
                      max_duration=total + 120)
    rss: list[tuple[float, float]] = []
    stop_mon = threading.Event()
    try:
        assert sender.stdout is not None and sender.stdin is not None
        if sender.stdout.readline().strip() != "ready":
            raise RuntimeError("flood sender did not start")
        svc.start()

        def monitor() -> None:
            while not stop_mon.is_set():
                v = proc_rss_mb(svc.pid)
                if v is not None:
                    rss.append((time.time(), v))
                time.sleep(0.2)

        mon = threading.Thread(target=monitor, daemon=True)
        mon.start()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        sender.wait(total * 10 + 120)
        stats = json.loads(sender.stdout.readline())
        svc.drain(30.0)
        time.sleep(1.0)
        stop_mon.set()
        mon.join(2.0)
        st = udp_socket_stats(port)
        c = svc.stop()
    finally:
        stop_mon.set()
        if sender.poll() is None:
            sender.kill()
        sender.wait()
        svc.stop()
        client.close()
    w0 = stats["wall0"]
    wall = {"pre": w0, "flood": w0 + pre_s, "post": w0 + pre_s + flood_s, "end": w0 + total}
    return {"stats": stats, "counters": c, "wall": wall, "rss": rss, "client": client,
            "kernel_drops_proc": st[1] if st else None, "pre_s": pre_s, "flood_s": flood_s, "post_s": post_s,
            "flood_hz": flood_hz}


def flood_rows(fr: dict) -> list[dict]:
    """Table rows of a flood run (the figures tests/faces/test_hardening.py once asserted on timing)."""
    c, st, wall, cl = fr["counters"], fr["stats"], fr["wall"], fr["client"]
    sent, processed = int(st["sent"]), int(c.get("messages_received", 0))
    dropped = int(c.get("flood_dropped", 0))
    label = f"flood {fr['flood_hz'] / 1000:g} kHz x {fr['flood_s']:g} s"
    rows = []
    ratio = sent / processed if processed else float("inf")
    rows.append(_row(f"{label}: datagrams sent / processed", samples=sent, seconds=st["seconds"],
                     rate=st["flood_sent"] / fr["flood_s"], value=f"{ratio:.1f}x",
                     goal=f">= 3x (a real overload): {_verdict(ratio >= 3.0)}",
                     note=f"processed {processed:,}; per s = flood datagrams / flood seconds scheduled"))
    # output rate: per wall second before the flood (the sender keeps its schedule), per second of sensor
    # time during it (a Python sender cannot send 200,000 a second on time)
    arr = np.array([a for a, _ in cl.attitude]) if cl.attitude else np.zeros(0)
    edges = np.arange(wall["pre"] + 1.5, wall["flood"] - 0.999, 1.0)
    before = [int(np.sum((arr >= e) & (arr < e + 1.0))) for e in edges]
    during = [(a, ms) for a, ms in cl.attitude if wall["flood"] + 1.0 <= a <= wall["post"]]
    ms = np.array([m for _, m in during], dtype=np.int64)
    sec = ms // 1000
    whole = np.unique(sec)[1:-1]
    per_sensor_s = [int(np.sum(sec == k)) for k in whole]
    lo, hi = 0.8 * FLOOD_OUT_RATE, 1.2 * FLOOD_OUT_RATE

    def span(v: list[int]) -> str:
        return f"{min(v)}-{max(v)}" if v else "none"

    rows.append(_row(f"{label}: ATTITUDE per s of wall time before", value=span(before),
                     goal=f"{lo:.0f}-{hi:.0f}: {_verdict(bool(before) and all(lo <= n <= hi for n in before))}",
                     note=f"--rate {FLOOD_OUT_RATE:g}, 250 Hz input"))
    rows.append(_row(f"{label}: ATTITUDE per s of sensor time during", value=span(per_sensor_s),
                     goal=f"{lo:.0f}-{hi:.0f}: "
                          f"{_verdict(bool(per_sensor_s) and all(lo <= n <= hi for n in per_sensor_s))}",
                     note="seconds of sensor time wholly inside the flood"))
    if during:
        wall_span = during[-1][0] - during[0][0]
        sensor_span = (ms[-1] - ms[0]) / 1000.0
        adv = sensor_span / wall_span if wall_span > 0 else float("nan")
        rows.append(_row(f"{label}: navigated sensor time / wall time during", value=f"{adv:.2f}",
                         goal=f"> 0.3 (no stall, no backlog): {_verdict(adv > 0.3)}",
                         note=f"{sensor_span:.2f} s of sensor time in {wall_span:.2f} s"))
    post = [m for a, m in cl.attitude if m * 1000 >= T0_USEC + (fr["pre_s"] + fr["flood_s"] + 0.5) * 1e6]
    n_post = len(post) / max(fr["post_s"] - 0.5, 1e-9)
    rows.append(_row(f"{label}: output sets per s of sensor time after", value=f"{n_post:.0f}",
                     goal=f">= {lo:.0f}: {_verdict(n_post >= lo)}", note="from 0.5 s after the flood"))
    rss = np.array(fr["rss"], dtype=float).reshape(-1, 2)
    base = rss[(rss[:, 0] > wall["pre"] + 1.0) & (rss[:, 0] < wall["flood"]), 1]
    rest = rss[rss[:, 0] >= wall["flood"], 1]
    if len(base) and len(rest):
        grown = float(rest.max() - base.max())
        rows.append(_row(f"{label}: RSS growth", value=f"{grown:+.1f} MB", goal=f"< 20 MB: {_verdict(grown < 20)}",
                         note=f"before {base.max():.1f} MB, max during and after {rest.max():.1f} MB"))
    lost = sent - processed
    rows.append(_row(f"{label}: counted as dropped", value=f"{dropped:,} of {lost:,}",
                     goal=f"all: {_verdict(dropped == lost)}",
                     note=f"skipped {c.get('flood_skipped', 0):,}, kernel {c.get('kernel_dropped', 0):,} "
                          f"(/proc/net/udp {fr['kernel_drops_proc']})"))
    hb = np.array(cl.heartbeat)
    for name, a, b in (("before", wall["pre"] + 1.0, wall["flood"]), ("during", wall["flood"], wall["post"])):
        gaps = np.diff(hb[(hb >= a) & (hb < b)])
        if len(gaps):
            med = float(np.median(gaps))
            rows.append(_row(f"HEARTBEAT interval (wall), {name} the flood", value=f"{med:.2f} s",
                             goal=f"1 Hz, 0.8-1.3 s: {_verdict(0.8 < med < 1.3)}",
                             note=f"median of {len(gaps)}, max {float(gaps.max()):.2f} s"))
    return rows

def main(argv: Sequence[str] = ()) -> list[dict]:
    """``mavins run`` under a flood: 250 Hz, then FLOOD_HZ on a wall-clock schedule, then 250 Hz."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="a short flood for development")
    p.add_argument("--flood-seconds", type=float, default=FLOOD_S, help=f"length of the {FLOOD_HZ:,.0f}/s flood")
    args = p.parse_args(list(argv))
    if args.quick:
        args.flood_seconds = 3.0
    NOTES.clear()
    log(f"flood: 250 Hz, {FLOOD_HZ:,.0f}/s for {args.flood_seconds:g} s, 250 Hz")
    return flood_rows(flood_run(flood_s=args.flood_seconds))


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--flood-sender":
        sys.exit(flood_sender_main(sys.argv[2:]))
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

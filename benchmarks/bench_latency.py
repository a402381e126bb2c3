"""Latency and CPU of ``mavins run`` at 1 kHz, the filter off and on.

* **Latency.** HIGHRES_IMU at 1 kHz, every sample published (``--rate 1000 --samples 1``). Client side:
  ``time.perf_counter_ns()`` just before ``sendto`` of sample *i*, against the time the ATTITUDE whose
  ``time_boot_ms`` is sample *i*'s millisecond is read from the same socket (the service publishes to
  the peers of its listening link). The kernel receive timestamp (``SO_TIMESTAMPNS``) of that ATTITUDE
  gives a second figure without the client's own wake-up. Baseline in the same run: a bare Python UDP
  echo process (``recvmsg`` + ``parse_buffer`` + ``sendto`` of one ATTITUDE). With the filter on,
  GPS_RAW_INT at 5 Hz too.
* **CPU.** HIGHRES_IMU at 1 kHz, output at 50 Hz (with ``--rerun FILE.rrd``, without, filter on, 1 Hz
  out): utime + stime of the service process (``/proc/PID/stat``, all threads) over a steady window
  after the alignment, in % of one core, against a bare Python UDP receiver.

``--profile`` also records the service with py-spy (``pip install py-spy``, or ``PY_SPY=/path``) and
prints its top functions and the full collections of the garbage collector.

Run from the repository root::

    .venv/bin/python benchmarks/bench_latency.py [--quick] [--latency-seconds S] [--cpu-seconds S] [--profile]"""

from __future__ import annotations

import argparse
import json
import re
import select
import socket
import struct
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Sequence

import numpy as np

from service_harness import (
    ALIGN_S, GNSS_HZ, GOAL_CPU_PCT, GOAL_LATENCY_P99_MS, HARNESS, NOTES, ROOT, ServiceProc, _row, _stacks,
    _verdict, free_udp_port, gnss_frames, highres_frames, inclusive, line_text, log, percentile, proc_cpu_seconds,
    proc_cpu_split, proc_rss_mb, py_spy_path, static_imu, top_functions, top_lines
)


# --- latency -------------------------------------------------------------------------
ATTITUDE_ID = 30


SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)


_ECHO = r"""
import os, socket, sys
os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind(("127.0.0.1", 0))
print(s.getsockname()[1], flush=True)
p = mavlink.MAVLink(None); p.robust_parsing = True
mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
while True:
    data, addr = s.recvfrom(65535)
    if data == b"stop":
        break
    for m in p.parse_buffer(data) or ():
        ms = (m.time_usec // 1000) % (2**32)
        s.sendto(mav.attitude_encode(ms, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0).pack(mav), addr)
"""


_BARE_RECEIVER = r"""
import os, select, socket, sys
os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_TIMESTAMP", 29), 1)
s.bind(("127.0.0.1", int(sys.argv[1])))
s.setblocking(False)
p = mavlink.MAVLink(None); p.robust_parsing = True
print("listening on", flush=True)
n = 0
while True:
    try:
        data, anc, _, addr = s.recvmsg(65535, 64)
    except BlockingIOError:
        select.select([s], [], [], 0.05)
        continue
    if data == b"stop":
        break
    n += len(p.parse_buffer(data) or ())
print(n, flush=True)
"""


def latency_run(port: int, seconds: float, warm_s: float, rate: float = 1000.0, gnss_hz: float = 0.0) -> dict:
    """Send 1 kHz HIGHRES_IMU to ``port`` from one socket; match ATTITUDE replies by time_boot_ms.
    With ``gnss_hz``, a GPS_RAW_INT follows the IMU frame of its time at that rate.

    Returns per-sample latencies (ms): client-side (perf_counter before sendto
    to reading the reply) and kernel (time_ns before sendto to the reply's
    kernel receive stamp), for samples sent after ``warm_s``.
    """
    gyro, accel = static_imu()
    n = int(round(rate * (warm_s + seconds)))
    frames, usec = highres_frames(n, rate, gyro, accel)
    gnss = gnss_frames(usec, rate, gnss_hz) if gnss_hz > 0 else {}
    flen = frames.shape[1]
    mv = memoryview(frames.tobytes())
    ms_of = (usec // 1000).astype(np.int64)
    first_ms = int(ms_of[0])
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 1024 * 1024)
    sock.setblocking(False)
    addr = ("127.0.0.1", port)
    send_perf = np.zeros(n, dtype=np.int64)
    send_wall = np.zeros(n, dtype=np.int64)
    recv_perf = np.zeros(n, dtype=np.int64)
    recv_kern = np.zeros(n, dtype=np.int64)
    perf_ns, wall_ns = time.perf_counter_ns, time.time_ns
    other = Counter()

    def drain() -> None:
        while True:
            try:
                data, anc, _, _ = sock.recvmsg(512, 64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            now = perf_ns()
            if len(data) < 14 or data[0] != 0xFD:
                other["non_v2"] += 1
                continue
            msgid = data[7] | (data[8] << 8) | (data[9] << 16)
            if msgid != ATTITUDE_ID:
                other[msgid] += 1
                continue
            plen = data[1]  # MAVLink 2 drops trailing zero bytes of the payload
            ms = int.from_bytes(data[10 : 10 + min(plen, 4)], "little")
            i = ms - first_ms
            if 0 <= i < n and recv_perf[i] == 0:
                recv_perf[i] = now
                for level, kind, value in anc:
                    if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(value) >= 16:
                        sec, nsec = struct.unpack("qq", value[:16])
                        recv_kern[i] = sec * 1_000_000_000 + nsec

    period = 1e9 / rate
    t0 = perf_ns() + 50_000_000
    for i in range(n):
        target = t0 + int(i * period)
        while True:
            left = target - perf_ns()
            if left <= 0:
                break
            timeout = (left - 150_000) / 1e9 if left > 200_000 else 0.0
            r, _, _ = select.select([sock], [], [], timeout)
            if r:
                drain()
        send_wall[i] = wall_ns()
        send_perf[i] = perf_ns()
        sock.sendto(mv[i * flen : (i + 1) * flen], addr)
        if i in gnss:
            sock.sendto(gnss[i], addr)
        drain()
    end = perf_ns() + 500_000_000
    while perf_ns() < end:
        r, _, _ = select.select([sock], [], [], 0.05)
        if r:
            drain()
    sock.close()
    first = int(round(rate * warm_s))
    got = recv_perf[first:] > 0
    client = (recv_perf[first:][got] - send_perf[first:][got]) / 1e6
    kern_ok = got & (recv_kern[first:] > 0)
    kernel = (recv_kern[first:][kern_ok] - send_wall[first:][kern_ok]) / 1e6
    return {"client_ms": client, "kernel_ms": kernel, "expected": n - first, "matched": int(got.sum()),
            "other": dict(other)}


def latency_rows(label: str, res: dict, e50: float, e99: float, note: str, max_note: str) -> list[dict]:
    """The p50, p99 and max rows of one latency run against the echo's p50 and p99."""
    rows = []
    for q, eq in ((50, e50), (99, e99)):
        v = percentile(res["client_ms"], q)
        goal = f"p99 <= 1 ms: {_verdict(v <= GOAL_LATENCY_P99_MS)}" if q == 99 else None
        rows.append(_row(f"{label}, p{q}", samples=len(res["client_ms"]), value=f"{v:.3f} ms",
                         ratio=v / eq if eq > 0 else None, baseline=f"Python UDP echo p{q} {eq:.3f} ms", goal=goal,
                         note=f"{note}kernel stamps: {percentile(res['kernel_ms'], q):.3f} ms"))
    top = float(np.max(res["client_ms"])) if len(res["client_ms"]) else float("nan")
    rows.append(_row(f"{label}, max", samples=len(res["client_ms"]), value=f"{top:.3f} ms", note=max_note))
    return rows


def latency_service(seconds: float, gnss_hz: float = 0.0) -> dict:
    """Latency of ``mavins run --rate 1000 --samples 1`` (filter on: GNSS at ``gnss_hz``, when > 0); the
    service's exit counters in ``counters``."""
    port = free_udp_port()
    svc = ServiceProc(port, ["--rate", "1000", "--samples", "1"], max_duration=seconds + 60)
    svc.start()
    try:
        cpu0, w0 = proc_cpu_seconds(svc.pid), time.monotonic()
        res = latency_run(port, seconds, warm_s=ALIGN_S + 1.0, gnss_hz=gnss_hz)
        cpu = proc_cpu_seconds(svc.pid)
        res["cpu_pct"] = 100.0 * (cpu - cpu0) / (time.monotonic() - w0)
    finally:
        res_counters = svc.stop()
    res["service_cpu_s"] = cpu
    res["counters"] = res_counters
    res["lines"] = list(svc.lines)
    return res


def latency_echo(seconds: float) -> dict:
    proc = subprocess.Popen([sys.executable, "-c", _ECHO], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert proc.stdout is not None
        port = int(proc.stdout.readline())
        res = latency_run(port, seconds, warm_s=0.5)
    finally:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"stop", ("127.0.0.1", port))
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return res


# --- CPU --------------------------------------------------------------------------
def cpu_bare(seconds: float, rate: float = 1000.0) -> tuple[float, float]:
    """CPU % (total, of which kernel) of a bare Python receiver (select + recvmsg + parse_buffer) at ``rate``."""
    gyro, accel = static_imu()
    port = free_udp_port()
    total = seconds + 2.0
    sender = subprocess.Popen(
        [sys.executable, str(HARNESS), "--sender", str(port), repr(rate), repr(total),
         *map(repr, gyro), *map(repr, accel)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    recv = subprocess.Popen([sys.executable, "-c", _BARE_RECEIVER, str(port)], stdout=subprocess.PIPE, text=True,
                            cwd=ROOT)
    try:
        assert sender.stdout is not None and sender.stdin is not None and recv.stdout is not None
        sender.stdout.readline()
        recv.stdout.readline()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        time.sleep(1.0)
        (u0, s0), w0 = proc_cpu_split(recv.pid), time.monotonic()
        time.sleep(seconds)
        (u1, s1), w1 = proc_cpu_split(recv.pid), time.monotonic()
        sender.wait(total + 30)
    finally:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"stop", ("127.0.0.1", port))
        for pr in (sender, recv):
            try:
                pr.wait(5)
            except subprocess.TimeoutExpired:
                pr.kill()
                pr.wait()
    return 100.0 * (u1 + s1 - u0 - s0) / (w1 - w0), 100.0 * (s1 - s0) / (w1 - w0)


def cpu_run(seconds: float, rerun: Path | None, rate: float = 1000.0, out_rate: float = 50.0,
            gnss_hz: float = 0.0) -> dict:
    """Service CPU % of one core over a steady window at ``rate`` input, ``out_rate`` Hz output (GPS_RAW_INT
    at ``gnss_hz`` too, when > 0: the filter on)."""
    gyro, accel = static_imu()
    port = free_udp_port()
    settle = ALIGN_S + 2.0
    total = settle + seconds + 1.0
    sender = subprocess.Popen(
        [sys.executable, str(HARNESS), "--sender", str(port), repr(rate), repr(total),
         *map(repr, gyro), *map(repr, accel), repr(gnss_hz)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    args = ["--rate", f"{out_rate:g}"] + (["--rerun", str(rerun)] if rerun is not None else [])
    svc = ServiceProc(port, args, max_duration=total + 60)
    try:
        assert sender.stdout is not None and sender.stdin is not None
        if sender.stdout.readline().strip() != "ready":
            raise RuntimeError("sender did not start")
        svc.start()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        time.sleep(settle)
        (u0, s0), w0 = proc_cpu_split(svc.pid), time.monotonic()
        rss0 = proc_rss_mb(svc.pid)
        time.sleep(seconds)
        (u1, s1), w1 = proc_cpu_split(svc.pid), time.monotonic()
        c0, c1 = u0 + s0, u1 + s1
        rss1 = proc_rss_mb(svc.pid)
        sender.wait(total + 30)
        stats = json.loads(sender.stdout.readline())
        svc.drain()
        c = svc.stop()
    finally:
        if sender.poll() is None:
            sender.kill()
        sender.wait()
        svc.stop()
    return {"cpu_pct": 100.0 * (c1 - c0) / (w1 - w0), "window_s": w1 - w0, "rss0": rss0, "rss1": rss1,
            "sys_pct": 100.0 * (s1 - s0) / (w1 - w0),
            "sent": stats["sent"], "accepted": c.get("imu_accepted", 0), "gnss": c.get("gnss_pos_accepted", 0),
            "sender_cpu_pct": 100.0 * stats["cpu_s"] / stats["seconds"],
            "rrd_mb": rerun.stat().st_size / 1e6 if rerun is not None and rerun.exists() else None}


SERVICE_PARTS = {
    "Service.run itself (the loop, not select)": r"(^|;)Service\.run \([^;]*$",
    "UdpLink.receive (recvmsg + pymavlink parse)": r"(^|;)UdpLink\.receive \(",
    "  MAVLink.parse_buffer": r"(^|;)MAVLink\.parse_buffer \(",
    "Service._handle (all per-message work)": r"(^|;)Service\._handle \(",
    "  Pipeline.handle (ingest + engine + recorder)": r"(^|;)Pipeline\.handle \(",
    "    Ingest.sample": r"(^|;)Ingest\.sample \(",
    "    Engine.on_imu (alignment, kernel calls)": r"(^|;)Engine\.on_imu \(",
    "    Recorder (on_sample, on_output, flush)": r"(^|;)Recorder\.",
    "  publish.encode (5 messages)": r"(^|;)encode \([^;]*publish\.py",
    "  Service._send (pack + sendto)": r"(^|;)Service\._send \(",
    "  Service._announce (events)": r"(^|;)Service\._announce \(",
    "  UdpLink.authorize": r"(^|;)UdpLink\.authorize \(",
    "  SolutionWriter.write": r"(^|;)SolutionWriter\.write \(",
    "Service._periodic, _flood_relief": r"(^|;)Service\.(_periodic|_flood_relief) \(",
}


def profile_service(rate: float, seconds: float, workdir: Path, extra: list[str]) -> list[str]:
    """py-spy record of ``mavins run`` at ``rate``; lines describing where its time goes."""
    spy = py_spy_path()
    if spy is None:
        return ["py-spy not found (pip install py-spy, or set PY_SPY): no profile"]
    gyro, accel = static_imu()
    port = free_udp_port()
    total = ALIGN_S + 1.0 + seconds + 1.0
    sender = subprocess.Popen(
        [sys.executable, str(HARNESS), "--sender", str(port), repr(rate), repr(total),
         *map(repr, gyro), *map(repr, accel)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    svc = ServiceProc(port, extra, max_duration=total + 60)
    raw = workdir / f"service_{int(rate)}.txt"
    try:
        assert sender.stdout is not None and sender.stdin is not None
        sender.stdout.readline()
        svc.start()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        time.sleep(ALIGN_S + 1.0)
        subprocess.run([spy, "record", "-p", str(svc.pid), "-d", str(int(seconds)), "-r", "200", "--format", "raw",
                        "-o", str(raw), "--nonblocking"], capture_output=True, text=True)
        sender.wait(total + 30)
        svc.drain()
        svc.stop()
    finally:
        if sender.poll() is None:
            sender.kill()
        sender.wait()
        svc.stop()
    if not raw.exists():
        return ["py-spy produced no profile (ptrace not permitted?)"]
    top, total_samples = top_functions(raw)
    _, waiting = _stacks(raw)
    args = " ".join(re.sub(r".*/", "", a) for a in extra)
    out = [f"py-spy (200 Hz, {seconds:g} s), mavins run {args} at {rate:,.0f} HIGHRES_IMU/s: {total_samples} busy "
           f"samples (+{waiting} waiting in select, left out); % of busy samples:"]
    incl = inclusive(raw, list(SERVICE_PARTS.values()))
    out += [f"  {incl[pat]:5.1f} % incl  {name}" for name, pat in SERVICE_PARTS.items()]
    out.append("  top functions by self time (self %, inclusive %):")
    out += [f"  {s:5.1f} %  {i:5.1f} %  {n}" for n, s, i in top]
    out.append("  hottest lines of mavins itself (self %; C calls are charged to the line making them):")
    out += [f"  {pct:5.1f} %  {ref}  | {line_text(ref)}" for ref, pct in top_lines(raw)]
    return out


#: ``python -c`` script: ``mavins`` with a gc callback that reports full (generation 2) collections
#: made while serving; with ``freeze`` set, ``gc.freeze()`` runs just before the service loop (a what-if).
_GC_PROBE = r"""
import gc, json, sys, time
freeze = sys.argv.pop(1) == "freeze"
events, t = [], {}
def cb(phase, info):
    if phase == "start":
        t["s"] = time.perf_counter()
    elif info["generation"] == 2 and "serving" in t:
        events.append(time.perf_counter() - t["s"])
gc.callbacks.append(cb)
import mavins.service as service
run = service.Service.run
def probe_run(self, stop):
    if freeze:
        gc.collect()
        gc.freeze()
    t["serving"] = True
    try:
        return run(self, stop)
    finally:
        t.pop("serving")
        print("GC_PROBE " + json.dumps({"full": len(events), "max_ms": 1e3 * max(events, default=0.0),
              "total_ms": 1e3 * sum(events), "tracked": len(gc.get_objects())}), file=sys.stderr, flush=True)
service.Service.run = probe_run
from mavins.cli import main
sys.exit(main(sys.argv[1:]))
"""


def gc_pauses(seconds: float, extra: list[str], freeze: bool, rate: float = 1000.0) -> dict:
    """Full garbage collections while ``mavins run`` serves ``rate`` HIGHRES_IMU/s for ``seconds``."""
    gyro, accel = static_imu()
    port = free_udp_port()
    sender = subprocess.Popen(
        [sys.executable, str(HARNESS), "--sender", str(port), repr(rate), repr(seconds),
         *map(repr, gyro), *map(repr, accel)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
    svc = ServiceProc(port, extra, max_duration=seconds + 60,
                      command=[sys.executable, "-c", _GC_PROBE, "freeze" if freeze else "no"])
    try:
        assert sender.stdout is not None and sender.stdin is not None
        sender.stdout.readline()
        svc.start()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        sender.wait(seconds + 60)
        svc.drain()
    finally:
        if sender.poll() is None:
            sender.kill()
        sender.wait()
        svc.stop()
    for line in svc.lines:
        if line.startswith("GC_PROBE "):
            return json.loads(line[len("GC_PROBE "):])
    return {}

BASELINE = "latency: bare Python UDP echo; CPU: bare Python UDP receiver (each measured in this run)"


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Latency (IMU in -> ATTITUDE out at 1 kHz) and CPU of ``mavins run``, filter off and on."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="short runs for development (seconds, not minutes)")
    p.add_argument("--latency-seconds", type=float, default=30.0, help="measured seconds of the latency runs")
    p.add_argument("--cpu-seconds", type=float, default=20.0, help="CPU window (s)")
    p.add_argument("--skip", action="append", default=[], choices=("latency", "cpu"),
                   help="leave a part out (repeatable)")
    p.add_argument("--profile", action="store_true", help="also record the service with py-spy and print the top functions")
    p.add_argument("--profile-rate", type=float, default=15_000.0, help="input rate of the high-rate profile")
    args = p.parse_args(list(argv))
    if args.quick:
        args.latency_seconds, args.cpu_seconds = 5.0, 5.0
    NOTES.clear()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_latency_") as tmp:
        work = Path(tmp)
        if "latency" not in args.skip:
            log(f"latency baseline: bare Python UDP echo, 1 kHz, {args.latency_seconds:g} s")
            echo = latency_echo(args.latency_seconds)
            log(f"latency: mavins run --rate 1000 --samples 1, 1 kHz, {args.latency_seconds:g} s")
            lat = latency_service(args.latency_seconds)
            e50, e99 = percentile(echo["client_ms"], 50), percentile(echo["client_ms"], 99)
            rows += latency_rows("latency IMU in -> ATTITUDE out", lat, e50, e99, "1 kHz, ",
                                 f"echo max {float(np.max(echo['client_ms'])):.3f} ms")
            log(f"latency with the filter on: GPS_RAW_INT at {GNSS_HZ:g} Hz too, {args.latency_seconds:g} s")
            flt = latency_service(args.latency_seconds, gnss_hz=GNSS_HZ)
            fixes = flt["counters"].get("gnss_pos_accepted", 0)
            rows += latency_rows(f"latency, filter on (GNSS {GNSS_HZ:g} Hz)", flt, e50, e99, f"{fixes} fixes fused; ",
                                 f"p99.9 {percentile(flt['client_ms'], 99.9):.3f} ms")
            rows.append(_row("CPU at 1 kHz in, 1 kHz out, filter on", value=f"{flt['cpu_pct']:.1f} % of a core",
                             goal=f"<= 25 %: {_verdict(flt['cpu_pct'] <= 25.0)}",
                             note="over the latency run (one output set per sample)"))
            missing = lat["expected"] - lat["matched"]
            NOTES.append(f"latency: {lat['matched']:,} of {lat['expected']:,} samples after alignment got their "
                         f"ATTITUDE ({missing} missing); p99.9 {percentile(lat['client_ms'], 99.9):.3f} ms; "
                         f"echo baseline p50/p99/max {e50:.3f}/{e99:.3f}/{float(np.max(echo['client_ms'])):.3f} ms")

        if "cpu" not in args.skip:
            log(f"CPU baseline: bare Python receiver at 1 kHz ({args.cpu_seconds:g} s window)")
            bare, bare_sys = cpu_bare(args.cpu_seconds)
            log(f"CPU at 1 kHz, 50 Hz output, with --rerun ({args.cpu_seconds:g} s window)")
            with_rr = cpu_run(args.cpu_seconds, work / "cpu.rrd")
            log("CPU at 1 kHz, 50 Hz output, without Rerun")
            without = cpu_run(args.cpu_seconds, None)
            base = f"bare receiver {bare:.1f} %"
            rows.append(_row("CPU at 1 kHz in, 50 Hz out, --rerun", seconds=with_rr["window_s"],
                             value=f"{with_rr['cpu_pct']:.1f} % of a core",
                             ratio=with_rr["cpu_pct"] / bare if bare > 0 else None, baseline=base,
                             goal=f"<= 10 %: {_verdict(with_rr['cpu_pct'] <= GOAL_CPU_PCT)}",
                             note=f"kernel {with_rr['sys_pct']:.1f} %, RSS {with_rr['rss1']:.0f} MB, "
                                  f"rrd {with_rr['rrd_mb']:.1f} MB, loss {with_rr['sent'] - with_rr['accepted']}"))
            rows.append(_row("CPU at 1 kHz in, 50 Hz out, no Rerun", seconds=without["window_s"],
                             value=f"{without['cpu_pct']:.1f} % of a core",
                             ratio=without["cpu_pct"] / bare if bare > 0 else None, baseline=base,
                             note=f"kernel {without['sys_pct']:.1f} %, RSS {without['rss1']:.0f} MB, "
                                  f"loss {without['sent'] - without['accepted']}"))
            log(f"CPU at 1 kHz, 50 Hz output, filter on (GNSS {GNSS_HZ:g} Hz), without Rerun")
            gn = cpu_run(args.cpu_seconds, None, gnss_hz=GNSS_HZ)
            rows.append(_row(f"CPU at 1 kHz in, 50 Hz out, filter on (GNSS {GNSS_HZ:g} Hz)", seconds=gn["window_s"],
                             value=f"{gn['cpu_pct']:.1f} % of a core",
                             ratio=gn["cpu_pct"] / bare if bare > 0 else None, baseline=base,
                             goal=f"<= 10 %: {_verdict(gn['cpu_pct'] <= GOAL_CPU_PCT)}",
                             note=f"kernel {gn['sys_pct']:.1f} %, {gn['gnss']} fixes fused, "
                                  f"loss {gn['sent'] - gn['accepted']}"))
            log("CPU at 1 kHz, 1 Hz output, without Rerun (what the output sets cost)")
            quiet = cpu_run(args.cpu_seconds, None, out_rate=1.0)
            rows.append(_row("CPU at 1 kHz in, 1 Hz out, no Rerun", seconds=quiet["window_s"],
                             value=f"{quiet['cpu_pct']:.1f} % of a core",
                             ratio=quiet["cpu_pct"] / bare if bare > 0 else None, baseline=base,
                             note=f"kernel {quiet['sys_pct']:.1f} %; the 50 Hz row minus this is the output sets' cost"))
            rows.append(_row("CPU baseline: bare Python UDP receiver, 1 kHz", seconds=args.cpu_seconds,
                             value=f"{bare:.1f} % of a core", ratio=1.0, baseline="(is the baseline)",
                             note=f"kernel {bare_sys:.1f} %; select + recvmsg + parse_buffer, nothing else"))
            NOTES.append(f"CPU: the sender process used {with_rr['sender_cpu_pct']:.1f} % of a core at 1 kHz")

        if args.profile:
            rate = args.profile_rate or 15_000.0
            log(f"py-spy profile at {rate:,.0f}/s")
            NOTES.extend(profile_service(rate, 5.0 if args.quick else 10.0, work, ["-o", str(work / "prof.csv")]))
            log("py-spy profile at 1 kHz with --rerun")
            NOTES.extend(profile_service(1000.0, 5.0 if args.quick else 10.0, work,
                                         ["--rerun", str(work / "prof.rrd")]))
            gc_s = 10.0 if args.quick else 20.0
            for label, extra in (("--rerun, 50 Hz out", ["--rerun", str(work / "gc.rrd")]),
                                 ("--rerun, --rate 1000 --samples 1", ["--rerun", str(work / "gc1.rrd"), "--rate",
                                                                       "1000", "--samples", "1"]),
                                 ("no Rerun, --rate 1000 --samples 1", ["--rate", "1000", "--samples", "1"])):
                for freeze in (False, True):
                    log(f"full GC collections at 1 kHz, {label}{', gc.freeze()' if freeze else ''}")
                    g = gc_pauses(gc_s, extra, freeze)
                    if g:
                        NOTES.append(f"gc at 1 kHz for {gc_s:g} s, {label}{' + gc.freeze() (what-if)' if freeze else ''}: "
                                     f"{g['full']} full collections while serving, longest {g['max_ms']:.1f} ms, "
                                     f"total {g['total_ms']:.0f} ms; {g['tracked']:,} objects tracked")
    return rows


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

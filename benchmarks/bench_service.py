"""The live service under load: UDP ingest rate, latency and CPU of ``mavins run``.

Every figure comes from the real console script (``mavins run``) in a
subprocess, fed over UDP on 127.0.0.1:

* **Sustained ingest.** A separate sender process sends pre-encoded
  HIGHRES_IMU frames at a fixed rate (paced in 0.5 ms ticks). Loss = frames
  sent - ``imu_accepted`` from the service's exit summary; the socket's kernel
  drop counter (``/proc/net/udp``) and the service's ``flood_dropped`` say
  where a loss happened. The solution must stay correct: final attitude and
  position against the known truth of the static record. First the goal rate
  (10 kHz) for 60 s, then the highest loss-free rate is searched (doubling,
  then bisection, 10 s runs) and confirmed with a 60 s run.
* **Latency.** HIGHRES_IMU at 1 kHz, every sample published (``--rate 1000
  --samples 1``). Client side: ``time.perf_counter_ns()`` just before
  ``sendto`` of sample *i*, against the time the ATTITUDE whose
  ``time_boot_ms`` is sample *i*'s millisecond is read from the same socket
  (the service publishes to the peers of its listening link). The kernel
  receive timestamp (``SO_TIMESTAMPNS``) of that ATTITUDE gives a second
  figure without the client's own wake-up.
* **CPU.** HIGHRES_IMU at 1 kHz, output at 50 Hz, ``--rerun FILE.rrd``:
  utime + stime of the service process (``/proc/PID/stat``, all threads) over
  a steady window after the alignment, in % of one core.
* **Flood.** 250 Hz, then 200 kHz on a wall-clock schedule for 6 s, then
  250 Hz (sensor time = the schedule): input over what was processed, ATTITUDE
  per second (of wall time before, of sensor time during), navigated sensor
  time over wall time, RSS growth, drops counted, HEARTBEAT interval.
* **Peers.** How soon a silent peer stops receiving (``--peer-timeout 2``);
  RSS growth of the peer table under 3000 source ports.
* **Recorder.** RSS growth of a live Rerun recorder over 200,000 samples;
  ``--rerun-serve`` without a viewer: logging, ``close()`` and a whole
  ``mavins run --duration 1``.

The flood, peer and recorder rows hold the figures the tests once asserted on
timing or memory; the tests now check the behaviour behind them by events and
counts, never by the clock.

Baselines, measured in the same run: the pymavlink parse ceiling (one
``parse_buffer`` call per frame, in process) for ingest; a bare Python UDP echo
process (``recvmsg`` + ``parse_buffer`` + ``sendto`` of one ATTITUDE) for
latency; the same service run without ``--rerun`` for CPU.

The static record: level, heading 0, at rest at 47.397742 N, 8.545594 E,
488 m; gyros read the Earth rate ``C_n^b w_ie^n``, accelerometers
``[0, 0, -g(lat, h)]`` (mavins' own gravity model), float32 as HIGHRES_IMU
carries them. Truth is therefore constant: roll = pitch = yaw = 0.

Run from the repository root::

    .venv/bin/python benchmarks/bench_service.py [--quick] [--profile]

``--profile`` also records the service with py-spy (``pip install py-spy``,
or ``PY_SPY=/path/to/py-spy``) at a high input rate and prints its top
functions. See benchmarks/README.md for what each row means.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import select
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(HERE), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

os.environ.setdefault("MAVLINK20", "1")

LAT, LON, ALT = 47.397742, 8.545594, 488.0
HEADING = 0.0
ALIGN_S = 1.0
T0_USEC = 1_000_000  # sensor time of the first sample (1 s)
SYSID, COMPID = 1, 1
GOAL_RATE = 10_000.0  # Hz, sustained ingest goal
GOAL_LATENCY_P99_MS = 1.0
GOAL_CPU_PCT = 10.0
#: A run is correct when the final attitude is within this of the truth (deg) ...
ATT_TOL_DEG = 0.01
#: ... and the final position within this (m, horizontal).
POS_TOL_M = 1.0
SEND_TICK_S = 0.0005  # sender pacing: sleep at least this long, then send every frame that is due

#: Footnotes printed under the table (filled by main()).
NOTES: list[str] = []
#: What each ratio of this module compares with (run_all prints it).
BASELINE = ("ingest: pymavlink parse_buffer ceiling; latency: bare Python UDP echo; "
            "CPU: bare Python UDP receiver (each measured in this run)")


def log(msg: str) -> None:
    print(f"[bench_service] {msg}", file=sys.stderr, flush=True)


# --- the static record -------------------------------------------------------------
def static_imu(lat_deg: float = LAT, alt: float = ALT) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Gyro (rad/s) and specific force (m/s^2) of a level IMU at rest, heading 0 (body = NED)."""
    from mavins.core import earth

    lat = math.radians(lat_deg)
    w = earth.earth_rate_n(lat)
    g = earth.gravity(lat, alt)
    return (float(w[0]), float(w[1]), float(w[2])), (0.0, 0.0, -float(g))


def _x25_rows(data: np.ndarray, extra: int) -> np.ndarray:
    """MAVLink's X.25 CRC of every row of ``data`` (uint8, n x m), then ``extra``; vectorised over rows."""
    crc = np.full(data.shape[0], 0xFFFF, dtype=np.uint32)
    cols = [data[:, j].astype(np.uint32) for j in range(data.shape[1])]
    cols.append(np.full(data.shape[0], extra, dtype=np.uint32))
    for b in cols:
        tmp = (b ^ (crc & 0xFF)) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def highres_frames(
    n: int, rate: float, gyro: Sequence[float], accel: Sequence[float], t0_usec: int = T0_USEC,
    sysid: int = SYSID, compid: int = COMPID, chunk: int = 500_000, times: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` MAVLink 2 HIGHRES_IMU frames (uint8 rows, one frame each) and their ``time_usec``
    (``rate`` apart from ``t0_usec``, or the given ``times``).

    One frame is encoded by pymavlink as a template; ``time_usec``, ``seq`` and
    the CRC are then written for every row with numpy. The first rows are
    checked byte for byte against pymavlink's own encoding.
    """
    from mavins.link.mavlink import mavlink

    usec = (np.round(t0_usec + np.arange(n) * (1e6 / rate)) if times is None else np.asarray(times)).astype(np.uint64)
    n = len(usec)
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def encode(i: int) -> bytes:
        mav.seq = i % 256
        return mavlink.MAVLink_highres_imu_message(
            int(usec[i]), accel[0], accel[1], accel[2], gyro[0], gyro[1], gyro[2],
            0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0, 0b111111, 0).pack(mav)

    tmpl = np.frombuffer(encode(0), dtype=np.uint8)
    plen = int(tmpl[1])
    flen = tmpl.size  # 10 header + payload + 2 CRC
    extra = mavlink.MAVLink_highres_imu_message.crc_extra
    out = np.empty((n, flen), dtype=np.uint8)
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        rows = np.repeat(tmpl[None, :], b - a, axis=0)
        rows[:, 4] = (np.arange(a, b) % 256).astype(np.uint8)
        rows[:, 10:18] = usec[a:b].astype("<u8").view(np.uint8).reshape(-1, 8)
        crc = _x25_rows(rows[:, 1 : 10 + plen], extra)
        rows[:, flen - 2] = (crc & 0xFF).astype(np.uint8)
        rows[:, flen - 1] = (crc >> 8).astype(np.uint8)
        out[a:b] = rows
    for i in range(min(n, 3)):
        if out[i].tobytes() != encode(i):
            raise AssertionError(f"vectorised HIGHRES_IMU frame {i} differs from pymavlink's encoding")
    return out, usec


# --- /proc helpers ---------------------------------------------------------------
CLK_TCK = os.sysconf("SC_CLK_TCK")


def proc_cpu_split(pid: int) -> tuple[float, float]:
    """(utime, stime) of a process, all threads (s)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
        text = fh.read()
    rest = text[text.rfind(")") + 2 :].split()
    return int(rest[11]) / CLK_TCK, int(rest[12]) / CLK_TCK


def proc_cpu_seconds(pid: int) -> float:
    """utime + stime of a process, all threads (s)."""
    return sum(proc_cpu_split(pid))


def proc_rss_mb(pid: int, field: str = "VmRSS") -> float | None:
    """Resident set size (``VmRSS``) or its peak since exec (``VmHWM``) of a process, MB; None if gone."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    kb = int(line.split()[1])
                    return kb / 1024.0 if kb > 0 else None
    except OSError:
        return None
    return None


def udp_socket_stats(port: int) -> tuple[int, int] | None:
    """(bytes waiting, kernel drops) of the UDP socket bound to 127.0.0.1:port, from /proc/net/udp."""
    want = f"0100007F:{port:04X}"
    try:
        with open("/proc/net/udp", encoding="ascii") as fh:
            next(fh)
            for line in fh:
                f = line.split()
                if f[1] == want:
                    return int(f[4].split(":")[1], 16), int(f[-1])
    except OSError:
        return None
    return None


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def mavins_cmd() -> list[str]:
    """The ``mavins`` console script of this interpreter's environment."""
    script = Path(sys.executable).parent / "mavins"
    return [str(script)] if script.exists() else [sys.executable, "-m", "mavins.cli"]


def percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else float("nan")


# --- the service process -----------------------------------------------------------
GNSS_HZ = 5.0  # GPS_RAW_INT in the filter-on runs (issue 33: "GNSS at 5 Hz")


def gnss_frames(usec: np.ndarray, rate: float, gnss_hz: float, sysid: int = SYSID, compid: int = COMPID
                ) -> dict[int, bytes]:
    """GPS_RAW_INT frames (3D fix at the static record's position, at rest) to send straight after the IMU
    frame of the same time, every ``rate / gnss_hz`` IMU samples: {IMU index: frame}."""
    from mavins.link.mavlink import mavlink

    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    every = max(1, int(round(rate / gnss_hz)))
    out = {}
    for i in range(0, len(usec), every):
        mav.seq = (i // every) % 256
        out[i] = mavlink.MAVLink_gps_raw_int_message(
            int(usec[i]), 3, int(round(LAT * 1e7)), int(round(LON * 1e7)), int(round(ALT * 1000)), 80, 120, 0, 0,
            12, int(round(ALT * 1000)), 500, 800, 50, 100, 0).pack(mav)
    return out


@dataclass
class ServiceProc:
    """``mavins run`` in a subprocess; stderr collected; stopped with SIGTERM."""

    port: int
    args: list[str]
    max_duration: float
    lines: list[str] = field(default_factory=list)
    proc: subprocess.Popen | None = None
    counters: dict[str, int] = field(default_factory=dict)
    command: list[str] | None = None  # instead of the console script (e.g. an instrumented interpreter)
    _ready: threading.Event = field(default_factory=threading.Event)

    def start(self, timeout: float = 600.0) -> None:
        cmd = (self.command or mavins_cmd()) + ["run", "--master", f"udpin:127.0.0.1:{self.port}", "--lat", str(LAT), "--lon",
                              str(LON), "--alt", str(ALT), "--heading", str(HEADING), "--align", str(ALIGN_S),
                              "--duration", f"{self.max_duration:.0f}"] + self.args
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, text=True, cwd=ROOT)
        threading.Thread(target=self._read, daemon=True).start()
        if not self._ready.wait(timeout) or self.proc.poll() is not None:
            self.stop()
            raise RuntimeError("mavins run did not start:\n" + "\n".join(self.lines[-20:]))

    def _read(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))
            if "listening on" in line:
                self._ready.set()
        self._ready.set()

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def drain(self, timeout: float = 10.0) -> None:
        """Wait until the service has read everything waiting in its socket."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            st = udp_socket_stats(self.port)
            if st is None or st[0] == 0:
                break
            time.sleep(0.05)
        time.sleep(0.3)  # the last batch read is processed

    def stop(self) -> dict[str, int]:
        if self.proc is None:
            return {}
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        time.sleep(0.05)
        for line in self.lines:
            m = re.match(r"mavins run: ([a-z_]+): (\d+)$", line)
            if m:
                self.counters[m.group(1)] = int(m.group(2))
            m = re.match(r"mavins run: messages received: (\d+)$", line)
            if m:
                self.counters["messages_received"] = int(m.group(1))
        return self.counters


def read_last_row(path: Path) -> np.ndarray | None:
    """Last solution row of a solution CSV (degrees), or None."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - 4096))
            tail = fh.read().decode("ascii", "replace").strip().splitlines()
    except OSError:
        return None
    if len(tail) < 2 or tail[-1].startswith("t,"):
        return None
    return np.array([float(x) for x in tail[-1].split(",")])


def solution_error(row: np.ndarray | None) -> tuple[float, float]:
    """(attitude error deg, horizontal position error m) of a solution row against the static truth."""
    if row is None:
        return float("inf"), float("inf")
    roll, pitch, yaw = row[7], row[8], row[9]
    dyaw = (yaw - HEADING + 180.0) % 360.0 - 180.0
    att = max(abs(roll), abs(pitch), abs(dyaw))
    dn = math.radians(row[1] - LAT) * 6.371e6
    de = math.radians(row[2] - LON) * 6.371e6 * math.cos(math.radians(LAT))
    return float(att), float(math.hypot(dn, de))


# --- sender subprocess ---------------------------------------------------------------
def sender_main(argv: Sequence[str]) -> int:
    """``--sender PORT RATE SECONDS GX GY GZ AX AY AZ [GNSS_HZ]``: build frames, print ready, wait for a
    line, send (a GPS_RAW_INT after the IMU frame of its time at GNSS_HZ, when given)."""
    port, rate, seconds = int(argv[0]), float(argv[1]), float(argv[2])
    gyro = [float(x) for x in argv[3:6]]
    accel = [float(x) for x in argv[6:9]]
    gnss_hz = float(argv[9]) if len(argv) > 9 else 0.0
    n = int(round(rate * seconds))
    frames, usec = highres_frames(n, rate, gyro, accel)
    gnss = gnss_frames(usec, rate, gnss_hz) if gnss_hz > 0 else {}
    flen = frames.shape[1]
    mv = memoryview(frames.tobytes())
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)  # replies are not read
    addr = ("127.0.0.1", port)
    print("ready", flush=True)
    sys.stdin.readline()
    cpu0 = os.times()
    sendto, perf, sleep = sock.sendto, time.perf_counter, time.sleep
    errors = 0
    max_behind = 0.0
    t0 = perf()
    i = 0
    while i < n:
        now = perf()
        due = min(n, int((now - t0) * rate) + 1)
        if due - i > 1:
            max_behind = max(max_behind, (due - 1 - i) / rate)
        while i < due:
            try:
                sendto(mv[i * flen : (i + 1) * flen], addr)
                if i in gnss:
                    sendto(gnss[i], addr)
            except OSError:
                errors += 1
            i += 1
        if i < n:
            wait = t0 + i / rate - perf()
            if wait > 0:
                sleep(max(wait, SEND_TICK_S))
    elapsed = perf() - t0
    cpu1 = os.times()
    sock.close()
    print(json.dumps({"sent": n - errors, "send_errors": errors, "seconds": elapsed,
                      "cpu_s": (cpu1.user - cpu0.user) + (cpu1.system - cpu0.system),
                      "max_behind_s": max_behind}), flush=True)
    return 0


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
        [sys.executable, str(Path(__file__).resolve()), "--sender", str(port), repr(rate), repr(seconds),
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
        [sys.executable, str(Path(__file__).resolve()), "--sender", str(port), repr(rate), repr(total),
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
        [sys.executable, str(Path(__file__).resolve()), "--sender", str(port), repr(rate), repr(total),
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


# --- profile ------------------------------------------------------------------------
def py_spy_path() -> str | None:
    return os.environ.get("PY_SPY") or shutil.which("py-spy")


def _select_leaves() -> tuple[str, ...]:
    """Leaf frames (as py-spy writes them) of the service waiting in ``select()``: not work, left out."""
    src = ROOT / "mavins" / "service.py"
    lines = src.read_text(encoding="utf-8").splitlines()
    return tuple(f"(mavins/service.py:{i + 1})" for i, text in enumerate(lines) if "select.select(" in text)


def _stacks(raw: Path) -> tuple[list[tuple[list[str], int]], int]:
    """(frames, count) of the busy stacks of a py-spy raw file, and the number of samples waiting in select()."""
    idle = _select_leaves()
    out: list[tuple[list[str], int]] = []
    waiting = 0
    for line in raw.read_text(encoding="utf-8", errors="replace").splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack or not count.isdigit():
            continue
        frames = stack.split(";")
        if frames[-1].endswith(idle) and idle:
            waiting += int(count)
            continue
        out.append((frames, int(count)))
    return out, waiting


def top_functions(raw: Path, k: int = 15) -> tuple[list[tuple[str, float, float]], int]:
    """(function, self %, inclusive %) of the ``k`` heaviest functions in a py-spy raw (collapsed) file.

    Percentages are of the busy samples: samples of the service waiting in
    ``select()`` (which py-spy does not always see as idle) are left out.
    """
    self_c: Counter = Counter()
    incl_c: Counter = Counter()
    total = 0
    stacks, _ = _stacks(raw)
    for frames, c in stacks:
        total += c
        frames = [re.sub(r":\d+\)$", ")", f) for f in frames]
        self_c[frames[-1]] += c
        for f in set(frames):
            incl_c[f] += c
    names = [n for n, _ in self_c.most_common(k)]
    if not total:
        return [], 0
    return [(n, 100.0 * self_c[n] / total, 100.0 * incl_c[n] / total) for n in names], total


def top_lines(raw: Path, k: int = 10, prefix: str = "mavins/") -> list[tuple[str, float]]:
    """Source lines of our own code that are the leaf Python frame most often: (file:line function, self %).

    Time in a C call (recvmsg, a numba kernel) is charged to the line that makes it.
    """
    counts: Counter = Counter()
    total = 0
    stacks, _ = _stacks(raw)
    for frames, c in stacks:
        total += c
        m = re.match(r"(.*) \((.*)\)$", frames[-1])
        if m and m.group(2).startswith(prefix):
            counts[f"{m.group(2)} {m.group(1)}"] += c
    return [(n, 100.0 * c / total) for n, c in counts.most_common(k)] if total else []


def line_text(ref: str) -> str:
    """The source text of ``mavins/file.py:N``."""
    m = re.match(r"(mavins/[\w/]+\.py):(\d+)", ref)
    if not m:
        return ""
    try:
        return (ROOT / m.group(1)).read_text(encoding="utf-8").splitlines()[int(m.group(2)) - 1].strip()[:70]
    except (OSError, IndexError):
        return ""


def inclusive(raw: Path, patterns: Sequence[str]) -> dict[str, float]:
    """Inclusive % of the busy samples whose stack has a frame matching each regex."""
    tot = 0
    hits: Counter = Counter()
    stacks, _ = _stacks(raw)
    for frames, c in stacks:
        tot += c
        stack = ";".join(frames)
        for p in patterns:
            if re.search(p, stack):
                hits[p] += c
    return {p: (100.0 * hits[p] / tot if tot else 0.0) for p in patterns}


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
        [sys.executable, str(Path(__file__).resolve()), "--sender", str(port), repr(rate), repr(total),
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
        [sys.executable, str(Path(__file__).resolve()), "--sender", str(port), repr(rate), repr(seconds),
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


# --- peers -------------------------------------------------------------------------------
def _hb_frame() -> bytes:
    from mavins.link.mavlink import mavlink

    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    return bytes(plain.heartbeat_encode(6, 8, 0, 0, 4).pack(plain))


def _stamped(sock: socket.socket) -> list[float]:
    """Kernel receive stamps of every datagram waiting in ``sock`` (SO_TIMESTAMP on)."""
    out = []
    so_ts = getattr(socket, "SO_TIMESTAMP", 29)
    while True:
        try:
            _, anc, _, _ = sock.recvmsg(65535, 64, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return out
        stamp = time.time()
        for level, kind, value in anc:
            if level == socket.SOL_SOCKET and kind == so_ts and len(value) >= 16:
                sec, usec = struct.unpack("qq", value[:16])
                stamp = sec + usec * 1e-6
        out.append(stamp)


def _peer_socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_TIMESTAMP", 29), 1)
    s.bind(("127.0.0.1", 0))
    return s


def peer_expiry(timeout: float = 2.0, watch: float = 5.5) -> dict:
    """How long after its only frame a silent peer still receives (``--peer-timeout``); a talker for contrast."""
    hb = _hb_frame()
    port = free_udp_port()
    svc = ServiceProc(port, ["--sysid", "1", "--peer-timeout", repr(timeout)], max_duration=watch + 120)
    silent, talker = _peer_socket(), _peer_socket()
    svc.start()
    try:
        t0 = time.time()
        silent.sendto(hb, ("127.0.0.1", port))
        got_s: list[float] = []
        got_t: list[float] = []
        next_talk = time.monotonic()
        end = next_talk + watch
        while time.monotonic() < end:
            if time.monotonic() >= next_talk:
                talker.sendto(hb, ("127.0.0.1", port))
                next_talk += 0.5
            got_s += _stamped(silent)
            got_t += _stamped(talker)
            time.sleep(0.02)
    finally:
        svc.stop()
        silent.close()
        talker.close()
    return {"timeout": timeout, "watch": watch, "silent_last": (max(got_s) - t0) if got_s else None,
            "silent_n": len(got_s), "talker_last": (max(got_t) - t0) if got_t else None}


def peer_table_rss(n_ports: int = 3000) -> dict:
    """RSS of ``mavins run --max-peers 4`` before and after frames from ``n_ports`` source ports."""
    hb = _hb_frame()
    port = free_udp_port()
    svc = ServiceProc(port, ["--sysid", "1", "--max-peers", "4", "--peer-timeout", "600"], max_duration=600)
    svc.start()
    try:
        time.sleep(0.5)
        rss0 = proc_rss_mb(svc.pid)
        for i in range(n_ports):
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.bind(("127.0.0.1", 0))
                s.sendto(hb, ("127.0.0.1", port))
            if i % 200 == 199:
                time.sleep(0.01)
        svc.drain()
        time.sleep(2.0)
        rss1 = proc_rss_mb(svc.pid)
    finally:
        c = svc.stop()
    return {"n": n_ports, "rss0": rss0, "rss1": rss1, "received": c.get("messages_received", 0)}


# --- the recorder --------------------------------------------------------------------------
#: ``python -c`` script: a live Recorder fed ``n`` samples (250 Hz) and n/5 output sets; prints JSON with the
#: process's RSS after a warm-up fifth and at four points after it, and the file size at each.
_RECORDER_MEMORY = r"""
import gc, json, math, sys, time
from pathlib import Path
import numpy as np
from mavins.record.recorder import Recorder

def rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0

path, n = Path(sys.argv[1]), int(sys.argv[2])
rec = Recorder(path, serve=False, app="mavins-membench", live=True)
row = np.zeros(14); row[10] = 1.0
lat0, lon0 = math.radians(47.0), math.radians(8.0)
ned = np.zeros(3)

def feed(a, b):
    for i in range(a, b):
        t = 1.0 + i * 0.004
        rec.on_sample(t, (0.01, -0.02, 0.03 * math.sin(t)), (0.1, 0.2, -9.8))
        if i % 5 == 0:
            row[0] = t; row[1] = lat0 + 1e-7 * i; row[2] = lon0; row[3] = 400.0; row[9] = 0.1 * math.sin(t)
            ned[0] = 0.6 * i; ned[1] = 10.0 * math.sin(t / 10.0)
            rec.on_output(row, (47.0, 8.0, 400.0), ned)
        if i % 2500 == 0:
            rec.on_counters(t, {"time_backwards": i // 2500})
            rec.on_event(t, "INFO", f"event {i}")

warm = n // 5
t0 = time.perf_counter()
feed(0, warm); gc.collect(); time.sleep(0.2)
base, size0 = rss_mb(), path.stat().st_size
step = (n - warm) // 4
rss = []
for k in range(4):
    feed(warm + k * step, warm + (k + 1) * step)
    rss.append(rss_mb())
t_feed = time.perf_counter() - t0
rec.close()
print(json.dumps({"base": base, "rss": rss, "size0": size0, "size": path.stat().st_size, "feed_s": t_feed}))
"""


def recorder_memory(workdir: Path, n: int = 200_000) -> dict:
    rrd = workdir / "recorder_memory.rrd"
    proc = subprocess.run([sys.executable, "-c", _RECORDER_MEMORY, str(rrd), str(n)], capture_output=True, text=True,
                          timeout=1800, cwd=ROOT)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "recorder script failed")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["n"] = n
    return out


def recorder_serve(n: int = 20_000) -> dict:
    """A Recorder with the gRPC server and no viewer: seconds to log ``n`` samples (+ n/5 sets) and to close."""
    from mavins.record.recorder import Recorder

    with tempfile.TemporaryDirectory(prefix="bench_serve_") as tmp:
        t0 = time.perf_counter()
        rec = Recorder(Path(tmp) / "served.rrd", serve=True, app="mavins-servebench")
        row = np.zeros(14)
        row[10] = 1.0
        for i in range(n):
            t = i * 0.004
            rec.on_sample(t, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8))
            if i % 5 == 0:
                row[0] = t
                rec.on_output(row, (47.0, 8.0, 400.0), np.zeros(3))
        t1 = time.perf_counter()
        rec.close()
        t2 = time.perf_counter()
    cli0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_serve_cli_") as tmp:
        proc = subprocess.run(mavins_cmd() + ["run", "--master", f"udpin:127.0.0.1:{free_udp_port()}", "--rerun",
                                              str(Path(tmp) / "live.rrd"), "--rerun-serve", "--duration", "1"],
                              capture_output=True, text=True, timeout=600, cwd=ROOT)
    cli = time.perf_counter() - cli0
    return {"n": n, "log_s": t1 - t0, "close_s": t2 - t1, "cli_s": cli, "cli_rc": proc.returncode}


# --- driver ----------------------------------------------------------------------------
def _row(case: str, *, samples: int | None = None, seconds: float | None = None, rate: float | None = None,
         value: str | None = None, ratio: float | None = None, baseline: str | None = None,
         goal: str | None = None, note: str = "") -> dict:
    return {"case": case, "samples": samples, "seconds": seconds, "rate": rate, "value": value, "ratio": ratio,
            "baseline": baseline, "goal": goal, "note": note}


def _verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def main(argv: Sequence[str] = ()) -> list[dict]:
    """Measure ingest, latency and CPU of ``mavins run`` and return the table rows."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="short runs for development (seconds, not minutes)")
    p.add_argument("--goal-seconds", type=float, default=60.0, help="length of the 10 kHz and confirmation runs")
    p.add_argument("--search-seconds", type=float, default=10.0, help="length of each rate-search run")
    p.add_argument("--latency-seconds", type=float, default=30.0, help="measured seconds of the latency runs")
    p.add_argument("--cpu-seconds", type=float, default=20.0, help="CPU window (s)")
    p.add_argument("--cap", type=float, default=160_000.0, help="highest rate the search tries")
    p.add_argument("--tol", type=float, default=0.05, help="relative resolution of the rate search")
    p.add_argument("--flood-seconds", type=float, default=FLOOD_S, help=f"length of the {FLOOD_HZ:,.0f}/s flood")
    p.add_argument("--skip", action="append", default=[],
                   choices=("ingest", "search", "latency", "cpu", "flood", "peers", "recorder"),
                   help="leave a part out (repeatable)")
    p.add_argument("--profile", action="store_true", help="also record the service with py-spy and print the top functions")
    p.add_argument("--profile-rate", type=float, default=None, help="input rate of the profile (default: the found maximum)")
    args = p.parse_args(list(argv))
    if args.quick:
        args.goal_seconds, args.search_seconds = 5.0, 3.0
        args.latency_seconds, args.cpu_seconds, args.tol = 5.0, 5.0, 0.25
        args.flood_seconds = 3.0
    NOTES.clear()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench_service_") as tmp:
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
            args.profile_rate = args.profile_rate or (confirmed.rate if confirmed else None)
        rows += ingest_rows

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

        if "flood" not in args.skip:
            log(f"flood: 250 Hz, {FLOOD_HZ:,.0f}/s for {args.flood_seconds:g} s, 250 Hz")
            rows += flood_rows(flood_run(flood_s=args.flood_seconds))

        if "peers" not in args.skip:
            log("peers: expiry of a silent peer (--peer-timeout 2)")
            pe = peer_expiry(2.0)
            last = pe["silent_last"]
            rows.append(_row("peer expiry: last datagram to a silent peer after its frame",
                             value="none" if last is None else f"{last:.2f} s",
                             goal=f"<= timeout + 0.5 s: {_verdict(last is not None and last <= pe['timeout'] + 0.5)}",
                             note=f"--peer-timeout {pe['timeout']:g}; {pe['silent_n']} datagrams; a talker every "
                                  f"0.5 s last received at {pe['talker_last'] or 0:.2f} s of {pe['watch']:g}"))
            log("peers: memory of the peer table under 3000 source ports")
            pt = peer_table_rss(3000)
            if pt["rss0"] and pt["rss1"]:
                grown = pt["rss1"] - pt["rss0"]
                rows.append(_row(f"peer table: RSS growth after {pt['n']:,} source ports", samples=pt["n"],
                                 value=f"{grown:+.1f} MB", goal=f"< 5 MB: {_verdict(grown < 5)}",
                                 note=f"--max-peers 4; {pt['rss0']:.1f} -> {pt['rss1']:.1f} MB; "
                                      f"{pt['received']:,} frames read"))

        if "recorder" not in args.skip:
            n_rec = 50_000 if args.quick else 200_000
            log(f"recorder: memory over {n_rec:,} samples")
            rm = recorder_memory(work, n_rec)
            written = (rm["size"] - rm["size0"]) / 2**20
            grown = max(rm["rss"]) - rm["base"]
            rows.append(_row(f"recorder: RSS growth over {n_rec:,} samples + {n_rec // 5:,} sets", samples=n_rec,
                             seconds=rm["feed_s"], rate=n_rec / rm["feed_s"], value=f"{grown:+.1f} MB",
                             goal=f"< 0.6 x written + 4 MB: {_verdict(grown < 0.6 * written + 4)}",
                             note=f"{written:.1f} MB written meanwhile; RSS {rm['base']:.0f} MB after a warm-up fifth"))
            log("recorder: --rerun-serve without a viewer")
            rs = recorder_serve()
            rows.append(_row(f"recorder --rerun-serve, no viewer: log {rs['n']:,} samples", samples=rs["n"],
                             seconds=rs["log_s"], rate=rs["n"] / rs["log_s"], goal=None,
                             note="+ a set every 5 samples"))
            rows.append(_row("recorder --rerun-serve, no viewer: close()", seconds=rs["close_s"],
                             goal=f"< 5 s: {_verdict(rs['close_s'] < 5)}"))
            rows.append(_row("mavins run --rerun-serve --duration 1, no viewer: process", seconds=rs["cli_s"],
                             goal=f"< 30 s: {_verdict(rs['cli_s'] < 30 and rs['cli_rc'] == 0)}",
                             note=f"exit code {rs['cli_rc']}; includes loading the kernels"))

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
    if len(sys.argv) > 1 and sys.argv[1] == "--sender":
        sys.exit(sender_main(sys.argv[2:]))
    if len(sys.argv) > 1 and sys.argv[1] == "--flood-sender":
        sys.exit(flood_sender_main(sys.argv[2:]))
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

"""What the live-service benchmarks share (bench_ingest, bench_latency, bench_flood, bench_peers,
bench_recorder): the static IMU record and its frames, ``mavins run`` in a subprocess, the sender
subprocess, /proc readings, py-spy helpers and the table row.

The static record: level, heading 0, at rest at 47.397742 N, 8.545594 E, 488 m; gyros read the Earth
rate ``C_n^b w_ie^n``, accelerometers ``[0, 0, -g(lat, h)]`` (mavins' own gravity model), float32 as
HIGHRES_IMU carries them. Truth is therefore constant: roll = pitch = yaw = 0. Each benchmark runs the
real console script (``mavins run``) in a subprocess, fed over UDP on 127.0.0.1; see
benchmarks/README.md for what each row means."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
HARNESS = Path(__file__).resolve()  # run as ``python service_harness.py --sender ...``: the sender subprocess
for _p in (str(HERE), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

os.environ.setdefault("MAVLINK20", "1")

#: Footnotes printed under a benchmark's table (filled by its main()).
NOTES: list[str] = []


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


def log(msg: str) -> None:
    print(f"[{Path(sys.argv[0]).stem}] {msg}", file=sys.stderr, flush=True)


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


# --- driver ----------------------------------------------------------------------------
def _row(case: str, *, samples: int | None = None, seconds: float | None = None, rate: float | None = None,
         value: str | None = None, ratio: float | None = None, baseline: str | None = None,
         goal: str | None = None, note: str = "") -> dict:
    return {"case": case, "samples": samples, "seconds": seconds, "rate": rate, "value": value, "ratio": ratio,
            "baseline": baseline, "goal": goal, "note": note}


def _verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


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


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--sender":
        sys.exit(sender_main(sys.argv[2:]))
    sys.exit("usage: service_harness.py --sender PORT RATE SECONDS GX GY GZ AX AY AZ [GNSS_HZ]")

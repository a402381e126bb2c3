"""What several test modules share: the mavins command, its environment, ports and log waits, the typed
WGS-84 truth, and the one angle wrap and attitude-error metric of the tests."""

from __future__ import annotations

import math
import os
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MAVINS = [str(Path(sys.executable).parent / "mavins")] if (Path(sys.executable).parent / "mavins").is_file() \
    else [sys.executable, "-m", "mavins.cli"]
ENV = {**os.environ, "MAVLINK20": "1", "PYTHONUNBUFFERED": "1"}
READY_TIMEOUT_S = 600.0  # a cold start compiles the kernels; on a loaded machine that takes a while


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that is free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_line(path: Path, text: str, proc: subprocess.Popen, timeout: float = READY_TIMEOUT_S) -> None:
    """Wait until ``text`` appears in a process's log file; fail if the process exits first."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if text in path.read_text(errors="replace"):
            return
        if proc.poll() is not None:
            raise AssertionError(f"exited ({proc.returncode}) before {text!r}:\n{path.read_text()}")
        time.sleep(0.05)
    raise AssertionError(f"no {text!r} within {timeout} s:\n{path.read_text()}")


def mavins(*args: str, cwd: Path, env: dict[str, str] | None = None,
           timeout: float = 600.0) -> subprocess.CompletedProcess:
    """Run ``mavins ARGS`` to completion, capturing its output."""
    return subprocess.run([*MAVINS, *args], cwd=cwd, env=env or ENV, capture_output=True, text=True,
                          timeout=timeout)


@contextmanager
def running_service(log_path: Path, *args: str, cwd: Path, env: dict[str, str] | None = None,
                    stop_timeout: float = 120.0) -> Iterator[subprocess.Popen]:
    """``mavins run ARGS`` logging to log_path, listening when the block starts; stopped with SIGTERM when
    it ends (killed if it does not stop in time or the block raised). The exit code is for the caller."""
    with open(log_path, "w") as log:
        proc = subprocess.Popen([*MAVINS, "run", *args], stdout=log, stderr=subprocess.STDOUT, env=env or ENV, cwd=cwd)
    try:
        wait_for_line(log_path, "ready: listening on", proc)
        yield proc
        proc.send_signal(signal.SIGTERM)
        proc.wait(stop_timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)


def summary(log: str) -> dict[str, str]:
    """The ``mavins run: key: value`` lines of a service's exit summary."""
    out: dict[str, str] = {}
    for line in log.splitlines():
        if line.startswith("mavins run: ") and ": " in line[len("mavins run: "):]:
            k, v = line[len("mavins run: "):].split(": ", 1)
            out[k] = v
    return out


# -- typed WGS-84 (NIMA TR8350.2, docs/conventions.md) and C_b^n: the tests' truth, never imported from mavins --
# aided.run_aided's last arguments when nothing is smoothed and no wheel aids: an empty epoch store, no active
# states, 1 s; no odometer rows, its lever arm, no constraint
NO_SMOOTHING = (np.empty((0, 2)), np.empty(0, dtype=np.int64), 1.0, np.empty((0, 3)), np.zeros(3), 0.0)

A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
OMEGA = 7.292115e-5
GAMMA_E = 9.7803253359
K_SOM = 0.00193185265241
M_RATIO = 0.00344978650684


def gamma(lat, h):  # type: ignore[no-untyped-def]
    """Normal gravity (m/s^2) at latitude lat (rad) and height h (m): Somigliana with the second-order height term."""
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_E * (1 + K_SOM * s2) / np.sqrt(1 - E2 * s2)
    return g0 * (1 - 2 / A * (1 + F + M_RATIO - 2 * F * s2) * h + 3 * h * h / (A * A))


def cbn(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """C_b^n = Rz(yaw) Ry(pitch) Rx(roll) (conventions.md "Euler angles")."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


# -- angles: the tests' own forms, written apart from mavins.core.rotation (test_rotation checks they agree) --


def quat_zyx(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """q_b^n [w x y z] (Hamilton) of C_b^n = Rz(yaw) Ry(pitch) Rx(roll), typed from the half angles
    (docs/conventions.md "Euler angles")."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy])


def _wrap(a, half: float):  # type: ignore[no-untyped-def]
    w = half - (half - np.asarray(a, float)) % (2.0 * half)
    return np.where(w <= -half, w + 2.0 * half, w)[()]  # the modulo of a tiny negative rounds up to a whole turn


def wrap_rad(a):  # type: ignore[no-untyped-def]
    """Angle(s) (rad) wrapped into (-pi, pi]."""
    return _wrap(a, np.pi)


def wrap_deg(a):  # type: ignore[no-untyped-def]
    """Angle(s) (deg) wrapped into (-180, 180]."""
    return _wrap(a, 180.0)


def _quat_over(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scalar and vector parts of ``a (x) b^-1`` (Hamilton, [w, x, y, z], rows; any norm)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    w = np.sum(a * b, axis=-1)
    v = b[..., :1] * a[..., 1:] - a[..., :1] * b[..., 1:] - np.cross(a[..., 1:], b[..., 1:])
    return w, v


def quat_error(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Attitude error phi (rad), rows: the rotation vector of ``q_est (x) q_true^-1``.

    Estimate minus truth in the reference frame, ``C(est) = exp([phi x]) C(true)``.
    """
    w, v = _quat_over(q_est, q_true)
    v = np.where((w < 0.0)[..., None], -v, v)
    s = np.linalg.norm(v, axis=-1)
    k = 2.0 * np.arctan2(s, np.abs(w)) / np.where(s > 0.0, s, 1.0)  # s = 0: phi = v = 0
    return v * k[..., None]


def quat_angle(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The attitude error as an angle (rad, in [0, pi]) between attitudes p and q, rows (atan2 form, exact near 0)."""
    w, v = _quat_over(q, p)
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=-1), np.abs(w))


def quat_angle_deg(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """:func:`quat_angle` in degrees."""
    return np.degrees(quat_angle(p, q))


# -- events, not durations ------------------------------------------------------------------------
EVENT_TIMEOUT_S = 180.0  # generous: a wait only fails when the event never comes, never because the machine is busy


def wait_until(cond, what: str, timeout: float = EVENT_TIMEOUT_S, poll: float = 0.02):  # type: ignore[no-untyped-def]
    """Poll ``cond()`` until it returns something truthy and return that; fail after ``timeout`` s."""
    t_end = time.monotonic() + timeout
    while True:
        v = cond()
        if v:
            return v
        if time.monotonic() > t_end:
            raise AssertionError(f"{what}: not within {timeout:g} s")
        time.sleep(poll)


# -- UDP sockets as the kernel sees them -----------------------------------------------------------
SO_TIMESTAMP = getattr(socket, "SO_TIMESTAMP", 29)
SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)
TEST_RCVBUF = 64 << 20  # what the test's own receivers ask for, so that they lose nothing while busy
ROOM_BYTES = 64 << 10  # backpressure: queued bytes a sender leaves in a receiver's socket (any buffer holds 200 KiB)


def roomy(sock: socket.socket, size: int = TEST_RCVBUF) -> socket.socket:
    """Give a test's receiving socket a large buffer (beyond rmem_max where permitted) and kernel stamps."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, size)
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)  # capped at net.core.rmem_max
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMP, 1)
    except OSError:
        pass
    return sock


def udp_stats(port: int) -> tuple[int, int] | None:
    """(bytes queued, datagrams dropped by the kernel) of the UDP socket bound to 127.0.0.1:port (/proc/net/udp)."""
    want = f"0100007F:{port:04X}"
    try:
        with open("/proc/net/udp", encoding="ascii") as fh:
            next(fh)
            for line in fh:
                f = line.split()
                if f[1] == want:
                    return int(f[4].split(":")[1], 16), int(f[-1])
    except (OSError, StopIteration):
        return None
    return None


def kernel_drops(port: int) -> int:
    """Datagrams the kernel dropped at the socket on 127.0.0.1:port (full buffer); 0 if unknown."""
    st = udp_stats(port)
    return st[1] if st else 0


def wait_until_read(port: int, proc: subprocess.Popen | None = None, timeout: float = EVENT_TIMEOUT_S) -> float:
    """Wait until the socket on 127.0.0.1:port holds nothing unread; return the wall time (time.time()) seen."""
    def empty() -> float | None:
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"exited ({proc.returncode}) with input unread on port {port}")
        st = udp_stats(port)
        return time.time() if st is None or st[0] == 0 else None

    return float(wait_until(empty, f"everything sent to port {port} read", timeout))


def wait_for_room(port: int, limit: int = ROOM_BYTES) -> None:
    """Backpressure for a test's sender: wait while the receiver on port has more than ``limit`` bytes unread.

    A test that must deliver every datagram paces its sender with this, so a busy
    machine slows the test down instead of overflowing the receiver's buffer.
    """
    wait_until(lambda: (udp_stats(port) or (0, 0))[0] <= limit, f"receiver on port {port} reading", poll=0.002)


def softnet_dropped() -> int:
    """Packets the kernel dropped machine-wide before any socket (backlog full; /proc/net/softnet_stat)."""
    try:
        with open("/proc/net/softnet_stat", encoding="ascii") as fh:
            return sum(int(line.split()[1], 16) for line in fh if line.strip())
    except (OSError, IndexError, ValueError):
        return 0


def recv_stamped(sock: socket.socket) -> list[tuple[float, bytes]]:
    """Every datagram waiting in ``sock`` with its kernel receive time (time.time() scale; needs ``roomy``)."""
    import struct

    out = []
    while True:
        try:
            data, anc, _, _ = sock.recvmsg(65535, 64, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return out
        stamp = time.time()
        for level, kind, value in anc:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMP and len(value) >= 16:
                sec, usec = struct.unpack("qq", value[:16])
                stamp = sec + usec * 1e-6
        out.append((stamp, data))


def tlog_frames(path: Path) -> int:
    """MAVLink 2 frames in a tlog (each record: 8-byte big-endian microseconds, then one frame)."""
    data, n, i = path.read_bytes(), 0, 0
    while i + 8 < len(data):
        assert data[i + 8] == 0xFD, f"not a MAVLink 2 frame at byte {i + 8}"
        i += 8 + 12 + data[i + 9] + (13 if data[i + 10] & 1 else 0)
        n += 1
    assert i == len(data), "the tlog ends inside a frame"
    return n


class StampedReceiver:
    """A pymavlink parser (MAVLink 2, ardupilotmega) on a fresh 127.0.0.1 UDP port, e.g. the service's --out,
    read by a thread; every message goes to ``take(kernel receive stamp, message)``."""

    def __init__(self) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink

        self.sock = roomy(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def take(self, arrival: float, m) -> None:  # type: ignore[no-untyped-def]
        raise NotImplementedError

    def _run(self) -> None:
        while not self._stop.is_set():
            if not select.select([self.sock], [], [], 0.05)[0]:
                continue
            for arrival, data in recv_stamped(self.sock):
                self.datagram(arrival, data, list(self._parser.parse_buffer(data) or []))

    def datagram(self, arrival: float, data: bytes, msgs: list) -> None:  # type: ignore[type-arg]
        """One datagram's bytes and the messages parsed from it (each goes to ``take``)."""
        for m in msgs:
            self.take(arrival, m)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


FEED_ROOM = 4096  # bytes the kernel may hold unread for the service (about 4 small datagrams, by its accounting)


# --- the service as a subprocess fed over UDP ---------------------------------------------------
class Feed:
    """File-like sink for a pymavlink encoder: one datagram per frame to the service, paced so the
    service's socket never holds more than a few datagrams unread (support.wait_for_room with a
    4 KiB limit, checked every 4 frames). Every sample must be navigated for the closed form to
    hold, and the service skips input that waited over 0.25 s once it keeps finding such input
    for 2 s (docs/reliability.md): with at most ~8 datagrams ahead of any one, even a slow service
    (ms per sample) reads each long before that, so no sample is ever shed."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.dest = ("127.0.0.1", port)
        self.n = 0

    def write(self, buf: bytes) -> None:
        if self.n % 4 == 3:
            wait_for_room(self.dest[1], FEED_ROOM)
        self.sock.sendto(buf, self.dest)
        self.n += 1


@dataclass
class RunResult:
    log: str
    counters: dict[str, str]
    nav: np.ndarray


class ServiceProcess:
    """``mavins run OPTIONS`` listening on a free port of 127.0.0.1, writing ``-o nav.csv``."""

    def __init__(self, tmp: Path, *options: str) -> None:
        self.port = free_udp_port()
        self.log_path, self.nav_path = tmp / "service.log", tmp / "nav.csv"
        cmd = [*MAVINS, "run", "--master", f"udpin:127.0.0.1:{self.port}", "-o", str(self.nav_path), *options]
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=ENV, cwd=tmp)
        wait_for_line(self.log_path, "ready: listening on", self.proc)
        self.feed = Feed(self.port)

    def mav(self, sysid: int = 1, compid: int = 1):  # type: ignore[no-untyped-def]
        """A pymavlink encoder whose frames go to the service (MAVLink 2)."""
        from pymavlink.dialects.v20 import ardupilotmega as mavlink

        return mavlink.MAVLink(self.feed, srcSystem=sysid, srcComponent=compid)

    def stop(self) -> RunResult:
        """Wait until the service has read every datagram, stop it (SIGINT) and collect."""
        try:
            wait_until_read(self.port, self.proc)
            self.proc.send_signal(signal.SIGINT)
            self.proc.wait(EVENT_TIMEOUT_S)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait(10)
            self.feed.sock.close()
        log = self.log_path.read_text(errors="replace")
        assert self.proc.returncode == 0 and "Traceback" not in log, log
        nav = np.loadtxt(self.nav_path, delimiter=",", skiprows=1, ndmin=2)
        return RunResult(log, summary(log), nav)


def mag_by_hand(tans: list[float], p0: float, r: float, nu: float) -> tuple[float, float]:
    """Scalar Kalman algebra of the north tilt under heading samples at declination 0 (H_N = -tan I, the other
    states uncorrelated): samples of tan I ``tans[:-1]`` with nu = 0, each H from the mean of those before (its
    own for the first), then one with innovation nu. Returns (its NIS, its north-tilt correction x_N)."""
    p = p0
    for k, _ in enumerate(tans[:-1]):
        h = tans[0] if k == 0 else sum(tans[:k]) / k
        p -= p * p * h * h / (h * h * p + r)
    h = -(sum(tans[:-1]) / (len(tans) - 1) if len(tans) > 1 else tans[-1])
    S = h * h * p + r
    return nu * nu / S, p * h * nu / S


# --- the live engine fed a simulated run in this process ------------------------------------------------------
def horizontal_errors(rows: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """North and east errors (m) of rows ``t, lat, lon (rad), ...`` against the truth row (sim file units) at or
    after each row's time, through the WGS-84 radii of curvature at the truth's latitude and height."""
    k = np.clip(np.searchsorted(truth[:, 0], rows[:, 0]), 0, len(truth) - 1)
    lat = np.radians(truth[k, 1])
    e2 = F * (2.0 - F)
    r_n = A * (1 - e2) / (1 - e2 * np.sin(lat) ** 2) ** 1.5
    r_e = A / np.sqrt(1 - e2 * np.sin(lat) ** 2)
    h = truth[k, 3]
    return np.column_stack([(rows[:, 1] - lat) * (r_n + h),
                            (rows[:, 2] - np.radians(truth[k, 2])) * (r_e + h) * np.cos(lat)])


def feed_engine(engine, run, gnss: np.ndarray, each_fix=None, row=None, wheel=None,  # type: ignore[no-untyped-def]
                vision=None) -> list:
    """Feed ``engine`` (mavins.live.engine.Engine) the run's IMU samples (sim.generate.SimRun, its rates) and the
    GNSS rows ``gnss`` (sim.aiding.simulate_aiding's columns: horizontal velocity only, as GPS_RAW_INT gives)
    at their times, each fix before the first sample after it; ``each_fix(engine, j, fix_row)`` runs after
    each fix (e.g. its dual-antenna heading); ``wheel`` rows (sim.aiding.wheel: t, speed, sigma) go to
    ``engine.on_wheel`` likewise, and ``vision`` rows (t, vn, ve, vd, sigma: m/s) to ``engine.on_vision_velocity``.
    Returns ``row(solution)`` for every output set (default: the solution row)."""
    import math as _math

    from mavins.core.records import ImuSample

    w, f = run.rates()
    out, j, k, m = [], 0, 0, 0
    wheel = np.zeros((0, 3)) if wheel is None else wheel
    vision = np.zeros((0, 5)) if vision is None else vision
    for i, t in enumerate(run.t.tolist()):
        while k < len(wheel) and wheel[k, 0] <= t:
            engine.on_wheel(float(wheel[k, 0]), float(wheel[k, 1]), float(wheel[k, 2]))
            k += 1
        while m < len(vision) and vision[m, 0] <= t:
            engine.on_vision_velocity(float(vision[m, 0]), tuple(vision[m, 1:4].tolist()), float(vision[m, 4]), False)
            m += 1
        while j < len(gnss) and gnss[j, 0] <= t:
            r = gnss[j].tolist()
            engine.on_gnss(r[0], r[1], r[2], r[3], (r[4], r[5], _math.nan), r[7], r[8], r[9])
            if each_fix is not None:
                each_fix(engine, j, r)
            j += 1
        sol = engine.on_imu(ImuSample(t, tuple(w[i].tolist()), tuple(f[i].tolist()), None, 1, 1))
        if sol is not None:
            out.append(sol.row if row is None else row(sol))
    return out


# -- Monte Carlo consistency --------------------------------------------------------------------------------------
Z975 = 1.959963984540054  # the standard normal's 97.5 % quantile
Z995 = 2.5758293035489004  # and its 99.5 %


def chi2_quantile(z: float, k: float) -> float:
    """Wilson-Hilferty: the chi-square(k) quantile at the standard normal quantile z."""
    c = 2.0 / (9.0 * k)
    return k * (1.0 - c + z * math.sqrt(c)) ** 3


def consumer_stochastic(grade: str = "consumer"):  # type: ignore[no-untyped-def]
    """The simulator's error model of a grade (consumer by default) without the errors outside the filter's model
    (scale factors, misalignments, g-sensitivity, dropped samples): what a consistency test simulates."""
    import dataclasses

    from sim import errors

    m = errors.grade(grade)
    zero33 = ((0.0, 0.0, 0.0),) * 3

    def strip(s: errors.SensorErrorModel) -> errors.SensorErrorModel:
        return dataclasses.replace(s, scale_factor_ppm=(0.0, 0.0, 0.0), misalignment=zero33)

    return dataclasses.replace(m, gyro=strip(m.gyro), accel=strip(m.accel), g_sensitivity=zero33, drop_probability=0.0)

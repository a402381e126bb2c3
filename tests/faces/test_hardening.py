"""Hardening, live: ``mavins run`` as a real subprocess on 127.0.0.1, fed by this test over UDP.

The valid data is the simulator's (``sim.generate.generate`` + ``sim.stream.frames``:
HEARTBEAT, HIGHRES_IMU, SIM_STATE, ATTITUDE, GPS_RAW_INT, SCALED_PRESSURE, one
message per datagram, as an autopilot sends them). The test sends the
datagrams itself, paced, so that it can put faults between valid frames, drop,
duplicate and reorder them, or flood the service. Every run is bounded in time
and in datagrams; docs/reliability.md lists each case with its counts and the
guarantees that follow.

* ``test_faults_then_valid_data``: garbage, truncated frames, bad CRCs, NaN/Inf
  and out-of-range samples, duplicates, late (backwards) datagrams, a 5 s gap
  and an autopilot restart (time back by more than 1 s) between valid frames;
  the process stays up, every fault is counted, and the solution is right
  again afterwards (roll/pitch within 1 deg of the truth, through a manoeuvre).
* ``test_lossy_link``: a UDP proxy drops, duplicates and reorders a fixed
  fraction of the datagrams of a manoeuvring flight; the attitude stays within
  a bound derived from the losses themselves (see ``loss_bound``).
* ``test_flood_*``: the service stopped (SIGSTOP) while its socket overflows,
  then flooded at the sender's full speed: it stays up, every datagram is
  processed or counted (exactly, against the kernel's own counts), the output
  stays on sensor time and is back at ``--rate`` afterwards. Memory and the
  output rate during a flood are benchmark figures (bench_flood.py).
* ``test_sigterm_leaves_readable_recording_and_tlog``: SIGTERM mid-stream: exit
  code 0, the Rerun file reads back, the tlog replays to the same solution.

Nothing here depends on the machine's speed: senders wait while the service's
socket holds more than 64 KiB (backpressure), runs end on events (the service
has read everything), and waits have generous timeouts.
* ``test_signing_accepts_only_the_key_holder``: signed peer accepted, unsigned
  and wrong-key peers rejected and counted.
* ``test_long_extreme_stream_keeps_service_up``: 600 in-range but extreme
  samples (the unaided vertical channel runs away): the process stays up.
"""

from __future__ import annotations

import math
import os
import random
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from sim.generate import SimRun, generate  # noqa: E402
from sim.scenarios import Scenario  # noqa: E402
from sim.stream import StreamOptions, frames  # noqa: E402
from support import (  # noqa: E402
    EVENT_TIMEOUT_S, READY_TIMEOUT_S, StampedReceiver, kernel_drops, quat_angle_deg, roomy,
    softnet_dropped, tlog_frames, wait_for_room, wait_until, wait_until_read, wrap_deg,
)

BIN = Path(sys.executable).parent
MAVINS = [str(BIN / "mavins")] if (BIN / "mavins").is_file() else [sys.executable, "-m", "mavins.cli"]
ENV = {**os.environ, "MAVLINK20": "1", "PYTHONUNBUFFERED": "1", "PYTHONFAULTHANDLER": "1"}
START = (47.397742, 8.545594, 488.0)
VEH_SYS = 1
BOOT_US = 600_000_000  # the simulated autopilot booted 10 min before the data starts
G = 9.80665


# -- the service as a subprocess ---------------------------------------------------------
def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Svc:
    """``mavins run --master udpin:127.0.0.1:PORT ARGS`` with its log in a file; killed on exit if still up."""

    def __init__(self, tmp: Path, *args: str, name: str = "service", port: int | None = None) -> None:
        self.port = port or free_udp_port()
        self.addr = ("127.0.0.1", self.port)
        self.log_path = tmp / f"{name}.log"
        self.cmd = [*MAVINS, "run", "--master", f"udpin:127.0.0.1:{self.port}", *args]
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen(self.cmd, stdout=log, stderr=subprocess.STDOUT, env=ENV, cwd=tmp)
        self.wait_for("ready: listening on", READY_TIMEOUT_S)  # after the kernels are loaded (or compiled)

    def __enter__(self) -> Svc:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)

    def wait_for(self, text: str, timeout: float = EVENT_TIMEOUT_S) -> None:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if text in self.log():
                return
            if self.proc.poll() is not None:
                raise AssertionError(f"service exited ({self.proc.returncode}) before {text!r}:\n{self.log()}")
            time.sleep(0.05)
        raise AssertionError(f"no {text!r} within {timeout} s:\n{self.log()}")

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def alive(self) -> bool:
        return self.proc.poll() is None

    def settle(self) -> float:
        """Wait until the service has read everything sent to it (an event, not a pause); the wall time then."""
        return wait_until_read(self.port, self.proc)

    def pause(self) -> None:
        """Stop the process (SIGSTOP) and wait until it is stopped: a stall of any length, made on purpose."""
        self.proc.send_signal(signal.SIGSTOP)
        wait_until(lambda: Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "T",
                   "the service stopped")

    def resume(self) -> None:
        self.proc.send_signal(signal.SIGCONT)

    def stop(self, sig: int = signal.SIGTERM, timeout: float = EVENT_TIMEOUT_S, send: bool = True) -> int:
        """Signal the service (unless ``send`` is False: already signalled) and wait for its exit code."""
        if self.proc.poll() is None:
            if send:
                self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.send_signal(signal.SIGABRT)  # faulthandler (on in ENV) writes every thread's stack
                try:
                    self.proc.wait(10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(5)
                raise AssertionError(f"no exit within {timeout} s of signal {sig}:\n{self.log()}") from None
        return int(self.proc.returncode)

    def summary(self) -> dict[str, str]:
        """The ``mavins run: key: value`` lines printed on exit."""
        out = {}
        for line in self.log().splitlines():
            if line.startswith("mavins run: ") and ": " in line[12:]:
                k, v = line[12:].split(": ", 1)
                out[k] = v
        return out

    def count(self, key: str) -> int:
        return int(self.summary().get(key, 0))


# -- simulated data -------------------------------------------------------------------
def scenario(name: str, segments: list[dict], rate: float, roll: float = 0.0, pitch: float = 0.0,
             yaw: float = 0.0, perturbations: list[dict] | None = None) -> Scenario:
    doc = {"description": name, "start": {"lat": START[0], "lon": START[1], "h": START[2], "roll": roll,
                                          "pitch": pitch, "yaw": yaw},
           "imu": {"rate": rate}, "segments": segments, "perturbations": perturbations or []}
    return Scenario(name, f"test_hardening:{name}", doc)


@dataclass
class Item:
    """One datagram of the stream: simulated time (s), message type, bytes, IMU sample index or -1."""

    t: float
    name: str
    data: bytes
    imu: int = -1


def encode(run: SimRun, enc: mavlink.MAVLink, t_from: float = -1.0, t_to: float = 1e99,
           shift_us: int = BOOT_US) -> list[Item]:
    """The simulator's stream for t_from < t <= t_to, sensor times shifted by ``shift_us`` (us)."""
    items: list[Item] = []
    for i, (t, msgs) in enumerate(frames(run, enc, StreamOptions(sysid=VEH_SYS))):
        if t <= t_from:
            continue
        if t > t_to:
            break
        for m in msgs:
            if hasattr(m, "time_usec"):
                m.time_usec += shift_us
            elif hasattr(m, "time_boot_ms"):
                m.time_boot_ms = (m.time_boot_ms + shift_us // 1000) % 2**32
            items.append(Item(t, m.get_type(), m.pack(enc), i if m.get_type() == "HIGHRES_IMU" else -1))
            enc.seq = (enc.seq + 1) % 256
    return items


def send_paced(sock: socket.socket, dest: tuple[str, int], items: list[Item], speed: float,
               t0: float | None = None) -> None:
    """Send each item when its simulated time comes, at ``speed`` x real time."""
    if not items:
        return
    t_first = items[0].t if t0 is None else t0
    wall0 = time.monotonic()
    for k, it in enumerate(items):
        delay = wall0 + (it.t - t_first) / speed - time.monotonic()
        if delay > 0.002:
            time.sleep(delay)
        if k % 16 == 15:
            wait_for_room(dest[1])  # a busy receiver slows the sender down; nothing overflows
        sock.sendto(it.data, dest)


def udp_socket(rcvbuf: int = 4 << 20) -> socket.socket:
    s = roomy(socket.socket(socket.AF_INET, socket.SOCK_DGRAM), rcvbuf)
    s.bind(("127.0.0.1", 0))
    return s


def read_nav(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def truth_at(run: SimRun, t_sim: np.ndarray) -> np.ndarray:
    """Truth rows (deg for angles) at simulated times, by nearest sample (outputs are stamped at samples)."""
    tt = run.exact.truth[:, 0]
    idx = np.clip(np.searchsorted(tt, t_sim - 1e-7), 0, len(tt) - 1)
    assert np.all(np.abs(tt[idx] - t_sim) < 1e-5), "output times are sample times"
    return run.exact.truth[idx]


def imu_frame(enc: mavlink.MAVLink, t_us: int, f: tuple, w: tuple, fields: int = 0b111111) -> bytes:
    return enc.highres_imu_encode(t_us, *f, *w, 0, 0, 0, 0, 0, 0, 20.0, fields, 0).pack(enc)


def nav_args(align: float, *extra: str) -> list[str]:
    """Free inertial (``--aiding none``): these tests hold the strapdown to its closed-form accuracy
    while the link misbehaves; aiding is tested in test_autopilot_conformance.py."""
    return ["--lat", str(START[0]), "--lon", str(START[1]), "--alt", str(START[2]), "--heading", "vehicle",
            "--align", str(align), "--aiding", "none", *extra]


# -- 1. faults between valid frames -------------------------------------------------------
FAULT_STATIC_S = 18.0  # tilted at rest; then a 4 s roll/pitch manoeuvre; at rest again


def test_faults_then_valid_data(tmp_path: Path) -> None:
    run = generate(scenario("faults", [{"kind": "static", "duration": FAULT_STATIC_S},
                                       {"kind": "attitude", "duration": 4.0, "roll": 15.0, "pitch": 10.0},
                                       {"kind": "static", "duration": 3.0}], 100.0, roll=3.0, pitch=-2.0,
                            yaw=30.0), grade="ideal")
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    bad = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    rng = random.Random(1)
    w_all, f_all = run.rates()
    # A: valid 0..4 s (aligned at 2 s); B: valid 4..8 s with a fault after every valid IMU datagram
    stream = encode(run, enc, t_to=4.0)
    counts = dict(garbage=0, truncated=0, bad_crc=0, non_finite=0, out_of_range=0, fields_missing=0,
                  duplicate=0, backwards=0)
    for it in encode(run, enc, t_from=4.0, t_to=8.0):
        stream.append(it)
        if it.imu < 0:
            continue
        t_us = int(round(run.t[it.imu] * 1e6)) + BOOT_US
        k = it.imu % 8
        if k == 0:  # random bytes
            stream.append(Item(it.t, "garbage", bytes(rng.randrange(256) for _ in range(rng.randrange(1, 200)))))
            counts["garbage"] += 1
        elif k == 1:  # the next sample, one payload byte changed: CRC fails
            fr = bytearray(imu_frame(bad, t_us + 5000, (0.0, 0.0, -9.8), (0.5, 0.0, 0.0)))
            fr[20] ^= 0x55
            stream.append(Item(it.t, "bad_crc", bytes(fr)))
            counts["bad_crc"] += 1
        elif k == 2:  # NaN / Inf sample between two valid ones
            v = [0.0, 0.0, -9.8, 0.0, 0.0, 0.0]
            v[rng.randrange(6)] = rng.choice([math.nan, math.inf, -math.inf])
            stream.append(Item(it.t, "non_finite", imu_frame(bad, t_us + 5000, tuple(v[:3]), tuple(v[3:]))))
            counts["non_finite"] += 1
        elif k == 3:  # beyond the sensor range
            stream.append(Item(it.t, "out_of_range", imu_frame(bad, t_us + 5000, (0.0, 0.0, -9.8), (0.0, 0.0, 50.0))))
            counts["out_of_range"] += 1
        elif k == 4:  # the same datagram again
            stream.append(Item(it.t, "duplicate", it.data))
            counts["duplicate"] += 1
        elif k == 5:  # a late datagram: 0.5 s old, plausible but wrong values
            stream.append(Item(it.t, "backwards", imu_frame(bad, t_us - 500_000, (0.3, 0.0, -9.8), (0.2, 0.0, 0.0))))
            counts["backwards"] += 1
        elif k == 6:  # a truncated frame
            stream.append(Item(it.t, "truncated", imu_frame(bad, t_us + 5000, (0.0, 0.0, -9.8), (0.0,) * 3)[:30]))
            counts["truncated"] += 1
        else:  # fields_updated without the gyro bits
            stream.append(Item(it.t, "fields", imu_frame(bad, t_us + 5000, (0.0, 0.0, -9.8), (1.0, 0.0, 0.0),
                                                          fields=0b000111)))
            counts["fields_missing"] += 1
    # C: a 5 s gap (no data 8..13 s); D: valid 13..14 s; E: the autopilot restarts: time starts again at 5 s
    stream += encode(run, enc, t_from=13.0, t_to=14.0)
    restart_us = 5_000_000 - int(14.0 * 1e6)
    stream += encode(run, enc, t_from=14.0, shift_us=restart_us)
    n_imu_valid = sum(1 for it in stream if it.name == "HIGHRES_IMU")
    nav = tmp_path / "nav.csv"
    sock = udp_socket()
    with Svc(tmp_path, *nav_args(2.0, "-o", str(nav))) as svc:
        send_paced(sock, svc.addr, stream, speed=6.0)
        svc.settle()
        assert svc.alive(), svc.log()
        rc = svc.stop()
    log = svc.log()
    assert rc == 0, log
    assert "Traceback" not in log, log
    c = svc.summary()
    print("\nfaults injected:", counts, "\nservice summary:", c)
    # every valid sample taken, every fault refused and counted by reason
    assert svc.count("imu_accepted") == n_imu_valid, c
    assert svc.count("rejected_bad_crc") == counts["bad_crc"]
    assert svc.count("rejected_garbage") + svc.count("rejected_truncated") >= counts["garbage"] + counts["truncated"]
    assert svc.count("rejected_non_finite") == counts["non_finite"]
    assert svc.count("rejected_out_of_range") == counts["out_of_range"]
    assert svc.count("rejected_fields_missing") == counts["fields_missing"]
    assert svc.count("rejected_duplicate_time") == counts["duplicate"]
    # late datagrams, plus the first sample after the autopilot restart (which starts the re-alignment)
    assert svc.count("rejected_time_backwards") == counts["backwards"] + 1
    assert svc.count("restarts") == 1 and svc.count("gaps_long") == 1, c
    assert c.get("final state") == "NAVIGATING"
    # the solution after the restart: re-aligned at rest, then through the manoeuvre, against the truth
    rows = read_nav(nav)
    after = rows[rows[:, 0] * 1e6 < BOOT_US]  # the new time base
    t_sim = after[:, 0] - restart_us * 1e-6
    assert t_sim[0] < FAULT_STATIC_S and t_sim[-1] > FAULT_STATIC_S + 6.0, "navigated through the manoeuvre"
    tr = truth_at(run, t_sim)
    err = np.abs(wrap_deg(after[:, 7:10] - tr[:, 7:10]))
    assert np.ptp(tr[:, 7]) > 10.0, "the manoeuvre rolls by 12 deg"
    print(f"after the restart: max |roll, pitch, yaw| error {err.max(0)} deg over {len(after)} output sets")
    assert err[:, :2].max() < 1.0
    # before the restart: the gap was skipped, not integrated, so the attitude at rest was still right
    before = rows[(rows[:, 0] * 1e6 >= BOOT_US + 13e6)]
    assert len(before) > 0
    tr = truth_at(run, before[:, 0] - BOOT_US * 1e-6)
    assert np.abs(wrap_deg(before[:, 7:9] - tr[:, 7:9])).max() < 1.0


# -- 2. a lossy link -----------------------------------------------------------------------
P_DROP, P_DUP, P_REORDER = 0.05, 0.03, 0.03


class LossyProxy:
    """UDP relay 127.0.0.1:port -> dest that drops, duplicates and reorders datagrams at fixed rates.

    Reordering holds a datagram back and sends it after the next one. ``forwarded``
    keeps what was sent on, in order (the service sees exactly that: loopback UDP
    neither loses nor reorders).
    """

    def __init__(self, dest: tuple[str, int], seed: int = 3) -> None:
        self.rx = udp_socket()
        self.port = self.rx.getsockname()[1]
        self.tx = udp_socket()
        self.dest = dest
        self.rng = random.Random(seed)
        self.forwarded: list[bytes] = []
        self.received = self.dropped = self.duplicated = self.reordered = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _send(self, data: bytes) -> None:
        if len(self.forwarded) % 16 == 15:
            wait_for_room(self.dest[1])  # never overflow the service: the proxy's losses are the only ones
        self.tx.sendto(data, self.dest)
        self.forwarded.append(data)

    def _run(self) -> None:
        held: bytes | None = None
        while not self._stop.is_set():
            ready, _, _ = select.select([self.rx, self.tx], [], [], 0.05)
            for s in ready:
                data = s.recv(65535)
                if s is self.tx:
                    continue  # the service's output to its peer: not needed here
                self.received += 1
                u = self.rng.random()
                if u < P_DROP:
                    self.dropped += 1
                    continue
                if u < P_DROP + P_REORDER and held is None:
                    held = data
                    self.reordered += 1
                    continue
                self._send(data)
                if u < P_DROP + P_REORDER + P_DUP:
                    self._send(data)
                    self.duplicated += 1
                if held is not None:
                    self._send(held)
                    held = None
        if held is not None:
            self._send(held)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(EVENT_TIMEOUT_S)  # it may be waiting for room at the service
        self.rx.close()
        self.tx.close()


def level_deg(f_mean: np.ndarray) -> np.ndarray:
    """Roll, pitch (deg) from a mean specific force at rest (the service's coarse levelling)."""
    fx, fy, fz = f_mean
    return np.degrees([math.atan2(-fy, -fz), math.atan2(fx, math.hypot(fy, fz))])


@dataclass
class LossBound:
    """What losses can do to a solution on interval-averaged rates (see ``loss_bound``)."""

    t: np.ndarray  # sample times of the accepted samples
    att_rad: np.ndarray  # worst case: sum of |e_r| up to each accepted sample (rad)
    vel: np.ndarray  # worst case for velocity (m/s), without the attitude coupling
    att_rw_rad: np.ndarray  # random walk: sqrt(sum of |e_r|^2) (rad)
    vel_rw: np.ndarray  # random walk for velocity (m/s)
    lost: int
    align_deg: float  # level difference of the alignment mean with and without the lost samples
    per_loss_rad: float  # rms of |w_next - w_lost| dt over the lost samples (the a-priori per-loss error)


def loss_bound(run: SimRun, accepted: np.ndarray, align_s: float) -> LossBound:
    """Bound on the extra attitude and velocity error caused by the samples the service never saw.

    HIGHRES_IMU carries interval averages (PX4): sample k is the mean rate w_k over
    (t_{k-1}, t_k], so the exact angle increment is w_k dt_k. When samples j of a
    run L are lost, the next accepted sample r is integrated over the whole
    interval, w_r (t_r - t_p) = sum over j in L + {r} of w_r dt_j; the angle
    increment errs by e_r = sum_j (w_r - w_j) dt_j, i.e. by the change of the
    rate over the lost interval times its length. Attitude errors of successive
    small rotations add at most linearly, so after any number of losses the
    extra attitude error is at most B(t) = sum over accepted r <= t of
    sum_j |w_r - w_j| dt_j (plus second-order coning terms, far smaller). The
    same holds for the velocity increment with f in place of w, plus the
    specific force (about g) tilted by the attitude error. During alignment a
    loss only changes which samples are averaged: its effect is the difference
    of the two levelling results, computed here exactly.

    That worst case assumes every error points the same way. Here the rate
    changes come mostly from random vibration (zero mean, 40-90 Hz), so the
    errors of different losses are independent and add as a random walk:
    sigma(t)^2 = sum over r <= t of |e_r|^2, and |sum| > 4 sigma has a
    probability below 1e-8 for a 3-D Gaussian sum. A-priori, with an effective
    loss rate p (drops, plus reordered datagrams that arrive after their
    successor) over N samples: sigma ~ sqrt(p N) * rms(|w_{k+1} - w_k| dt).
    """
    w, f = run.rates()
    t = run.t
    dt = np.diff(np.concatenate(([run.exact.t0], t)))
    acc = np.sort(accepted)
    first = acc[0]
    t_align_end = t[first] + align_s
    clean_win = (t >= t[first]) & (t <= t_align_end + 1e-9)
    lossy_win = acc[(t[acc] >= t[first]) & (t[acc] <= t_align_end + 1e-9)]
    align_deg = float(np.max(np.abs(level_deg(f[clean_win].mean(0)) - level_deg(f[lossy_win].mean(0)))))
    b_att = np.zeros(len(acc))
    b_vel = np.zeros(len(acc))
    s_att = np.zeros(len(acc))
    s_vel = np.zeros(len(acc))
    per_loss = []
    for n in range(1, len(acc)):
        p, r = acc[n - 1], acc[n]
        skipped = np.arange(p + 1, r)
        ea = ev = 0.0
        if len(skipped) and t[r] > t_align_end:
            ea = float(np.sum(np.linalg.norm(w[r] - w[skipped], axis=1) * dt[skipped]))
            ev = float(np.sum(np.linalg.norm(f[r] - f[skipped], axis=1) * dt[skipped]))
            per_loss.append(ea / len(skipped))
        b_att[n] = b_att[n - 1] + ea
        b_vel[n] = b_vel[n - 1] + ev
        s_att[n] = s_att[n - 1] + ea**2
        s_vel[n] = s_vel[n - 1] + ev**2
    return LossBound(t[acc], b_att, b_vel, np.sqrt(s_att), np.sqrt(s_vel), len(t) - len(acc), align_deg,
                     float(np.sqrt(np.mean(np.square(per_loss)))) if per_loss else 0.0)


def accepted_samples(datagrams: list[bytes], usec_to_index: dict[int, int]) -> np.ndarray:
    """The IMU samples the service accepts from datagrams in this order (strictly increasing time)."""
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    last = -1
    out = []
    for d in datagrams:
        for m in p.parse_buffer(d) or []:
            if m.get_type() == "HIGHRES_IMU" and m.time_usec > last:
                last = m.time_usec
                out.append(usec_to_index[m.time_usec])
    return np.array(out)


def clean_solution(items: list[Item], args: dict) -> np.ndarray:
    """The same stream without losses through the same pipeline, in process: the solution rows."""
    from mavins.live.engine import EngineConfig
    from mavins.link.ingest import IngestConfig
    from mavins.live.pipeline import Pipeline

    pipe = Pipeline(EngineConfig(**args), IngestConfig())
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    rows = []
    for it in items:
        for m in p.parse_buffer(it.data) or []:
            out = pipe.handle(m)
            if out is not None:
                r = out.row.copy()
                r[7:10] = np.degrees(r[7:10])
                rows.append(r)
    return np.array(rows)


LOSSY_ALIGN_S = 5.0


def test_lossy_link(tmp_path: Path) -> None:
    run = generate(scenario("lossy", [{"kind": "static", "duration": 6.0},
                                      {"kind": "accelerate", "speed": 8.0, "accel": 2.0, "tilt": True},
                                      {"kind": "turn", "angle": 180.0, "rate": 30.0},
                                      {"kind": "cruise", "duration": 2.0},
                                      {"kind": "turn", "angle": -90.0, "rate": 30.0}], 250.0,
                            perturbations=[{"kind": "random_vibration", "angular_psd": 1e-6, "linear_psd": 1e-3,
                                            "band": [40.0, 90.0], "seed": 7}]), grade="ideal")
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    items = encode(run, enc)
    usec_to_index = {int(round(t * 1e6)) + BOOT_US: i for i, t in enumerate(run.t)}
    nav = tmp_path / "nav.csv"
    sock = udp_socket()
    with Svc(tmp_path, *nav_args(LOSSY_ALIGN_S, "--gyro-bias", "none", "-o", str(nav))) as svc:
        proxy = LossyProxy(svc.addr)
        try:
            send_paced(sock, ("127.0.0.1", proxy.port), items, speed=4.0)
            wait_until_read(proxy.port)
        finally:
            proxy.close()  # joins the relay thread: everything it read is forwarded
        svc.settle()
        rc = svc.stop()
    assert rc == 0, svc.log()
    n_imu = len(run.t)
    acc = accepted_samples(proxy.forwarded, usec_to_index)
    print(f"\nproxy: {proxy.received} datagrams in, {proxy.dropped} dropped, {proxy.duplicated} duplicated, "
          f"{proxy.reordered} reordered; IMU samples {n_imu}, accepted {len(acc)}")
    assert proxy.received == len(items)
    # the service saw exactly what the proxy forwarded, and took exactly the samples the model says
    assert svc.count("imu_accepted") == len(acc), svc.summary()
    assert svc.count("rejected_duplicate_time") + svc.count("rejected_time_backwards") > 0
    assert svc.count("restarts") == 0
    bound = loss_bound(run, acc, LOSSY_ALIGN_S)
    lost_rate = bound.lost / n_imu
    assert 0.04 < lost_rate < 0.12, "drops + reordered-late samples, about P_DROP + P_REORDER"
    rows = read_nav(nav)
    t_sim = rows[:, 0] - BOOT_US * 1e-6
    tr = truth_at(run, t_sim)
    err = quat_angle_deg(rows[:, 10:14], tr[:, 10:14])
    verr = np.linalg.norm(rows[:, 4:7] - tr[:, 4:7], axis=1)
    # the same stream without losses through the same pipeline (in process): its error envelope
    clean = clean_solution(items, dict(lat=START[0], lon=START[1], alt=START[2], heading="vehicle",
                                       align=LOSSY_ALIGN_S, gyro_bias="none"))
    ct = clean[:, 0] - BOOT_US * 1e-6
    ctr = truth_at(run, ct)
    cerr = np.maximum.accumulate(quat_angle_deg(clean[:, 10:14], ctr[:, 10:14]))
    cverr = np.maximum.accumulate(np.linalg.norm(clean[:, 4:7] - ctr[:, 4:7], axis=1))
    k = np.searchsorted(ct, t_sim, side="right") - 1
    k = np.clip(k + 1, 0, len(ct) - 1)  # the clean envelope up to the next clean output
    j = np.clip(np.searchsorted(bound.t, t_sim + 1e-7) - 1, 0, len(bound.t) - 1)
    t_nav = np.maximum(t_sim - (bound.t[0] + LOSSY_ALIGN_S), 0.0)
    # worst case (triangle inequality) and random walk (4 sigma) of what the losses can add
    worst_deg = np.degrees(bound.att_rad[j]) + bound.align_deg
    worst_vel = bound.vel[j] + G * np.radians(worst_deg) * t_nav
    rw_deg = 4 * np.degrees(bound.att_rw_rad[j]) + bound.align_deg
    rw_vel = 4 * bound.vel_rw[j] + G * np.radians(rw_deg) * t_nav
    a_priori = 4 * math.degrees(math.sqrt(bound.lost) * bound.per_loss_rad)
    print(f"lost samples {bound.lost} ({100 * lost_rate:.1f} %), rms error per loss {bound.per_loss_rad:.2e} rad, "
          f"alignment {bound.align_deg:.5f} deg\n"
          f"attitude: measured max error {err.max():.4f} deg (clean run {cerr[-1]:.4f} deg); limits at the end: "
          f"4 sigma {rw_deg[-1]:.4f} deg (a-priori 4 sqrt(pN) rms = {a_priori:.4f} deg), worst case {worst_deg[-1]:.4f}\n"
          f"velocity: measured max error {verr.max():.4f} m/s (clean {cverr[-1]:.4f}); limits 4 sigma "
          f"{rw_vel[-1]:.3f} m/s, worst case {worst_vel[-1]:.3f} m/s")
    assert len(rows) > 0.9 * (t_sim[-1] - t_sim[0]) * 50.0, "outputs at --rate in sensor time despite losses"
    assert np.all(err <= cerr[k] + worst_deg + 1e-4)
    assert np.all(verr <= cverr[k] + worst_vel + 1e-3)
    assert np.all(err <= cerr[k] + rw_deg + 1e-4), np.max(err - cerr[k] - rw_deg)
    assert np.all(verr <= cverr[k] + rw_vel + 1e-3), np.max(verr - cverr[k] - rw_vel)
    # the limit follows from the loss rate: the data-derived sigma is the a-priori one
    assert 0.5 < (rw_deg[-1] - bound.align_deg) / a_priori < 2.0


# -- 3. a flood ----------------------------------------------------------------------------
OUT_RATE = 50.0
PRE_S = 2.0  # 250 Hz at rest before the overload (aligned after 1 s)
PRE_HZ = POST_HZ = 250.0
FLOOD_N = 300_000  # datagrams sent as fast as this process can after the stall: more than any service parses
FLOOD_STEP_US = 5  # sensor time between flood samples (a 200 kHz stream)
BURST_CHUNK = 2_000  # datagrams sent into the stopped service between looks at its socket
POST_SETS = 50  # after the flood: wait until this many consecutive output sets (1 s of sensor time) arrive


def crc_x25(rows: np.ndarray, extra: int) -> np.ndarray:
    """MAVLink's CRC-16/MCRF4XX of each row of a uint8 matrix, then the message's CRC_EXTRA."""
    crc = np.full(rows.shape[0], 0xFFFF, dtype=np.uint32)
    for b in [rows[:, j].astype(np.uint32) for j in range(rows.shape[1])] + [np.full(rows.shape[0], extra, np.uint32)]:
        tmp = (b ^ (crc & 0xFF)) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def highres_block(usec: np.ndarray, f: tuple, w: tuple) -> tuple[bytes, int]:
    """Many HIGHRES_IMU frames that differ only in time_usec, built at once: (concatenated frames, frame length)."""
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    tmpl = np.frombuffer(imu_frame(enc, 0, f, w), dtype=np.uint8)
    buf = np.tile(tmpl, (len(usec), 1))
    buf[:, 10:18] = np.asarray(usec, dtype="<u8").view(np.uint8).reshape(len(usec), 8)  # payload starts at 10
    crc = crc_x25(buf[:, 1:-2], mavlink.mavlink_map[mavlink.MAVLINK_MSG_ID_HIGHRES_IMU].crc_extra)
    buf[:, -2], buf[:, -1] = crc & 0xFF, crc >> 8
    return buf.tobytes(), len(tmpl)


class Client(StampedReceiver):
    """Receives the service's --out link with kernel receive stamps; keeps ATTITUDE, SYS_STATUS, HEARTBEAT."""

    def __init__(self) -> None:
        self.attitude: list[tuple[float, int]] = []  # (kernel arrival, time_boot_ms)
        self.sys_status: list[tuple[float, object]] = []
        self.heartbeat: list[tuple[float, object]] = []
        super().__init__()

    def take(self, arrival: float, m) -> None:  # type: ignore[no-untyped-def]
        if m.get_type() == "ATTITUDE":
            self.attitude.append((arrival, m.time_boot_ms))
        elif m.get_type() == "SYS_STATUS":
            self.sys_status.append((arrival, m))
        elif m.get_type() == "HEARTBEAT":
            self.heartbeat.append((arrival, m))


@dataclass
class FloodRun:
    """One overloaded run (see ``flood``): what was sent, what the kernel and the service counted."""

    sent: int  # datagrams sent to the service, all phases (every one a valid HIGHRES_IMU)
    burst: int  # of which sent while the service was stopped
    usec: np.ndarray  # time_usec of every sample sent, in order
    post_from_us: int  # first time_usec after the flood
    proc_kernel_drops: int  # the kernel's drop count of the service's socket (/proc/net/udp), after the run
    softnet_drops: int  # packets dropped machine-wide before reaching any socket during the run (normally 0)
    alive_throughout: bool
    rc: int
    summary: dict[str, str]
    log: str
    nav: np.ndarray
    tlog: Path
    status_after: object  # the first SYS_STATUS sent after the service had read everything
    attitude_ms: list[int]  # time_boot_ms of every ATTITUDE the --out client received


def _count(fr: FloodRun, key: str) -> int:
    return int(fr.summary.get(key, 0))


@pytest.fixture(scope="module")
def flood(tmp_path_factory: pytest.TempPathFactory) -> FloodRun:
    """A navigating service is overloaded twice: stopped (SIGSTOP) while its socket is filled until the
    kernel drops, then flooded at the sender's full speed (HIGHRES_IMU 5 us apart in sensor time); then
    valid 250 Hz data again until the output is back at --rate. Overload is made, not hoped for: the
    stopped process cannot read, so the kernel must drop, however fast the machine is."""
    tmp = tmp_path_factory.mktemp("flood")
    run = generate(scenario("rest", [{"kind": "static", "duration": 1.0}], 100.0, yaw=30.0), grade="ideal")
    w, f = run.rates()
    f0, w0 = tuple(float(x) for x in f[0]), tuple(float(x) for x in w[0])
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    client = Client()
    nav, tlog = tmp / "nav.csv", tmp / "in.tlog"
    usec: list[np.ndarray] = []
    sent = burst = 0
    softnet0 = softnet_dropped()
    with Svc(tmp, "--lat", str(START[0]), "--lon", str(START[1]), "--alt", str(START[2]), "--heading", "30",
             "--align", "1", "--rate", str(OUT_RATE), "--out", f"udpout:127.0.0.1:{client.port}",
             "-o", str(nav), "--tlog", str(tlog)) as svc:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.connect(svc.addr)
        alive = True

        def send_block(t_us: np.ndarray) -> None:
            nonlocal sent, alive
            blob, flen = highres_block(t_us, f0, w0)
            view = memoryview(blob)
            for i in range(len(t_us)):
                sock.send(view[i * flen:(i + 1) * flen])
            sent += len(t_us)
            usec.append(t_us)
            alive = alive and svc.alive()

        # 1. at rest, paced, until navigating
        t_next = BOOT_US
        items = [Item(i / PRE_HZ, "HIGHRES_IMU", imu_frame(enc, BOOT_US + int(i * 1e6 / PRE_HZ), f0, w0))
                 for i in range(int(PRE_S * PRE_HZ))]
        send_paced(sock, svc.addr, items, speed=1.0)
        sent += len(items)
        usec.append(BOOT_US + (np.arange(len(items)) * 1e6 / PRE_HZ).astype(np.int64))
        t_next = int(usec[-1][-1]) + FLOOD_STEP_US
        wait_until(lambda: client.attitude, "the service navigating before the overload")
        # 2. a stall: the service stopped while its socket fills, until the kernel drops (and a little more)
        svc.pause()
        drops_before = kernel_drops(svc.port)
        while kernel_drops(svc.port) == drops_before:
            assert burst < 5_000_000, "the kernel never dropped: the service's socket holds millions of datagrams?"
            send_block(t_next + FLOOD_STEP_US * np.arange(BURST_CHUNK, dtype=np.int64))
            t_next += FLOOD_STEP_US * BURST_CHUNK
            burst += BURST_CHUNK
        send_block(t_next + FLOOD_STEP_US * np.arange(BURST_CHUNK, dtype=np.int64))
        t_next += FLOOD_STEP_US * BURST_CHUNK
        burst += BURST_CHUNK
        svc.resume()
        # 3. a flood at the sender's full speed
        for a in range(0, FLOOD_N, 50_000):
            n = min(50_000, FLOOD_N - a)
            send_block(t_next + FLOOD_STEP_US * np.arange(n, dtype=np.int64))
            t_next += FLOOD_STEP_US * n
        # 4. valid data at 250 Hz until the output is back at --rate: POST_SETS consecutive sets after the flood
        post_from = t_next - FLOOD_STEP_US + int(1e6 / POST_HZ)
        period_ms = int(1000 / OUT_RATE)

        def back_at_rate() -> bool:
            ms = [m for _, m in client.attitude if m * 1000 >= post_from]
            k = np.array(ms[-POST_SETS:]) // period_ms
            return len(k) == POST_SETS and bool(np.all(np.diff(k) == 1))

        post: list[int] = []
        wall0 = time.monotonic()
        while not back_at_rate():
            assert svc.alive(), svc.log()[-3000:]
            assert time.monotonic() - wall0 < EVENT_TIMEOUT_S, "output not back at --rate after the flood"
            t_us = post_from + int(len(post) * 1e6 / POST_HZ)
            sock.send(imu_frame(enc, t_us, f0, w0))
            post.append(t_us)
            if len(post) % 16 == 0:
                wait_for_room(svc.port)
            time.sleep(max(0.0, wall0 + len(post) / POST_HZ - time.monotonic()))
        sent += len(post)
        usec.append(np.array(post, dtype=np.int64))
        # everything read, then a SYS_STATUS sent after that: its counts are the final ones
        read_at = svc.settle()
        proc_drops = kernel_drops(svc.port)
        status = wait_until(lambda: [m for a, m in client.sys_status if a > read_at], "a SYS_STATUS after the run")[0]
        alive = alive and svc.alive()
        rc = svc.stop()
        sock.close()
    client.close()
    return FloodRun(sent, burst, np.concatenate(usec), post_from, proc_drops, softnet_dropped() - softnet0, alive,
                    rc, svc.summary(), svc.log(), read_nav(nav), tlog, status, [m for _, m in client.attitude])


def test_flood_service_stays_up_and_recovers(flood: FloodRun) -> None:
    """Through a stall and a flood the process stays up, exits cleanly, and navigates right afterwards."""
    fr = flood
    print(f"\nflood: sent {fr.sent} datagrams ({fr.burst} into the stopped service); summary {fr.summary}")
    assert fr.alive_throughout and fr.rc == 0, fr.log[-3000:]
    assert "Traceback" not in fr.log
    assert fr.summary.get("final state") == "NAVIGATING", fr.summary
    assert fr.proc_kernel_drops > 0, "the stall overflowed the service's socket (the kernel dropped)"
    # after the flood: navigating on the new data, at rest, level, heading 30 (the truth)
    after = fr.nav[fr.nav[:, 0] * 1e6 >= fr.post_from_us]
    assert len(after) >= POST_SETS and np.all(np.isfinite(after))
    assert np.abs(after[:, 7:9]).max() < 1.0
    assert abs(wrap_deg(after[-1, 9] - 30.0)) < 1.0


def test_flood_output_stays_on_sensor_time(flood: FloodRun) -> None:
    """--rate is a rate of sensor time (docs/conventions.md): whatever is shed, every output set is stamped with
    the time of a sample that was sent, no 1/rate period gets two sets, time never runs backwards, and
    once the overload is over the sets come one per period again (the fixture waits for that)."""
    fr = flood
    period_us = int(1e6 / OUT_RATE)
    t_us = np.round(fr.nav[:, 0] * 1e6).astype(np.int64)
    assert np.all(np.isin(t_us, fr.usec)), "every set at the time of a sample sent"
    assert np.all(np.diff(t_us // period_us) >= 1), "no period with two sets, no step back"
    # what the --out client received is what the solution file holds (a subset if the client lost any)
    ms = np.array(fr.attitude_ms, dtype=np.int64)
    assert len(ms) and np.all(np.isin(ms, t_us // 1000))
    post = t_us[t_us >= fr.post_from_us] // period_us
    assert len(post) >= POST_SETS and np.all(np.diff(post[-POST_SETS:]) == 1)


def test_flood_drops_are_counted(flood: FloodRun) -> None:
    """Every datagram sent is processed or counted: ``flood_dropped`` = ``flood_skipped`` (read, not processed,
    still in the tlog) + ``kernel_dropped`` (the kernel's own count for that socket), and SYS_STATUS
    ``drop_rate_comm`` reports the share. Only packets the kernel drops before any socket (its backlog,
    counted machine-wide in /proc/net/softnet_stat, normally 0) can go uncounted."""
    fr = flood
    processed = _count(fr, "messages received")
    dropped, skipped, kernel = _count(fr, "flood_dropped"), _count(fr, "flood_skipped"), _count(fr, "kernel_dropped")
    tlog = tlog_frames(fr.tlog)
    m = fr.status_after
    print(f"\nsent {fr.sent}: processed {processed}, skipped {skipped}, kernel dropped {kernel} (/proc/net/udp: "
          f"{fr.proc_kernel_drops}), uncounted {fr.sent - processed - dropped} (softnet drops {fr.softnet_drops}); "
          f"tlog {tlog}; SYS_STATUS drop_rate_comm {m.drop_rate_comm}, errors_count1 {m.errors_count1}")
    assert kernel == fr.proc_kernel_drops > 0
    assert dropped == skipped + kernel
    assert processed == _count(fr, "imu_accepted"), "every datagram a valid, new sample"
    assert 0 <= fr.sent - (processed + dropped) <= fr.softnet_drops
    assert 0 <= (fr.sent - kernel) - tlog <= fr.softnet_drops, "the tlog holds every datagram read"
    assert abs(m.drop_rate_comm - 10000 * dropped / (processed + dropped)) <= 1.0


# -- 4. SIGTERM mid-run ----------------------------------------------------------------------
def test_sigterm_leaves_readable_recording_and_tlog(tmp_path: Path) -> None:
    from rerun.chunk import RrdReader

    run = generate(scenario("rest", [{"kind": "static", "duration": 12.0}], 100.0, roll=3.0, pitch=-2.0,
                            yaw=30.0), grade="ideal")
    items = encode(run, mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1))
    rrd, tlog, nav = tmp_path / "rec.rrd", tmp_path / "in.tlog", tmp_path / "nav.csv"
    args = nav_args(2.0)
    sock = udp_socket()
    cut = int(0.625 * len(items))  # 7.5 s of the 12 s stream: navigating, recording
    at_cut, signalled = threading.Event(), threading.Event()
    after_signal: list[int] = []

    def sender() -> None:
        send_paced(sock, svc.addr, items[:cut], 3.0)
        at_cut.set()
        signalled.wait(EVENT_TIMEOUT_S)
        for it in items[cut:]:  # the stream goes on while the service stops
            try:
                sock.sendto(it.data, svc.addr)
            except ConnectionRefusedError:  # the service has closed its port
                break
            after_signal.append(1)
            time.sleep(0.002)

    with Svc(tmp_path, *args, "--rerun", str(rrd), "--tlog", str(tlog), "-o", str(nav)) as svc:
        th = threading.Thread(target=sender, daemon=True)
        th.start()
        wait_until(at_cut.is_set, "the first 7.5 s of the stream sent")
        svc.settle()
        svc.proc.send_signal(signal.SIGTERM)
        signalled.set()
        rc = svc.stop(signal.SIGTERM, send=False)
        th.join(EVENT_TIMEOUT_S)
    log = svc.log()
    print(f"\nexit code {rc}; {svc.summary().get('messages received')} messages; "
          f"{len(after_signal)} datagrams sent after SIGTERM")
    assert after_signal, "data still arriving when SIGTERM came"
    assert rc == 0 and "Traceback" not in log, log
    assert svc.summary().get("final state") == "NAVIGATING"
    # the Rerun file reads back, with samples, outputs and events in it
    reader = RrdReader(str(rrd))
    assert reader.recordings(), "a recording in the file"
    entities = {str(c.entity_path) for c in reader.stream()}
    for needed in ("/imu/gyro", "/plots/attitude", "/log"):
        assert any(e.startswith(needed) for e in entities), (needed, sorted(entities))
    # the tlog replays to the solution published live, row for row
    replay_csv = tmp_path / "replay.csv"
    res = subprocess.run([*MAVINS, "replay", str(tlog), "-o", str(replay_csv), *args], env=ENV, cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    live, again = read_nav(nav), read_nav(replay_csv)
    assert len(live) > 100
    assert live.shape == again.shape and np.array_equal(live, again)


# -- 5. signing -------------------------------------------------------------------------------
def make_key(tmp: Path, passphrase: str, name: str = "key") -> tuple[Path, bytes]:
    import hashlib

    path = tmp / name
    res = subprocess.run([*MAVINS, "key", str(path), "--passphrase", passphrase], env=ENV, capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    return path, hashlib.sha256(passphrase.encode("ascii")).digest()


def signer(key: bytes, sysid: int = VEH_SYS, compid: int = 1, link_id: int = 0) -> mavlink.MAVLink:
    from mavins.link.signing import now_timestamp

    enc = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    enc.signing.secret_key, enc.signing.sign_outgoing, enc.signing.link_id = key, True, link_id
    enc.signing.timestamp = now_timestamp()
    return enc


def drain(sock: socket.socket) -> list[bytes]:
    sock.setblocking(False)
    out = []
    while True:
        try:
            out.append(sock.recv(65535))
        except BlockingIOError:
            return out


def _until_heartbeat(sock: socket.socket, key: bytes, got: list[bytes]) -> bool:
    """Add what ``sock`` holds to ``got``; whether ``got`` now holds a HEARTBEAT signed with ``key``."""
    got += drain(sock)
    check = mavlink.MAVLink(None)
    check.signing.secret_key = key
    check.robust_parsing = True
    return any(m.get_type() == "HEARTBEAT" for d in got for m in check.parse_buffer(d) or [])


def test_signing_accepts_only_the_key_holder(tmp_path: Path) -> None:
    key_path, key = make_key(tmp_path, "correct horse battery staple")
    run = generate(scenario("rest", [{"kind": "static", "duration": 4.0}], 100.0, roll=3.0, pitch=-2.0, yaw=30.0),
                   grade="ideal")
    items = encode(run, signer(key))
    n_imu = sum(it.name == "HIGHRES_IMU" for it in items)
    unsigned = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    wrong = signer(bytes(32))  # the all-zero key
    genuine, s_unsigned, s_wrong = udp_socket(), udp_socket(), udp_socket()
    stream: list[tuple[socket.socket, bytes]] = []
    n_unsigned = n_wrong = 0
    for it in items:
        stream.append((genuine, it.data))
        if it.imu >= 0 and it.imu % 10 == 3:  # plausible samples between the genuine ones, 1 ms later
            t_us = int(round(run.t[it.imu] * 1e6)) + BOOT_US + 1000
            stream.append((s_unsigned, imu_frame(unsigned, t_us, (0.5, 0.0, -9.8), (0.3, 0.0, 0.0))))
            n_unsigned += 1
            if it.imu % 20 == 3:
                stream.append((s_wrong, imu_frame(wrong, t_us + 1000, (0.5, 0.0, -9.8), (0.3, 0.0, 0.0))))
                n_wrong += 1
    nav = tmp_path / "nav.csv"
    got: list[bytes] = []
    with Svc(tmp_path, *nav_args(1.0, "--signing-key", str(key_path), "-o", str(nav))) as svc:
        wall0 = time.monotonic()
        for k, (s, data) in enumerate(stream):
            s.sendto(data, svc.addr)
            if k % 50 == 49:
                time.sleep(max(0.0, wall0 + k / 2000 - time.monotonic()))
                wait_for_room(svc.port)
        svc.settle()
        # the HEARTBEAT goes out once a second of wall time, and the stream may take less than that
        wait_until(lambda: _until_heartbeat(genuine, key, got), "a HEARTBEAT to the key holder")
        rc = svc.stop()
    assert rc == 0, svc.log()
    c = svc.summary()
    print(f"\nsigned frames sent {len(items)} (IMU {n_imu}), unsigned {n_unsigned}, wrong key {n_wrong}; summary {c}")
    assert svc.count("imu_accepted") == n_imu
    assert svc.count("rejected_unsigned") == n_unsigned
    assert svc.count("rejected_bad_signature") == n_wrong
    # output goes to the key holder only, and is signed with the key
    got += drain(genuine)
    assert got and not drain(s_unsigned) and not drain(s_wrong)
    check = mavlink.MAVLink(None)
    check.signing.secret_key = key
    check.robust_parsing = True
    msgs = [m for d in got for m in check.parse_buffer(d) or []]
    assert msgs and all(m.get_type() != "BAD_DATA" for m in msgs)
    assert {"HEARTBEAT", "ATTITUDE"} <= {m.get_type() for m in msgs}
    rows = read_nav(nav)
    assert np.abs(wrap_deg(rows[-1, 7:10] - [3.0, -2.0, 30.0])).max() < 0.01


# -- 6. in range, but extreme, for long -------------------------------------------------------
def test_long_extreme_stream_keeps_service_up(tmp_path: Path) -> None:
    """600 samples at 16 g (within the sensor range), 0.99 s apart, each gap bridged: the unaided vertical
    channel runs away (int32 overflow of GLOBAL_POSITION_INT.alt after ~166 samples, a NaN state after ~450).
    The service must stay up, and navigate right again once valid data resumes on a new time base."""
    run = generate(scenario("rest", [{"kind": "static", "duration": 3.0}], 100.0, roll=3.0, pitch=-2.0, yaw=30.0),
                   grade="ideal")
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    first = encode(run, enc)
    t_last = BOOT_US + int(round(run.t[-1] * 1e6))
    extreme = [Item(0.0, "HIGHRES_IMU", imu_frame(enc, t_last + i * 990_000, (0.0, 0.0, 150.0), (0.0,) * 3))
               for i in range(1, 601)]
    resume_us = t_last + 600 * 990_000 + 100_000_000 - int(round(run.t[0] * 1e6))
    again = encode(run, enc, shift_us=resume_us)
    nav = tmp_path / "nav.csv"
    sock = udp_socket()
    with Svc(tmp_path, *nav_args(1.0, "-o", str(nav))) as svc:
        send_paced(sock, svc.addr, first, speed=10.0)
        for k, it in enumerate(extreme):
            sock.sendto(it.data, svc.addr)
            if k % 50 == 49:
                wait_for_room(svc.port)
        svc.settle()
        up_after_extreme = svc.alive()
        send_paced(sock, svc.addr, again, speed=10.0)
        svc.settle()
        alive = svc.alive()
        rc = svc.stop()
    log = svc.log()
    assert up_after_extreme and alive and rc == 0, log[-3000:]
    assert "Traceback" not in log
    rows = read_nav(nav)
    assert np.all(np.isfinite(rows))
    last = rows[rows[:, 0] * 1e6 >= resume_us]
    assert len(last) > 50 and np.abs(wrap_deg(last[-1, 7:10] - [3.0, -2.0, 30.0])).max() < 0.01

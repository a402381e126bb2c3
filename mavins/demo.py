"""``mavins demo``: the loopback simulation, end to end over real UDP sockets.

simulator --UDP--> service --UDP--> collector (a plain pymavlink client)

The simulator streams a built-in scenario like an autopilot; the service
aligns, navigates and publishes; the collector keeps what arrives. At the end
the published attitude, position and velocity are compared with the
simulator's truth at the same sensor time.
"""

from __future__ import annotations

import logging
import math
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .core.frames import north_east_error
from .core.rotation import euler_to_quat, quat_angle_rows
from .engine import EngineConfig
from .link.ingest import IngestConfig
from .link.mavlink import mavutil
from .service import Service, ServiceConfig, Summary

log = logging.getLogger("mavins")


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that is free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Collected:
    """What a plain pymavlink client received from the service."""

    attitude: list[tuple[int, float, float, float]] = field(default_factory=list)
    global_pos: list[tuple[int, int, int, int, int, int, int]] = field(default_factory=list)
    local_pos: list[tuple[int, float, float, float]] = field(default_factory=list)
    heartbeats: int = 0
    statustext: list[str] = field(default_factory=list)
    other: int = 0


def collect(url: str, stop: threading.Event, into: Collected, ready: threading.Event) -> None:
    """Receive from ``url`` until ``stop``; keep the service's outputs."""
    conn = mavutil.mavlink_connection(url, dialect="common")
    ready.set()
    try:
        while not stop.is_set():
            m = conn.recv_match(blocking=True, timeout=0.05)
            if m is None:
                continue
            name = m.get_type()
            if name == "ATTITUDE":
                into.attitude.append((m.time_boot_ms, m.roll, m.pitch, m.yaw))
            elif name == "GLOBAL_POSITION_INT":
                into.global_pos.append((m.time_boot_ms, m.lat, m.lon, m.alt, m.vx, m.vy, m.vz))
            elif name == "LOCAL_POSITION_NED":
                into.local_pos.append((m.time_boot_ms, m.x, m.y, m.z))
            elif name == "HEARTBEAT":
                into.heartbeats += 1
            elif name == "STATUSTEXT":
                into.statustext.append(m.text)
            else:
                into.other += 1
    finally:
        conn.close()


@dataclass
class DemoReport:
    """Errors of the published solution against the simulator's truth."""

    outputs: int
    att_err_deg_max: float
    att_err_deg_final: float
    pos_err_m_final: float
    vel_err_ms_final: float
    summary: Summary
    collected: Collected

    def lines(self) -> list[str]:
        return [
            f"published output sets received: {self.outputs}",
            f"attitude error vs truth: max {self.att_err_deg_max:.4f} deg, final {self.att_err_deg_final:.4f} deg",
            f"position error vs truth (final): {self.pos_err_m_final:.3f} m",
            f"velocity error vs truth (final): {self.vel_err_ms_final:.4f} m/s",
        ]


def compare(collected: Collected, truth: np.ndarray) -> tuple[float, float, float, float]:
    """Max and final attitude error (deg), final position (m) and velocity (m/s) errors."""
    ms_truth = np.floor(np.round(truth[:, 0] * 1e6) / 1000).astype(np.int64)
    att = np.array(collected.attitude, dtype=float).reshape(-1, 4)
    idx = np.searchsorted(ms_truth, att[:, 0].astype(np.int64))
    ok = idx < len(truth)
    att, idx = att[ok], idx[ok]
    q_pub = np.array([euler_to_quat(r, p, y) for _, r, p, y in att]).reshape(-1, 4)
    d = quat_angle_rows(q_pub, np.ascontiguousarray(truth[idx, 10:14])) if len(att) else np.array([math.nan])
    d_deg = np.degrees(d)
    pos_err = vel_err = math.nan
    if collected.global_pos:
        g = collected.global_pos[-1]
        i = min(int(np.searchsorted(ms_truth, g[0])), len(truth) - 1)
        dn, de = north_east_error(math.radians(g[1] * 1e-7), math.radians(g[2] * 1e-7),
                                  math.radians(truth[i, 1]), math.radians(truth[i, 2]))
        pos_err = math.hypot(dn, de)
        vel_err = float(np.linalg.norm(np.array(g[4:7]) / 100.0 - truth[i, 4:7]))
    return float(np.nanmax(d_deg)), float(d_deg[-1]), pos_err, vel_err


def run_demo(
    scenario: str = "flight", duration: float | None = 120.0, speed: float | None = 10.0, grade: str = "industrial",
    heading: str = "vehicle", rerun_path: Path | None = None, rerun_serve: bool = False, seed: int = 0,
    stop: threading.Event | None = None,
) -> DemoReport:
    """Simulate, serve and collect over UDP on 127.0.0.1; return the error report."""
    from sim.generate import generate
    from sim.scenarios import load
    from sim.stream import StreamOptions, stream

    stop = stop or threading.Event()
    run = generate(load(scenario), duration=duration, seed=seed, grade=grade, usec_grid=True)
    p_in, p_out = free_udp_port(), free_udp_port()
    init = run.init()
    engine_cfg = EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading=heading, align=5.0)
    recorder = None
    if rerun_path is not None or rerun_serve:
        from .record.recorder import Recorder

        recorder = Recorder(rerun_path, serve=rerun_serve, app="mavins-demo")
        if recorder.url:
            print(f"mavins demo: live recording at {recorder.url} (open it with: rerun {recorder.url})", flush=True)
    svc = Service(engine_cfg, IngestConfig(), ServiceConfig(master=f"udpin:127.0.0.1:{p_in}",
                                                           outs=[f"udpout:127.0.0.1:{p_out}"]))
    if recorder is not None:
        svc.attach_recorder(recorder)
        recorder.log_truth(run.exact.truth)
    collected = Collected()
    svc_stop, col_stop, ready = threading.Event(), threading.Event(), threading.Event()
    col = threading.Thread(target=collect, args=(f"udpin:127.0.0.1:{p_out}", col_stop, collected, ready), daemon=True)
    col.start()
    ready.wait(5.0)
    summary_box: list[Summary] = []
    srv = threading.Thread(target=lambda: summary_box.append(svc.run(svc_stop)), daemon=True)
    srv.start()
    try:
        stream(run, f"udpout:127.0.0.1:{p_in}", StreamOptions(speed=speed), stop=stop)
        time.sleep(0.5)
    finally:
        svc_stop.set()
        srv.join(10.0)
        col_stop.set()
        col.join(5.0)
        if recorder is not None:
            recorder.close()
    a_max, a_fin, p_fin, v_fin = compare(collected, run.exact.truth)
    return DemoReport(len(collected.attitude), a_max, a_fin, p_fin, v_fin,
                      summary_box[0] if summary_box else svc.summary, collected)

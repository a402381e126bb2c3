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
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .live.livefilter import FilterSettings
from .core import jit
from .core.frames import north_east_error
from .core.rotation import euler_to_quat, quat_angle_rows
from .live.engine import EngineConfig
from .link.ingest import IngestConfig
from .link.mavlink import mavutil
from .link.publish import PublishConfig
from .service import Service, ServiceConfig, Summary, warm_up

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
    odometry_var: dict[int, tuple[float, float, float]] = field(default_factory=dict)  # ms -> var n, e, d (m^2)
    heartbeats: int = 0
    statustext: list[str] = field(default_factory=list)
    other: int = 0


def collect(url: str, stop: threading.Event, into: Collected, ready: threading.Event) -> None:
    """Receive from ``url`` until ``stop``; keep the service's outputs."""
    conn = mavutil.mavlink_connection(url, dialect="ardupilotmega")
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
            elif name == "ODOMETRY":
                c = m.pose_covariance
                into.odometry_var[m.time_usec // 1000] = (c[0], c[6], c[11])
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
    att_err_deg_rms: float = math.nan
    pos_err_m_rms: float = math.nan
    pos_err_m_max: float = math.nan
    within_3_sigma: tuple[int, int] = (0, 0)  # (north/east errors inside 3 sigma, errors compared)
    sent: int = 0  # messages the simulator streamed
    scale: tuple[tuple[str, float, float, float], ...] = ()  # with --scale-factors: (name, estimate, sigma, truth) ppm
    misalignment: tuple[tuple[str, float, float, float], ...] = ()  # with --misalignment: likewise in arcsec

    def lines(self) -> list[str]:
        inside, total = self.within_3_sigma
        share = f"{inside}/{total} ({100.0 * inside / total:.1f} %)" if total else "none compared"
        sensor = []
        for what, rows in (("scale factors (ppm)", self.scale), ("misalignments (arcsec)", self.misalignment)):
            if rows:
                ok = sum(abs(e - t) <= 3.0 * s for _, e, s, t in rows)
                sensor.append(f"{what} estimate +- 1-sigma (simulated): "
                              + ", ".join(f"{n} {e:.0f} +- {s:.0f} ({t:.0f})" for n, e, s, t in rows)
                              + f"; inside 3-sigma: {ok}/{len(rows)}")
        return [
            f"messages streamed / taken by the service: {self.sent} / {self.summary.messages}",
            f"published output sets received: {self.outputs}",
            f"attitude error vs truth: RMS {self.att_err_deg_rms:.4f} deg, max {self.att_err_deg_max:.4f} deg, "
            f"final {self.att_err_deg_final:.4f} deg",
            f"horizontal position error vs truth: RMS {self.pos_err_m_rms:.3f} m, max {self.pos_err_m_max:.3f} m, "
            f"final {self.pos_err_m_final:.3f} m",
            f"velocity error vs truth (final): {self.vel_err_ms_final:.4f} m/s",
            f"north/east position errors inside the published 3-sigma (ODOMETRY covariance): {share}",
        ] + sensor


def compare(collected: Collected, truth: np.ndarray) -> dict[str, object]:
    """Errors of what was published against the truth at the same sensor time: attitude (deg,
    rotation angle) RMS/max/final, horizontal position (m) RMS/max/final, final velocity (m/s),
    and how many north/east errors lie inside the ODOMETRY covariance's 3-sigma."""
    ms_truth = np.floor(np.round(truth[:, 0] * 1e6) / 1000).astype(np.int64)
    att = np.array(collected.attitude, dtype=float).reshape(-1, 4)
    idx = np.searchsorted(ms_truth, att[:, 0].astype(np.int64))
    ok = idx < len(truth)
    att, idx = att[ok], idx[ok]
    q_pub = np.array([euler_to_quat(r, p, y) for _, r, p, y in att]).reshape(-1, 4)
    d = np.degrees(quat_angle_rows(q_pub, np.ascontiguousarray(truth[idx, 10:14]))) if len(att) \
        else np.array([math.nan])
    out: dict[str, object] = {"att_max": float(np.nanmax(d)), "att_final": float(d[-1]),
                              "att_rms": float(np.sqrt(np.nanmean(d * d))), "pos_final": math.nan,
                              "vel_final": math.nan, "pos_rms": math.nan, "pos_max": math.nan, "inside": (0, 0)}
    if collected.global_pos:
        errs, inside, total = [], 0, 0
        for g in collected.global_pos:
            i = int(np.searchsorted(ms_truth, g[0]))
            if i >= len(truth):
                continue
            dn, de = north_east_error(math.radians(g[1] * 1e-7), math.radians(g[2] * 1e-7),
                                      math.radians(truth[i, 1]), math.radians(truth[i, 2]))
            errs.append(math.hypot(dn, de))
            var = collected.odometry_var.get(g[0])
            if var is not None and all(math.isfinite(v) for v in var[:2]):
                total += 2
                inside += int(abs(dn) <= 3.0 * math.sqrt(var[0])) + int(abs(de) <= 3.0 * math.sqrt(var[1]))
        if errs:
            e = np.array(errs)
            out.update(pos_final=float(e[-1]), pos_rms=float(np.sqrt(np.mean(e * e))), pos_max=float(e.max()),
                       inside=(inside, total))
            g = collected.global_pos[-1]
            i = min(int(np.searchsorted(ms_truth, g[0])), len(truth) - 1)
            out["vel_final"] = float(np.linalg.norm(np.array(g[4:7]) / 100.0 - truth[i, 4:7]))
    return out


PREWARM_WAIT_S = 600.0  # s: the longest the demo waits for the compiling process before it compiles itself


MAG_RATE = 50.0  # Hz: the simulated magnetometer in HIGHRES_IMU when the demo aids with it (the live path's rate)
MAX_IN_FLIGHT = 100  # messages streamed and not yet taken by the service at --speed max
MAX_STALL_S = 5.0  # s: how long --speed max waits for a service that takes nothing, before going on


class KeepUp:
    """``--speed max`` without losing data: hold the stream while more than MAX_IN_FLIGHT of its messages
    wait for the service. A UDP socket's buffer holds a few hundred datagrams and the kernel drops what
    overflows it; the demo then lost samples at the start, whose gaps restarted the alignment into the
    take-off (position errors of hundreds of metres). A service that takes nothing for MAX_STALL_S is
    assumed to have lost what is missing, and the stream goes on."""

    def __init__(self, taken: Callable[[], int], stop: threading.Event) -> None:
        self.taken = taken  # messages the service has taken so far
        self.stop = stop
        self.lost = 0

    def __call__(self, sent: int) -> None:
        last = self.taken()
        t_end = time.monotonic() + MAX_STALL_S
        while sent - self.lost - last > MAX_IN_FLIGHT and not self.stop.is_set():
            time.sleep(0.0002)
            now = self.taken()
            if now != last:
                last, t_end = now, time.monotonic() + MAX_STALL_S
            elif time.monotonic() > t_end:
                self.lost = sent - last - MAX_IN_FLIGHT
                return


def _engine_config(lat: float, lon: float, alt: float, heading: str, grade: str,
                   aiding: tuple[str, ...], year: float | None = None, scale_factors: bool = False,
                   misalignment: bool = False) -> EngineConfig:
    """The service's settings; the magnetic declination is the World Magnetic Model's at the start for
    ``year`` (None: today), the model the simulator's field comes from."""
    return EngineConfig(lat=lat, lon=lon, alt=alt, heading=heading, align=5.0, mag_year=year,
                        filter=FilterSettings(spec=grade if grade != "ideal" else "navigation", aiding=aiding,
                                              scale_factors=scale_factors, misalignment=misalignment))


def _sensor_report(svc: Service, grade: str, blocks: tuple[str, str]) -> tuple[tuple[str, float, float, float], ...]:
    """The filter's estimates and 1-sigma of two sensor-error blocks of errmodel.STATE (gyro's, accelerometer's:
    ``("SG", "SA")`` in ppm, ``("MG", "MA")`` in arcsec, the solution file's units) beside the simulated
    unit's (sim.errors.grade)."""
    from sim.errors import grade as unit_of

    from .core import errmodel
    from .core.aided import unit_factors

    flt, unit = svc.pipeline.engine.filter, unit_of(grade)
    out = []
    for name, blk, sensor in (("gyro", blocks[0], unit.gyro), ("accel", blocks[1], unit.accel)):
        block = next(b for b in errmodel.STATE if b.name == blk)
        x0 = errmodel.OFFSET[blk]
        if blk.startswith("S"):
            true = [float(v) for v in sensor.scale_factor_ppm]
        else:
            true = [float(sensor.misalignment[i][j]) / errmodel.ARCSEC for i, j in errmodel.OFF_DIAGONAL]
        factor = float(unit_factors([f"{blk.lower()}_{block.labels[0]}"])[0])
        for i, label in enumerate(block.labels):
            out.append((f"{name} {label}", factor * float(flt.bias[x0 - errmodel.X_SENSORS + i]),
                        factor * math.sqrt(max(float(flt.P[x0 + i, x0 + i]), 0.0)), true[i]))
    return tuple(out)


def prewarm(heading: str, grade: str, aiding: tuple[str, ...]) -> None:
    """Compile (or load) the kernels the demo's service calls, into the shared numba cache."""
    warm_up(_engine_config(45.0, 7.0, 100.0, heading, grade, aiding), PublishConfig())


def start_prewarm(heading: str, grade: str, aiding: tuple[str, ...]) -> subprocess.Popen | None:
    """On a machine whose numba cache is empty, a second process that compiles the service's
    kernels while this one simulates the flight (the simulator's kernel compiles here at the
    same time); None when the cache is already there."""
    if jit.cache_is_warm():
        return None
    print("mavins demo: first start of this version on this machine: compiling the navigation kernels "
          f"(once; later starts load them from {jit.numba.config.CACHE_DIR})", flush=True)
    code = f"from mavins.demo import prewarm; prewarm({heading!r}, {grade!r}, {tuple(aiding)!r})"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(jit.numba.config.CACHE_DIR)}  # the folder this process loads from
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)


def run_demo(
    scenario: str = "flight", duration: float | None = 120.0, speed: float | None = 10.0, grade: str = "industrial",
    heading: str = "vehicle", rerun_path: Path | None = None, rerun_serve: bool = False, seed: int = 0,
    stop: threading.Event | None = None, aiding: tuple[str, ...] = ("gnss", "baro"),
    gnss_outage: tuple[float, float] | None = (60.0, 90.0), scale_factors: bool = False, misalignment: bool = False,
) -> DemoReport:
    """Simulate, serve and collect over UDP on 127.0.0.1; return the error report."""
    from sim.generate import generate
    from sim.scenarios import load
    from sim.stream import StreamOptions, stream

    stop = stop or threading.Event()
    compiling = start_prewarm(heading, grade, aiding)
    try:
        run = generate(load(scenario), duration=duration, seed=seed, grade=grade, usec_grid=True)
        if compiling is not None:
            try:
                compiling.wait(PREWARM_WAIT_S)
            except subprocess.TimeoutExpired:
                pass  # what it did not finish, the service compiles itself (killed below)
    finally:
        if compiling is not None and compiling.poll() is None:
            compiling.kill()
            compiling.wait()
    p_in, p_out = free_udp_port(), free_udp_port()
    init = run.init()
    from mavins.core.magmodel import this_year
    from sim.aiding import MagConfig

    year = this_year()  # one date for the simulator's field and the service's magnetic model
    engine_cfg = _engine_config(init.lat, init.lon, init.h, heading, grade, aiding, year, scale_factors, misalignment)
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
        outages = (gnss_outage,) if gnss_outage is not None else ()
        mag_rate = MAG_RATE if "mag" in aiding else 0.0
        hold = KeepUp(lambda: svc.summary.messages, stop) if speed is None else None
        sent = stream(run, f"udpout:127.0.0.1:{p_in}",
                      StreamOptions(speed=speed, gnss_outages=outages, mag_rate=mag_rate,
                                    mag=MagConfig.at(init.lat, init.lon, init.h, year)), stop=stop, hold=hold).messages
        time.sleep(0.5)
    finally:
        svc_stop.set()
        srv.join(10.0)
        col_stop.set()
        col.join(5.0)
        if recorder is not None:
            recorder.close()
    c = compare(collected, run.exact.truth)
    return DemoReport(len(collected.attitude), c["att_max"], c["att_final"], c["pos_final"], c["vel_final"],  # type: ignore[arg-type]
                      summary_box[0] if summary_box else svc.summary, collected, c["att_rms"], c["pos_rms"],  # type: ignore[arg-type]
                      c["pos_max"], c["inside"], sent,  # type: ignore[arg-type]
                      _sensor_report(svc, grade, ("SG", "SA")) if scale_factors and grade != "ideal" else (),
                      _sensor_report(svc, grade, ("MG", "MA")) if misalignment and grade != "ideal" else ())

"""``mavins run``: the live MAVLink INS service (link in -> pipeline -> publish).

Reads a link (UDP handled by mavins.link.links; other pymavlink connection strings
through pymavlink), feeds every message through the shared pipeline,
publishes output sets to the master link's authorised peers and every
``--out`` link, keeps an input tlog, and stops cleanly on request.

Robustness (docs/reliability.md): every rejection is counted by reason; input
beyond capacity is dropped by draining the socket (counted), never by
blocking or buffering without bound; failures of optional parts (recording,
output links, tlog) are logged and switch that part off, never navigation.
"""

from __future__ import annotations

import dataclasses
import gc
import logging
import select
import struct
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from .core import jit
from .core.gpstime import gps_week_ms
from .core import strapdown as sd
from .core.runner import rest_state
from .core.settings import strapdown_of
from .live.engine import EngineConfig, State
from .common.files import SolutionWriter
from .link import publish
from .link.ingest import IMU_MESSAGES, IngestConfig
from .link.links import Link, PeerPolicy, datagrams, open_link
from .link.mavlink import mavlink
from .live.pipeline import Pipeline
from .record.sink import GuardedSink, Sink
from .link.signing import Signer, Verifier

log = logging.getLogger("mavins")

BATCH = 256  # datagrams read per loop turn
SYS_STATUS_PERIOD = 1.0  # s
STATUS_RATE_HZ = 1.0  # ESTIMATOR_STATUS, EKF_STATUS_REPORT and SYSTEM_TIME per second of sensor time
GPS_INPUT_RATE_HZ = 5.0  # GPS_INPUT per second of sensor time (--gps-input)
UNIX_USEC_MIN = 1_000_000_000_000_000  # a GNSS time_usec above this (2001-09-09) is UNIX time, i.e. UTC
HELPER_WAIT_S = 120.0  # s: the cold-start compile helper is waited for at most this long, then stopped
DRAIN_S = 2.0  # s: on a stop, input already in the socket is processed for at most this long


@dataclass
class ServiceConfig:
    """Links, identity, security and side outputs of the service."""

    master: str = "udpin:127.0.0.1:14551"
    outs: list[str] = field(default_factory=list)
    sysid: int | None = None
    compid: int = 191
    tlog: Path | None = None
    solution: Path | None = None
    request_imu: float | None = None
    signing_key: bytes | None = None
    signing_state: Path | None = None
    peers: PeerPolicy = field(default_factory=PeerPolicy)
    publish: publish.PublishConfig = field(default_factory=publish.PublishConfig)


@dataclass
class Summary:
    """What happened during a run (printed on exit)."""

    messages: int = 0
    outputs: int = 0
    state: str = ""
    counters: dict[str, int] = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"messages received: {self.messages}", f"output sets published: {self.outputs}",
               f"final state: {self.state}"]
        out += [f"{k}: {v}" for k, v in sorted(self.counters.items())]
        return out


def warm_up(engine_cfg: EngineConfig, pub: publish.PublishConfig) -> float:
    """Load (or compile, the first time on a machine) every kernel the live path calls.

    Runs a synthetic static stream through a throw-away pipeline with the
    run's own settings, from alignment into navigation and publishing, so no
    kernel is compiled while real input waits in the socket. Returns the
    seconds it took; the first time it says so once on the log.
    """
    t0 = time.monotonic()
    cold = not jit.cache_is_warm()
    helper = None
    if cold:
        log.warning("first start of this version on this machine: compiling the navigation kernels "
                    "(once; later starts load them from %s)", jit.numba.config.CACHE_DIR)
        # two cores at once: a second process compiles the filter's measurement and propagation
        # kernels into the shared cache while this one compiles the strapdown kernel; the filter's
        # top-level kernels then load them (29.4 -> 20.4 s on a 2-core machine, benchmarks/bench_startup.py)
        code = "from mavins.live.livefilter import warm_measurements; warm_measurements()"
        helper = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        kcfg = sd.make_config(**strapdown_of(engine_cfg).keywords())
        jit.for_frame(sd.push_rate_scalars, sd.kernel_frame(kcfg))(rest_state(), kcfg, 0.01, 0.0, 0.0, 0.0, 0.0, 0.0, -9.8)
    cfg = dataclasses.replace(engine_cfg, lat=45.0, lon=7.0, alt=100.0, heading=0.0, align=0.05,
                              rate=max(engine_cfg.rate, 1.0))
    pipe = Pipeline(cfg, IngestConfig(message="HIGHRES_IMU"), own_component=-1)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    out = None
    for i in range(1, 60):
        msg = mavlink.MAVLink_highres_imu_message(10_000 * i, 0.0, 0.0, -9.80, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4,
                                                  0.0, 0.0, 0.0, 0.0, 0b111111111, 0)
        msg.pack(mav)
        out = pipe.handle(msg) or out
    if out is None:
        raise RuntimeError("warm-up produced no solution")  # the engine itself is broken
    publish.encode(mav, out, pub, 0)
    if helper is not None:
        try:  # normally done already; what it did not finish this process has compiled itself
            helper.wait(timeout=HELPER_WAIT_S)
        except subprocess.TimeoutExpired:
            helper.kill()
            helper.wait()
    took = time.monotonic() - t0
    if cold:
        log.warning("navigation kernels compiled in %.1f s", took)
    return took


class Service:
    """The live loop. ``run(stop)`` returns when ``stop`` is set."""

    def __init__(self, engine_cfg: EngineConfig, ingest_cfg: IngestConfig, cfg: ServiceConfig) -> None:
        self.cfg = cfg
        warm_up(engine_cfg, cfg.publish)
        self.pipeline = Pipeline(engine_cfg, ingest_cfg, own_component=cfg.compid)
        self.summary = Summary()
        self.counters: Counter = Counter()
        self.mav = mavlink.MAVLink(None, srcSystem=cfg.sysid or 0, srcComponent=cfg.compid)
        self.verifier = Verifier(cfg.signing_key) if cfg.signing_key else None
        self.signer = Signer(cfg.signing_key, cfg.signing_state) if cfg.signing_key else None
        if self.signer is not None:
            self.signer.attach(self.mav)
        self.master: Link = open_link(cfg.master, cfg.peers)
        self.outs: list[Link] = []
        try:
            self.outs = [open_link(u, cfg.peers) for u in cfg.outs]
        except OSError:
            self.master.close()
            raise
        self._tlog = open(cfg.tlog, "wb") if cfg.tlog else None
        self._solution = SolutionWriter(cfg.solution, self.pipeline.columns) if cfg.solution else None
        self._sysid_known = cfg.sysid is not None
        self._last_hb = 0.0
        self._last_status = 0.0
        self._status_tick = -1
        self._gps_tick = -1
        self._origin_sent = False
        self._utc_offset: float | None = None  # UTC (s since the UNIX epoch) minus sensor time
        self._last_imu_wall = 0.0
        self._last_request = 0.0
        self._cpu0 = (time.process_time(), time.monotonic())
        self._text_id = 0
        self._batch_time = 0.0
        self._batch_age = 0.0
        self._pending_text: list[tuple[str, str]] = []

    # -- optional parts ----------------------------------------------------------
    def attach_recorder(self, recorder: Sink) -> None:
        """Record every sample, output and event (closed with the service). A recorder that
        fails is switched off and the failure logged; navigation goes on."""
        self.pipeline.recorder = GuardedSink(recorder, lambda exc: self._optional_failed("recording", exc))

    def _optional_failed(self, part: str, exc: BaseException) -> None:
        self.counters[f"{part}_failed"] += 1
        log.error("%s failed and is switched off (navigation goes on): %s", part, exc)

    # -- sending -------------------------------------------------------------------
    def _send(self, msgs: list[mavlink.MAVLink_message]) -> None:
        if not self._sysid_known:
            return
        frames = []
        for m in msgs:
            frames.append(self.signer.pack(m, self.mav) if self.signer is not None else m.pack(self.mav))
            self.mav.seq = (self.mav.seq + 1) % 256
        for buf in datagrams(frames):
            for link in (self.master, *self.outs):
                try:
                    link.send(buf)
                except OSError as exc:
                    self.counters["send_errors"] += 1
                    log.debug("send to %s failed: %s", link.url, exc)

    def _announce(self) -> None:
        events = self.pipeline.take_events()
        for level, text in events:
            log.log(logging.WARNING if level == "WARNING" else logging.INFO, text)
            self._text_id += 1
            msgs = publish.statustext(self.mav, level, text, self._text_id)
            if self._sysid_known:
                self._send(msgs)
            else:
                self._pending_text = (self._pending_text + [(level, text)])[-20:]  # bounded until we know who we are

    # -- receiving -----------------------------------------------------------------
    def _handle(self, msg: mavlink.MAVLink_message, addr: object) -> None:
        self.summary.messages += 1
        name = msg.get_type()
        if name == "BAD_DATA":
            reason = str(getattr(msg, "reason", ""))
            key = "bad_crc" if "CRC" in reason else "truncated" if "truncated" in reason else "garbage"
            self.counters[f"rejected_{key}"] += 1
            return
        if name.startswith("UNKNOWN_"):
            # an id outside the dialect: its CRC cannot be checked, so it proves nothing
            self.counters["rejected_unknown_message"] += 1
            return
        if self.verifier is not None:
            why = self.verifier.check(bytes(msg.get_msgbuf()), msg.get_srcSystem(), msg.get_srcComponent())
            if why is not None:
                self.counters[f"rejected_{why}"] += 1
                return
        self.master.authorize(addr)
        if self._tlog is not None:
            try:
                self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + bytes(msg.get_msgbuf()))
            except OSError as exc:
                self._tlog = None
                self._optional_failed("tlog", exc)
        out = self.pipeline.handle(msg)
        if not self._sysid_known:
            vehicle = self.pipeline.vehicle_sysid
            if vehicle is None and name == "HEARTBEAT" and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID \
                    and msg.type != mavlink.MAV_TYPE_GCS:
                vehicle = msg.get_srcSystem()  # an autopilot's heartbeat names the vehicle
            if vehicle is not None:
                self.mav.srcSystem = vehicle
                self._sysid_known = True
                pending, self._pending_text = self._pending_text, []
                for level, text in pending:
                    self._text_id += 1
                    self._send(publish.statustext(self.mav, level, text, self._text_id))
        if name in IMU_MESSAGES:
            self._last_imu_wall = time.monotonic()
        elif name == "TIMESYNC" and msg.tc1 == 0:
            # a request: answer at once with our clock, theirs echoed (docs/autopilots.md)
            self._send([publish.timesync_reply(self.mav, msg.ts1, time.monotonic_ns())])
        elif name == "GPS_RAW_INT" and UNIX_USEC_MIN < msg.time_usec < 2**63 and self.pipeline.last_sample is not None:
            self._utc_offset = msg.time_usec * 1e-6 - self.pipeline.last_sample.t
        elif name == "COMMAND_ACK" and msg.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            ok = msg.result == mavlink.MAV_RESULT_ACCEPTED
            log.info("SET_MESSAGE_INTERVAL %s", "accepted" if ok else f"refused (result {msg.result})")
        self._announce()
        if out is not None:
            resets = out.unc.resets if out.unc is not None else self.pipeline.engine.counters["restarts"]
            msgs = publish.encode(self.mav, out, self.cfg.publish, resets)
            t = float(out.row[0])
            k = int(t * STATUS_RATE_HZ)
            if k != self._status_tick:
                self._status_tick = k
                msgs += publish.estimator_status(self.mav, out)
                unix_usec = int((t + self._utc_offset) * 1e6) if self._utc_offset is not None else -1
                if UNIX_USEC_MIN <= unix_usec < 2**63:
                    msgs.append(publish.system_time(self.mav, unix_usec, t))
            if self.cfg.publish.gps_input and int(t * GPS_INPUT_RATE_HZ) != self._gps_tick:
                self._gps_tick = int(t * GPS_INPUT_RATE_HZ)
                msgs.append(publish.gps_input(self.mav, out, self.cfg.publish, self._gps_time(t)))
            if self.cfg.publish.set_origin and not self._origin_sent and self._sysid_known:
                self._origin_sent = True
                msgs.append(publish.set_gps_global_origin(self.mav, self.mav.srcSystem, out.origin,
                                                          self.cfg.publish.geoid_height))
                log.info("sent SET_GPS_GLOBAL_ORIGIN %.7f %.7f %.1f m", *out.origin)
            self._send(msgs)
            self.summary.outputs += 1
            rec = self.pipeline.recorder
            if rec is not None:
                # from the datagrams' arrival in the kernel to this output set sent
                rec.on_latency(float(out.row[0]), 1e3 * (time.time() - self._batch_time + self._batch_age))
            if self._solution is not None:
                self._solution.write(self.pipeline.file_row(out))

    def _gps_time(self, t: float) -> tuple[int, int] | None:
        """GPS week and milliseconds of sensor time t when the GNSS input carries UTC."""
        if self._utc_offset is None:
            return None
        return gps_week_ms(t + self._utc_offset)

    def _periodic(self) -> None:
        now = time.monotonic()
        if now - self._last_hb >= 1.0:
            self._last_hb = now
            self._send([publish.heartbeat(self.mav, self.pipeline.engine.state is State.NAVIGATING)])
            if self._solution is not None:
                self._solution.flush()  # the solution file at most a second behind (docs/service.md)
        if now - self._last_status >= SYS_STATUS_PERIOD:
            self._last_status = now
            self._send([self._sys_status(now)])
        if (self.cfg.request_imu and self._sysid_known and now - self._last_imu_wall > 2.0
                and now - self._last_request > 2.0):
            self._last_request = now
            self._send([self.mav.command_long_encode(
                self.mav.srcSystem, mavlink.MAV_COMP_ID_AUTOPILOT1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, 1e6 / self.cfg.request_imu, 0, 0, 0, 0, 0)])
            log.info("asked for HIGHRES_IMU at %.0f Hz", self.cfg.request_imu)

    def _flood_dropped(self) -> int:
        """Input not processed for lack of capacity (skipped by us or dropped by the kernel)."""
        return int(self.master.dropped)

    def _log_skipped(self) -> None:
        """Datagrams read but skipped under overload still go into the input tlog."""
        skipped = self.master.take_skipped()
        if not skipped or self._tlog is None:
            return
        stamp = struct.pack(">Q", int(time.time() * 1e6))
        try:
            for data in skipped:
                self._tlog.write(stamp + data)
        except OSError as exc:
            self._tlog = None
            self._optional_failed("tlog", exc)

    def _sys_status(self, now: float) -> mavlink.MAVLink_message:
        """SYS_STATUS: IMU sensor health, load, and rejection/drop counters."""
        cpu, wall = time.process_time() - self._cpu0[0], now - self._cpu0[1]
        self._cpu0 = (time.process_time(), now)
        load = min(1000, int(1000 * cpu / wall)) if wall > 0 else 0
        sensors = mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
        healthy = sensors if self.pipeline.engine.state is State.NAVIGATING and not self.pipeline.engine.degraded else 0
        if self.pipeline.imuset is not None:  # --imus: the second IMU's bits, isolated sensors unhealthy
            present, bad = self.pipeline.imuset.status_bits()
            sensors |= present
            healthy = (healthy | present if healthy else 0) & ~bad
        rejected = sum(self.pipeline.ingest.rejected.values()) + sum(
            v for k, v in self.counters.items() if k.startswith("rejected_"))
        dropped = self._flood_dropped()
        total = self.summary.messages + dropped
        drop_rate = int(10000 * dropped / total) if total else 0
        return self.mav.sys_status_encode(sensors, sensors, healthy, load, 0, -1, -1, min(drop_rate, 10000),
                                          min(rejected, 65535), min(int(self.master.dropped_late), 65535),
                                          min(self.pipeline.engine.counters["gaps_long"], 65535),
                                          min(self.pipeline.engine.counters["restarts"], 65535),
                                          min(int(self.master.kernel_dropped), 65535))

    def run(self, stop: threading.Event) -> Summary:
        """Serve until ``stop`` is set; flush the side outputs and return the summary."""
        fd = self.master.fileno()
        # everything built so far lives for the whole run: keep it out of the
        # collector's full passes, which otherwise pause the loop for 0.1 s
        gc.collect()
        gc.freeze()
        try:
            while not stop.is_set():
                self._batch_time = time.time()
                batch, n = self.master.receive(BATCH)
                self._batch_age = self.master.age
                if n:
                    self._log_skipped()
                    for msg, addr in batch:
                        self._handle(msg, addr)
                self._periodic()
                if n < BATCH:
                    # receive took what was waiting (a UDP link stops at a datagram nothing is queued
                    # behind, or at an empty socket): wait here for more rather than ask again, one read
                    # and one wake-up per datagram at kHz (select returns at once if more is waiting)
                    if fd is not None:
                        select.select([fd], [], [], 0.05)
                    else:
                        time.sleep(0.002)
            self._drain()
        finally:
            self.close()
        return self.summary

    def _drain(self) -> None:
        """On a stop, process what already arrived (bounded by ``DRAIN_S`` of wall time)."""
        t_end = time.monotonic() + DRAIN_S
        while time.monotonic() < t_end:
            batch, n = self.master.receive(BATCH)
            if not n:
                return
            self._log_skipped()
            for msg, addr in batch:
                self._handle(msg, addr)

    def close(self) -> None:
        """Flush and close the tlog, the solution file, the recording and the links."""
        self._log_skipped()
        self._announce()
        if self._tlog is not None:
            self._tlog.close()
            self._tlog = None
        if self._solution is not None:
            self._solution.close()
            self._solution = None
        for link in (self.master, *self.outs):
            try:
                link.close()
            except OSError:
                pass
        if self.pipeline.recorder is not None:
            self.pipeline.recorder.close()
            self.pipeline.recorder = None
        c = dict(self.counters)
        c["flood_dropped"] = self._flood_dropped()
        c["flood_skipped"] = int(self.master.dropped_late)  # received and logged, not navigated
        c["kernel_dropped"] = int(self.master.kernel_dropped)  # never received
        c.update(self.pipeline.counters)
        c.update({f"rejected_{k}": v for k, v in self.pipeline.ingest.rejected.items()})
        c.update(self.pipeline.engine.counters)
        c.update(self.pipeline.engine.filter.counters)  # measurements accepted and rejected, by kind
        c["imu_accepted"] = self.pipeline.ingest.accepted
        self.summary.counters = c
        self.summary.state = self.pipeline.engine.state.value

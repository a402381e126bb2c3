"""``mavins run``: the live MAVLink INS service (link in -> pipeline -> publish).

Reads a pymavlink connection (UDP first; any connection string), feeds every
message through the shared pipeline, publishes output sets to the master link
and every ``--out`` link, keeps an input tlog, and stops cleanly on request.
"""

from __future__ import annotations

import logging
import select
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from . import publish
from .engine import EngineConfig, State
from .files import SolutionWriter
from .ingest import IngestConfig
from .mavlink import mavlink, mavutil
from .pipeline import Pipeline

log = logging.getLogger("mavins")

RCVBUF_BYTES = 8 * 1024 * 1024


@dataclass
class ServiceConfig:
    """Links, identity and side outputs of the service."""

    master: str = "udpin:127.0.0.1:14551"
    outs: list[str] = field(default_factory=list)
    sysid: int | None = None
    compid: int = 191
    tlog: Path | None = None
    solution: Path | None = None
    request_imu: float | None = None
    publish: publish.PublishConfig = field(default_factory=publish.PublishConfig)


@dataclass
class Summary:
    """What happened during a run (printed on exit)."""

    messages: int = 0
    outputs: int = 0
    state: str = ""
    counters: dict[str, int] = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"messages received: {self.messages}", f"output sets published: {self.outputs}", f"final state: {self.state}"]
        out += [f"{k}: {v}" for k, v in sorted(self.counters.items())]
        return out


class Service:
    """The live loop. ``run(stop)`` returns when ``stop`` is set."""

    def __init__(self, engine_cfg: EngineConfig, ingest_cfg: IngestConfig, cfg: ServiceConfig) -> None:
        self.cfg = cfg
        self.pipeline = Pipeline(engine_cfg, ingest_cfg, own_component=cfg.compid)
        self.summary = Summary()
        self.mav = mavlink.MAVLink(None, srcSystem=cfg.sysid or 0, srcComponent=cfg.compid)
        self.mav.robust_parsing = True
        self.master = mavutil.mavlink_connection(cfg.master, source_system=cfg.sysid or 0,
                                                 source_component=cfg.compid, dialect="common")
        self._tune_socket(self.master)
        self.outs = [mavutil.mavlink_connection(u, source_system=cfg.sysid or 0, source_component=cfg.compid,
                                                dialect="common") for u in cfg.outs]
        self._tlog = open(cfg.tlog, "wb") if cfg.tlog else None
        self._solution = SolutionWriter(cfg.solution) if cfg.solution else None
        self._sysid_known = cfg.sysid is not None
        self._last_hb = 0.0
        self._last_imu_wall = 0.0
        self._last_request = 0.0
        self._acked = False

    @staticmethod
    def _tune_socket(conn: object) -> None:
        sock = getattr(conn, "port", None)
        if isinstance(sock, socket.socket) and sock.type == socket.SOCK_DGRAM:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)

    # -- sending -------------------------------------------------------------
    def _send(self, msgs: list[mavlink.MAVLink_message]) -> None:
        if not self._sysid_known:
            return
        for m in msgs:
            buf = m.pack(self.mav)
            self.mav.seq = (self.mav.seq + 1) % 256
            for link in (self.master, *self.outs):
                try:
                    link.write(buf)
                except OSError as exc:
                    self.pipeline.counters["send_errors"] += 1
                    log.debug("send to %s failed: %s", getattr(link, "address", link), exc)

    def attach_recorder(self, recorder: object) -> None:
        """Record every sample, output and event to Rerun (closed with the service)."""
        self.pipeline.recorder = recorder

    def _announce(self) -> None:
        for level, text in self.pipeline.take_events():
            getattr(log, level.lower() if level != "WARNING" else "warning", log.info)(text)
            self._send([publish.statustext(self.mav, level, text)])

    # -- receiving -----------------------------------------------------------
    def _handle(self, msg: mavlink.MAVLink_message) -> None:
        self.summary.messages += 1
        if self._tlog is not None and msg.get_type() != "BAD_DATA":
            self._tlog.write(struct.pack(">Q", int(time.time() * 1e6)) + msg.get_msgbuf())
        out = self.pipeline.handle(msg)
        if not self._sysid_known and self.pipeline.vehicle_sysid is not None:
            self.mav.srcSystem = self.pipeline.vehicle_sysid
            self._sysid_known = True
        if msg.get_type() in ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"):
            self._last_imu_wall = time.monotonic()
        if msg.get_type() == "COMMAND_ACK" and msg.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self._acked = msg.result == mavlink.MAV_RESULT_ACCEPTED
            log.info("SET_MESSAGE_INTERVAL %s", "accepted" if self._acked else f"refused (result {msg.result})")
        self._announce()
        if out is not None:
            self._send(publish.encode(self.mav, out, self.cfg.publish, self.pipeline.engine.counters["restarts"]))
            self.summary.outputs += 1
            if self._solution is not None:
                self._solution.write(out.row)

    def _periodic(self) -> None:
        now = time.monotonic()
        if now - self._last_hb >= 1.0:
            self._last_hb = now
            self._send([publish.heartbeat(self.mav, self.pipeline.engine.state is State.NAVIGATING)])
        if self.cfg.request_imu and self._sysid_known and now - self._last_imu_wall > 2.0 and now - self._last_request > 2.0:
            self._last_request = now
            interval_us = 1e6 / self.cfg.request_imu
            self._send([self.mav.command_long_encode(self.mav.srcSystem, mavlink.MAV_COMP_ID_AUTOPILOT1,
                                                     mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                                     mavlink.MAVLINK_MSG_ID_HIGHRES_IMU, interval_us, 0, 0, 0, 0, 0)])
            log.info("asked for HIGHRES_IMU at %.0f Hz", self.cfg.request_imu)

    def run(self, stop: threading.Event) -> Summary:
        """Serve until ``stop`` is set; flush the side outputs and return the summary."""
        fd = self.master.fd if getattr(self.master, "fd", None) is not None else None
        try:
            while not stop.is_set():
                msg = self.master.recv_msg()
                if msg is None:
                    self._periodic()
                    if fd is not None:
                        select.select([fd], [], [], 0.05)
                    else:
                        time.sleep(0.002)
                    continue
                self._handle(msg)
                self._periodic()
        finally:
            self.close()
        return self.summary

    def close(self) -> None:
        """Flush and close the tlog, the solution file and the links."""
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
            try:
                self.pipeline.take_events()
                self.pipeline.recorder.close()  # type: ignore[attr-defined]
            except Exception as exc:  # a recording failure must never take navigation down
                log.error("closing the Rerun recording failed: %s", exc)
            self.pipeline.recorder = None
        c = dict(self.pipeline.counters)
        c.update({f"rejected_{k}": v for k, v in self.pipeline.ingest.rejected.items()})
        c.update(self.pipeline.engine.counters)
        c["imu_accepted"] = self.pipeline.ingest.accepted
        self.summary.counters = c
        self.summary.state = self.pipeline.engine.state.value

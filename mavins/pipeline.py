"""The message pipeline shared by ``run``, ``replay`` and ``demo``.

MAVLink message in -> ingest (validate, select the IMU) -> engine (align,
navigate) -> output set out. Position and heading aids (GPS_RAW_INT,
GLOBAL_POSITION_INT, ATTITUDE of the vehicle) are taken here too. Nothing in
it looks at the wall clock, so live and replayed input give identical output.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field

from .core.frames import local_ned
from .core.records import ImuSample, Solution
from .engine import Engine, EngineConfig
from .link.ingest import IMU_MESSAGES, Ingest, IngestConfig
from .record.sink import Sink

log = logging.getLogger("mavins")

RESTART_JUMP = 1.0  # s: sensor time going back further than this is an autopilot restart


@dataclass
class Pipeline:
    """Ingest + engine, fed one message at a time."""

    engine_cfg: EngineConfig
    ingest_cfg: IngestConfig = field(default_factory=IngestConfig)
    own_component: int = 191
    engine: Engine = field(init=False)
    ingest: Ingest = field(init=False)
    counters: Counter = field(default_factory=Counter)
    last_sample: ImuSample | None = None
    recorder: Sink | None = None
    _outputs: int = 0

    def __post_init__(self) -> None:
        self.engine = Engine(self.engine_cfg)
        self.ingest = Ingest(self.ingest_cfg)

    @property
    def vehicle_sysid(self) -> int | None:
        return self.ingest.locked_system

    def handle(self, msg: object) -> Solution | None:
        """Process one message; returns an output set when one is due."""
        name = msg.get_type()  # type: ignore[attr-defined]
        if name == "BAD_DATA":
            self.counters["bad_data"] += 1
            return None
        if name in IMU_MESSAGES:
            return self._imu(msg)
        src = msg.get_srcSystem()  # type: ignore[attr-defined]
        if self.ingest.locked_system is not None and src != self.ingest.locked_system:
            return None
        if msg.get_srcComponent() == self.own_component:  # type: ignore[attr-defined]
            return None
        if name == "GPS_RAW_INT" and msg.fix_type >= 3:  # type: ignore[attr-defined]
            alt = msg.alt_ellipsoid / 1000.0 if getattr(msg, "alt_ellipsoid", 0) else msg.alt / 1000.0  # type: ignore[attr-defined]
            self.engine.set_position(msg.lat * 1e-7, msg.lon * 1e-7, alt, "GPS_RAW_INT")  # type: ignore[attr-defined]
        elif name == "GLOBAL_POSITION_INT" and (msg.lat or msg.lon):  # type: ignore[attr-defined]
            self.engine.set_position(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt / 1000.0, "GLOBAL_POSITION_INT")  # type: ignore[attr-defined]
        elif name == "ATTITUDE" and math.isfinite(msg.yaw):  # type: ignore[attr-defined]
            self.engine.set_vehicle_yaw(float(msg.yaw))  # type: ignore[attr-defined]
        return None

    def _imu(self, msg: object) -> Solution | None:
        last = self.ingest.last_t
        smp = self.ingest.sample(msg)
        if smp is None:
            t_new = _msg_time(msg)
            if last is not None and t_new is not None and t_new < last - RESTART_JUMP and \
                    self.ingest.last_reason == "time_backwards":
                # the autopilot restarted (its clock went back): start over
                self.ingest.reset_time()
                self.engine.restart(f"sensor time went back from {last:.3f} to {t_new:.3f} s")
                smp = self.ingest.sample(msg)
            if smp is None:
                return None
        self.last_sample = smp
        out = self.engine.on_imu(smp)
        rec = self.recorder
        if rec is not None:
            rec.on_sample(smp.t, smp.gyro, smp.accel)
            if out is not None:
                r = out.row
                rec.on_output(r, out.origin, local_ned(float(r[1]), float(r[2]), float(r[3]), out.origin))
                self._outputs += 1
                if self._outputs % 50 == 1:
                    counts = {f"rejected_{k}": v for k, v in self.ingest.rejected.items()}
                    counts.update({k: v for k, v in self.engine.counters.items() if v})
                    if counts:
                        rec.on_counters(float(r[0]), counts)
        return out

    def take_events(self) -> list[tuple[str, str]]:
        """State changes and warnings since the last call, drained once (also sent to the recorder)."""
        events = self.engine.take_events()
        if self.recorder is not None:
            t = self.last_sample.t if self.last_sample is not None else None
            for level, text in events:
                self.recorder.on_event(t, level, text)
        return events


def _msg_time(msg: object) -> float | None:
    if hasattr(msg, "time_usec"):
        return msg.time_usec * 1e-6  # type: ignore[attr-defined]
    if hasattr(msg, "time_boot_ms"):
        return msg.time_boot_ms * 1e-3  # type: ignore[attr-defined]
    return None

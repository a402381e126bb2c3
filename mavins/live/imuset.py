"""Several IMU streams of one vehicle, fused sample by sample with parity-space FDI (``--imus``).

Used by the pipeline in place of the single-stream ingest when ``--imus`` is given
(docs/redundancy.md "Live"). Each stream keeps its own validation (link/ingest.py); samples of
the streams that carry the same sensor time (within ``SAME_INSTANT``) form one instant, whose rates
go through core/fdi.py's monitor; the fused rates leave as one ImuSample on the first stream's
time. Streams are numbered as FDI.csv numbers IMUs: HIGHRES_IMU ``id`` k is IMU k; RAW_IMU (or
SCALED_IMU) is IMU 0, SCALED_IMU2 IMU 1, SCALED_IMU3 IMU 2.
"""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np

from ..core import errmodel
from ..core.fdi import FdiEvent, ImuSetMonitor
from ..core.records import ImuSample
from ..core.redundancy import ST_ALARM
from ..link.ingest import IMU_MESSAGES, Ingest, IngestConfig

SAME_INSTANT = 1.5e-3  # s: ArduPilot's SCALED_IMU2/3 carry whole milliseconds beside RAW_IMU's microseconds
DISCOVERY_S = 1.0  # s of sensor time in which ``--imus all`` collects the streams


def imu_index(msg: object) -> int | None:
    """The IMU number of an IMU message (module docstring), None for other messages."""
    name = msg.get_type()  # type: ignore[attr-defined]
    if name not in IMU_MESSAGES:
        return None
    if name in ("HIGHRES_IMU", "RAW_IMU"):
        return int(getattr(msg, "id", 0)) if name == "HIGHRES_IMU" else 0
    return {"SCALED_IMU": 0, "SCALED_IMU2": 1, "SCALED_IMU3": 2}[name]


def _warm_up() -> None:
    """Load (or compile) the monitor's kernel now, not when the first samples wait for it."""
    from ..core.errmodel import ImuSpec

    mon = ImuSetMonitor(2, ImuSpec(gyro_arw=1e-3, accel_vrw=1e-2), 0.01, window=0.02)
    mon.process(np.array([0.01, 0.02]), np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), np.full(2, 0.01), rates=True)


class ImuSet:
    """Validate, align, monitor and fuse several IMU streams; the same interface as Ingest
    (``sample``, ``last_t``, ``last_reason``, ``reset_time``) so the pipeline can use either.

    ``imus`` are the IMU numbers to fuse, or () for every stream seen in the first DISCOVERY_S s.
    ``spec`` is the sensors' noise (grade name or spec keys, core/errmodel.py), ``false_alarm`` the
    design probability per test.
    """

    def __init__(self, cfg: IngestConfig, imus: tuple[int, ...], spec: object, false_alarm: float) -> None:
        self.cfg = cfg
        self.wanted = tuple(imus)
        self.spec = spec
        self.false_alarm = false_alarm
        self.ingests: dict[tuple[str, int], Ingest] = {}
        self.order: list[int] = sorted(set(imus))
        self.fixed = bool(imus)
        self.first_t: float | None = None
        self.pending: dict[int, ImuSample] = {}
        self.group_t = 0.0
        self.held: dict[int, ImuSample] = {}
        self.prev_t: float | None = None
        self.monitor: ImuSetMonitor | None = None
        self.events: list[tuple[str, str]] = []
        self.tests: list[tuple[float, str, float, float, np.ndarray]] = []
        self.fdi: list[FdiEvent] = []
        self.counters: Counter = Counter()
        self.last_t: float | None = None
        self.last_reason: str | None = None
        self.primary = Ingest(cfg)  # the pipeline reads the vehicle's system and counts from it
        _warm_up()


    def reset_time(self) -> None:
        """Forget the streams' last times and the instant being gathered (autopilot restart)."""
        for ing in self.ingests.values():
            ing.reset_time()
        self.pending.clear()
        self.prev_t = None
        self.last_t = None

    def take_events(self) -> list[tuple[str, str]]:
        ev, self.events = self.events, []
        return ev

    def take_tests(self) -> list[tuple[float, str, float, float, np.ndarray]]:
        """``(t, sensor, statistic, threshold, residuals)`` of every window test since the last call."""
        tests, self.tests = self.tests, []
        return tests

    def status_bits(self) -> tuple[int, int]:
        """SYS_STATUS sensor bits ``(present, unhealthy)`` of the set: IMU 0 is 3D_GYRO/3D_ACCEL, IMU 1
        3D_GYRO2/3D_ACCEL2 (MAVLink has no bit for a third IMU). A sensor is unhealthy while isolated;
        the first IMU's bit also while a detected fault could not be isolated."""
        from ..link.mavlink import mavlink

        bits = {("gyro", 0): mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO, ("accel", 0): mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
                ("gyro", 1): mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO2,
                ("accel", 1): mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL2}
        present = sum(b for (_, k), b in bits.items() if k in self.order)
        bad = 0
        if self.monitor is not None:
            for part in (self.monitor.gyro, self.monitor.accel):
                for row in np.flatnonzero(part.active == 0.0):
                    bad |= bits.get((part.name, self.order[row // 3]), 0)
                if part.st[ST_ALARM] > 0.0:
                    bad |= bits[(part.name, 0)]
        return present, bad

    def sample(self, msg: object) -> ImuSample | None:
        """The fused sample of the instant this message completes (or the previous one, when it
        starts a new instant), else None."""
        self.last_reason = None
        k = imu_index(msg)
        if k is None:
            return None
        name = msg.get_type()  # type: ignore[attr-defined]
        if self.fixed and k not in self.order:
            self.counters["other_imu"] += 1
            return None
        key = (name, k)
        ing = self.ingests.get(key)
        if ing is None:
            if any(i == k for _, i in self.ingests):
                self.counters["other_imu"] += 1  # the same IMU number from a second message kind
                return None
            system = self.primary.locked_system if self.primary.locked_system is not None else self.cfg.target_system
            ing = Ingest(dataclasses.replace(self.cfg, message=name, imu_id=getattr(msg, "id", 0)
                                             if name in ("HIGHRES_IMU", "RAW_IMU") else None, target_system=system))
            self.ingests[key] = ing
        smp = ing.sample(msg)
        if smp is None:
            self.last_reason = ing.last_reason
            if ing.last_reason is not None:
                self.primary.reject(ing.last_reason)
            return None
        if self.primary.locked_system is None:
            self.primary.locked_message, self.primary.locked_id, self.primary.locked_system = name, k, smp.sysid
        if not self.fixed:
            if self.first_t is None:
                self.first_t = smp.t
            if k not in self.order:
                self.order.append(k)
                self.order.sort()
            if smp.t - self.first_t < DISCOVERY_S:
                return None
            self.fixed = True
            self.pending.clear()
            names = ", ".join(str(i) for i in self.order)
            self.events.append(("INFO", f"fusing IMUs {names}" if len(self.order) > 1
                                else f"only IMU {names} found: navigating on it without FDI"))
        if len(self.order) < 2:
            return self._publish(smp)
        out = None
        if self.pending and (abs(smp.t - self.group_t) > SAME_INSTANT or k in self.pending):
            out = self._flush()
        if not self.pending:
            self.group_t = smp.t
        self.pending[k] = smp
        if len(self.pending) == len(self.order):
            out = self._flush()
        return out

    def _publish(self, smp: ImuSample) -> ImuSample:
        self.last_t = smp.t
        self.primary.accepted += 1
        return smp

    def _flush(self) -> ImuSample | None:
        """Fuse the gathered instant (a missing IMU holds its last rates, counted)."""
        group, self.pending = self.pending, {}
        for k in self.order:
            if k in group:
                self.held[k] = group[k]
            elif k in self.held:
                self.counters["imu_missing"] += 1
            else:
                return None
        first = group[min(group)]
        t = first.t
        if self.prev_t is None or t <= self.prev_t:
            self.prev_t = t
            return None
        dt = t - self.prev_t
        self.prev_t = t
        if self.monitor is None:
            self.monitor = ImuSetMonitor(len(self.order), errmodel.spec_of(self.spec), dt,  # type: ignore[arg-type]
                                         false_alarm=self.false_alarm, keep_log=False)
        rows = [self.held[k] for k in self.order]
        w = np.array([[r.gyro for r in rows]])
        f = np.array([[r.accel for r in rows]])
        g, a, events = self.monitor.process(np.array([t]), w, f, np.array([dt]), rates=True)
        for part in (self.monitor.gyro, self.monitor.accel):
            for tw, stat, thr in part.recent:
                self.tests.append((float(tw), part.name, float(stat), float(thr), part.residuals()))
        for i, e in enumerate(events):
            self.fdi.append(e)
            nxt = events[i + 1] if i + 1 < len(events) else None
            if not (e.event == "detected" and nxt is not None and nxt.event == "isolated" and nxt.sensor == e.sensor):
                self._announce(e)  # a detection that is isolated at once is told by its isolation
        mag = next((r.mag for r in rows if r.mag is not None), None)
        fused = ImuSample(t, tuple(map(float, g[0])), tuple(map(float, a[0])), mag, first.sysid,
                          first.compid)
        return self._publish(fused)

    def _announce(self, e: FdiEvent) -> None:
        stat = f"statistic {e.statistic:.4g}, threshold {e.threshold:.4g}"
        if e.index < 0:
            text = (f"{e.sensor} fault detected, not isolable ({stat})" if e.event == "detected"
                    else f"{e.sensor} fault cleared ({stat})")
        else:
            imu = self.order[e.imu] if e.imu is not None else -1
            text = f"IMU {imu} {e.sensor} {e.axis} {e.event} ({stat})"
        self.events.append(("INFO" if e.event == "recovered" else "WARNING", f"FDI at t={e.t:.3f} s: {text}"))

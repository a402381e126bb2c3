"""The one interface the pipeline and the service record through, and its guard.

A recording is optional: when the recorder raises, :class:`GuardedSink`
switches it off, reports the failure once, and every later call does nothing,
so navigation, logging and publishing go on unchanged.
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np


class Sink(Protocol):
    """What gets recorded: samples, solutions, counters, events, latency (sensor time t, s)."""

    def on_sample(self, t: float, gyro: tuple[float, float, float], accel: tuple[float, float, float]) -> None: ...
    def on_output(self, row: np.ndarray, origin: tuple[float, float, float], ned: np.ndarray) -> None: ...
    def on_counters(self, t: float, counters: dict[str, int]) -> None: ...
    def on_event(self, t: float | None, level: str, text: str) -> None: ...
    def on_latency(self, t: float, ms: float) -> None: ...
    def on_filter(self, t: float, unc: object) -> None: ...
    def on_states(self, t: float, groups: tuple, row: np.ndarray) -> None: ...
    def on_gnss(self, t: float, ned: np.ndarray) -> None: ...
    def on_fdi(self, t: float, sensor: str, statistic: float, threshold: float, residuals: np.ndarray) -> None: ...
    def close(self) -> None: ...


class GuardedSink:
    """A :class:`Sink` that never raises: the first failure switches it off."""

    def __init__(self, sink: Sink, on_failure: Callable[[BaseException], None]) -> None:
        self._sink: Sink | None = sink
        self._on_failure = on_failure

    @property
    def active(self) -> bool:
        return self._sink is not None

    def _call(self, name: str, *args: object) -> None:
        if self._sink is None:
            return
        try:
            getattr(self._sink, name)(*args)
        except Exception as exc:  # a recording failure must never take navigation down
            self._sink = None
            self._on_failure(exc)

    def on_sample(self, t: float, gyro: tuple[float, float, float], accel: tuple[float, float, float]) -> None:
        self._call("on_sample", t, gyro, accel)

    def on_output(self, row: np.ndarray, origin: tuple[float, float, float], ned: np.ndarray) -> None:
        self._call("on_output", row, origin, ned)

    def on_counters(self, t: float, counters: dict[str, int]) -> None:
        self._call("on_counters", t, counters)

    def on_event(self, t: float | None, level: str, text: str) -> None:
        self._call("on_event", t, level, text)

    def on_latency(self, t: float, ms: float) -> None:
        self._call("on_latency", t, ms)

    def on_filter(self, t: float, unc: object) -> None:
        self._call("on_filter", t, unc)

    def on_states(self, t: float, groups: tuple, row: np.ndarray) -> None:
        self._call("on_states", t, groups, row)

    def on_gnss(self, t: float, ned: np.ndarray) -> None:
        self._call("on_gnss", t, ned)

    def on_fdi(self, t: float, sensor: str, statistic: float, threshold: float, residuals: np.ndarray) -> None:
        self._call("on_fdi", t, sensor, statistic, threshold, residuals)

    def close(self) -> None:
        self._call("close")
        self._sink = None

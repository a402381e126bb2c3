"""Fault detection, isolation and fusion of redundant IMUs: a thin stateful shell over core/redundancy.py.

:class:`ParityMonitor` watches one set of single-axis sensors (all the gyro axes of the IMUs, or all
the accelerometer axes) and :class:`ImuSetMonitor` pairs two of them for IMUs given as time-aligned
increments or rates. The design (docs/redundancy.md):

* Window: the test runs on window means of ``window`` seconds (default 0.5 s, non-overlapping), so
  a fault is seen at the end of the first window it covers enough of: the delay is at most two
  windows for a fault just above the threshold's reach and about one window (0.5 s) for a large one.
  A longer window lowers the noise (sigma ~ 1/sqrt(window)) and the test count per hour, and
  lengthens the delay in proportion.
* Bias: the sensors' constant and slowly varying biases differ from IMU to IMU (a consumer gyro's
  turn-on bias is 1/3 deg/s, as large as the faults to be found), so the part of them the parity space
  sees is learnt in the first ``calibration`` seconds (assumed fault-free) and then followed with a
  first-order low-pass of time constant ``tau_bias`` (60 s) that stops while a test fails. A ramp
  slower than ``threshold reach / tau_bias`` is followed rather than detected.
* Reconfiguration: an isolated sensor is dropped (fusion and parity of the rest); it is taken back,
  with a ``recovered`` event, after ``holdoff`` seconds of agreement with the fused estimate. A fault
  that is detected but cannot be isolated (two IMUs, or four single-axis sensors) leaves the fusion as
  it is and raises an alarm, cleared after ``holdoff`` seconds under the threshold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import redundancy as rd
from .errmodel import ImuSpec

AXES = "xyz"


@dataclass(frozen=True)
class FdiEvent:
    """One FDI decision (docs/conventions.md "Redundant IMUs", FDI.csv).

    ``sensor`` is ``gyro`` or ``accel``; ``index`` the sensor row of the set (-1 when only
    detected or an alarm cleared); ``imu`` and ``axis`` follow from it for sets of triads.
    """

    t: float
    event: str
    sensor: str
    index: int
    statistic: float
    threshold: float

    @property
    def imu(self) -> int | None:
        return None if self.index < 0 else self.index // 3

    @property
    def axis(self) -> str:
        return "" if self.index < 0 else AXES[self.index % 3]


class ParityMonitor:
    """Parity-space FDI of one sensor set ``m = H x + b + e`` (``H`` (n, 3), noise ``sigma`` (n,) per
    sensor as the 1-sigma of a window-mean rate, rate units).

    ``window`` samples per test, ``window_s`` their nominal duration (s); ``false_alarm`` the design
    probability per test; ``calibration`` and ``holdoff`` in windows; ``keep_log`` keeps every test's
    statistic for :meth:`statistics` (off for a long live run).
    """

    def __init__(self, H: np.ndarray, sigma: np.ndarray, *, window: int, window_s: float, false_alarm: float,
                 tau_bias: float = 60.0, calibration: int = 10, holdoff: int = 20, name: str = "gyro",
                 keep_log: bool = True) -> None:
        self.H = np.ascontiguousarray(H, dtype=float)
        n = self.H.shape[0]
        self.sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).copy()
        if not np.all(self.sigma > 0.0) or not np.all(np.isfinite(self.sigma)):
            raise ValueError(f"{name}: the sensor model gives no noise; FDI needs a positive noise figure")
        if not 0.0 < false_alarm < 1.0:
            raise ValueError(f"false-alarm probability must be in (0, 1), got {false_alarm!r}")
        if window < 1:
            raise ValueError(f"window must hold at least one sample, got {window}")
        self.name = name
        self.window = int(window)
        self.false_alarm = float(false_alarm)
        self.alpha = min(1.0, window_s / tau_bias)
        self.calibration = int(calibration)
        self.holdoff = int(holdoff)
        self.keep_log = keep_log
        self.active = np.ones(n)
        self.st = np.zeros(rd.ST_SIZE)
        self.acc = np.zeros(n)
        self.b = np.zeros(n)
        self.excl_count = np.zeros(n)
        self.p = np.zeros(max(n - 3, 1))
        self.thr1 = rd.chi2_quantile(self.false_alarm, 1, upper=True)
        self._logs: list[np.ndarray] = []
        self.recent = np.empty((0, 3))  # (t, statistic, threshold) of the tests of the last process() call
        self._configure()
        self._res = np.zeros(n)

    def _configure(self) -> None:
        act = self.active > 0.0
        if act.sum() < 3:
            raise ValueError(f"{self.name}: fewer than three sensors left")
        G, Vw = rd.reconfigure(self.H, act, self.sigma)
        self.G = np.ascontiguousarray(G)
        self.V = np.ascontiguousarray(Vw / self.sigma[None, :])  # p = V_w W y
        k = self.V.shape[0]
        self.dof = k
        self.threshold = rd.chi2_quantile(self.false_alarm, k, upper=True) if k > 0 else math.inf
        cov = np.linalg.inv(self.H[act].T @ (self.H[act] / self.sigma[act, None] ** 2))
        self.excl_sigma = np.sqrt(self.sigma**2 + np.einsum("ij,jk,ik->i", self.H, cov, self.H))

    @property
    def isolating(self) -> bool:
        """Whether a fault in the present configuration could be isolated (some column isolable)."""
        return bool(self.dof > 0 and rd.isolable(self.V).any())

    def residuals(self) -> np.ndarray:
        """Each sensor's parity residual of the last test, ``v_j^T p / |v_j|`` (sensor-noise units,
        0 for a sensor dropped before it): the signed square root of its isolation score."""
        return self._res

    def _residuals_now(self) -> np.ndarray:
        p = self.p[: self.dof]
        norms = np.sqrt(np.sum(self.V * self.V, axis=0))
        proj = p @ self.V if self.dof else np.zeros(self.V.shape[1])
        return np.where(norms > 0.0, proj / np.where(norms > 0.0, norms, 1.0), 0.0)

    def statistics(self) -> np.ndarray:
        """``(t, statistic, threshold)`` of every test so far, (K, 3)."""
        return np.concatenate(self._logs) if self._logs else np.empty((0, 3))

    def process(self, t: np.ndarray, m: np.ndarray, dt: np.ndarray, *, rates: bool = False
                ) -> tuple[np.ndarray, list[FdiEvent]]:
        """Monitor samples ``m`` (N, n) (increments, or rates with ``rates``) over intervals ``dt`` ending
        at ``t``; returns the fused 3-vectors (N, 3), same kind as ``m``, and the events."""
        m = np.ascontiguousarray(m, dtype=float)
        t = np.ascontiguousarray(t, dtype=float)
        dt = np.ascontiguousarray(dt, dtype=float)
        fused = np.empty((m.shape[0], 3))
        log = np.empty((m.shape[0] // self.window + 2, 3))
        events: list[FdiEvent] = []
        i = 0
        self.st[rd.ST_NLOG] = 0.0
        tested = 0.0
        while True:
            i, code, j = rd.monitor_run(m, dt, t, i, self.window, self.st, self.acc, self.b, self.H, self.G,
                                        self.V, self.active, self.threshold, self.thr1, self.excl_sigma,
                                        self.excl_count, self.alpha, self.calibration, self.holdoff, self.p,
                                        fused, log, rates)
            if self.st[rd.ST_NLOG] > tested:  # a new test: its residuals with its own configuration
                tested = self.st[rd.ST_NLOG]
                self._res = self._residuals_now()
            if code == rd.RUN_DONE:
                break
            nl = int(self.st[rd.ST_NLOG])
            stat = float(log[nl - 1, 1]) if nl else math.nan
            te = float(t[i - 1])
            if code == rd.RUN_DETECTED:
                events.append(FdiEvent(te, "detected", self.name, -1, stat, self.threshold))
                jj = rd.isolate(self.V, self.p[: self.dof])
                if jj >= 0:
                    events.append(FdiEvent(te, "isolated", self.name, jj, stat, self.threshold))
                    self.active[jj] = 0.0
                    self.excl_count[jj] = 0.0
                    self._configure()
                else:
                    self.st[rd.ST_ALARM] = 1.0
            elif code == rd.RUN_CLEARED:
                self.st[rd.ST_ALARM] = 0.0
                events.append(FdiEvent(te, "recovered", self.name, -1, stat, self.threshold))
            else:
                threshold = self.threshold  # the test's own, before the restored set's (FDI.csv contract)
                self.active[j] = 1.0
                self._configure()
                events.append(FdiEvent(te, "recovered", self.name, j, stat, threshold))
        self.recent = log[: int(self.st[rd.ST_NLOG])].copy()
        if self.keep_log and self.recent.shape[0]:
            self._logs.append(self.recent)
        return fused, events


class ImuSetMonitor:
    """FDI and fusion of ``n_imus`` IMUs sampled at the same times, each a triad whose axes are the
    body axes turned by ``rotations[i]`` (body -> IMU, default identity), with the noise of ``spec``
    (the same for every IMU).

    ``dt`` is the nominal sample interval (s): the window holds ``round(window / dt)`` samples.
    Times in s, ``calibration`` and ``holdoff`` in s.
    """

    def __init__(self, n_imus: int, spec: ImuSpec, dt: float, *, window: float = 0.5, false_alarm: float = 1e-6,
                 tau_bias: float = 60.0, calibration: float = 5.0, holdoff: float = 10.0,
                 rotations: list[np.ndarray] | None = None, keep_log: bool = True) -> None:
        if n_imus < 2:
            raise ValueError(f"FDI needs two or more IMUs, got {n_imus}")
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"sample interval must be positive, got {dt!r}")
        self.n_imus = n_imus
        win = max(1, round(window / dt))
        self.window_s = win * dt
        rots = rotations if rotations is not None else [np.eye(3)] * n_imus
        H = rd.triad_rows(rots)
        sg = rd.window_sigma(spec.gyro_arw, self.window_s, tau_bias, spec.gyro_gm, spec.gyro_tau, spec.gyro_rrw)
        sa = rd.window_sigma(spec.accel_vrw, self.window_s, tau_bias, spec.accel_gm, spec.accel_tau,
                             spec.accel_rrw)
        n_cal = max(1, round(calibration / self.window_s))
        hold = max(1, round(holdoff / self.window_s))
        self.gyro, self.accel = (
            ParityMonitor(H, s, window=win, window_s=self.window_s, false_alarm=false_alarm, tau_bias=tau_bias,
                          calibration=n_cal, holdoff=hold, name=name, keep_log=keep_log)
            for s, name in ((sg, "gyro"), (sa, "accel")))

    def process(self, t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, dt: np.ndarray, *, rates: bool = False
                ) -> tuple[np.ndarray, np.ndarray, list[FdiEvent]]:
        """``dtheta``, ``dv`` (N, n_imus, 3) increments (rad, m/s) or, with ``rates``, rates (rad/s,
        m/s^2), IMU axes; returns the fused body-frame ones (N, 3) each and the events in time order."""
        n = t.shape[0]
        g, ev_g = self.gyro.process(t, np.reshape(dtheta, (n, -1)), dt, rates=rates)
        a, ev_a = self.accel.process(t, np.reshape(dv, (n, -1)), dt, rates=rates)
        events = sorted(ev_g + ev_a, key=lambda e: e.t)
        return g, a, events

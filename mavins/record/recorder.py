"""Rerun recording of everything the service sees and computes.

Layout (entity paths, units in the series names):

* ``/world`` NED (right-handed, Z down) at the initial position:
  ``/world/vehicle`` pose (Rerun quaternions are xyzw: converted here only),
  with body axes and a body box; ``/world/trajectory/estimated`` and
  ``/world/trajectory/truth`` (decimated line strips).
* ``/plots/attitude`` roll, pitch, yaw (deg); ``/plots/velocity`` vn, ve, vd
  (m/s); ``/plots/position`` north, east, down (m) and ``/plots/height`` (m).
* ``/imu/gyro`` (rad/s) and ``/imu/accel`` (m/s^2), every sample.
* ``/errors/attitude`` (deg), ``/errors/position`` (m), ``/errors/velocity``
  (m/s): only where truth exists at the output's sensor time.
* ``/health/*``: sample interval (ms), output rate (Hz), processing latency
  (ms, live runs), ``/health/counts/*`` (rejected samples by reason, bridged
  and long gaps, restarts); ``/log`` text log of state changes, alignment
  result and warnings.
* ``/fdi/gyro`` and ``/fdi/accel`` with ``--imus``: ``test`` (statistic,
  threshold) and ``residuals`` (each sensor's parity residual) per window.

Timelines: ``sensor_time`` (duration) everywhere; ``wall_time`` on live runs.
Rows are buffered and sent with ``send_columns`` (columnar) every
``FLUSH_ROWS`` rows, so memory stays bounded on long runs; the trajectory
strip keeps at most ``TRAJ_POINTS`` points, halving its density when full.
"""

from __future__ import annotations

import math
import socket
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

FLUSH_ROWS = 512
TRUTH_MATCH_S = 1e-3  # truth is compared at the nearest truth sample within this much sensor time
TRAJ_POINTS = 2000
TRAJ_EVERY_S = 2.0
SMOOTHED_POINTS = 20000  # rows of the smoothed solution recorded per series (replay --smooth), evenly spaced

COLORS = {
    "x": [230, 60, 60],
    "y": [60, 170, 60],
    "z": [60, 90, 230],
    "estimated": [0, 170, 255],
    "truth": [255, 160, 0],
    "smoothed": [150, 60, 220],
}
XYZ = [COLORS["x"], COLORS["y"], COLORS["z"]]


TRAJECTORY_POINTS = 1.5  # the estimated trajectory's line width (screen points, readable at any zoom)
TRUTH_POINTS = 3.5  # the truth's: wider, so where the estimate lies on it the truth still shows round it


def _line_radius(points: float = TRAJECTORY_POINTS):  # type: ignore[no-untyped-def]
    """A trajectory line width in screen points (the same at any zoom)."""
    import rerun as rr

    return rr.components.Radius.ui_points(points)


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def blueprint():  # type: ignore[no-untyped-def]
    """The default layout: 3D and log left, navigation and errors middle, IMU and health right.

    Plots span the whole run and the time cursor follows new data, so the first
    screen of a file or of a live run shows the story.
    """
    import rerun.blueprint as rrb

    whole = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                  end=rrb.TimeRangeBoundary.infinite()))

    def series(origin: str, name: str, **kw: object):  # type: ignore[no-untyped-def]
        return rrb.TimeSeriesView(origin=origin, name=name, axis_x=whole,
                                  plot_legend=rrb.PlotLegend(corner="RightTop"), **kw)

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(origin="/world", name="3D (NED)"),
                rrb.TextLogView(origin="/log", name="Log"),
                row_shares=[3, 1],
            ),
            rrb.Vertical(
                series("/plots/attitude", "Attitude (deg)"),
                series("/plots/velocity", "Velocity NED (m/s)"),
                series("/plots/position", "Position from origin (m)"),
                rrb.Horizontal(
                    series("/errors/attitude", "Attitude error (deg)"),
                    series("/errors", "Position (m) / velocity (m/s) error, published 3-sigma",
                           contents=["+ /errors/position", "+ /errors/velocity", "+ /errors/position_3sigma"]),
                ),
                rrb.Horizontal(
                    series("/filter/sigma_pos", "Filter 1-sigma position (m)"),
                    series("/filter/test_ratios", "Test ratios (below 1 passes)"),
                ),
            ),
            rrb.Vertical(
                series("/imu/gyro", "Gyro (rad/s)"),
                series("/imu/accel", "Accel (m/s^2)"),
                series("/health/sample_interval", "Sample interval (ms)"),
                series("/health/output_rate", "Output rate (Hz)"),
                series("/health/latency", "Processing latency (ms)"),
                series("/health/counts", "Counts: rejected, gaps, restarts"),
                series("/fdi", "FDI (--imus): statistic, threshold", contents=["+ /fdi/gyro/test", "+ /fdi/accel/test"]),
            ),
            column_shares=[4, 3, 2],
        ),
        rrb.TimePanel(timeline="sensor_time", state="collapsed", play_state="following"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


class Recorder:
    """Buffers rows per entity and sends them as columns; never blocks on a viewer."""

    def __init__(self, path: Path | None, serve: bool = False, app: str = "mavins", live: bool = True) -> None:
        import rerun as rr

        self.rr = rr
        self.rec = rr.RecordingStream(app)
        sinks = []
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(path)))
        self.url: str | None = None
        if serve:
            server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=_free_port(), server_memory_limit="512MiB")
            self.url = server.uri
            sinks.append(server)
        if not sinks:
            raise ValueError("a recorder needs a file or --rerun-serve")
        self.rec.set_sinks(*sinks)
        self.rec.set_log_time_enabled(False)
        self.rec.send_blueprint(blueprint(), make_active=True, make_default=True)
        self.live = live
        self._buf: dict[str, list[tuple[float, float, list[float]]]] = defaultdict(list)
        self._state_series: set[str] = set()  # /filter/<name> entities whose series names were logged
        self._traj: list[list[float]] = []
        self._gnss: list[list[float]] = []
        self._traj_stride = 1
        self._traj_n = 0
        self._traj_last = -math.inf
        self._truth_t: np.ndarray | None = None
        self._truth: np.ndarray | None = None
        self._last_sample_t: float | None = None
        self._last_out_t: float | None = None
        self._static_done = False
        self.rows = defaultdict(int)
        self._log_static()

    # -- static content --------------------------------------------------------
    def _log_static(self) -> None:
        rr = self.rr
        self.rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)
        self.rec.log("/world/vehicle/axes", rr.Arrows3D(vectors=[[2, 0, 0], [0, 2, 0], [0, 0, 2]], colors=XYZ,
                                                        labels=["forward", "right", "down"]), static=True)
        self.rec.log("/world/vehicle/body", rr.Boxes3D(half_sizes=[[0.6, 0.4, 0.12]], colors=[[200, 200, 200]]),
                     static=True)
        series = {
            "/plots/attitude": (["roll", "pitch", "yaw"], XYZ),
            "/plots/velocity": (["vn", "ve", "vd"], XYZ),
            "/plots/position": (["north", "east", "down"], XYZ),
            "/plots/height": (["height"], [COLORS["estimated"]]),
            "/imu/gyro": (["gyro x", "gyro y", "gyro z"], XYZ),
            "/imu/accel": (["accel x", "accel y", "accel z"], XYZ),
            "/health/sample_interval": (["sample interval (ms)"], [[150, 150, 150]]),
            "/health/output_rate": (["output rate (Hz)"], [[100, 200, 200]]),
            "/health/latency": (["processing latency (ms)"], [[220, 120, 220]]),
            "/filter/test_ratios": (["position", "velocity", "height", "magnetometer"],
                                    [[0, 170, 255], [230, 60, 60], [60, 170, 60], [200, 160, 0]]),
            "/errors/position_3sigma": (["3-sigma horizontal (published)"], [[150, 150, 150]]),
        }
        for path, (names, colors) in series.items():
            self.rec.log(path, rr.SeriesLines(names=names, colors=colors), static=True)

    def log_truth(self, truth: np.ndarray) -> None:
        """Truth rows (sim file units: t, lat, lon, h, vn, ve, vd, roll, pitch, yaw, q...) for errors and the 3D view."""
        self._truth = np.asarray(truth)
        self._truth_t = self._truth[:, 0]
        rr = self.rr
        for path, name, color in (("/errors/attitude", "attitude error (deg)", COLORS["x"]),
                                  ("/errors/position", "horizontal position error (m)", COLORS["y"]),
                                  ("/errors/velocity", "velocity error (m/s)", COLORS["z"])):
            self.rec.log(path, rr.SeriesLines(names=[name], colors=[color]), static=True)

    # -- per-sample and per-output ----------------------------------------------
    def _push(self, path: str, t: float, values: list[float]) -> None:
        buf = self._buf[path]
        buf.append((t, time.time(), values))
        if len(buf) >= FLUSH_ROWS:
            self._flush(path)

    def on_sample(self, t: float, gyro: tuple[float, float, float], accel: tuple[float, float, float]) -> None:
        """A raw IMU sample (sensor time s, rad/s, m/s^2)."""
        self._push("/imu/gyro", t, list(gyro))
        self._push("/imu/accel", t, list(accel))
        if self._last_sample_t is not None:
            self._push("/health/sample_interval", t, [1e3 * (t - self._last_sample_t)])
        self._last_sample_t = t

    def on_output(self, row: np.ndarray, origin: tuple[float, float, float], ned: np.ndarray) -> None:
        """An output set: kernel row (radians), origin (deg, m), NED offset (m)."""
        t = float(row[0])
        if not self._static_done and self._truth is not None:
            self._log_truth_strip(origin)
        self._static_done = True
        self._push("/plots/attitude", t, [math.degrees(float(x)) for x in row[7:10]])
        self._push("/plots/velocity", t, [float(x) for x in row[4:7]])
        self._push("/plots/position", t, [float(x) for x in ned])
        self._push("/plots/height", t, [float(row[3])])
        q = row[10:14]
        self._push("/world/vehicle", t, [float(ned[0]), float(ned[1]), float(ned[2]),
                                         float(q[1]), float(q[2]), float(q[3]), float(q[0])])
        if self._last_out_t is not None and t > self._last_out_t:
            self._push("/health/output_rate", t, [1.0 / (t - self._last_out_t)])
        self._last_out_t = t
        self._errors(t, row)
        self._trajectory(t, ned)

    def _errors(self, t: float, row: np.ndarray) -> None:
        if self._truth_t is None:
            return
        tt = self._truth_t
        i = int(np.searchsorted(tt, t))
        cands = [k for k in (i - 1, i) if 0 <= k < len(tt)]
        if not cands:
            return
        i = min(cands, key=lambda k: abs(tt[k] - t))
        if abs(tt[i] - t) > TRUTH_MATCH_S:
            return
        tr = self._truth[i]  # type: ignore[index]
        from ..core.frames import north_east_error
        from ..core.rotation import quat_angle_between

        att = math.degrees(quat_angle_between(np.ascontiguousarray(tr[10:14]), np.ascontiguousarray(row[10:14])))
        dn, de = north_east_error(float(row[1]), float(row[2]), math.radians(tr[1]), math.radians(tr[2]))
        self._push("/errors/attitude", t, [att])
        self._push("/errors/position", t, [math.hypot(dn, de)])
        self._push("/errors/velocity", t, [float(np.linalg.norm(row[4:7] - tr[4:7]))])

    def _log_truth_strip(self, origin: tuple[float, float, float]) -> None:
        from ..core.frames import local_ned

        tr = self._truth  # type: ignore[assignment]
        step = max(1, len(tr) // TRAJ_POINTS)
        pts = [local_ned(math.radians(r[1]), math.radians(r[2]), r[3], origin) for r in tr[::step]]
        self.rec.log("/world/trajectory/truth", self.rr.LineStrips3D([np.array(pts)], colors=[COLORS["truth"]],
                                                                        radii=_line_radius(TRUTH_POINTS)), static=True)

    def _trajectory(self, t: float, ned: np.ndarray) -> None:
        self._traj_n += 1
        if self._traj_n % self._traj_stride == 0:
            self._traj.append([float(x) for x in ned])
            if len(self._traj) > TRAJ_POINTS:
                self._traj = self._traj[::2]
                self._traj_stride *= 2
        if t - self._traj_last >= TRAJ_EVERY_S and len(self._traj) > 1:
            self._traj_last = t
            self._send_row("/world/trajectory/estimated", t, self.rr.LineStrips3D.columns(
                strips=[np.array(self._traj)], colors=[COLORS["estimated"]], radii=[_line_radius()]))

    def on_event(self, t: float | None, level: str, text: str) -> None:
        """A state change or warning into the text log."""
        rr = self.rr
        lvl = {"INFO": rr.TextLogLevel.INFO, "WARNING": rr.TextLogLevel.WARN, "ERROR": rr.TextLogLevel.ERROR}.get(
            level, rr.TextLogLevel.INFO)
        if t is None:
            # an event before the first sample still belongs on the timeline (a static
            # row would hide every later one)
            t = self._last_sample_t if self._last_sample_t is not None else 0.0
        self.rec.set_time("sensor_time", duration=t)
        self.rec.log("/log", rr.TextLog(text, level=lvl))

    def on_filter(self, t: float, unc: object) -> None:
        """The filter's test ratios and the published horizontal 3-sigma (docs/filter.md); a ratio not
        measured yet is left out. (Its sigmas and estimates come with :meth:`on_states`.)"""
        sig = unc.sigma_pos  # type: ignore[attr-defined]
        ratios = [unc.pos_ratio, unc.vel_ratio, unc.hgt_ratio, unc.mag_ratio]  # type: ignore[attr-defined]
        self._push("/filter/test_ratios", t, [float(r) if math.isfinite(r) else 0.0 for r in ratios])
        self._push("/errors/position_3sigma", t, [3.0 * math.sqrt(0.5 * (sig[0] ** 2 + sig[1] ** 2))])

    def on_states(self, t: float, groups: tuple, row: np.ndarray) -> None:
        """The filter's estimates and 1-sigma in file units, one series entity ``/filter/<name>`` per group of
        columns (core.aided.column_groups: name, column names, indices into ``row``), named after its
        columns, whatever states the run estimates."""
        for name, names, idx in groups:
            path = f"/filter/{name}"
            if path not in self._state_series:
                self._state_series.add(path)
                self.rec.log(path, self.rr.SeriesLines(names=list(names)), static=True)
            self._push(path, t, [float(row[i]) for i in idx])

    def on_gnss(self, t: float, ned: np.ndarray) -> None:
        """A GNSS fix (NED m from the origin), shown as a point in the 3D view (at most
        TRAJ_POINTS, thinned like the trajectory)."""
        self._gnss.append([float(x) for x in ned])
        if len(self._gnss) > TRAJ_POINTS:
            self._gnss = self._gnss[::2]
        if len(self._gnss) % 10 == 1:
            self._send_row("/world/gnss", t, self.rr.Points3D.columns(
                positions=self._gnss, colors=[[255, 60, 200]] * len(self._gnss),
                radii=[0.4] * len(self._gnss)).partition([len(self._gnss)]))

    def on_smoothed(self, rows: np.ndarray, origin: tuple[float, float, float]) -> None:
        """The smoothed solution after the run (``replay --smooth``; kernel rows, aided.ROW_SIZE), beside the
        forward one: ``/plots/attitude/smoothed``, ``/plots/position/smoothed`` (NED m from the origin),
        ``/filter/sigma_pos/smoothed`` at most SMOOTHED_POINTS rows of each, and the path in the 3D view
        (``/world/trajectory/smoothed``, TRAJ_POINTS)."""
        from ..core.frames import local_ned

        if rows.shape[0] == 0:
            return
        rr = self.rr
        pick = rows[::max(1, -(-rows.shape[0] // SMOOTHED_POINTS))]
        t = pick[:, 0]
        ned = np.array([local_ned(float(r[1]), float(r[2]), float(r[3]), origin) for r in pick])
        for path, names, vals in (
                ("/plots/attitude/smoothed", ["smoothed roll", "smoothed pitch", "smoothed yaw"], np.degrees(pick[:, 7:10])),
                ("/plots/position/smoothed", ["smoothed n", "smoothed e", "smoothed d"], ned),
                ("/filter/sigma_pos/smoothed", ["smoothed sigma_n", "smoothed sigma_e", "smoothed sigma_d"],
                 pick[:, 14:17])):
            self.rec.log(path, rr.SeriesLines(names=names), static=True)
            self.rec.send_columns(path, indexes=[rr.TimeColumn("sensor_time", duration=t)],
                                  columns=rr.Scalars.columns(scalars=np.ascontiguousarray(vals)))
            self.rows[path] += len(t)
        strip = ned[::max(1, -(-ned.shape[0] // TRAJ_POINTS))]
        self.rec.log("/world/trajectory/smoothed", rr.LineStrips3D([strip], colors=[COLORS["smoothed"]],
                                                                    radii=_line_radius()), static=True)

    def _send_row(self, path: str, t: float, columns: object) -> None:
        """One row of a growing geometry (the whole strip or point set so far) at sensor time t (s),
        as a chunk of its own: the Rerun 0.41 viewer may draw nothing at the end of the run when
        such rows share a chunk (the batcher groups them by wall-clock timing), so they never do."""
        self.rec.send_columns(path, indexes=[self.rr.TimeColumn("sensor_time", duration=[t])],
                              columns=columns)  # type: ignore[arg-type]

    def on_fdi(self, t: float, sensor: str, statistic: float, threshold: float, residuals: np.ndarray) -> None:
        """One FDI window test of ``--imus`` (docs/redundancy.md): statistic and threshold, and each
        sensor's parity residual (sensor-noise units; IMU-major, x y z per IMU)."""
        self._push(f"/fdi/{sensor}/test", t, [statistic, threshold])
        self._push(f"/fdi/{sensor}/residuals", t, [float(r) for r in residuals])

    def on_counters(self, t: float, counters: dict[str, int]) -> None:
        """Counts so far: rejected samples by reason, bridged and long gaps, restarts (one entity each)."""
        for name, n in counters.items():
            self._push(f"/health/counts/{name}", t, [float(n)])

    def on_latency(self, t: float, ms: float) -> None:
        """Processing latency of an output set (ms): kernel arrival of its input to the set sent."""
        self._push("/health/latency", t, [ms])

    # -- output ------------------------------------------------------------------
    def _flush(self, path: str) -> None:
        rows = self._buf.get(path)
        if not rows:
            return
        rr = self.rr
        ts = np.array([r[0] for r in rows])
        vals = np.array([r[2] for r in rows], dtype=float)
        indexes = [rr.TimeColumn("sensor_time", duration=ts)]
        if self.live:
            indexes.append(rr.TimeColumn("wall_time", timestamp=np.array([r[1] for r in rows])))
        if path == "/world/vehicle":
            cols = rr.Transform3D.columns(translation=vals[:, 0:3], quaternion=vals[:, 3:7])
        else:
            cols = rr.Scalars.columns(scalars=vals if vals.shape[1] > 1 else vals[:, 0])
        self.rec.send_columns(path, indexes=indexes, columns=cols)
        self.rows[path] += len(rows)
        rows.clear()

    def close(self) -> None:
        """Flush every buffer and close the sinks (writes the file's footer)."""
        for path in list(self._buf):
            self._flush(path)
        self.rec.flush(timeout_sec=10.0)
        self.rec.disconnect()

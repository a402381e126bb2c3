"""``mavins replay``: a recorded log through the live pipeline, as fast as it goes.

Logs: MAVLink .tlog (every message as received), ArduPilot DataFlash .bin
(IMU messages) and PX4 .ulg (``sensor_combined``, interval-averaged rates).
DataFlash and ULog samples are turned into HIGHRES_IMU frames and parsed back,
so they take exactly the path a live message takes.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from .engine import EngineConfig, Output
from .files import DataFileError, SolutionWriter
from .ingest import IngestConfig
from .mavlink import mavlink, mavutil
from .pipeline import Pipeline
from .progress import Progress


@dataclass
class ReplayResult:
    """Counts of a replay."""

    messages: int
    outputs: int
    pipeline: Pipeline


def _frames_to_messages(frames: Iterator[bytes]) -> Iterator[mavlink.MAVLink_message]:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    for buf in frames:
        for m in parser.parse_buffer(buf) or ():
            yield m


def _ulog_messages(path: Path) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    try:
        from pyulog import ULog
    except ImportError as exc:  # pragma: no cover - pyulog is a dependency
        raise DataFileError(f"{path}: reading .ulg needs pyulog ({exc})") from None
    try:
        ulog = ULog(str(path), ["sensor_combined"])
    except Exception as exc:  # pyulog raises plain exceptions on bad files
        raise DataFileError(f"{path}: not a readable ULog: {exc}") from None
    data = [d for d in ulog.data_list if d.name == "sensor_combined"]
    if not data:
        raise DataFileError(f"{path}: no sensor_combined topic")
    d = data[0].data
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    n = len(d["timestamp"])

    def frames() -> Iterator[bytes]:
        for i in range(n):
            m = enc.highres_imu_encode(
                int(d["timestamp"][i]),
                float(d["accelerometer_m_s2[0]"][i]), float(d["accelerometer_m_s2[1]"][i]),
                float(d["accelerometer_m_s2[2]"][i]),
                float(d["gyro_rad[0]"][i]), float(d["gyro_rad[1]"][i]), float(d["gyro_rad[2]"][i]),
                0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0b111111, 0,
            )
            buf = m.pack(enc)
            enc.seq = (enc.seq + 1) % 256
            yield buf

    for i, m in enumerate(_frames_to_messages(frames())):
        yield (i + 1) / n, m


def _bin_messages(path: Path) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    log = mavutil.mavlink_connection(str(path))
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    size = max(os.path.getsize(path), 1)

    def frames() -> Iterator[bytes]:
        while True:
            m = log.recv_match(type="IMU", blocking=False)
            if m is None:
                return
            msg = enc.highres_imu_encode(int(m.TimeUS), m.AccX, m.AccY, m.AccZ, m.GyrX, m.GyrY, m.GyrZ,
                                         0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0b111111, int(getattr(m, "I", 0)))
            buf = msg.pack(enc)
            enc.seq = (enc.seq + 1) % 256
            yield buf

    for m in _frames_to_messages(frames()):
        yield min(getattr(log, "offset", 0) / size, 1.0), m


def _tlog_messages(path: Path) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """Records of a tlog (8-byte big-endian microsecond time + one MAVLink frame), streamed.

    Frames are split by their own length fields and decoded by pymavlink's
    ``MAVLink.decode`` (CRC checked), the decoder the live path uses; memory
    stays flat however long the log is. Bytes that are not a frame are
    reported as BAD_DATA, and reading resumes at the next frame marker.
    """
    parser = _parser_for_decode()
    size = max(os.path.getsize(path), 1)
    with open(path, "rb") as fh:
        buf = b""
        pos = 0
        offset = 0
        while True:
            if len(buf) - pos < 4096:
                chunk = fh.read(1 << 20)
                buf = buf[pos:] + chunk
                offset += pos
                pos = 0
                if not chunk and len(buf) < 8 + 8:
                    return
            if len(buf) - pos < 8 + 8:
                return
            start = pos + 8
            magic = buf[start]
            if magic == 0xFD:
                n = 12 + buf[start + 1] + (13 if buf[start + 2] & 0x01 else 0)
            elif magic == 0xFE:
                n = 8 + buf[start + 1]
            else:
                nxt = _next_record(buf, pos + 1)
                yield (offset + pos) / size, mavlink.MAVLink_bad_data(bytearray(buf[pos:nxt][:64]), "not a tlog record")
                pos = nxt
                continue
            frame = buf[start : start + n]
            pos = start + n
            try:
                msg = parser.decode(bytearray(frame))
            except mavlink.MAVError as exc:
                msg = mavlink.MAVLink_bad_data(bytearray(frame[:64]), str(exc))
            yield (offset + pos) / size, msg


def _parser_for_decode() -> mavlink.MAVLink:
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    return p


def _next_record(buf: bytes, start: int) -> int:
    """Index of the next plausible record (8 time bytes then a frame marker) after ``start``."""
    for i in range(start, len(buf) - 8):
        if buf[i + 8] in (0xFD, 0xFE):
            return i
    return len(buf)


def iter_log(path: Path) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """(fraction read, message) for every message of a log, in order."""
    if not path.is_file():
        raise DataFileError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".ulg":
        return _ulog_messages(path)
    if suffix == ".bin":
        return _bin_messages(path)
    if suffix == ".tlog":
        return _tlog_messages(path)
    raise DataFileError(f"{path}: unknown log type {suffix!r} (expected .tlog, .bin or .ulg)")


def replay(
    path: Path, engine_cfg: EngineConfig, ingest_cfg: IngestConfig, out_csv: Path | None,
    on_output: Callable[[Output, Pipeline], None] | None = None, recorder: object | None = None,
) -> ReplayResult:
    """Run the pipeline over a log; write output sets to ``out_csv`` (solution columns)."""
    pipeline = Pipeline(engine_cfg, ingest_cfg, recorder=recorder)
    writer = SolutionWriter(out_csv) if out_csv is not None else None
    n_msg = n_out = 0
    try:
        with Progress(f"replay {path.name}", 1.0) as bar:
            for frac, msg in iter_log(path):
                n_msg += 1
                out: Output | None = pipeline.handle(msg)
                if out is not None:
                    n_out += 1
                    if writer is not None:
                        writer.write(out.row)
                    if on_output is not None:
                        on_output(out, pipeline)
                pipeline.take_events()
                if n_msg % 2000 == 0:
                    bar.update(frac)
            bar.update(1.0)
    finally:
        if writer is not None:
            writer.close()
        if recorder is not None:
            recorder.close()  # type: ignore[attr-defined]
    return ReplayResult(n_msg, n_out, pipeline)


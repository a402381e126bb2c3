"""``mavins replay``: a recorded log through the live pipeline, as fast as it goes.

Logs: MAVLink .tlog (every message as received), ArduPilot DataFlash .bin
(IMU messages) and PX4 .ulg (``sensor_combined``, interval-averaged rates).
DataFlash and ULog samples are turned into HIGHRES_IMU frames and parsed back,
so they take exactly the path a live message takes.

Bad input (docs/reliability.md, "Offline tools on bad input"): a file that
cannot be what its name says (empty, another format, no IMU message of the
chosen kind) is a :class:`DataFileError` and no output is written; a damaged
or cut log replays what it can, and :class:`LogReport` says how many bytes
were skipped, where, and whether the log ends inside a record.
"""

from __future__ import annotations

import contextlib
import io
import mmap
import struct
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from . import files
from .core.records import Solution
from .engine import EngineConfig
from .files import FOUND, DataFileError, SolutionWriter, sniff
from .link.ingest import IMU_MESSAGES, IngestConfig
from .link.mavlink import mavlink
from .pipeline import Pipeline
from .progress import Progress

DF_HEAD = b"\xa3\x95"
KINDS = {".tlog": "a MAVLink telemetry log (.tlog)", ".bin": "an ArduPilot DataFlash log (.bin)",
         ".ulg": "a PX4 ULog (.ulg)"}


@dataclass
class LogReport:
    """What a reader could not use: skipped stretches, and a record cut off at the end."""

    path: Path
    size: int
    skipped: list[list] = field(default_factory=list)  # [first byte, bytes, sensor time before (s) or None]
    cut_at: int | None = None  # first byte of an incomplete last record
    notes: list[str] = field(default_factory=list)

    def skip(self, start: int, length: int) -> None:
        if length <= 0:
            return
        last = self.skipped[-1] if self.skipped else None
        if last is not None and last[0] + last[1] == start:
            last[1] += length
        else:
            self.skipped.append([start, length, None])

    @property
    def skipped_bytes(self) -> int:
        return sum(s[1] for s in self.skipped)

    @property
    def damaged(self) -> bool:
        return bool(self.skipped) or self.cut_at is not None

    def lines(self, shown: int = 3) -> list[str]:
        """Warnings for the command line (empty for an intact log)."""
        out = []
        if self.skipped:
            n = self.skipped_bytes
            where = []
            for start, length, t in self.skipped[:shown]:
                when = f", after sensor time {t:.3f} s" if t is not None else ", before the first IMU sample"
                where.append(f"byte {start} ({length} bytes{when})")
            more = f" and {len(self.skipped) - shown} more" if len(self.skipped) > shown else ""
            out.append(f"{self.path}: skipped {n} unreadable bytes ({100.0 * n / max(self.size, 1):.2g} % of the "
                       f"file) in {len(self.skipped)} place{'s' if len(self.skipped) > 1 else ''}: "
                       + ", ".join(where) + more)
        if self.cut_at is not None:
            out.append(f"{self.path}: the log ends early: its last record, from byte {self.cut_at} to the end "
                       f"({self.size - self.cut_at} bytes), is incomplete (a cut or unfinished file)")
        out += [f"{self.path}: {n}" for n in self.notes]
        return out


@dataclass
class ReplayResult:
    """Counts of a replay."""

    messages: int
    outputs: int
    pipeline: Pipeline
    report: LogReport | None = None
    t_first: float | None = None  # sensor time of the first and last accepted IMU sample
    t_last: float | None = None


# -- format checks ----------------------------------------------------------------------------


def _check_kind(path: Path, suffix: str, head: bytes) -> None:
    """Refuse a file whose first bytes say it is something else than its name says."""
    found = sniff(head)
    if found == suffix or found is None and suffix == ".tlog":
        return  # a .tlog has no magic: a damaged start is found by reading
    if found == ".tlog" and suffix != ".tlog":
        found = None  # too weak a sign to name; say what the bytes are
    what = FOUND.get(found or "", "")
    rename = f" (rename it to {found})" if found in KINDS else ""
    if what:
        raise DataFileError(f"{path}: expected {KINDS[suffix]}, found {what}{rename}")
    magic = {".bin": "bytes a3 95", ".ulg": "'ULog'"}[suffix]
    raise DataFileError(f"{path}: expected {KINDS[suffix]} starting with {magic}, found bytes {head[:8].hex(' ')}")


def open_log(path: Path) -> tuple[Iterator[tuple[float, mavlink.MAVLink_message]], LogReport]:
    """(fraction read, message) for every message of a log, and the report its reader fills in.

    Raises DataFileError at once for a missing, empty or mislabelled file.
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in KINDS:
        raise DataFileError(f"{path}: unknown log type {suffix!r} (expected .tlog, .bin or .ulg)")
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(64)
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if size == 0:
        raise DataFileError(f"{path}: the file is empty (expected {KINDS[suffix]})")
    _check_kind(path, suffix, head)
    report = LogReport(path, size)
    reader = {".ulg": _ulog_messages, ".bin": _bin_messages, ".tlog": _tlog_messages}[suffix]
    return reader(path, report), report


def iter_log(path: Path) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """(fraction read, message) for every message of a log, in order."""
    return open_log(path)[0]


# -- readers ----------------------------------------------------------------------------------


def _decoder() -> mavlink.MAVLink:
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    return p


def _highres(enc: mavlink.MAVLink, dec: mavlink.MAVLink, t_us: int, acc: tuple, gyr: tuple,
             imu_id: int) -> mavlink.MAVLink_message:
    """A HIGHRES_IMU frame of one logged sample, packed and decoded as a live one would be."""
    m = enc.highres_imu_encode(t_us, float(acc[0]), float(acc[1]), float(acc[2]), float(gyr[0]), float(gyr[1]),
                               float(gyr[2]), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0b111111, imu_id)
    buf = m.pack(enc)
    enc.seq = (enc.seq + 1) % 256
    return dec.decode(bytearray(buf))


class _Stuck(Exception):
    """The ULog reader keeps reading without getting further into the file."""


class _ReadTracker:
    """A binary file that remembers its last read, to tell a log cut inside a record from a clean end.

    It also stops a reader that goes in circles: pyulog 1.x, on a damaged
    record at the end of the definitions, seeks back further than it read and
    loops forever. While reads get no further into the file than before, a
    read starting at a position already read from ``REVISITS`` times (the
    reader's only state is its position: it is in a loop), or more than
    ``STUCK_READS`` of them, raise :class:`_Stuck`. Legitimate
    resynchronisation over a damaged record reads each start position once
    or twice, at most about 140,000 reads.
    """

    REVISITS = 20
    STUCK_READS = 200_000

    def __init__(self, fh: io.BufferedReader) -> None:
        self._fh = fh
        self.header_at = 0  # where the last 3-byte read (a ULog message header) started
        self.last: tuple[int, int, int] = (0, 0, 0)  # (position, bytes asked, bytes got) of the last read
        self._furthest = 0
        self._idle = 0
        self._visits: dict[int, int] = {}

    def read(self, n: int = -1) -> bytes:
        pos = self._fh.tell()
        data = self._fh.read(n)
        if n == 3:
            self.header_at = pos
        self.last = (pos, n, len(data))
        if pos + len(data) > self._furthest:
            self._furthest = pos + len(data)
            self._idle = 0
            if self._visits:
                self._visits.clear()
        else:
            self._idle += 1
            seen = self._visits[pos] = self._visits.get(pos, 0) + 1
            if seen > self.REVISITS or self._idle > self.STUCK_READS:
                raise _Stuck(f"its reader went in circles near byte {pos} (damaged records)")
        return data

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self._fh, name)


def _ulog_messages(path: Path, report: LogReport) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    try:
        from pyulog import ULog
    except ImportError as exc:  # pragma: no cover - pyulog is a dependency
        raise DataFileError(f"{path}: reading .ulg needs pyulog ({exc})") from None
    # pyulog holds the topic in memory (about twice its bytes in the file)
    files.check_resources(f"reading {path}", memory=2.0 * report.size)
    chatter = io.StringIO()  # pyulog prints what it finds damaged to stdout; the report says it instead
    try:
        with open(path, "rb") as raw, contextlib.redirect_stdout(chatter):
            tracked = _ReadTracker(raw)
            ulog = ULog(tracked, ["sensor_combined"])  # type: ignore[arg-type]
    except MemoryError:
        raise files.ResourceError(f"{path}: not enough memory to read this ULog") from None
    except Exception as exc:  # pyulog raises plain exceptions on bad files
        raise DataFileError(f"{path}: not a readable ULog: {exc}") from None
    pos, asked, got = tracked.last
    if got < asked and (got > 0 or asked != 3):
        report.cut_at = tracked.header_at
    if getattr(ulog, "file_corruption", False):
        report.notes.append("corrupt data inside the ULog was skipped by its reader (pyulog: no byte offsets)")
    dropouts = getattr(ulog, "dropouts", [])
    if dropouts:
        ms = sum(int(getattr(d, "duration", 0)) for d in dropouts)
        report.notes.append(f"note: the PX4 logger itself lost data {len(dropouts)} times ({ms} ms in all)")
    data = [d for d in ulog.data_list if d.name == "sensor_combined"]
    if not data or len(data[0].data.get("timestamp", ())) == 0:
        cut = f" (it ends inside a record at byte {report.cut_at}: cut short?)" if report.cut_at is not None else ""
        raise DataFileError(f"{path}: expected IMU data (the sensor_combined topic), found none in the ULog{cut}")
    d = data[0].data
    names = ("timestamp", "accelerometer_m_s2[0]", "accelerometer_m_s2[1]", "accelerometer_m_s2[2]",
             "gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]")
    lacking = [k for k in names if k not in d]
    if lacking:
        raise DataFileError(f"{path}: sensor_combined lacks the field(s) {', '.join(lacking)}")
    ts, ax, ay, az, gx, gy, gz = (d[k] for k in names)
    n = len(ts)
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    dec = _decoder()

    def messages() -> Iterator[tuple[float, mavlink.MAVLink_message]]:
        for i in range(n):
            yield (i + 1) / n, _highres(enc, dec, int(ts[i]), (ax[i], ay[i], az[i]), (gx[i], gy[i], gz[i]), 0)

    return messages()


# DataFlash: format characters -> struct codes (pymavlink's DFReader table; scaling does not matter for IMU)
DF_STRUCT = {"a": "64s", "b": "b", "B": "B", "g": "e", "h": "h", "H": "H", "i": "i", "I": "I", "f": "f", "n": "4s",
             "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i", "d": "d", "M": "b", "q": "q",
             "Q": "Q"}
DF_FMT = struct.Struct("<BB4s16s64s")  # FMT: type, length, name, format, columns
DF_FMT_TYPE, DF_FMT_LEN = 128, 3 + DF_FMT.size


def _imu_layout(fmt: str, columns: str) -> tuple[struct.Struct, int, int, list[int], list[int], int | None] | None:
    """How to read an IMU record of this FMT: (unpacker, time index, time scale to us, gyro, accel, instance)."""
    if not fmt or any(c not in DF_STRUCT for c in fmt):
        return None
    cols = columns.split(",")
    if len(cols) != len(fmt):
        return None
    try:
        unpack = struct.Struct("<" + "".join(DF_STRUCT[c] for c in fmt))
    except struct.error:
        return None
    numeric = set("bBhHiIqQ")
    try:
        if "TimeUS" in cols:
            it, scale = cols.index("TimeUS"), 1
        else:
            it, scale = cols.index("TimeMS"), 1000
        gyr = [cols.index(k) for k in ("GyrX", "GyrY", "GyrZ")]
        acc = [cols.index(k) for k in ("AccX", "AccY", "AccZ")]
    except ValueError:
        return None
    if fmt[it] not in numeric or any(fmt[i] not in "fdg" for i in gyr + acc):
        return None
    inst = cols.index("I") if "I" in cols and fmt[cols.index("I")] in numeric else None
    return unpack, it, scale, gyr, acc, inst


def _bin_messages(path: Path, report: LogReport) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """IMU records of an ArduPilot DataFlash log, as HIGHRES_IMU messages.

    Records are found by their header (A3 95, type) and the length their FMT
    gives; bytes that are no record are skipped to the next header and
    reported, and a record cut off by the end of the file is reported too.
    """
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    dec = _decoder()
    size = report.size
    lengths = {DF_FMT_TYPE: DF_FMT_LEN}
    imu: dict[int, tuple] = {}
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        off = 0
        while off < size:
            if size - off < 3:  # a tail shorter than a record header
                if mm[off] == 0xA3 and (size - off == 1 or mm[off + 1] == 0x95):
                    report.cut_at = off
                else:
                    report.skip(off, size - off)
                return
            typ = mm[off + 2]
            if mm[off] == 0xA3 and mm[off + 1] == 0x95 and typ in lengths:
                ln = lengths[typ]
                if off + ln > size:
                    report.cut_at = off
                    return
                if typ == DF_FMT_TYPE:
                    new, length, name, fmt, cols = DF_FMT.unpack_from(mm, off + 3)
                    name_s = name.split(b"\0", 1)[0].decode("ascii", "replace")
                    fmt_s = fmt.split(b"\0", 1)[0].decode("ascii", "replace")
                    cols_s = cols.split(b"\0", 1)[0].decode("ascii", "replace")
                    if length < 3 or (new == DF_FMT_TYPE and length != DF_FMT_LEN):
                        report.skip(off, ln)  # a damaged FMT: its type stays unknown
                        off += ln
                        continue
                    lengths[new] = length
                    layout = _imu_layout(fmt_s, cols_s) if name_s == "IMU" else None
                    if layout is not None and layout[0].size + 3 == length:
                        imu[new] = layout
                    else:
                        imu.pop(new, None)
                elif typ in imu:
                    unpack, it, scale, gyr, acc, inst = imu[typ]
                    v = unpack.unpack_from(mm, off + 3)
                    try:
                        msg = _highres(enc, dec, int(v[it]) * scale, tuple(v[i] for i in acc),
                                       tuple(v[i] for i in gyr), int(v[inst]) if inst is not None else 0)
                    except Exception:  # a value no HIGHRES_IMU can carry (negative time, instance > 255)
                        report.skip(off, ln)
                    else:
                        yield off / size, msg
                off += ln
                continue
            nxt = mm.find(DF_HEAD, off + 1)
            nxt = size if nxt < 0 else nxt
            report.skip(off, nxt - off)
            off = nxt


def _tlog_messages(path: Path, report: LogReport) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """Records of a tlog (8-byte big-endian microsecond time + one MAVLink frame), streamed.

    Frames are split by their own length fields and decoded by pymavlink's
    ``MAVLink.decode`` (CRC checked), the decoder the live path uses; memory
    stays flat however long the log is. Bytes that are not a frame are
    reported as BAD_DATA (and in the report), and reading resumes at the next
    frame marker; a record cut off by the end of the file is reported.
    """
    parser = _decoder()
    size = max(report.size, 1)
    with open(path, "rb") as fh:
        buf = b""
        pos = 0
        offset = 0
        eof = False
        while True:
            if not eof and len(buf) - pos < 4096:
                chunk = fh.read(1 << 20)
                eof = not chunk
                buf = buf[pos:] + chunk
                offset += pos
                pos = 0
            left = len(buf) - pos
            if left == 0:
                return
            if left < 8 + 8 and eof:  # shorter than the smallest record
                report.cut_at = offset + pos
                return
            if left < 8 + 8:
                continue
            start = pos + 8
            magic = buf[start]
            if magic == 0xFD:
                n = 12 + buf[start + 1] + (13 if buf[start + 2] & 0x01 else 0)
            elif magic == 0xFE:
                n = 8 + buf[start + 1]
            else:
                nxt = _next_record(buf, pos + 1, eof)
                report.skip(offset + pos, nxt - pos)
                yield (offset + pos) / size, mavlink.MAVLink_bad_data(bytearray(buf[pos:min(nxt, pos + 64)]),
                                                                      "not a tlog record")
                pos = nxt
                continue
            if start + n > len(buf):  # only at the end of the file (4 kB are kept ahead otherwise)
                report.cut_at = offset + pos
                return
            frame = buf[start : start + n]
            rec = pos
            pos = start + n
            try:
                msg = parser.decode(bytearray(frame))
            except Exception as exc:  # MAVError (CRC, length); anything else pymavlink may raise on junk
                report.skip(offset + rec, pos - rec)
                msg = mavlink.MAVLink_bad_data(bytearray(frame[:64]), str(exc))
            yield (offset + pos) / size, msg


def _next_record(buf: bytes, start: int, eof: bool = True) -> int:
    """Index of the next plausible record (8 time bytes then a frame marker) at or after ``start``.

    Without a marker in the buffer: its end, or before eight bytes short of it
    (which may start a record whose marker has not been read yet).
    """
    hits = [i for i in (buf.find(b"\xfd", start + 8), buf.find(b"\xfe", start + 8)) if i >= 0]
    if hits:
        return min(hits) - 8
    return len(buf) if eof else max(start, len(buf) - 8)


# -- the replay ---------------------------------------------------------------------------------


def replay(
    path: Path, engine_cfg: EngineConfig, ingest_cfg: IngestConfig, out_csv: Path | None,
    on_output: Callable[[Solution, Pipeline], None] | None = None, recorder: object | None = None,
    *, rerun: Path | None = None,
) -> ReplayResult:
    """Run the pipeline over a log; write output sets to ``out_csv`` (solution columns).

    ``rerun`` records to a Rerun file (``recorder``: a recorder of the
    caller's, closed at the end). The CSV and the Rerun file are written to
    temporary files and renamed into place only when the replay succeeded.
    Raises DataFileError when the log cannot be what its name says, holds no
    usable IMU message of the chosen kind, or gives no solution row; nothing
    is written then.
    """
    path = Path(path)
    files.check_outputs({"-o": out_csv, "--rerun": rerun}, {"LOG": path})
    messages, report = open_log(path)
    pipeline: Pipeline | None = None
    n_msg = n_out = 0
    t_first: float | None = None
    with files.atomic_outputs([out_csv, rerun]) as (tmp_csv, tmp_rrd):
        writer = None
        try:
            if tmp_rrd is not None:
                from .record.recorder import Recorder

                recorder = Recorder(tmp_rrd, serve=False, app="mavins-replay", live=False)
            pipeline = Pipeline(engine_cfg, ingest_cfg, recorder=recorder)
            writer = SolutionWriter(tmp_csv) if tmp_csv is not None else None
            n_skips = 0
            with Progress(f"replay {path.name}", 1.0) as bar:
                for frac, msg in messages:
                    n_msg += 1
                    if len(report.skipped) != n_skips:  # where: the sensor time just before the damage
                        n_skips = _locate(report, n_skips, pipeline)
                    out: Solution | None = pipeline.handle(msg)
                    if out is not None:
                        n_out += 1
                        if writer is not None:
                            writer.write(out.row)
                        if on_output is not None:
                            on_output(out, pipeline)
                    if t_first is None and pipeline.last_sample is not None:
                        t_first = pipeline.last_sample.t
                    pipeline.take_events()
                    if n_msg % 2000 == 0:
                        bar.update(frac)
                _locate(report, n_skips, pipeline)  # damage after the last message
                bar.update(1.0)
        finally:
            if writer is not None:
                writer.close()
            if recorder is not None:
                recorder.close()  # type: ignore[attr-defined]
        if pipeline.ingest.accepted == 0:
            raise DataFileError(_no_imu(path, report, ingest_cfg, pipeline))
        if n_out == 0:
            raise DataFileError(_no_solution(path, engine_cfg, pipeline, t_first))
    last = pipeline.last_sample
    return ReplayResult(n_msg, n_out, pipeline, report, t_first, last.t if last is not None else None)


def _locate(report: LogReport, done: int, pipeline: Pipeline) -> int:
    """Give the skipped stretches found since entry ``done`` the sensor time of the last sample before them."""
    last = pipeline.last_sample
    for entry in report.skipped[done:]:
        entry[2] = last.t if last is not None else None
    return len(report.skipped)


def _counts(c: Counter | dict, shown: int = 5) -> str:
    items = sorted(c.items(), key=lambda kv: (-kv[1], str(kv[0])))
    text = ", ".join(f"{v} {k}" for k, v in items[:shown])
    return text + (f" and {len(items) - shown} more types" if len(items) > shown else "")


def _no_imu(path: Path, report: LogReport, cfg: IngestConfig, pipeline: Pipeline) -> str:
    """Why no IMU sample was accepted: what the log holds (read again: this is the error path only)."""
    want = "IMU messages (HIGHRES_IMU, RAW_IMU, SCALED_IMU*)" if cfg.message.upper() == "AUTO" \
        else f"{cfg.message} messages"
    if cfg.imu_id is not None:
        want += f" with id {cfg.imu_id}"
    if cfg.target_system is not None:
        want += f" from system {cfg.target_system}"
    types: Counter = Counter()
    imus: Counter = Counter()
    try:
        for _, msg in open_log(path)[0]:
            name = msg.get_type()
            if name == "BAD_DATA" or name.startswith("UNKNOWN_"):
                continue
            if name in IMU_MESSAGES:
                imu_id = getattr(msg, "id", 0) if name in ("HIGHRES_IMU", "RAW_IMU") else 0
                imus[f"{name} id {imu_id} from system {msg.get_srcSystem()}"] += 1
            else:
                types[name] += 1
    except DataFileError:
        pass
    size = f"{report.size} bytes"
    if imus:
        rejected = pipeline.ingest.rejected
        why = f" (rejected: {_counts(rejected)})" if rejected else ""
        return f"{path}: expected {want}, found only {_counts(imus, 3)}{why}"
    if types:
        return f"{path}: expected {want}, found none among {sum(types.values())} messages ({_counts(types)})"
    kind = KINDS[path.suffix.lower()]
    if path.suffix.lower() == ".bin":
        return f"{path}: expected {kind} with {want}, found no IMU record in {size}" + (
            f" ({report.skipped_bytes} bytes are no DataFlash record)" if report.skipped else "")
    return f"{path}: expected {kind}, found no valid MAVLink message in {size}"


def _no_solution(path: Path, cfg: EngineConfig, pipeline: Pipeline, t_first: float | None) -> str:
    eng = pipeline.engine
    last = pipeline.last_sample
    span = (last.t - t_first) if (last is not None and t_first is not None) else 0.0
    state = eng.state.value
    if state == "WAITING":
        why = ("no initial position: give --lat, --lon and --alt (the log has no GPS_RAW_INT or "
               "GLOBAL_POSITION_INT fix)")
    elif state == "ALIGNING":
        why = (f"the alignment (--align {cfg.align:g} s at rest) did not finish in the {span:.1f} s of IMU data"
               + (f"; it restarted {eng.counters['align_restarts']} times on motion"
                  if eng.counters.get("align_restarts") else ""))
    else:
        why = f"final state {state}"
    return f"{path}: no solution rows from {pipeline.ingest.accepted} IMU samples: {why}"

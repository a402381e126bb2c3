"""``mavins replay``: a recorded log through the live pipeline, as fast as it goes.

Logs: MAVLink .tlog (every message as received), ArduPilot DataFlash .bin
(``IMU``, ``GPS``/``GPA``, ``BARO``, ``MAG``) and PX4 .ulg (``sensor_combined``
with interval-averaged rates; ``vehicle_gps_position`` or ``sensor_gps``;
``vehicle_air_data`` or ``sensor_baro``; ``vehicle_magnetometer`` or
``sensor_mag``). DataFlash and ULog rows are turned into the MAVLink messages a
live autopilot would send (HIGHRES_IMU with its magnetometer fields,
GPS_RAW_INT, SCALED_PRESSURE), stamped on the log's own (IMU) clock, packed and
parsed back, so they take exactly the path a live message takes and the
pipeline's GNSS/baro/magnetometer handling aids the solution (docs/real-data.md
"Aided replay"). A tlog carries these messages already.

Bad input (docs/reliability.md, "Offline tools on bad input"): a file that
cannot be what its name says (empty, another format, no IMU message of the
chosen kind) is a :class:`DataFileError` and no output is written; a damaged
or cut log replays what it can, and :class:`LogReport` says how many bytes
were skipped, where, and whether the log ends inside a record.
"""

from __future__ import annotations

import contextlib
import io
import math
import mmap
import struct
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from .common import files
from .core import magmodel
from .core.gpstime import unix_of_gps
from .core.records import Solution
from .live.engine import EngineConfig
from .common.files import FOUND, DataFileError, SolutionWriter, sniff
from .common.fleet import Outcome, batch_outputs, write_summary
from .live.imuset import DISCOVERY_S
from .link.ingest import HIGHRES_ACC_GYRO, HIGHRES_MAG, IMU_MESSAGES, IngestConfig
from .link import publish
from .link.decode import decode_one
from .link.mavlink import mavlink
from .live.pipeline import GNSS_MESSAGES, UINT16_UNKNOWN, Pipeline
from .live.smoothing import KeptRows
from .common.progress import Progress

DF_HEAD = b"\xa3\x95"
AIDING_MESSAGES = (*GNSS_MESSAGES, "SCALED_PRESSURE")
NO_GNSS = ("note: no GNSS message in the log (GPS_RAW_INT, GPS_INPUT, HIL_GPS; PX4 vehicle_gps_position/"
           "sensor_gps, ArduPilot GPS): the position is free inertial")
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
    rejected: Counter = field(default_factory=Counter)  # aiding records no MAVLink message can carry, by kind

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
        if self.rejected:
            out.append(f"{self.path}: left out {_counts(self.rejected)} record(s) whose values no MAVLink "
                       "message can carry (out of range or not finite)")
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
    aiding: Counter = field(default_factory=Counter)  # GNSS and baro messages fed to the pipeline, by type
    smoothed: tuple[int, int] | None = None  # --smooth: the smoother's epochs and those whose prior was singular


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


def _frame(enc: mavlink.MAVLink, dec: mavlink.MAVLink, m: mavlink.MAVLink_message) -> mavlink.MAVLink_message:
    """A message packed and decoded as a live one would be (raises on values its fields cannot hold)."""
    buf = m.pack(enc)
    enc.seq = (enc.seq + 1) % 256
    return dec.decode(bytearray(buf))


def _highres(enc: mavlink.MAVLink, dec: mavlink.MAVLink, t_us: int, acc: tuple, gyr: tuple,
             imu_id: int, mag: tuple | None = None) -> mavlink.MAVLink_message:
    """A HIGHRES_IMU frame of one logged sample (m/s^2, rad/s, FRD; ``mag`` in gauss, FRD, or None)."""
    fields = HIGHRES_ACC_GYRO | (HIGHRES_MAG if mag is not None else 0)
    mx, my, mz = (float(v) for v in mag) if mag is not None else (0.0, 0.0, 0.0)
    m = enc.highres_imu_encode(t_us, float(acc[0]), float(acc[1]), float(acc[2]), float(gyr[0]), float(gyr[1]),
                               float(gyr[2]), mx, my, mz, 0.0, 0.0, 0.0, 0.0, fields, imu_id)
    return _frame(enc, dec, m)


# -- aiding records as MAVLink messages ---------------------------------------------------------

PACK_ERRORS = (ValueError, OverflowError, TypeError, struct.error)  # a value a message field cannot hold


def _int(v: float, lo: int, hi: int, unknown: int | None = None) -> int:
    """A finite value rounded to an integer field's range; ``unknown`` (or an error) for NaN and values outside."""
    x = float(v)
    if math.isfinite(x) and lo <= round(x) <= hi:
        return round(x)
    if unknown is None:
        raise ValueError(f"{v!r} outside [{lo}, {hi}]")
    return unknown


def gps_raw_int(enc: mavlink.MAVLink, dec: mavlink.MAVLink, t_us: int, fix_type: int, lat_deg: float,
                lon_deg: float, alt_msl_m: float, alt_ellipsoid_m: float | None, h_acc_m: float, v_acc_m: float,
                vel_m_s: float, cog_deg: float, vel_acc_m_s: float, hdop: float, vdop: float,
                satellites: int) -> mavlink.MAVLink_message:
    """A GPS_RAW_INT of one logged fix, stamped ``t_us`` on the log's IMU clock.

    Field units (MAVLink common.xml GPS_RAW_INT): lat/lon degE7, alt and
    alt_ellipsoid mm, eph/epv HDOP/VDOP x 100, vel cm/s, cog cdeg, h_acc/v_acc
    mm, vel_acc mm/s. Accuracies unknown (NaN, 0) are sent as 0, which the
    pipeline reads as "not given" (its default 1-sigma). Raises ValueError for
    a position or time no field can hold.
    """
    big = 2**32 - 1
    m = enc.gps_raw_int_encode(
        _int(t_us, 0, 2**64 - 1), _int(fix_type, 0, 255),
        _int(lat_deg * 1e7, -2**31, 2**31 - 1), _int(lon_deg * 1e7, -2**31, 2**31 - 1),
        _int(alt_msl_m * 1e3, -2**31, 2**31 - 1),
        _int(hdop * 100.0, 0, UINT16_UNKNOWN, UINT16_UNKNOWN), _int(vdop * 100.0, 0, UINT16_UNKNOWN, UINT16_UNKNOWN),
        _int(vel_m_s * 100.0, 0, UINT16_UNKNOWN - 1, UINT16_UNKNOWN),
        _int((cog_deg % 360.0) * 100.0, 0, 35999, UINT16_UNKNOWN) if math.isfinite(cog_deg) else UINT16_UNKNOWN,
        _int(satellites, 0, 255, 255),
        _int(alt_ellipsoid_m * 1e3, -2**31, 2**31 - 1, 0) if alt_ellipsoid_m is not None else 0,
        _int(h_acc_m * 1e3, 0, big, 0), _int(v_acc_m * 1e3, 0, big, 0), _int(vel_acc_m_s * 1e3, 0, big, 0),
    )
    return _frame(enc, dec, m)


def scaled_pressure(enc: mavlink.MAVLink, dec: mavlink.MAVLink, t_us: int, pressure_pa: float,
                    temperature_c: float) -> mavlink.MAVLink_message:
    """A SCALED_PRESSURE of one logged static pressure (Pa), stamped ``t_us`` on the IMU clock.

    MAVLink common.xml SCALED_PRESSURE: time_boot_ms ms, press_abs hPa (= Pa / 100), temperature cdegC.
    Raises ValueError for a pressure that is not finite and positive.
    """
    p = float(pressure_pa)
    if not (math.isfinite(p) and p > 0.0):
        raise ValueError(f"pressure {pressure_pa!r} Pa")
    temp = _int(temperature_c * 100.0, -32768, 32767, 0)
    # time_boot_ms is uint32 ms: a clock past 49.7 days (a UNIX-time SITL clock) is sent modulo 2^32, as an
    # autopilot sends it; the pipeline restores the high part from the IMU's uint64 time (Pipeline._unwrap_ms)
    m = enc.scaled_pressure_encode(_int(t_us, 0, 2**64 - 1) // 1000 % 2**32, p / 100.0, 0.0, temp)
    return _frame(enc, dec, m)


def system_time(enc: mavlink.MAVLink, dec: mavlink.MAVLink, t_us: int, unix_us: int) -> mavlink.MAVLink_message:
    """A SYSTEM_TIME of the UTC time ``unix_us`` (us since the UNIX epoch, from the log's GPS) at
    ``t_us`` on the IMU clock (MAVLink common.xml SYSTEM_TIME: time_unix_usec, time_boot_ms uint32 ms)."""
    return _frame(enc, dec, publish.system_time(enc, _int(unix_us, 1, 2**64 - 1), _int(t_us, 0, 2**64 - 1) * 1e-6))


def _col(d: dict, name: str, i: int, default: float = math.nan) -> float:
    """Row ``i`` of a ULog field as a float, or ``default`` when the log's message version lacks it."""
    return float(d[name][i]) if name in d else default


def ulog_gps(enc: mavlink.MAVLink, dec: mavlink.MAVLink, d: dict, i: int) -> mavlink.MAVLink_message:
    """GPS_RAW_INT of row ``i`` of PX4's ``vehicle_gps_position`` / ``sensor_gps`` (``d``: field -> array).

    Field names and units (PX4 msg/vehicle_gps_position.msg, sensor_gps.msg):
    up to v1.13 ``lat``/``lon`` int32 1e-7 deg, ``alt``/``alt_ellipsoid`` int32
    mm; from v1.14 ``latitude_deg``/``longitude_deg`` float64 deg and
    ``altitude_msl_m``/``altitude_ellipsoid_m`` float64 m. ``eph``/``epv``
    (m, 1-sigma position accuracy), ``s_variance_m_s`` (m/s, speed accuracy),
    ``vel_m_s`` (m/s), ``cog_rad`` (rad), ``fix_type`` (GPS_FIX_TYPE numbers),
    ``timestamp`` (us, the IMU's boot clock). The mapping to GPS_RAW_INT is the
    one PX4's own MAVLink module uses for its GPS_RAW_INT stream: h_acc = eph,
    v_acc = epv, vel_acc = s_variance_m_s, the eph/epv fields = HDOP/VDOP x 100.
    """
    if "latitude_deg" in d:
        lat, lon = _col(d, "latitude_deg", i), _col(d, "longitude_deg", i)
        alt, alt_e = _col(d, "altitude_msl_m", i), _col(d, "altitude_ellipsoid_m", i)
    else:
        lat, lon = _col(d, "lat", i) * 1e-7, _col(d, "lon", i) * 1e-7  # int32 1e-7 deg
        alt, alt_e = _col(d, "alt", i) * 1e-3, _col(d, "alt_ellipsoid", i, 0.0) * 1e-3  # int32 mm
    return gps_raw_int(enc, dec, int(d["timestamp"][i]), int(_col(d, "fix_type", i, 0.0)), lat, lon, alt,
                       alt_e if alt_e else None, _col(d, "eph", i), _col(d, "epv", i), _col(d, "vel_m_s", i),
                       math.degrees(_col(d, "cog_rad", i)), _col(d, "s_variance_m_s", i), _col(d, "hdop", i),
                       _col(d, "vdop", i), int(_col(d, "satellites_used", i, 255.0)))


PA_PER_HPA = 100.0
HPA_MAX = 2000.0  # a static pressure below this is in hPa (mbar): 2000 Pa is about 27 km up (ICAO Doc 7488)


def ulog_baro(enc: mavlink.MAVLink, dec: mavlink.MAVLink, topic: str, d: dict, i: int) -> mavlink.MAVLink_message:
    """SCALED_PRESSURE of row ``i`` of PX4's ``vehicle_air_data`` or ``sensor_baro``.

    PX4 msg/vehicle_air_data.msg: ``baro_pressure_pa`` (Pa), ``baro_temp_celcius``
    (degC), ``timestamp_sample`` (us, when the sensor sampled). msg/sensor_baro.msg:
    ``pressure`` in millibar (hPa) up to v1.12 and in Pa from v1.13, told apart
    by its size (HPA_MAX); ``temperature`` (degC).
    """
    t = int(d["timestamp_sample"][i]) if "timestamp_sample" in d else int(d["timestamp"][i])
    if topic == "vehicle_air_data":
        return scaled_pressure(enc, dec, t, _col(d, "baro_pressure_pa", i), _col(d, "baro_temp_celcius", i))
    p = _col(d, "pressure", i)
    return scaled_pressure(enc, dec, t, p * PA_PER_HPA if p < HPA_MAX else p, _col(d, "temperature", i))


ULOG_GPS = ("vehicle_gps_position", "sensor_gps")
ULOG_BARO = ("vehicle_air_data", "sensor_baro")
ULOG_MAG = {"vehicle_magnetometer": ("magnetometer_ga[0]", "magnetometer_ga[1]", "magnetometer_ga[2]"),
            "sensor_mag": ("x", "y", "z")}  # gauss, body FRD (PX4 msg/vehicle_magnetometer.msg, sensor_mag.msg)


def _ulog_topic(ulog: object, names: tuple[str, ...] | dict, fields: tuple[str, ...] = ()) -> tuple[str, dict] | None:
    """The first of ``names`` the log holds with data (instance 0) and the ``fields``, as (name, field -> array)."""
    for name in names:
        for d in ulog.data_list:  # type: ignore[attr-defined]
            if d.name == name and d.multi_id == 0 and len(d.data.get("timestamp", ())) > 0 \
                    and all(f in d.data for f in fields):
                return name, d.data
    return None


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
            ulog = ULog(tracked, ["sensor_combined", *ULOG_GPS, *ULOG_BARO, *ULOG_MAG])  # type: ignore[arg-type]
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
    gps = _ulog_topic(ulog, ULOG_GPS, ("timestamp", "fix_type"))
    baro = _ulog_topic(ulog, ULOG_BARO)
    mag = _ulog_topic(ulog, ULOG_MAG)
    if mag is not None and not all(k in mag[1] for k in ULOG_MAG[mag[0]]):
        mag = None
    # aiding rows in the order their topics were published (``timestamp``, us): (time, 0 = GPS / 1 = baro, row)
    events = [(int(t), 0, j) for j, t in enumerate(gps[1]["timestamp"])] if gps is not None else []
    events += [(int(t), 1, j) for j, t in enumerate(baro[1]["timestamp"])] if baro is not None else []
    events.sort()
    mag_t = mag[1]["timestamp"] if mag is not None else ()
    mag_xyz = tuple(mag[1][k] for k in ULOG_MAG[mag[0]]) if mag is not None else ()

    # the UTC date (for the magnetic model): the first fix with a UTC time (PX4 ``time_utc_usec``, us)
    utc = gps[1].get("time_utc_usec") if gps is not None else None
    dated = next((j for j in range(len(utc)) if magmodel.plausible_unix(float(utc[j]) * 1e-6)), None) \
        if utc is not None else None

    def aiding(k: int, j: int) -> mavlink.MAVLink_message:
        if k == 0:
            return ulog_gps(enc, dec, gps[1], j)  # type: ignore[index]
        return ulog_baro(enc, dec, baro[0], baro[1], j)  # type: ignore[index]

    def messages() -> Iterator[tuple[float, mavlink.MAVLink_message]]:
        e = m = 0
        held: tuple | None = None  # the latest magnetometer sample (gauss), carried by every later IMU frame
        for i in range(n):
            t = int(ts[i])
            while e < len(events) and events[e][0] <= t:  # what was published before this IMU sample
                _, k, j = events[e]
                e += 1
                try:
                    msg = aiding(k, j)
                except PACK_ERRORS:  # a value no field can hold (NaN position, negative time, ...)
                    report.rejected[(gps if k == 0 else baro)[0]] += 1  # type: ignore[index]
                else:
                    if k == 0 and j == dated:
                        yield i / n, system_time(enc, dec, int(gps[1]["timestamp"][j]), int(utc[j]))  # type: ignore[index]
                    yield i / n, msg
            while m < len(mag_t) and int(mag_t[m]) <= t:
                held = (mag_xyz[0][m], mag_xyz[1][m], mag_xyz[2][m])
                m += 1
            if held is not None and not all(math.isfinite(float(v)) for v in held):
                report.rejected[mag[0]] += 1  # type: ignore[index]
                held = None
            yield (i + 1) / n, _highres(enc, dec, t, (ax[i], ay[i], az[i]), (gx[i], gy[i], gz[i]), 0, held)

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


DF_AIDING = {"GPS": ("Status", "Lat", "Lng", "Alt"), "GPA": ("HAcc", "VAcc"), "BARO": ("Press",),
             "MAG": ("MagX", "MagY", "MagZ")}  # the columns each aiding record needs (ArduPilot LogStructure.h)
DF_HUNDREDTHS = "cCeE"  # format characters stored as value * 100 (AP_Logger/LogStructure.h)


def _aiding_layout(name: str, fmt: str, columns: str) -> tuple[struct.Struct, dict[str, int], int] | None:
    """How to read a GPS/GPA/BARO/MAG record of this FMT: (unpacker, column -> index, time scale to us)."""
    if not fmt or any(c not in DF_STRUCT for c in fmt):
        return None
    cols = columns.split(",")
    if len(cols) != len(fmt) or any(k not in cols for k in DF_AIDING[name]):
        return None
    try:
        unpack = struct.Struct("<" + "".join(DF_STRUCT[c] for c in fmt))
    except struct.error:
        return None
    if "TimeUS" in cols:
        scale = 1
    elif "TimeMS" in cols:
        scale = 1000
    else:
        return None
    index = {k: i for i, k in enumerate(cols)}
    index["_time"] = index["TimeUS" if scale == 1 else "TimeMS"]
    if any(fmt[i] in "aNnZ" for k, i in index.items() if k in (*DF_AIDING[name], "_time", "I")):
        return None
    return unpack, index, scale


def _df_value(v: tuple, fmt: str, index: dict[str, int], name: str, default: float = math.nan) -> float:
    """Column ``name`` of an unpacked record in the unit of its scaled format character
    (``c C e E``: the log stores value * 100; LogStructure.h), or ``default`` if absent."""
    if name not in index:
        return default
    i = index[name]
    return float(v[i]) / 100.0 if fmt[i] in DF_HUNDREDTHS else float(v[i])


def df_gps(enc: mavlink.MAVLink, dec: mavlink.MAVLink, t_us: int, gps: dict[str, float],
           gpa: dict[str, float] | None) -> mavlink.MAVLink_message:
    """GPS_RAW_INT of an ArduPilot ``GPS`` record (and its ``GPA``, if logged), values already in the
    units of the format characters: Status (AP_GPS::GPS_Status, the numbering of MAVLink
    GPS_FIX_TYPE), Lat/Lng (1e-7 deg, format L), Alt (m AMSL, format e), Spd (m/s), GCrs (deg),
    HDop; GPA HAcc/VAcc (m, format C), SAcc (m/s), VDop. The GPS record has no ellipsoidal height:
    the pipeline adds its geoid height (``--geoid-height``, default 0) to the AMSL altitude."""
    acc = gpa or {}
    return gps_raw_int(enc, dec, t_us, int(gps["Status"]), gps["Lat"] * 1e-7, gps["Lng"] * 1e-7, gps["Alt"], None,
                       acc.get("HAcc", math.nan), acc.get("VAcc", math.nan), gps.get("Spd", math.nan),
                       gps.get("GCrs", math.nan), acc.get("SAcc", math.nan), gps.get("HDop", math.nan),
                       acc.get("VDop", math.nan), int(gps.get("NSats", 255)))


def _bin_messages(path: Path, report: LogReport) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """IMU, GPS (with GPA), BARO and MAG records of an ArduPilot DataFlash log, as HIGHRES_IMU (with the
    latest magnetometer sample), GPS_RAW_INT and SCALED_PRESSURE messages; instance 0 of GPS, BARO
    and MAG, every IMU instance (the ingest selects one).

    Records are found by their header (A3 95, type) and the length their FMT
    gives; bytes that are no record are skipped to the next header and
    reported, and a record cut off by the end of the file is reported too.
    A GPS record waits for the GPA record ArduPilot writes after it (same time)
    for its accuracies, and goes out at the next IMU record at the latest.
    """
    enc = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
    dec = _decoder()
    size = report.size
    lengths = {DF_FMT_TYPE: DF_FMT_LEN}
    imu: dict[int, tuple] = {}
    aid: dict[int, tuple[str, str, struct.Struct, dict[str, int], int]] = {}
    pending: tuple[int, int, dict[str, float]] | None = None  # a GPS record waiting for its GPA: (time us, offset, values)
    held: tuple[float, float, float] | None = None  # the latest magnetometer sample (gauss)
    dated = False  # a SYSTEM_TIME was sent

    def gps_out(gpa: dict[str, float] | None) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
        nonlocal pending
        if pending is None:
            return
        t_us, at, values = pending
        pending = None
        try:
            msg = df_gps(enc, dec, t_us, values, gpa)
        except PACK_ERRORS:  # a value no GPS_RAW_INT field can hold
            report.rejected["GPS"] += 1
        else:
            yield at / size, msg

    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        off = 0
        while off < size:
            if size - off < 3:  # a tail shorter than a record header
                if mm[off] == 0xA3 and (size - off == 1 or mm[off + 1] == 0x95):
                    report.cut_at = off
                else:
                    report.skip(off, size - off)
                break
            typ = mm[off + 2]
            if mm[off] == 0xA3 and mm[off + 1] == 0x95 and typ in lengths:
                ln = lengths[typ]
                if off + ln > size:
                    report.cut_at = off
                    break
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
                    alayout = _aiding_layout(name_s, fmt_s, cols_s) if name_s in DF_AIDING else None
                    if alayout is not None and alayout[0].size + 3 == length:
                        aid[new] = (name_s, fmt_s, *alayout)
                    else:
                        aid.pop(new, None)
                elif typ in imu:
                    yield from gps_out(None)
                    unpack, it, scale, gyr, acc, inst = imu[typ]
                    v = unpack.unpack_from(mm, off + 3)
                    try:
                        msg = _highres(enc, dec, int(v[it]) * scale, tuple(v[i] for i in acc),
                                       tuple(v[i] for i in gyr), int(v[inst]) if inst is not None else 0, held)
                    except Exception:  # a value no HIGHRES_IMU can carry (negative time, instance > 255)
                        report.skip(off, ln)
                    else:
                        yield off / size, msg
                elif typ in aid:
                    name_s, fmt_s, unpack, index, scale = aid[typ]
                    v = unpack.unpack_from(mm, off + 3)
                    if int(_df_value(v, fmt_s, index, "I", 0.0)) == 0:
                        t_us = int(v[index["_time"]]) * scale
                        values = {k: _df_value(v, fmt_s, index, k) for k in index if k not in ("_time", "I")}
                        if name_s == "GPS":
                            yield from gps_out(None)
                            pending = (t_us, off, values)
                            if not dated:  # the UTC date for the magnetic model, from the first dated fix
                                unix = unix_of_gps(values.get("GWk", math.nan), values.get("GMS", math.nan))
                                if magmodel.plausible_unix(unix):
                                    dated = True
                                    yield off / size, system_time(enc, dec, t_us, int(unix * 1e6))
                        elif name_s == "GPA":
                            if pending is not None and pending[0] == t_us:
                                yield from gps_out(values)
                        elif name_s == "BARO":  # Press in Pa, Temp in degC (BARO: units "P", "O")
                            try:
                                msg = scaled_pressure(enc, dec, t_us, values["Press"], values.get("Temp", math.nan))
                            except PACK_ERRORS:
                                report.rejected["BARO"] += 1
                            else:
                                yield off / size, msg
                        else:  # MAG: int16 milligauss (units "G" with multiplier "C" = 1e-3; AP_Compass LogStructure.h)
                            xyz = (values["MagX"] * 1e-3, values["MagY"] * 1e-3, values["MagZ"] * 1e-3)
                            held = xyz if any(xyz) else None
                off += ln
                continue
            nxt = mm.find(DF_HEAD, off + 1)
            nxt = size if nxt < 0 else nxt
            report.skip(off, nxt - off)
            off = nxt
        yield from gps_out(None)


def _tlog_messages(path: Path, report: LogReport) -> Iterator[tuple[float, mavlink.MAVLink_message]]:
    """Records of a tlog (8-byte big-endian microsecond time + one MAVLink frame), streamed.

    Frames are split by their own length fields and decoded as the live link decodes a
    datagram: an unsigned MAVLink 2 frame of a plain message in one step (``decode.decode_one``),
    any other by pymavlink's ``MAVLink.decode``, both CRC checked; memory
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
            msg = decode_one(frame)  # the common frame in one step, as the live link decodes a datagram
            if msg is None:
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
    """Run the pipeline over a log; write output sets to ``out_csv`` (the solution columns, and the
    filter's sigma and bias columns when it aids, as ``mavins nav``: docs/conventions.md).

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
    aiding: Counter = Counter()
    kept = KeptRows() if engine_cfg.filter.smooth and engine_cfg.filter.aiding else None
    smoothed = None
    with files.atomic_outputs([out_csv, rerun]) as (tmp_csv, tmp_rrd):
        writer = None
        try:
            if tmp_rrd is not None:
                from .record.recorder import Recorder

                recorder = Recorder(tmp_rrd, serve=False, app="mavins-replay", live=False)
            pipeline = Pipeline(engine_cfg, ingest_cfg, recorder=recorder)
            writer = SolutionWriter(tmp_csv, pipeline.columns) if tmp_csv is not None and kept is None else None
            n_skips = 0
            with Progress(f"replay {path.name}", 1.0) as bar:
                for frac, msg in messages:
                    n_msg += 1
                    if len(report.skipped) != n_skips:  # where: the sensor time just before the damage
                        n_skips = _locate(report, n_skips, pipeline)
                    name = msg.get_type()
                    if name in AIDING_MESSAGES:
                        aiding[name] += 1
                    out: Solution | None = pipeline.handle(msg)
                    if out is not None:
                        n_out += 1
                        if kept is not None:
                            kept.add(pipeline.engine.filter.output_row(out.row), pipeline.engine.filter.epochs)
                        elif writer is not None:
                            writer.write(pipeline.file_row(out))
                        if on_output is not None:
                            on_output(out, pipeline)
                    if t_first is None and pipeline.last_sample is not None:
                        t_first = pipeline.last_sample.t
                    pipeline.take_events()
                    if n_msg % 2000 == 0:
                        bar.update(frac)
                _locate(report, n_skips, pipeline)  # damage after the last message
                if not any(aiding[k] for k in GNSS_MESSAGES):
                    report.notes.append(NO_GNSS)
                bar.update(1.0)
            if kept is not None and n_out:
                smoothed = _write_smoothed(kept, pipeline, tmp_csv, recorder)
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
    return ReplayResult(n_msg, n_out, pipeline, report, t_first, last.t if last is not None else None, aiding,
                        smoothed)


def _write_smoothed(kept: KeptRows, pipeline: Pipeline, tmp_csv: Path | None,
                    recorder: object | None) -> tuple[int, int]:
    """--smooth: the kept rows smoothed (live/smoothing.py), recorded beside the forward solution and
    written in the solution file's columns; returns the epochs and those whose prior was singular."""
    from .core import aided

    f = pipeline.engine.filter
    rows, singular = kept.smooth(f.epochs)
    origin = pipeline.engine.origin
    if recorder is not None and origin is not None:
        recorder.on_smoothed(rows, origin)  # type: ignore[attr-defined]
    if tmp_csv is not None:
        rows *= aided.unit_factors(aided.ROW_COLUMNS)  # in place: file-backed
        files.write_table(tmp_csv, pipeline.columns, rows, aided.file_columns(f.spec, f.settings.sigma_mag_bias))
    return (f.epochs.count if f.epochs is not None else 0), singular


def replay_outcome(job: tuple[Path, Path, EngineConfig, IngestConfig]) -> Outcome:
    """One log of ``mavins replay --each``: replayed into its solution file (:func:`replay`), summed up as a
    row of summary.csv (common/fleet.py); a log that cannot be read or gives no solution has its one-line
    error there and no file, and so has one that breaks the reader in a way nobody foresaw (its exception's
    type and text), so that the batch goes on. ``worst_ratio`` is the largest test ratio published."""
    log, out, engine_cfg, ingest_cfg = job
    outcome = Outcome(str(log), str(out))
    seen: dict[str, object] = {"worst": math.nan, "sigma": None}

    def watch(sol: Solution, _pipeline: Pipeline) -> None:
        unc = sol.unc
        if unc is None:
            return
        seen["sigma"] = tuple(float(x) for x in unc.sigma_pos)
        for r in (unc.pos_ratio, unc.vel_ratio, unc.hgt_ratio, unc.mag_ratio):
            if math.isfinite(r) and not r <= seen["worst"]:  # type: ignore[operator]
                seen["worst"] = float(r)

    try:
        res = replay(log, engine_cfg, ingest_cfg, out, on_output=watch)
    except (files.DataFileError, files.ResourceError, ValueError, OSError) as exc:
        outcome.error = str(exc)
        return outcome
    except Exception as exc:  # noqa: BLE001 - reported in the log's row, the other logs go on
        outcome.error = f"{log}: {type(exc).__name__}: {exc}"
        return outcome
    eng = res.pipeline.engine
    c = eng.filter.counters
    outcome.duration_s = (res.t_last - res.t_first) if res.t_first is not None and res.t_last is not None \
        else math.nan
    outcome.samples = res.pipeline.ingest.accepted
    outcome.solution_rows = res.outputs
    outcome.gnss_accepted = c["gnss_pos_accepted"] + c["gnss_vel_accepted"]
    outcome.gnss_rejected = c["gnss_pos_rejected"] + c["gnss_vel_rejected"]
    outcome.worst_ratio = float(seen["worst"])  # type: ignore[arg-type]
    if seen["sigma"] is not None:
        outcome.sigma = seen["sigma"]  # type: ignore[assignment]
    outcome.state = eng.state.value
    return outcome


def replay_each(logs: list[Path], out_dir: Path, engine_cfg: EngineConfig, ingest_cfg: IngestConfig,
                jobs: int | None = None, cluster: str | None = None) -> tuple[list[Outcome], Path]:
    """``mavins replay --each LOG... -o DIR``: each log on its own into ``DIR/.../<name>.nav.csv``
    (common/fleet.batch_outputs), on ``jobs`` local processes or the Dask cluster at ``cluster``; then
    ``DIR/summary.csv``, one row per log in the order given. Returns the outcomes and the summary's path."""
    from .common.parallel import run_jobs

    outs = batch_outputs(logs, out_dir)
    for log, out in zip(logs, outs):
        files.check_outputs({"-o": out}, {"LOG": log})
    items = [(log, out, engine_cfg, ingest_cfg) for log, out in zip(logs, outs)]
    outcomes = run_jobs(replay_outcome, items, jobs=min(jobs or len(items), len(items)), cluster=cluster,
                        label="mavins replay --each")
    return outcomes, write_summary(out_dir, outcomes)


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
    if cfg.imus:
        want += f" of IMU {', '.join(map(str, cfg.imus))} (--imus)"
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
        rejected = Counter(pipeline.ingest.rejected)
        missing: list[int] = []
        chosen = pipeline.imuset
        if chosen is not None:
            if not chosen.fixed and chosen.first_t is not None:
                return (f"{path}: expected {want}, found only {_counts(imus, 3)} within the first {DISCOVERY_S:g} s "
                        "of sensor time, where --imus all looks for the streams before it fuses them")
            if chosen.counters["other_imu"]:
                rejected["other_imu"] += chosen.counters["other_imu"]
            seen = {k for _, k in chosen.ingests}
            missing = [k for k in chosen.order if k not in seen] if chosen.fixed else []
        why = f" (rejected: {_counts(rejected)})" if rejected else ""
        if missing:  # a set is fused once each of its IMUs has sent a sample
            why += f"; no sample of IMU {', '.join(map(str, missing))}, and the set is fused once each has sent one"
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

"""The contract's files: IMU CSVs, initial-state JSON, solution/truth CSVs.

Every reading error is a :class:`DataFileError` whose message names the file,
the line and the column, so the command line can print one clear line.
Floats are written with round-trip precision (docs/conventions.md "Files").

Every offline writer goes through :func:`atomic_outputs`: the data goes to a
temporary file beside the target and is renamed into place only when the
whole job succeeded, so an error or Ctrl-C never leaves a partial or empty
file and never damages an existing one (docs/reliability.md, "Offline tools
on bad input"). :func:`check_outputs` refuses an output that is also an input.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import numpy as np

INCREMENT_COLUMNS = ("t", "dtheta_x", "dtheta_y", "dtheta_z", "dv_x", "dv_y", "dv_z")
RATE_COLUMNS = ("t", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
SOLUTION_COLUMNS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz")
INIT_KEYS = ("t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")


class DataFileError(ValueError):
    """A data file that cannot be used, with a message naming where and why."""


class ResourceError(ValueError):
    """A request that needs more memory or disk than the machine has (the message has the estimate)."""


# -- outputs: refuse clashes, write beside the target, rename on success -------


def _same_path(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def check_outputs(outputs: Mapping[str, Path | None], inputs: Mapping[str, Path | None]) -> None:
    """Refuse an output that is also an input, two outputs to one file, or an output that is a directory.

    Keys are the names the user knows them by (``-o``, ``--init``, ``LOG``); None values are skipped.
    """
    outs = [(k, Path(v)) for k, v in outputs.items() if v is not None]
    ins = [(k, Path(v)) for k, v in inputs.items() if v is not None]
    for i, (name, out) in enumerate(outs):
        if out.is_dir():
            raise DataFileError(f"{out}: {name} names a directory, expected a file to write")
        for in_name, inp in ins:
            if _same_path(out, inp):
                raise DataFileError(f"{out}: {name} is also the input {in_name}: writing it would destroy the "
                                    "input; choose another output file")
        for other_name, other in outs[i + 1:]:
            if _same_path(out, other):
                raise DataFileError(f"{out}: {name} and {other_name} name the same file; choose two files")


def _umask() -> int:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # no /proc: read it the portable way (and put it back)
    os.umask(mask)
    return mask


def _make_parents(directory: Path) -> list[Path]:
    """Create ``directory`` and missing parents; return those created, deepest first."""
    made: list[Path] = []
    d = directory
    while not d.exists() and d != d.parent:
        made.append(d)
        d = d.parent
    for m in reversed(made):
        m.mkdir(exist_ok=True)
    return made


@contextmanager
def atomic_outputs(targets: Sequence[Path | None], *, mode: int | None = None) -> Iterator[list[Path | None]]:
    """Temporary files beside ``targets``, renamed onto them when the block ends without an exception.

    ``with atomic_outputs([a, b]) as (ta, tb): write(ta); write(tb)``. On any
    exception (an error, Ctrl-C) the temporary files are removed, directories
    made for them too, and the targets are left as they were; on success each
    is flushed to disk and renamed into place (an existing target is replaced
    in one step, keeping its permission bits). ``mode`` sets the permission
    bits of new files (default: 0666 less the umask). None targets give None.
    OSError while creating or renaming is raised as :class:`DataFileError`.
    """
    tmps: list[Path | None] = []
    made: list[Path] = []
    reals: list[Path | None] = []
    try:
        for target in targets:
            if target is None:
                tmps.append(None)
                reals.append(None)
                continue
            real = Path(os.path.realpath(target))  # a symlink target is written through, like open(..., "w")
            try:
                made += _make_parents(real.parent)
                fd, name = tempfile.mkstemp(dir=real.parent, prefix=f".{real.name}.", suffix=f".tmp{real.suffix}")
            except OSError as exc:
                raise DataFileError(f"{target}: cannot write: {exc.strerror or exc}") from None
            os.close(fd)
            if mode is not None:
                bits = mode
            elif real.exists():
                bits = real.stat().st_mode & 0o7777
            else:
                bits = 0o666 & ~_umask()
            os.chmod(name, bits)
            tmps.append(Path(name))
            reals.append(real)
        yield tmps
        for tmp, real, target in zip(tmps, reals, targets):
            if tmp is None or real is None:
                continue
            try:
                with open(tmp, "rb") as fh:
                    os.fsync(fh.fileno())
                os.replace(tmp, real)
            except OSError as exc:
                raise DataFileError(f"{target}: cannot write: {exc.strerror or exc}") from None
    except BaseException:
        for tmp in tmps:
            if tmp is not None:
                try:
                    tmp.unlink()
                except OSError:
                    pass
        for d in made:  # deepest first; only if still empty
            try:
                d.rmdir()
            except OSError:
                pass
        raise


@contextmanager
def atomic_output(target: Path, *, mode: int | None = None) -> Iterator[Path]:
    """:func:`atomic_outputs` for one file: yields the temporary path to write."""
    with atomic_outputs([target], mode=mode) as (tmp,):
        assert tmp is not None
        yield tmp


# -- what a file is: its first bytes -----------------------------------------------------------

FOUND = {".ulg": "a PX4 ULog", ".bin": "an ArduPilot DataFlash log", ".tlog": "a MAVLink telemetry log",
         ".rrd": "a Rerun recording", ".gz": "a gzip file", ".zip": "a zip file", "text": "a text file"}


def sniff(head: bytes) -> str | None:
    """The format the first bytes of a file say (a key of FOUND), None if they say nothing."""
    if head.startswith(b"ULog\x01\x12\x35"):
        return ".ulg"
    if head.startswith(b"\xa3\x95"):
        return ".bin"
    if head.startswith(b"RRF"):
        return ".rrd"
    if head.startswith(b"\x1f\x8b"):
        return ".gz"
    if head.startswith(b"PK\x03\x04"):
        return ".zip"
    if len(head) >= 16 and head[8] in (0xFD, 0xFE):
        return ".tlog"  # a weak sign: 8 time bytes, then a MAVLink frame marker
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return None
    if text and all(c.isprintable() or c in "\r\n\t" for c in text):
        return "text"
    return None


# -- sizes: refuse what the machine cannot hold --------------------------------


def available_memory() -> int:
    """Bytes of memory available for a new allocation (MemAvailable; else physical memory)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 1 << 62  # unknown: do not refuse


def free_disk(path: Path) -> int:
    """Free bytes on the file system that holds ``path`` (or its nearest existing parent)."""
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return shutil.disk_usage(p).free
    except OSError:
        return 1 << 62


def gib(n: float) -> str:
    """Bytes as GiB (or MiB below 1 GiB) for messages."""
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**20:.0f} MiB"


def check_resources(what: str, *, memory: float = 0.0, disk: float = 0.0, disk_at: Path | None = None,
                    hint: str = "") -> None:
    """Raise :class:`ResourceError` if ``memory`` or ``disk`` bytes (estimates) exceed what is free."""
    avail = available_memory()
    if memory > avail:
        raise ResourceError(f"{what} needs about {gib(memory)} of memory, the machine has {gib(avail)} "
                            f"available{hint}")
    if disk and disk_at is not None:
        free = free_disk(disk_at)
        if disk > free:
            raise ResourceError(f"{what} needs about {gib(disk)} of disk, {disk_at} has {gib(free)} free{hint}")


@dataclass(frozen=True)
class InitialState:
    """Initial state of docs/conventions.md: time (s), lat/lon/angles (deg), h (m), NED velocity (m/s)."""

    t: float
    lat: float
    lon: float
    h: float
    vn: float
    ve: float
    vd: float
    roll: float
    pitch: float
    yaw: float

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in INIT_KEYS}


def _open_text(path: Path) -> io.TextIOBase:
    if path.suffix == ".gz":
        import gzip

        return io.TextIOWrapper(gzip.open(path, "rb"), encoding="utf-8")
    return open(path, encoding="utf-8", newline="")


def _bad_text(path: Path) -> str:
    """Message naming the first line that is not UTF-8."""
    import gzip

    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rb") as fh:
        for lineno, raw in enumerate(fh, start=1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                return f"{path}: line {lineno}: not UTF-8 text ({exc.reason} at column {exc.start + 1})"
    return f"{path}: not UTF-8 text"


CHUNK_BYTES = 32 << 20  # text read per chunk by TableReader (about 250,000 IMU rows)
WHOLE_BYTES = 512 << 20  # a CSV up to this size is parsed in one multithreaded pass


class _Refused(Exception):
    """The fast reader declines a file the line-by-line reader should handle."""


def _arrow_refused() -> tuple[type[BaseException], ...]:
    import pyarrow as pa

    return (pa.ArrowException, OSError, EOFError, UnicodeDecodeError, _Refused)


def _csv_header(path: Path) -> list[str]:
    """Column names of a CSV's first line."""
    try:
        with _open_text(path) as fh:
            header_line = fh.readline()
    except UnicodeDecodeError:
        raise DataFileError(_bad_text(path)) from None
    except (OSError, EOFError) as exc:
        raise DataFileError(f"{path}: cannot read: {exc}") from None
    return [h.strip() for h in header_line.strip().split(",")]


def _parquet_columns(path: Path) -> list[str]:
    """Column names of a parquet file's schema."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        return list(pq.ParquetFile(path).schema_arrow.names)
    except (pa.ArrowException, OSError) as exc:
        raise DataFileError(f"{path}: cannot read as parquet: {exc}") from None


def missing_field(path: Path, lineno: int, name: str, fields: int) -> str:
    """The one-line error of a row too short to hold column ``name``."""
    return f"{path}: line {lineno}: column '{name}' is missing (row has {fields} fields)"


def not_a_number(path: Path, lineno: int, name: str, cell: str) -> str:
    """The one-line error of a cell that is not a (finite) number."""
    return f"{path}: line {lineno}, column '{name}': not a number: {cell!r}"


def first_increment_error(path: Path, t_first: float, t0: float) -> DataFileError:
    """An increment file whose first row does not come after the initial state (row i covers (t[i-1], t[i]])."""
    return DataFileError(f"{path}: line 2, column 't': first increment time {float(t_first)!r} is not after "
                         f"the initial state's t = {float(t0)!r} (row i covers (t[i-1], t[i]])")


class TableReader:
    """The named columns of a CSV in chunks of rows, checked like :func:`read_table`.

    Opening checks the file and its header; :meth:`chunks` yields (n, k)
    arrays of consecutive data rows, so a file larger than memory can be
    processed in constant memory. Every error is a :class:`DataFileError`
    naming the file line (blank lines counted) and the column, exactly as
    :func:`read_table` reports it; an empty table is an error at the end.
    """

    def __init__(self, path: str | Path, columns: tuple[str, ...], *, strictly_increasing: bool = True,
                 chunk_bytes: int | None = None) -> None:
        self.path = path = Path(path)
        self.columns = columns
        self.strictly_increasing = strictly_increasing
        self.chunk_bytes = max(int(CHUNK_BYTES if chunk_bytes is None else chunk_bytes), 1)
        # up to this size a CSV is parsed whole (memory about twice the file); beyond, in blocks
        self.whole_bytes = WHOLE_BYTES if chunk_bytes is None else 4 * self.chunk_bytes
        self.rows = 0
        if not path.is_file():
            raise DataFileError(f"{path}: no such file")
        if path.stat().st_size == 0:
            raise DataFileError(f"{path}: line 1: the file is empty (expected a CSV with the header "
                                f"{','.join(columns)})")
        self.header = header = _parquet_columns(path) if path.suffix == ".parquet" else _csv_header(path)
        missing = [c for c in columns if c not in header]
        if missing:
            raise DataFileError(
                f"{path}: line 1: missing column(s) {', '.join(missing)} (header has: {', '.join(header)})"
            )
        self.usecols = [header.index(c) for c in columns]

    def estimated_rows(self) -> int:
        """Data rows, estimated from the file size and the first 64 kB (a parquet file says how many)."""
        if self.path.suffix == ".parquet":
            import pyarrow.parquet as pq

            return int(pq.ParquetFile(self.path).metadata.num_rows)
        size = self.path.stat().st_size
        if self.path.suffix == ".gz":
            size *= 4  # typical ratio of a CSV of floats
        with _open_text(self.path) as fh:
            try:
                head = fh.read(1 << 16)
            except (UnicodeDecodeError, OSError, EOFError):
                return 0
        lines = [ln for ln in head.splitlines()[1:-1] if ln.strip()]
        if not lines:
            return 1
        return int(size / (sum(len(ln) + 1 for ln in lines) / len(lines)))

    def chunks(self) -> Iterator[np.ndarray]:
        """Consecutive (n, k) arrays of data rows.

        A parquet file is read by row groups. A CSV is parsed by pyarrow's
        multithreaded reader (exact float conversion); whatever it refuses
        is handed, from the first row not yet yielded, to the line-by-line
        numpy parser, which accepts what the contract accepts and names the
        line and column of the first bad cell.
        """
        if self.path.suffix == ".parquet":
            yield from self._parquet_chunks()
            return
        last_t: float | None = None
        try:
            for data in self._arrow_chunks():
                last_t = self._check(data, self._locate(self.rows), last_t)
                self.rows += data.shape[0]
                yield data
        except _arrow_refused():
            yield from self._numpy_chunks(skip=self.rows, last_t=last_t)
            return
        if self.rows == 0:
            raise DataFileError(f"{self.path}: no data rows")

    def _arrow_chunks(self) -> Iterator[np.ndarray]:
        """Data rows as parsed by pyarrow.csv, in blocks of about ``chunk_bytes`` of text."""
        import pyarrow as pa
        from pyarrow import csv as pacsv

        if len(set(self.header)) != len(self.header):
            raise _Refused("repeated column names")
        read = pacsv.ReadOptions(column_names=self.header, skip_rows=1, block_size=min(self.chunk_bytes, 8 << 20))
        convert = pacsv.ConvertOptions(column_types={c: pa.float64() for c in self.columns},
                                       include_columns=list(self.columns), null_values=[], strings_can_be_null=False,
                                       quoted_strings_can_be_null=False)
        if self.path.suffix != ".gz" and self.path.stat().st_size <= self.whole_bytes:
            # the whole file at once: pyarrow parses its blocks on every core (4x the streaming reader)
            table = pacsv.read_csv(self.path, read_options=read, convert_options=convert)
            if table.num_rows:
                yield np.column_stack([_numpy_of(table.column(i)) for i in range(table.num_columns)])
            return
        with pa.input_stream(str(self.path), compression="detect") as stream:
            reader = pacsv.open_csv(stream, read_options=read, convert_options=convert)
            for batch in reader:
                if batch.num_rows:
                    yield np.column_stack([_numpy_of(batch.column(i)) for i in range(batch.num_columns)])

    def _parquet_chunks(self) -> Iterator[np.ndarray]:
        """Data rows of a parquet file, one array per row group (columns cast to float64)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        last_t: float | None = None
        try:
            pf = pq.ParquetFile(self.path)
            for batch in pf.iter_batches(batch_size=max(self.chunk_bytes // 64, 1), columns=list(self.columns)):
                data = np.column_stack([_numpy_of(batch.column(i).cast(pa.float64()))
                                        for i in range(batch.num_columns)])
                last_t = self._check(data, lambda i, r0=self.rows: r0 + i + 1, last_t, unit="row")
                self.rows += data.shape[0]
                yield data
        except (pa.ArrowException, OSError, ValueError) as exc:
            if isinstance(exc, DataFileError):
                raise
            raise DataFileError(f"{self.path}: cannot read as parquet: {exc}") from None
        if self.rows == 0:
            raise DataFileError(f"{self.path}: no data rows")

    def _locate(self, row0: int) -> Callable[[int], int]:
        """File line of data row ``row0 + i`` (blank lines counted), found by reading the file again."""

        def line_of(i: int) -> int:
            seen = -1
            with _open_text(self.path) as fh:
                fh.readline()
                for k, line in enumerate(fh, start=2):
                    if line.strip():
                        seen += 1
                        if seen == row0 + i:
                            return k
            return row0 + i + 2

        return line_of

    def _numpy_chunks(self, skip: int, last_t: float | None) -> Iterator[np.ndarray]:
        """The line-by-line parser, starting after ``skip`` data rows (blank lines not counted)."""
        if skip == 0 and self.path.suffix != ".gz":
            try:
                size = self.path.stat().st_size
            except OSError as exc:
                raise DataFileError(f"{self.path}: cannot read: {exc.strerror or exc}") from None
            if size <= 4 * self.chunk_bytes:
                yield self._whole()
                return
        path = self.path
        line0 = 2  # file line of the first line in the chunk
        try:
            fh = _open_text(path)
        except OSError as exc:
            raise DataFileError(f"{path}: cannot read: {exc}") from None
        with fh:
            try:
                fh.readline()
                while skip:
                    line = fh.readline()
                    if not line:
                        break
                    line0 += 1
                    skip -= bool(line.strip())
                while True:
                    lines = fh.readlines(self.chunk_bytes)
                    if not lines:
                        break
                    data = self._parse(lines, line0)
                    if data.shape[0]:
                        last_t = self._check(data, lambda i, ls=lines, l0=line0: self._line_of(ls, l0, i), last_t)
                        self.rows += data.shape[0]
                        yield data
                    line0 += len(lines)
            except UnicodeDecodeError:
                raise DataFileError(_bad_text(path)) from None
            except (OSError, EOFError) as exc:  # EOFError: a cut .gz
                raise DataFileError(f"{path}: cannot read: {exc}") from None
        if self.rows == 0:
            raise DataFileError(f"{path}: no data rows")

    def _whole(self) -> np.ndarray:
        """The whole file in one array (numpy reads the file itself); lines are read only to locate an error."""
        path = self.path

        def lines() -> list[str]:
            with _open_text(path) as fh:
                fh.readline()
                return fh.readlines()

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
                data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=self.usecols, ndmin=2, dtype=np.float64,
                                  encoding="utf-8")
        except UnicodeDecodeError:
            raise DataFileError(_bad_text(path)) from None
        except (ValueError, IndexError):
            raise DataFileError(self._bad_cell(lines(), 2)) from None
        except OSError as exc:
            raise DataFileError(f"{path}: cannot read: {exc}") from None
        if data.shape[0] == 0:
            raise DataFileError(f"{path}: no data rows")
        self._check(data, lambda i: self._line_of(lines(), 2, i), None)
        self.rows = data.shape[0]
        return data

    def _parse(self, lines: list[str], line0: int) -> np.ndarray:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data": counted by the caller
                return np.loadtxt(lines, delimiter=",", usecols=self.usecols, ndmin=2, dtype=np.float64)
        except (ValueError, IndexError):
            raise DataFileError(self._bad_cell(lines, line0)) from None

    def _bad_cell(self, lines: list[str], line0: int) -> str:
        """Slow second pass over the chunk that finds the first cell which is not a number."""
        idx = {name: self.header.index(name) for name in self.columns}
        for lineno, row in enumerate(csv.reader(lines), start=line0):
            if not row:
                continue
            for name, j in idx.items():
                if j >= len(row):
                    return missing_field(self.path, lineno, name, len(row))
                try:
                    float(row[j])
                except ValueError:
                    return not_a_number(self.path, lineno, name, row[j])
        return f"{self.path}: cannot parse as CSV numbers"

    @staticmethod
    def _line_of(lines: list[str], line0: int, data_row: int) -> int:
        """File line of a data row of the chunk, counting the blank lines numpy skips."""
        seen = -1
        for k, line in enumerate(lines):
            if line.strip():
                seen += 1
                if seen == data_row:
                    return line0 + k
        return line0 + data_row

    def _check(self, data: np.ndarray, line_of: Callable[[int], int], last_t: float | None, unit: str = "line") -> float:
        """Finite values and increasing time; ``line_of(i)`` locates data row i of the chunk in the file."""
        path, columns = self.path, self.columns
        bad = ~np.isfinite(data)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise DataFileError(
                f"{path}: {unit} {line_of(i)}, column '{columns[j]}': "
                f"value {float(data[i, j])!r} is not finite"
            )
        if self.strictly_increasing:
            t = data[:, 0] if last_t is None else np.concatenate(([last_t], data[:, 0]))
            nonpos = np.flatnonzero(~(np.diff(t) > 0))
            if nonpos.size:
                i = nonpos[0] + 1  # index in t
                prev = float(t[i - 1])
                if last_t is not None:
                    i -= 1  # index in data
                raise DataFileError(
                    f"{path}: {unit} {line_of(i)}, column 't': time {float(data[i, 0])!r} "
                    f"does not increase (previous row has {prev!r})"
                )
        return float(data[-1, 0])


def read_table(path: str | Path, columns: tuple[str, ...], *, strictly_increasing: bool = True) -> np.ndarray:
    """Read the named columns of a CSV (extra columns ignored) into an (n, k) array.

    Raises DataFileError for a missing file or column, a non-numeric cell, a
    NaN/Inf value, an empty table, or a time column that does not increase.
    """
    reader = TableReader(path, columns, strictly_increasing=strictly_increasing)
    parts = list(reader.chunks())
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def read_init(path: str | Path) -> InitialState:
    """Read and check the initial-state JSON (docs/conventions.md "Initial state")."""
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path}: no such file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise DataFileError(_bad_text(path)) from None
    except json.JSONDecodeError as exc:
        raise DataFileError(f"{path}: line {exc.lineno}, column {exc.colno}: invalid JSON: {exc.msg}") from None
    if not isinstance(doc, dict):
        raise DataFileError(f"{path}: expected a JSON object with keys {', '.join(INIT_KEYS)}")
    values = {}
    for key in INIT_KEYS:
        if key not in doc:
            raise DataFileError(f"{path}: key '{key}' is missing")
        v = doc[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise DataFileError(f"{path}: key '{key}': {v!r} is not a finite number")
        values[key] = float(v)
    if not -90.0 <= values["lat"] <= 90.0:
        raise DataFileError(f"{path}: key 'lat': {values['lat']} is outside [-90, 90] deg")
    return InitialState(**values)


def write_init(path: str | Path, init: InitialState) -> None:
    """Write the initial-state JSON with round-trip floats."""
    Path(path).write_text(json.dumps(init.to_dict(), indent=2) + "\n", encoding="utf-8")


def _arrow_table(columns: Sequence[str], data: np.ndarray) -> object:
    """The float64 columns of data as a pyarrow table, sharing their memory (``pa.Array.from_buffers``:
    ``pa.array`` of a numpy array imports pandas when it is installed, 0.2 s of every ``mavins nav``)."""
    import pyarrow as pa

    arrays = []
    for j in range(len(columns)):
        col = np.ascontiguousarray(data[:, j], dtype=np.float64)
        arrays.append(pa.Array.from_buffers(pa.float64(), col.shape[0], [None, pa.py_buffer(col)]))
    return pa.Table.from_arrays(arrays, names=list(columns))


def _numpy_of(column: object) -> np.ndarray:
    """A float64 pyarrow column (Array or ChunkedArray) as numpy, read from its data buffers when it
    has no nulls (pyarrow's ``to_numpy`` imports pandas when it is installed, 0.2 s); nulls go through
    ``to_numpy`` (NaN)."""
    import pyarrow as pa

    chunks = column.chunks if isinstance(column, pa.ChunkedArray) else [column]  # type: ignore[attr-defined]
    parts = []
    for ch in chunks:
        if ch.type != pa.float64() or ch.null_count:
            parts.append(ch.to_numpy(zero_copy_only=False))
        else:
            parts.append(np.frombuffer(ch.buffers()[1], dtype=np.float64, count=len(ch), offset=8 * ch.offset))
    if not parts:
        return np.empty(0)
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def format_rows(data: np.ndarray) -> str:
    """CSV body with shortest round-trip float text (pyarrow's writer: ``float(text)`` gives the value back)."""
    if data.shape[0] == 0:
        return ""
    buf = io.BytesIO()
    write_rows(buf, data)
    return buf.getvalue().decode("ascii")


def write_rows(sink: object, data: np.ndarray) -> None:
    """CSV rows (no header) of round-trip float text straight to a binary file or pyarrow sink."""
    from pyarrow import csv as pacsv

    pacsv.write_csv(_arrow_table([f"c{j}" for j in range(data.shape[1])], data), sink,
                    pacsv.WriteOptions(include_header=False, quoting_style="none"))


class TableWriter:
    """Named float columns written in chunks to a CSV (header line, round-trip floats) or,
    for a ``.parquet`` path, a parquet file (float64 columns, one row group per chunk)."""

    def __init__(self, path: str | Path, columns: Sequence[str]) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        self.rows = 0
        self._parquet = None
        self._fh = None
        if self.path.suffix == ".parquet":
            import pyarrow as pa
            import pyarrow.parquet as pq

            schema = pa.schema([(c, pa.float64()) for c in self.columns])
            self._parquet = pq.ParquetWriter(self.path, schema)
        else:
            import pyarrow as pa

            self._fh = pa.OSFile(str(self.path), "wb")  # closed by close()
            self._fh.write((",".join(self.columns) + "\n").encode("ascii"))

    def write(self, data: np.ndarray) -> None:
        """Append rows (an (n, len(columns)) array)."""
        if data.shape[0] == 0:
            return
        if self._parquet is not None:
            self._parquet.write_table(_arrow_table(self.columns, data))
        else:
            write_rows(self._fh, data)
        self.rows += data.shape[0]

    def close(self) -> None:
        if self._parquet is not None:
            self._parquet.close()
        if self._fh is not None:
            self._fh.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_table(path: str | Path, columns: tuple[str, ...], data: np.ndarray, keep: np.ndarray | None = None) -> None:
    """Write a table (CSV with a header line and round-trip floats, or parquet by the suffix); ``keep``: the
    columns of ``data`` to write (default all), picked a piece of rows at a time (``data`` may be larger
    than memory: a file-backed array)."""
    with TableWriter(path, columns) as w:
        chunk = 1 << 18
        for start in range(0, data.shape[0], chunk):
            piece = data[start : start + chunk]
            w.write(piece if keep is None else piece[:, keep])


def read_solution(path: str | Path) -> np.ndarray:
    """Read a solution or truth CSV (degrees as in the file)."""
    return read_table(path, SOLUTION_COLUMNS)


class SolutionWriter:
    """Write solution rows (kernel units) to a solution file as they come: the 14 solution columns,
    or with ``columns`` (the filter's, core.aided.ROW_COLUMNS) those, in file units
    (core.aided.unit_factors). Rows are kept ``block`` at a time and written as a table
    (:class:`TableWriter`: round-trip text, or parquet by the suffix); :meth:`flush` writes what is
    kept (the service does once a second), :meth:`close` the rest."""

    def __init__(self, path: str | Path, columns: tuple[str, ...] = SOLUTION_COLUMNS, block: int = 4096) -> None:
        from ..core.aided import unit_factors

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._table = TableWriter(self.path, columns)
        self._factors = unit_factors(columns)
        self._kept = np.empty((max(1, block), len(columns)))
        self._n = 0

    @property
    def rows(self) -> int:
        """Rows written so far, kept ones included."""
        return self._table.rows + self._n

    def write(self, row: np.ndarray) -> None:
        if row.shape[0] != self._kept.shape[1]:
            raise ValueError(f"a row of {row.shape[0]} values for {self._kept.shape[1]} columns")
        self._kept[self._n] = row
        self._n += 1
        if self._n == self._kept.shape[0]:
            self.flush()

    def flush(self) -> None:
        """Write the rows kept so far."""
        if self._n:
            self._table.write(self._kept[: self._n] * self._factors)
            self._n = 0

    def close(self) -> None:
        try:
            self.flush()
        finally:
            self._table.close()

"""mavins/common/files.py, the contract's files: exact float round trips through CSV (plain and gzip) and
parquet, the fast reader's refusals handed to the line-by-line reader with the same messages, and what the
mutation runs found unchecked (docs/testing.md).

Every file is real, written by hand in tmp_path with known text or bytes: IMU tables
(docs/conventions.md "Files": a header line, extra columns ignored, round-trip floats), the
initial-state JSON, the solution CSV. Expected values are the written doubles themselves (bit
patterns through ``float.hex``) and the one-line errors of docs/reliability.md "Offline tools on bad
input", which name the file, the line and the column ("FILE: line L, column 'C': ..."), with line
numbers counted by hand, blank lines included.
Both CSV parsers are driven on purpose: pyarrow's reader takes a well-formed file, and a repeated
column name or a ragged row hands the file to the line-by-line reader. Sizes are taken at their
boundaries (a file of exactly 4 blocks is read whole, one byte more is streamed).
"""

from __future__ import annotations

import errno
import gzip
import json
import math
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from support import ENV, MAVINS

from mavins.common import files
from mavins.common.files import DataFileError, ResourceError

COLS = files.INCREMENT_COLUMNS
HEADER = "t,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z"
AWKWARD = [0.1, 1e-300, 5e-324, -0.0, math.nextafter(1.0, 2.0), math.nextafter(0.3, 0.0), -1.7976931348623157e308]


def hexes(a: np.ndarray) -> list[list[str]]:
    return [[float(v).hex() for v in row] for row in np.atleast_2d(a)]


def rows(n: int, t0: int = 1) -> list[str]:
    """n data lines of equal length: t = (t0 + i) ms, then 1..6."""
    return [f"0.{t0 + i:03d},1,2,3,4,5,6" for i in range(n)]


def table(tmp_path: Path, lines: list[str], header: str = HEADER, name: str = "imu.csv") -> Path:
    p = tmp_path / name
    p.write_text(header + "\n" + "".join(ln + "\n" for ln in lines), encoding="utf-8")
    return p


def read(path: Path, chunk_bytes: int | None = None, **kw) -> tuple[list[np.ndarray], files.TableReader]:
    r = files.TableReader(path, COLS, chunk_bytes=chunk_bytes, **kw)
    return list(r.chunks()), r


def error(path: Path, chunk_bytes: int | None = None, columns=COLS, **kw) -> str:
    with pytest.raises(DataFileError) as err:
        list(files.TableReader(path, columns, chunk_bytes=chunk_bytes, **kw).chunks())
    return str(err.value)


def hidden(d: Path) -> list[str]:
    return sorted(p.name for p in d.rglob(".*"))


# -- check_outputs ----------------------------------------------------------------------------


def test_an_output_that_is_an_input_is_refused_by_every_name(tmp_path: Path) -> None:
    """The same file through its path, a ./ spelling, a symlink and a hard link is the input; the message names both."""
    inp = tmp_path / "imu.csv"
    inp.write_text("x\n")
    (tmp_path / "link.csv").symlink_to(inp)
    os.link(inp, tmp_path / "hard.csv")
    for out in (inp, tmp_path / "." / "imu.csv", tmp_path / "link.csv", tmp_path / "hard.csv"):
        with pytest.raises(DataFileError) as err:
            files.check_outputs({"-o": out}, {"IMU": inp})
        assert str(err.value) == (f"{out}: -o is also the input IMU: writing it would destroy the input; "
                                  "choose another output file")


def test_two_outputs_to_one_file_and_a_directory_are_refused(tmp_path: Path) -> None:
    """Adjacent and distant clashing outputs, a new file spelled twice, and a directory as output."""
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    with pytest.raises(DataFileError) as err:
        files.check_outputs({"-o": a, "--log": tmp_path / "." / "a.csv"}, {})
    assert str(err.value) == f"{a}: -o and --log name the same file; choose two files"
    with pytest.raises(DataFileError) as err:
        files.check_outputs({"-o": b, "--log": a, "--rerun": b}, {"IMU": None})
    assert str(err.value) == f"{b}: -o and --rerun name the same file; choose two files"
    with pytest.raises(DataFileError) as err:
        files.check_outputs({"-o": None, "--log": tmp_path}, {})
    assert str(err.value) == f"{tmp_path}: --log names a directory, expected a file to write"


def test_distinct_outputs_and_none_pass(tmp_path: Path) -> None:
    """Different files (one existing, one not) and None entries are accepted."""
    inp = tmp_path / "imu.csv"
    inp.write_text("x\n")
    (tmp_path / "old.csv").write_text("y\n")
    files.check_outputs({"-o": tmp_path / "old.csv"}, {"IMU": inp})
    files.check_outputs({"-o": tmp_path / "new.csv", "--log": None, "--rerun": tmp_path / "n.rrd"},
                        {"IMU": inp, "--init": None})


# -- atomic_outputs ---------------------------------------------------------------------------


def test_success_renames_into_place_with_the_right_permissions(tmp_path: Path) -> None:
    """New files get 0666 less the umask (folders made for them), an existing one keeps its bits, a symlink
    is written through, None gives None; the temporaries are hidden beside the targets and gone afterwards."""
    old = tmp_path / "old.csv"
    old.write_text("old\n")
    old.chmod(0o604)
    real = tmp_path / "real.csv"
    real.write_text("real\n")
    (tmp_path / "link.csv").symlink_to(real)
    new = tmp_path / "a" / "b" / "new.csv"
    mask = os.umask(0o027)
    try:
        with files.atomic_outputs([new, None, old, tmp_path / "link.csv"]) as tmps:
            assert tmps[1] is None
            assert [t.parent for t in (tmps[0], tmps[2], tmps[3])] == [new.parent, tmp_path, tmp_path]
            assert re.fullmatch(r"\.new\.csv\..+\.tmp\.csv", tmps[0].name)
            assert re.fullmatch(r"\.real\.csv\..+\.tmp\.csv", tmps[3].name)
            for tmp, text in zip((tmps[0], tmps[2], tmps[3]), ("new\n", "replaced\n", "through\n")):
                tmp.write_text(text)
            assert new.parent.is_dir() and not new.exists() and old.read_text() == "old\n"
    finally:
        os.umask(mask)
    assert new.read_text() == "new\n" and old.read_text() == "replaced\n" and real.read_text() == "through\n"
    assert (new.stat().st_mode & 0o7777, old.stat().st_mode & 0o7777) == (0o640, 0o604)
    assert (tmp_path / "link.csv").is_symlink()
    assert hidden(tmp_path) == []


def test_mode_sets_the_bits_of_new_and_replaced_files(tmp_path: Path) -> None:
    """mode=0o600 from the first byte, for a new file and over an existing 0644 one (atomic_output for one file)."""
    old = tmp_path / "key"
    old.write_text("k\n")
    old.chmod(0o644)
    with files.atomic_output(tmp_path / "new", mode=0o600) as tmp:
        assert tmp.stat().st_mode & 0o7777 == 0o600
        tmp.write_text("n\n")
    with files.atomic_output(old, mode=0o600) as tmp:
        tmp.write_text("k2\n")
    assert (tmp_path / "new").stat().st_mode & 0o7777 == 0o600 and old.stat().st_mode & 0o7777 == 0o600
    assert (tmp_path / "new").read_text() == "n\n" and old.read_text() == "k2\n"


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_an_error_or_interrupt_leaves_nothing_behind(tmp_path: Path, exc: type[BaseException]) -> None:
    """The temporaries and the folders made for them are removed; an existing target and folder stay as they were."""
    (tmp_path / "keep").mkdir()
    old = tmp_path / "keep" / "old.csv"
    old.write_text("old\n")
    with pytest.raises(exc):
        with files.atomic_outputs([tmp_path / "x" / "y" / "new.csv", old]) as (t1, t2):
            t1.write_text("partial")
            t2.write_text("partial")
            raise exc
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == ["keep", "keep/old.csv"]
    assert old.read_text() == "old\n"
    with pytest.raises(exc):
        with files.atomic_output(tmp_path / "one.csv") as tmp:
            tmp.write_text("partial")
            raise exc
    assert not (tmp_path / "one.csv").exists() and hidden(tmp_path) == []


def test_cannot_create_or_rename_is_one_clear_error(tmp_path: Path) -> None:
    """A target under a regular file, and a target that became a folder before the rename: "TARGET: cannot write:
    REASON", and no temporary left."""
    (tmp_path / "file").write_text("f\n")
    target = tmp_path / "file" / "out.csv"
    with pytest.raises(DataFileError) as err:
        with files.atomic_outputs([tmp_path / "ok.csv", target]):
            pass
    assert str(err.value) == f"{target}: cannot write: Not a directory"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
    later = tmp_path / "later.csv"
    with pytest.raises(DataFileError) as err:
        with files.atomic_output(later) as tmp:
            tmp.write_text("data")
            later.mkdir()
    assert str(err.value) == f"{later}: cannot write: Is a directory"
    assert hidden(tmp_path) == [] and later.is_dir()


# -- sniff, sizes -----------------------------------------------------------------------------


@pytest.mark.parametrize("head, found", [
    (b"ULog\x01\x12\x35\x01rest", ".ulg"),
    (b"ULog\x01\x12\x36\x01", None),
    (b"\xa3\x95\x80", ".bin"),
    (b"RRF2\x00", ".rrd"),
    (b"\x1f\x8b\x08", ".gz"),
    (b"PK\x03\x04\x14", ".zip"),
    (bytes(8) + b"\xfd" + bytes(7), ".tlog"),
    (bytes(8) + b"\xfe" + bytes(7), ".tlog"),
    (bytes(8) + b"\xfd" + bytes(6), None),
    (bytes(8) + b"\xfc" + bytes(7), None),
    (bytes(9) + b"\xfd" + bytes(6), None),
    (b"t,dv_x\r\n0.1,\t2\n", "text"),
    (b"", None),
    (b"t,dv\x00x", None),
    (b"\xc3\xa9t\xe9", None),
])
def test_sniff(head: bytes, found: str | None) -> None:
    """Each magic, the tlog's frame marker at byte 8 of at least 16, printable UTF-8 text (CR, LF, tab allowed)."""
    assert files.sniff(head) == found


def test_gib_switches_units_at_one_gib() -> None:
    """One decimal in GiB from 2**30 bytes up, whole MiB below."""
    assert files.gib(2**30) == "1.0 GiB"
    assert files.gib(2**30 - 1) == "1024 MiB"
    assert files.gib(3 * 2**29) == "1.5 GiB"
    assert files.gib(5 * 2**20) == "5 MiB"


def test_memory_and_disk_are_read_from_the_system(tmp_path: Path) -> None:
    """MemAvailable in whole kB (not MemFree), at most MemTotal; the free disk of a path not yet made is that of
    its nearest existing folder, on that folder's file system."""
    def meminfo(key: str) -> int:
        with open("/proc/meminfo", encoding="ascii") as fh:
            return next(int(ln.split()[1]) for ln in fh if ln.startswith(key + ":")) * 1024

    before = meminfo("MemAvailable")
    mem = files.available_memory()
    after = meminfo("MemAvailable")
    assert mem % 1024 == 0 and 0 < mem <= meminfo("MemTotal")
    assert min(before, after) - (64 << 20) <= mem <= max(before, after) + (64 << 20)
    for place in (tmp_path, Path("/dev/shm")):  # /dev/shm: usually another file system than /
        if place.is_dir():
            free = shutil.disk_usage(place).free
            got = files.free_disk(place / "a" / "b" / "c.csv")
            assert abs(got - free) <= 0.01 * free + (64 << 20)


def test_check_resources(tmp_path: Path) -> None:
    """2**70 bytes of memory or disk is refused with the estimate and the hint; zero, or disk with no place, passes."""
    files.check_resources("tiny", memory=0.0, disk=1.0, disk_at=tmp_path)
    files.check_resources("no place", disk=2.0**70)
    files.check_resources("no disk", disk=0.0, disk_at=tmp_path / "missing" / "x")
    with pytest.raises(ResourceError, match=r"^huge needs about 1099511627776\.0 GiB of memory, the machine has "
                                            r"\d+(\.\d)? [GM]iB available \(try less\)$"):
        files.check_resources("huge", memory=2.0**70, hint=" (try less)")
    disk = rf"^huge needs about 1099511627776\.0 GiB of disk, {re.escape(str(tmp_path))} has \d+(\.\d)? [GM]iB free$"
    with pytest.raises(ResourceError, match=disk):
        files.check_resources("huge", disk=2.0**70, disk_at=tmp_path)


# -- the initial-state JSON -------------------------------------------------------------------


def test_init_reads_awkward_doubles_exactly(tmp_path: Path) -> None:
    """Integers become floats; 0.1, 5e-324, -0.0, a nextafter value and the latitude limits come back bit for bit."""
    doc = {"t": 0.1, "lat": -90, "lon": 5e-324, "h": -0.0, "vn": math.nextafter(1.0, 2.0), "ve": 1e-300,
           "vd": -1.7976931348623157e308, "roll": 3, "pitch": -0.0, "yaw": 180.0}
    p = tmp_path / "init.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    got = files.read_init(p)
    assert all(type(getattr(got, k)) is float for k in files.INIT_KEYS)
    assert {k: v.hex() for k, v in got.to_dict().items()} == {k: float(v).hex() for k, v in doc.items()}
    assert list(got.to_dict()) == list(files.INIT_KEYS)
    p.write_text(json.dumps({**doc, "lat": 90.0}), encoding="utf-8")
    assert files.read_init(p).lat == 90.0


def test_write_init_text_and_round_trip(tmp_path: Path) -> None:
    """Two-space indented JSON with repr floats and a final newline; read back bit for bit."""
    values = dict(zip(files.INIT_KEYS, [0.1, 45.0, 5e-324, -0.0, 1e-300, math.nextafter(0.3, 0.0), 2.0, -1.5,
                                        89.99999999999999, 179.0]))
    init = files.InitialState(**values)
    p = tmp_path / "init.json"
    files.write_init(p, init)
    expect = "{\n" + ",\n".join(f'  "{k}": {v!r}' for k, v in values.items()) + "\n}\n"
    assert p.read_text(encoding="utf-8") == expect
    assert {k: v.hex() for k, v in files.read_init(p).to_dict().items()} == {k: v.hex() for k, v in values.items()}


BASE = {"t": 0.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0, "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0,
        "yaw": 30.0}


@pytest.mark.parametrize("text, says", [
    ('{\n "t": 1,\n x}', "line 3, column 2: invalid JSON: Expecting property name enclosed in double quotes"),
    ("[1, 2]", "expected a JSON object with keys t, lat, lon, h, vn, ve, vd, roll, pitch, yaw"),
    (json.dumps({k: v for k, v in BASE.items() if k != "t"}), "key 't' is missing"),
    (json.dumps({k: v for k, v in BASE.items() if k != "yaw"}), "key 'yaw' is missing"),
    (json.dumps({**BASE, "vn": True}), "key 'vn': True is not a finite number"),
    (json.dumps({**BASE, "h": "100"}), "key 'h': '100' is not a finite number"),
    (json.dumps({**BASE, "h": None}), "key 'h': None is not a finite number"),
    (json.dumps({**BASE, "yaw": math.nan}), "key 'yaw': nan is not a finite number"),
    (json.dumps({**BASE, "t": -math.inf}), "key 't': -inf is not a finite number"),
    (json.dumps({**BASE, "lat": math.nextafter(90.0, 91.0)}), "key 'lat': 90.00000000000001 is outside [-90, 90] deg"),
    (json.dumps({**BASE, "lat": math.nextafter(-90.0, -91.0)}),
     "key 'lat': -90.00000000000001 is outside [-90, 90] deg"),
])
def test_bad_init_is_one_line_naming_file_and_key(tmp_path: Path, text: str, says: str) -> None:
    """Invalid JSON (line and column), a non-object, a missing key, a non-number (bool included), a latitude past 90."""
    p = tmp_path / "init.json"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(DataFileError) as err:
        files.read_init(p)
    assert str(err.value) == f"{p}: {says}"


def test_init_missing_or_not_utf8(tmp_path: Path) -> None:
    """A missing file or a folder is "no such file"; a bad byte is located by line and column."""
    for p in (tmp_path / "none.json", tmp_path):
        with pytest.raises(DataFileError) as err:
            files.read_init(p)
        assert str(err.value) == f"{p}: no such file"
    p = tmp_path / "init.json"
    p.write_bytes(b'{\n"t": 1\xff}')
    with pytest.raises(DataFileError) as err:
        files.read_init(p)
    assert str(err.value) == f"{p}: line 2: not UTF-8 text (invalid start byte at column 7)"


# -- reading tables: opening ------------------------------------------------------------------


def test_opening_refuses_missing_empty_and_columnless_files(tmp_path: Path) -> None:
    """No file, a folder, an empty file, missing columns (named, with the header), a gzip that is not one."""
    for p in (tmp_path / "none.csv", tmp_path):
        with pytest.raises(DataFileError) as err:
            files.TableReader(p, COLS)
        assert str(err.value) == f"{p}: no such file"
    empty = tmp_path / "empty.csv"
    empty.write_bytes(b"")
    with pytest.raises(DataFileError) as err:
        files.TableReader(empty, COLS)
    assert str(err.value) == f"{empty}: line 1: the file is empty (expected a CSV with the header {HEADER})"
    p = table(tmp_path, rows(2), header="t,dtheta_x,dv_x")
    with pytest.raises(DataFileError) as err:
        files.TableReader(p, COLS)
    assert str(err.value) == (f"{p}: line 1: missing column(s) dtheta_y, dtheta_z, dv_y, dv_z "
                              "(header has: t, dtheta_x, dv_x)")
    (tmp_path / "imu.csv.gz").write_bytes(b"not gzip at all\n")
    with pytest.raises(DataFileError) as err:
        files.TableReader(tmp_path / "imu.csv.gz", COLS)
    assert str(err.value).startswith(f"{tmp_path / 'imu.csv.gz'}: cannot read: ")


def test_header_with_spaces_reordered_and_extra_columns(tmp_path: Path) -> None:
    """Names are trimmed, taken in any order among extra columns; both parsers pick the same cells."""
    header = " dv_z , note ,t,dtheta_z,dtheta_y,dtheta_x,dv_y,dv_x ,note"
    lines = [f"{6 + k},a,0.{k + 1},{3 + k},{2 + k},{1 + k},{5 + k},{4 + k},b" for k in range(3)]
    expect = [[float(f"0.{k + 1}"), 1 + k, 2 + k, 3 + k, 4 + k, 5 + k, 6 + k] for k in range(3)]
    p = table(tmp_path, lines, header=header)
    for chunk_bytes in (None, 16):
        parts, r = read(p, chunk_bytes)
        assert np.concatenate(parts).tolist() == expect and r.rows == 3
    assert r.header == ["dv_z", "note", "t", "dtheta_z", "dtheta_y", "dtheta_x", "dv_y", "dv_x", "note"]


# -- reading tables: sizes, chunks and the two parsers ----------------------------------------


def sized(tmp_path: Path, size: int, header: str = HEADER) -> tuple[Path, list[str]]:
    """A table of exactly ``size`` bytes (the last cell of the last line padded with zeros)."""
    head = len(header) + 1
    n = (size - head) // 18
    lines = rows(n)
    pad = size - head - 18 * n
    if pad:
        lines[-1] = lines[-1] + "0" * pad
    p = table(tmp_path, lines, header=header)
    assert p.stat().st_size == size
    return p, lines


def expected(lines: list[str]) -> list[list[str]]:
    return [[float(c).hex() for c in ln.split(",")[:7]] for ln in lines]


@pytest.mark.parametrize("header", [HEADER, HEADER + ",t"])  # pyarrow's reader, and the line-by-line one
def test_a_file_of_four_blocks_is_read_whole_one_byte_more_is_streamed(tmp_path: Path, header: str) -> None:
    """With chunk_bytes=64: 256 bytes give one array, 257 several; the rows and their count are the same."""
    for size, whole in ((256, True), (257, False)):
        d = tmp_path / str(size)
        d.mkdir()
        p, lines = sized(d, size, header=header)
        parts, r = read(p, 64)
        assert (len(parts) == 1) is whole
        assert hexes(np.concatenate(parts)) == expected(lines) and r.rows == len(lines)


def test_chunk_bytes_zero_means_one_byte_blocks(tmp_path: Path) -> None:
    """A 6-byte file "t\\n1\\n2\\n" with chunk_bytes 0 or 1 (whole up to 4 bytes) is streamed a line at a time, with
    2 (whole up to 8) it is read whole."""
    p = tmp_path / "t.csv"
    p.write_text("t\n1\n2\n", encoding="utf-8")
    for chunk_bytes, n in ((0, 2), (1, 2), (2, 1)):
        parts = list(files.TableReader(p, ("t",), chunk_bytes=chunk_bytes).chunks())
        assert len(parts) == n and np.concatenate(parts).tolist() == [[1.0], [2.0]]


def test_a_small_gzip_is_still_streamed(tmp_path: Path) -> None:
    """A .csv.gz is never parsed whole: 30 rows compressed below 4 blocks of 64 bytes come in several arrays."""
    lines = rows(30)
    p = tmp_path / "imu.csv.gz"
    p.write_bytes(gzip.compress((HEADER + "\n" + "\n".join(lines) + "\n").encode()))
    assert p.stat().st_size <= 256
    parts, r = read(p, 64)
    assert len(parts) > 1 and hexes(np.concatenate(parts)) == expected(lines) and r.rows == 30


def test_streamed_reordered_columns_with_a_text_column(tmp_path: Path) -> None:
    """pyarrow's streamed reader returns the asked columns in the asked order, never the extra text column."""
    header = "note,dv_z,dv_y,dv_x,dtheta_z,dtheta_y,dtheta_x,t"
    lines = [f"n{k},{6 + k},{5 + k},{4 + k},{3 + k},{2 + k},{1 + k},0.{k + 1:03d}" for k in range(30)]
    p = table(tmp_path, lines, header=header)
    assert p.stat().st_size > 4 * 64
    parts, r = read(p, 64)
    assert len(parts) > 1
    assert np.concatenate(parts).tolist() == [[(k + 1) / 1000, 1 + k, 2 + k, 3 + k, 4 + k, 5 + k, 6 + k]
                                              for k in range(30)]


@pytest.mark.parametrize("k", range(2, 14))
def test_time_is_checked_across_pyarrow_blocks(tmp_path: Path, k: int) -> None:
    """Row k repeats row k-1's time: refused wherever the 64-byte blocks of the streamed reader fall."""
    lines = rows(24)
    lines[k] = lines[k - 1]
    p = table(tmp_path, lines)
    t = k / 1000
    assert error(p, 64) == f"{p}: line {k + 2}, column 't': time {t!r} does not increase (previous row has {t!r})"


@pytest.mark.parametrize("at", range(4, 16))
def test_time_is_checked_across_the_handover(tmp_path: Path, at: int) -> None:
    """A ragged row that also repeats the previous time: refused on its line wherever pyarrow hands over."""
    lines = rows(24)
    lines[at] = lines[at - 1] + ",7"
    p = table(tmp_path, lines[:2] + [""] + lines[2:])
    t = at / 1000
    assert error(p, 64) == f"{p}: line {at + 3}, column 't': time {t!r} does not increase (previous row has {t!r})"


def test_one_row_and_one_column_through_the_line_reader(tmp_path: Path) -> None:
    """A single data row, and a single asked column, are (n, k) arrays in the line-by-line reader too."""
    p = table(tmp_path, ["0.5,1,2,3,4,5,6"], header=HEADER + ",t")
    parts, r = read(p)
    assert [x.tolist() for x in parts] == [[[0.5, 1, 2, 3, 4, 5, 6]]] and r.rows == 1
    one = files.TableReader(p, ("dv_x",))
    assert [x.tolist() for x in one.chunks()] == [[[4.0]]]
    p = table(tmp_path, ["0.5,1,2,3,4,5,6", "0.75,1,2,3,4,5,7"], header=HEADER + ",t")
    assert files.read_table(p, ("dv_z",)).tolist() == [[6.0], [7.0]]


def test_read_table_refuses_a_repeated_time_by_default(tmp_path: Path) -> None:
    """read_table checks time unless strictly_increasing=False."""
    p = table(tmp_path, ["0.5,1,2,3,4,5,6", "0.5,1,2,3,4,5,6"])
    with pytest.raises(DataFileError, match="line 3, column 't': time 0.5 does not increase"):
        files.read_table(p, COLS)
    assert files.read_table(p, COLS, strictly_increasing=False)[:, 0].tolist() == [0.5, 0.5]


def test_read_table_joins_the_batches_of_a_large_parquet(tmp_path: Path) -> None:
    """2**19 + 1 rows (more than one default batch of 32 MiB / 64 rows): every row, in order."""
    n = (1 << 19) + 1
    t = np.arange(1, n + 1) * 0.001
    p = tmp_path / "t.parquet"
    files.write_table(p, ("t",), t[:, None])
    assert len(list(files.TableReader(p, ("t",)).chunks())) > 1
    assert files.read_table(p, ("t",))[:, 0].view(np.int64).tolist() == t.view(np.int64).tolist()


def test_streamed_numpy_reader_with_blank_lines_and_one_line_blocks(tmp_path: Path) -> None:
    """chunk_bytes=0 (one line per block) and blank lines: every row once, in order."""
    lines = rows(6)
    p = table(tmp_path, [lines[0], "", lines[1], lines[2], "", lines[3], lines[4], lines[5]], header=HEADER + ",t")
    parts, r = read(p, 0)
    assert hexes(np.concatenate(parts)) == expected(lines) and r.rows == 6 and len(parts) == 6


@pytest.mark.parametrize("at", range(8, 14))
def test_arrow_refusal_midway_hands_over_without_losing_or_repeating_rows(tmp_path: Path, at: int) -> None:
    """A ragged row (one field more) in a streamed file: pyarrow yields its blocks, the line reader the rest."""
    lines = rows(24)
    lines[at] += ",7"
    p = table(tmp_path, lines[:4] + [""] + lines[4:])
    parts, r = read(p, 64)
    assert len(parts) > 1
    assert hexes(np.concatenate(parts)) == expected(lines) and r.rows == 24


@pytest.mark.parametrize("at", range(8, 14))
def test_handover_locates_errors_and_checks_time_across_it(tmp_path: Path, at: int) -> None:
    """After the hand-over a time equal to the previous row's, and a bad cell, are located on their file lines."""
    lines = rows(24)
    lines[at] += ",7"
    lines[at + 1] = lines[at + 1].replace(f"0.{at + 2:03d}", f"0.{at + 1:03d}")
    p = table(tmp_path, lines[:4] + [""] + lines[4:])
    assert error(p, 64) == (f"{p}: line {at + 4}, column 't': time {(at + 1) / 1000!r} does not increase "
                            f"(previous row has {(at + 1) / 1000!r})")
    lines = rows(24)
    lines[at] += ",7"
    lines[at + 2] = lines[at + 2].replace(",3,", ",x3,")
    p = table(tmp_path, lines[:4] + ["", ""] + lines[4:])
    assert error(p, 64) == f"{p}: line {at + 6}, column 'dtheta_z': not a number: 'x3'"


@pytest.mark.parametrize("chunk_bytes", [None, 16])
def test_time_must_increase_unless_told_otherwise(tmp_path: Path, chunk_bytes: int | None) -> None:
    """Equal or smaller times are refused with the previous value; strictly_increasing=False reads them."""
    lines = ["0.5,1,2,3,4,5,6", "0.5,1,2,3,4,5,6", "0.25,1,2,3,4,5,6"]
    for header in (HEADER, HEADER + ",t"):
        p = table(tmp_path, lines, header=header)
        assert error(p, chunk_bytes) == f"{p}: line 3, column 't': time 0.5 does not increase (previous row has 0.5)"
        p = table(tmp_path, [lines[0], "0.75,1,2,3,4,5,6", "", lines[2]], header=header)
        assert error(p, chunk_bytes) == \
            f"{p}: line 5, column 't': time 0.25 does not increase (previous row has 0.75)"
        parts, _ = read(p, chunk_bytes, strictly_increasing=False)
        assert np.concatenate(parts)[:, 0].tolist() == [0.5, 0.75, 0.25]


@pytest.mark.parametrize("chunk_bytes", [None, 16])
@pytest.mark.parametrize("header", [HEADER, HEADER + ",t"])
def test_bad_cells_are_located(tmp_path: Path, chunk_bytes: int | None, header: str) -> None:
    """Not a number, a missing field (with the row's field count), a non-finite value, on their file lines."""
    good = rows(3)
    p = table(tmp_path, good + ["", "0.009,1,2,3,4"], header=header)
    assert error(p, chunk_bytes) == f"{p}: line 6: column 'dv_y' is missing (row has 5 fields)"
    p = table(tmp_path, good + ["0.009,1,2,3,4,5,six"], header=header)
    assert error(p, chunk_bytes) == f"{p}: line 5, column 'dv_z': not a number: 'six'"
    p = table(tmp_path, ["", *good, "0.009,1,-inf,3,4,5,6"], header=header)
    assert error(p, chunk_bytes) == f"{p}: line 6, column 'dtheta_y': value -inf is not finite"


@pytest.mark.parametrize("header", [HEADER, HEADER + ",t"])
def test_no_data_rows(tmp_path: Path, header: str) -> None:
    """A header and blank lines only: "no data rows", whole and streamed."""
    p = table(tmp_path, [""] * 40, header=header)
    for chunk_bytes in (None, 8):
        assert error(p, chunk_bytes) == f"{p}: no data rows"


def test_gzip_tables_are_streamed_and_located(tmp_path: Path) -> None:
    """A .csv.gz: rows bit for bit, a bad cell and a bad byte on their lines, a cut file is "cannot read"."""
    lines = [f"{i / 7!r},{AWKWARD[i % 7]!r},1,2,3,4,5" for i in range(1, 30)]
    p = tmp_path / "imu.csv.gz"
    p.write_bytes(gzip.compress((HEADER + "\n" + "\n".join(lines) + "\n").encode()))
    for chunk_bytes in (None, 64):
        assert hexes(np.concatenate(read(p, chunk_bytes)[0])) == expected(lines)
    bad = lines.copy()
    bad[20] = bad[20].replace(",1,", ",one,")
    p.write_bytes(gzip.compress((HEADER + "\n" + "\n".join(bad) + "\n").encode()))
    assert error(p, 64) == f"{p}: line 22, column 'dtheta_y': not a number: 'one'"
    p.write_bytes(gzip.compress((HEADER + "\n" + "\n".join(lines[:5]) + "\n0.9,\xff,1,2,3,4,5\n").encode("latin-1")))
    assert error(p) == f"{p}: line 7: not UTF-8 text (invalid start byte at column 5)"
    whole = gzip.compress((HEADER + "\n" + "\n".join(lines) + "\n").encode())
    p.write_bytes(whole[: len(whole) // 2])
    assert error(p).startswith(f"{p}: cannot read: ")


@pytest.mark.parametrize("header", [HEADER, HEADER + ",t"])
def test_bad_bytes_in_a_plain_csv(tmp_path: Path, header: str) -> None:
    """A byte that is not UTF-8 is located by line and column, in a data line past the first read and in the header."""
    p = tmp_path / "imu.csv"
    lines = [f"{i}.5,1,2,3,4,5,6" for i in range(650)] + ["650.5,1,2,3,\xe9,5,6", "651.5,1,2,3,4,5,6"]
    p.write_bytes((header + "\n" + "\n".join(lines) + "\n").encode("latin-1"))
    for chunk_bytes in (None, 64):
        assert error(p, chunk_bytes) == f"{p}: line 652: not UTF-8 text (invalid continuation byte at column 13)"
    p.write_bytes(b"t,\xffdtheta_x\n")
    with pytest.raises(DataFileError) as err:
        files.TableReader(p, COLS)
    assert str(err.value) == f"{p}: line 1: not UTF-8 text (invalid start byte at column 3)"


def test_estimated_rows(tmp_path: Path) -> None:
    """Size over the mean length of the data lines seen (not the header, not a possibly cut last line);
    four times the size of a .gz; 1 with no full data line; 0 for undecodable text; a parquet file's count."""
    lines = ["0.1,1,2,3,4,5,6.000000000000001", "0.25,1,2,3,4,5,6.5", "", "0.375,1,2,3,4,5,6",
             "0.5,1,2,3,4,5,6.00000000000000000000000000000001"]
    p = table(tmp_path, lines)
    seen = [31, 18, 17]
    assert files.TableReader(p, COLS).estimated_rows() == int(p.stat().st_size / (sum(seen) / 3 + 1))
    g = tmp_path / "imu.csv.gz"
    g.write_bytes(gzip.compress(p.read_bytes()))
    assert files.TableReader(g, COLS).estimated_rows() == int(4 * g.stat().st_size / (sum(seen) / 3 + 1))
    assert files.TableReader(table(tmp_path, lines[:1], name="one.csv"), COLS).estimated_rows() == 1
    u = tmp_path / "u.csv"
    good = "".join(f"{i}.5,1,2,3,4,5,6\n" for i in range(650))
    u.write_bytes((HEADER + "\n" + good + "650.5,\xe9,2,3,4,5,6\n").encode("latin-1"))
    assert u.stat().st_size < 1 << 16
    assert files.TableReader(u, COLS).estimated_rows() == 0
    q = tmp_path / "imu.parquet"
    files.write_table(q, COLS, np.column_stack([np.arange(1.0, 38.0), np.zeros((37, 6))]))
    assert files.TableReader(q, COLS).estimated_rows() == 37


def test_estimated_rows_looks_at_the_first_64_kib_only(tmp_path: Path) -> None:
    """4000 lines of 19 characters, then 3000 of 34: the estimate is the size over the short lines' length."""
    short = [f"{i:05d}.0,1,2,3,4,5,6" for i in range(4000)]
    long = [f"{i:05d}.0,1,2,3,4,5,6.000000000000001" for i in range(4000, 7000)]
    p = table(tmp_path, short + long)
    assert 20 * 4000 > 1 << 16 and p.stat().st_size > 2 << 16
    assert files.TableReader(p, COLS).estimated_rows() == p.stat().st_size // 20


# -- parquet ----------------------------------------------------------------------------------


def test_parquet_batches_rows_and_errors(tmp_path: Path) -> None:
    """Batches of chunk_bytes/64 rows; an error names the row across batches; integer columns are cast;
    no rows, a missing column and damaged pages are errors."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    data = np.column_stack([np.arange(1.0, 11.0), np.tile(np.array(AWKWARD[:6]), (10, 1))])
    p = tmp_path / "imu.parquet"
    files.write_table(p, COLS, data)
    assert files.TableReader(p, COLS).header == list(COLS)
    parts, r = read(p, 4 * 64)
    assert [x.shape[0] for x in parts] == [4, 4, 2] and r.rows == 10
    assert hexes(np.concatenate(parts)) == hexes(data)
    parts, _ = read(p, 1)
    assert len(parts) == 10
    bad = data.copy()
    bad[6, 0] = bad[5, 0]
    files.write_table(p, COLS, bad)
    assert error(p, 4 * 64) == f"{p}: row 7, column 't': time 6.0 does not increase (previous row has 6.0)"
    bad[6, 0], bad[4, 0] = data[6, 0], data[3, 0]
    files.write_table(p, COLS, bad)
    assert error(p, 4 * 64) == f"{p}: row 5, column 't': time 4.0 does not increase (previous row has 4.0)"
    ints = pa.table({c: pa.array([1, 2, 3], type=pa.int32()) for c in COLS})
    pq.write_table(ints, p)
    assert read(p)[0][0].dtype == np.float64 and read(p)[0][0][:, 0].tolist() == [1.0, 2.0, 3.0]
    pq.write_table(pa.table({c: pa.array([], type=pa.float64()) for c in COLS}), p)
    assert error(p) == f"{p}: no data rows"
    pq.write_table(pa.table({"t": pa.array([1.0])}), p)
    assert error(p).startswith(f"{p}: line 1: missing column(s) dtheta_x")
    files.write_table(p, COLS, data)
    broken = bytearray(p.read_bytes())
    broken[4:404] = b"\xff" * 400
    p.write_bytes(bytes(broken))
    assert error(p).startswith(f"{p}: cannot read as parquet: ")
    p.write_bytes(b"PAR1 junk PAR1")
    with pytest.raises(DataFileError) as err:
        files.TableReader(p, COLS)
    assert str(err.value).startswith(f"{p}: cannot read as parquet: ")


# -- writing ----------------------------------------------------------------------------------


def test_parquet_columns_by_name(tmp_path: Path) -> None:
    """Columns in another order among extra ones (a text column too) come back in the asked order."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = {c: pa.array([10.0 * j + k for k in range(3)]) for j, c in reversed(list(enumerate(COLS)))}
    p = tmp_path / "imu.parquet"
    pq.write_table(pa.table({"note": pa.array(["a", "b", "c"]), **cols, "x": pa.array([9.0, 9.0, 9.0])}), p)
    assert files.read_table(p, COLS).tolist() == [[10.0 * j + k for j in range(7)] for k in range(3)]


def test_write_table_csv_text_round_trips(tmp_path: Path) -> None:
    """The header line, then each double as text that reads back as itself (one row too; integers as their
    values); empty writes add nothing."""
    data = np.array([[1.0, *AWKWARD[:6]], [2.5, *AWKWARD[1:7]]])
    p = tmp_path / "x.csv"
    with files.TableWriter(p, COLS) as w:
        w.write(data[:1])
        w.write(np.empty((0, 7)))
        w.write(data[1:])
        assert w.rows == 2
    text = p.read_text(encoding="ascii")
    lines = text.split("\n")
    assert lines[0] == HEADER and lines[-1] == "" and len(lines) == 4
    for line, row in zip(lines[1:3], data):
        cells = line.split(",")
        assert [float(c).hex() for c in cells] == [float(v).hex() for v in row]
    assert files.format_rows(np.empty((0, 3))) == ""
    assert [float(c).hex() for c in files.format_rows(np.array([[0.1, -0.0, 5e-324]])).rstrip("\n").split(",")] \
        == [(0.1).hex(), (-0.0).hex(), (5e-324).hex()]
    ints = tmp_path / "ints.csv"
    files.write_table(ints, ("t", "n"), np.array([[1, -2], [3, 4]]))
    assert [[float(c) for c in ln.split(",")] for ln in ints.read_text().split("\n")[1:3]] == [[1.0, -2.0], [3.0, 4.0]]
    body = files.format_rows(data)
    assert body.endswith("\n") and [[float(c).hex() for c in ln.split(",")] for ln in body.split("\n")[:-1]] == \
        hexes(data)


def test_write_table_parquet_and_row_groups(tmp_path: Path) -> None:
    """A parquet table is float64 columns named as given, one row group per 2**18 rows (none for no rows), read
    back bit for bit."""
    import pyarrow.parquet as pq

    n = (1 << 18) + 1
    data = np.column_stack([np.arange(1, n + 1) * 0.001, np.tile(np.array(AWKWARD[:6]), (n, 1))])
    p = tmp_path / "big.parquet"
    files.write_table(p, COLS, data)
    meta = pq.ParquetFile(p)
    assert meta.metadata.num_row_groups == 2 and meta.metadata.row_group(1).num_rows == 1
    assert meta.schema_arrow.names == list(COLS) and all(str(t) == "double" for t in meta.schema_arrow.types)
    assert files.read_table(p, COLS).view(np.int64).tolist() == data.view(np.int64).tolist()
    small = tmp_path / "small.csv"
    files.write_table(small, COLS, data[:3])
    assert small.read_text().count("\n") == 4
    with files.TableWriter(tmp_path / "none.parquet", COLS) as w:
        w.write(np.empty((0, 7)))
    assert pq.ParquetFile(tmp_path / "none.parquet").metadata.num_row_groups == 0 and w.rows == 0


def test_solution_writer_degrees_and_round_trip(tmp_path: Path) -> None:
    """Radians in, degrees out for lat, lon, roll, pitch, yaw only; round-trip text of at most 17 significant
    digits (docs/conventions.md "Files"); missing folders are made, an existing one is used; read back exactly."""
    rad = np.array([0.1, math.pi / 4, -math.pi / 2, 100.5, 5e-324, -0.0, 1e-300, 0.25, -0.5, math.pi,
                    math.nextafter(1.0, 0.0), 0.1, -0.2, 0.3])
    p = tmp_path / "out" / "run" / "nav.csv"
    w = files.SolutionWriter(p)
    w.write(rad)
    w.write(rad + np.r_[1.0, np.zeros(13)])
    assert w.rows == 2
    w.close()
    assert rad[1] == math.pi / 4
    deg = rad.copy()
    for j in (1, 2, 7, 8, 9):
        deg[j] = math.degrees(rad[j])
    lines = p.read_text(encoding="utf-8").split("\n")
    assert lines[0] == ",".join(files.SOLUTION_COLUMNS) and lines[3] == ""
    fields = lines[1].split(",")
    assert [float(f) for f in fields] == [float(v) for v in deg]
    assert all(math.copysign(1.0, float(f)) == math.copysign(1.0, v) for f, v in zip(fields, deg))  # -0.0 stays
    assert all(len(re.sub(r"e.*|[^0-9]", "", f).strip("0") or "0") <= 17 for f in fields)
    back = files.read_solution(p)
    assert hexes(back[0]) == hexes(deg) and back.shape == (2, 14) and back[1, 0] == 1.1
    assert deg[1] == 45.0 and deg[2] == -90.0 and deg[9] == 180.0
    second = files.SolutionWriter(p.parent / "again.csv")
    second.close()
    assert (p.parent / "again.csv").read_text(encoding="utf-8") == ",".join(files.SOLUTION_COLUMNS) + "\n"


def test_solution_writer_keeps_a_block_and_writes_it_when_full_flushed_or_closed(tmp_path: Path) -> None:
    p = tmp_path / "nav.csv"
    row = np.arange(14.0)
    w = files.SolutionWriter(p, block=3)
    header = ",".join(files.SOLUTION_COLUMNS) + "\n"
    body = lambda: p.read_text(encoding="utf-8")[len(header):].splitlines()  # noqa: E731
    w.write(row)
    w.write(row + 1.0)
    assert p.read_text(encoding="utf-8") == header and w.rows == 2  # kept, not written yet
    w.write(row + 2.0)
    assert [float(x.split(",")[0]) for x in body()] == [0.0, 1.0, 2.0]  # the block is full: written
    w.write(row + 3.0)
    w.flush()
    assert len(body()) == 4
    w.flush()  # nothing kept: nothing written
    w.write(row + 4.0)
    w.close()
    assert [float(x.split(",")[0]) for x in body()] == [0.0, 1.0, 2.0, 3.0, 4.0] and w.rows == 5
    one = files.SolutionWriter(tmp_path / "one.csv", block=1)  # a block of one row: each written at once
    one.write(row)
    assert (tmp_path / "one.csv").read_text(encoding="utf-8").count("\n") == 2
    with pytest.raises(ValueError, match="a row of 13 values for 14 columns"):
        files.SolutionWriter(tmp_path / "x.csv").write(np.zeros(13))


def test_gnss_rows_without_a_position_are_no_fix_with_only_the_required_columns(tmp_path: Path) -> None:
    """docs/conventions.md: "A row whose position is empty or NaN is no fix", whatever optional columns are present."""
    from mavins import nav

    body = "1.0,45.0,7.0,100.0\n2.0,,,\n3.0,nan,nan,nan\n4.0,45.5,7.5,90.0\n"
    p = table(tmp_path, body.splitlines(), header="t,lat,lon,h", name="gnss.csv")
    got = nav.read_aiding(p, nav.GNSS_REQUIRED, nav.GNSS_OPTIONAL, no_fix_rows=True)
    assert got[:, 0].tolist() == [1.0, 2.0, 3.0, 4.0]
    assert np.isnan(got[1:3, 1:4]).all() and got[3, 1:4].tolist() == [45.5, 7.5, 90.0]



def test_a_gzip_removed_after_opening_is_cannot_read(tmp_path: Path) -> None:
    """A .csv.gz deleted between opening and reading: "FILE: cannot read: ..."."""
    g = tmp_path / "imu.csv.gz"
    g.write_bytes(gzip.compress((HEADER + "\n" + "\n".join(rows(3)) + "\n").encode()))
    reader = files.TableReader(g, COLS)
    g.unlink()
    with pytest.raises(DataFileError) as err:
        list(reader.chunks())
    assert str(err.value).startswith(f"{g}: cannot read: ")


def test_a_table_removed_after_opening_is_a_data_file_error(tmp_path: Path) -> None:
    """files.py: "Every reading error is a DataFileError", as for a .csv.gz."""
    p = table(tmp_path, rows(3))
    reader = files.TableReader(p, COLS)
    p.unlink()
    with pytest.raises(DataFileError) as err:
        list(reader.chunks())
    assert str(err.value) == f"{p}: cannot read: {os.strerror(errno.ENOENT)}"


# -- round trips and the two parsers (until 2026-11-29 tests/common/test_files_io.py) ------------------------
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _increasing_table(values: np.ndarray) -> np.ndarray:
    out = values.copy()
    out[:, 0] = np.arange(1, out.shape[0] + 1) * 0.005  # time must increase
    return out


@settings(max_examples=60, deadline=None)
@given(values=hnp.arrays(np.float64, st.tuples(st.integers(1, 40), st.just(7)), elements=finite),
       suffix=st.sampled_from([".csv", ".csv.gz", ".parquet"]))
def test_any_double_round_trips_bit_for_bit(tmp_path_factory: pytest.TempPathFactory, values: np.ndarray,
                                            suffix: str) -> None:
    data = _increasing_table(values)
    path = tmp_path_factory.mktemp("rt") / f"imu{suffix}"
    if suffix == ".csv.gz":
        text = ",".join(COLS) + "\n" + files.format_rows(data)
        path.write_bytes(gzip.compress(text.encode()))
    else:
        files.write_table(path, COLS, data)
    back = files.read_table(path, COLS)
    assert back.view(np.int64).tolist() == data.view(np.int64).tolist()  # -0.0 and subnormals included


def test_extremes_round_trip(tmp_path: Path) -> None:
    special = np.array([5e-324, -5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, -0.0, 0.1, 1 / 3,
                        123456789.12345679, 1e-5, 2.0**60, -1e22])
    data = np.tile(special[:, None], (1, 7))
    data[:, 0] = np.arange(1, special.size + 1)
    files.write_table(tmp_path / "x.csv", COLS, data)
    back = files.read_table(tmp_path / "x.csv", COLS)
    assert back.view(np.int64).tolist() == data.view(np.int64).tolist()


def _csv(tmp_path: Path, body: str, name: str = "imu.csv") -> Path:
    p = tmp_path / name
    p.write_text(",".join(COLS) + "\n" + body, encoding="utf-8")
    return p


GOOD = "0.01,0,0,0,0,0,-0.098\n"


@pytest.mark.parametrize("chunk_bytes", [None, 64])  # whole file, and streamed in small blocks
@pytest.mark.parametrize("body, line, column, says", [
    (GOOD + "0.02,0,0,x,0,0,-0.098\n", 3, "dtheta_z", "not a number: 'x'"),
    (GOOD + "\n\n0.02,0,0,0,0,,-0.098\n", 5, "dv_y", "not a number: ''"),
    (GOOD + "0.011,0,0,0,0,0,0\n0.012,0,0,0,0,0,0\n0.02,0,0,nan,0,0,-0.098\n", 5, "dtheta_z", "is not finite"),
    (GOOD + "0.01,0,0,0,0,0,-0.098\n", 3, "t", "does not increase"),
    (GOOD + "0.02,0,0\n", 3, "dtheta_z", "is missing"),
])
def test_errors_name_line_and_column(tmp_path: Path, chunk_bytes: int | None, body: str, line: int, column: str,
                                     says: str) -> None:
    path = _csv(tmp_path, body)
    with pytest.raises(files.DataFileError) as err:
        list(files.TableReader(path, COLS, chunk_bytes=chunk_bytes).chunks())
    msg = str(err.value)
    assert msg.startswith(f"{path}: line {line}") and f"'{column}'" in msg and says in msg, msg


def test_rows_with_extra_fields_and_quotes_are_read(tmp_path: Path) -> None:
    """What the contract allows (extra columns; a quoted number is still a number) reads the same
    whichever parser takes the file."""
    path = tmp_path / "imu.csv"
    path.write_text("t,dtheta_x,dtheta_y,dtheta_z,dv_x,dv_y,dv_z,note\n0.01,1,2,3,4,5,6,a\n\"0.02\",1,2,3,4,5,6,b\n",
                    encoding="utf-8")
    assert files.read_table(path, COLS).tolist() == [[0.01, 1, 2, 3, 4, 5, 6], [0.02, 1, 2, 3, 4, 5, 6]]
    ragged = tmp_path / "ragged.csv"  # a row with one field more than the header
    ragged.write_text(",".join(COLS) + "\n0.01,1,2,3,4,5,6\n0.02,1,2,3,4,5,6,7\n", encoding="utf-8")
    assert files.read_table(ragged, COLS).tolist() == [[0.01, 1, 2, 3, 4, 5, 6], [0.02, 1, 2, 3, 4, 5, 6]]


def test_parquet_errors_name_the_row(tmp_path: Path) -> None:
    data = _increasing_table(np.zeros((5, 7)))
    data[3, 2] = np.inf
    files.write_table(tmp_path / "imu.parquet", COLS, data)
    with pytest.raises(files.DataFileError, match=r"imu.parquet: row 4, column 'dtheta_y': value inf is not finite"):
        files.read_table(tmp_path / "imu.parquet", COLS)
    (tmp_path / "junk.parquet").write_bytes(b"PAR1 not really")
    with pytest.raises(files.DataFileError, match="cannot read as parquet"):
        files.read_table(tmp_path / "junk.parquet", COLS)


def test_nav_reads_and_writes_parquet_like_csv(tmp_path: Path) -> None:
    """`mavins nav` on the same data as CSV and as parquet: identical solutions, either output format."""
    n = 400
    t = 0.005 * np.arange(1, n + 1)
    dtheta = np.column_stack([np.full(n, 1e-4), np.sin(t) * 1e-4, np.zeros(n)])
    dv = np.column_stack([np.full(n, 0.01), np.zeros(n), np.full(n, -9.80665 * 0.005)])
    data = np.column_stack([t, dtheta, dv])
    files.write_table(tmp_path / "imu.csv", COLS, data)
    files.write_table(tmp_path / "imu.parquet", COLS, data)
    (tmp_path / "init.json").write_text(json.dumps({"t": 0.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0,
                                                    "ve": 0.0, "vd": 0.0, "roll": 0.0, "pitch": 0.0, "yaw": 30.0}))
    runs = {"csv.csv": ("imu.csv", "a.csv"), "pq.csv": ("imu.parquet", "b.csv"), "pq.pq": ("imu.parquet", "c.parquet")}
    for src, out in runs.values():
        proc = subprocess.run([*MAVINS, "nav", src, "--init", "init.json", "-o", out], cwd=tmp_path, env=ENV, check=False,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
    a = files.read_table(tmp_path / "a.csv", files.SOLUTION_COLUMNS)
    assert a.shape == (n // 2, 14)
    for other in ("b.csv", "c.parquet"):
        b = files.read_table(tmp_path / other, files.SOLUTION_COLUMNS)
        assert b.view(np.int64).tolist() == a.view(np.int64).tolist(), other


def test_arrow_columns_to_numpy_and_back() -> None:
    """The buffer-level conversion between numpy and pyarrow columns (files._numpy_of, files._arrow_table): a
    chunked column whose chunks start inside their buffers (slices), a column with nulls (NaN, as pyarrow's
    to_numpy gives), an empty column, and a table built from a non-contiguous array, all bit for bit."""
    import pyarrow as pa

    x = np.array([0.1, -2.5e-300, np.inf, -0.0, 1e308, 3.0, np.nan, 7.25])
    whole = pa.Array.from_buffers(pa.float64(), len(x), [None, pa.py_buffer(x)])
    sliced = pa.chunked_array([whole.slice(1, 3), whole.slice(5, 3)])
    got = files._numpy_of(sliced)
    assert got.tobytes() == np.concatenate([x[1:4], x[5:8]]).tobytes()
    with_nulls = pa.array([1.5, None, -3.0], type=pa.float64())
    np.testing.assert_array_equal(files._numpy_of(with_nulls), [1.5, np.nan, -3.0])
    assert files._numpy_of(pa.chunked_array([], type=pa.float64())).shape == (0,)
    data = np.arange(12.0).reshape(3, 4)[:, ::2]  # strided columns
    table = files._arrow_table(("a", "b"), data)
    assert table.column_names == ["a", "b"]
    assert np.column_stack([files._numpy_of(table.column(i)) for i in range(2)]).tobytes() == \
        np.ascontiguousarray(data).tobytes()

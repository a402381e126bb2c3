"""Table files: exact float round trip through CSV (plain and gzip) and parquet, and the
fast reader's refusals handed to the line-by-line reader with the same messages.

Expected values are the written doubles themselves (bit patterns) and the contract's
error format ("FILE: line L, column 'C': ..."), never the reader's output.
"""
from __future__ import annotations

import gzip
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from support import ENV, MAVINS

from mavins.common import files

COLS = files.INCREMENT_COLUMNS

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

"""`mavins nav --gnss/--baro` end to end, in process: the simulator's files in, the filter's solution out.

The contract (docs/conventions.md "Aided navigation"): the solution file holds the 14 solution
columns, then the filter's 21; a GNSS row whose position is empty or NaN is no fix, whatever
optional columns the file has.
"""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path

import numpy as np
import pytest

from mavins import cli

SOLUTION = ["t", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz"]
FILTER = ["sigma_n", "sigma_e", "sigma_d", "sigma_vn", "sigma_ve", "sigma_vd", "sigma_att_n", "sigma_att_e",
          "sigma_att_d", "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z", "sigma_bg_x", "sigma_bg_y", "sigma_bg_z",
          "sigma_ba_x", "sigma_ba_y", "sigma_ba_z"]
A, F = 6378137.0, 1.0 / 298.257223563  # WGS-84


def run(*argv: object) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli.main([str(a) for a in argv])
    return code, err.getvalue()


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("gnss") / "sim"
    code, err = run("sim", "static", "--duration", "30", "--grade", "consumer", "--seed", "7", "-o", out)
    assert code == 0, err
    return out


def _table(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text(encoding="utf-8").splitlines()
    return lines[0].split(","), np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])


def test_the_solution_has_the_filter_columns_and_truth_within_three_sigma(sim: Path, tmp_path: Path) -> None:
    """Header: the 14 solution columns, then the 21 filter columns, in the contract's order. At the end of 30 s
    at rest with 1 Hz fixes, the horizontal error against the simulator's truth lies within 3 times the
    filter's own horizontal 1-sigma (north and east combined; a 2-D Gaussian exceeds that with probability
    exp(-4.5) = 1.1 %, and the seeded run is one fixed draw). Metres per radian from the WGS-84 radii of
    curvature at the truth's latitude."""
    out = tmp_path / "nav.csv"
    code, err = run("nav", sim / "imu.csv", "--init", sim / "init.json", "-o", out, "--gnss", sim / "gnss.csv",
                    "--baro", sim / "baro.csv", "--grade", "consumer")
    assert code == 0, err
    header, nav = _table(out)
    assert header == SOLUTION + FILTER
    truth_header, truth = _table(sim / "truth.csv")
    lat_t = math.radians(truth[-1, truth_header.index("lat")])
    e2 = F * (2.0 - F)
    d = 1.0 - e2 * math.sin(lat_t) ** 2
    m_n, m_e = A * (1.0 - e2) / d**1.5, A / math.sqrt(d) * math.cos(lat_t)
    assert abs(nav[-1, 0] - truth[-1, 0]) < 0.05  # the consumer grade's time stamps jitter; at rest either way
    dn = math.radians(nav[-1, 1] - truth[-1, truth_header.index("lat")]) * m_n
    de = math.radians(nav[-1, 2] - truth[-1, truth_header.index("lon")]) * m_e
    sig = math.hypot(nav[-1, header.index("sigma_n")], nav[-1, header.index("sigma_e")])
    assert 0.0 < sig < 5.0
    assert math.hypot(dn, de) < 3.0 * sig


@pytest.mark.parametrize("blank", [",,", "nan,nan,nan"])
def test_gnss_rows_without_a_position_are_no_fix_with_only_the_required_columns(sim: Path, tmp_path: Path,
                                                                              blank: str) -> None:
    """A GNSS file of only t,lat,lon,h whose every other row has an empty (or NaN) position gives the very same
    solution, byte for byte, as the file without those rows: they are no fix, not an error."""
    lines = (sim / "gnss.csv").read_text(encoding="utf-8").splitlines()
    rows = [ln.split(",")[:4] for ln in lines[1:]]
    assert len(rows) >= 20
    blanked = ["t,lat,lon,h"] + [r[0] + "," + blank if i % 2 else ",".join(r) for i, r in enumerate(rows)]
    dropped = ["t,lat,lon,h"] + [",".join(r) for i, r in enumerate(rows) if not i % 2]
    (tmp_path / "blanked.csv").write_text("\n".join(blanked) + "\n", encoding="utf-8")
    (tmp_path / "dropped.csv").write_text("\n".join(dropped) + "\n", encoding="utf-8")
    outs = []
    for name in ("blanked", "dropped"):
        out = tmp_path / f"{name}.nav.csv"
        code, err = run("nav", sim / "imu.csv", "--init", sim / "init.json", "-o", out, "--gnss",
                        tmp_path / f"{name}.csv", "--grade", "consumer")
        assert code == 0, err
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]

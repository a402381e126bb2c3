"""The filter in the Rerun recording: 1-sigma, test ratios, published 3-sigma beside the errors, GNSS fixes.

A short aided demo (simulator GNSS at 5 Hz) is recorded to a real .rrd file and
read back with Rerun's own reader: every output set carries the filter's
position 1-sigma (finite, positive) and its test ratios, the published
horizontal 3-sigma sits beside the position error against truth, and the GNSS
fixes appear as points in the 3D view.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

from mavins.demo import run_demo


def _scalars(path: Path) -> dict[str, list[np.ndarray]]:
    out: dict[str, list[np.ndarray]] = defaultdict(list)
    for ch in RrdReader(str(path)).stream():
        if ch.is_static:
            continue
        batch = ch.to_record_batch()
        for name in batch.schema.names:
            if name.endswith(("Scalars:scalars", "Points3D:positions")):
                for v in batch.column(name).to_pylist():
                    if v is not None:
                        out[ch.entity_path].append(np.asarray(v, dtype=float))
    return out


def test_recording_holds_the_filter(tmp_path: Path) -> None:
    rrd = tmp_path / "aided.rrd"
    report = run_demo("flight", duration=30.0, speed=20.0, grade="industrial", rerun_path=rrd, gnss_outage=None)
    data = _scalars(rrd)
    sig = np.array(data["/filter/sigma_pos"])
    assert sig.shape == (report.outputs, 3), sig.shape  # one row per output set, north/east/down
    assert np.all(np.isfinite(sig)) and np.all(sig > 0.0)
    # 5 Hz GNSS of 0.5 m: the horizontal 1-sigma falls below the initial 10 m (docs/filter.md, Tuning)
    assert sig[-1, :2].max() < 2.0 < 9.0 < sig[0, :2].max() + 1.0
    ratios = np.array(data["/filter/test_ratios"])
    assert ratios.shape[1] == 4 and np.all(ratios >= 0.0)
    band = np.array(data["/errors/position_3sigma"]).ravel()
    assert band.size == report.outputs and np.allclose(band, 3.0 * np.sqrt(0.5 * (sig[:, 0] ** 2 + sig[:, 1] ** 2)))
    assert "/errors/position" in data
    assert len(data["/world/gnss"]) >= 1  # fixes drawn in the 3D view


def test_the_demo_estimates_the_units_scale_factors(tmp_path: Path) -> None:
    """``mavins demo --scale-factors`` on the industrial flight: the service's filter estimates the six scale
    factors of the simulated unit (sim.errors.grade, 1000, -700, 400 ppm per triad) and each ends within 3 of
    its sigma, which the report shows; the gyro z one, seen in the turns, below its 1000 ppm prior. The
    recording holds every estimated group of the filter's columns as ``/filter/<name>`` (file units), the
    scale factors among them, and no group the run does not estimate."""
    rrd = tmp_path / "sf.rrd"
    report = run_demo("flight", duration=90.0, speed=None, grade="industrial", rerun_path=rrd, gnss_outage=None,
                      scale_factors=True)
    data = _scalars(rrd)
    groups = {p for p in data if p.startswith("/filter/")} - {"/filter/test_ratios"}
    assert groups == {"/filter/" + g for g in ("sigma_pos", "sigma_vel", "sigma_att", "bg", "ba", "sigma_bg", "sigma_ba", "sg",
                                                 "sigma_sg", "sa", "sigma_sa")}
    sig = np.array(data["/filter/sigma_sg"])
    assert sig.shape[1] == 3 and np.allclose(sig[0], 1000.0, rtol=1e-3) and np.all(sig[-1] <= sig[0])
    np.testing.assert_allclose(np.array(data["/filter/sg"])[-1], [e for _, e, _, _ in report.scale[:3]], atol=5.0)
    assert [n for n, *_ in report.scale] == ["gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z"]
    assert [t for *_, t in report.scale] == [1000.0, -700.0, 400.0] * 2
    for name, est, sig, true in report.scale:
        assert 0.0 < sig <= 1000.0 + 1e-6 and abs(est - true) <= 3.0 * sig, (name, est, sig, true)
    assert report.scale[2][2] < 1000.0
    assert any(line.startswith("scale factors (ppm)") and line.endswith("inside 3-sigma: 6/6") for line in report.lines())


def test_the_demo_estimates_the_units_misalignments() -> None:
    """``mavins demo --misalignment`` on the industrial flight: the service's filter estimates the twelve
    misalignment elements of the simulated unit (sim.errors.grade: 0.05 deg times its fixed pattern, e.g.
    180 arcsec for m_xy) and each ends within 3 of its sigma, which the report shows; the flight's turns and
    accelerations teach it at least two of them (sigma below 0.9 of the 0.05 deg prior)."""
    report = run_demo("flight", duration=90.0, speed=None, grade="industrial", rerun_path=None, gnss_outage=None,
                      misalignment=True)
    pairs = ["xy", "xz", "yx", "yz", "zx", "zy"]
    assert [n for n, *_ in report.misalignment] == [f"{s} {p}" for s in ("gyro", "accel") for p in pairs]
    pattern = [1.0, -0.6, -0.8, 0.5, 0.3, -0.9]  # sim/errors.py _MIS_PATTERN, row-major off the diagonal
    np.testing.assert_allclose([t for *_, t in report.misalignment], [180.0 * p for p in pattern] * 2, rtol=1e-12)
    prior = 180.0  # 0.05 deg in arcsec
    for name, est, sig, true in report.misalignment:
        assert 0.0 < sig <= prior + 1e-6 and abs(est - true) <= 3.0 * sig, (name, est, sig, true)
    assert sum(sig < 0.9 * prior for _, _, sig, _ in report.misalignment) >= 2
    assert report.scale == ()
    assert any(line.startswith("misalignments (arcsec)") and line.endswith("inside 3-sigma: 12/12")
               for line in report.lines())

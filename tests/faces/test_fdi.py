"""Redundant IMUs end to end: simulator faults, ``mavins nav IMU0 IMU1 IMU2 --fdi-log``, false alarms.
Expected values come from the fault definitions, the sensor model and the chi-square design."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from mavins.cli import main
from mavins.core.errmodel import spec_from_grade
from mavins.core.fdi import ImuSetMonitor
from mavins.core.rotation import quat_angle_rows
from sim import errors, faults
from sim.generate import generate, write
from sim.scenarios import Scenario, ScenarioError, load

FDI_HEADER = "t,event,imu,sensor,axis,statistic,threshold"


def _fault(kind: str, **keys: object) -> faults.Fault:
    doc = {"faults": [{"kind": kind, "imu": 0, "sensor": "accel", "axis": "x", "start": 0.25, "end": 0.75, **keys}]}
    return faults.parse(doc)[0]


def test_fault_kinds_change_exactly_the_part_of_each_interval_they_cover() -> None:
    t0, t = 0.0, 0.1 * np.arange(1, 11)  # intervals (0, .1], ..., (.9, 1]; the fault spans [0.25, 0.75)
    begin = np.concatenate(([t0], t[:-1]))
    dt = 0.1
    rate = 10.0 * t  # m/s^2, the true rate of each interval
    x = rate * dt
    cover = np.array([0, 0, 0.05, 0.1, 0.1, 0.1, 0.1, 0.05, 0, 0])  # s of each interval in [0.25, 0.75)
    frac = cover / dt
    np.testing.assert_allclose(faults.apply_channel(_fault("step", bias=2.0), x, begin, t) - x, 2.0 * cover,
                               atol=1e-15)
    # ramp 3 m/s^3: integral of 3 (tau - 0.25) over the covered part of each interval
    lo, hi = np.maximum(begin, 0.25), np.minimum(t, 0.75)
    ramp = np.where(cover > 0, 1.5 * ((hi - 0.25) ** 2 - (lo - 0.25) ** 2), 0.0)
    np.testing.assert_allclose(faults.apply_channel(_fault("ramp", rate=3.0), x, begin, t) - x, ramp, atol=1e-15)
    assert ramp.sum() == pytest.approx(1.5 * 0.5**2, rel=1e-12)  # 3/2 (end - start)^2
    np.testing.assert_allclose(faults.apply_channel(_fault("dropout"), x, begin, t), x * (1 - frac), atol=1e-15)
    np.testing.assert_allclose(faults.apply_channel(_fault("scale", ppm=1e5), x, begin, t), x * (1 + 0.1 * frac),
                               atol=1e-15)
    # stuck: held at the rate of the last interval before the start, (0.1, 0.2] -> 2 m/s^2
    np.testing.assert_allclose(faults.apply_channel(_fault("stuck"), x, begin, t), x * (1 - frac) + 2.0 * cover,
                               atol=1e-15)
    # gyro values are deg/s in the file, rad/s inside
    g = faults.parse({"faults": [{"kind": "step", "imu": 1, "sensor": "gyro", "axis": "z", "start": 1, "bias": 0.5}]})
    assert g[0].value == pytest.approx(math.radians(0.5), rel=1e-15) and g[0].axis == 2 and g[0].end == math.inf


def test_noise_burst_has_the_stated_sigma() -> None:
    n = 20000
    t = 0.01 * np.arange(1, n + 1)
    f = faults.parse({"faults": [{"kind": "noise", "imu": 0, "sensor": "accel", "axis": "y", "start": 0.0,
                                  "sigma": 0.3, "seed": 4}]})[0]
    added = faults.apply_channel(f, np.zeros(n), np.concatenate(([0.0], t[:-1])), t) / 0.01
    # sample sd of n normal draws: relative standard error 1/sqrt(2n) = 0.5 %; 5 of them
    assert np.std(added) == pytest.approx(0.3, rel=0.025)


@pytest.mark.parametrize(("table", "message"), [
    ({"kind": "spike"}, "kind 'spike'"),
    ({"kind": "step", "imu": 0, "sensor": "gyro", "axis": "x", "start": 1.0}, "bias missing"),
    ({"kind": "step", "imu": 3, "sensor": "gyro", "axis": "x", "start": 1.0, "bias": 1}, "imu must be"),
    ({"kind": "step", "imu": 0, "sensor": "mag", "axis": "x", "start": 1.0, "bias": 1}, "sensor must be"),
    ({"kind": "step", "imu": 0, "sensor": "gyro", "axis": "w", "start": 1.0, "bias": 1}, "axis must be"),
    ({"kind": "step", "imu": 0, "sensor": "gyro", "axis": "x", "start": 5.0, "end": 4.0, "bias": 1}, "start < end"),
    ({"kind": "dropout", "imu": 0, "sensor": "gyro", "axis": "x", "start": 1.0, "bias": 1}, "unknown key"),
])
def test_bad_fault_tables_are_scenario_errors(tmp_path: Path, table: dict, message: str) -> None:
    lines = ["[[faults]]"] + [f"{k} = {v!r}".replace("'", '"') for k, v in table.items()]
    src = tmp_path / "bad.toml"
    src.write_text(Path(load("static").source).read_text() + "\n" + "\n".join(lines) + "\n")
    with pytest.raises(ScenarioError, match=message):
        load(str(src))


def test_generate_applies_the_faults_to_the_imu_they_name() -> None:
    base = load("static")
    doc = {**base.doc, "faults": [{"kind": "step", "imu": 1, "sensor": "gyro", "axis": "z", "start": 1.005,
                                   "bias": 0.5}]}
    faulty = Scenario("static_fault", base.source, doc)
    kw = {"duration": 2.0, "rate": 100.0, "grade": "industrial", "seed": 5, "imus": 3}
    ref, run = generate(base, **kw), generate(faulty, **kw)
    np.testing.assert_array_equal(run.dtheta, ref.dtheta)
    np.testing.assert_array_equal(run.extra[1][0], ref.extra[1][0])
    np.testing.assert_array_equal(run.extra[0][1], ref.extra[0][1])
    diff = run.extra[0][0] - ref.extra[0][0]
    te = run.exact.t[run.kept]  # true interval ends (the file's t carry timestamp jitter)
    cover = np.clip(te - np.maximum(te - 0.01, 1.005), 0.0, None)  # intervals (t - 0.01, t]
    np.testing.assert_allclose(diff[:, 2], math.radians(0.5) * cover, atol=1e-15)
    np.testing.assert_array_equal(diff[:, :2], 0.0)
    with pytest.raises(ValueError, match="names IMU 1"):
        generate(faulty, duration=1.0, rate=100.0, imus=1)


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """The flight scenario with three consumer IMUs, written as files."""
    out = tmp_path_factory.mktemp("flight3")
    run = generate(load("flight"), grade="consumer", imus=3, seed=11)
    write(run, out)
    return out, run


def _attitude_error(nav: Path, truth: Path) -> tuple[np.ndarray, np.ndarray]:
    sol = np.loadtxt(nav, delimiter=",", skiprows=1)
    tru = np.loadtxt(truth, delimiter=",", skiprows=1, usecols=range(14))
    # the solution's t are the jittered sample times; its state is that of the exact time nearest
    idx = np.clip(np.searchsorted(tru[:, 0], sol[:, 0]), 1, tru.shape[0] - 1)
    idx -= np.abs(tru[idx - 1, 0] - sol[:, 0]) < np.abs(tru[idx, 0] - sol[:, 0])
    assert np.allclose(tru[idx, 0], sol[:, 0], atol=1e-3)
    return sol[:, 0], np.degrees(quat_angle_rows(sol[:, 10:14], tru[idx, 10:14]))


def test_three_consumer_imus_isolate_a_gyro_step_and_keep_the_attitude(flight: tuple[Path, object],
                                                                       tmp_path: Path) -> None:
    out, run = flight
    # IMU 2's y gyro gains 0.5 deg/s at t = 60 s: the scenario key, applied to the written rows
    fault = faults.parse({"faults": [{"kind": "step", "imu": 2, "sensor": "gyro", "axis": "y", "start": 60.0,
                                      "bias": 0.5}]})
    begin = np.concatenate(([run.exact.t0], run.exact.t[:-1]))[run.kept]
    dth2, dv2 = faults.apply(fault, 2, begin, run.exact.t[run.kept], *run.extra[1])
    bad = tmp_path / "imu2_fault.csv"
    np.savetxt(bad, np.column_stack([run.t, dth2, dv2]), delimiter=",", header="t,dtheta_x,dtheta_y,dtheta_z,"
               "dv_x,dv_y,dv_z", comments="", fmt="%.17g")
    common = ["--init", str(out / "init.json"), "--grade", "consumer"]
    imus = [str(out / "imu.csv"), str(out / "imu1.csv")]
    assert main(["nav", *imus, str(out / "imu2.csv"), "-o", str(tmp_path / "ok.csv"),
                 "--fdi-log", str(tmp_path / "ok_fdi.csv"), *common]) == 0
    assert main(["nav", *imus, str(bad), "-o", str(tmp_path / "bad.csv"),
                 "--fdi-log", str(tmp_path / "bad_fdi.csv"), *common]) == 0
    # fault-free: 2 x 430 tests at 1e-6 each, 0.9 per mille chance of any event
    assert (tmp_path / "ok_fdi.csv").read_text().strip() == FDI_HEADER
    rows = [r.split(",") for r in (tmp_path / "bad_fdi.csv").read_text().strip().splitlines()]
    assert rows[0] == FDI_HEADER.split(",")
    assert [r[1:5] for r in rows[1:]] == [["detected", "", "gyro", ""], ["isolated", "2", "gyro", "y"]]
    t_iso = float(rows[2][0])
    assert 60.0 < t_iso <= 61.0
    assert float(rows[2][5]) > float(rows[2][6])
    # after isolation the navigation runs on IMUs 0 and 1; before it the fused gyro carried 1/3 of the
    # fault for at most one window (0.5 deg/s / 3 x 0.5 s = 0.08 deg). The fault-free error is that of
    # the fused turn-on biases (1/3 deg/s 1-sigma per axis, divided by sqrt 3) over the flight.
    t_ok, e_ok = _attitude_error(tmp_path / "ok.csv", out / "truth.csv")
    _, e_bad = _attitude_error(tmp_path / "bad.csv", out / "truth.csv")
    after = t_ok > t_iso
    assert e_bad[after].max() <= 1.5 * e_ok[after].max()


def test_several_imu_files_must_share_their_times(flight: tuple[Path, object], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out, _ = flight
    rows = (out / "imu1.csv").read_text().splitlines()
    shifted = rows[:100] + [rows[100].replace(rows[100].split(",")[0], str(float(rows[100].split(",")[0]) + 1e-3), 1)]
    (tmp_path / "late.csv").write_text("\n".join(shifted + rows[101:]) + "\n")
    nav, log = tmp_path / "nav.csv", tmp_path / "fdi.csv"
    code = main(["nav", str(out / "imu.csv"), str(tmp_path / "late.csv"), "--init", str(out / "init.json"),
                 "-o", str(nav), "--fdi-log", str(log)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "line 101, column 't'" in err[0] and "same times" in err[0]
    assert not nav.exists() and not log.exists()
    code = main(["nav", str(out / "imu.csv"), "--init", str(out / "init.json"), "-o", str(nav), "--fdi-log", str(log)])
    assert code == 2 and "two or more IMU files" in capsys.readouterr().err
    assert not nav.exists() and not log.exists()


def _window_noise(grade: str, n_imus: int, window: float, hours: float, seed: int) -> tuple[np.ndarray, ...]:
    """Fault-free sensor errors of ``n_imus`` IMUs at rest summed over windows, straight from the
    simulator's error model: white noise summed over a window is N(0, N^2 window) exactly, and the
    bias processes are propagated at the window boundaries (quantisation off: its window error,
    at most one LSB, is 1e-6 rad against a noise of 5e-5)."""
    model = errors.grade(grade)
    model = dataclasses.replace(model, gyro=dataclasses.replace(model.gyro, quantization=0.0),
                                accel=dataclasses.replace(model.accel, quantization=0.0),
                                jitter_sigma=0.0, drop_probability=0.0)
    n = round(hours * 3600.0 / window)
    t = window * np.arange(1, n + 1)
    zero = np.zeros((n, 3))
    draws = [errors.apply(model, t, zero, zero, seed + k, t_start=0.0) for k in range(n_imus)]
    return t, np.stack([d[1] for d in draws], axis=1), np.stack([d[2] for d in draws], axis=1)


def _binomial_upper(n: int, p: float, alpha: float) -> int:
    """Smallest k with P(K > k) <= alpha for K ~ Binomial(n, p) (summed in logs)."""
    logs = [math.lgamma(n + 1) - math.lgamma(j + 1) - math.lgamma(n - j + 1) + j * math.log(p)
            + (n - j) * math.log1p(-p) for j in range(int(n * p + 50 * math.sqrt(n * p) + 50))]
    cdf = 0.0
    for k, lg in enumerate(logs):
        cdf += math.exp(lg)
        if 1.0 - cdf <= alpha:
            return k
    raise AssertionError("bound not reached")


def test_false_alarms_over_ten_hours_agree_with_the_design_probability() -> None:
    t, dth, dv = _window_noise("consumer", 3, 0.5, 10.0, seed=2024)
    for p in (1e-3, 1e-6):
        # one sample per 0.5 s window: the monitor's window is that sample
        mon = ImuSetMonitor(3, spec_from_grade("consumer"), 0.5, false_alarm=p)
        mon.process(t, dth, dv, np.full(t.shape[0], 0.5))
        for part in (mon.gyro, mon.accel):
            stats = part.statistics()
            tests = stats.shape[0]
            assert tests == t.shape[0] - 10  # all but the 5 s calibration
            alarms = int(np.sum(stats[:, 1] > stats[:, 2]))
            # each test exceeds with probability p: the count is Binomial(tests, p); its upper
            # 1e-4 tail bounds it (the model is not looser than designed)
            assert alarms <= _binomial_upper(tests, p, 1e-4), (part.name, p, alarms, tests * p)
            full = stats[:, 2] == stats[0, 2]
            # without fault p^T p is chi-square with n - 3 = 6 degrees of freedom, mean 6. The sample
            # mean of 72 000 tests: white part sd sqrt(12/72000) = 0.013; the Gauss-Markov part
            # (correlation 50 s, 9 processes, about half the variance after the tracker) adds a
            # realised-variance error near sqrt(2 x 50 / 36000 / 9) x 0.5 x 6 = 0.05: 0.2 is four sd.
            assert abs(np.mean(stats[full, 1]) - 6.0) < 0.2, part.name


def test_dodecahedron_gyros_isolate_each_single_failure_and_detect_two() -> None:
    from mavins.core import redundancy as rd
    from mavins.core.fdi import ParityMonitor

    run = generate(load("static"), duration=20.0, rate=100.0, seed=1)
    axes = rd.dodecahedron_axes()
    spec = spec_from_grade("industrial")
    sigma = rd.window_sigma(spec.gyro_arw, 0.5, 60.0, spec.gyro_gm, spec.gyro_tau, spec.gyro_rrw)
    t = run.exact.t
    dt = np.diff(np.concatenate(([run.exact.t0], t)))

    def events(faulted: tuple[int, ...]) -> list:
        step = faults.Fault("step", 0, "gyro", 0, 12.0, math.inf, math.radians(0.2))
        m = faults.skewed_gyros(run.exact.t0, t, run.exact.dtheta, axes, "industrial", seed=9,
                                faults=tuple((j, step) for j in faulted))
        mon = ParityMonitor(axes, sigma, window=50, window_s=0.5, false_alarm=1e-6)
        return mon.process(t, m, dt)[1]

    # 0.2 deg/s = 3.5e-3 rad/s against a window sigma of 1.5e-4 rad/s (industrial: random walk
    # 9.9e-5 rad/sqrt(s) over 0.5 s, plus the tracked bias terms): |v_j|^2 = 1/2 gives a non-centrality
    # of (3.5e-3 / 1.5e-4)^2 / 2 = 270 over a threshold of 31: seen in the first window after 12 s
    for j in range(6):
        ev = events((j,))
        assert [(e.event, e.index) for e in ev] == [("detected", -1), ("isolated", j)]
        assert 12.0 < ev[0].t <= 12.5 + 1e-9
    for pair in ((0, 1), (2, 5), (3, 4)):
        ev = events(pair)
        assert ev and ev[0].event == "detected" and 12.0 < ev[0].t <= 12.5 + 1e-9


@pytest.mark.parametrize("msg", ["highres", "raw"])
def test_live_pipeline_fuses_the_streamed_imus_and_isolates_a_fault(msg: str, tmp_path: Path) -> None:
    """mavins run/replay --imus: the simulator streams three IMUs (HIGHRES_IMU ids 0-2, or RAW_IMU with
    SCALED_IMU2/3), IMU 1's z gyro steps by 0.3 deg/s at 20 s; the pipeline isolates it, says so, and
    (highres run) records every window test to Rerun."""
    from pymavlink.dialects.v20 import common as mavlink2

    from mavins.live.engine import EngineConfig
    from mavins.link.ingest import IngestConfig
    from mavins.live.pipeline import Pipeline
    from mavins.record.recorder import Recorder
    from sim.stream import StreamOptions, frames

    base = load("static")
    doc = {**base.doc, "faults": [{"kind": "step", "imu": 1, "sensor": "gyro", "axis": "z", "start": 20.0,
                                   "bias": 0.3}]}
    run = generate(Scenario("static_fault", base.source, doc), duration=30.0, rate=100.0, grade="industrial",
                   seed=3, imus=3, usec_grid=True)
    init = run.init()
    enc = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    dec = mavlink2.MAVLink(None)
    rrd = tmp_path / "fdi.rrd"
    rec = Recorder(rrd, live=False) if msg == "highres" else None
    p = Pipeline(EngineConfig(lat=init.lat, lon=init.lon, alt=init.h, heading=init.yaw, align=2.0),
                 IngestConfig(imus=()), recorder=rec)
    outs, events = [], []
    for _, ms in frames(run, enc, StreamOptions(msg=msg, imus=3)):
        for m in ms:
            for mm in dec.parse_buffer(m.pack(enc)) or []:
                if (o := p.handle(mm)) is not None:
                    outs.append(o)
        events += p.take_events()
    texts = [t for _, t in events]
    assert any(t == "fusing IMUs 0, 1, 2" for t in texts)
    fdi = [t for t in texts if t.startswith("FDI")]
    # industrial window sigma 1.5e-4 rad/s; 0.3 deg/s = 5.2e-3 rad/s: a non-centrality of 800 in the
    # first full window (RAW/SCALED: 1 mrad/s counts add a rounding noise of 0.3 mrad/s / sqrt(50))
    assert len(fdi) == 1 and "IMU 1 gyro z isolated" in fdi[0], texts
    t_iso = float(fdi[0].split("t=")[1].split(" ")[0])
    assert 20.0 < t_iso <= 21.0
    assert p.imuset is not None and p.imuset.counters["imu_missing"] == 0
    present, bad = p.imuset.status_bits()  # SYS_STATUS: IMU 1's gyro is the isolated one
    assert present == (mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                       | mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO2 | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL2)
    assert bad == mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO2
    assert outs and abs(math.degrees(outs[-1].row[7])) < 1.0  # navigating on the fused data, level
    if rec is None:
        return
    rec.close()
    from rerun.chunk import RrdReader

    series: dict[str, list[list[float]]] = {}
    for ch in RrdReader(str(rrd)).stream():
        batch = ch.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("Scalars:scalars") and ch.entity_path.startswith("/fdi/gyro"):
                series.setdefault(ch.entity_path, []).extend(v for v in batch.column(name).to_pylist() if v)
    test = np.array(series["/fdi/gyro/test"])
    res = np.array(series["/fdi/gyro/residuals"])
    # one test per 0.5 s window from the end of discovery (1 s) and calibration (5 s) to 30 s
    assert 44 <= test.shape[0] <= 48 and res.shape == (test.shape[0], 9)
    over = np.flatnonzero(test[:, 0] > test[:, 1])
    assert over.size == 1  # the isolating window; IMU 1 is dropped after it
    # one threshold while three IMUs are tested (6 degrees of freedom), a lower one with two (3): the
    # chi-square quantile at a fixed P grows with the degrees of freedom
    np.testing.assert_allclose(test[: over[0] + 1, 1], test[0, 1])
    assert test[-1, 1] < test[0, 1]
    # the failing window's largest residual is IMU 1's z gyro (row 5), its residual 0 once dropped
    assert int(np.argmax(np.abs(res[over[0]]))) == 5 and res[-1, 5] == 0.0

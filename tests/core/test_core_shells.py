"""The core's thin shells in process: settings.Setting.check, grades.grade_figures and runner.py.

Expected values are typed from the contract (docs/conventions.md: the
settings' names and ranges, the four grades, solution rows in degrees) and
from a vehicle at rest in the laboratory frame, whose solution must not move.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mavins.core import runner
from mavins.core import strapdown as sd
from mavins.core.grades import grade_figures
from mavins.core.settings import BY_NAME, Strapdown, strapdown_from_options
from support import gamma

# ============================================================== settings


@pytest.mark.parametrize("name,value,message", [
    ("frame", "ned", "frame must be one of geographic, wander, free, inertial, got 'ned'"),
    ("order", 5, "order must be one of 1, 2, 3, 4, exact, got 5"),
    ("samples", 0, "samples must be 1..6, got 0"),
    ("samples", 7, "samples must be 1..6, got 7"),
    ("l_every", 0, "l_every must be >= 1, got 0"),
    ("orthonormalize_every", -1, "orthonormalize_every must be >= 0, got -1"),
])
def test_a_value_outside_a_setting_is_refused_naming_it(name: str, value: object, message: str) -> None:
    with pytest.raises(ValueError) as e:
        BY_NAME[name].check(value)
    assert str(e.value) == message


@pytest.mark.parametrize("name,value", [
    ("frame", "wander"), ("order", 4), ("order", "exact"), ("samples", 1), ("samples", 6),
    ("l_every", 1), ("l_every", 10**6), ("orthonormalize_every", 0), ("coning", False),
])
def test_values_inside_a_setting_pass(name: str, value: object) -> None:
    assert BY_NAME[name].check(value) is None


@pytest.mark.parametrize("no_coning", [True, False])
def test_strapdown_settings_from_parsed_options(no_coning: bool) -> None:
    """The command line's dests (docs/conventions.md option names: ``--earth`` is earth_model, ``--no-coning`` the
    inverse of coning) map onto the settings by name."""
    options = SimpleNamespace(samples=3, no_coning=no_coning, imu_rates="sampled", attitude="dcm", order="4",
                              earth="none", orthonormalize_every=5, vertical="hold", position="simpson", l_every=2,
                              frame="wander")
    assert strapdown_from_options(options) == Strapdown(
        samples=3, coning=not no_coning, imu_rates="sampled", attitude="dcm", order="4", earth_model="none",
        orthonormalize_every=5, vertical="hold", position="simpson", l_every=2, frame="wander")


# ============================================================== grades


def test_an_unknown_grade_names_the_choices() -> None:
    with pytest.raises(ValueError) as e:
        grade_figures("military")
    assert str(e.value) == "unknown grade 'military'; choose one of ('consumer', 'industrial', 'tactical', 'navigation')"
    assert e.value.__cause__ is None and e.value.__suppress_context__


# ============================================================== runner

INIT = {"t": 2.0, "lat": 45.0, "lon": 7.0, "h": 100.0, "vn": 0.0, "ve": 0.0, "vd": 0.0,
        "roll": 0.0, "pitch": 0.0, "yaw": 90.0}
DT = 0.01
G_LAB = float(gamma(math.radians(45.0), 100.0))  # laboratory mode: the start point's normal gravity (WGS-84, the tests' own)


def test_to_file_units_turns_latitude_longitude_and_euler_angles_to_degrees() -> None:
    rows = np.arange(28, dtype=float).reshape(2, 14) / 10.0
    out = runner.to_file_units(rows)
    want = rows.copy()
    for c in (1, 2, 7, 8, 9):
        want[:, c] = rows[:, c] * 180.0 / math.pi
    np.testing.assert_allclose(out, want, rtol=1e-15, atol=0)
    assert np.array_equal(rows, np.arange(28, dtype=float).reshape(2, 14) / 10.0)


def test_initial_state_from_contract_units() -> None:
    """Degrees in, radians and the attitude's DCM in the state: yaw 90 deg, level, is x north -> east."""
    s = runner.initial_state({**INIT, "vn": 1, "ve": -2, "vd": 3})
    assert sd.state_time(s) == 2.0
    np.testing.assert_array_equal(s[sd.S.V:sd.S.V + 3], [1.0, -2.0, 3.0])
    c = s[sd.S.C:sd.S.C + 9].reshape(3, 3)
    np.testing.assert_allclose(c, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    lat, lon, h = sd.position(s, sd.make_config(), sd.GEOGRAPHIC)
    assert (lat, lon, h) == pytest.approx((math.radians(45.0), math.radians(7.0), 100.0), rel=1e-15, abs=0)


def at_rest(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = INIT["t"] + DT * np.arange(1, n + 1)
    return t, np.zeros((n, 3)), np.tile([0.0, 0.0, -G_LAB * DT], (n, 1))


@pytest.mark.parametrize("samples,data", [(1, "increments"), (3, "increments"), (2, "rates")])
def test_navigate_at_rest_in_the_laboratory_frame(samples: int, data: str) -> None:
    """One row per attitude update, the last at the last sample's time, in file units: the start point, zero
    velocity, yaw 90 deg and its quaternion (cos 45 deg, 0, 0, sin 45 deg)."""
    t, dth, dv = at_rest(12)
    if data == "rates":
        dth, dv = dth / DT, dv / DT
    rows = runner.navigate(t, dth, dv, INIT, data=data, samples=samples, earth_model="none")
    assert rows.shape == (12 // samples, 14)
    np.testing.assert_allclose(rows[:, 0], t[samples - 1::samples], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rows[:, 1:4], np.tile([45.0, 7.0, 100.0], (rows.shape[0], 1)), rtol=1e-12, atol=0)
    np.testing.assert_allclose(rows[:, 4:7], 0.0, atol=1e-12)
    np.testing.assert_allclose(rows[:, 7:10], np.tile([0.0, 0.0, 90.0], (rows.shape[0], 1)), atol=1e-9)
    h = math.sqrt(0.5)
    np.testing.assert_allclose(rows[:, 10:14], np.tile([h, 0.0, 0.0, h], (rows.shape[0], 1)), atol=1e-12)


def test_navigate_passes_the_options_to_the_kernel() -> None:
    """samples=4 gives one row per four samples; the input may be lists of numbers."""
    t, dth, dv = at_rest(8)
    rows = runner.navigate(t.tolist(), dth.tolist(), dv.tolist(), INIT, samples=4, earth_model="none")
    assert rows.shape == (2, 14) and rows[-1, 0] == pytest.approx(t[-1], abs=1e-12)


def test_navigate_refuses_an_unknown_kind_of_data() -> None:
    t, dth, dv = at_rest(2)
    with pytest.raises(ValueError) as e:
        runner.navigate(t, dth, dv, INIT, data="counts")
    assert str(e.value) == "data must be increments or rates, got 'counts'"


def test_to_file_units_converts_a_buffer_of_the_callers_own_in_place() -> None:
    """copy=False converts the very array given (the kernel's output buffer: no second 56 MB per million
    samples) and returns it; the default leaves its input as it was; no rows, nothing to do."""
    rows = np.tile(np.radians(np.arange(14.0)), (3, 1))
    before = rows.copy()
    out = runner.to_file_units(rows)
    np.testing.assert_array_equal(rows, before)
    same = runner.to_file_units(rows, copy=False)
    assert same is rows
    np.testing.assert_array_equal(rows, out)
    np.testing.assert_array_equal(rows[:, [1, 2, 7, 8, 9]], np.degrees(before[:, [1, 2, 7, 8, 9]]))
    np.testing.assert_array_equal(rows[:, [0, 3, 4, 5, 6, 10, 11, 12, 13]], before[:, [0, 3, 4, 5, 6, 10, 11, 12, 13]])
    assert runner.to_file_units(np.empty((0, 14)), copy=False).shape == (0, 14)

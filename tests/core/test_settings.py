"""The strapdown settings are defined once (mavins/core/settings.py): nav, run and replay
offer every one of them with the same default and help, and the engine, the offline
runner and the kernel's make_config take their defaults from the same place."""
from __future__ import annotations

import dataclasses
import inspect
import subprocess

import pytest

from mavins.core import settings
from mavins.core import strapdown as sd
from mavins.live.engine import EngineConfig
from mavins.nav import NavOptions
from support import ENV, MAVINS


def _help(cmd: str) -> str:
    proc = subprocess.run([*MAVINS, cmd, "--help"], env={**ENV, "COLUMNS": "400"}, capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    return " ".join(proc.stdout.split())


@pytest.mark.parametrize("cmd", ["nav", "run", "replay"])
def test_every_setting_on_every_command_with_its_default_and_help(cmd: str) -> None:
    text = _help(cmd)
    for s in settings.SETTINGS:
        assert s.flag in text, (cmd, s.flag)
        assert " ".join(s.help.split()) in text, (cmd, s.flag)
        if not s.switch_off:
            assert f"(default: {s.default})" in text.split(s.flag, 2)[-1], (cmd, s.flag)


def test_defaults_come_from_one_place() -> None:
    want = settings.Strapdown().keywords()
    assert set(want) == {s.name for s in settings.SETTINGS}
    kernel = {k: p.default for k, p in inspect.signature(sd.make_config).parameters.items()}
    assert kernel == want
    engine = {f.name: f.default for f in dataclasses.fields(EngineConfig) if f.name in want}
    assert engine == want
    assert NavOptions().strapdown.keywords() == want
    assert settings.strapdown_of(EngineConfig()).keywords() == want


def test_options_map_to_settings() -> None:
    """--no-coning turns coning off; --earth is earth_model; every other dest is the setting's name."""

    class Args:
        pass

    args = Args()
    for s in settings.SETTINGS:
        setattr(args, s.dest, True if s.switch_off else s.default)
    got = settings.strapdown_from_options(args)
    assert got.coning is False
    assert got.earth_model == "wgs84"
    assert {s.dest for s in settings.SETTINGS} >= {"no_coning", "earth", "samples", "imu_rates", "l_every"}


# One value outside each setting's allowed set (the contract's option list), and one inside it.
_BAD = {"samples": (0, 7), "attitude": ("euler",), "order": (5, "0"), "earth_model": ("wgs72",),
        "orthonormalize_every": (-1,), "vertical": ("climb",), "position": ("euler",), "l_every": (0,),
        "imu_rates": ("raw",), "frame": ("ned",)}
_GOOD = {"samples": (1, 6), "order": (2, "exact"), "orthonormalize_every": (0,), "l_every": (7,)}


@pytest.mark.parametrize("name", sorted(_BAD))
def test_make_config_refuses_each_value_outside_the_setting(name: str) -> None:
    for value in _BAD[name]:
        with pytest.raises(ValueError, match=f"^{name} must be"):
            sd.make_config(**{name: value})
    for value in _GOOD.get(name, ()):
        sd.make_config(**{name: value})


def test_every_setting_is_checked() -> None:
    assert set(_BAD) | {"coning"} == {s.name for s in settings.SETTINGS}

"""The strapdown settings: one definition, from which ``mavins nav``, ``run`` and
``replay`` build their options, defaults and help, and the kernel its
configuration (docs/conventions.md "Command line", ``mavins nav`` options).

Each setting is named as the keyword of ``strapdown.make_config``; the command
line spells it ``--name-with-dashes`` (``coning`` is the switch ``--no-coning``,
``earth_model`` is ``--earth``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields


@dataclass(frozen=True)
class Setting:
    """One strapdown setting: its keyword, flag, default, allowed values and help text."""

    name: str
    flag: str
    default: object
    help: str
    choices: tuple[str, ...] | None = None
    int_range: tuple[int, int | None] | None = None  # (min, max or None) for integer settings
    metavar: str | None = None

    @property
    def dest(self) -> str:
        """The option's name as a Python identifier (argparse dest, ``--config`` TOML key)."""
        return self.flag.lstrip("-").replace("-", "_")

    def check(self, value: object) -> None:
        """Raise ValueError, naming the setting, unless ``value`` is one it allows."""
        if self.choices is not None and str(value) not in self.choices:
            raise ValueError(f"{self.name} must be one of {', '.join(self.choices)}, got {value!r}")
        if self.int_range is not None:
            lo, hi = self.int_range
            if not lo <= value <= (value if hi is None else hi):  # type: ignore[operator]
                allowed = f">= {lo}" if hi is None else f"{lo}..{hi}"
                raise ValueError(f"{self.name} must be {allowed}, got {value!r}")

    @property
    def switch_off(self) -> bool:
        """A ``--no-...`` switch: present means the (default True) setting is False."""
        return self.flag.startswith("--no-")


SETTINGS: tuple[Setting, ...] = (
    Setting("samples", "--samples", 2, "samples per attitude/velocity update, 1..6; N>=2 applies N-sample coning "
            "and sculling", int_range=(1, 6), metavar="N"),
    Setting("coning", "--no-coning", True, "keep N-sample updates but drop coning and sculling corrections"),
    Setting("imu_rates", "--imu-rates", "averaged", "rate input: each row/message is the mean over the interval "
            "ending at its time (PX4 HIGHRES_IMU), or an instantaneous sample", choices=("averaged", "sampled")),
    Setting("attitude", "--attitude", "quaternion", "attitude representation", choices=("quaternion", "dcm")),
    Setting("order", "--order", "exact", "series order of the attitude update (T&W 11.2.1)",
            choices=("1", "2", "3", "4", "exact")),
    Setting("earth_model", "--earth", "wgs84", "none = non-rotating laboratory frame, constant gravity",
            choices=("wgs84", "none")),
    Setting("orthonormalize_every", "--orthonormalize-every", 1, "with --attitude dcm, re-orthonormalise every K "
            "updates (0 = never)", int_range=(0, None), metavar="K"),
    Setting("vertical", "--vertical", "free", "hold = keep height and vertical velocity at start values",
            choices=("free", "hold")),
    Setting("position", "--position", "trapezoidal", "integration rule of the position update",
            choices=("rectangular", "trapezoidal", "simpson")),
    Setting("l_every", "--l-every", 1, "attitude updates per slow (l) cycle: Earth rate, transport rate, gravity",
            int_range=(1, None), metavar="M"),
    Setting("frame", "--frame", "geographic", "mechanisation frame (Zhang & Sun ch. 2): geographic (north-pointing, "
            "not beyond |lat| 89.5 deg), wander or free azimuth, or inertial (ECI); the output stays NED",
            choices=("geographic", "wander", "free", "inertial")),
)

BY_NAME: dict[str, Setting] = {s.name: s for s in SETTINGS}


@dataclass(frozen=True)
class Strapdown:
    """Values of the strapdown settings (defaults from SETTINGS)."""

    samples: int = BY_NAME["samples"].default  # type: ignore[assignment]
    coning: bool = BY_NAME["coning"].default  # type: ignore[assignment]
    imu_rates: str = BY_NAME["imu_rates"].default  # type: ignore[assignment]
    attitude: str = BY_NAME["attitude"].default  # type: ignore[assignment]
    order: str = BY_NAME["order"].default  # type: ignore[assignment]
    earth_model: str = BY_NAME["earth_model"].default  # type: ignore[assignment]
    orthonormalize_every: int = BY_NAME["orthonormalize_every"].default  # type: ignore[assignment]
    vertical: str = BY_NAME["vertical"].default  # type: ignore[assignment]
    position: str = BY_NAME["position"].default  # type: ignore[assignment]
    l_every: int = BY_NAME["l_every"].default  # type: ignore[assignment]
    frame: str = BY_NAME["frame"].default  # type: ignore[assignment]

    def keywords(self) -> dict[str, object]:
        """The settings as ``strapdown.make_config`` keywords."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def strapdown_of(obj: object) -> Strapdown:
    """The strapdown settings held by any object with attributes of the same names."""
    return Strapdown(**{s.name: getattr(obj, s.name) for s in SETTINGS})


def strapdown_from_options(options: object) -> Strapdown:
    """The strapdown settings from parsed command-line options (attributes named by ``Setting.dest``)."""
    values = {}
    for s in SETTINGS:
        v = getattr(options, s.dest)
        values[s.name] = (not v) if s.switch_off else v
    return Strapdown(**values)



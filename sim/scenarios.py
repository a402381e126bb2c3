"""Scenario files (TOML): built-in ones and users' own.

A scenario names a start state, IMU settings, a list of segments, superposed
perturbations and an optional turntable; see the files in sim/scenarios/ and
docs/simulator.md for every key. :func:`load` checks the file and returns a
:class:`Scenario`; :func:`build` turns it into a sim.trajectory.Trajectory.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import SCENARIO_DIR as BUILTIN_DIR
from .trajectory import Trajectory


class ScenarioError(ValueError):
    """A scenario that cannot be used, with a message naming the file and key."""


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario: the raw TOML document and where it came from."""

    name: str
    source: str
    doc: dict[str, Any]

    @property
    def description(self) -> str:
        return str(self.doc.get("description", ""))

    @property
    def rate(self) -> float:
        return float(self.doc.get("imu", {}).get("rate", 100.0))

    @property
    def duration(self) -> float | None:
        d = self.doc.get("imu", {}).get("duration")
        return None if d is None else float(d)

    @property
    def grade(self) -> str:
        return str(self.doc.get("imu", {}).get("grade", "ideal"))

    @property
    def earth(self) -> str:
        return str(self.doc.get("imu", {}).get("earth", "wgs84"))


def builtin_names() -> list[str]:
    """Names of the scenarios shipped with mavins."""
    return sorted(p.stem for p in BUILTIN_DIR.glob("*.toml"))


def load(name_or_path: str) -> Scenario:
    """A built-in scenario by name, or a TOML file by path."""
    path = Path(name_or_path)
    if not path.suffix and (BUILTIN_DIR / f"{name_or_path}.toml").is_file():
        path = BUILTIN_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        raise ScenarioError(
            f"{name_or_path}: no such scenario (built-in: {', '.join(builtin_names())}; or give a .toml path)"
        )
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: {exc}") from None
    scenario = Scenario(path.stem, str(path), doc)
    build(scenario)  # validate every key now, not halfway through a run
    return scenario


_SEGMENTS = {
    "static": ("duration",),
    "hover": ("duration",),
    "cruise": ("duration",),
    "accelerate": ("speed",),
    "decelerate": ("speed",),
    "turn": ("angle",),
    "climb": ("height",),
    "attitude": ("duration",),
    "waypoints": ("points",),
}
_OPTIONAL = {
    "accelerate": ("accel", "tilt"),
    "decelerate": ("accel", "tilt"),
    "turn": ("rate", "coordinated", "ramp"),
    "climb": ("rate", "accel"),
    "attitude": ("roll", "pitch"),
    "waypoints": ("speed", "turn_rate", "accel", "climb_rate", "coordinated"),
}


def _need(src: str, where: str, table: dict[str, Any], key: str) -> Any:
    if key not in table:
        raise ScenarioError(f"{src}: {where}: key '{key}' is missing")
    return table[key]


def build(s: Scenario) -> Trajectory:
    """Build the trajectory a scenario describes (raises ScenarioError on bad keys)."""
    src = s.source
    start = s.doc.get("start")
    if not isinstance(start, dict):
        raise ScenarioError(f"{src}: table [start] with lat, lon, h is missing")
    try:
        traj = Trajectory(
            float(_need(src, "[start]", start, "lat")),
            float(_need(src, "[start]", start, "lon")),
            float(_need(src, "[start]", start, "h")),
            yaw=float(start.get("yaw", 0.0)),
            roll=float(start.get("roll", 0.0)),
            pitch=float(start.get("pitch", 0.0)),
            speed=float(start.get("speed", 0.0)),
            use_earth=s.earth != "none",
        )
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{src}: [start]: {exc}") from None
    for i, seg in enumerate(s.doc.get("segments", [])):
        where = f"segments[{i}]"
        kind = seg.get("kind")
        if kind not in _SEGMENTS:
            raise ScenarioError(f"{src}: {where}: kind {kind!r} is not one of {', '.join(sorted(_SEGMENTS))}")
        allowed = set(_SEGMENTS[kind]) | set(_OPTIONAL.get(kind, ())) | {"kind"}
        extra = set(seg) - allowed
        if extra:
            raise ScenarioError(f"{src}: {where}: unknown key(s) {', '.join(sorted(extra))} for kind {kind!r}")
        for key in _SEGMENTS[kind]:
            _need(src, where, seg, key)
        args = {k: v for k, v in seg.items() if k != "kind"}
        try:
            if kind in ("accelerate", "decelerate"):
                traj.accelerate(float(args.pop("speed")), **args)
            elif kind == "waypoints":
                traj.waypoints([tuple(map(float, p)) for p in args.pop("points")], **args)
            else:
                getattr(traj, kind)(**args)
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f"{src}: {where}: {exc}") from None
    for i, p in enumerate(s.doc.get("perturbations", [])):
        where = f"perturbations[{i}]"
        kind = p.get("kind")
        args = {k: v for k, v in p.items() if k != "kind"}
        try:
            if kind == "coning":
                traj.add_coning(float(args["half_angle"]), float(args["freq"]))
            elif kind == "angular_vibration":
                traj.add_angular_vibration(tuple(args["axis"]), float(args["amplitude"]), float(args["freq"]))
            elif kind == "linear_vibration":
                traj.add_linear_vibration(tuple(args["accel"]), float(args["freq"]))
            elif kind == "random_vibration":
                traj.add_random_vibration(float(args.get("angular_psd", 0.0)), float(args.get("linear_psd", 0.0)),
                                          tuple(args["band"]), int(args.get("seed", 0)))
            elif kind == "sculling":
                traj.add_sculling(float(args["angle"]), float(args["accel"]), float(args["freq"]))
            else:
                raise ScenarioError(f"{src}: {where}: kind {kind!r} is not one of coning, angular_vibration, "
                                    "linear_vibration, random_vibration, sculling")
        except KeyError as exc:
            raise ScenarioError(f"{src}: {where}: key {exc} is missing") from None
    return traj


def apply_turntable(s: Scenario, traj: Trajectory, until: float) -> None:
    """Schedule the scenario's turntable (if any) up to time ``until``."""
    tt = s.doc.get("turntable")
    if not tt:
        return
    kind = tt.get("kind")
    if kind == "continuous":
        traj.turntable_continuous(float(tt["rate"]), until)
    elif kind == "stop_and_go":
        traj.turntable_stop_and_go([float(x) for x in tt["positions"]], float(tt["rate"]), float(tt["dwell"]),
                                   until, bool(tt.get("alternate", True)))
    else:
        raise ScenarioError(f"{s.source}: [turntable]: kind {kind!r} is not continuous or stop_and_go")

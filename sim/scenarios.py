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
from collections.abc import Collection, Iterator
from typing import Any

from . import SCENARIO_DIR as BUILTIN_DIR
from . import faults
from .polar import EarthFixedMotion
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


_START_KEYS = {"lat", "lon", "h", "yaw", "roll", "pitch", "speed"}
_IMU_KEYS = {"rate", "duration", "grade", "earth"}
_PERTURBATIONS = {
    "coning": ({"half_angle", "freq"}, set()),
    "angular_vibration": ({"axis", "amplitude", "freq"}, set()),
    "linear_vibration": ({"accel", "freq"}, set()),
    "random_vibration": ({"band"}, {"angular_psd", "linear_psd", "seed"}),
    "sculling": ({"angle", "accel", "freq"}, set()),
}
_TURNTABLES = {
    "continuous": ({"rate"}, set()),
    "stop_and_go": ({"positions", "rate", "dwell"}, {"alternate"}),
}
_EARTH_FIXED_KEYS = {"kind", "roll", "roll_period", "pitch", "pitch_period"}
_FAILURES = (KeyError, TypeError, ValueError, ZeroDivisionError, AttributeError, IndexError)


def _keys(src: str, where: str, table: object, required: set[str], optional: set[str]) -> dict[str, Any]:
    """Check a table's keys: all required present, nothing unknown."""
    if not isinstance(table, dict):
        raise ScenarioError(f"{src}: {where}: expected a table, got {type(table).__name__}")
    unknown = set(table) - required - optional - {"kind"}
    if unknown:
        raise ScenarioError(f"{src}: {where}: unknown key(s) {', '.join(sorted(unknown))}")
    missing = required - set(table)
    if missing:
        raise ScenarioError(f"{src}: {where}: key(s) {', '.join(sorted(missing))} missing")
    return table


def _tables(s: Scenario, name: str, kinds: Collection[str]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    """``(where, kind, table)`` for each table of an array such as ``[[segments]]``, kinds checked."""
    items = s.doc.get(name, [])
    if not isinstance(items, list):
        raise ScenarioError(f"{s.source}: {name}: expected an array of tables ([[{name}]])")
    for i, table in enumerate(items):
        where = f"{name}[{i}]"
        kind = table.get("kind") if isinstance(table, dict) else None
        if kind not in kinds:
            raise ScenarioError(f"{s.source}: {where}: kind {kind!r} is not one of {', '.join(sorted(kinds))}")
        yield where, kind, table


def build(s: Scenario) -> Trajectory | EarthFixedMotion:
    """Build the trajectory a scenario describes (raises ScenarioError on bad keys or values)."""
    src = s.source
    _keys(src, "[imu]", s.doc.get("imu", {}), set(), _IMU_KEYS)
    unknown_top = set(s.doc) - {"description", "start", "imu", "segments", "perturbations", "turntable", "faults",
                                "earth_fixed"}
    if unknown_top:
        raise ScenarioError(f"{src}: unknown top-level key(s) {', '.join(sorted(unknown_top))}")
    if "earth_fixed" in s.doc:
        return _build_earth_fixed(s)
    try:
        faults.parse(s.doc, src)
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
    if s.rate <= 0:
        raise ScenarioError(f"{src}: [imu]: rate must be positive, got {s.rate}")
    start = _keys(src, "[start]", s.doc.get("start"), {"lat", "lon", "h"}, _START_KEYS - {"lat", "lon", "h"})
    try:
        traj = Trajectory(
            float(start["lat"]), float(start["lon"]), float(start["h"]),
            yaw=float(start.get("yaw", 0.0)), roll=float(start.get("roll", 0.0)),
            pitch=float(start.get("pitch", 0.0)), speed=float(start.get("speed", 0.0)),
            use_earth=s.earth != "none",
        )
    except _FAILURES as exc:
        raise ScenarioError(f"{src}: [start]: {exc}") from None
    for where, kind, seg in _tables(s, "segments", _SEGMENTS):
        _keys(src, where, seg, set(_SEGMENTS[kind]), set(_OPTIONAL.get(kind, ())))
        args = {k: v for k, v in seg.items() if k != "kind"}
        try:
            if kind in ("accelerate", "decelerate"):
                traj.accelerate(float(args.pop("speed")), **args)
            elif kind == "waypoints":
                traj.waypoints([tuple(map(float, p)) for p in args.pop("points")], **args)
            else:
                getattr(traj, kind)(**args)
        except _FAILURES as exc:
            raise ScenarioError(f"{src}: {where}: {exc}") from None
    for where, kind, p in _tables(s, "perturbations", _PERTURBATIONS):
        _keys(src, where, p, *_PERTURBATIONS[kind])
        try:
            if kind == "coning":
                traj.add_coning(float(p["half_angle"]), float(p["freq"]))
            elif kind == "angular_vibration":
                traj.add_angular_vibration(tuple(map(float, p["axis"])), float(p["amplitude"]), float(p["freq"]))
            elif kind == "linear_vibration":
                traj.add_linear_vibration(tuple(map(float, p["accel"])), float(p["freq"]))
            elif kind == "random_vibration":
                band = tuple(map(float, p["band"]))
                if len(band) != 2 or not 0 < band[0] < band[1]:
                    raise ValueError(f"band must be [low, high] Hz with 0 < low < high, got {p['band']!r}")
                traj.add_random_vibration(float(p.get("angular_psd", 0.0)), float(p.get("linear_psd", 0.0)),
                                          band, int(p.get("seed", 0)))
            else:
                traj.add_sculling(float(p["angle"]), float(p["accel"]), float(p["freq"]))
        except _FAILURES as exc:
            raise ScenarioError(f"{src}: {where}: {exc}") from None
    _check_turntable(s)
    return traj


def _build_earth_fixed(s: Scenario) -> EarthFixedMotion:
    """``[earth_fixed]``: a great circle or circle of latitude over or near a pole (sim/polar.py).

    ``[start]`` gives lat, lon, h, yaw (the course) and speed; ``[earth_fixed]`` the kind
    (great_circle or parallel) and the rocking (roll, pitch amplitudes in deg, periods in s).
    Segments, perturbations, a turntable and faults do not apply to it.
    """
    src = s.source
    for key in ("segments", "perturbations", "turntable", "faults"):
        if key in s.doc:
            raise ScenarioError(f"{src}: {key}: not available with [earth_fixed]")
    if s.earth != "wgs84":
        raise ScenarioError(f"{src}: [imu]: [earth_fixed] needs earth = wgs84")
    start = _keys(src, "[start]", s.doc.get("start"), {"lat", "lon", "h", "speed"}, {"yaw"})
    ef = _keys(src, "[earth_fixed]", s.doc["earth_fixed"], {"kind"}, _EARTH_FIXED_KEYS - {"kind"})
    try:
        m = EarthFixedMotion(str(ef["kind"]), float(start["lat"]), float(start["lon"]), float(start["h"]),
                             float(start.get("yaw", 0.0)), float(start["speed"]),
                             **{k: float(v) for k, v in ef.items() if k != "kind"})
    except _FAILURES as exc:
        raise ScenarioError(f"{src}: [earth_fixed]: {exc}") from None
    return m


def _check_turntable(s: Scenario) -> None:
    tt = s.doc.get("turntable")
    if tt is None:
        return
    kind = tt.get("kind") if isinstance(tt, dict) else None
    if kind not in _TURNTABLES:
        raise ScenarioError(f"{s.source}: [turntable]: kind {kind!r} is not continuous or stop_and_go")
    _keys(s.source, "[turntable]", tt, *_TURNTABLES[kind])


def apply_turntable(s: Scenario, traj: Trajectory, until: float) -> None:
    """Schedule the scenario's turntable (if any) up to time ``until``."""
    tt = s.doc.get("turntable")
    if not tt:
        return
    _check_turntable(s)
    try:
        if tt["kind"] == "continuous":
            traj.turntable_continuous(float(tt["rate"]), until)
        else:
            traj.turntable_stop_and_go([float(x) for x in tt["positions"]], float(tt["rate"]), float(tt["dwell"]),
                                       until, bool(tt.get("alternate", True)))
    except _FAILURES as exc:
        raise ScenarioError(f"{s.source}: [turntable]: {exc}") from None

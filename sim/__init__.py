"""Bundled IMU simulator: trajectories, exact increments, sensor errors, files and MAVLink streaming."""

from pathlib import Path

#: Folder of the built-in scenario files (kept import-light for the CLI's --help).
SCENARIO_DIR = Path(__file__).parent / "scenarios"

"""Bundled IMU simulator: trajectories, ideal increments and sensor error models."""

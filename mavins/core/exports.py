"""The core's kernels that Python calls on the live path (``mavins run``, ``mavins demo``) and in
``mavins nav`` (the batch strapdown and filter runs), built ahead of time with these signatures
(:mod:`mavins.core.aot`).

Frames: geographic only (``frame=0``, the default of every command); the other frames compile on
first use. A call with other argument types compiles as before. ``tests/core/test_aot.py`` checks that
the live path calls nothing else and that each signature is the one numba infers.
"""

from .aot import Export

V = "f8[::1]"  # a C-contiguous float64 vector
M = "f8[:, ::1]"  # a C-contiguous float64 matrix
C = "f8[:, :, ::1]"  # a C-contiguous float64 array of matrices
MEASUREMENT = f"Tuple(({V}, {M}, {M}))"  # innovation, H, R of a measurement model

EXPORTS = (
    Export("strapdown", "push_rate_scalars", f"i8({V}, {V}, f8, f8, f8, f8, f8, f8, f8)", frame=0),
    Export("strapdown", "solution_row", f"none({V}, {V}, {V})", frame=0),
    Export("strapdown", "position", f"UniTuple(f8, 3)({V}, {V})", frame=0),
    Export("strapdown", "_run_increments", f"i8({V}, {V}, {V}, {M}, {M}, {M})", frame=0),
    Export("strapdown", "_run_rates", f"i8({V}, {V}, {V}, {M}, {M}, {M})", frame=0),
    # mavins nav: time and the increment (or rate) triads as views of the file's table, not copied
    Export("strapdown", "_run_increments", f"i8({V}, {V}, f8[:], f8[:, :], f8[:, :], {M})", frame=0, variant="views"),
    Export("strapdown", "_run_rates", f"i8({V}, {V}, f8[:], f8[:, :], f8[:, :], {M})", frame=0, variant="views"),
    Export("aided", "run_aided", f"UniTuple(i8, 3)({V}, {V}, {V}, {M}, {M}, {M}, {M}, {M}, {M}, {V}, {V}, f8, f8, f8, f8, f8, i8, "
                                 f"{M}, {V}, {M}, i8[:, ::1], {M}, {C}, i8, {M}, i8[::1], f8, {M}, {V}, f8)"),
    Export("runner", "degrees_in_place", f"none({M}, i8[::1])"),
    # mavins nav --smooth: the backward pass and the smoothed rows
    Export("smoother", "backward", f"i8({M}, i8, i8)"),
    # mavins replay --smooth: the live filter's epochs
    Export("smoother", "reset_transition", f"none({V})"),
    Export("smoother", "record", f"i8({M}, i8, f8, i8, {M}, {M}, {V}, {V}, i8[::1])"),
    Export("smoother", "nominal_difference", f"{V}({V}, {V}, {V}, {V}, {V})"),
    Export("aided", "smooth_rows", f"none({M}, i8, i8[::1], {M}, i8, i8[::1])"),
    Export("strapdown", "init_state", f"{V}(f8, f8, f8, f8, {V}, f8, f8, f8)"),
    Export("aided", "push_rate_aided",
           f"i8({V}, {V}, {V}, {M}, {V}, {V}, {V}, f8, f8, f8, f8, f8, f8, f8, i8)", frame=0),
    Export("aided", "filter_row", f"none({M}, {V}, {V})"),
    Export("kalman", "gyro_bias_total", f"{V}({V})"),
    Export("kalman", "correct_gyro3", f"UniTuple(f8, 3)({V}, f8, f8, f8, f8)"),
    Export("aided", "mag_stats", f"{V}({M})"),
    Export("kalman", "accel_bias_total", f"{V}({V})"),
    Export("aided", "flush_propagation", f"none({V}, {V}, {V}, {M}, {V})", frame=0),
    Export("kalman", "apply_update", f"Tuple((f8, f8, b1))({V}, {V}, {V}, {M}, {M}, {V}, {M}, f8, {V})"),
    Export("kalman", "initial_covariance", f"{M}({V}, f8, f8, f8, f8, f8, f8)"),
    Export("kalman", "gnss_position", f"{MEASUREMENT}({V}, {V}, f8, f8, f8, {V}, f8, f8, f8)"),
    Export("kalman", "gnss_velocity", f"{MEASUREMENT}({V}, {V}, {V}, {V}, f8, f8, f8)"),
    Export("kalman", "horizontal_rows", f"{MEASUREMENT}({V}, {M}, {M})"),
    Export("kalman", "baro_height", f"{MEASUREMENT}({V}, {V}, f8, f8, f8)"),
    Export("aided", "apply_gnss", f"Tuple((i8, i8, f8, f8, i8, i8, f8, f8))({V}, {V}, {V}, {M}, f8, f8, f8, {V}, {V}, "
                                  f"{V}, f8, f8, f8, f8, f8, f8, {V})"),
    Export("aided", "keep_or_undo", f"none(b1, {M}, {V}, {M}, {V})"),
    Export("aided", "apply_mag", f"Tuple((i8, f8, f8))({V}, {V}, {V}, {M}, {V}, {V}, {V}, f8, f8, f8, f8, f8, f8, f8, {V})"),
    Export("kalman", "zupt", f"{MEASUREMENT}({V}, f8)"),
    Export("kalman", "nhc", f"{MEASUREMENT}({V}, f8)"),
    Export("kalman", "body_velocity", f"{MEASUREMENT}({V}, {V}, {V})"),
    Export("kalman", "wheel_speed", f"{MEASUREMENT}({V}, {V}, f8, {V}, {V}, f8, f8, f8)"),
    Export("kalman", "heading", f"{MEASUREMENT}({V}, f8, f8)"),
    Export("kalman", "vision_position", f"{MEASUREMENT}({V}, {V}, {V}, {V}, {V}, f8, {V})"),
    Export("kalman", "vision_attitude", f"{MEASUREMENT}({V}, {V}, {M}, {V})"),
    Export("kalman", "vision_place", f"none({V}, {V}, {V}, {M}, {V}, {V}, {M}, f8, {V}, {V})"),
    Export("kalman", "yaw_reset", f"none({V}, {V}, {V}, {M}, f8, f8, f8, f8, f8, f8, f8, f8)"),
    Export("yawgsf", "predict", f"none({M}, {C}, {V}, {V}, f8, f8, f8, f8)"),
    Export("yawgsf", "update", f"none({M}, {C}, {V}, f8, f8, f8)"),
    Export("yawgsf", "estimate", f"UniTuple(f8, 2)({M}, {C}, {V})"),
    Export("earth", "gravity", "f8(f8, f8)"),
    Export("earth", "radii", "UniTuple(f8, 2)(f8)"),
    Export("earth", "lla_to_ecef", f"{V}(f8, f8, f8)"),
    Export("earth", "cne_from_latlon", f"{M}(f8, f8)"),
    # every output set: its local NED position and its body-to-NED rotation (mavins/link/publish.py)
    Export("frames", "local_ned_s", "UniTuple(f8, 3)(f8, f8, f8, f8, f8, f8)"),
    Export("rotation", "quat_to_dcm_s", "UniTuple(f8, 9)(UniTuple(f8, 4))"),
    Export("earth", "earth_rate_n", f"{V}(f8)"),
    Export("rotation", "euler_to_quat", f"{V}(f8, f8, f8)"),
    Export("rotation", "euler_to_dcm", f"{M}(f8, f8, f8)"),
    Export("rotation", "quat_to_euler", f"{V}({V})"),
    Export("rotation", "quat_to_dcm", f"{M}({V})"),
    Export("rotation", "quat_angle_between", f"f8({V}, {V})"),
    Export("rotation", "quat_angle_rows", f"{V}({M}, {M})"),
)

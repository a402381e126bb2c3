"""The simulator's kernels that ``mavins demo`` calls from Python, built ahead of time with these
signatures (:mod:`mavins.core.aot`; ``tests/core/test_aot.py`` checks them)."""

from mavins.core.aot import Export

V = "f8[::1]"
M = "f8[:, ::1]"
C = "f8[:, :, ::1]"

EXPORTS = (
    Export("kinematics", "integrate",
           f"none(f8, {V}, i8, {V}, {V}, f8, f8, f8, {M}, {M}, {C}, i8[::1], {M}, {V}, {M}, b1, {V}, {M}, {M}, {M}, {M})"),
    Export("kinematics", "euler_rows", f"none({M}, {M})"),
    Export("kinematics", "truth", f"none({V}, {M}, {M}, {C}, i8[::1], {M}, {V}, {M}, {M})"),
    Export("kinematics", "channel_eval", f"UniTuple(f8, 2)({V}, {V}, {M}, i8, f8)"),
    Export("kinematics", "channel_values", f"none({V}, {V}, {M}, i8, {V}, {V})"),
    Export("polar", "_tilt_rows", f"f8[:, :, ::1]({V}, {V})"),
    Export("polar", "_ned_rows", f"none({V}, {V}, {M}, {C}, {M})"),
    Export("polar", "_gravity_rows", f"f8[::1]({V}, {V}, f8)"),
)

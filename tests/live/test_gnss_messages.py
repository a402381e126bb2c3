"""GNSS messages the service reads (GPS_RAW_INT, GPS_INPUT, HIL_GPS): what counts as a fix.

Expected values come from the MAVLink message definitions (common.xml: GPS_FIX_TYPE,
units of each field) and docs/filter.md (accuracy limit), never from the decoder.
"""
from __future__ import annotations

import math

import pytest

from mavins.link.mavlink import mavlink
from mavins.live.pipeline import GNSS_MAX_SIGMA, gnss_fix, gnss_invalid

ENC = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
LAT, LON = 473977420, 85455940  # 1e-7 deg


def _decoded(msg: object) -> object:
    return mavlink.MAVLink(None).decode(bytearray(msg.pack(ENC)))  # type: ignore[attr-defined]


def _raw(fix_type: int = 3, lat: int = LAT, lon: int = LON, h_acc: int = 0, v_acc: int = 0, alt_e: int = 0,
         vel: int = 0) -> object:
    return _decoded(ENC.gps_raw_int_encode(5_000_000, fix_type, lat, lon, 488000, 80, 120, vel, 0, 12,
                                           alt_ellipsoid=alt_e, h_acc=h_acc, v_acc=v_acc))


@pytest.mark.parametrize("alt_e, vel, ok", [
    (-1_000_000, 0, True), (50_000_000, 0, True), (-1_000_001, 0, False), (50_000_001, 0, False),
    (2_147_483_646, 0, False), (0, 60_000, True), (0, 60_001, False),
])
def test_heights_and_speeds_no_vehicle_reaches_are_out_of_range(alt_e: int, vel: int, ok: bool) -> None:
    """Ellipsoidal height (GPS_RAW_INT alt_ellipsoid, mm) within -1,000 .. 50,000 m and ground speed (cm/s) at
    most 600 m/s (above the receivers' 1,000-knot export limit): a fix; beyond either, ``out_of_range`` (a
    random GPS_RAW_INT in the vehicle's name, as the ingest fuzz test sends, is then refused before the filter)."""
    fix = gnss_fix(_raw(alt_e=alt_e, vel=vel), geoid_height=0.0)
    assert fix is not None
    assert (gnss_invalid(fix) is None) is ok, (fix, gnss_invalid(fix))


@pytest.mark.parametrize("fix_type", [3, 4, 5, 6, 7, 8])
def test_3d_fix_types_are_fixes(fix_type: int) -> None:
    fix = gnss_fix(_raw(fix_type), geoid_height=47.0)
    assert fix is not None and gnss_invalid(fix) is None
    t, lat, lon, h = fix[:4]
    assert (t, lat, lon) == (5.0, LAT * 1e-7, LON * 1e-7)
    assert h == 488.0 + 47.0  # AMSL mm -> m, plus the geoid height when alt_ellipsoid is absent


@pytest.mark.parametrize("fix_type", [0, 1, 2, 9, 106, 255])
def test_no_fix_and_undefined_fix_types_are_not_fixes(fix_type: int) -> None:
    assert gnss_fix(_raw(fix_type), geoid_height=0.0) is None


@pytest.mark.parametrize("lat, lon", [(900_000_001, LON), (-900_000_001, LON), (LAT, 1_800_000_001),
                                      (LAT, -2_147_483_648)])
def test_coordinates_outside_their_range_are_rejected(lat: int, lon: int) -> None:
    fix = gnss_fix(_raw(lat=lat, lon=lon), geoid_height=0.0)
    assert fix is not None and gnss_invalid(fix) == "out_of_range"


def test_accuracy_from_the_message_and_its_limit() -> None:
    fix = gnss_fix(_raw(h_acc=1500, v_acc=3000), geoid_height=0.0)  # mm
    assert fix is not None and fix[5:7] == (1.5, 3.0) and gnss_invalid(fix) is None
    at_limit = int(GNSS_MAX_SIGMA * 1000)
    assert gnss_invalid(gnss_fix(_raw(h_acc=at_limit, v_acc=at_limit), 0.0)) is None
    assert gnss_invalid(gnss_fix(_raw(h_acc=at_limit + 1), 0.0)) == "inaccurate"
    assert gnss_invalid(gnss_fix(_raw(v_acc=4_294_967_294), 0.0)) == "inaccurate"


def test_gps_input_with_non_finite_values_is_rejected() -> None:
    msg = _decoded(ENC.gps_input_encode(5_000_000, 0, 0, 0, 0, 3, LAT, LON, float("nan"), 1.0, 1.0,
                                        0.0, 0.0, 0.0, 0.2, 1.5, 3.0, 12))
    fix = gnss_fix(msg, geoid_height=0.0)
    assert fix is not None and gnss_invalid(fix) == "out_of_range"


# --- GPS_RAW_INT / GPS2_RAW ground speed and course -----------------------------------------------
def _raw_vel(vel: int, cog: int, vel_acc: int = 0, name: str = "GPS_RAW_INT") -> object:
    if name == "GPS2_RAW":
        return _decoded(ENC.gps2_raw_encode(7_000_000, 3, LAT, LON, 488000, 80, 120, vel, cog, 12, 0, 0,
                                            alt_ellipsoid=0, h_acc=0, v_acc=0, vel_acc=vel_acc))
    return _decoded(ENC.gps_raw_int_encode(7_000_000, 3, LAT, LON, 488000, 80, 120, vel, cog, 12,
                                           alt_ellipsoid=0, h_acc=0, v_acc=0, vel_acc=vel_acc))


@pytest.mark.parametrize("name", ["GPS_RAW_INT", "GPS2_RAW"])
@pytest.mark.parametrize("vel, cog, vn, ve", [
    (1000, 0, 10.0, 0.0),          # 10 m/s due north
    (1000, 9000, 0.0, 10.0),       # due east: cog 90.00 deg
    (250, 22500, -1.767766952966369, -1.767766952966369),  # 2.5 m/s south-west: 2.5 / sqrt(2) each
    (0, 31000, 0.0, 0.0),          # standing: any course gives zero velocity
])
def test_ground_speed_and_course_give_the_horizontal_velocity(name: str, vel: int, cog: int, vn: float,
                                                              ve: float) -> None:
    """common.xml GPS_RAW_INT/GPS2_RAW: ``vel`` ground speed cm/s, ``cog`` course over ground cdeg
    from true north, clockwise: v_N = vel cos(cog), v_E = vel sin(cog); the vertical is not measured
    (NaN); its 1-sigma is ``vel_acc`` (mm/s) when given, else the 0.3 m/s default."""
    fix = gnss_fix(_raw_vel(vel, cog, name=name), geoid_height=0.0)
    assert fix is not None and gnss_invalid(fix) is None
    v = fix[4]
    assert v is not None and abs(v[0] - vn) < 1e-12 and abs(v[1] - ve) < 1e-12 and v[2] != v[2]
    assert fix[7] == 0.3
    fix = gnss_fix(_raw_vel(vel, cog, vel_acc=450, name=name), geoid_height=0.0)
    assert fix is not None and fix[7] == 0.45


@pytest.mark.parametrize("vel, cog", [(65535, 0), (100, 65535), (100, 36000)])
def test_unknown_speed_or_course_gives_no_velocity(vel: int, cog: int) -> None:
    """UINT16_MAX means unknown (common.xml); a course of 360.00 deg or more is not one: position only."""
    fix = gnss_fix(_raw_vel(vel, cog), geoid_height=0.0)
    assert fix is not None and gnss_invalid(fix) is None and fix[4] is None and fix[7] == 0.3


# --- a dual-antenna receiver's heading: GPS_RAW_INT / GPS2_RAW yaw, hdg_acc ---------------------------------
def _raw_yaw(yaw: int, hdg_acc: int = 0, name: str = "GPS_RAW_INT") -> object:
    if name == "GPS2_RAW":
        return _decoded(ENC.gps2_raw_encode(7_000_000, 3, LAT, LON, 488000, 80, 120, 0, 0, 12, 0, 0, yaw=yaw,
                                            alt_ellipsoid=0, h_acc=0, v_acc=0, vel_acc=0, hdg_acc=hdg_acc))
    return _decoded(ENC.gps_raw_int_encode(7_000_000, 3, LAT, LON, 488000, 80, 120, 0, 0, 12, alt_ellipsoid=0,
                                           h_acc=0, v_acc=0, vel_acc=0, hdg_acc=hdg_acc, yaw=yaw))


@pytest.mark.parametrize("name", ["GPS_RAW_INT", "GPS2_RAW"])
@pytest.mark.parametrize("yaw, deg", [(36000, 0.0), (9000, 90.0), (18000, 180.0), (27050, -89.5), (1, 0.01)])
def test_dual_antenna_heading_in_cdeg_from_north(name: str, yaw: int, deg: float) -> None:
    """common.xml: yaw in cdeg clockwise from true north, 36000 for north (0 means not available); the heading
    comes back in rad in (-180, 180] deg; hdg_acc is degE5 (150000 = 1.5 deg), 0 unknown (1 deg)."""
    from mavins.live.pipeline import gnss_heading

    h = gnss_heading(_raw_yaw(yaw, 150000, name))
    assert h is not None and abs(math.degrees(h[0]) - deg) < 1e-9 and abs(math.degrees(h[1]) - 1.5) < 1e-12
    assert abs(math.degrees(gnss_heading(_raw_yaw(yaw, 0, name))[1]) - 1.0) < 1e-12


def test_no_heading_when_the_receiver_has_none() -> None:
    """yaw 0 is 'not available'; above 36000 is no heading."""
    from mavins.live.pipeline import gnss_heading

    assert gnss_heading(_raw_yaw(0)) is None and gnss_heading(_raw_yaw(36001)) is None


@pytest.mark.parametrize("yaw, deg", [(36000, 0.0), (9000, 90.0), (27050, -89.5)])
def test_gps_input_heading_in_cdeg_with_the_default_sigma(yaw: int, deg: float) -> None:
    """GPS_INPUT's ``yaw`` (common.xml: cdeg from true north, 0 not available, 36000 north) is a heading too;
    the message has no accuracy for it, so its 1-sigma is the 1 deg default; yaw 0 is none."""
    from mavins.live.pipeline import gnss_heading

    def gps_input(y: int):  # type: ignore[no-untyped-def]
        return _decoded(ENC.gps_input_encode(5_000_000, 0, 0, 0, 0, 3, LAT, LON, 488.0, 1.0, 1.0, 0.0, 0.0, 0.0,
                                             0.3, 1.0, 2.0, 10, yaw=y))

    h = gnss_heading(gps_input(yaw))
    assert h is not None and abs(math.degrees(h[0]) - deg) < 1e-9 and abs(math.degrees(h[1]) - 1.0) < 1e-12
    assert gnss_heading(gps_input(0)) is None

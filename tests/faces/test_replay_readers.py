"""What the mutation runs found unchecked in mavins/replay.py, the log readers of ``mavins replay`` (docs/testing.md).

Every log is real bytes written by hand in tmp_path from the format definitions: tlog records
(8-byte big-endian microseconds + one MAVLink frame), ArduPilot DataFlash records (A3 95, type, the
fields the record's FMT declares; AP_Logger LogStructure.h for the scaled format characters) and
PX4 ULog files (header, F/A/D messages; PX4 msg/*.msg field names and units). Expected values are
the logged values converted by hand into the MAVLink fields (common.xml: HIGHRES_IMU in SI units,
GPS_RAW_INT lat/lon degE7, alt mm, vel cm/s, cog cdeg; SCALED_PRESSURE hPa and cdegC). Damaged logs
put the junk at byte offsets counted by hand, so the skipped stretches and the cut are known.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from mavins import replay
from mavins.common.files import DataFileError
from mavins.link.mavlink import mavlink
from mavins.replay import LogReport, open_log

ACC_GYRO, MAG_BITS = 0b111111, 0b111000000


def read_all(path: Path) -> tuple[list[tuple[float, object]], LogReport]:
    it, report = open_log(path)
    return list(it), report


def types(msgs: list[tuple[float, object]]) -> list[str]:
    return [m.get_type() for _, m in msgs]


# -- DataFlash ----------------------------------------------------------------------------------

FMT_LEN = 3 + 1 + 1 + 4 + 16 + 64  # FMT: Type B, Length B, Name n, Format N, Columns Z


def df_struct(fmt: str) -> str:
    """The struct codes of DataFlash format characters (c C e E: int16/uint16/int32/uint32 of value x 100, g half)."""
    codes = {"c": "h", "C": "H", "e": "i", "E": "I", "L": "i", "g": "e", "n": "4s", "N": "16s", "Z": "64s"}
    return "<" + "".join(codes.get(c, c) for c in fmt)


def df_record(msg_type: int, fmt: str, *values: object) -> bytes:
    return b"\xa3\x95" + bytes([msg_type]) + struct.pack(df_struct(fmt), *values)


def df_fmt(msg_type: int, name: str, fmt: str, cols: str, length: int | None = None) -> bytes:
    size = 3 + struct.calcsize(df_struct(fmt)) if length is None else length
    return df_record(128, "BBnNZ", msg_type, size, name.encode(), fmt.encode(), cols.encode())


FMT_OF_FMT = df_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
IMU_FMT, IMU_COLS = "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"
GPS_FMT, GPS_COLS = "QBBBcLLeff", "TimeUS,I,Status,NSats,HDop,Lat,Lng,Alt,Spd,GCrs"
GPA_FMT, GPA_COLS = "QBCCCC", "TimeUS,I,VDop,HAcc,VAcc,SAcc"
BARO_FMT, BARO_COLS = "QBfc", "TimeUS,I,Press,Temp"
MAG_FMT, MAG_COLS = "QBhhh", "TimeUS,I,MagX,MagY,MagZ"
IMU_LEN, GPS_LEN = 3 + 8 + 1 + 6 * 4, 3 + 8 + 3 + 2 + 5 * 4  # record sizes, header included


def df_head() -> bytes:
    return (FMT_OF_FMT + df_fmt(130, "IMU", IMU_FMT, IMU_COLS) + df_fmt(131, "GPS", GPS_FMT, GPS_COLS)
            + df_fmt(132, "GPA", GPA_FMT, GPA_COLS) + df_fmt(133, "BARO", BARO_FMT, BARO_COLS)
            + df_fmt(134, "MAG", MAG_FMT, MAG_COLS))


def df_imu(t_us: int, inst: int = 0, gyr=(0.5, -0.25, 0.125), acc=(1.5, -2.0, -9.75)) -> bytes:
    return df_record(130, IMU_FMT, t_us, inst, *gyr, *acc)


def df_gps(t_us: int, inst: int = 0, lat: int = 473977418, lng: int = 85455939, alt_cm: int = 48850) -> bytes:
    return df_record(131, GPS_FMT, t_us, inst, 3, 10, 120, lat, lng, alt_cm, 2.5, 90.0)


def write(tmp_path: Path, name: str, data: bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(data)
    return p


def test_dataflash_imu_record_is_a_highres_imu_in_si_units(tmp_path: Path) -> None:
    """IMU GyrX..Z (rad/s) and AccX..Z (m/s^2) go out unchanged, TimeUS is time_usec, I is the id."""
    data = df_head() + df_imu(1_000_000, inst=2)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert types(msgs) == ["HIGHRES_IMU"]
    frac, m = msgs[0]
    assert frac == (len(data) - IMU_LEN) / len(data)
    assert (m.time_usec, m.id, m.fields_updated) == (1_000_000, 2, ACC_GYRO)
    assert (m.xgyro, m.ygyro, m.zgyro) == (0.5, -0.25, 0.125)
    assert (m.xacc, m.yacc, m.zacc) == (1.5, -2.0, -9.75)
    assert (m.xmag, m.ymag, m.zmag) == (0.0, 0.0, 0.0)
    assert not report.damaged and report.size == len(data)


def test_dataflash_timems_is_scaled_to_microseconds(tmp_path: Path) -> None:
    """An IMU with TimeMS (older logs) and no instance column: time x 1000, id 0."""
    fmt = df_fmt(130, "IMU", "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
    data = FMT_OF_FMT + fmt + df_record(130, "Iffffff", 1234, 0.5, 0.0, 0.0, 0.0, 0.0, -9.75)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    assert [(m.time_usec, m.id, m.xgyro, m.zacc) for _, m in msgs] == [(1_234_000, 0, 0.5, -9.75)]


@pytest.mark.parametrize("fmt, cols", [
    ("Qhfffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),       # integer gyro
    ("Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccW"),       # no AccZ
    ("Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY"),            # fewer columns than format characters
    ("fffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),       # float time
    ("Qfffffff", "Time,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T"),      # no time column
    ("Qffffffy", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T"),    # unknown format character
])
def test_dataflash_imu_fmt_it_cannot_read_gives_no_imu_and_no_damage(tmp_path: Path, fmt: str, cols: str) -> None:
    """Records of an IMU FMT without usable columns are whole records, left out silently."""
    size = 3 + struct.calcsize("<" + fmt.replace("y", "B"))
    rec = b"\xa3\x95\x82" + bytes(size - 3)
    data = FMT_OF_FMT + df_fmt(130, "IMU", fmt, cols, length=size) + rec + rec
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert msgs == [] and not report.damaged


def test_dataflash_imu_fmt_with_a_wrong_length_is_not_read_as_imu(tmp_path: Path) -> None:
    """An IMU FMT whose Length is not the format's size + 3 keeps the length but is no IMU."""
    size = 3 + 8 + 1 + 24
    data = FMT_OF_FMT + df_fmt(130, "IMU", IMU_FMT, IMU_COLS, length=size + 1) + df_imu(1) + b"\0"
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert msgs == [] and not report.damaged


def test_a_later_fmt_replaces_an_imu_layout(tmp_path: Path) -> None:
    """A second FMT for the IMU type that is no IMU ends IMU reading of that type."""
    data = df_head() + df_imu(1) + df_fmt(130, "XXX", IMU_FMT, IMU_COLS) + df_imu(2)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert [m.time_usec for _, m in msgs] == [1] and not report.damaged


def test_dataflash_fmt_of_length_3_is_a_record_of_its_header_only(tmp_path: Path) -> None:
    """Length 3 is the smallest record (header, no fields); Length 2 is a damaged FMT, skipped whole."""
    ok = FMT_OF_FMT + df_fmt(140, "EV", "", "", length=3) + b"\xa3\x95\x8c" * 2 + df_head() + df_imu(5)
    msgs, report = read_all(write(tmp_path, "a.bin", ok))
    assert [m.time_usec for _, m in msgs] == [5] and not report.damaged
    bad_fmt = df_fmt(140, "EV", "", "", length=2)
    bad = FMT_OF_FMT + bad_fmt + df_head() + df_imu(5)
    msgs, report = read_all(write(tmp_path, "b.bin", bad))
    assert [m.time_usec for _, m in msgs] == [5]
    assert report.skipped == [[FMT_LEN, FMT_LEN, None]]


def test_dataflash_fmt_redefining_fmt_with_another_length_is_skipped(tmp_path: Path) -> None:
    """An FMT for type 128 whose Length is not 89 is damage: skipped, the FMT length stays 89."""
    bad = df_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", length=FMT_LEN + 1)
    data = FMT_OF_FMT + bad + df_head()[FMT_LEN:] + df_imu(7)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert [m.time_usec for _, m in msgs] == [7]
    assert report.skipped == [[FMT_LEN, FMT_LEN, None]]


def test_dataflash_junk_is_skipped_to_the_next_header_and_counted(tmp_path: Path) -> None:
    """Bytes that are no record are skipped to the next A3 95; the stretch is [start, length]."""
    head = df_head()
    junk = b"\x01\xa3\x02\x95\x03"
    data = head + df_imu(1) + junk + df_imu(2) + b"\xa3\x95\x7f" + df_imu(3)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert [m.time_usec for _, m in msgs] == [1, 2, 3]
    a = len(head) + IMU_LEN
    b = a + len(junk) + IMU_LEN
    assert report.skipped == [[a, 5, None], [b, 3, None]]
    assert report.skipped_bytes == 8 and report.cut_at is None


def test_dataflash_record_cut_by_the_end_is_reported(tmp_path: Path) -> None:
    """A record one byte short is a cut at its first byte; one ending exactly at the end is whole."""
    whole = df_head() + df_imu(1) + df_imu(2)
    msgs, report = read_all(write(tmp_path, "a.bin", whole))
    assert len(msgs) == 2 and report.cut_at is None and not report.damaged
    msgs, report = read_all(write(tmp_path, "b.bin", whole[:-1]))
    assert len(msgs) == 1 and report.cut_at == len(whole) - IMU_LEN and report.skipped == []


@pytest.mark.parametrize("tail, cut", [(b"\xa3", True), (b"\xa3\x95", True), (b"\xa3\x00", False),
                                       (b"\x00", False), (b"\x00\x95", False)])
def test_dataflash_tail_shorter_than_a_header(tmp_path: Path, tail: bytes, cut: bool) -> None:
    """A last 1-2 bytes that begin a header are a cut record; anything else is skipped bytes."""
    head = df_head() + df_imu(1)
    msgs, report = read_all(write(tmp_path, "a.bin", head + tail))
    assert len(msgs) == 1
    if cut:
        assert report.cut_at == len(head) and report.skipped == []
    else:
        assert report.cut_at is None and report.skipped == [[len(head), len(tail), None]]


def test_dataflash_imu_record_no_highres_imu_can_carry_is_skipped(tmp_path: Path) -> None:
    """An IMU with instance 256 (HIGHRES_IMU id is uint8) is skipped as damage, the next one is read."""
    fmt = df_fmt(130, "IMU", "QHffffff", IMU_COLS)
    data = FMT_OF_FMT + fmt
    at = len(data)
    data += df_record(130, "QHffffff", 1, 256, 0, 0, 0, 0, 0, 0) + df_record(130, "QHffffff", 2, 255, 0, 0, 0, 0, 0, 0)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert [(m.time_usec, m.id) for _, m in msgs] == [(2, 255)]
    assert report.skipped == [[at, 3 + 8 + 2 + 24, None]]


def test_dataflash_gps_with_gpa_is_a_gps_raw_int_in_mavlink_units(tmp_path: Path) -> None:
    """GPS Lat/Lng 1e-7 deg, Alt (e: cm) m, Spd m/s, GCrs deg, HDop (c: x100); GPA VDop/HAcc/VAcc/SAcc (C: x100)."""
    gpa = df_record(132, GPA_FMT, 2_000_000, 0, 150, 250, 400, 30)
    data = df_head() + df_gps(2_000_000) + gpa + df_imu(2_000_500)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert types(msgs) == ["GPS_RAW_INT", "HIGHRES_IMU"]
    frac, g = msgs[0]
    assert frac == len(df_head()) / len(data)
    assert (g.time_usec, g.fix_type, g.satellites_visible) == (2_000_000, 3, 10)
    assert (g.lat, g.lon, g.alt, g.alt_ellipsoid) == (473977418, 85455939, 488500, 0)
    assert (g.vel, g.cog, g.eph, g.epv) == (250, 9000, 120, 150)
    assert (g.h_acc, g.v_acc, g.vel_acc) == (2500, 4000, 300)
    assert not report.damaged and not report.rejected


def test_dataflash_gps_without_matching_gpa_has_no_accuracies(tmp_path: Path) -> None:
    """A GPA of another time does not belong to the GPS: accuracies unknown (0), VDop unknown (65535)."""
    gpa = df_record(132, GPA_FMT, 2_000_001, 0, 150, 250, 400, 30)
    data = df_head() + df_gps(2_000_000) + gpa + df_imu(2_000_500)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    g = msgs[0][1]
    assert types(msgs) == ["GPS_RAW_INT", "HIGHRES_IMU"]
    assert (g.h_acc, g.v_acc, g.vel_acc, g.epv, g.eph) == (0, 0, 0, 65535, 120)


def test_dataflash_gps_goes_out_before_the_next_gps_or_at_the_end(tmp_path: Path) -> None:
    """A GPS waiting for its GPA is sent when the next GPS or the end of the log comes."""
    data = df_head() + df_gps(1_000_000) + df_gps(2_000_000)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    assert [(m.get_type(), m.time_usec) for _, m in msgs] == [("GPS_RAW_INT", 1_000_000), ("GPS_RAW_INT", 2_000_000)]
    assert [f for f, _ in msgs] == [len(df_head()) / len(data), (len(df_head()) + GPS_LEN) / len(data)]


def test_dataflash_gps_of_instance_1_and_impossible_fixes(tmp_path: Path) -> None:
    """Only GPS instance 0 is used; a latitude beyond 2^31 - 1 degE7 is counted as rejected."""
    data = df_head() + df_gps(1, inst=1) + df_gps(2, lat=2**31 - 1) + df_imu(3) + df_gps(4, lat=-2**31)
    data += df_gps(5, lng=2**31 - 1)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert [(m.get_type(), m.time_usec) for _, m in msgs] == [("GPS_RAW_INT", 2), ("HIGHRES_IMU", 3),
                                                             ("GPS_RAW_INT", 4), ("GPS_RAW_INT", 5)]
    assert [m.lat for _, m in msgs if m.get_type() == "GPS_RAW_INT"] == [2**31 - 1, -2**31, 473977418]
    assert not report.rejected


def test_dataflash_baro_is_a_scaled_pressure_in_hpa(tmp_path: Path) -> None:
    """BARO Press (Pa) / 100 is press_abs; Temp (c: cdegC) is temperature; time in ms."""
    data = df_head() + df_record(133, BARO_FMT, 3_456_789, 0, 101325.0, 2534)
    data += df_record(133, BARO_FMT, 4_000_000, 1, 90000.0, 0) + df_record(133, BARO_FMT, 5_000_000, 0, 0.0, 0)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert types(msgs) == ["SCALED_PRESSURE"]
    frac, b = msgs[0]
    assert frac == len(df_head()) / len(data)
    assert (b.time_boot_ms, b.press_abs, b.temperature) == (3456, pytest.approx(1013.25, abs=1e-4), 2534)
    assert report.rejected == {"BARO": 1}
    assert report.lines() == [f"{tmp_path / 'a.bin'}: left out 1 BARO record(s) whose values no MAVLink message "
                              "can carry (out of range or not finite)"]


def test_dataflash_mag_milligauss_rides_on_the_next_imu_records(tmp_path: Path) -> None:
    """MAG MagX..Z (int16 mGauss) x 1e-3 is the gauss of every later HIGHRES_IMU; all zeros is no sample."""
    data = df_head() + df_imu(1) + df_record(134, MAG_FMT, 2, 0, 200, -500, 1000) + df_imu(3) + df_imu(4)
    data += df_record(134, MAG_FMT, 5, 1, 1, 1, 1) + df_imu(6) + df_record(134, MAG_FMT, 7, 0, 0, 0, 0) + df_imu(8)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    got = [(m.time_usec, m.fields_updated, m.xmag, m.ymag, m.zmag) for _, m in msgs]
    mag = (pytest.approx(0.2), pytest.approx(-0.5), pytest.approx(1.0))
    assert got == [(1, ACC_GYRO, 0.0, 0.0, 0.0), (3, ACC_GYRO | MAG_BITS, *mag), (4, ACC_GYRO | MAG_BITS, *mag),
                   (6, ACC_GYRO | MAG_BITS, *mag), (8, ACC_GYRO, 0.0, 0.0, 0.0)]


def test_dataflash_mag_with_one_axis_non_zero_is_a_sample(tmp_path: Path) -> None:
    """A magnetometer sample with only MagZ non-zero is still a sample."""
    data = df_head() + df_record(134, MAG_FMT, 2, 0, 0, 0, 7) + df_imu(3)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    m = msgs[0][1]
    assert (m.fields_updated, m.zmag) == (ACC_GYRO | MAG_BITS, pytest.approx(0.007))


def test_dataflash_aiding_fmt_needs_its_columns_and_a_time(tmp_path: Path) -> None:
    """A BARO FMT without Press, without a time column, or with a string Press is not read."""
    for i, (fmt, cols) in enumerate([("QBf", "TimeUS,I,Alt"), ("BBf", "X,I,Press"), ("QBN", "TimeUS,I,Press"),
                                     ("QBff", "TimeUS,I,Press")]):
        data = FMT_OF_FMT + df_fmt(133, "BARO", fmt, cols) + b"\xa3\x95\x85" + bytes(200)[:struct.calcsize(
            "<" + fmt.replace("N", "16s"))]
        msgs, report = read_all(write(tmp_path, f"{i}.bin", data))
        assert msgs == [] and not report.damaged


def test_dataflash_baro_with_timems(tmp_path: Path) -> None:
    """A BARO with TimeMS is stamped TimeMS x 1000 us, i.e. time_boot_ms = TimeMS."""
    data = FMT_OF_FMT + df_fmt(133, "BARO", "If", "TimeMS,Press") + df_record(133, "If", 4321, 95000.0)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    assert [(m.time_boot_ms, m.press_abs, m.temperature) for _, m in msgs] == [(4321, 950.0, 0)]


# -- tlog ---------------------------------------------------------------------------------------


def rec(t_us: int, frame: bytes) -> bytes:
    return struct.pack(">Q", t_us) + frame


def imu_frame(mav: mavlink.MAVLink, t_us: int) -> bytes:
    return mav.highres_imu_encode(t_us, 0.5, -1.0, -9.75, 0.25, 0.0, -0.125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                  ACC_GYRO, 1).pack(mav)


def test_tlog_records_are_decoded_with_the_fraction_read(tmp_path: Path) -> None:
    """Each record's frame is decoded in SI units; the fraction is the end of the record over the size."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = rec(1, imu_frame(mav, 100))
    b = rec(2, imu_frame(mav, 200))
    msgs, report = read_all(write(tmp_path, "a.tlog", a + b))
    assert [(f, m.time_usec, m.xacc, m.zgyro, m.id) for f, m in msgs] == [
        (len(a) / len(a + b), 100, 0.5, -0.125, 1), (1.0, 200, 0.5, -0.125, 1)]
    assert not report.damaged


def test_tlog_mavlink1_and_signed_frames(tmp_path: Path) -> None:
    """A MAVLink 1 frame is 8 + payload bytes; a signed MAVLink 2 frame carries 13 more."""
    v1 = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    f1 = bytearray(imu_frame(mavlink.MAVLink(None), 100))
    hb = v1.heartbeat_encode(2, 12, 0, 0, 0)
    hb_bytes = bytearray(hb.pack(v1))
    hb_bytes[0] = 0xFE
    signed = bytearray(f1)
    signed[2] |= 0x01
    data = rec(1, bytes(f1)) + rec(2, bytes(signed) + bytes(13)) + rec(3, bytes(f1))
    msgs, report = read_all(write(tmp_path, "a.tlog", data))
    assert types(msgs)[0] == "HIGHRES_IMU" and types(msgs)[2] == "HIGHRES_IMU"
    assert report.skipped == [[len(rec(1, bytes(f1))), len(rec(2, bytes(signed) + bytes(13))), None]]


def test_tlog_junk_is_bad_data_and_skipped_to_the_next_record(tmp_path: Path) -> None:
    """Bytes before a record (8 time bytes then a marker) are one BAD_DATA; the stretch is counted."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = rec(1, imu_frame(mav, 100))
    junk = b"\x00" * 20
    b = rec(2, imu_frame(mav, 200))
    msgs, report = read_all(write(tmp_path, "a.tlog", a + junk + b))
    assert types(msgs) == ["HIGHRES_IMU", "BAD_DATA", "HIGHRES_IMU"]
    assert msgs[1][0] == len(a) / len(a + junk + b)
    assert bytes(msgs[1][1].data) == junk
    assert report.skipped == [[len(a), 20, None]]


def test_tlog_bad_crc_skips_the_whole_record(tmp_path: Path) -> None:
    """A frame failing its CRC is BAD_DATA and its record (time + frame) is skipped."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = bytearray(rec(1, imu_frame(mav, 100)))
    a[-1] ^= 0xFF
    b = rec(2, imu_frame(mav, 200))
    msgs, report = read_all(write(tmp_path, "a.tlog", bytes(a) + b))
    assert types(msgs) == ["BAD_DATA", "HIGHRES_IMU"]
    assert report.skipped == [[0, len(a), None]]


def test_tlog_cut_record_and_short_tail(tmp_path: Path) -> None:
    """A record cut by the end, or a tail shorter than 16 bytes, is a cut at its first byte."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = rec(1, imu_frame(mav, 100))
    b = rec(2, imu_frame(mav, 200))
    for i, tail in enumerate([b[:-1], b[:15], b[:16]]):
        msgs, report = read_all(write(tmp_path, f"{i}.tlog", a + tail))
        assert types(msgs) == ["HIGHRES_IMU"] and report.cut_at == len(a) and report.skipped == []


def test_tlog_junk_at_the_end_without_a_marker(tmp_path: Path) -> None:
    """Junk of 16 bytes or more with no marker after it is skipped to the end of the file."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = rec(1, imu_frame(mav, 100))
    msgs, report = read_all(write(tmp_path, "a.tlog", a + b"\x01" * 16))
    assert types(msgs) == ["HIGHRES_IMU", "BAD_DATA"]
    assert report.skipped == [[len(a), 16, None]] and report.cut_at is None


def test_next_record_finds_the_nearer_marker_eight_bytes_back() -> None:
    """The next record starts 8 bytes before the nearer of FD/FE; with none, the end (or 8 short of it)."""
    buf = bytes(12) + b"\xfe" + bytes(5) + b"\xfd" + bytes(30)
    assert replay._next_record(buf, 1) == 4
    assert replay._next_record(buf, 5) == 10
    assert replay._next_record(bytes(40), 1) == 40
    assert replay._next_record(bytes(40), 1, eof=False) == 32
    assert replay._next_record(bytes(40), 35, eof=False) == 35
    assert replay._next_record(bytes(8) + b"\xfd", 0) == 0


def test_tlog_longer_than_the_read_chunk_is_read_whole(tmp_path: Path) -> None:
    """Records straddling the 1 MiB read boundary are read in order, none lost."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    recs = [rec(i, imu_frame(mav, i)) for i in range(256)]
    one = b"".join(recs)
    n = (1 << 20) // len(one) + 1
    msgs, report = read_all(write(tmp_path, "a.tlog", one * n))
    assert len(msgs) == 256 * n and not report.damaged
    assert [m.time_usec for _, m in msgs[:3]] == [0, 1, 2] and msgs[-1][1].time_usec == 255


# -- ULog ---------------------------------------------------------------------------------------

ULOG_TYPES = {"uint64_t": "Q", "int32_t": "i", "uint8_t": "B", "float": "f", "double": "d", "uint16_t": "H"}


def ulog_msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def ulog(topics: list[tuple[str, list[tuple[str, str]], list[tuple]]], multi: dict[str, int] | None = None) -> bytes:
    """A ULog (file format version 1): header, flag bits, one F and A per topic, then D rows by time."""
    out = bytearray(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0))
    out += ulog_msg(b"B", bytes(40))
    for name, fields, _ in topics:
        text = name + ":" + "".join(f"{t} {f};" for t, f in fields)
        out += ulog_msg(b"F", text.encode())
    rows = []
    for msg_id, (name, fields, data) in enumerate(topics):
        out += ulog_msg(b"A", struct.pack("<BH", (multi or {}).get(name, 0), msg_id) + name.encode())
        code = "<" + "".join(f"{n}{ULOG_TYPES[t.split('[')[0]]}" if "[" in t else ULOG_TYPES[t]
                             for t, _ in fields for n in ([int(t.split("[")[1][:-1])] if "[" in t else [""]))
        for row in data:
            rows.append((row[0], msg_id, struct.pack("<H", msg_id) + struct.pack(code, *row)))
    for _, _, payload in sorted(rows, key=lambda r: (r[0], r[1])):
        out += ulog_msg(b"D", payload)
    return bytes(out)


SC = ("sensor_combined", [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"), ("float[3]", "accelerometer_m_s2")])


def sc_rows(times: list[int]) -> list[tuple]:
    return [(t, 0.5, -0.25, 0.125, 1.5, -2.0, -9.75) for t in times]


def test_ulog_sensor_combined_is_highres_imu_on_its_timestamps(tmp_path: Path) -> None:
    """sensor_combined gyro_rad (rad/s) and accelerometer_m_s2 go out unchanged; timestamp (us) is time_usec."""
    data = ulog([(*SC, sc_rows([1000, 2000, 3000, 4000]))])
    msgs, report = read_all(write(tmp_path, "a.ulg", data))
    assert [(f, m.time_usec, m.id) for f, m in msgs] == [(0.25, 1000, 0), (0.5, 2000, 0), (0.75, 3000, 0),
                                                         (1.0, 4000, 0)]
    m = msgs[0][1]
    assert (m.xgyro, m.ygyro, m.zgyro, m.xacc, m.yacc, m.zacc) == (0.5, -0.25, 0.125, 1.5, -2.0, -9.75)
    assert m.fields_updated == ACC_GYRO and not report.damaged


GPS_OLD = ("vehicle_gps_position", [("uint64_t", "timestamp"), ("int32_t", "lat"), ("int32_t", "lon"),
                                    ("int32_t", "alt"), ("int32_t", "alt_ellipsoid"), ("float", "s_variance_m_s"),
                                    ("float", "eph"), ("float", "epv"), ("float", "hdop"), ("float", "vdop"),
                                    ("float", "vel_m_s"), ("float", "cog_rad"), ("uint8_t", "fix_type"),
                                    ("uint8_t", "satellites_used")])


def test_ulog_vehicle_gps_position_up_to_v1_13(tmp_path: Path) -> None:
    """lat/lon int32 1e-7 deg, alt/alt_ellipsoid int32 mm, eph/epv m, vel_m_s, cog_rad, published before the IMU."""
    gps = [(2000, 473977418, 85455939, 488500, 536250, 0.25, 1.5, 2.5, 0.75, 1.25, 3.0, math.pi / 2, 3, 12)]
    data = ulog([(*SC, sc_rows([1000, 2000, 3000])), (*GPS_OLD, gps)])
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    assert [(f, m.get_type(), m.time_usec) for f, m in msgs] == [
        (pytest.approx(1 / 3), "HIGHRES_IMU", 1000), (pytest.approx(1 / 3), "GPS_RAW_INT", 2000),
        (pytest.approx(2 / 3), "HIGHRES_IMU", 2000), (1.0, "HIGHRES_IMU", 3000)]
    g = msgs[1][1]
    assert (g.lat, g.lon, g.alt, g.alt_ellipsoid, g.fix_type, g.satellites_visible) == (
        473977418, 85455939, 488500, 536250, 3, 12)
    assert (g.h_acc, g.v_acc, g.vel_acc, g.eph, g.epv, g.vel, g.cog) == (1500, 2500, 250, 75, 125, 300, 9000)


def test_ulog_sensor_gps_from_v1_14_in_degrees_and_metres(tmp_path: Path) -> None:
    """latitude_deg/longitude_deg float64 deg, altitude_msl_m/altitude_ellipsoid_m float64 m."""
    fields = [("uint64_t", "timestamp"), ("double", "latitude_deg"), ("double", "longitude_deg"),
              ("double", "altitude_msl_m"), ("double", "altitude_ellipsoid_m"), ("uint8_t", "fix_type")]
    data = ulog([(*SC, sc_rows([1000, 2000])), ("sensor_gps", fields, [(1500, 47.25, -8.5, 488.5, 536.25, 4)])])
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    g = [m for _, m in msgs if m.get_type() == "GPS_RAW_INT"][0]
    assert (g.time_usec, g.lat, g.lon, g.alt, g.alt_ellipsoid, g.fix_type) == (
        1500, 472500000, -85000000, 488500, 536250, 4)
    assert (g.h_acc, g.eph, g.vel, g.cog, g.satellites_visible) == (0, 65535, 65535, 65535, 255)


def test_ulog_gps_that_no_field_can_hold_is_counted(tmp_path: Path) -> None:
    """A NaN latitude is left out and counted under the topic's name."""
    fields = [("uint64_t", "timestamp"), ("double", "latitude_deg"), ("double", "longitude_deg"),
              ("double", "altitude_msl_m"), ("uint8_t", "fix_type")]
    data = ulog([(*SC, sc_rows([1000])), ("sensor_gps", fields, [(500, math.nan, 8.5, 400.0, 3)])])
    msgs, report = read_all(write(tmp_path, "a.ulg", data))
    assert types(msgs) == ["HIGHRES_IMU"] and report.rejected == {"sensor_gps": 1}


BARO = ("sensor_baro", [("uint64_t", "timestamp"), ("float", "pressure"), ("float", "temperature")])


def test_ulog_sensor_baro_hpa_below_2000_and_pa_from_2000(tmp_path: Path) -> None:
    """sensor_baro pressure under 2000 is hPa (up to v1.12), from 2000 up it is Pa (v1.13)."""
    rows = [(100, 1013.25, 21.5), (200, 1999.0, 0.0), (300, 2000.0, 0.0), (400, 101325.0, -5.25)]
    data = ulog([(*SC, sc_rows([1000])), (*BARO, rows)])
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    got = [(m.time_boot_ms, m.press_abs, m.temperature) for _, m in msgs if m.get_type() == "SCALED_PRESSURE"]
    assert got == [(0, 1013.25, 2150), (0, 1999.0, 0), (0, 20.0, 0), (0, 1013.25, -525)]


def test_ulog_vehicle_air_data_uses_its_sample_time(tmp_path: Path) -> None:
    """vehicle_air_data baro_pressure_pa (Pa) and baro_temp_celcius, stamped timestamp_sample (us)."""
    fields = [("uint64_t", "timestamp"), ("uint64_t", "timestamp_sample"), ("float", "baro_pressure_pa"),
              ("float", "baro_temp_celcius")]
    data = ulog([(*SC, sc_rows([9000])), ("vehicle_air_data", fields, [(8000, 6999, 95000.0, 12.5)])])
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    assert [(m.get_type(), getattr(m, "time_boot_ms", None)) for _, m in msgs][0] == ("SCALED_PRESSURE", 6)
    b = msgs[0][1]
    assert (b.press_abs, b.temperature) == (950.0, 1250)


MAG = ("vehicle_magnetometer", [("uint64_t", "timestamp"), ("float[3]", "magnetometer_ga")])


def test_ulog_magnetometer_rides_on_imu_samples_from_its_time(tmp_path: Path) -> None:
    """vehicle_magnetometer (gauss) is on every IMU sample at or after its timestamp; NaN ends it, counted."""
    rows = [(2000, 0.25, -0.5, 0.125), (4000, math.nan, 0.0, 0.0)]
    data = ulog([(*SC, sc_rows([1000, 2000, 3000, 4000, 5000])), (*MAG, rows)])
    msgs, report = read_all(write(tmp_path, "a.ulg", data))
    got = [(m.time_usec, m.fields_updated, m.xmag, m.ymag, m.zmag) for _, m in msgs]
    assert got == [(1000, ACC_GYRO, 0.0, 0.0, 0.0), (2000, ACC_GYRO | MAG_BITS, 0.25, -0.5, 0.125),
                   (3000, ACC_GYRO | MAG_BITS, 0.25, -0.5, 0.125), (4000, ACC_GYRO, 0.0, 0.0, 0.0),
                   (5000, ACC_GYRO, 0.0, 0.0, 0.0)]
    assert report.rejected == {"vehicle_magnetometer": 1}


def test_ulog_sensor_mag_xyz(tmp_path: Path) -> None:
    """sensor_mag x/y/z (gauss) when there is no vehicle_magnetometer; instance 1 is not used."""
    fields = [("uint64_t", "timestamp"), ("float", "x"), ("float", "y"), ("float", "z")]
    data = ulog([(*SC, sc_rows([1000, 2000])), ("sensor_mag", fields, [(1500, 0.5, 0.25, -0.75)]),
                 ("vehicle_magnetometer", MAG[1], [(1500, 0.125, 0.125, 0.125)])], multi={"vehicle_magnetometer": 1})
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    assert [(m.xmag, m.ymag, m.zmag) for _, m in msgs] == [(0.0, 0.0, 0.0), (0.5, 0.25, -0.75)]


def test_ulog_without_sensor_combined_is_refused(tmp_path: Path) -> None:
    """A ULog with no sensor_combined rows is a DataFileError naming the topic."""
    data = ulog([(*BARO, [(100, 1013.25, 21.5)])])
    with pytest.raises(DataFileError, match="sensor_combined"):
        read_all(write(tmp_path, "a.ulg", data))


# -- the report -----------------------------------------------------------------------------------


def test_report_merges_adjacent_stretches_and_ignores_empty_ones() -> None:
    """A stretch starting where the last ended extends it; a zero or negative length is no stretch."""
    r = LogReport(Path("x.bin"), 1000)
    r.skip(10, 0)
    r.skip(10, -1)
    assert r.skipped == [] and not r.damaged
    r.skip(10, 5)
    r.skip(15, 1)
    r.skip(17, 2)
    assert r.skipped == [[10, 6, None], [17, 2, None]] and r.skipped_bytes == 8 and r.damaged


def test_report_lines_name_places_times_and_the_cut() -> None:
    """The warning counts bytes and places, shows the first three with their sensor time, and the cut."""
    r = LogReport(Path("x.bin"), 1000)
    assert r.lines() == []
    r.skipped = [[10, 5, None]]
    assert r.lines() == ["x.bin: skipped 5 unreadable bytes (0.5 % of the file) in 1 place: byte 10 (5 bytes, "
                         "before the first IMU sample)"]
    r.skipped = [[10, 5, None], [20, 5, 1.5], [30, 5, 2.0], [40, 5, 3.25]]
    r.cut_at = 900
    r.notes.append("a note")
    assert r.lines() == [
        "x.bin: skipped 20 unreadable bytes (2 % of the file) in 4 places: byte 10 (5 bytes, before the first IMU "
        "sample), byte 20 (5 bytes, after sensor time 1.500 s), byte 30 (5 bytes, after sensor time 2.000 s) and 1 "
        "more",
        "x.bin: the log ends early: its last record, from byte 900 to the end (100 bytes), is incomplete (a cut or "
        "unfinished file)",
        "x.bin: a note"]
    four = r.skipped
    r.skipped = four[:2]
    assert " in 2 places: " in r.lines()[0]
    r.skipped = four[:3]
    assert r.lines()[0].endswith("after sensor time 2.000 s)")


def test_report_counts_are_ordered_by_count_then_name() -> None:
    """Rejected kinds are listed most first, ties by name, five shown and the rest counted."""
    c = {"b": 1, "a": 1, "c": 3, "d": 2, "e": 1, "f": 1, "g": 5}
    assert replay._counts(c) == "5 g, 3 c, 2 d, 1 a, 1 b and 2 more types"
    assert replay._counts({"a": 1}, shown=1) == "1 a"


# -- opening -------------------------------------------------------------------------------------


def test_open_log_refuses_missing_empty_unknown_and_mislabelled_files(tmp_path: Path) -> None:
    """Missing, empty, unknown suffix and a .bin that does not start with A3 95 are refused at once."""
    with pytest.raises(DataFileError, match="no such file"):
        open_log(tmp_path / "none.bin")
    with pytest.raises(DataFileError, match="unknown log type '.csv'"):
        open_log(write(tmp_path, "a.csv", b"x"))
    with pytest.raises(DataFileError, match="the file is empty"):
        open_log(write(tmp_path, "a.bin", b""))
    with pytest.raises(DataFileError, match="starting with bytes a3 95, found bytes 00 01 02 03 04 05 06 07$"):
        open_log(write(tmp_path, "b.bin", bytes(range(20))))
    with pytest.raises(DataFileError, match=r"found an ArduPilot DataFlash log \(rename it to .bin\)$"):
        open_log(write(tmp_path, "c.ulg", df_head()))
    msgs, _ = read_all(write(tmp_path, "D.BIN", df_head() + df_imu(1)))
    assert types(msgs) == ["HIGHRES_IMU"]


# -- field ranges of the MAVLink messages ----------------------------------------------------------


def codec() -> tuple[mavlink.MAVLink, mavlink.MAVLink]:
    return mavlink.MAVLink(None, srcSystem=1, srcComponent=1), replay._decoder()


def fix(**kw: float) -> mavlink.MAVLink_message:
    enc, dec = codec()
    args = dict(t_us=0, fix_type=0, lat_deg=0.0, lon_deg=0.0, alt_msl_m=0.0, alt_ellipsoid_m=None, h_acc_m=0.0,
                v_acc_m=0.0, vel_m_s=0.0, cog_deg=0.0, vel_acc_m_s=0.0, hdop=0.0, vdop=0.0, satellites=0)
    args.update(kw)
    return replay.gps_raw_int(enc, dec, **args)


def test_gps_raw_int_zero_fix_is_all_zero() -> None:
    """Zeros in every field stay zeros (0 is inside every field's range)."""
    g = fix()
    assert (g.time_usec, g.fix_type, g.lat, g.lon, g.alt, g.eph, g.epv, g.vel, g.cog, g.satellites_visible,
            g.alt_ellipsoid, g.h_acc, g.v_acc, g.vel_acc) == (0,) * 14


def test_gps_raw_int_field_ranges_at_their_ends() -> None:
    """Each integer field takes its type's extremes; one step beyond is an error or the field's 'unknown'."""
    top = fix(t_us=2**53, fix_type=255, lat_deg=(2**31 - 1) / 1e7, lon_deg=(2**31 - 1) / 1e7,
              alt_msl_m=(2**31 - 1) / 1e3, alt_ellipsoid_m=(2**31 - 1) / 1e3, h_acc_m=(2**32 - 1) / 1e3,
              v_acc_m=(2**32 - 1) / 1e3, vel_acc_m_s=(2**32 - 1) / 1e3, vel_m_s=655.34, cog_deg=359.99,
              hdop=655.35, vdop=655.35, satellites=255)
    assert (top.time_usec, top.fix_type, top.lat, top.lon, top.alt, top.alt_ellipsoid) == (
        2**53, 255, 2**31 - 1, 2**31 - 1, 2**31 - 1, 2**31 - 1)
    assert (top.h_acc, top.v_acc, top.vel_acc, top.vel, top.cog, top.eph, top.epv, top.satellites_visible) == (
        2**32 - 1, 2**32 - 1, 2**32 - 1, 65534, 35999, 65535, 65535, 255)
    low = fix(lat_deg=-2**31 / 1e7, lon_deg=-2**31 / 1e7, alt_msl_m=-2**31 / 1e3, alt_ellipsoid_m=-2**31 / 1e3)
    assert (low.lat, low.lon, low.alt, low.alt_ellipsoid) == (-2**31, -2**31, -2**31, -2**31)
    assert fix(vel_m_s=655.36).vel == 65535
    beyond = fix(alt_ellipsoid_m=2**31 / 1e3, h_acc_m=2**32 / 1e3, v_acc_m=2**32 / 1e3, vel_acc_m_s=2**32 / 1e3,
                 vel_m_s=655.35, cog_deg=359.996, hdop=655.36, vdop=-0.01, satellites=256)
    assert (beyond.alt_ellipsoid, beyond.h_acc, beyond.v_acc, beyond.vel_acc, beyond.vel, beyond.cog, beyond.eph,
            beyond.epv, beyond.satellites_visible) == (0, 0, 0, 0, 65535, 65535, 65535, 65535, 255)
    assert fix(alt_msl_m=-1.0).alt == -1000
    assert (fix(alt_ellipsoid_m=-2**31 / 1e3 - 0.001).alt_ellipsoid, fix(satellites=-1).satellites_visible) == (0, 255)
    assert (fix(cog_deg=-90.0).cog, fix(cog_deg=360.0).cog, fix(vel_acc_m_s=2.0).vel_acc) == (27000, 0, 2000)
    for kw in [dict(t_us=-1), dict(t_us=2**64), dict(fix_type=256), dict(fix_type=-1), dict(lat_deg=2**31 / 1e7),
               dict(lat_deg=(-2**31 - 1) / 1e7), dict(lon_deg=2**31 / 1e7), dict(lon_deg=(-2**31 - 1) / 1e7),
               dict(alt_msl_m=2**31 / 1e3), dict(alt_msl_m=(-2**31 - 1) / 1e3), dict(lat_deg=math.nan)]:
        with pytest.raises(replay.PACK_ERRORS):
            fix(**kw)


def test_scaled_pressure_ranges_at_their_ends() -> None:
    """Any positive pressure is sent; temperature cdegC fits int16 or is 0; time_boot_ms is the IMU clock's
    milliseconds modulo 2^32 (uint32, as an autopilot with a UNIX-time clock sends it: PX4 SITL), so a
    time past 2^32 ms wraps instead of losing the barometer; a negative time is refused."""
    enc, dec = codec()
    b = replay.scaled_pressure(enc, dec, (2**32 - 1) * 1000 + 999, 0.5, -327.68)
    assert (b.time_boot_ms, b.press_abs, b.press_diff, b.temperature) == (2**32 - 1, pytest.approx(0.005), 0.0, -32768)
    assert replay.scaled_pressure(enc, dec, 2**32 * 1000, 1.0, 0.0).time_boot_ms == 0
    sitl_us = 1_732_838_400_123_456  # 2024-11-29T00:00:00.123456Z in us
    assert replay.scaled_pressure(enc, dec, sitl_us, 1.0, 0.0).time_boot_ms == 1_732_838_400_123 % 2**32
    assert replay.scaled_pressure(enc, dec, 0, 1.0, 327.67).temperature == 32767
    assert replay.scaled_pressure(enc, dec, 0, 1.0, 327.68).temperature == 0
    assert replay.scaled_pressure(enc, dec, 0, 1.0, -327.69).temperature == 0
    for t_us, p in [(-1000, 1.0), (0, 0.0), (0, -1.0), (0, math.inf), (0, math.nan)]:
        with pytest.raises(ValueError):
            replay.scaled_pressure(enc, dec, t_us, p, 0.0)


def test_dataflash_messages_come_from_the_autopilot_with_nothing_else_set(tmp_path: Path) -> None:
    """Made-up messages are from system 1, component 1 (MAV_COMP_ID_AUTOPILOT1); pressure fields stay 0."""
    data = df_head() + df_gps(1) + df_imu(2)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    assert [(m.get_srcSystem(), m.get_srcComponent()) for _, m in msgs] == [(1, 1), (1, 1)]
    m = msgs[1][1]
    assert (m.abs_pressure, m.diff_pressure, m.pressure_alt, m.temperature) == (0.0, 0.0, 0.0, 0.0)


def test_dataflash_rejected_records_are_counted_one_by_one(tmp_path: Path) -> None:
    """Each GPS with an altitude beyond int32 mm (Alt in cm) and each BARO with no pressure counts once."""
    bad_baro = df_record(133, BARO_FMT, 1, 0, 0.0, 0)
    data = df_head() + df_gps(1, alt_cm=2**31 - 1) + df_gps(2, alt_cm=-2**31) + bad_baro + bad_baro + df_imu(3)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert types(msgs) == ["HIGHRES_IMU"] and report.rejected == {"GPS": 2, "BARO": 2}


def test_dataflash_three_byte_tail_of_an_unknown_type_is_skipped(tmp_path: Path) -> None:
    """A last A3 95 with an unknown type is three skipped bytes; of a known type it is a cut."""
    head = df_head() + df_imu(1)
    _, report = read_all(write(tmp_path, "a.bin", head + b"\xa3\x95\x00"))
    assert report.skipped == [[len(head), 3, None]] and report.cut_at is None
    _, report = read_all(write(tmp_path, "b.bin", head + b"\xa3\x95\x82"))
    assert report.skipped == [] and report.cut_at == len(head)


@pytest.mark.parametrize("tail", [b"\xa3", b"\xa3\x95\x82\x00"])
def test_dataflash_gps_waiting_for_its_gpa_is_sent_when_the_log_is_cut(tmp_path: Path, tail: bytes) -> None:
    """A cut after a GPS record still sends the GPS."""
    msgs, report = read_all(write(tmp_path, "a.bin", df_head() + df_gps(1) + tail))
    assert types(msgs) == ["GPS_RAW_INT"] and report.cut_at == len(df_head()) + GPS_LEN


def test_dataflash_one_junk_byte_before_a_record(tmp_path: Path) -> None:
    """A single junk byte is skipped and the record right after it is read."""
    head = df_head()
    msgs, report = read_all(write(tmp_path, "a.bin", head + b"\x00" + df_imu(1)))
    assert [m.time_usec for _, m in msgs] == [1] and report.skipped == [[len(head), 1, None]]


def test_dataflash_fmt_with_non_ascii_name_is_read_past(tmp_path: Path) -> None:
    """An FMT whose name, format or columns are not ASCII is a record of no use; reading goes on."""
    odd = df_record(128, "BB4s16s64s", 140, 4, b"\xff\xfe", b"B\xff", b"\xfeX")
    msgs, report = read_all(write(tmp_path, "a.bin", FMT_OF_FMT + odd + df_head()[FMT_LEN:] + df_imu(1)))
    assert [m.time_usec for _, m in msgs] == [1] and not report.damaged


def test_dataflash_imu_with_signed_time_and_double_or_half_floats(tmp_path: Path) -> None:
    """TimeUS of format q and an instance of format b are integers; gyro d and accel g (half) are floats."""
    fmt = "qbdddggg"
    data = FMT_OF_FMT + df_fmt(130, "IMU", fmt, IMU_COLS) + df_record(130, fmt, 77, 3, 0.5, 0.25, -0.5, 1.5, 2.0, -9.75)
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    m = msgs[0][1]
    assert (m.time_usec, m.id, m.xgyro, m.zgyro, m.xacc, m.zacc) == (77, 3, 0.5, -0.5, 1.5, -9.75)


@pytest.mark.parametrize("fmt, cols", [("QBfy", "TimeUS,I,Press,X"), ("QBa", "TimeUS,I,Press"),
                                       ("NBf", "TimeUS,I,Press"), ("QNf", "TimeUS,I,Press")])
def test_dataflash_baro_fmt_with_text_or_unknown_columns_is_not_read(tmp_path: Path, fmt: str, cols: str) -> None:
    """A BARO whose time, instance or pressure is text, or with an unknown format character, is not read."""
    size = 3 + struct.calcsize(df_struct(fmt.replace("y", "B").replace("a", "64s")))
    data = FMT_OF_FMT + df_fmt(133, "BARO", fmt, cols, length=size) + b"\xa3\x95\x85" + bytes(size - 3)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    assert msgs == [] and not report.damaged


def test_dataflash_gps_fmt_redefined_without_lat_stops_gps(tmp_path: Path) -> None:
    """A later GPS FMT of the same type without Lat is not read as GPS."""
    again = df_fmt(131, "GPS", GPS_FMT, GPS_COLS.replace("Lat", "Lxx"))
    msgs, _ = read_all(write(tmp_path, "a.bin", df_head() + df_gps(1) + again + df_gps(2)))
    assert [m.time_usec for _, m in msgs] == [1]


def v1_heartbeat() -> bytes:
    """A MAVLink 1 HEARTBEAT (FE, len 9, seq, sys, comp, id 0, payload, X.25 CRC with crc_extra 50)."""
    body = bytes([9, 0, 1, 1, 0]) + struct.pack("<IBBBBB", 0, 2, 12, 0, 4, 3)
    crc = mavlink.x25crc(body)
    crc.accumulate(bytes([50]))
    return b"\xfe" + body + struct.pack("<H", crc.crc)


def test_tlog_mavlink1_frame_is_eight_bytes_plus_payload(tmp_path: Path) -> None:
    """A MAVLink 1 record between two MAVLink 2 records is decoded, none skipped."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    data = rec(1, imu_frame(mav, 100)) + rec(2, v1_heartbeat()) + rec(3, imu_frame(mav, 200))
    msgs, report = read_all(write(tmp_path, "a.tlog", data))
    assert types(msgs) == ["HIGHRES_IMU", "HEARTBEAT", "HIGHRES_IMU"] and not report.damaged


def test_tlog_shorter_than_one_record_is_a_cut_at_byte_0(tmp_path: Path) -> None:
    """A tlog of 5 bytes holds no record: it ends inside one at byte 0."""
    msgs, report = read_all(write(tmp_path, "a.tlog", b"\x00\x00\x00\x00\x01"))
    assert msgs == [] and report.cut_at == 0


def test_tlog_damage_beyond_the_first_read_chunk_is_located_in_the_file(tmp_path: Path) -> None:
    """Junk and a cut after the first 1 MiB are reported at their byte offsets in the file."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    one = b"".join(rec(i, imu_frame(mav, i)) for i in range(256))
    body = one * ((1 << 20) // len(one) + 1)
    tail = rec(9, imu_frame(mav, 9))
    data = body + b"\x00" * 20 + tail + tail[:10]
    msgs, report = read_all(write(tmp_path, "a.tlog", data))
    assert report.skipped == [[len(body), 20, None]]
    assert report.cut_at == len(body) + 20 + len(tail)
    _, report = read_all(write(tmp_path, "b.tlog", body + tail[:-1]))
    assert report.cut_at == len(body) and report.skipped == []


def test_ulog_old_gps_without_ellipsoid_height_and_counted_rejects(tmp_path: Path) -> None:
    """A vehicle_gps_position without alt_ellipsoid sends 0 (not given); two NaN fixes count 2."""
    fields = [("uint64_t", "timestamp"), ("int32_t", "lat"), ("int32_t", "lon"), ("int32_t", "alt"),
              ("uint8_t", "fix_type")]
    rows = [(100, 473977418, 85455939, 488500, 3)]
    data = ulog([(*SC, sc_rows([1000])), ("vehicle_gps_position", fields, rows)])
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    g = msgs[0][1]
    assert (g.get_type(), g.alt, g.alt_ellipsoid, g.fix_type) == ("GPS_RAW_INT", 488500, 0, 3)
    assert (g.get_srcSystem(), g.get_srcComponent()) == (1, 1)
    new = [("uint64_t", "timestamp"), ("double", "latitude_deg"), ("double", "longitude_deg"),
           ("double", "altitude_msl_m"), ("uint8_t", "fix_type")]
    data = ulog([(*SC, sc_rows([1000])), ("sensor_gps", new, [(1, math.nan, 0.0, 0.0, 3), (2, 0.0, math.nan, 0.0, 3)]),
                 (*BARO, [(3, -1.0, 0.0), (4, math.nan, 0.0)]), (*MAG, [(5, math.nan, 0.0, 0.0)])])
    msgs, report = read_all(write(tmp_path, "b.ulg", data))
    assert types(msgs) == ["HIGHRES_IMU"]
    assert report.rejected == {"sensor_gps": 2, "sensor_baro": 2, "vehicle_magnetometer": 1}


def test_ulog_gps_topic_without_rows_or_fix_type_is_passed_over(tmp_path: Path) -> None:
    """vehicle_gps_position with no rows, or without fix_type, gives way to sensor_gps."""
    new = [("uint64_t", "timestamp"), ("double", "latitude_deg"), ("double", "longitude_deg"),
           ("double", "altitude_msl_m"), ("uint8_t", "fix_type")]
    for i, old in enumerate([(GPS_OLD[0], GPS_OLD[1], []),
                             ("vehicle_gps_position", [f for f in GPS_OLD[1] if f[1] != "fix_type"],
                              [(50, 1, 1, 1, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 9)])]):
        data = ulog([(*SC, sc_rows([1000])), old, ("sensor_gps", new, [(100, 1.5, 2.5, 3.5, 3)])])
        msgs, _ = read_all(write(tmp_path, f"{i}.ulg", data))
        assert [(m.get_type(), getattr(m, "lat", None)) for _, m in msgs] == [("GPS_RAW_INT", 15000000),
                                                                              ("HIGHRES_IMU", None)]


def test_ulog_dropouts_are_noted_with_their_total_time(tmp_path: Path) -> None:
    """Two logger dropout messages ('O', duration ms) are one note with their count and sum."""
    data = ulog([(*SC, sc_rows([1000]))]) + ulog_msg(b"O", struct.pack("<H", 15)) + ulog_msg(b"O", struct.pack("<H", 10))
    _, report = read_all(write(tmp_path, "a.ulg", data))
    assert report.notes == ["note: the PX4 logger itself lost data 2 times (25 ms in all)"]


def test_ulog_cut_inside_a_header_or_before_a_payload(tmp_path: Path) -> None:
    """One byte of a message header, or a whole header without its payload, is a cut at that header."""
    full = ulog([(*SC, sc_rows([1000, 2000]))])
    _, report = read_all(write(tmp_path, "a.ulg", full))
    assert report.cut_at is None and not report.damaged
    _, report = read_all(write(tmp_path, "b.ulg", full + b"\x05"))
    assert report.cut_at == len(full)
    last = 3 + 2 + 8 + 24
    _, report = read_all(write(tmp_path, "c.ulg", full[:-last + 3]))
    assert report.cut_at == len(full) - last


def test_ulog_sensor_combined_lacking_fields_is_refused_by_name(tmp_path: Path) -> None:
    """sensor_combined without gyro_rad names the three missing fields."""
    data = ulog([("sensor_combined", [("uint64_t", "timestamp"), ("float[3]", "accelerometer_m_s2")],
                  [(1000, 0.0, 0.0, -9.75)])])
    with pytest.raises(DataFileError, match=r"lacks the field\(s\) gyro_rad\[0\], gyro_rad\[1\], gyro_rad\[2\]$"):
        read_all(write(tmp_path, "a.ulg", data))


def test_report_of_a_one_byte_file_is_100_percent() -> None:
    """One skipped byte of a one-byte file is 100 % of it."""
    r = LogReport(Path("x.tlog"), 1)
    r.skip(0, 1)
    assert "(1e+02 % of the file) in 1 place:" in r.lines()[0]


def test_made_up_frames_count_their_sequence_modulo_256(tmp_path: Path) -> None:
    """Each made-up frame takes the next MAVLink sequence number, 255 wrapping to 0."""
    data = df_head() + b"".join(df_imu(i) for i in range(258))
    msgs, _ = read_all(write(tmp_path, "a.bin", data))
    assert [m.get_seq() for _, m in msgs] == [i % 256 for i in range(258)]


def test_dataflash_gps_with_only_the_needed_columns(tmp_path: Path) -> None:
    """A GPS of TimeUS, Status, Lat, Lng, Alt only: speed, course and HDOP unknown, satellites 255."""
    fmt, cols = "QBLLe", "TimeUS,Status,Lat,Lng,Alt"
    data = FMT_OF_FMT + df_fmt(131, "GPS", fmt, cols) + df_record(131, fmt, 10, 3, 1, 2, 300)
    msgs, report = read_all(write(tmp_path, "a.bin", data))
    g = msgs[0][1]
    assert (g.lat, g.lon, g.alt, g.vel, g.cog, g.eph, g.satellites_visible) == (1, 2, 3000, 65535, 65535, 65535, 255)
    assert not report.rejected


def test_next_record_looks_for_markers_from_eight_bytes_on() -> None:
    """A marker before ``start + 8`` cannot start a record from ``start``."""
    assert replay._next_record(b"\xfd" + bytes(39), 1) == 40
    assert replay._next_record(b"\xfe" + bytes(39), 1) == 40


def test_ulog_magnetometer_without_its_fields_and_repeated_nan(tmp_path: Path) -> None:
    """A vehicle_magnetometer without magnetometer_ga is not used; each NaN sample counts once."""
    data = ulog([(*SC, sc_rows([1000])), ("vehicle_magnetometer", [("uint64_t", "timestamp"), ("float", "x")],
                                          [(500, 0.5)])])
    msgs, _ = read_all(write(tmp_path, "a.ulg", data))
    assert [m.fields_updated for _, m in msgs] == [ACC_GYRO]
    data = ulog([(*SC, sc_rows([1000, 2000])), (*MAG, [(500, math.nan, 0.0, 0.0), (1500, 0.0, math.nan, 0.0)])])
    _, report = read_all(write(tmp_path, "b.ulg", data))
    assert report.rejected == {"vehicle_magnetometer": 2}


# -- the command layer: replay() on small hand-written logs -----------------------------------------
#
# A vehicle at rest: HIGHRES_IMU with specific force (0, 0, -g) m/s^2 in FRD (gravity seen as an upward
# reaction) and no rotation, 100 Hz from sensor time 1.00 s. With --lat/--lon/--alt given, --align 0.5
# and --rate 10 the alignment ends at 1.50 s and rows follow at 10 Hz until the last sample at 1.99 s.

from mavins.live.livefilter import FilterSettings  # noqa: E402
from mavins.live.engine import EngineConfig  # noqa: E402
from mavins.link.ingest import IngestConfig  # noqa: E402

G_STD = 9.80665
AT_REST = dict(lat=10.0, lon=20.0, alt=30.0, align=0.5, heading=0.0, rate=10.0)
# docs/conventions.md: the navigation-solution columns, and the filter's after them (typed from the contract)
SOLUTION_HEADER = "t,lat,lon,h,vn,ve,vd,roll,pitch,yaw,qw,qx,qy,qz"
FILTER_HEADER = ("sigma_n,sigma_e,sigma_d,sigma_vn,sigma_ve,sigma_vd,sigma_att_n,sigma_att_e,sigma_att_d,"
                 "bg_x,bg_y,bg_z,ba_x,ba_y,ba_z,sigma_bg_x,sigma_bg_y,sigma_bg_z,sigma_ba_x,sigma_ba_y,sigma_ba_z")
NO_GNSS_NOTE = ("note: no GNSS message in the log (GPS_RAW_INT, GPS_INPUT, HIL_GPS; PX4 vehicle_gps_position/"
                "sensor_gps, ArduPilot GPS): the position is free inertial")
ANY_IMU = "IMU messages (HIGHRES_IMU, RAW_IMU, SCALED_IMU*)"


def rest_imu(mav: mavlink.MAVLink, t_us: int, gx: float = 0.0, imu_id: int = 0, az: float = -G_STD) -> bytes:
    m = mav.highres_imu_encode(t_us, 0.0, 0.0, az, gx, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, ACC_GYRO, imu_id)
    return rec(t_us, m.pack(mav))


def rest_records(n: int, first_us: int = 1_000_000, step_us: int = 10_000, **kw: float) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return b"".join(rest_imu(mav, first_us + k * step_us, **kw) for k in range(n))


def run(path: Path, out: Path | None = None, ingest: IngestConfig | None = None, **engine: float):
    return replay.replay(path, EngineConfig(**engine), ingest or IngestConfig(), out)


def test_replay_at_rest_writes_a_row_per_output_and_counts_everything(tmp_path: Path) -> None:
    """100 messages, first/last sensor time 1.00/1.99 s, one CSV row and one callback per output, the note."""
    log = write(tmp_path, "rest.tlog", rest_records(100))
    out = tmp_path / "nav.csv"
    seen = []
    res = replay.replay(log, EngineConfig(**AT_REST), IngestConfig(), out,
                        on_output=lambda sol, pipe: seen.append((float(sol.row[0]), pipe)))
    lines = out.read_text().splitlines()
    assert lines[0] == SOLUTION_HEADER + "," + FILTER_HEADER  # it aids (the default): the filter's columns too
    rows = [[float(x) for x in line.split(",")] for line in lines[1:]]
    # no fix: the position's 1-sigma starts at the filter's 10 m (docs/filter.md) and only grows
    assert all(len(r) == 35 and r[14] >= 10.0 and r[15] >= 10.0 and all(map(math.isfinite, r)) for r in rows)
    assert (res.messages, res.t_first, res.t_last) == (100, 1.0, 1.99)
    assert res.outputs == len(rows) == len(seen) and res.outputs >= 4  # at least 1.6, 1.7, 1.8, 1.9 s
    assert [t for t, _ in seen] == [r[0] for r in rows]
    assert all(p is res.pipeline for _, p in seen)
    assert all(1.5 <= r[0] <= 1.99 for r in rows) and [r[0] for r in rows] == sorted({r[0] for r in rows})
    assert all(abs(r[1] - 10.0) < 1e-6 and abs(r[2] - 20.0) < 1e-6 and abs(r[3] - 30.0) < 0.01 for r in rows)
    assert res.pipeline.engine.state.value == "NAVIGATING" and res.pipeline.ingest.accepted == 100
    assert res.pipeline.take_events() == []  # drained after every message
    assert res.aiding == {} and res.report is not None and res.report.notes == [NO_GNSS_NOTE]
    assert res.report.lines() == [f"{log}: {NO_GNSS_NOTE}"]


def test_replay_without_aiding_writes_the_solution_columns_only(tmp_path: Path) -> None:
    """--aiding none: no filter, the 14 solution columns (docs/conventions.md)."""
    log = write(tmp_path, "rest.tlog", rest_records(100))
    out = tmp_path / "nav.csv"
    replay.replay(log, EngineConfig(**AT_REST, filter=FilterSettings(aiding=())), IngestConfig(), out)
    lines = out.read_text().splitlines()
    assert lines[0] == SOLUTION_HEADER and all(len(line.split(",")) == 14 for line in lines[1:])


def test_replay_without_an_output_file_still_counts_outputs(tmp_path: Path) -> None:
    """With no -o the rows are counted all the same; nothing is written beside the log."""
    log = write(tmp_path, "rest.tlog", rest_records(100))
    res = run(log, **AT_REST)
    assert res.outputs >= 4 and res.messages == 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rest.tlog"]


def test_replay_counts_aiding_messages_by_type_and_needs_no_note_with_gnss(tmp_path: Path) -> None:
    """GPS_RAW_INT and SCALED_PRESSURE are counted by type (HEARTBEAT is not); a GNSS fix gives the position."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    gps = [mav.gps_raw_int_encode(t, 3, 100_000_000, 200_000_000, 30_000, 100, 150, 0, 0, 10) for t in
           (1_000_000, 1_500_000)]
    baro = [mav.scaled_pressure_encode(t_ms, 1013.25, 0.0, 2000) for t_ms in (1000, 1250, 1500)]
    data = rec(1, v1_heartbeat())
    for k in range(100):
        t = 1_000_000 + k * 10_000
        data += b"".join(rec(t, m.pack(mav)) for m in gps if m.time_usec == t)
        data += b"".join(rec(t, m.pack(mav)) for m in baro if m.time_boot_ms * 1000 == t)
        data += rest_imu(mav, t)
    log = write(tmp_path, "aided.tlog", data)
    res = run(log, align=0.5, heading=0.0, rate=10.0)
    assert res.aiding == {"GPS_RAW_INT": 2, "SCALED_PRESSURE": 3}
    assert res.messages == 1 + 2 + 3 + 100 and res.outputs >= 4
    assert res.report.notes == [] and res.report.lines() == []


def test_replay_places_damage_at_the_sensor_time_before_it(tmp_path: Path) -> None:
    """Junk before the first IMU sample has no time; junk after sample k has sample k's time (s)."""
    first, second = rest_records(50), rest_records(50, first_us=1_500_000)
    junk = b"\x01" * 20
    log = write(tmp_path, "d.tlog", junk + first + junk + second)
    res = run(log, **AT_REST)
    assert res.report.skipped == [[0, 20, None], [20 + len(first), 20, 1.49]]
    assert res.report.lines()[0] == (
        f"{log}: skipped 40 unreadable bytes ({100 * 40 / (40 + 2 * len(first)):.2g} % of the file) in 2 places: "
        f"byte 0 (20 bytes, before the first IMU sample), byte {20 + len(first)} (20 bytes, after sensor time "
        "1.490 s)")
    assert res.messages == 2 + 100  # each stretch of junk is one BAD_DATA


def test_replay_places_damage_after_the_last_message_at_the_last_sample(tmp_path: Path) -> None:
    """DataFlash junk at the very end yields no message: it gets the time of the last IMU sample."""
    imus = b"".join(df_imu(1_000_000 + k * 10_000, gyr=(0.0, 0.0, 0.0), acc=(0.0, 0.0, -G_STD)) for k in range(100))
    head = df_head() + imus
    log = write(tmp_path, "d.bin", head + b"\x01\x02\x03\x04")
    res = run(log, **AT_REST)
    assert res.report.skipped == [[len(head), 4, 1.99]]
    assert (res.messages, res.t_first, res.t_last) == (100, 1.0, 1.99)


def test_replay_refuses_an_output_that_is_the_log_or_the_rerun_file(tmp_path: Path) -> None:
    """-o onto the log, or -o and --rerun onto one file, is refused before reading; the log stays."""
    data = rest_records(10)
    log = write(tmp_path, "rest.tlog", data)
    with pytest.raises(DataFileError) as e:
        run(log, log, **AT_REST)
    assert str(e.value) == (f"{log}: -o is also the input LOG: writing it would destroy the input; choose another "
                            "output file")
    out = tmp_path / "o.csv"
    with pytest.raises(DataFileError) as e:
        replay.replay(log, EngineConfig(**AT_REST), IngestConfig(), out, rerun=out)
    assert str(e.value) == f"{out}: -o and --rerun name the same file; choose two files"
    assert log.read_bytes() == data and not out.exists()


def test_iter_log_gives_the_messages_of_open_log(tmp_path: Path) -> None:
    """iter_log is the message stream alone, in file order, with the fraction read."""
    log = write(tmp_path, "r.tlog", rest_records(3))
    got = [(f, m.time_usec) for f, m in replay.iter_log(log)]
    n = len(rest_records(1))
    assert got == [(n / (3 * n), 1_000_000), (2 / 3, 1_010_000), (1.0, 1_020_000)]
    with pytest.raises(DataFileError, match="no such file"):
        replay.iter_log(tmp_path / "none.tlog")


# -- why no IMU sample was accepted (_no_imu) ----------------------------------------------------------


def no_imu(path: Path, ingest: IngestConfig | None = None) -> str:
    out = path.parent / "never.csv"
    with pytest.raises(DataFileError) as e:
        run(path, out, ingest, **AT_REST)
    assert not out.exists()  # nothing written on failure
    return str(e.value)


def unknown_frame() -> bytes:
    """A MAVLink 2 frame of message id 9999 (in no dialect): pymavlink decodes it as UNKNOWN_9999."""
    return b"\xfd\x00\x00\x00\x00\x01\x01\x0f\x27\x00\x00\x00"


def test_no_imu_lists_the_messages_the_log_holds(tmp_path: Path) -> None:
    """BAD_DATA and UNKNOWN_* are not named; the others are counted by type."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    baro = mav.scaled_pressure_encode(5, 1000.0, 0.0, 0).pack(mav)
    data = (rec(1, v1_heartbeat()) + rec(2, unknown_frame()) + b"\x01" * 20 + rec(3, v1_heartbeat())
            + rec(4, baro) + rec(5, v1_heartbeat()))
    log = write(tmp_path, "hb.tlog", data)
    assert no_imu(log) == f"{log}: expected {ANY_IMU}, found none among 4 messages (3 HEARTBEAT, 1 SCALED_PRESSURE)"


def test_no_imu_in_a_tlog_of_junk(tmp_path: Path) -> None:
    """A tlog of which no byte is a frame: the size is named."""
    log = write(tmp_path, "j.tlog", bytes(range(1, 40)))
    assert no_imu(log) == f"{log}: expected a MAVLink telemetry log (.tlog), found no valid MAVLink message in 39 bytes"


def test_no_imu_in_a_dataflash_log_names_its_unreadable_bytes(tmp_path: Path) -> None:
    """A DataFlash log of FMTs only; and one with 5 bytes that are no record."""
    head = df_head()
    log = write(tmp_path, "f.bin", head)
    want = f"expected an ArduPilot DataFlash log (.bin) with {ANY_IMU}, found no IMU record in {len(head)} bytes"
    assert no_imu(log) == f"{log}: {want}"
    log = write(tmp_path, "g.bin", head + b"\x01\x02\x03\x04\x05")
    want = f"with {ANY_IMU}, found no IMU record in {len(head) + 5} bytes (5 bytes are no DataFlash record)"
    assert no_imu(log) == f"{log}: expected an ArduPilot DataFlash log (.bin) {want}"


def test_no_imu_in_a_dataflash_log_with_a_gps_only(tmp_path: Path) -> None:
    """The made-up GPS_RAW_INT is what the log holds."""
    log = write(tmp_path, "g.bin", df_head() + df_gps(1))
    assert no_imu(log) == f"{log}: expected {ANY_IMU}, found none among 1 messages (1 GPS_RAW_INT)"


def test_no_imu_names_the_imu_streams_that_were_not_chosen(tmp_path: Path) -> None:
    """The wanted kind, id and system, and the IMU streams found (3 shown) with the rejection reasons."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    other = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    raw = other.raw_imu_encode(1, 0, 0, 1000, 0, 0, 0, 0, 0, 0, 2, 0)
    data = b"".join(rest_imu(mav, t, imu_id=4) for t in (1, 2, 3)) + rec(4, raw.pack(other)) + rec(5, raw.pack(other))
    data += rec(6, mav.scaled_imu_encode(6, 0, 0, 1000, 0, 0, 0, 0, 0, 0, 0).pack(mav))
    data += rec(7, mav.scaled_imu2_encode(7, 0, 0, 1000, 0, 0, 0, 0, 0, 0, 0).pack(mav))
    log = write(tmp_path, "ids.tlog", data)
    got = no_imu(log, IngestConfig(message="HIGHRES_IMU", imu_id=3, target_system=7))
    assert got == (f"{log}: expected HIGHRES_IMU messages with id 3 from system 7, found only 3 HIGHRES_IMU id 4 from "
                   "system 1, 2 RAW_IMU id 2 from system 7, 1 SCALED_IMU id 0 from system 1 and 1 more types "
                   "(rejected: 5 other_system, 2 other_imu)")
    got = no_imu(log, IngestConfig(imu_id=9))
    assert got.startswith(f"{log}: expected {ANY_IMU} with id 9, found only 3 HIGHRES_IMU id 4 from system 1, ")
    assert got.endswith(" (rejected: 7 other_imu)")


def test_no_imu_with_imus_names_the_set_and_why_it_never_fused(tmp_path: Path) -> None:
    """--imus: the IMU numbers asked for, the samples of other IMUs, an IMU of the set that never sent
    one, and a log shorter than the window in which --imus all looks for the streams (1 s)."""
    log = write(tmp_path, "one.tlog", rest_records(100))  # IMU 0 only, 1.00 .. 1.99 s
    found = "found only 100 HIGHRES_IMU id 0 from system 1"
    fused = "and the set is fused once each has sent one"
    assert no_imu(log, IngestConfig(imus=(1,))) == (
        f"{log}: expected {ANY_IMU} of IMU 1 (--imus), {found} (rejected: 100 other_imu); no sample of IMU 1, {fused}")
    assert no_imu(log, IngestConfig(imus=(0, 1))) == (
        f"{log}: expected {ANY_IMU} of IMU 0, 1 (--imus), {found}; no sample of IMU 1, {fused}")
    assert no_imu(log, IngestConfig(imus=())) == (
        f"{log}: expected {ANY_IMU}, {found} within the first 1 s of sensor time, where --imus all looks for the "
        "streams before it fuses them")
    assert no_imu(log, IngestConfig(imus=(0, 1, 2))) == (
        f"{log}: expected {ANY_IMU} of IMU 0, 1, 2 (--imus), {found}; no sample of IMU 1, 2, {fused}")
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)  # five streams in 0.5 s: three named, two counted
    five = write(tmp_path, "five.tlog", b"".join(rest_imu(mav, 1_000_000 + k * 10_000, imu_id=k % 5)
                                               for k in range(50)))
    assert no_imu(five, IngestConfig(imus=())) == (
        f"{five}: expected {ANY_IMU}, found only 10 HIGHRES_IMU id 0 from system 1, 10 HIGHRES_IMU id 1 from system 1, "
        "10 HIGHRES_IMU id 2 from system 1 and 2 more types within the first 1 s of sensor time, where --imus all "
        "looks for the streams before it fuses them")


def test_no_imu_in_a_ulog_whose_samples_are_all_out_of_range(tmp_path: Path) -> None:
    """sensor_combined rows beyond the 16 g accelerometer range are rejected by reason."""
    rows = [(t, 0.0, 0.0, 0.0, 0.0, 0.0, -200.0) for t in (1000, 2000)]
    log = write(tmp_path, "r.ulg", ulog([(*SC, rows)]))
    assert no_imu(log) == (f"{log}: expected {ANY_IMU}, found only 2 HIGHRES_IMU id 0 from system 1 "
                           "(rejected: 2 out_of_range)")


# -- why no solution row came (_no_solution) ---------------------------------------------------------


def no_solution(path: Path, **engine: float) -> str:
    with pytest.raises(DataFileError) as e:
        run(path, path.parent / "never.csv", **engine)
    assert not (path.parent / "never.csv").exists()
    return str(e.value)


def test_no_solution_without_a_position(tmp_path: Path) -> None:
    """No --lat/--lon/--alt and no fix in the log: the engine waits for a position."""
    log = write(tmp_path, "w.tlog", rest_records(100))
    assert no_solution(log, align=0.5) == (
        f"{log}: no solution rows from 100 IMU samples: no initial position: give --lat, --lon and --alt (the log "
        "has no GPS_RAW_INT or GLOBAL_POSITION_INT fix)")


def test_no_solution_when_the_alignment_is_longer_than_the_log(tmp_path: Path) -> None:
    """50 samples span 1.00 .. 1.49 s: 0.49 s of data for a 10 s alignment (shown to 0.1 s)."""
    log = write(tmp_path, "a.tlog", rest_records(50))
    assert no_solution(log, lat=1.0, lon=2.0, alt=3.0, align=10.0) == (
        f"{log}: no solution rows from 50 IMU samples: the alignment (--align 10 s at rest) did not finish in the "
        "0.5 s of IMU data")
    log = write(tmp_path, "b.tlog", rest_records(50, first_us=3_000_000))
    assert no_solution(log, lat=1.0, lon=2.0, alt=3.0, align=2.25).endswith(
        ": the alignment (--align 2.25 s at rest) did not finish in the 0.5 s of IMU data")


def test_no_solution_counts_alignment_restarts_on_motion(tmp_path: Path) -> None:
    """Two samples turning at 1 rad/s (above --motion-gyro 0.1) restart the alignment twice."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    data = b"".join(rest_imu(mav, 1_000_000 + k * 10_000, gx=1.0 if k in (10, 30) else 0.0) for k in range(50))
    log = write(tmp_path, "m.tlog", data)
    assert no_solution(log, lat=1.0, lon=2.0, alt=3.0, align=10.0) == (
        f"{log}: no solution rows from 50 IMU samples: the alignment (--align 10 s at rest) did not finish in the "
        "0.5 s of IMU data; it restarted 2 times on motion")


def test_no_solution_when_the_alignment_ends_on_the_last_sample(tmp_path: Path) -> None:
    """A 0.49 s alignment over samples 1.00 .. 1.49 s ends on the last one: navigating, but no row yet."""
    log = write(tmp_path, "n.tlog", rest_records(50))
    assert no_solution(log, lat=1.0, lon=2.0, alt=3.0, align=0.49, rate=10.0) == (
        f"{log}: no solution rows from 50 IMU samples: final state NAVIGATING")


# -- damaged ULogs: pyulog's loop guard and its corruption flag ---------------------------------------

ULOG_HEADER = b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0)  # magic, version 1, start time 0


def test_ulog_reader_going_in_circles_is_stopped_with_where(tmp_path: Path) -> None:
    """A message header of type 0 and size 5 with 4 bytes left: pyulog reads 3 + 4 bytes from byte 16, then seeks
    back 2 + 5 bytes to byte 16, again and again; the 21st revisit of byte 16 stops it."""
    log = write(tmp_path, "loop.ulg", ULOG_HEADER + struct.pack("<HB", 5, 0) + b"\x01\x02\x03\x04")
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: not a readable ULog: its reader went in circles near byte 16 (damaged records)"


def test_read_tracker_allows_twenty_revisits_of_one_position(tmp_path: Path) -> None:
    """Reads that get no further: the 21st read from one position raises; progress forgets the count."""
    f = write(tmp_path, "f.bin", bytes(range(64)))
    with open(f, "rb") as fh:
        tr = replay._ReadTracker(fh)
        assert tr.read(3) == b"\x00\x01\x02" and tr.header_at == 0 and tr.last == (0, 3, 3)
        for _ in range(20):
            tr.seek(0)
            assert tr.read(2) == b"\x00\x01"
        assert tr.last == (0, 2, 2) and tr.header_at == 0
        tr.seek(0)
        with pytest.raises(replay._Stuck, match=r"^its reader went in circles near byte 0 \(damaged records\)$"):
            tr.read(1)
    with open(f, "rb") as fh:
        tr = replay._ReadTracker(fh)
        tr.read(8)
        for _ in range(20):
            tr.seek(4)
            tr.read(1)
        tr.seek(8)
        assert tr.read(3) == b"\x08\x09\x0a" and tr.header_at == 8  # further than before: the visits are forgotten
        for _ in range(20):
            tr.seek(4)
            tr.read(1)
        tr.seek(60)
        assert tr.read(8) == b"\x3c\x3d\x3e\x3f" and tr.last == (60, 8, 4) and tr.header_at == 8
        tr.seek(0)
        assert tr.read() == bytes(range(64)) and tr.last == (0, -1, 64)


def test_read_tracker_stops_after_200000_reads_without_progress(tmp_path: Path) -> None:
    """Each position read once, but 200,000 reads in a row without getting further: the next one raises."""
    f = write(tmp_path, "f.bin", bytes(200_002))
    with open(f, "rb") as fh:
        tr = replay._ReadTracker(fh)
        tr.read(200_002)
        read = tr.read
        seek = fh.seek
        for pos in range(200_000):
            seek(pos)
            read(1)
        seek(200_000)
        with pytest.raises(replay._Stuck, match="near byte 200000 "):
            read(1)


def test_ulog_data_of_an_unsubscribed_id_is_noted_as_corruption(tmp_path: Path) -> None:
    """A data message of msg_id 99 (never added): pyulog flags the file corrupt and reads on; nothing is printed."""
    full = ulog([(*SC, sc_rows([1000, 2000, 3000]))])
    last = 3 + 2 + 8 + 24  # the last D message: header, msg_id, timestamp, six floats
    data = full[:-last] + ulog_msg(b"D", struct.pack("<H", 99) + bytes(8)) + full[-last:]
    msgs, report = read_all(write(tmp_path, "c.ulg", data))
    assert [m.time_usec for _, m in msgs] == [1000, 2000, 3000]
    assert report.notes == ["corrupt data inside the ULog was skipped by its reader (pyulog: no byte offsets)"]
    assert report.cut_at is None and report.skipped == []
    _, report = read_all(write(tmp_path, "ok.ulg", full))
    assert report.notes == []


def test_ulog_corruption_is_not_printed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """pyulog prints a warning for the unknown id: the replay says it in the report instead."""
    full = ulog([(*SC, sc_rows([1000]))])
    read_all(write(tmp_path, "c.ulg", full + ulog_msg(b"D", struct.pack("<H", 99) + bytes(8))))
    assert capsys.readouterr().out == ""


def test_ulog_without_imu_rows_says_where_it_was_cut(tmp_path: Path) -> None:
    """sensor_combined added but no row: refused; a cut inside a header is named with its byte."""
    data = ulog([(*SC, [])])
    log = write(tmp_path, "e.ulg", data)
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: expected IMU data (the sensor_combined topic), found none in the ULog"
    log = write(tmp_path, "f.ulg", data + b"\x05")
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == (f"{log}: expected IMU data (the sensor_combined topic), found none in the ULog (it ends "
                            f"inside a record at byte {len(data)}: cut short?)")


def test_ulog_header_too_short_is_not_a_readable_ulog(tmp_path: Path) -> None:
    """The 7 magic bytes and no more: pyulog's own reason is passed on."""
    log = write(tmp_path, "s.ulg", ULOG_HEADER[:7])
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: not a readable ULog: Invalid file format (Header too short)"


# -- a bad CRC beyond the tlog reader's first 1 MiB chunk --------------------------------------------


def test_tlog_bad_crc_beyond_the_first_chunk_is_skipped_at_its_file_offset(tmp_path: Path) -> None:
    """A record failing its CRC after the first 1 MiB is skipped from its first byte, in file bytes."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    one = b"".join(rec(i, imu_frame(mav, i)) for i in range(256))
    body = one * ((1 << 20) // len(one) + 1)
    bad = bytearray(rec(7, imu_frame(mav, 7)))
    bad[-1] ^= 0xFF
    good = rec(8, imu_frame(mav, 8))
    msgs, report = read_all(write(tmp_path, "a.tlog", body + bytes(bad) + good))
    assert report.skipped == [[len(body), len(bad), None]] and report.cut_at is None
    assert types(msgs[-2:]) == ["BAD_DATA", "HIGHRES_IMU"] and msgs[-1][1].time_usec == 8
    assert msgs[-2][0] == (len(body) + len(bad)) / (len(body) + len(bad) + len(good))


# -- what the user is told about a file that is not what its name says --------------------------------


@pytest.mark.parametrize("name, data, said", [
    ("a.tlog", ULOG_HEADER, "expected a MAVLink telemetry log (.tlog), found a PX4 ULog (rename it to .ulg)"),
    ("a.tlog", b"\xa3\x95\x80" + bytes(20), "expected a MAVLink telemetry log (.tlog), found an ArduPilot DataFlash "
                                            "log (rename it to .bin)"),
    ("a.tlog", b"t,lat,lon\n1,2,3\n", "expected a MAVLink telemetry log (.tlog), found a text file"),
    ("a.bin", b"\x1f\x8b\x08\x00" + bytes(12), "expected an ArduPilot DataFlash log (.bin), found a gzip file"),
    ("a.ulg", b"PK\x03\x04" + bytes(12), "expected a PX4 ULog (.ulg), found a zip file"),
    ("a.ulg", b"RRF2" + bytes(12), "expected a PX4 ULog (.ulg), found a Rerun recording"),
    ("a.bin", bytes(8) + b"\xfd" + bytes(30), "expected an ArduPilot DataFlash log (.bin) starting with bytes a3 95, "
                                              "found bytes 00 00 00 00 00 00 00 00"),
    ("a.ulg", b"\x01\x02\xff", "expected a PX4 ULog (.ulg) starting with 'ULog', found bytes 01 02 ff"),
    ("a.ulg", b"\xa3\x95" + bytes(10), "expected a PX4 ULog (.ulg), found an ArduPilot DataFlash log (rename it to "
                                       ".bin)"),
])
def test_mislabelled_file_is_named_by_what_it_is(tmp_path: Path, name: str, data: bytes, said: str) -> None:
    """The one-line refusal says what was expected, what the bytes are, and the suffix to rename to."""
    log = write(tmp_path, name, data)
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: {said}"


def test_tlog_of_unknown_bytes_is_read_as_a_damaged_tlog(tmp_path: Path) -> None:
    """A .tlog has no magic: bytes of no known kind are read, not refused. With no frame marker in the first read
    the last 8 bytes may be the time of a record still to come: 22 bytes are skipped, and the 8 left are a cut."""
    msgs, report = read_all(write(tmp_path, "a.tlog", b"\x01\x02\xff" * 10))
    assert types(msgs) == ["BAD_DATA"] and report.skipped == [[0, 22, None]] and report.cut_at == 22


def test_open_log_messages_for_missing_unknown_and_empty_files(tmp_path: Path) -> None:
    """Exact one-line messages: no such file, an unknown suffix, an empty file of each kind."""
    with pytest.raises(DataFileError) as e:
        open_log(tmp_path / "none.ulg")
    assert str(e.value) == f"{tmp_path / 'none.ulg'}: no such file"
    with pytest.raises(DataFileError) as e:
        open_log(tmp_path)
    assert str(e.value) == f"{tmp_path}: no such file"
    log = write(tmp_path, "log.TXT", b"x")
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: unknown log type '.txt' (expected .tlog, .bin or .ulg)"
    for name, kind in [("e.tlog", "a MAVLink telemetry log (.tlog)"), ("e.BIN", "an ArduPilot DataFlash log (.bin)"),
                       ("e.ulg", "a PX4 ULog (.ulg)")]:
        log = write(tmp_path, name, b"")
        with pytest.raises(DataFileError) as e:
            open_log(log)
        assert str(e.value) == f"{log}: the file is empty (expected {kind})"


# -- the Rerun recording -----------------------------------------------------------------------------


def test_replay_records_to_the_callers_recorder_and_closes_it(tmp_path: Path) -> None:
    """The caller's recorder gets every accepted sample and every output, and is closed (its buffers sent)."""
    from mavins.record.recorder import Recorder

    log = write(tmp_path, "rest.tlog", rest_records(100))
    rec_ = Recorder(tmp_path / "mine.rrd", live=False)
    res = replay.replay(log, EngineConfig(**AT_REST), IngestConfig(), None, recorder=rec_)
    assert rec_.rows["/imu/gyro"] == 100 and rec_.rows["/imu/accel"] == 100
    assert rec_.rows["/plots/attitude"] == res.outputs >= 4
    assert (tmp_path / "mine.rrd").stat().st_size > 0


def test_replay_writes_the_rerun_file_only_on_success(tmp_path: Path) -> None:
    """--rerun: the recording is renamed into place after a good replay; a log without IMU leaves nothing."""
    log = write(tmp_path, "rest.tlog", rest_records(100))
    rrd, out = tmp_path / "nav.rrd", tmp_path / "nav.csv"
    res = replay.replay(log, EngineConfig(**AT_REST), IngestConfig(), out, rerun=rrd)
    recording = rrd.read_bytes()
    assert recording[:3] == b"RRF" and len(out.read_text().splitlines()) == 1 + res.outputs
    from rerun.chunk import RrdReader

    assert [r.application_id for r in RrdReader(str(rrd)).recordings()] == ["mavins-replay"]  # what the viewer shows
    assert b"wall_time" not in recording  # not live: the sensor time is the only timeline
    bad = write(tmp_path, "hb.tlog", rec(1, v1_heartbeat()))
    with pytest.raises(DataFileError, match="found none among 1 messages"):
        replay.replay(bad, EngineConfig(**AT_REST), IngestConfig(), tmp_path / "b.csv", rerun=tmp_path / "b.rrd")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hb.tlog", "nav.csv", "nav.rrd", "rest.tlog"]


# -- where the tlog reader looks for the next record -------------------------------------------------


def test_next_record_takes_the_first_of_several_markers_from_eight_bytes_on() -> None:
    """The nearest FE wins over a later one; a marker exactly at start + 8 starts a record at ``start``."""
    assert replay._next_record(bytes(12) + b"\xfe" + bytes(10) + b"\xfe" + bytes(20), 1) == 4
    assert replay._next_record(bytes(9) + b"\xfe" + bytes(10), 1) == 1
    assert replay._next_record(bytes(9) + b"\xfd" + bytes(10), 1) == 1


def test_tlog_one_junk_byte_between_records(tmp_path: Path) -> None:
    """One byte of junk: the next record starts one byte on (its marker 9 bytes after the junk), nothing else lost."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a, b, c = (rec(i, imu_frame(mav, i)) for i in (1, 2, 3))
    msgs, report = read_all(write(tmp_path, "a.tlog", a + b"\x01" + b + c))
    assert [(m.get_type(), getattr(m, "time_usec", None)) for _, m in msgs] == [
        ("HIGHRES_IMU", 1), ("BAD_DATA", None), ("HIGHRES_IMU", 2), ("HIGHRES_IMU", 3)]
    assert report.skipped == [[len(a), 1, None]]


def test_tlog_marker_inside_the_time_bytes_of_junk_is_not_a_record(tmp_path: Path) -> None:
    """Junk whose 8th byte is FD: a record there would start before the junk, so the search goes past it."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a, b = rec(1, imu_frame(mav, 1)), rec(2, imu_frame(mav, 2))
    junk = b"\x01" * 7 + b"\xfd" + b"\x01" * 12
    msgs, report = read_all(write(tmp_path, "a.tlog", a + junk + b))
    assert types(msgs) == ["HIGHRES_IMU", "BAD_DATA", "HIGHRES_IMU"]
    assert report.skipped == [[len(a), 20, None]] and bytes(msgs[1][1].data) == junk


def test_tlog_junk_to_the_end_of_the_first_chunk_keeps_eight_bytes_for_a_record(tmp_path: Path) -> None:
    """Junk with no marker up to a record whose time starts 4 bytes before the 1 MiB read boundary: the record's
    time bytes are not skipped with the junk (the reader keeps 8 bytes until it has read on)."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    junk = b"\x01" * ((1 << 20) - 4)
    a, b = rec(1, imu_frame(mav, 1)), rec(2, imu_frame(mav, 2))
    msgs, report = read_all(write(tmp_path, "a.tlog", junk + a + b))
    assert report.skipped == [[0, len(junk), None]] and report.cut_at is None
    assert [m.time_usec for _, m in msgs if m.get_type() == "HIGHRES_IMU"] == [1, 2]


def test_read_tracker_counts_its_first_read_as_progress_and_reads_at_the_end_as_none(tmp_path: Path) -> None:
    """A first read of 1 byte is progress (20 revisits allowed after it); empty reads at the end get no further."""
    f = write(tmp_path, "f.bin", bytes(range(4)))
    with open(f, "rb") as fh:
        tr = replay._ReadTracker(fh)
        assert tr.read(0) == b"" and tr.last == (0, 0, 0)
        assert tr.read(1) == b"\x00"
        for _ in range(20):
            tr.seek(0)
            tr.read(1)
        with pytest.raises(replay._Stuck):
            tr.seek(0)
            tr.read(1)
    with open(f, "rb") as fh:
        tr = replay._ReadTracker(fh)
        assert tr.read() == bytes(range(4))
        for _ in range(20):
            assert tr.read(3) == b""
        assert tr.header_at == 4 and tr.last == (4, 3, 0)
        with pytest.raises(replay._Stuck, match="near byte 4 "):
            tr.read(3)


def test_ulog_larger_than_the_memory_is_refused_before_reading(tmp_path: Path) -> None:
    """A (sparse) 1 TiB ULog would need about twice its size in memory: 2048.0 GiB, refused up front."""
    from mavins.common.files import ResourceError

    log = tmp_path / "huge.ulg"
    with open(log, "wb") as fh:
        fh.write(ULOG_HEADER)
        fh.truncate(1 << 40)
    with pytest.raises(ResourceError) as e:
        open_log(log)
    msg = str(e.value)
    assert msg.startswith(f"reading {log} needs about 2048.0 GiB of memory, the machine has ") and msg.endswith(
        " available")


def test_log_that_cannot_be_read_is_refused_with_the_reason(tmp_path: Path) -> None:
    """A .tlog that is a link to /proc/self/mem: a file, but reading its first bytes fails (EIO)."""
    log = tmp_path / "mem.tlog"
    log.symlink_to("/proc/self/mem")
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: cannot read: Input/output error"


def test_only_the_first_64_bytes_say_what_a_file_is(tmp_path: Path) -> None:
    """64 printable bytes then binary: a text file by its start (the sniffed head is 64 bytes)."""
    log = write(tmp_path, "t.ulg", b"x" * 64 + b"\xff\x00" * 8)
    with pytest.raises(DataFileError) as e:
        open_log(log)
    assert str(e.value) == f"{log}: expected a PX4 ULog (.ulg), found a text file"


def test_tlog_bad_data_carries_its_reason_and_at_most_64_bytes(tmp_path: Path) -> None:
    """Junk: 'not a tlog record' with its first 64 bytes; a bad CRC: pymavlink's reason with the frame's first 64."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a = rec(1, imu_frame(mav, 1))
    junk = bytes(range(1, 101))
    bad = bytearray(rec(2, imu_frame(mav, 2)))
    bad[-1] ^= 0xFF
    msgs, _ = read_all(write(tmp_path, "a.tlog", a + junk + bytes(bad) + a))
    assert types(msgs) == ["HIGHRES_IMU", "BAD_DATA", "BAD_DATA", "HIGHRES_IMU"]
    j, c = msgs[1][1], msgs[2][1]
    assert (bytes(j.data), j.reason) == (junk[:64], "not a tlog record")
    assert len(bad) - 8 == 12 + 63 and bytes(c.data) == bytes(bad[8:72])
    assert c.reason.startswith("invalid MAVLink CRC in msgID 105 ")


def test_replay_progress_on_a_terminal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """On a terminal (a pty here) the bar shows the fraction read every 2000 messages and 100 % after the last
    message, then the time taken."""
    import os
    import re
    import sys

    log = write(tmp_path, "p.tlog", rest_records(4000, step_us=1000))  # 4000 records of one size: 2000 is half
    master, slave = os.openpty()
    with open(slave, "w", encoding="utf-8") as tty:
        monkeypatch.setattr(sys, "stderr", tty)
        res = run(log, **AT_REST)
        tty.flush()
    chunks = []  # one read returns what the pty holds at that moment: read until the closed side says EOF
    while True:
        try:
            chunk = os.read(master, 1 << 16)
        except OSError:  # EIO: the terminal side is closed and drained (Linux)
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    shown = b"".join(chunks).decode()
    assert res.messages == 4000
    bars = re.findall(r"\rreplay p\.tlog \[(#*) *\] +([0-9.]+)% eta +[0-9.]+ s", shown)
    assert bars == [("#" * 15, "50.0"), ("#" * 30, "100.0"), ("#" * 30, "100.0")]  # messages 2000, 4000; the end
    assert re.search(r"\rreplay p\.tlog done in [0-9]+\.[0-9] s {40}\r?\n$", shown)


def test_no_imu_with_an_upper_case_suffix(tmp_path: Path) -> None:
    """The kind named in the message comes from the suffix in any case."""
    log = write(tmp_path, "J.TLOG", bytes(range(1, 40)))
    assert no_imu(log) == f"{log}: expected a MAVLink telemetry log (.tlog), found no valid MAVLink message in 39 bytes"
    log = write(tmp_path, "F.BIN", FMT_OF_FMT)
    assert no_imu(log) == (f"{log}: expected an ArduPilot DataFlash log (.bin) with {ANY_IMU}, found no IMU record in "
                           f"{FMT_LEN} bytes")


def test_replay_with_a_bad_setting_raises_its_error_and_writes_nothing(tmp_path: Path) -> None:
    """An engine setting the pipeline refuses is raised as it is (nothing to close), and no CSV is left."""
    log = write(tmp_path, "rest.tlog", rest_records(10))
    with pytest.raises(ValueError) as e:
        replay.replay(log, EngineConfig(**AT_REST, frame="bogus"), IngestConfig(), tmp_path / "o.csv")
    assert str(e.value) == "frame must be one of geographic, wander, free, inertial, got 'bogus'"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rest.tlog"]


def test_tlog_fraction_read_of_junk_after_two_records(tmp_path: Path) -> None:
    """The fraction of a BAD_DATA is where its junk starts over the size, however far into the file."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    a, b, c = (rec(i, imu_frame(mav, i)) for i in (1, 2, 3))
    junk = b"\x01" * 20
    size = len(a + b + junk + c)
    msgs, report = read_all(write(tmp_path, "a.tlog", a + b + junk + c))
    assert [(f, m.get_type()) for f, m in msgs] == [(len(a) / size, "HIGHRES_IMU"), (len(a + b) / size, "HIGHRES_IMU"),
                                                    (len(a + b) / size, "BAD_DATA"), (1.0, "HIGHRES_IMU")]
    assert report.skipped == [[len(a + b), 20, None]]

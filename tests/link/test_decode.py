"""The one-step datagram decoder against pymavlink's own parser.

Every expected message comes from pymavlink (``MAVLink.parse_buffer`` on the
same bytes); the decoder must give the same object for the datagrams it
takes, and decline (None) every other datagram so that pymavlink's parser
decides and names the rejection.
"""

from __future__ import annotations

import math
import random
import socket
import struct
import time

import pytest

from mavins.link.decode import decode_one
from mavins.link.links import UdpLink
from mavins.link.mavlink import mavlink, parser

INT_RANGES = {"b": (-128, 127), "B": (0, 255), "h": (-32768, 32767), "H": (0, 65535),
              "i": (-2**31, 2**31 - 1), "I": (0, 2**32 - 1), "q": (-2**63, 2**63 - 1), "Q": (0, 2**64 - 1)}
PLAIN = sorted(mid for mid, cls in mavlink.mavlink_map.items()
               if all(n == 1 for n in cls.lengths) and "s" not in cls.unpacker.format)
WITH_ARRAYS_OR_TEXT = sorted(set(mavlink.mavlink_map) - set(PLAIN))


def _values(cls: type, rng: random.Random, zeros: bool = False) -> list:
    """Field values in declared order, drawn for each field's wire type."""
    fmt = cls.unpacker.format.lstrip("<")  # wire order
    out = [0] * len(cls.fieldnames)
    for wire, code in enumerate(fmt):
        declared = cls.orders.index(wire)
        if zeros:
            continue
        if code in "fd":
            out[declared] = rng.choice([rng.uniform(-1e6, 1e6), rng.uniform(-1, 1), 0.0, math.inf, math.nan])
        else:
            lo, hi = INT_RANGES[code]
            out[declared] = rng.choice([lo, hi, 0, rng.randint(lo, hi)])
    return out


def _pack(cls: type, values: list, seq: int, sysid: int, compid: int, **kw: object) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    return bytes(cls(*values).pack(mav, **kw))


def _same(a: object, b: object) -> None:
    assert type(a) is type(b)
    for name in b.fieldnames:  # type: ignore[attr-defined]
        x, y = getattr(a, name), getattr(b, name)
        assert type(x) is type(y), name
        assert x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)), name
    assert vars(a._header) == vars(b._header)  # type: ignore[attr-defined]
    for attr in ("_msgbuf", "_payload", "_crc", "_signed"):
        assert getattr(a, attr) == getattr(b, attr), attr
    assert a.get_seq() == b.get_seq() and a.get_srcSystem() == b.get_srcSystem()  # type: ignore[attr-defined]


def test_plain_messages_cover_the_imu_and_gnss_inputs() -> None:
    names = {mavlink.mavlink_map[m].msgname for m in PLAIN}
    assert {"HIGHRES_IMU", "SCALED_IMU", "RAW_IMU", "GPS_RAW_INT", "SCALED_PRESSURE", "HEARTBEAT",
            "TIMESYNC", "GLOBAL_POSITION_INT"} <= names
    assert "ATTITUDE_QUATERNION" not in names and "STATUSTEXT" not in names  # array / text: pymavlink's parser


@pytest.mark.parametrize("mid", PLAIN)
def test_every_plain_message_decodes_as_pymavlink_does(mid: int) -> None:
    cls = mavlink.mavlink_map[mid]
    rng = random.Random(mid)
    for k in range(4):
        buf = _pack(cls, _values(cls, rng, zeros=(k == 0)), seq=rng.randrange(256), sysid=rng.randrange(1, 256),
                    compid=rng.randrange(256))
        want = parser().parse_buffer(buf)
        assert want is not None and len(want) == 1
        got = decode_one(buf)
        assert got is not None
        _same(got, want[0])


def test_trimmed_payload_is_zero_filled() -> None:
    """MAVLink 2 drops trailing zero bytes of the payload: an all-zero HIGHRES_IMU is one byte long."""
    cls = mavlink.MAVLink_highres_imu_message
    buf = _pack(cls, [0] * len(cls.fieldnames), 5, 1, 1)
    assert buf[1] == 1 and len(buf) == 13
    got = decode_one(buf)
    assert got is not None and got.xacc == 0.0 and got.time_usec == 0 and got.id == 0
    _same(got, parser().parse_buffer(buf)[0])


def _imu_frame() -> bytes:
    cls = mavlink.MAVLink_highres_imu_message
    return _pack(cls, _values(cls, random.Random(1)), 9, 1, 1)


@pytest.mark.parametrize("case", ["crc", "payload_bit", "short", "long", "two_frames", "v1", "signed",
                                  "magic", "unknown_id", "empty"])
def test_anything_else_is_left_to_pymavlink(case: str) -> None:
    buf = bytearray(_imu_frame())
    if case == "crc":
        buf[-1] ^= 0x01
    elif case == "payload_bit":
        buf[12] ^= 0x10
    elif case == "short":
        buf = buf[:-1]
    elif case == "long":
        buf += b"\x00"
    elif case == "two_frames":
        buf += _imu_frame()
    elif case == "v1":
        buf = bytearray(mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(
            mavlink.MAVLink(None, 1, 1), force_mavlink1=True))
        assert buf[0] == mavlink.PROTOCOL_MARKER_V1
    elif case == "signed":
        buf[2] = mavlink.MAVLINK_IFLAG_SIGNED
    elif case == "magic":
        buf[0] = 0x00
    elif case == "unknown_id":
        buf[7:10] = (0xFFFFFE).to_bytes(3, "little")
    elif case == "empty":
        buf = bytearray()
    assert decode_one(bytes(buf)) is None


def test_messages_with_arrays_or_text_are_left_to_pymavlink() -> None:
    mav = mavlink.MAVLink(None, 1, 1)
    for msg in (mav.statustext_encode(4, b"hello"), mav.attitude_quaternion_encode(1, 1, 0, 0, 0, 0, 0, 0, [0] * 4),
                mav.gimbal_device_attitude_status_encode(1, 1, 1, 0, [1, 0, 0, 0], 0, 0, 0, 0)):
        assert msg.get_msgId() in WITH_ARRAYS_OR_TEXT
        assert decode_one(bytes(msg.pack(mav))) is None


def test_a_udp_link_gives_the_same_messages_either_way() -> None:
    """Over a real socket: plain frames, an array message, a bad CRC and two frames in one
    datagram come out of UdpLink.receive as pymavlink parses them, one datagram at a time."""
    link = UdpLink("udpin:127.0.0.1:0")
    port = link.sock.getsockname()[1]
    mav = mavlink.MAVLink(None, 1, 1)
    bad = bytearray(_imu_frame())
    bad[-2] ^= 0xFF
    datagrams = [_imu_frame(), bytes(mav.heartbeat_encode(2, 3, 0, 0, 4).pack(mav)),
                 bytes(mav.statustext_encode(4, b"x").pack(mav)), bytes(bad), _imu_frame() + _imu_frame()]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for d in datagrams:
            tx.sendto(d, ("127.0.0.1", port))
    got: list = []
    for _ in range(200):
        out, _n = link.receive(64)
        got += [m for m, _ in out]
        if len(got) >= 6:
            break
        time.sleep(0.01)
    link.close()
    want = []
    for d in datagrams:
        p = parser()
        msgs = p.parse_buffer(d) or []
        want += msgs if msgs else [None]
    assert [m.get_type() for m in got] == ["HIGHRES_IMU", "HEARTBEAT", "STATUSTEXT", "BAD_DATA", "HIGHRES_IMU",
                                           "HIGHRES_IMU"]
    assert "CRC" in got[3].reason
    for g, w in zip([got[0], got[1], got[2], got[4], got[5]], [want[0], want[1], want[2], want[4], want[5]]):
        _same(g, w)
    assert struct.unpack("<Q", got[0].get_payload()[4:12])[0] == got[0].time_usec


def _recrc(frame: bytearray, extra: int | None = None) -> bytes:
    """The frame with its CRC recomputed over what it now holds (pymavlink's pure-Python CRC),
    with its message's CRC_EXTRA unless ``extra`` is given."""
    from pymavlink.generator.mavcrc import x25crc_slow

    msgid = frame[7] | (frame[8] << 8) | (frame[9] << 16)
    if extra is None:
        extra = mavlink.mavlink_map[msgid].crc_extra
    crc = x25crc_slow(bytes(frame[1:-2]) + bytes([extra])).crc
    frame[-2:] = crc.to_bytes(2, "little")
    return bytes(frame)


def test_plain_means_scalars_only() -> None:
    from mavins.link.decode import _plain

    assert _plain(mavlink.MAVLink_highres_imu_message) and _plain(mavlink.MAVLink_heartbeat_message)
    assert not _plain(mavlink.MAVLink_statustext_message)  # text
    assert not _plain(mavlink.MAVLink_attitude_quaternion_message)  # an array
    assert not _plain(mavlink.MAVLink_named_value_float_message)  # text among scalars


def test_a_length_field_that_disagrees_is_declined_even_with_a_good_crc() -> None:
    frame = bytearray(_imu_frame())
    longer = frame[:-2] + b"\x07" + frame[-2:]  # one payload byte more than the length field says
    assert decode_one(_recrc(longer)) is None
    assert parser().parse_buffer(_recrc(longer))[0].get_type() != "HIGHRES_IMU"


def test_flags_with_a_good_crc() -> None:
    """Incompatibility flags (signing) are pymavlink's to handle; compatibility flags are ignored."""
    frame = bytearray(_imu_frame())
    flagged = bytearray(frame)
    flagged[2] = mavlink.MAVLINK_IFLAG_SIGNED
    assert decode_one(_recrc(flagged)) is None
    compat = bytearray(frame)
    compat[3] = 0x01
    got = decode_one(_recrc(compat))
    assert got is not None and got._header.compat_flags == 1
    _same(got, parser().parse_buffer(_recrc(compat))[0])


def test_the_third_id_byte_counts() -> None:
    """HEARTBEAT's id (0) with the top id byte set is id 65536, not a HEARTBEAT, even with a CRC
    that HEARTBEAT's CRC_EXTRA makes good."""
    mav = mavlink.MAVLink(None, 1, 1)
    frame = bytearray(mav.heartbeat_encode(2, 3, 0, 0, 4).pack(mav))
    frame[9] = 1
    assert 65536 not in mavlink.mavlink_map
    assert decode_one(_recrc(frame, mavlink.MAVLink_heartbeat_message.crc_extra)) is None


def test_an_empty_payload_is_all_zero_fields() -> None:
    """A zero-length payload (every field zero, trimmed away) decodes as pymavlink decodes it."""
    mav = mavlink.MAVLink(None, 1, 1)
    frame = bytearray(mav.heartbeat_encode(0, 0, 0, 0, 0, 0).pack(mav))
    empty = bytearray(frame[:10]) + bytearray(2)
    empty[1] = 0
    buf = _recrc(empty)
    assert len(buf) == 12
    got = decode_one(buf)
    assert got is not None and got.get_type() == "HEARTBEAT" and got.custom_mode == 0
    _same(got, parser().parse_buffer(buf)[0])

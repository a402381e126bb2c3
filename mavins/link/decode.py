"""The common datagram decoded in one step: one unsigned MAVLink 2 frame of a message without arrays.

A UDP datagram from an autopilot or a companion computer almost always holds
exactly one MAVLink 2 frame. pymavlink's ``parse_buffer`` feeds it byte-run by
byte-run through a stream state machine; at 1 kHz that costs as much as the
navigation itself. For the common case this module checks the frame the way
pymavlink's ``MAVLink.decode`` does (length, CRC-16/MCRF4XX with the message's
CRC_EXTRA, zero-filled truncated payload, MAVLink 2 frame layout of the
MAVLink serialization spec) and builds the same message object. Anything else
(MAVLink 1, a signed frame, several frames, a bad length or CRC, an unknown
id, a message with arrays or strings) returns ``None`` and goes through
pymavlink's parser, so what is rejected, and why, stays pymavlink's.
"""

from __future__ import annotations

from fastcrc import crc16

from .mavlink import mavlink

_MAGIC_V2 = mavlink.PROTOCOL_MARKER_V2
_HEADER = 10  # MAVLink 2 header: magic, len, incompat, compat, seq, sysid, compid, msgid (3 bytes)
_FRAME_EXTRA = _HEADER + 2  # header and CRC around the payload
_mcrf4xx = crc16.mcrf4xx


def _plain(msgtype: type) -> bool:
    """True for a message whose fields are all scalars (no arrays, no strings)."""
    return all(n == 1 for n in msgtype.lengths) and "s" not in msgtype.unpacker.format  # type: ignore[attr-defined]


# id -> (class, CRC_EXTRA as a byte, payload struct, wire-order -> declared-order map)
_PLAIN: dict[int, tuple[type, bytes, object, tuple[int, ...]]] = {
    mid: (cls, bytes([cls.crc_extra]), cls.unpacker, tuple(cls.orders))  # type: ignore[attr-defined]
    for mid, cls in mavlink.mavlink_map.items() if _plain(cls)
}


def decode_one(data: bytes) -> mavlink.MAVLink_message | None:
    """The message of a datagram that is exactly one valid unsigned MAVLink 2 frame of a plain message, else None."""
    n = len(data)
    if n < _FRAME_EXTRA or data[0] != _MAGIC_V2 or data[2] != 0 or n != data[1] + _FRAME_EXTRA:
        return None
    entry = _PLAIN.get(data[7] | (data[8] << 8) | (data[9] << 16))
    if entry is None:
        return None
    cls, extra, unpacker, orders = entry
    end = n - 2
    crc = data[end] | (data[end + 1] << 8)
    if _mcrf4xx(data[1:end] + extra) != crc:  # initial value 0xFFFF, as MCRF4XX defines it
        return None
    payload = data[_HEADER:end].ljust(unpacker.size, b"\0")  # type: ignore[attr-defined]  # MAVLink 2 trims trailing zeros
    t = unpacker.unpack_from(payload)  # type: ignore[attr-defined]
    m = cls(*[t[i] for i in orders])
    buf = bytearray(data)
    m._signed = False
    m._msgbuf = buf
    m._payload = buf[6:end]
    m._crc = crc
    m._header = mavlink.MAVLink_header(cls.id, 0, data[3], data[1], data[4], data[5], data[6])  # type: ignore[attr-defined]
    return m

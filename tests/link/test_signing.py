"""mavins/link/signing.py in process: key files, the verifier's replay state and the signer's timestamps.

tests/faces/test_security.py attacks a running service over UDP; these tests hold
each rule of docs/security.md to its boundary in process, so that mutation
testing (which cannot see into subprocesses) checks them. Signed frames are
made by pymavlink's own encoder (an implementation independent of the
verifier) and the signer's frames are checked by pymavlink's own parser.
"""

from __future__ import annotations

import os
import stat
import time
from pathlib import Path

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from mavins.link import signing  # noqa: E402
from mavins.link.signing import KeyFileError, Signer, Verifier, key_from_passphrase, load_key  # noqa: E402

KEY = bytes(range(1, 33))
OTHER_KEY = bytes(range(2, 34))
UNITS = 100_000  # 10 us per unit (MAVLink 2 signing specification)
EPOCH_2015 = 1420070400  # 2015-01-01 00:00:00 UTC
WINDOW = 60 * UNITS  # docs/security.md: a new stream may lag the clock by one minute


def heartbeat(ts: int, key: bytes = KEY, link_id: int = 0, sysid: int = 1, compid: int = 1) -> bytes:
    """A HEARTBEAT signed by pymavlink with signing timestamp ``ts``, link id and source ids as given."""
    mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key = key
    mav.signing.link_id = link_id
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = ts
    frame = mav.heartbeat_encode(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0).pack(mav)
    assert int.from_bytes(frame[-12:-6], "little") == ts
    return bytes(frame)


def now_units() -> int:
    return int((time.time() - EPOCH_2015) * UNITS)


# ============================================================== key files

def write_key(path: Path, data: bytes, mode: int = 0o600) -> Path:
    path.write_bytes(data)
    path.chmod(mode)
    return path


def test_raw_and_hex_keys(tmp_path: Path) -> None:
    """32 raw bytes are the key as they are (even when they happen to be hex digits); 64 hex digits, any case,
    with surrounding white space, are decoded."""
    assert load_key(write_key(tmp_path / "raw", KEY)) == KEY
    hex32 = b"0123456789abcdef0123456789abcdef"
    assert load_key(write_key(tmp_path / "hexlike", hex32)) == hex32
    assert load_key(write_key(tmp_path / "hex", b"  " + KEY.hex().upper().encode() + b"\n")) == KEY


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o610, 0o601, 0o620, 0o602, 0o660, 0o644])
def test_a_key_others_can_reach_is_refused(tmp_path: Path, mode: int) -> None:
    """Any group or other permission bit refuses the file, naming its mode and the fix."""
    p = write_key(tmp_path / "k", KEY, mode)
    with pytest.raises(KeyFileError) as e:
        load_key(p)
    assert str(e.value) == f"{p}: key file is accessible by others (mode {mode:03o}); run: chmod 600 {p}"


@pytest.mark.parametrize("mode", [0o600, 0o400, 0o700])
def test_owner_only_modes_are_accepted(tmp_path: Path, mode: int) -> None:
    assert load_key(write_key(tmp_path / "k", KEY, mode)) == KEY


def test_missing_key_file(tmp_path: Path) -> None:
    p = tmp_path / "absent"
    with pytest.raises(KeyFileError) as e:
        load_key(p)
    assert str(e.value) == f"{p}: cannot read the key: No such file or directory"
    assert e.value.__cause__ is None and e.value.__suppress_context__


@pytest.mark.parametrize("data", [b"", KEY[:31], KEY + b"\x00", KEY.hex().encode()[:62], KEY.hex().encode() + b"00",
                                  b"g" * 64, "é".encode() * 33])
def test_wrong_key_sizes_and_contents(tmp_path: Path, data: bytes) -> None:
    """Neither 32 raw bytes nor 64 hex digits: one line naming the file's size."""
    p = write_key(tmp_path / "k", data)
    with pytest.raises(KeyFileError) as e:
        load_key(p)
    assert str(e.value) == f"{p}: a key is 32 raw bytes or 64 hex digits (this file has {len(data)} bytes)"


def test_passphrase_key_is_its_sha256() -> None:
    """MAVProxy's convention, against the FIPS 180-2 test vector SHA-256("abc")."""
    want = bytes.fromhex("ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad")
    assert key_from_passphrase("abc") == want
    with pytest.raises(UnicodeEncodeError):
        key_from_passphrase("clé")


def test_now_timestamp_is_10_us_units_since_2015() -> None:
    before = now_units()
    ts = signing.now_timestamp()
    after = now_units()
    assert isinstance(ts, int) and before <= ts <= after


# ============================================================== the verifier

def test_an_authentic_frame_is_accepted_and_recorded() -> None:
    v = Verifier(KEY)
    ts = now_units()
    assert v.check(heartbeat(ts, link_id=3, sysid=7, compid=9), 7, 9) is None
    assert v.streams == {(3, 7, 9): ts} and v.latest == ts


@pytest.mark.parametrize("change", ["signature", "timestamp", "payload", "link_id", "key"])
def test_a_forged_frame_is_rejected_and_changes_nothing(change: str) -> None:
    """Any altered byte (signature, timestamp, payload, link id) or another key: bad_signature, and the replay state
    is untouched, so a forger cannot lock the genuine sender out by advancing its timestamp."""
    v = Verifier(KEY)
    ts = now_units()
    assert v.check(heartbeat(ts), 1, 1) is None
    frame = bytearray(heartbeat(ts + 1000, key=OTHER_KEY if change == "key" else KEY))
    where = {"signature": -1, "timestamp": -7, "payload": 12, "link_id": -13}.get(change)
    if where is not None:
        frame[where] ^= 0x01
    assert v.check(bytes(frame), 1, 1) == "bad_signature"
    assert v.streams == {(0, 1, 1): ts} and v.latest == ts
    assert v.check(heartbeat(ts + 1), 1, 1) is None


def test_unsigned_frames() -> None:
    """MAVLink 1, an unsigned MAVLink 2 frame, or one too short to hold a signature: unsigned."""
    v = Verifier(KEY)
    plain = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    unsigned = bytes(plain.heartbeat_encode(2, 12, 0, 0, 0).pack(plain))
    assert unsigned[0] == 0xFD and not unsigned[2] & 1
    assert v.check(unsigned, 1, 1) == "unsigned"
    signed = heartbeat(now_units())
    assert v.check(b"\xfe" + signed[1:], 1, 1) == "unsigned"
    flag_cleared = bytearray(signed)
    flag_cleared[2] &= 0xFE
    assert v.check(bytes(flag_cleared), 1, 1) == "unsigned"
    short = bytes([0xFD, 0, 1]) + bytes(19)  # 22 bytes: below 10 + 13
    assert v.check(short, 1, 1) == "unsigned"
    assert v.streams == {}


def test_the_shortest_signed_frame_is_checked() -> None:
    """23 bytes (a 10-byte header with no payload or CRC room, then the 13 signature bytes) is long enough to be
    checked, so it is a bad signature rather than unsigned."""
    frame = bytes([0xFD, 0, 1]) + bytes(20)
    assert len(frame) == 23
    assert Verifier(KEY).check(frame, 1, 1) == "bad_signature"


def test_replays_are_rejected_per_stream() -> None:
    """A stream is (link id, system, component): equal or older timestamps are replays there, and only there."""
    v = Verifier(KEY)
    ts = now_units()
    assert v.check(heartbeat(ts), 1, 1) is None
    assert v.check(heartbeat(ts), 1, 1) == "replayed"
    assert v.check(heartbeat(ts - 1), 1, 1) == "replayed"
    assert v.check(heartbeat(ts, link_id=1), 1, 1) is None
    assert v.check(heartbeat(ts, sysid=2), 2, 1) is None
    assert v.check(heartbeat(ts, compid=2), 1, 2) is None
    assert v.check(heartbeat(ts + 1), 1, 1) is None
    assert v.streams == {(0, 1, 1): ts + 1, (1, 1, 1): ts, (0, 2, 1): ts, (0, 1, 2): ts}


def test_the_stream_key_is_the_frame_s_link_id_and_the_given_ids() -> None:
    """The system and component ids are the caller's (the parsed header's), the link id the frame's own."""
    v = Verifier(KEY)
    ts = now_units()
    assert v.check(heartbeat(ts, link_id=5, sysid=1, compid=1), 4, 6) is None
    assert list(v.streams) == [(5, 4, 6)]


def test_a_new_stream_may_lag_the_latest_time_by_one_minute() -> None:
    """Against the latest authenticated timestamp when that is ahead of the clock: exactly one minute behind is
    accepted, one unit more is stale (and changes nothing)."""
    v = Verifier(KEY)
    ahead = now_units() + 3600 * UNITS
    assert v.check(heartbeat(ahead, sysid=9), 9, 1) is None
    assert v.latest == ahead
    assert v.check(heartbeat(ahead - WINDOW - 1, sysid=2), 2, 1) == "stale_new_stream"
    assert (0, 2, 1) not in v.streams
    assert v.check(heartbeat(ahead - WINDOW, sysid=3), 3, 1) is None
    assert v.latest == ahead


def test_a_new_stream_may_lag_the_clock_by_one_minute() -> None:
    """With nothing seen, the clock is the reference: 2 minutes old is stale, 30 s old is accepted."""
    v = Verifier(KEY)
    assert v.check(heartbeat(now_units() - 2 * WINDOW), 1, 1) == "stale_new_stream"
    assert v.streams == {} and v.latest == 0
    assert v.check(heartbeat(now_units() - WINDOW // 2), 1, 1) is None


def test_a_known_stream_may_lag_any_amount() -> None:
    """Staleness is for new streams only: a known stream moving forward is accepted however old its clock,
    and the latest time stays the highest seen."""
    v = Verifier(KEY)
    ts = now_units()
    assert v.check(heartbeat(ts), 1, 1) is None
    v.streams[(0, 1, 1)] = ts - 10 * WINDOW
    assert v.check(heartbeat(ts - 5 * WINDOW), 1, 1) is None
    assert v.latest == ts


# ============================================================== the signer

def test_timestamps_follow_the_clock_and_strictly_increase() -> None:
    s = Signer(KEY, None)
    before = now_units()
    a = s.next_timestamp()
    b = s.next_timestamp()
    after = now_units()
    assert before <= a < b <= max(after, a + 1) and s.last == b


def test_a_clock_behind_the_last_timestamp_gives_last_plus_one() -> None:
    s = Signer(KEY, None)
    s.last = now_units() + 3600 * UNITS
    first = s.last
    assert s.next_timestamp() == first + 1
    assert s.next_timestamp() == first + 2


def test_the_state_file_reserves_ahead_and_is_written_only_when_used_up(tmp_path: Path) -> None:
    """The file holds the first timestamp not yet handed out plus 30 s, mode 0600, written through a temporary
    file that does not stay; it is rewritten only when a timestamp reaches the reservation."""
    state = tmp_path / "signing.state"
    s = Signer(KEY, state, link_id=2)
    ts = s.next_timestamp()
    assert state.read_text() == f"{ts + 30 * UNITS}\n" and s.reserved == ts + 30 * UNITS
    assert stat.S_IMODE(state.stat().st_mode) == 0o600
    assert not (tmp_path / "signing.tmp").exists()
    state.write_text("marker\n")
    s.next_timestamp()
    assert state.read_text() == "marker\n"
    s.last = s.reserved - 1  # the next timestamp reaches the reservation
    t2 = s.next_timestamp()
    assert t2 == s.reserved - 30 * UNITS and state.read_text() == f"{t2 + 30 * UNITS}\n"


def test_a_restart_signs_above_the_reservation(tmp_path: Path) -> None:
    state = tmp_path / "signing.state"
    future = now_units() + 3600 * UNITS
    state.write_text(f"  {future}\n")
    s = Signer(KEY, state)
    assert s.last == future
    assert s.next_timestamp() == future + 1


@pytest.mark.parametrize("text", ["", "garbage\n", "1.5\n"])
def test_an_unreadable_state_file_starts_from_the_clock(tmp_path: Path, text: str) -> None:
    state = tmp_path / "signing.state"
    state.write_text(text)
    s = Signer(KEY, state)
    assert s.last == 0
    assert s.next_timestamp() >= now_units() - UNITS


def test_the_default_link_id_is_0() -> None:
    s = Signer(KEY, None)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    s.attach(mav)
    assert bytes(s.pack(mav.heartbeat_encode(18, 8, 0, 0, 0), mav))[-13] == 0


def test_a_state_path_that_is_not_a_file_is_not_read(tmp_path: Path) -> None:
    s = Signer(KEY, tmp_path / "absent")
    assert s.last == 0 and s.reserved == 0


def test_signed_frames_pass_pymavlink_s_own_check(tmp_path: Path) -> None:
    """attach + pack: pymavlink's parser with the key accepts the frame; its link id and timestamp are the
    signer's; without the key (or with another) pymavlink rejects it."""
    s = Signer(KEY, tmp_path / "state", link_id=7)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    s.attach(mav)
    assert mav.signing.sign_outgoing is True
    frame = bytes(s.pack(mav.heartbeat_encode(18, 8, 0, 0, 0), mav))
    assert frame[-13] == 7 and int.from_bytes(frame[-12:-6], "little") == s.last
    assert Verifier(KEY).check(frame, 1, 191) is None
    rx = mavlink.MAVLink(None)
    rx.signing.secret_key = KEY
    rx.signing.allow_unsigned_callback = None
    msgs = rx.parse_buffer(frame)
    assert msgs and msgs[0].get_type() == "HEARTBEAT"
    bad = mavlink.MAVLink(None)
    bad.signing.secret_key = OTHER_KEY
    with pytest.raises(mavlink.MAVError, match="Invalid signature"):
        bad.parse_buffer(frame)

"""MAVLink 2 message signing that holds against a hostile network.

Wire format (MAVLink 2 signing specification): a signed frame ends with
``link_id (1) | timestamp (6, little endian, 10 us units since
2015-01-01 00:00:00 UTC) | signature (6)`` where the signature is the first 6
bytes of ``sha256(secret_key || frame up to and including the timestamp)``.

Differences from pymavlink's own ``check_signature`` (on purpose):

* the signature is verified *before* any replay state changes, so a forged
  frame can never advance a stream's timestamp and lock its sender out;
* replay state is per (link id, system, component) and only authenticated
  frames update it; a new stream is accepted only if its timestamp is within
  one minute of our current signing time;
* outgoing timestamps follow the wall clock, ``max(previous + 1, now)``, and
  are reserved ahead in a state file beside the key, so a restart never
  reuses one (see docs/security.md).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path

EPOCH_2015 = 1420070400  # 2015-01-01 00:00:00 UTC as a UNIX time
UNITS_PER_S = 100_000  # 10 us
NEW_STREAM_WINDOW = 60 * UNITS_PER_S  # one minute
IFLAG_SIGNED = 0x01
SIGNATURE_LEN = 13
RESERVE = 30 * UNITS_PER_S  # timestamps reserved ahead in the state file


class KeyFileError(ValueError):
    """A signing key file that must not be used, with the reason."""


def load_key(path: Path) -> bytes:
    """Read a 32-byte key: raw binary or 64 hex digits. Refuse files others can read."""
    try:
        st = path.stat()
    except OSError as exc:
        raise KeyFileError(f"{path}: cannot read the key: {exc.strerror}") from None
    if st.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise KeyFileError(
            f"{path}: key file is accessible by others (mode {stat.S_IMODE(st.st_mode):03o}); run: chmod 600 {path}"
        )
    raw = path.read_bytes()
    if len(raw) == 32:
        return raw
    text = raw.strip()
    try:
        key = bytes.fromhex(text.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != 32:
        raise KeyFileError(f"{path}: a key is 32 raw bytes or 64 hex digits (this file has {len(raw)} bytes)")
    return key


def key_from_passphrase(passphrase: str) -> bytes:
    """MAVProxy's ``signing setup PASSPHRASE`` convention: SHA-256 of the passphrase."""
    return hashlib.sha256(passphrase.encode("ascii")).digest()


def now_timestamp() -> int:
    """Current signing time (10 us units since 2015-01-01 UTC) from the wall clock."""
    return int((time.time() - EPOCH_2015) * UNITS_PER_S)


@dataclass
class Verifier:
    """Checks signed frames; replay state changes only on authentic frames."""

    key: bytes
    streams: dict[tuple[int, int, int], int] = field(default_factory=dict)
    latest: int = 0  # highest authenticated timestamp seen

    def check(self, frame: bytes, sysid: int, compid: int) -> str | None:
        """None if the frame is authentic and fresh, else the reason to reject it."""
        if len(frame) < 10 + SIGNATURE_LEN or frame[0] != 0xFD or not frame[2] & IFLAG_SIGNED:
            return "unsigned"
        link_id = frame[-13]
        ts = int.from_bytes(frame[-12:-6], "little")
        expect = hashlib.sha256(self.key + frame[:-6]).digest()[:6]
        if not hmac.compare_digest(expect, frame[-6:]):
            return "bad_signature"
        key = (link_id, sysid, compid)
        last = self.streams.get(key)
        if last is not None:
            if ts <= last:
                return "replayed"
        elif ts + NEW_STREAM_WINDOW < max(self.latest, now_timestamp()):
            return "stale_new_stream"
        self.streams[key] = ts
        self.latest = max(self.latest, ts)
        return None


class Signer:
    """Outgoing timestamps: strictly increasing, following the clock, never reused.

    ``state_path`` holds a reserved timestamp; after a restart signing starts
    above it, so timestamps used before a crash are never repeated.
    """

    def __init__(self, key: bytes, state_path: Path | None, link_id: int = 0) -> None:
        self.key = key
        self.link_id = link_id
        self.state_path = state_path
        self.last = 0
        self.reserved = 0
        if state_path is not None and state_path.is_file():
            try:
                self.last = int(state_path.read_text().strip())
            except ValueError:
                self.last = 0

    def next_timestamp(self) -> int:
        ts = max(self.last + 1, now_timestamp())
        self.last = ts
        if self.state_path is not None and ts >= self.reserved:
            self.reserved = ts + RESERVE
            tmp = self.state_path.with_suffix(".tmp")
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w") as fh:
                fh.write(f"{self.reserved}\n")
            os.replace(tmp, self.state_path)
        return ts

    def attach(self, mav: object) -> None:
        """Make a pymavlink MAVLink encoder sign everything it packs with this key."""
        mav.signing.secret_key = self.key  # type: ignore[attr-defined]
        mav.signing.link_id = self.link_id  # type: ignore[attr-defined]
        mav.signing.sign_outgoing = True  # type: ignore[attr-defined]

    def pack(self, msg: object, mav: object) -> bytes:
        """Pack and sign ``msg`` with a fresh timestamp (``attach`` first)."""
        mav.signing.timestamp = self.next_timestamp()  # type: ignore[attr-defined]
        return msg.pack(mav)  # type: ignore[attr-defined]

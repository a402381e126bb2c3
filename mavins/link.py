"""Links in and out: MAVLink frames with the address they came from.

UDP (``udpin:HOST:PORT`` and, as in pymavlink, ``udp:HOST:PORT`` listen;
``udpout:HOST:PORT`` sends to a fixed address) is handled here directly, so that every datagram's
sender is known: output goes only to fixed destinations and to *peers* that
earned it (sent a valid frame, or an authenticated one when a key is set),
never to whoever sends a datagram. Peers expire after a silence and their
number is bounded. Other pymavlink connection strings (serial devices,
``tcp:``, ``tcpin:``) are point to point and go through pymavlink's own
connection objects.
"""

from __future__ import annotations

import socket
import struct
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Protocol

from .mavlink import mavlink, mavutil

RCVBUF_BYTES = 8 * 1024 * 1024
MAX_DATAGRAM = 65535
# Kernel receive timestamps (Linux: SO_TIMESTAMP = SCM_TIMESTAMP = 29, a struct timeval).
SO_TIMESTAMP = getattr(socket, "SO_TIMESTAMP", 29 if sys.platform.startswith("linux") else None)


class LinkError(OSError):
    """A link that cannot be opened, with a message naming it."""


class Link(Protocol):
    """What the service needs from a link."""

    url: str

    age: float

    def fileno(self) -> int | None: ...
    def receive(self, max_datagrams: int) -> tuple[list[tuple[mavlink.MAVLink_message, object]], int]: ...
    def discard(self, limit: int) -> int: ...
    def authorize(self, addr: object) -> None: ...
    def send(self, buf: bytes) -> None: ...
    def close(self) -> None: ...


@dataclass
class PeerPolicy:
    """Who gets output on a listening link."""

    timeout: float = 10.0  # s of silence after which a peer stops receiving
    max_peers: int = 8


def _parser() -> mavlink.MAVLink:
    p = mavlink.MAVLink(None)
    p.robust_parsing = True
    return p


def _reset(parser: mavlink.MAVLink) -> None:
    """Drop any partial frame held by a parser."""
    parser.buf = bytearray()
    parser.buf_index = 0
    parser.expected_length = mavlink.HEADER_LEN_V1 + 2
    parser.have_prefix_error = False


def _host_port(url: str, scheme: str) -> tuple[str, int]:
    rest = url[len(scheme) + 1 :]
    host, _, port = rest.rpartition(":")
    try:
        return (host or "127.0.0.1"), int(port)
    except ValueError:
        raise LinkError(f"{url}: expected {scheme}:HOST:PORT") from None


class UdpLink:
    """A UDP link with per-datagram parsing and an explicit peer table."""

    def __init__(self, url: str, policy: PeerPolicy | None = None) -> None:
        self.url = url
        self.policy = policy or PeerPolicy()
        self.listen = url.startswith(("udpin:", "udp:"))
        scheme = url.split(":", 1)[0]
        host, port = _host_port(url, scheme)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        if SO_TIMESTAMP is not None:
            self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMP, 1)
        self.sock.setblocking(False)
        self.age = 0.0  # s the last datagram read had waited in the kernel
        self.fixed: tuple[str, int] | None = None
        try:
            if self.listen:
                self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self.sock.bind((host, port))
            else:
                self.fixed = (socket.gethostbyname(host), port)
                self.sock.bind(("0.0.0.0" if host not in ("127.0.0.1", "localhost") else "127.0.0.1", 0))
        except OSError as exc:
            self.sock.close()
            raise LinkError(f"{url}: {exc.strerror or exc}") from None
        self.peers: OrderedDict[object, float] = OrderedDict()
        self.parser = _parser()

    def fileno(self) -> int | None:
        return self.sock.fileno()

    def receive(self, max_datagrams: int) -> tuple[list[tuple[mavlink.MAVLink_message, object]], int]:
        """Messages of up to ``max_datagrams`` waiting datagrams, and how many were read."""
        out: list[tuple[mavlink.MAVLink_message, object]] = []
        n = 0
        while n < max_datagrams:
            try:
                data, anc, _, addr = self.sock.recvmsg(MAX_DATAGRAM, 64)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break  # e.g. ICMP port unreachable reported on a connected-less socket
            n += 1
            for level, kind, value in anc:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMP and len(value) >= 16:
                    sec, usec = struct.unpack("qq", value[:16])
                    self.age = time.time() - (sec + usec * 1e-6)
            msgs = self.parser.parse_buffer(data) or []
            out.extend((m, addr) for m in msgs)
            if self.parser.buf_len() > 0 or not msgs:
                # each datagram stands alone: a partial frame or no frame at all is garbage
                reason = "truncated frame" if msgs or self.parser.buf_len() > 0 else "no frame in datagram"
                out.append((mavlink.MAVLink_bad_data(bytearray(data[:64]), reason), addr))
                _reset(self.parser)
        return out, n

    def discard(self, limit: int) -> int:
        """Read and drop waiting datagrams (flood relief); returns how many."""
        n = 0
        while n < limit:
            try:
                self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError, OSError):
                break
            n += 1
        return n

    def authorize(self, addr: object) -> None:
        """Let ``addr`` receive output (it sent a valid or authenticated frame)."""
        if not self.listen:
            return
        now = time.monotonic()
        self.peers[addr] = now
        self.peers.move_to_end(addr)
        while len(self.peers) > self.policy.max_peers:
            self.peers.popitem(last=False)

    def send(self, buf: bytes) -> None:
        if self.fixed is not None:
            self._sendto(buf, self.fixed)
            return
        now = time.monotonic()
        for addr, seen in list(self.peers.items()):
            if now - seen > self.policy.timeout:
                del self.peers[addr]
                continue
            self._sendto(buf, addr)

    def _sendto(self, buf: bytes, addr: object) -> None:
        try:
            self.sock.sendto(buf, addr)  # type: ignore[arg-type]
        except (BlockingIOError, ConnectionRefusedError):
            pass  # nobody listening right now, or the send buffer is full: drop, never block

    def close(self) -> None:
        self.sock.close()


class MavutilLink:
    """Any other pymavlink connection (serial, TCP): point to point."""

    def __init__(self, url: str) -> None:
        self.url = url
        try:
            self.conn = mavutil.mavlink_connection(url, dialect="common", autoreconnect=True)
        except Exception as exc:  # pymavlink raises plain exceptions for bad devices/addresses
            raise LinkError(f"{url}: {exc}") from None
        self.parser = _parser()
        self.age = 0.0

    def fileno(self) -> int | None:
        fd = getattr(self.conn, "fd", None)
        return fd if isinstance(fd, int) and fd >= 0 else None

    def receive(self, max_datagrams: int) -> tuple[list[tuple[mavlink.MAVLink_message, object]], int]:
        try:
            data = self.conn.recv(4096)
        except (OSError, EOFError):
            data = b""
        if not data:
            return [], 0
        msgs = self.parser.parse_buffer(bytes(data)) or []
        return [(m, None) for m in msgs], 1

    def discard(self, limit: int) -> int:
        return 0

    def authorize(self, addr: object) -> None:
        return None

    def send(self, buf: bytes) -> None:
        try:
            self.conn.write(buf)
        except OSError:
            pass

    def close(self) -> None:
        self.conn.close()


def open_link(url: str, policy: PeerPolicy | None = None) -> Link:
    """A link for a pymavlink-style connection string."""
    if url.startswith(("udpin:", "udpout:", "udp:")):
        return UdpLink(url, policy)
    return MavutilLink(url)

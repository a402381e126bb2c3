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

from .decode import decode_one
from .mavlink import mavlink, mavutil, parser as _parser

RCVBUF_BYTES = 8 * 1024 * 1024
MAX_DATAGRAM = 65535
# s: a datagram that waited less than this in the kernel arrived while we waited for it, so nothing
# is queued behind it; the read stops there instead of asking again and failing (docs/performance.md)
FRESH_S = 0.0005
# Kernel receive timestamps (Linux: SO_TIMESTAMP = SCM_TIMESTAMP = 29, a struct timeval) and the
# kernel's count of datagrams dropped for a full receive buffer (Linux: SO_RXQ_OVFL = 40, a uint32).
_LINUX = sys.platform.startswith("linux")
SO_TIMESTAMP = getattr(socket, "SO_TIMESTAMP", 29 if _LINUX else None)
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40 if _LINUX else None)


# bytes: MAVLink frames sent together share a datagram up to this size, which fits an Ethernet
# frame (1500 - 20 IP - 8 UDP), so that no datagram is fragmented on its way (docs/service.md)
MAX_OUT_DATAGRAM = 1472


def datagrams(frames: list[bytes], limit: int = MAX_OUT_DATAGRAM) -> list[bytes]:
    """Consecutive frames joined, in order, into as few byte strings of at most ``limit`` bytes as
    greedy filling gives (a frame longer than ``limit`` goes alone). One ``sendto`` per output set
    instead of one per message: receivers parse a datagram as a stream of frames."""
    out: list[bytes] = []
    group: list[bytes] = []
    size = 0
    for f in frames:
        if group and size + len(f) > limit:
            out.append(b"".join(group))
            group, size = [], 0
        group.append(f)
        size += len(f)
    if group:
        out.append(b"".join(group))
    return out


class LinkError(OSError):
    """A link that cannot be opened, with a message naming it."""


class Link(Protocol):
    """What the service needs from a link."""

    url: str

    age: float

    def fileno(self) -> int | None: ...
    def receive(self, max_datagrams: int) -> tuple[list[tuple[mavlink.MAVLink_message, object]], int]: ...
    @property
    def dropped(self) -> int: ...
    def authorize(self, addr: object) -> None: ...
    def take_skipped(self) -> list[bytes]: ...
    def send(self, buf: bytes) -> None: ...
    def close(self) -> None: ...


@dataclass
class PeerPolicy:
    """Who gets output on a listening link, and how long input may wait."""

    timeout: float = 10.0  # s of silence after which a peer stops receiving
    max_peers: int = 8
    max_lag: float = 0.25  # s: under a sustained overload, a datagram that waited longer is skipped
    stall_grace: float = 2.0  # s of reading late data before a backlog counts as overload, not a stall


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
        for opt in (SO_TIMESTAMP, SO_RXQ_OVFL):
            if opt is not None:
                try:
                    self.sock.setsockopt(socket.SOL_SOCKET, opt, 1)
                except OSError:
                    pass
        self.sock.setblocking(False)
        self.age = 0.0  # s the last datagram read had waited in the kernel
        self.dropped_late = 0  # datagrams read but not processed (overload only): skipped late or thinned
        self.kernel_dropped = 0  # datagrams the kernel dropped for a full buffer
        self.thin = 1  # under overload only every thin-th datagram is parsed
        self.skipped: list[bytes] = []  # raw datagrams read but not processed, for the input log
        self._seen = 0
        self._late_since: float | None = None  # wall time since which every read found late data
        self.fixed: tuple[str, int] | None = None
        try:
            if self.listen:
                # no SO_REUSEADDR: on Linux it would let any local user's socket bind the same UDP port
                # and take the input (docs/security.md); UDP has no TIME_WAIT, so a restart rebinds anyway
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
        """Messages of up to ``max_datagrams`` waiting datagrams, and how many were read.

        A one-off stall (start-up, a collection, a slow disk) leaves a backlog in
        the socket buffer that is read late and processed in full. Only a real
        overload sheds input: while the kernel drops datagrams (its buffer is
        full) only every ``thin``-th one is parsed, and once every read for
        ``stall_grace`` seconds has found data older than ``max_lag`` (the
        service does not keep up on average) the late ones are skipped. What
        is processed then stays current and evenly spread in sensor time.
        Skipped datagrams are kept in ``skipped`` (raw bytes) for the input log.
        The read stops early at a processed datagram that waited under ``FRESH_S``
        in the kernel (nothing is queued behind it), or when the socket is empty.
        """
        out: list[tuple[mavlink.MAVLink_message, object]] = []
        n = 0
        now = time.time()
        kernel_before = self.kernel_dropped
        shed_late = self._overloaded_by_lag(now)
        max_lag = self.policy.max_lag
        late_seen = False
        while n < max_datagrams:
            try:
                data, anc, _, addr = self.sock.recvmsg(MAX_DATAGRAM, 64)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break  # e.g. ICMP port unreachable reported on a connected-less socket
            n += 1
            stamped = False
            for level, kind, value in anc:
                if level != socket.SOL_SOCKET:
                    continue
                if kind == SO_TIMESTAMP and len(value) >= 16:
                    sec, usec = struct.unpack("qq", value[:16])
                    self.age = now - (sec + usec * 1e-6)
                    stamped = True
                elif kind == SO_RXQ_OVFL and len(value) >= 4:
                    self.kernel_dropped = struct.unpack("I", value[:4])[0]
            more = not (stamped and self.age < FRESH_S)
            late = self.age > max_lag
            late_seen = late_seen or late
            self._seen += 1
            if (late and shed_late) or (self.thin > 1 and self._seen % self.thin):
                self.dropped_late += 1
                self.skipped.append(data)
                continue
            one = decode_one(data)
            if one is not None:
                out.append((one, addr))
            else:
                msgs = self.parser.parse_buffer(data) or []
                out.extend((m, addr) for m in msgs)
                if self.parser.buf_len() > 0 or not msgs:
                    # each datagram stands alone: a partial frame or no frame at all is garbage
                    reason = "truncated frame" if msgs or self.parser.buf_len() > 0 else "no frame in datagram"
                    out.append((mavlink.MAVLink_bad_data(bytearray(data[:64]), reason), addr))
                    _reset(self.parser)
            if not more:
                break
        if n:
            self._late_since = (self._late_since or now) if late_seen else None
        self._adapt_thinning(kernel_before, n, max_datagrams)
        return out, n

    def _overloaded_by_lag(self, now: float) -> bool:
        """True once every read for ``stall_grace`` seconds has found late data."""
        return self._late_since is not None and now - self._late_since > self.policy.stall_grace

    def take_skipped(self) -> list[bytes]:
        """Raw datagrams read but not processed since the last call."""
        out, self.skipped = self.skipped, []
        return out

    def _adapt_thinning(self, kernel_before: int, n: int, max_datagrams: int) -> None:
        """Thin uniformly while the kernel is dropping (true overload), so the datagrams that are
        processed stay evenly spread in time instead of the clusters a full buffer lets through."""
        if self.kernel_dropped > kernel_before:
            self.thin = min(self.thin * 2, 1024)
        elif n < max_datagrams and self.thin > 1:
            self.thin //= 2

    @property
    def dropped(self) -> int:
        """Input not processed for lack of capacity: skipped by us plus dropped by the kernel."""
        return self.dropped_late + self.kernel_dropped

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
            self.conn = mavutil.mavlink_connection(url, dialect="ardupilotmega", autoreconnect=True)
        except Exception as exc:  # pymavlink raises plain exceptions for bad devices/addresses
            raise LinkError(f"{url}: {exc}") from None
        self.parser = _parser()
        self.age = 0.0
        self.dropped = 0
        self.dropped_late = 0
        self.kernel_dropped = 0

    def take_skipped(self) -> list[bytes]:
        return []

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

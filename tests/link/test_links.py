"""The MAVLink links over real sockets on 127.0.0.1: what UdpLink reads, sheds and sends, MavutilLink, open_link.

Time enters UdpLink in two places: the kernel's arrival stamp of each datagram (SO_TIMESTAMP, a
struct timeval) against the wall clock gives its ``age`` and drives the lag shedding, and the
monotonic clock drives peer expiry. Tests that depend on either replace the links module's ``time``
with a clock they set, and read a waiting datagram's kernel stamp with MSG_PEEK (the datagram stays
queued for the link), so an age or a silence is exactly the value the test gives it, whatever the
load. Kernel drops are made, not hoped for: the link's receive buffer is shrunk to the kernel's
minimum and a burst is sent while nothing reads. These mechanisms are Linux's (SO_RXQ_OVFL,
IP_RECVERR), as is the service's deployment.
"""

from __future__ import annotations

import errno
import math
import os
import select
import socket
import struct
import sys
import time

import pytest

from mavins.link import links
from mavins.link.links import LinkError, MavutilLink, PeerPolicy, UdpLink, open_link
from mavins.link.mavlink import mavlink, parser

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux socket options")

SO_TIMESTAMP = 29  # Linux: SO_TIMESTAMP = SCM_TIMESTAMP, ancillary data a struct timeval
IP_RECVERR = 11  # Linux: report ICMP errors on an unconnected UDP socket
END = b"end-of-test-output"
MAV = mavlink.MAVLink(None, 1, 1)


def _imu(t: int) -> bytes:
    """One HIGHRES_IMU frame with time_usec t (a datagram the one-step decoder takes)."""
    return bytes(MAV.highres_imu_encode(t, 0.0, 0.0, -9.8, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4, 0.0, 0.0, 0.0, 0.0,
                                        0b111111111, 0).pack(MAV))


def _text(s: bytes) -> bytes:
    """One STATUSTEXT frame (text: it goes through pymavlink's parser)."""
    return bytes(MAV.statustext_encode(6, s).pack(MAV))


def _port(link: UdpLink) -> int:
    return link.sock.getsockname()[1]


def _send(link: UdpLink, datagrams: list[bytes], settle: float = 0.05) -> None:
    """Send datagrams to the link from one socket, then wait ``settle`` s (loopback delivers within the send)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for d in datagrams:
            tx.sendto(d, ("127.0.0.1", _port(link)))
    time.sleep(settle)


def _wait_readable(sock: socket.socket | int) -> None:
    assert select.select([sock], [], [], 5.0)[0], "nothing arrived in 5 s"


def _stamp(link: UdpLink) -> float:
    """The kernel's arrival stamp (seconds + microseconds) of the next waiting datagram, which stays queued."""
    _wait_readable(link.sock)
    _, anc, _, _ = link.sock.recvmsg(65535, 64, socket.MSG_PEEK)
    (value,) = [v for level, kind, v in anc if level == socket.SOL_SOCKET and kind == SO_TIMESTAMP]
    sec, usec = struct.unpack("qq", value[:16])
    return sec + usec * 1e-6


def _receiver() -> socket.socket:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5.0)
    return rx


def _inbox(link: UdpLink, rx: socket.socket) -> list[bytes]:
    """What the link has sent to rx: every datagram before an end marker its own socket sends afterwards."""
    link.sock.sendto(END, rx.getsockname())
    got = []
    while (d := rx.recv(65535)) != END:
        got.append(d)
    return got


class Clock:
    """Stands in for the links module's ``time``: wall and monotonic time are what the test sets."""

    def __init__(self, now: float) -> None:
        self.now = now

    def time(self) -> float:
        return self.now

    def monotonic(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> Clock:
    c = Clock(time.time())
    monkeypatch.setattr(links, "time", c)
    return c


@pytest.fixture
def link():
    lk = UdpLink("udpin:127.0.0.1:0")
    yield lk
    lk.close()


# ---- opening links ----------------------------------------------------------------------------------------------


def test_datagrams_join_frames_in_order_up_to_the_limit() -> None:
    a, b, c, d = b"a" * 600, b"b" * 600, b"c" * 600, b"d" * 100
    assert links.datagrams([a, b, c, d], limit=1472) == [a + b, c + d]
    assert links.datagrams([a, b], limit=1200) == [a + b]  # exactly the limit fits
    assert links.datagrams([a, b], limit=1199) == [a, b]
    assert links.datagrams([a, b, c, b], limit=1200) == [a + b, c + b]  # a later datagram fills up exactly too
    assert links.datagrams([d, b"x" * 2000, d], limit=1472) == [d, b"x" * 2000, d]  # too long: alone, in place
    assert links.datagrams([]) == []
    assert links.MAX_OUT_DATAGRAM == 1500 - 20 - 8  # Ethernet MTU less the IPv4 and UDP headers


def test_defaults_are_the_documented_ones() -> None:
    """PeerPolicy defaults are docs/service.md's: peers 10 s and 8, overload after 2 s of data older than 0.25 s."""
    p = PeerPolicy()
    assert (p.timeout, p.max_peers, p.max_lag, p.stall_grace) == (10.0, 8, 0.25, 2.0)


@pytest.mark.parametrize("scheme", ["udpin", "udp"])
def test_udpin_and_udp_listen(scheme: str) -> None:
    """``udpin:`` and (as in pymavlink) ``udp:`` listen on HOST:PORT: a UdpLink with no fixed destination,
    whose output goes to a sender it authorised, and the policy given to open_link is the one it applies."""
    policy = PeerPolicy(max_peers=3)
    url = f"{scheme}:127.0.0.1:0"
    lk = open_link(url, policy)
    rx = _receiver()
    try:
        assert isinstance(lk, UdpLink)
        assert lk.url == url and lk.policy is policy and lk.fixed is None
        assert lk.sock.getsockname()[0] == "127.0.0.1"
        lk.authorize(rx.getsockname())
        lk.send(b"out")
        assert _inbox(lk, rx) == [b"out"]
    finally:
        lk.close()
        rx.close()


@pytest.mark.parametrize(("host", "bound"), [("127.0.0.1", "127.0.0.1"), ("", "127.0.0.1"), ("0.0.0.0", "0.0.0.0")])
def test_a_listening_link_binds_the_host_given_and_the_loopback_by_default(host: str, bound: str) -> None:
    """``udpin:HOST:PORT`` binds HOST; an empty HOST is the loopback (docs/security.md: loopback by default)."""
    lk = UdpLink(f"udpin:{host}:0")
    try:
        assert lk.sock.getsockname()[0] == bound
        assert lk.listen
    finally:
        lk.close()


@pytest.mark.parametrize(("host", "addr", "bound"), [("127.0.0.1", "127.0.0.1", "127.0.0.1"),
                                                      ("localhost", "127.0.0.1", "127.0.0.1"),
                                                      ("", "127.0.0.1", "127.0.0.1"),
                                                      ("192.0.2.1", "192.0.2.1", "0.0.0.0")])
def test_udpout_sends_to_a_fixed_address_from_an_ephemeral_port(host: str, addr: str, bound: str) -> None:
    """``udpout:HOST:PORT`` resolves its destination and binds an ephemeral port (from the kernel's range):
    on the loopback for a local destination, on every interface otherwise (192.0.2.1 is TEST-NET-1)."""
    lo, hi = map(int, open("/proc/sys/net/ipv4/ip_local_port_range").read().split())
    lk = open_link(f"udpout:{host}:14550")
    try:
        assert isinstance(lk, UdpLink) and not lk.listen
        assert lk.fixed == (addr, 14550)
        got_host, got_port = lk.sock.getsockname()
        assert got_host == bound and lo <= got_port <= hi
    finally:
        lk.close()


def test_udpout_output_goes_to_its_destination_only_and_replies_come_back() -> None:
    """A udpout link sends to its fixed address, not to an address it was asked to authorise (it has no peers),
    and reads what the destination sends back, with the destination's address."""
    dest, other = _receiver(), _receiver()
    lk = UdpLink(f"udpout:127.0.0.1:{dest.getsockname()[1]}")
    try:
        lk.authorize(other.getsockname())
        assert len(lk.peers) == 0
        lk.send(b"solution")
        assert dest.recv(100) == b"solution"
        assert _inbox(lk, other) == []
        dest.sendto(_imu(7), lk.sock.getsockname())
        _wait_readable(lk.sock)
        out, n = lk.receive(8)
        assert n == 1
        assert [(m.time_usec, a) for m, a in out] == [(7, dest.getsockname())]
    finally:
        lk.close()
        dest.close()
        other.close()


@pytest.mark.parametrize("url", ["udpin:127.0.0.1:x", "udpout:127.0.0.1", "udp:host:"])
def test_a_malformed_url_is_a_link_error_naming_it(url: str) -> None:
    """A port that is not a number: LinkError whose message names the URL and the expected form."""
    scheme = url.split(":")[0]
    with pytest.raises(LinkError) as err:
        open_link(url)
    assert str(err.value) == f"{url}: expected {scheme}:HOST:PORT"


def test_a_port_in_use_is_a_link_error_and_leaves_no_socket_open() -> None:
    """Binding a port another socket holds exclusively fails: LinkError '<url>: <the system's reason>', and the
    socket the link had opened is closed (the half-built link is reached through the error's traceback)."""
    holder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    holder.bind(("127.0.0.1", 0))
    url = f"udpin:127.0.0.1:{holder.getsockname()[1]}"
    try:
        with pytest.raises(LinkError) as err:
            UdpLink(url)
        assert str(err.value) == f"{url}: {os.strerror(errno.EADDRINUSE)}"
        half_built = {id(x): x for x in (e.frame.f_locals.get("self") for e in err.traceback)
                      if isinstance(x, UdpLink)}
        assert len(half_built) == 1
        assert [x.sock.fileno() for x in half_built.values()] == [-1]
    finally:
        holder.close()


def test_no_other_socket_can_bind_a_listening_port(link: UdpLink) -> None:
    """A second socket, even one asking for SO_REUSEADDR, cannot bind the port the link listens on: on Linux a
    listening socket with SO_REUSEADDR would let any local user's socket take the datagrams meant for the
    service (docs/security.md: a local user can send to the port, not take it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        with pytest.raises(OSError):
            other.bind(link.sock.getsockname())


def test_a_fresh_link_has_read_and_dropped_nothing(link: UdpLink) -> None:
    """Before any read: age 0, nothing dropped or skipped, no thinning, no peers."""
    assert link.age == 0.0
    assert (link.dropped, link.dropped_late, link.kernel_dropped, link.thin) == (0, 0, 0, 1)
    assert link.take_skipped() == []
    assert len(link.peers) == 0


# ---- reading ----------------------------------------------------------------------------------------------------


def test_age_is_the_time_since_the_kernel_stamp(link: UdpLink, clock: Clock) -> None:
    """``age`` = now - the kernel's arrival stamp: 1.5 s with the clock set 1.5 s after the stamp (both are
    multiples of the clock's resolution, so the difference is exact)."""
    _send(link, [_imu(1)], settle=0.0)
    clock.now = _stamp(link) + 1.5
    out, n = link.receive(8)
    assert n == 1 and [m.time_usec for m, _ in out] == [1]
    assert link.age == 1.5


def test_without_kernel_stamps_a_backlog_is_read_to_the_end(link: UdpLink, monkeypatch: pytest.MonkeyPatch) -> None:
    """With SO_TIMESTAMP off (as on a platform without it) nothing says a datagram is fresh, so even with every
    stamped datagram counting as fresh the read goes on to the end of the backlog; age stays 0."""
    monkeypatch.setattr(links, "FRESH_S", 3600.0)
    link.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMP, 0)
    _send(link, [_imu(t) for t in range(1, 6)])
    out, n = link.receive(64)
    assert n == 5 and [m.time_usec for m, _ in out] == [1, 2, 3, 4, 5]
    assert link.age == 0.0


def test_a_socket_error_ends_the_read_and_sends_never_raise() -> None:
    """An ICMP 'port unreachable' reported on the socket (made real with IP_RECVERR, which has Linux report it on
    an unconnected socket) ends a read with nothing read, and a send that meets it is dropped without raising."""
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()
    lk = UdpLink(f"udpout:127.0.0.1:{port}")
    try:
        lk.sock.setsockopt(socket.IPPROTO_IP, IP_RECVERR, 1)
        lk.send(b"x")
        _wait_readable(lk.sock)
        assert lk.receive(8) == ([], 0)
        lk.send(b"x")
        _wait_readable(lk.sock)
        lk.send(b"x")
    finally:
        lk.close()


def test_each_datagram_stands_alone(link: UdpLink, monkeypatch: pytest.MonkeyPatch) -> None:
    """Datagrams the one-step decoder declines go through pymavlink's parser one at a time: what pymavlink
    gives for the bytes (a fresh parser on the same datagram) comes out, and a datagram that leaves a partial
    frame or gives no frame adds one BAD_DATA (its first 64 bytes; 'truncated frame' or 'no frame in
    datagram') and leaves nothing behind for the next one. FRESH_S is set below any wait so that only the
    empty socket ends the read."""
    monkeypatch.setattr(links, "FRESH_S", -1.0)
    long = bytes(MAV.file_transfer_protocol_encode(0, 1, 1, list(range(1, 252))).pack(MAV))
    assert len(long) > 100
    datagrams = [_imu(1) + _imu(2)[:10], _imu(3) + b"\xfd", b"\xfd", b"", long[:100], b"hello", _text(b"ok")]
    link_adds = ["truncated frame", "truncated frame", "truncated frame", "no frame in datagram",
                 "truncated frame", None, None]
    want = []
    for d, reason in zip(datagrams, link_adds):
        want += [(m.get_type(), bytes(m.get_msgbuf())) for m in parser().parse_buffer(d) or []]
        if reason:
            want.append(("BAD_DATA", reason, d[:64]))
    _send(link, datagrams)
    out, n = link.receive(64)
    while n < len(datagrams):
        _wait_readable(link.sock)
        more, k = link.receive(64)
        out, n = out + more, n + k
    assert n == len(datagrams)
    got = [("BAD_DATA", m.reason, bytes(m.data)) if m.get_type() == "BAD_DATA" and m.reason in link_adds
           else (m.get_type(), bytes(m.get_msgbuf())) for m, _ in out]
    assert got == want
    assert [t for t, *_ in want] == ["HIGHRES_IMU", "BAD_DATA", "HIGHRES_IMU", "BAD_DATA", "BAD_DATA", "BAD_DATA",
                                     "BAD_DATA", "BAD_DATA", "STATUSTEXT"]


@pytest.mark.parametrize(("fresh_s", "per_call"), [(links.FRESH_S, 5), (3600.0, 1)])
def test_parsed_datagrams_end_the_read_only_when_fresh(link: UdpLink, monkeypatch: pytest.MonkeyPatch,
                                                       fresh_s: float, per_call: int) -> None:
    """Datagrams through pymavlink's parser: a backlog that waited 50 ms (100 FRESH_S) is read in one call;
    with every datagram counting as fresh each call reads one. Nothing is lost either way."""
    monkeypatch.setattr(links, "FRESH_S", fresh_s)
    texts = [f"t{i}".encode() for i in range(5)]
    _send(link, [_text(t) for t in texts])
    got = []
    for _ in range(5 // per_call):
        out, n = link.receive(64)
        assert n == per_call
        got += [m.text for m, _ in out]
    assert got == [t.decode() for t in texts]
    assert link.receive(64) == ([], 0)


# ---- overload: thinning while the kernel drops -------------------------------------------------------------------


def _udp_drops(port: int) -> int:
    """The kernel's drop count of the UDP socket bound to 127.0.0.1:port (/proc/net/udp, last column)."""
    for line in open("/proc/net/udp").read().splitlines()[1:]:
        f = line.split()
        if f[1] == f"0100007F:{port:04X}":
            return int(f[-1])
    raise AssertionError("socket not found")


def test_kernel_drops_are_counted_and_thin_the_input(link: UdpLink) -> None:
    """With the receive buffer at the kernel's minimum, a burst of 50 unread datagrams overflows it. The
    datagrams queued before the overflow carry no drop count; the next one carries the kernel's count
    (50 - those read), which becomes ``kernel_dropped`` (as /proc/net/udp says) and ``dropped``, and on that
    read thin goes from 1 to 2: only every second datagram is parsed from then on."""
    link.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1)
    _send(link, [_imu(t) for t in range(1, 51)])
    _, queued = link.receive(1000)
    assert 0 < queued < 50
    assert (link.kernel_dropped, link.thin) == (0, 1)
    _send(link, [_imu(51)], settle=0.0)
    _wait_readable(link.sock)
    out, n = link.receive(1000)
    assert n == 1 and [m.time_usec for m, _ in out] == [51]
    assert link.kernel_dropped == 50 - queued == _udp_drops(_port(link))
    assert link.dropped == link.kernel_dropped and link.dropped_late == 0
    assert link.thin == 2


def test_thin_doubles_per_read_while_the_kernel_drops_and_halves_on_short_reads(link: UdpLink) -> None:
    """thin doubles on each read that finds the kernel's count risen (up to 1 in 1024), halves on each read that
    comes back short without a new drop, and stays on a full read. After one real overflow every datagram
    carries the kernel's (now constant) count, so setting ``kernel_dropped`` to 0 before a read is the kernel
    having dropped since the last one."""
    link.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1)
    _send(link, [_imu(t) for t in range(50)])
    link.receive(1000)
    link.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)

    def read(thin_before: int, dropping: bool, limit: int = 64) -> int:
        link.thin = thin_before
        if dropping:
            link.kernel_dropped = 0
        _send(link, [_imu(1)], settle=0.0)
        _wait_readable(link.sock)
        link.receive(limit)
        assert link.kernel_dropped > 0
        return link.thin

    assert read(1, True) == 2
    assert read(2, True) == 4
    assert read(512, True) == 1024
    assert read(1024, True) == 1024
    assert read(8, False) == 4
    assert read(2, False) == 1
    assert read(1, False) == 1
    assert read(4, False, limit=1) == 4


@pytest.mark.parametrize("thin", [2, 4])
def test_thinning_parses_every_thin_th_datagram_and_keeps_the_rest(link: UdpLink, monkeypatch: pytest.MonkeyPatch,
                                                                   thin: int) -> None:
    """With thin = m (as after reads with the kernel dropping) eight waiting datagrams are all read: the m-th,
    2m-th, ... are parsed, the others are counted as dropped and handed over raw, once, for the input log."""
    monkeypatch.setattr(links, "FRESH_S", -1.0)
    frames = [_imu(t) for t in range(1, 9)]
    link.thin = thin
    _send(link, frames)
    out, n = link.receive(8)
    assert n == 8
    assert [m.time_usec for m, _ in out] == [t for t in range(1, 9) if t % thin == 0]
    assert link.take_skipped() == [f for t, f in enumerate(frames, 1) if t % thin]
    assert link.take_skipped() == []
    assert link.dropped_late == link.dropped == 8 - 8 // thin
    assert link.thin == thin


# ---- overload: late data skipped only after stall_grace ----------------------------------------------------------


def _read_one(link: UdpLink, t: int) -> list[int]:
    """Send one HIGHRES_IMU with time_usec t, read it, and give the time_usec values that came out."""
    _send(link, [_imu(t)], settle=0.0)
    _wait_readable(link.sock)
    out, n = link.receive(8)
    assert n == 1
    return [m.time_usec for m, _ in out]


def test_late_data_is_skipped_only_after_stall_grace_of_late_reads(link: UdpLink, clock: Clock) -> None:
    """Default policy (max_lag 0.25 s, stall_grace 2 s). With the clock 1000 s after every stamp all data is
    late. Late reads at B, B+2 (a stall: processed, 2 s is not over the grace), B+2.5 (skipped, kept raw).
    A read of current data (0.1 s old) ends the overload: late reads from B+3 are processed until B+5, and
    skipped again at B+5.5."""
    base = time.time() + 1000.0
    for dt, t, kept in [(0.0, 1, True), (2.0, 2, True), (2.5, 3, False)]:
        clock.now = base + dt
        assert _read_one(link, t) == ([t] if kept else [])
    assert link.dropped_late == 1 and link.take_skipped() == [_imu(3)]
    _send(link, [_imu(4)], settle=0.0)
    clock.now = _stamp(link) + 0.1
    assert [m.time_usec for m, _ in link.receive(8)[0]] == [4]
    for dt, t, kept in [(3.0, 5, True), (5.0, 6, True), (5.5, 7, False)]:
        clock.now = base + dt
        assert _read_one(link, t) == ([t] if kept else [])
    assert link.dropped_late == 2 and link.dropped == 2


def test_one_late_datagram_makes_a_read_late(link: UdpLink, clock: Clock) -> None:
    """A read of a late datagram (0.3 s old) then a current one (sent 60 ms later, so at most 0.24 s old) counts
    as a late read: both are processed, and a late read 1000 s later skips its datagram."""
    _send(link, [_imu(1)], settle=0.06)
    _send(link, [_imu(2)])
    clock.now = _stamp(link) + 0.3
    out, n = link.receive(8)
    assert n == 2 and [m.time_usec for m, _ in out] == [1, 2]
    clock.now += 1000.0
    assert _read_one(link, 3) == []


def test_a_datagram_exactly_max_lag_old_is_not_late(monkeypatch: pytest.MonkeyPatch, clock: Clock) -> None:
    """Overloaded (stall_grace 0, after a read of data 2^-20 s over max_lag): a datagram one clock tick over
    max_lag = 0.25 s is skipped, one exactly 0.25 s old is processed. The sends are 10 ms apart, so each read
    is later than the first late one. FRESH_S below any wait, so every read takes one datagram only because
    one is waiting."""
    monkeypatch.setattr(links, "FRESH_S", -1.0)
    lk = UdpLink("udpin:127.0.0.1:0", PeerPolicy(max_lag=0.25, stall_grace=0.0))
    try:
        for t, over in [(1, 2.0 ** -20), (2, "tick"), (3, 0.0)]:
            _send(lk, [_imu(t)], settle=0.0)
            stamp = _stamp(lk)
            clock.now = math.nextafter(stamp + 0.25, math.inf) if over == "tick" else stamp + 0.25 + over
            out, n = lk.receive(8)
            assert n == 1
            assert [m.time_usec for m, _ in out] == ([] if t == 2 else [t])
            time.sleep(0.01)
        assert lk.take_skipped() == [_imu(2)]
    finally:
        lk.close()


# ---- peers ------------------------------------------------------------------------------------------------------


def test_only_authorised_senders_receive(link: UdpLink) -> None:
    """Output goes to the addresses the service authorised, not to other sockets; with no peers nothing goes out."""
    a, b = _receiver(), _receiver()
    try:
        link.send(b"nobody")
        link.authorize(a.getsockname())
        link.send(b"out")
        assert _inbox(link, a) == [b"out"]
        assert _inbox(link, b) == []
    finally:
        a.close()
        b.close()


def test_the_peer_table_keeps_the_max_peers_most_recent() -> None:
    """max_peers = 2: two peers both receive; a peer heard again becomes the most recent, so a third evicts
    the one heard least recently."""
    lk = UdpLink("udpin:127.0.0.1:0", PeerPolicy(max_peers=2))
    a, b, c = _receiver(), _receiver(), _receiver()
    try:
        lk.authorize(a.getsockname())
        lk.authorize(b.getsockname())
        lk.send(b"1")
        lk.authorize(a.getsockname())
        lk.authorize(c.getsockname())
        lk.send(b"2")
        assert [_inbox(lk, r) for r in (a, b, c)] == [[b"1", b"2"], [b"1"], [b"2"]]
        assert list(lk.peers) == [a.getsockname(), c.getsockname()]
    finally:
        for s in (lk, a, b, c):
            s.close()


def test_a_silent_peer_expires_after_the_timeout(link: UdpLink, clock: Clock) -> None:
    """Default timeout 10 s on the monotonic clock: A heard at 100, B at 105. At 110 (A silent exactly 10 s) both
    receive; at 110.5 A has expired and leaves the table while B still receives; heard again, A receives again."""
    a, b = _receiver(), _receiver()
    try:
        clock.now = 100.0
        link.authorize(a.getsockname())
        clock.now = 105.0
        link.authorize(b.getsockname())
        for now, payload in [(110.0, b"1"), (110.5, b"2")]:
            clock.now = now
            link.send(payload)
        assert list(link.peers) == [b.getsockname()]
        clock.now = 111.0
        link.authorize(a.getsockname())
        link.send(b"3")
        assert _inbox(link, a) == [b"1", b"3"]
        assert _inbox(link, b) == [b"1", b"2", b"3"]
    finally:
        a.close()
        b.close()


# ---- other pymavlink connections ---------------------------------------------------------------------------------


@pytest.fixture
def tcp():
    """A TCP server on 127.0.0.1, a MavutilLink connected to it, and the server's end of the connection."""
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    server.settimeout(5.0)
    url = f"tcp:127.0.0.1:{server.getsockname()[1]}"
    lk = open_link(url)
    conn, _ = server.accept()
    yield server, lk, conn, url
    lk.close()
    conn.close()
    server.close()


def test_a_tcp_link_reads_writes_and_has_nothing_to_shed(tcp) -> None:
    """``tcp:HOST:PORT`` is a MavutilLink: its descriptor is the connection's (for select), a read gives the frames
    that arrived (no sender address, one read counted) or nothing, a send writes the bytes; it has no peers and
    never skips or drops input."""
    server, lk, conn, url = tcp
    assert isinstance(lk, MavutilLink) and lk.url == url
    with socket.socket(fileno=os.dup(lk.fileno())) as same:
        assert same.getpeername() == conn.getsockname()
    assert lk.receive(64) == ([], 0)
    conn.sendall(_imu(1) + _imu(2))
    _wait_readable(lk.fileno())
    out, n = lk.receive(64)
    assert n == 1 and [(m.time_usec, a) for m, a in out] == [(1, None), (2, None)]
    lk.send(b"solution")
    assert conn.recv(100) == b"solution"
    assert lk.authorize(("127.0.0.1", 1)) is None and lk.take_skipped() == []
    assert (lk.age, lk.dropped, lk.dropped_late, lk.kernel_dropped) == (0.0, 0, 0, 0)


def test_a_reset_tcp_link_reads_nothing_and_reconnects(tcp) -> None:
    """The server resets the connection: the read gives nothing (no exception), pymavlink reconnects, and what
    the server sends on the new connection is read."""
    server, lk, conn, _ = tcp
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    conn.close()
    _wait_readable(lk.fileno())
    assert lk.receive(64) == ([], 0)
    conn2, _ = server.accept()
    try:
        conn2.sendall(_imu(9))
        _wait_readable(lk.fileno())
        out, n = lk.receive(64)
        assert n == 1 and [m.time_usec for m, _ in out] == [9]
    finally:
        conn2.close()


@pytest.mark.parametrize(("fd", "want"), [(0, 0), (-1, None), (None, None)])
def test_fileno_is_a_usable_descriptor_or_none(tcp, fd: object, want: object) -> None:
    """A connection's descriptor is given when it is one (0 included); -1 or none (pymavlink connections without
    a pollable descriptor) give None, so the service does not select on it."""
    _, lk, _, _ = tcp
    real = lk.conn.fd
    lk.conn.fd = fd
    try:
        assert lk.fileno() == want
    finally:
        lk.conn.fd = real


def test_a_device_that_cannot_be_opened_is_a_link_error_naming_it(tmp_path) -> None:
    """A serial device that does not exist: LinkError whose message starts with the URL."""
    url = str(tmp_path / "no-such-device")
    with pytest.raises(LinkError) as err:
        open_link(url)
    assert str(err.value).startswith(f"{url}: ")

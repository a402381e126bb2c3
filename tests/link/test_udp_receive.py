"""UdpLink.receive over a real socket on 127.0.0.1: what one call reads.

A call reads the datagrams waiting in the kernel, in order, up to its limit,
and stops early at a datagram that waited less than ``links.FRESH_S`` (it
arrived while the service was waiting, so nothing is queued behind it): at
kilohertz rates the read then does not ask the empty socket again.
"""

from __future__ import annotations

import socket
import time

import pytest

from mavins.link import links
from mavins.link.links import UdpLink
from mavins.link.mavlink import mavlink


def _frames(n: int) -> list[bytes]:
    """n HIGHRES_IMU frames, time_usec 1..n."""
    mav = mavlink.MAVLink(None, 1, 1)
    return [bytes(mav.highres_imu_encode(i, 0.0, 0.0, -9.8, 0.0, 0.0, 0.0, 0.2, 0.0, 0.4, 0.0, 0.0, 0.0, 0.0,
                                         0b111111111, 0).pack(mav)) for i in range(1, n + 1)]


def _send_and_settle(link: UdpLink, frames: list[bytes], settle: float) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        for f in frames:
            tx.sendto(f, ("127.0.0.1", link.sock.getsockname()[1]))
    time.sleep(settle)


def test_a_backlog_is_read_in_one_call() -> None:
    """Twenty datagrams that waited 50 ms (100 times FRESH_S) in the kernel: one call reads all twenty, in order,
    and the next finds the socket empty."""
    link = UdpLink("udpin:127.0.0.1:0")
    try:
        assert links.FRESH_S * 100 <= 0.05
        _send_and_settle(link, _frames(20), 0.05)
        out, n = link.receive(64)
        assert n == 20
        assert [m.time_usec for m, _ in out] == list(range(1, 21))
        assert link.receive(64) == ([], 0)
    finally:
        link.close()


def test_the_limit_bounds_a_call_and_the_rest_waits() -> None:
    """A limit of 8 over twenty waiting datagrams: 8, 8, then 4, in order."""
    link = UdpLink("udpin:127.0.0.1:0")
    try:
        _send_and_settle(link, _frames(20), 0.05)
        got = []
        for want in (8, 8, 4):
            out, n = link.receive(8)
            assert n == want
            got += [m.time_usec for m, _ in out]
        assert got == list(range(1, 21))
    finally:
        link.close()


def test_a_fresh_datagram_ends_the_read_and_nothing_is_lost(monkeypatch: pytest.MonkeyPatch) -> None:
    """With FRESH_S set above any wait, every datagram counts as fresh: each call reads exactly one and stops
    (no further read of the socket), and the queued ones come in the next calls, in order, none lost."""
    monkeypatch.setattr(links, "FRESH_S", 3600.0)
    link = UdpLink("udpin:127.0.0.1:0")
    try:
        _send_and_settle(link, _frames(5), 0.05)
        got = []
        for _ in range(5):
            out, n = link.receive(64)
            assert n == 1
            got += [m.time_usec for m, _ in out]
        assert got == [1, 2, 3, 4, 5]
        assert link.receive(64) == ([], 0)
    finally:
        link.close()

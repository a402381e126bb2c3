"""The peer table of ``mavins run``: how soon a silent peer stops receiving (``--peer-timeout 2``),
and the RSS growth of the table under 3000 source ports.

Run from the repository root::

    .venv/bin/python benchmarks/bench_peers.py"""

from __future__ import annotations

import argparse
import socket
import struct
import sys
import time
from typing import Sequence

from service_harness import NOTES, ServiceProc, _row, _verdict, free_udp_port, log, proc_rss_mb


# --- peers -------------------------------------------------------------------------------
def _hb_frame() -> bytes:
    from mavins.link.mavlink import mavlink

    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    return bytes(plain.heartbeat_encode(6, 8, 0, 0, 4).pack(plain))


def _stamped(sock: socket.socket) -> list[float]:
    """Kernel receive stamps of every datagram waiting in ``sock`` (SO_TIMESTAMP on)."""
    out = []
    so_ts = getattr(socket, "SO_TIMESTAMP", 29)
    while True:
        try:
            _, anc, _, _ = sock.recvmsg(65535, 64, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return out
        stamp = time.time()
        for level, kind, value in anc:
            if level == socket.SOL_SOCKET and kind == so_ts and len(value) >= 16:
                sec, usec = struct.unpack("qq", value[:16])
                stamp = sec + usec * 1e-6
        out.append(stamp)


def _peer_socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_TIMESTAMP", 29), 1)
    s.bind(("127.0.0.1", 0))
    return s


def peer_expiry(timeout: float = 2.0, watch: float = 5.5) -> dict:
    """How long after its only frame a silent peer still receives (``--peer-timeout``); a talker for contrast."""
    hb = _hb_frame()
    port = free_udp_port()
    svc = ServiceProc(port, ["--sysid", "1", "--peer-timeout", repr(timeout)], max_duration=watch + 120)
    silent, talker = _peer_socket(), _peer_socket()
    svc.start()
    try:
        t0 = time.time()
        silent.sendto(hb, ("127.0.0.1", port))
        got_s: list[float] = []
        got_t: list[float] = []
        next_talk = time.monotonic()
        end = next_talk + watch
        while time.monotonic() < end:
            if time.monotonic() >= next_talk:
                talker.sendto(hb, ("127.0.0.1", port))
                next_talk += 0.5
            got_s += _stamped(silent)
            got_t += _stamped(talker)
            time.sleep(0.02)
    finally:
        svc.stop()
        silent.close()
        talker.close()
    return {"timeout": timeout, "watch": watch, "silent_last": (max(got_s) - t0) if got_s else None,
            "silent_n": len(got_s), "talker_last": (max(got_t) - t0) if got_t else None}


def peer_table_rss(n_ports: int = 3000) -> dict:
    """RSS of ``mavins run --max-peers 4`` before and after frames from ``n_ports`` source ports."""
    hb = _hb_frame()
    port = free_udp_port()
    svc = ServiceProc(port, ["--sysid", "1", "--max-peers", "4", "--peer-timeout", "600"], max_duration=600)
    svc.start()
    try:
        time.sleep(0.5)
        rss0 = proc_rss_mb(svc.pid)
        for i in range(n_ports):
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.bind(("127.0.0.1", 0))
                s.sendto(hb, ("127.0.0.1", port))
            if i % 200 == 199:
                time.sleep(0.01)
        svc.drain()
        time.sleep(2.0)
        rss1 = proc_rss_mb(svc.pid)
    finally:
        c = svc.stop()
    return {"n": n_ports, "rss0": rss0, "rss1": rss1, "received": c.get("messages_received", 0)}

def main(argv: Sequence[str] = ()) -> list[dict]:
    """How soon a silent peer stops receiving, and the peer table's memory under many source ports."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="(no shorter form: the runs take seconds)")
    p.parse_args(list(argv))
    NOTES.clear()
    rows: list[dict] = []
    log("peers: expiry of a silent peer (--peer-timeout 2)")
    pe = peer_expiry(2.0)
    last = pe["silent_last"]
    rows.append(_row("peer expiry: last datagram to a silent peer after its frame",
                     value="none" if last is None else f"{last:.2f} s",
                     goal=f"<= timeout + 0.5 s: {_verdict(last is not None and last <= pe['timeout'] + 0.5)}",
                     note=f"--peer-timeout {pe['timeout']:g}; {pe['silent_n']} datagrams; a talker every "
                          f"0.5 s last received at {pe['talker_last'] or 0:.2f} s of {pe['watch']:g}"))
    log("peers: memory of the peer table under 3000 source ports")
    pt = peer_table_rss(3000)
    if pt["rss0"] and pt["rss1"]:
        grown = pt["rss1"] - pt["rss0"]
        rows.append(_row(f"peer table: RSS growth after {pt['n']:,} source ports", samples=pt["n"],
                         value=f"{grown:+.1f} MB", goal=f"< 5 MB: {_verdict(grown < 5)}",
                         note=f"--max-peers 4; {pt['rss0']:.1f} -> {pt['rss1']:.1f} MB; "
                              f"{pt['received']:,} frames read"))

    return rows


if __name__ == "__main__":
    from run_all import print_report

    print_report(main(sys.argv[1:]), NOTES)

"""Link security, live: ``mavins run`` as a subprocess on 127.0.0.1, attacked over real UDP (docs/security.md).

Threat model in short: anyone who can send a datagram to the service's port
may send anything (garbage, forged, captured and replayed frames, commands)
from any number of source ports. With a key, only frames signed with it count
and only their senders receive output; without a key, any valid frame is
accepted (there is nothing to tell a vehicle from an impostor), but garbage
still earns nothing.

One service runs for the whole module (``long_service``, started first): it
navigates on a signed stream at real time while the other tests run against
their own services, and the last test checks it after 90 s (longer than the
one minute a new signed stream may lag the clock): a freshly started plain
pymavlink peer accepts its frames, whose signing timestamps follow the wall
clock. Signed streams are encoded once the service is ready, so a slow start
(kernels compiled on a loaded machine) never makes them stale.

Nothing here asserts how long something took: each wait is for an event (a
datagram, the service having read its input) with a generous timeout, and
order is told by the kernel's receive stamps. Timings (peer expiry, memory of
the peer table) are measured in benchmarks/bench_peers.py.
"""

from __future__ import annotations

import hashlib
import os
import random
import socket
import stat
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from sim.generate import generate  # noqa: E402
from support import recv_stamped, udp_stats, wait_for_room, wait_until, wait_until_read  # noqa: E402
from test_hardening import (  # noqa: E402
    BOOT_US, ENV, MAVINS, VEH_SYS, Svc, drain, encode, imu_frame, make_key, nav_args, read_nav, scenario,
    send_paced, truth_at, udp_socket, wrap_deg,
)

EPOCH_2015 = 1420070400
UNITS = 100_000  # signing timestamp units per second (10 us)
LONG_RUN_S = 90.0
PASSPHRASE = "mavins security test"


def now_units() -> int:
    return int((time.time() - EPOCH_2015) * UNITS)


class ClockSigner(mavlink.MAVLink):
    """A pymavlink encoder that signs with timestamps following the clock (as an autopilot with a clock does)."""

    def __init__(self, key: bytes, sysid: int = VEH_SYS, compid: int = 1, link_id: int = 0,
                 offset_units: int = 0) -> None:
        super().__init__(None, srcSystem=sysid, srcComponent=compid)
        self.signing.secret_key, self.signing.sign_outgoing, self.signing.link_id = key, True, link_id
        self.offset = offset_units
        self.signing.timestamp = now_units() + offset_units

    def frame(self, msg: mavlink.MAVLink_message) -> bytes:
        self.signing.timestamp = max(self.signing.timestamp, now_units() + self.offset)
        buf = msg.pack(self)  # pack signs and then advances the timestamp by one
        self.seq = (self.seq + 1) % 256
        return buf


def timestamp_of(frame: bytes) -> int:
    return int.from_bytes(frame[-12:-6], "little")


def frames_of(datagram: bytes) -> list[bytes]:
    """The MAVLink 2 frames a datagram holds, in order (the service joins an output set's frames:
    docs/service.md): 10 header bytes, the payload, the CRC, and 13 signature bytes when signed."""
    out, i = [], 0
    while i < len(datagram):
        assert datagram[i] == 0xFD, f"not a MAVLink 2 frame at byte {i}"
        n = 12 + datagram[i + 1] + (13 if datagram[i + 2] & 1 else 0)
        out.append(datagram[i:i + n])
        i += n
    return out


def verify(key: bytes, datagrams: list[bytes]) -> tuple[list[mavlink.MAVLink_message], int]:
    """Messages whose signature checks with ``key`` (pymavlink's own check), and how many did not."""
    p = mavlink.MAVLink(None)
    p.signing.secret_key = key
    p.signing.timestamp = now_units()
    p.robust_parsing = True
    good, bad = [], 0
    for d in datagrams:
        for m in p.parse_buffer(d) or []:
            if m.get_type() == "BAD_DATA":
                bad += 1
            else:
                good.append(m)
    return good, bad


def rest_samples() -> tuple[tuple, tuple]:
    run = generate(scenario("rest", [{"kind": "static", "duration": 0.1}], 100.0, yaw=30.0), grade="ideal")
    w, f = run.rates()
    return tuple(float(x) for x in f[0]), tuple(float(x) for x in w[0])


# -- the long-running service ----------------------------------------------------------------
@dataclass
class LongRun:
    svc: Svc
    key: bytes
    key_path: Path
    tmp: Path
    t_start: float
    captured: list[bytes] = field(default_factory=list)  # the first signed frames the sender sent
    stop: threading.Event = field(default_factory=threading.Event)
    thread: threading.Thread | None = None
    sent: int = 0


def _stream_at_rest(lr: LongRun, sock: socket.socket) -> None:
    """HIGHRES_IMU at 100 Hz (+ ATTITUDE at 10 Hz) at real time, signed, until stopped."""
    f, w = rest_samples()
    enc = ClockSigner(lr.key)
    t0 = time.monotonic()
    k = 0
    while not lr.stop.is_set():
        t_us = BOOT_US + k * 10_000
        frames = [enc.frame(enc.highres_imu_encode(t_us, *f, *w, 0, 0, 0, 0, 0, 0, 20.0, 0b111111, 0))]
        if k % 10 == 0:
            frames.append(enc.frame(enc.attitude_encode((t_us // 1000) % 2**32, 0.0, 0.0, np.radians(30.0),
                                                        0.0, 0.0, 0.0)))
        try:
            for fr in frames:
                sock.sendto(fr, lr.svc.addr)
                lr.sent += 1
                if len(lr.captured) < 300:
                    lr.captured.append(fr)
            drain(sock)
        except ConnectionRefusedError:  # the service has stopped
            return
        k += 1
        delay = t0 + k * 0.01 - time.monotonic()
        if delay > 0:
            time.sleep(delay)


@pytest.fixture(scope="module", autouse=True)
def long_service(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    tmp = tmp_path_factory.mktemp("long")
    key_path, key = make_key(tmp, PASSPHRASE)
    svc = Svc(tmp, *nav_args(1.0), "--signing-key", str(key_path), name="long")
    lr = LongRun(svc, key, key_path, tmp, time.monotonic())
    sock = udp_socket()
    lr.thread = threading.Thread(target=_stream_at_rest, args=(lr, sock), daemon=True)
    lr.thread.start()
    try:
        yield lr
    finally:
        lr.stop.set()
        lr.thread.join(5.0)
        sock.close()
        svc.__exit__()


# -- forged frames in a signed stream --------------------------------------------------------------
def test_forged_frames_do_not_disturb_the_genuine_sender(tmp_path: Path) -> None:
    """Wrong-key frames with the genuine link id, system, component and a timestamp a day ahead, in the middle
    of a signed stream: refused and counted, and they never advance the stream's replay state (which would
    lock the genuine sender out): the solution keeps following the genuine data through a manoeuvre."""
    key_path, key = make_key(tmp_path, "forgery test")
    run = generate(scenario("turns", [{"kind": "static", "duration": 6.0},
                                      {"kind": "accelerate", "speed": 8.0, "accel": 2.0, "tilt": True},
                                      {"kind": "turn", "angle": 180.0, "rate": 30.0},
                                      {"kind": "cruise", "duration": 2.0}], 100.0), grade="ideal")
    nav = tmp_path / "nav.csv"
    g_sock, f_sock = udp_socket(), udp_socket()
    with Svc(tmp_path, *nav_args(5.0, "--gyro-bias", "none", "--signing-key", str(key_path), "-o", str(nav))) as svc:
        genuine = ClockSigner(key)
        forger = ClockSigner(hashlib.sha256(b"not the key").digest(), offset_units=86_400 * UNITS)  # link id 0 too
        items = encode(run, genuine)
        n_imu = sum(it.name == "HIGHRES_IMU" for it in items)
        stream: list[tuple[str, bytes]] = []
        n_forged = 0
        for it in items:
            stream.append(("genuine", it.data))
            if it.imu >= 0 and it.imu % 20 == 7:
                t_us = int(round(run.t[it.imu] * 1e6)) + BOOT_US + 1000
                stream.append(("forged", forger.frame(forger.highres_imu_encode(
                    t_us, 0.0, 0.0, -9.8, 1.0, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 20.0, 0b111111, 0))))
                n_forged += 1
                if it.imu % 100 == 7:
                    stream.append(("forged", forger.frame(forger.attitude_encode(t_us // 1000, 0.5, 0.5, 2.0,
                                                                                 0, 0, 0))))
                    n_forged += 1
        wall0 = time.monotonic()
        for k, (who, data) in enumerate(stream):
            (g_sock if who == "genuine" else f_sock).sendto(data, svc.addr)
            if k % 40 == 39:
                time.sleep(max(0.0, wall0 + k / 1500 - time.monotonic()))
                wait_for_room(svc.port)
        svc.settle()
        rc = svc.stop()
    assert rc == 0, svc.log()
    c = svc.summary()
    print(f"\ngenuine IMU {n_imu}, forged frames {n_forged}; summary {c}")
    assert svc.count("rejected_bad_signature") == n_forged
    assert svc.count("rejected_replayed") == 0 and svc.count("imu_accepted") == n_imu
    assert not drain(f_sock), "the forger receives nothing"
    rows = read_nav(nav)
    t_sim = rows[:, 0] - BOOT_US * 1e-6
    err = np.abs(wrap_deg(rows[:, 7:10] - truth_at(run, t_sim)[:, 7:10]))
    print(f"max |roll, pitch, yaw| error {err.max(0)} deg over {len(rows)} output sets")
    assert t_sim[-1] > run.t[-1] - 0.05, "outputs to the end of the genuine stream"
    assert np.ptp(truth_at(run, t_sim)[:, 9]) > 90.0, "the vehicle turned"
    assert err.max() < 0.5


# -- captured and replayed ---------------------------------------------------------------------
def test_replayed_signed_frames_are_rejected(tmp_path: Path) -> None:
    key_path, key = make_key(tmp_path, "replay test")
    run = generate(scenario("rest", [{"kind": "static", "duration": 4.0}], 100.0, roll=3.0, pitch=-2.0, yaw=30.0),
                   grade="ideal")
    nav = tmp_path / "nav.csv"
    g_sock, a_sock = udp_socket(), udp_socket()
    with Svc(tmp_path, *nav_args(1.0, "--signing-key", str(key_path), "-o", str(nav))) as svc:
        items = encode(run, ClockSigner(key))
        half = len(items) // 2
        send_paced(g_sock, svc.addr, items[:half], speed=4.0)
        captured = [it.data for it in items[:half]]
        replays = captured[-150:]  # the latest frames: the newest possible replays
        for k, d in enumerate(replays):  # from an attacker's address
            a_sock.sendto(d, svc.addr)
            if k % 16 == 15:
                wait_for_room(svc.port)
        for d in captured[:50]:  # and the genuine sender's own old frames (e.g. a routing loop)
            g_sock.sendto(d, svc.addr)
        send_paced(g_sock, svc.addr, items[half:], speed=4.0)
        svc.settle()
        rc = svc.stop()
    assert rc == 0
    c = svc.summary()
    print(f"\nreplayed {len(replays) + 50} captured frames; summary {c}")
    assert svc.count("rejected_replayed") == len(replays) + 50
    assert svc.count("imu_accepted") == sum(it.name == "HIGHRES_IMU" for it in items)
    assert not drain(a_sock), "a replaying address earns no output"
    assert np.abs(wrap_deg(read_nav(nav)[-1, 7:10] - [3.0, -2.0, 30.0])).max() < 0.01


# -- who receives anything --------------------------------------------------------------------------
def _junk_frames(rng: random.Random) -> list[bytes]:
    """Classic garbage: random bytes, a frame with a bad CRC, a truncated frame."""
    enc = mavlink.MAVLink(None, srcSystem=VEH_SYS, srcComponent=1)
    hb = bytearray(enc.heartbeat_encode(2, 3, 0, 0, 4).pack(enc))
    hb[12] ^= 0xFF
    return [bytes(rng.randrange(256) for _ in range(rng.randrange(1, 120))), bytes(hb),
            imu_frame(enc, 1_000_000, (0.0, 0.0, -9.8), (0.0,) * 3)[:25]]


UNKNOWN_ID_JUNK = bytes([0xFD, 0, 0, 0, 0, 1, 1, 0xFF, 0xFF, 0xFF, 0x12, 0x34])  # a header of an unknown id


def _pester(svc: Svc, senders: dict[str, tuple[socket.socket, list[bytes]]], rounds: int = 15) -> dict[str, int]:
    """Each sender sends its datagrams in turn, ``rounds`` times; returns how many datagrams each received.

    The first sender is one the service should answer. Once the service has read
    every datagram, it must receive two more (stamped after that): whatever the
    service sends to its peers then goes to every sender it took for a peer.
    """
    got: dict[str, list[tuple[float, bytes]]] = {name: [] for name in senders}
    for k in range(rounds):
        for name, (sock, frames) in senders.items():
            sock.sendto(frames[k % len(frames)], svc.addr)
    read_at = svc.settle()
    heard, (sock0, _) = next(iter(senders.items()))

    def two_more() -> bool:
        got[heard] += recv_stamped(sock0)
        return sum(1 for a, _ in got[heard] if a > read_at) >= 2

    wait_until(two_more, f"{heard}: two datagrams sent after the service read everything")
    for name, (sock, _) in senders.items():
        if name != heard:
            got[name] += recv_stamped(sock)
    return {name: len(v) for name, v in got.items()}


def test_with_a_key_only_the_key_holder_receives_anything(tmp_path: Path) -> None:
    key_path, key = make_key(tmp_path, "who receives")
    rng = random.Random(5)
    genuine = ClockSigner(key, sysid=255, compid=190)
    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    wrong = ClockSigner(hashlib.sha256(b"a guess").digest(), sysid=255, compid=190)
    f, w = rest_samples()
    hb = plain.heartbeat_encode(6, 8, 0, 0, 4)
    senders = {
        "genuine": (udp_socket(), [genuine.frame(hb) for _ in range(40)]),
        "garbage": (udp_socket(), _junk_frames(rng) + [UNKNOWN_ID_JUNK]),
        "unsigned": (udp_socket(), [hb.pack(plain), imu_frame(plain, 2_000_000, f, w)]),
        "wrong key": (udp_socket(), [wrong.frame(hb) for _ in range(40)]),
    }
    with Svc(tmp_path, "--sysid", "1", "--signing-key", str(key_path)) as svc:  # --sysid: it talks from the start
        got = _pester(svc, senders)
        rc = svc.stop()
    print(f"\ndatagrams received: {got}; summary {svc.summary()}")
    assert rc == 0
    assert got["genuine"] >= 2, "the key holder hears HEARTBEAT and SYS_STATUS"
    assert got["garbage"] == 0 and got["unsigned"] == 0 and got["wrong key"] == 0
    assert svc.count("rejected_unsigned") > 0 and svc.count("rejected_bad_signature") > 0


def test_without_a_key_garbage_earns_nothing(tmp_path: Path) -> None:
    rng = random.Random(6)
    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    senders = {
        "valid frames": (udp_socket(), [plain.heartbeat_encode(6, 8, 0, 0, 4).pack(plain)]),
        "garbage": (udp_socket(), _junk_frames(rng)),
        "unknown-id junk": (udp_socket(), [UNKNOWN_ID_JUNK]),
    }
    with Svc(tmp_path, "--sysid", "1") as svc:
        got = _pester(svc, senders)
        rc = svc.stop()
    print(f"\ndatagrams received: {got}; summary {svc.summary()}")
    assert rc == 0
    assert got["valid frames"] >= 2
    assert got["garbage"] == 0
    assert got["unknown-id junk"] == 0, "12 bytes shaped like a header of an unknown message id are garbage too"


# -- the peer table ------------------------------------------------------------------------------------
def test_silent_peer_stops_receiving_after_the_timeout(tmp_path: Path) -> None:
    """A peer that stops talking stops receiving (``--peer-timeout``), a peer that keeps talking keeps
    receiving, and a peer that talks again receives again. Told by the kernel's receive stamps: the
    service sends each datagram to its peers one after the other, so once the silent peer is dropped the
    talker receives datagrams stamped after the silent peer's last one (how soon: bench_peers.py)."""
    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    hb = plain.heartbeat_encode(6, 8, 0, 0, 4).pack(plain)
    silent, talker = udp_socket(), udp_socket()
    got: dict[str, list[float]] = {"silent": [], "talker": []}

    def poll(name: str, sock: socket.socket) -> list[float]:
        got[name] += [a for a, _ in recv_stamped(sock)]
        return got[name]

    with Svc(tmp_path, "--sysid", "1", "--peer-timeout", "1") as svc:
        def silent_is_a_peer() -> list[float]:
            silent.sendto(hb, svc.addr)  # it talks until it has heard something: then it is surely a peer
            return poll("silent", silent)

        wait_until(silent_is_a_peer, "the (not yet) silent peer receiving", poll=0.1)

        def dropped() -> bool:
            talker.sendto(hb, svc.addr)  # the other peer keeps talking
            poll("talker", talker)
            last = max(poll("silent", silent))  # read after the talker: every earlier datagram to it is in
            return sum(1 for a in got["talker"] if a > last) >= 6

        wait_until(dropped, "the silent peer dropped (six datagrams to the talker after its last)", poll=0.1)
        after = max(got["silent"])
        n_talker = sum(1 for a in got["talker"] if a > after)
        heard = len(got["silent"])
        wait_until(lambda: len(silent_is_a_peer()) > heard, "the silent peer receiving again once it talks", poll=0.1)
        rc = svc.stop()
    assert rc == 0
    print(f"\nsilent peer: {heard} datagrams, then none while the talker received {n_talker}; "
          f"{len(got['silent']) - heard} more once it talked again")
    assert n_talker >= 6


def test_peer_table_is_bounded_under_many_source_ports(tmp_path: Path) -> None:
    """3000 source ports with ``--max-peers 4``: only the 4 newest receive. The newest port's first datagram
    was sent after the service had taken every frame, so from that stamp on nothing may reach the 4 ports
    before them (the memory the table takes is measured in bench_peers.py)."""
    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    hb = plain.heartbeat_encode(6, 8, 0, 0, 4).pack(plain)
    n_ports, kept = 3000, 8
    with Svc(tmp_path, "--sysid", "1", "--max-peers", "4", "--peer-timeout", "3600") as svc:
        keep: list[socket.socket] = []
        for i in range(n_ports):
            s = udp_socket(1 << 16)
            s.sendto(hb, svc.addr)
            if i >= n_ports - kept:
                keep.append(s)
            else:
                s.close()
            if i % 16 == 15:
                wait_for_room(svc.port)  # every frame is read: none is lost to a full socket
        svc.settle()
        got: list[list[float]] = [[] for _ in keep]

        def newest_hear_twice() -> bool:
            for g, s in zip(got, keep):
                g += [a for a, _ in recv_stamped(s)]
            return all(len(g) >= 2 for g in got[-4:])

        wait_until(newest_hear_twice, "the 4 newest peers receiving")
        for g, s in zip(got, keep):
            g += [a for a, _ in recv_stamped(s)]
        rc = svc.stop()
        summary = svc.summary()
    first = min(got[-1])  # the newest peer's first datagram: sent when the table was final
    late = [sum(1 for a in g if a >= first) for g in got[:-4]]
    print(f"\n{n_ports} source ports; datagrams received by the last {kept}: {[len(g) for g in got]}; "
          f"by the 4 older ones after the table was final: {late}")
    assert rc == 0
    assert int(summary.get("kernel_dropped", 0)) == 0 and int(summary.get("messages received", 0)) == n_ports
    assert all(len(g) >= 2 for g in got[-4:]) and late == [0] * (kept - 4), "only the 4 newest peers receive"


# -- keys ----------------------------------------------------------------------------------------------
def test_key_files(tmp_path: Path) -> None:
    from mavins.link.signing import load_key

    # mavins key FILE --passphrase P: mode 600, 64 hex digits, SHA-256(P) (MAVProxy's 'signing setup P')
    key_path, key = make_key(tmp_path, "MAVProxy passphrase")
    assert stat.S_IMODE(key_path.stat().st_mode) == 0o600
    assert key_path.read_text() == hashlib.sha256(b"MAVProxy passphrase").hexdigest() + "\n"
    assert load_key(key_path) == key
    # no overwrite without --force; --force leaves mode 600 even where the old file was 644
    res = subprocess.run([*MAVINS, "key", str(key_path), "--passphrase", "other"], env=ENV, capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 2 and "exists" in res.stderr
    key_path.chmod(0o644)
    res = subprocess.run([*MAVINS, "key", str(key_path), "--passphrase", "other", "--force"], env=ENV,
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and stat.S_IMODE(key_path.stat().st_mode) == 0o600
    # a key file others can read is refused, clearly, with exit code 2
    for mode in (0o644, 0o640, 0o604):
        key_path.chmod(mode)
        res = subprocess.run([*MAVINS, "run", "--master", "udpin:127.0.0.1:0", "--signing-key", str(key_path),
                              "--duration", "1"], env=ENV, capture_output=True, text=True, timeout=60)
        assert res.returncode == 2, (oct(mode), res.stderr)
        assert "accessible by others" in res.stderr and "chmod 600" in res.stderr and "Traceback" not in res.stderr
    print(f"\nrefused with: {res.stderr.strip().splitlines()[-1]}")


def test_key_from_a_non_ascii_passphrase_is_a_clear_error(tmp_path: Path) -> None:
    """MAVProxy takes SHA-256 of the ASCII passphrase; a non-ASCII one must be a one-line error (exit 2)."""
    res = subprocess.run([*MAVINS, "key", str(tmp_path / "k"), "--passphrase", "pässword"], env=ENV,
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert not (tmp_path / "k").exists()


# -- no commands from the link ---------------------------------------------------------------------
def test_commands_and_setup_signing_are_ignored(tmp_path: Path) -> None:
    """Signed with the key or not, COMMAND_LONG / COMMAND_INT get no COMMAND_ACK and change nothing, and
    SETUP_SIGNING cannot change the key: afterwards the new key is refused and the old one still works."""
    key_path, key = make_key(tmp_path, "commands")
    new_key = hashlib.sha256(b"the attacker's key").digest()
    run = generate(scenario("rest", [{"kind": "static", "duration": 4.0}], 100.0, roll=3.0, pitch=-2.0, yaw=30.0),
                   grade="ideal")
    gcs = ClockSigner(key, sysid=255, compid=190)
    plain = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    commands = [gcs.command_long_encode(VEH_SYS, 191, cmd, 0, 0, 0, 0, 0, 0, 0, 0) for cmd in (
        mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
        mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_DO_SET_HOME, mavlink.MAV_CMD_COMPONENT_ARM_DISARM)]
    commands.append(gcs.command_int_encode(VEH_SYS, 191, 0, mavlink.MAV_CMD_DO_REPOSITION, 0, 0, 0, 0, 0, 0,
                                           473977420, 85455940, 500.0))
    setup = gcs.setup_signing_encode(VEH_SYS, 191, list(new_key), now_units())
    new_signer = ClockSigner(new_key, sysid=255, compid=190)
    g_sock = udp_socket()
    nav = tmp_path / "nav.csv"
    with Svc(tmp_path, *nav_args(1.0, "--signing-key", str(key_path), "-o", str(nav))) as svc:
        items = encode(run, ClockSigner(key))  # signed now: a new stream must be less than a minute old
        half = len(items) // 2
        send_paced(g_sock, svc.addr, items[:half], speed=4.0)
        for m in commands:
            g_sock.sendto(gcs.frame(m), svc.addr)
            g_sock.sendto(m.pack(plain), svc.addr)  # the same, unsigned
        g_sock.sendto(gcs.frame(setup), svc.addr)
        svc.settle()  # SETUP_SIGNING taken (and ignored) before anything signed with its key arrives
        for _ in range(5):
            g_sock.sendto(new_signer.frame(plain.heartbeat_encode(6, 8, 0, 0, 4)), svc.addr)
        send_paced(g_sock, svc.addr, items[half:], speed=4.0)
        svc.settle()
        rc = svc.stop()
    assert rc == 0
    got, bad = verify(key, drain(g_sock))
    names = {m.get_type() for m in got}
    print(f"\nreceived {len(got)} frames signed with the original key ({bad} not): {sorted(names)}; "
          f"summary {svc.summary()}")
    assert "COMMAND_ACK" not in names and bad == 0
    assert svc.count("rejected_unsigned") == len(commands)
    assert svc.count("rejected_bad_signature") == 5, "frames signed with the key SETUP_SIGNING carried are refused"
    assert svc.count("imu_accepted") == sum(it.name == "HIGHRES_IMU" for it in items), "the old key still works"
    assert svc.summary().get("final state") == "NAVIGATING"
    assert np.abs(wrap_deg(read_nav(nav)[-1, 7:10] - [3.0, -2.0, 30.0])).max() < 0.01


def _mavproxy() -> str | None:
    import shutil
    import sys

    return shutil.which("mavproxy.py", path=os.pathsep.join([str(Path(sys.executable).parent),
                                                              os.environ.get("PATH", "")]))


@pytest.mark.skipif(_mavproxy() is None, reason="MAVProxy is not installed (no mavproxy.py)")
def test_through_mavproxy_with_signing_key_passphrase(tmp_path: Path) -> None:
    """autopilot (signed) -> MAVProxy 'signing key P' -> mavins --signing-key (mavins key --passphrase P): every
    sample taken, and the solution goes back through MAVProxy to the autopilot side, signed with the same key."""
    import signal

    from test_hardening import free_udp_port

    passphrase = "interop-passphrase"  # MAVProxy takes the first word of the command as the passphrase
    key_path, key = make_key(tmp_path, passphrase)
    run = generate(scenario("rest", [{"kind": "static", "duration": 4.0}], 100.0, roll=3.0, pitch=-2.0, yaw=30.0),
                   grade="ideal")
    a = free_udp_port()
    nav = tmp_path / "nav.csv"
    with Svc(tmp_path, *nav_args(1.0, "--signing-key", str(key_path), "-o", str(nav))) as svc:
        with open(tmp_path / "mavproxy.log", "w") as log:
            mp = subprocess.Popen(
                [_mavproxy(), f"--master=udpin:127.0.0.1:{a}", f"--out=udpout:127.0.0.1:{svc.port}", "--daemon",
                 "--non-interactive", "--default-modules=signing", "--streamrate=-1", "--nowait",
                 f"--cmd=signing key {passphrase}"],
                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=ENV, cwd=tmp_path,
                start_new_session=True)
        try:
            wait_until(lambda: "Setup signing key" in (tmp_path / "mavproxy.log").read_text(), "MAVProxy keyed")
            wait_until(lambda: udp_stats(a) is not None, "MAVProxy listening")  # it opens its master socket late
            items = encode(run, ClockSigner(key))  # signed now: a new stream must be less than a minute old
            sock = udp_socket()
            send_paced(sock, ("127.0.0.1", a), items, speed=2.0)
            wait_until_read(a)
            svc.settle()
            back: list[bytes] = []
            wait_until(lambda: back.extend(drain(sock)) or any(verify(key, back)[0]), "the solution back through MAVProxy")
            rc = svc.stop()
            back += drain(sock)
        finally:
            if mp.poll() is None:
                os.killpg(mp.pid, signal.SIGTERM)
                try:
                    mp.wait(10)
                except subprocess.TimeoutExpired:
                    os.killpg(mp.pid, signal.SIGKILL)
    good, bad = verify(key, back)
    print(f"\nthrough MAVProxy: summary {svc.summary()}; the autopilot side received {len(back)} datagrams, "
          f"{len(good)} verified with the key, {bad} not")
    assert rc == 0
    assert svc.count("imu_accepted") == sum(it.name == "HIGHRES_IMU" for it in items)
    assert not any(k.startswith("rejected_") for k in svc.summary())
    assert {"ATTITUDE", "ODOMETRY", "HEARTBEAT"} <= {m.get_type() for m in good} and bad == 0
    assert np.abs(wrap_deg(read_nav(nav)[-1, 7:10] - [3.0, -2.0, 30.0])).max() < 0.01


def test_listens_on_loopback_by_default() -> None:
    from mavins.cli import build_parser
    from mavins.service import ServiceConfig

    assert build_parser().parse_args(["run"]).master == "udpin:127.0.0.1:14551"
    assert ServiceConfig().master == "udpin:127.0.0.1:14551"


# -- after 90 s: a fresh peer, timestamps on the clock, never reused --------------------------------
def test_after_90_s_a_fresh_pymavlink_peer_accepts_the_service(long_service: LongRun, tmp_path: Path) -> None:
    lr = long_service
    wait = LONG_RUN_S - (time.monotonic() - lr.t_start)
    if wait > 0:
        time.sleep(wait)
    assert lr.svc.alive(), lr.svc.log()[-2000:]
    # a plain pymavlink peer, just started, holding the key: its clock is its only state (as MAVProxy's)
    peer = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    peer.signing.secret_key, peer.signing.sign_outgoing = lr.key, True
    peer.signing.timestamp = now_units()
    peer.robust_parsing = True
    sock = udp_socket()
    hello = time.time()
    sock.sendto(peer.heartbeat_encode(6, 8, 0, 0, 4).pack(peer), lr.svc.addr)  # signed: earns output
    received: list[tuple[float, bytes]] = []  # (kernel arrival, datagram)

    def fifty() -> bool:
        received.extend(recv_stamped(sock))
        return len(received) >= 50

    wait_until(fifty, "50 datagrams to a fresh peer")
    good = bad = 0
    after_hello, before_arrival = [], []
    frames = [(arrival, f) for arrival, d in received for f in frames_of(d)]
    for arrival, f in frames:
        for m in peer.parse_buffer(f) or []:  # check_signature: a new stream must be within 1 min of our clock
            if m.get_type() == "BAD_DATA":
                bad += 1
            else:
                good += 1
        ts = EPOCH_2015 + timestamp_of(f) / UNITS
        after_hello.append(ts - hello)
        before_arrival.append(arrival - ts)
    ran = time.monotonic() - lr.t_start
    print(f"\nafter {ran:.0f} s of service ({lr.sent} signed frames in): fresh peer accepted {good} frames, refused "
          f"{bad}; signing timestamp - our frame's time {min(after_hello):+.4f} s .., arrival - signing timestamp "
          f"{min(before_arrival):+.4f} s ..")
    assert good == len(frames) and bad == 0
    # on the clock: every frame was signed after our frame (it made us a peer) and before it arrived
    # (10 ms allow for the 10 us steps a timestamp may run ahead within a burst of frames)
    assert min(after_hello) > -0.01 and min(before_arrival) > -0.01
    # timestamps are reserved ahead in KEY.timestamp (mode 600): after a restart none is used again
    last_used = max(timestamp_of(f) for _, f in frames)
    lr.stop.set()
    lr.thread.join(5.0)  # type: ignore[union-attr]
    rc = lr.svc.stop()
    assert rc == 0, lr.svc.log()[-2000:]
    state = lr.key_path.with_name(lr.key_path.name + ".timestamp")
    reserved = int(state.read_text())
    assert stat.S_IMODE(state.stat().st_mode) == 0o600
    assert last_used < reserved <= now_units() + 31 * UNITS
    with Svc(lr.tmp, "--sysid", "1", "--signing-key", str(lr.key_path), name="restarted") as again:
        sock2 = udp_socket()
        sock2.sendto(ClockSigner(lr.key, sysid=255, compid=190).frame(peer.heartbeat_encode(6, 8, 0, 0, 4)),
                     again.addr)
        # the frames captured 90 s ago, replayed to the restarted service: too old for a new stream
        attacker = udp_socket()
        for d in lr.captured:
            attacker.sendto(d, again.addr)
        first: list[bytes] = []
        wait_until(lambda: first.extend(drain(sock2)) or first, "output to the signed peer of the restarted service")
        again.settle()
        rc = again.stop()
    assert rc == 0
    assert first and min(timestamp_of(f) for d in first for f in frames_of(d)) > reserved, \
        "no timestamp of the last run is reused"
    assert again.count("rejected_stale_new_stream") == len(lr.captured)
    assert not drain(attacker)

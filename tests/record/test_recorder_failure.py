"""A recorder that fails mid-run is switched off; every event is still logged and sent.

Fault injection on the real Rerun recorder: its ``on_event`` raises the error a
full disk gives. The alignment-end event that triggers it must still reach
the log and go out as STATUSTEXT, exactly once, and navigation must go on
publishing.
"""

from __future__ import annotations

import logging
import socket
import threading
from pathlib import Path

import pytest

from mavins.live.engine import EngineConfig
from mavins.link.ingest import IngestConfig
from mavins.link.mavlink import mavlink
from mavins.record.recorder import Recorder
from mavins.service import Service, ServiceConfig
from support import free_udp_port


class FullDiskRecorder(Recorder):
    def on_event(self, t: float | None, level: str, text: str) -> None:
        if text.startswith("NAVIGATING"):
            raise OSError(28, "No space left on device")
        super().on_event(t, level, text)


def test_events_are_logged_and_sent_once_when_the_recorder_fails(tmp_path: Path,
                                                                 caplog: pytest.LogCaptureFixture) -> None:
    port_in = free_udp_port()
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("127.0.0.1", 0))
    client.settimeout(0.2)
    svc = Service(EngineConfig(lat=47.0, lon=8.0, alt=400.0, heading=10.0, align=0.5, rate=10.0),
                  IngestConfig(), ServiceConfig(master=f"udpin:127.0.0.1:{port_in}",
                                                outs=[f"udpout:127.0.0.1:{client.getsockname()[1]}"]))
    svc.attach_recorder(FullDiskRecorder(tmp_path / "r.rrd", app="mavins-test", live=False))
    stop = threading.Event()
    result: list = []
    runner = threading.Thread(target=lambda: result.append(svc.run(stop)), daemon=True)
    caplog.set_level(logging.INFO, logger="mavins")
    runner.start()
    mav = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for i in range(400):  # 2 s at 200 Hz: alignment over 0.5 s, then navigation
            m = mavlink.MAVLink_highres_imu_message(1_000_000 + 5000 * i, 0.0, 0.0, -9.806, 0.0, 0.0, 0.0,
                                                    0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0b111111, 0)
            sender.sendto(m.pack(mav), ("127.0.0.1", port_in))
    texts: list[str] = []
    attitude = 0
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    deadline_reads = 0
    while deadline_reads < 25:  # stop after 5 s without anything new
        try:
            data = client.recv(65535)
        except socket.timeout:
            deadline_reads += 1
            continue
        for m in parser.parse_buffer(data) or []:
            if m.get_type() == "STATUSTEXT":
                texts.append(m.text)
            elif m.get_type() == "ATTITUDE":
                attitude += 1
    stop.set()
    runner.join(30)
    client.close()
    summary = result[0]
    nav_texts = [t for t in texts if t.startswith("mavins: NAVIGATING")]
    assert len(nav_texts) == 1, texts
    logged = [r.getMessage() for r in caplog.records]
    assert sum(1 for x in logged if x.startswith("NAVIGATING")) == 1, logged
    # the reason the recorder gave, not only that it failed
    assert "recording failed and is switched off (navigation goes on): [Errno 28] No space left on device" in logged, \
        logged
    assert summary.counters["recording_failed"] == 1
    # 2 s of sensor time, navigating from 0.5 s at 10 sets per second: the sets kept coming after the failure
    assert attitude >= 14, attitude
    assert summary.state == "NAVIGATING"

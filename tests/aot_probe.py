"""Run what ``mavins demo`` computes, without sockets, and print fingerprints of it (JSON).

The simulator generates a 12 s flight; its MAVLink messages go through the service's pipeline
and every solution is encoded as the service publishes it. Printed: SHA-256 of the simulated
increments and truth, SHA-256 of the published bytes, the number of solutions, and whether the
kernels built ahead of time were loaded (tests/core/test_aot.py runs this with and without them).
"""

from __future__ import annotations

import hashlib
import json

from mavins.core import aot
from mavins.demo import _engine_config
from mavins.link.ingest import IngestConfig
from mavins.link.mavlink import mavlink
from mavins.link.publish import PublishConfig, encode
from mavins.live.pipeline import Pipeline
from sim.generate import generate
from sim.scenarios import load
from sim.stream import StreamOptions, frames


def main() -> None:
    run = generate(load("flight"), duration=12.0, seed=3, grade="industrial", usec_grid=True)
    simulated = hashlib.sha256()
    for a in (run.t, run.dtheta, run.dv, run.exact.truth):
        simulated.update(a.tobytes())
    init = run.init()
    pipe = Pipeline(_engine_config(init.lat, init.lon, init.h, "vehicle", "industrial", ("gnss", "baro")),
                    IngestConfig(), own_component=-1)
    sender, publisher = mavlink.MAVLink(None, srcSystem=1, srcComponent=1), mavlink.MAVLink(None, srcSystem=1)
    published, solutions = hashlib.sha256(), 0
    for _, msgs in frames(run, sender, StreamOptions()):
        for m in msgs:
            m.pack(sender)
            out = pipe.handle(m)
            if out is not None:
                solutions += 1
                for p in encode(publisher, out, PublishConfig(), 0):
                    published.update(p.pack(publisher))
    print(json.dumps({"simulated": simulated.hexdigest(), "published": published.hexdigest(), "solutions": solutions,
                      "built": {p: aot.has_built(p) for p in aot.PACKAGES}}))


if __name__ == "__main__":
    main()

#!/usr/bin/env bash
# MAVProxy as a router between an autopilot and mavins (docs/service.md, "Through MAVProxy").
#
#   autopilot  --UDP-->  MAVProxy                    --UDP-->  mavins run
#   (simulator)          --master udpin:127.0.0.1:A            --master udpin:127.0.0.1:B
#       ^                --out    udpout:127.0.0.1:B               |
#       +--------- the solution, routed back by MAVProxy ----------+
#
# The "autopilot" is the bundled simulator (sim.stream.frames: HEARTBEAT, HIGHRES_IMU,
# SIM_STATE, ATTITUDE, GPS_RAW_INT ... paced in real time x SPEED) sending from one UDP
# socket and listening on the same socket, as an autopilot's telemetry port does.
# MAVProxy forwards the autopilot's stream to its --out link; mavins navigates on it and
# answers on that link; MAVProxy forwards what comes in on an --out link to its master,
# so the autopilot receives HEARTBEAT, ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED,
# GLOBAL_POSITION_INT and ODOMETRY from (its system id, component 191).
#
# It prints what arrived back at the autopilot and exits 0 only if the solution came
# through MAVProxy. Everything runs on 127.0.0.1 on free ports; all started processes are
# stopped on exit.
#
# Usage:  scripts/mavproxy_interop.sh            (needs mavproxy.py: pip install MAVProxy)
# Environment: SCENARIO (flight), DURATION (s of simulated time, 30), SPEED (x real time, 5),
#              GRADE (industrial), MAVPROXY (path to mavproxy.py), KEEP=1 keeps the work dir.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="$here/.venv/bin"
if [[ -x "$bin/python" ]]; then PY="$bin/python"; MAVINS="$bin/mavins"; else PY="$(command -v python3)"; MAVINS="$(command -v mavins)"; fi
MAVPROXY="${MAVPROXY:-$(PATH="$bin:$PATH" command -v mavproxy.py || true)}"
if [[ -z "$MAVPROXY" || ! -x "$MAVPROXY" ]]; then
    echo "mavproxy_interop: mavproxy.py not found${MAVPROXY:+ at $MAVPROXY} (pip install MAVProxy, or set MAVPROXY=/path/to/mavproxy.py)" >&2
    exit 3
fi
SCENARIO="${SCENARIO:-flight}"
DURATION="${DURATION:-30}"
SPEED="${SPEED:-5}"
GRADE="${GRADE:-industrial}"
export MAVLINK20=1 PYTHONUNBUFFERED=1

work="$(mktemp -d -t mavins-interop.XXXXXX)"
pids=()
cleanup() {
    local p
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
    for p in "${pids[@]}"; do
        for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
        kill -KILL "$p" 2>/dev/null || true
    done
    if [[ "${KEEP:-0}" == 1 ]]; then echo "mavproxy_interop: logs kept in $work" >&2; else rm -rf "$work"; fi
}
trap cleanup EXIT

free_port() { "$PY" -c 'import socket; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
A="$(free_port)"   # MAVProxy's master (the autopilot sends here)
B="$(free_port)"   # mavins' master (MAVProxy's --out)

# 1. the service: start position of the scenario, heading from the vehicle's ATTITUDE
read -r LAT LON ALT < <("$PY" -c '
import sys
from sim.scenarios import load
st = load(sys.argv[1]).doc["start"]
print(st["lat"], st["lon"], st.get("h", 0.0))' "$SCENARIO")
"$MAVINS" run --master "udpin:127.0.0.1:$B" --lat "$LAT" --lon "$LON" --alt "$ALT" \
    --heading vehicle --align 5 -o "$work/nav.csv" >"$work/mavins.log" 2>&1 &
pids+=($!)

# 2. MAVProxy as a plain router: no modules, no stream requests, no waiting for a heartbeat
( cd "$work" && exec "$MAVPROXY" --master="udpin:127.0.0.1:$A" --out="udpout:127.0.0.1:$B" \
    --daemon --non-interactive --nowait --default-modules= --streamrate=-1 \
    --state-basedir="$work" </dev/null >"$work/mavproxy.log" 2>&1 ) &
pids+=($!)

# both up: mavins says so once its kernels are loaded; MAVProxy once it holds port A
for _ in $(seq 1200); do grep -q "listening on" "$work/mavins.log" && break; sleep 0.1; done
grep -q "listening on" "$work/mavins.log" || { cat "$work/mavins.log" >&2; echo "mavproxy_interop: mavins did not start" >&2; exit 1; }
port_taken() { "$PY" -c 'import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
try:
    s.bind(("127.0.0.1", int(sys.argv[1])))
except OSError:
    sys.exit(0)
sys.exit(1)' "$1"; }
for _ in $(seq 300); do port_taken "$A" && break; kill -0 "${pids[1]}" 2>/dev/null || break; sleep 0.1; done
port_taken "$A" || { cat "$work/mavproxy.log" >&2; echo "mavproxy_interop: MAVProxy did not start" >&2; exit 1; }

# 3. the autopilot: stream the scenario to MAVProxy and listen for what comes back
echo "mavproxy_interop: autopilot -> MAVProxy udpin:127.0.0.1:$A -> mavins udpin:127.0.0.1:$B ($SCENARIO, ${DURATION}s, x$SPEED)"
status=0
("$PY" - "$SCENARIO" "$DURATION" "$SPEED" "$GRADE" "$A" <<'EOF'
import collections, socket, sys, time
from pymavlink.dialects.v20 import common as mavlink
from sim.generate import generate
from sim.scenarios import load
from sim.stream import StreamOptions, frames

scenario, duration, speed, grade, port = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4], int(sys.argv[5])
run = generate(load(scenario), duration=duration, grade=grade)
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", 0))
sock.setblocking(False)
mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_AUTOPILOT1)
parser = mavlink.MAVLink(None)
parser.robust_parsing = True
got = collections.Counter()
texts, first_odo, last_att = [], None, None

def drain():
    global first_odo, last_att
    while True:
        try:
            data, _ = sock.recvfrom(65535)
        except BlockingIOError:
            return
        for m in parser.parse_buffer(data) or []:
            if m.get_type() == "BAD_DATA" or m.get_srcComponent() != 191:
                continue  # MAVProxy's own traffic (component 230) is not what we look for
            got[m.get_type()] += 1
            if m.get_type() == "STATUSTEXT":
                texts.append(m.text)
            elif m.get_type() == "ODOMETRY" and first_odo is None:
                first_odo = m
            elif m.get_type() == "ATTITUDE":
                last_att = (m.get_srcSystem(), m)

t_wall0, t_sim0 = time.monotonic(), run.exact.t0
for t_s, msgs in frames(run, mav, StreamOptions(speed=speed)):
    delay = t_wall0 + (t_s - t_sim0) / speed - time.monotonic()
    if delay > 0:
        time.sleep(delay)
    for m in msgs:
        buf = m.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        sock.sendto(buf, ("127.0.0.1", port))
    drain()
t_end = time.monotonic() + 1.0
while time.monotonic() < t_end:
    time.sleep(0.05)
    drain()

print("received back through MAVProxy from component 191:", dict(sorted(got.items())))
for t in texts:
    print("  STATUSTEXT", t)
if first_odo is not None:
    print(f"  first ODOMETRY: time_usec {first_odo.time_usec} frame_id {first_odo.frame_id} "
          f"child_frame_id {first_odo.child_frame_id} q {[round(x, 5) for x in first_odo.q]}")
if last_att is not None:
    sysid, a = last_att
    print(f"  last ATTITUDE from system {sysid}: t {a.time_boot_ms} ms roll {a.roll:.4f} pitch {a.pitch:.4f} yaw {a.yaw:.4f} rad")
need = ("HEARTBEAT", "ATTITUDE", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "ODOMETRY")
missing = [n for n in need if not got[n]]
if missing:
    print("MAVPROXY INTEROP FAILED: nothing of", ", ".join(missing), "came back", file=sys.stderr)
    sys.exit(1)
print("MAVPROXY INTEROP OK")
EOF
) || status=$?
# stop the service, then show its summary (what it received through MAVProxy)
kill -TERM "${pids[0]}" 2>/dev/null || true
wait "${pids[0]}" 2>/dev/null || true
grep -E "^mavins run: (messages received|output sets|final state|imu_accepted)" "$work/mavins.log" || true
exit $status

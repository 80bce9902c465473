#!/usr/bin/env bash
# The main job: install tdmon in .venv, then run it on the embedded default (no server at all).
#  1. the model alone: the example well's loads, broomstick figures (out/broomstick-*.png);
#  2. the live daemon as on a rig: `tdmon run` on a Zenoh peer (tcp/127.0.0.1:7457), fed by
#     `tdmon publish` playing the bundled simulated trip out (replays/trip-out-tight-spot.mcap,
#     25 min of rig time) at 60 x real time over Zenoh; when the publisher is done the daemon
#     gets SIGINT, flushes and stops. Outputs: the MCAP flight recording, the Rerun .rrd, a
#     summary (JSON) and a post-well report in out/. Takes about a minute after installing.
set -euo pipefail
cd "$(dirname "$0")/.."

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e .
# compile the model kernels into numba's on-disk cache now (a minute or so), not in the
# first command
.venv/bin/tdmon model warmup

TDMON=.venv/bin/tdmon
CONFIG=config/daemon/replay-zenoh-demo.toml
REPLAY=replays/trip-out-tight-spot.mcap
PORT=7457      # the config's listen endpoint
SPEED=${SPEED:-60}

mkdir -p out
echo "== model: example well loads and broomsticks"
$TDMON model loads --well config/wells/aadnoy-example-7-1.toml --method soft-string
$TDMON model broomstick --well config/wells/aadnoy-example-7-1.toml \
    --mu 0.1,0.2,0.3 --png out/broomstick-example-7-1.png
$TDMON model broomstick --well config/wells/volve-f4.toml \
    --mu 0.15,0.25,0.35 --png out/broomstick-volve-f4.png

echo "== live daemon on a Zenoh peer, fed with $REPLAY at ${SPEED}x"
rm -rf out/demo-recording out/demo.rrd out/demo-report out/demo-summary.json
$TDMON run --config "$CONFIG" --log-level warning 2>out/demo-daemon.log &
daemon=$!
# whatever happens below, the daemon does not outlive the script
trap 'kill -INT "$daemon" 2>/dev/null || true' EXIT

for _ in $(seq 1 100); do            # wait up to 20 s for the daemon to listen
    if (exec 3<>"/dev/tcp/127.0.0.1/$PORT") 2>/dev/null; then break; fi
    kill -0 "$daemon" 2>/dev/null || { cat out/demo-daemon.log; exit 1; }
    sleep 0.2
done
timeout 600 $TDMON publish "$REPLAY" --config "$CONFIG" --speed "$SPEED"
sleep 2                              # the last messages reach the daemon
kill -INT "$daemon"
wait "$daemon"
trap - EXIT
tail -n 1 out/demo-daemon.log

recording=$(ls -t out/demo-recording/*.mcap | head -n 1)
.venv/bin/python - "$recording" out/demo-summary.json <<'EOF'
import json, sys
from tdmon.replay.driver import summarize_recording
summary = summarize_recording(sys.argv[1])
with open(sys.argv[2], "w") as f:
    json.dump(summary, f, indent=2)
print(json.dumps({k: summary[k] for k in ("messages_in", "windows", "alarms", "state_shares")}))
EOF
$TDMON report "$recording" --out out/demo-report

echo
echo "outputs:"
echo "  flight recording  $recording   (Foxglove, or: tdmon view $recording --rrd X.rrd)"
echo "  Rerun views       out/demo.rrd   (rerun out/demo.rrd)"
echo "  summary           out/demo-summary.json, daemon log out/demo-daemon.log"
echo "  report            out/demo-report/report.html"
echo "  model figures     out/broomstick-example-7-1.png, out/broomstick-volve-f4.png"

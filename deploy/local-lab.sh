#!/usr/bin/env bash
# The rendered lab on loopback with one process per part: `roomlight calibrate` measures the
# simulated lab (in one process, through captures) and writes the files; `roomlight sim --scene`
# serves the rendered room; the camera agent samples its charts; one node agent per luminaire
# draws its nodes into its projector's image. Ctrl-C stops them all.
# Usage: deploy/local-lab.sh [SCENE]   (default: the embedded lab; `small` for the test room)
set -euo pipefail
scene=${1:-default}
here=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
cargo build --release -p roomlight --manifest-path "$here/Cargo.toml"
bin="$here/target/release/roomlight"
camera_size=()
if [ "$scene" = small ]; then camera_size=(--camera 640x480); fi
pids=()
stop() {
    trap - INT TERM EXIT
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    echo "stopped; logs in $work"
}
trap stop INT TERM EXIT
cd "$work"
"$bin" calibrate --scene "$scene" "${camera_size[@]}" --out . > calibrate.log
"$bin" sim --scene "$scene" "${camera_size[@]}" --listen 127.0.0.1:50060 > sim.log 2>&1 &
pids+=($!)
until grep -q "listening on" sim.log; do sleep 0.1; done
cat > camera.toml <<TOML
room = "rendered"
token = "change-me"
listen = "127.0.0.1:50061"
hardware = "http://127.0.0.1:50060"
model = "model.json"
charts = "charts.json"
model_rounds = 20
mdns = false
TOML
"$bin" camera --config camera.toml > camera.log 2>&1 &
pids+=($!)
until grep -q "listening on" camera.log; do sleep 0.1; done
for frame in frame-*.json; do
    p=${frame#frame-}; p=${p%.json}
    cat > "$p.toml" <<TOML
room = "rendered"
token = "change-me"
camera = "http://127.0.0.1:50061"
hardware = "http://127.0.0.1:50060"
frame = "$frame"
projector = "$p"
TOML
    "$bin" node --config "$p.toml" > "$p.log" 2>&1 &
    pids+=($!)
done
echo "rendered $scene running in $work (Ctrl-C stops it); the camera agent's rounds: $work/camera.log"
tail -f camera.log

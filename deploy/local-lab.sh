#!/usr/bin/env bash
# The rendered lab on loopback with one process per part: `roomlight calibrate` measures the
# simulated lab (in one process, through captures) and writes the files; `roomlight sim --scene`
# serves the rendered room; the camera agent samples its charts; one node agent per luminaire
# draws its nodes into its projector's image. Ctrl-C stops them all.
# With --wire, nothing is calibrated beforehand but the survey (chart corners, target mask): the
# camera agent calibrates each projector through its node agent as it joins (DESIGN §4, §6).
# Usage: deploy/local-lab.sh [--wire] [SCENE]   (default: the embedded lab; `small` for the test room)
set -euo pipefail
wire=false
if [ "${1:-}" = --wire ]; then wire=true; shift; fi
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
if $wire; then
    "$bin" calibrate --scene "$scene" "${camera_size[@]}" --survey-only --out . > calibrate.log
    source_lines="survey = \"survey.json\"
model_out = \"model.json\""
else
    "$bin" calibrate --scene "$scene" "${camera_size[@]}" --out . > calibrate.log
    source_lines="model = \"model.json\"
charts = \"charts.json\""
fi
"$bin" sim --scene "$scene" "${camera_size[@]}" --listen 127.0.0.1:50060 > sim.log 2>&1 &
pids+=($!)
until grep -q "listening on" sim.log; do sleep 0.1; done
cat > camera.toml <<TOML
room = "rendered"
token = "change-me"
listen = "127.0.0.1:50061"
hardware = { sim = "http://127.0.0.1:50060" }
$source_lines
model_rounds = 100
mdns = false
TOML
"$bin" camera --config camera.toml > camera.log 2>&1 &
pids+=($!)
until grep -q "listening on" camera.log; do sleep 0.1; done
start_node() { # projector, then the lines that say where its weights come from
    cat > "$1.toml" <<TOML
room = "rendered"
token = "change-me"
camera = "http://127.0.0.1:50061"
hardware = { sim = "http://127.0.0.1:50060" }
projector = "$1"
state_file = "$1.state.json"
$2
TOML
    "$bin" node --config "$1.toml" > "$1.log" 2>&1 &
    pids+=($!)
}
if $wire; then
    while read -r _ p kind; do
        start_node "$p" "rendered = true
kind = \"$kind\""
    done < <(grep '^luminaire ' calibrate.log)
else
    for frame in frame-*.json; do
        p=${frame#frame-}; p=${p%.json}
        start_node "$p" "frame = \"$frame\""
    done
fi
echo "rendered $scene running in $work (Ctrl-C stops it); the camera agent's rounds: $work/camera.log"
tail -f camera.log

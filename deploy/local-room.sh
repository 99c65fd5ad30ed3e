#!/usr/bin/env bash
# A simulated room on this PC, one process per part, with the installer's console: `roomlight
# sim` serves a rendered room, the camera agent calibrates it over the wire (only the survey is
# written beforehand) and serves the console, and one node agent per luminaire joins it.
# Prints the console's URL and token; Ctrl-C or SIGTERM stops every process.
#
# Usage: deploy/local-room.sh [SCENE]        SCENE: small (default) or default (the embedded lab)
# Environment:
#   ROOMLIGHT_BIN           the roomlight binary (default ./target/release/roomlight; built by
#                           `cargo build --release -p roomlight`, never by this script)
#   ROOMLIGHT_CONSOLE_PORT  the console's port on 127.0.0.1 (default 8080; 0: any free port)
#   ROOMLIGHT_TOKEN         the room's and console's token (default: a random one)
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
bin=${ROOMLIGHT_BIN:-$here/target/release/roomlight}
if [ ! -x "$bin" ]; then
    echo "error: no roomlight binary at $bin: build it first (cargo build --release -p roomlight) or set ROOMLIGHT_BIN" >&2
    exit 1
fi
# The work happens in a folder of its own: the binary's path must not depend on where we are.
bin=$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")
scene=${1:-small}
port=${ROOMLIGHT_CONSOLE_PORT:-8080}
token=${ROOMLIGHT_TOKEN:-$(head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \n')}
camera_size=()
if [ "$scene" = small ]; then camera_size=(--camera 640x480); fi
work=$(mktemp -d -t roomlight-room.XXXXXX)
pids=()
stop() {
    trap - INT TERM EXIT
    for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    echo "stopped; logs, survey and model in $work"
}
trap stop EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# Waits (at most $3 seconds) until file $1 has a line starting with $2, and prints that line;
# fails if the process $4 ended first.
wait_line() {
    local file=$1 prefix=$2 within=$3 pid=$4 i
    for ((i = 0; i < within * 10; i++)); do
        if grep -q "^$prefix" "$file" 2>/dev/null; then
            grep -m1 "^$prefix" "$file"
            return 0
        fi
        if ! kill -0 "$pid" 2>/dev/null; then
            echo "error: it stopped before printing \"$prefix\"; see $file:" >&2
            tail -n 20 "$file" >&2
            return 1
        fi
        sleep 0.1
    done
    echo "error: no \"$prefix\" in $file within ${within}s" >&2
    return 1
}

cd "$work"
"$bin" calibrate --scene "$scene" "${camera_size[@]}" --survey-only --out . > calibrate.log
"$bin" sim --scene "$scene" "${camera_size[@]}" --listen 127.0.0.1:0 > sim.log 2>&1 &
pids+=($!)
sim=$(wait_line sim.log "sim listening on" 120 "${pids[-1]}" | awk '{print $NF}')
cat > camera.toml <<EOF
room = "$scene"
token = "$token"
listen = "127.0.0.1:0"
hardware = { sim = "http://$sim" }
survey = "survey.json"
model_out = "model.json"
model_rounds = 100
mdns = false
console = "127.0.0.1:$port"
EOF
"$bin" camera --config camera.toml > camera.log 2>&1 &
pids+=($!)
camera=$(wait_line camera.log "camera listening on" 120 "${pids[-1]}" | awk '{print $NF}')
console=$(wait_line camera.log "console on" 30 "${pids[-1]}" | awk '{print $NF}')
# One node agent per luminaire, as `roomlight calibrate` listed them.
while read -r _ name kind; do
    cat > "$name.toml" <<EOF
room = "$scene"
token = "$token"
camera = "http://$camera"
hardware = { sim = "http://$sim" }
rendered = true
kind = "$kind"
projector = "$name"
state_file = "$name.state.json"
EOF
    "$bin" node --config "$name.toml" > "$name.log" 2>&1 &
    pids+=($!)
done < <(grep '^luminaire ' calibrate.log)
echo "room $scene running in $work ($((${#pids[@]} - 2)) projectors)"
echo "console: $console"
echo "token: $token"
echo "Ctrl-C stops it."
wait

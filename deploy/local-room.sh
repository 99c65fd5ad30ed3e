#!/usr/bin/env bash
# A simulated room on loopback with one process per part: `roomlight sim`, the camera agent and
# one node agent per projector. Ctrl-C stops them all. Usage: deploy/local-room.sh [PROJECTORS]
set -euo pipefail
projectors=${1:-3}
here=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
cargo build --release -p roomlight --manifest-path "$here/Cargo.toml"
bin="$here/target/release/roomlight"
pids=()
stop() {
    trap - INT TERM EXIT
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
    wait 2>/dev/null || true
    echo "stopped; logs and state files in $work"
}
trap stop INT TERM EXIT
cd "$work"
"$bin" sim --synthetic $((projectors * 10)) --projectors "$projectors" --listen 127.0.0.1:50050 --model-out room-model.json > sim.log 2>&1 &
pids+=($!)
# The node agents find the camera agent over mDNS, on loopback and a port of this room's own.
sed -e 's/^listen = .*/listen = "127.0.0.1:50051"/' -e 's/^mdns_port = .*/mdns_port = 53530/' \
    -e 's/^mdns_loopback_only = .*/mdns_loopback_only = true/' "$here/deploy/camera.toml" > camera.toml
until grep -q "listening on" sim.log; do sleep 0.1; done
"$bin" camera --config camera.toml &
pids+=($!)
sleep 0.5
for ((k = 0; k < projectors; k++)); do
    sed -e "s/^projector = .*/projector = \"p$k\"/" -e "s/^state_file = .*/state_file = \"p$k.state.json\"/" \
        -e 's/^camera = .*/camera = { mdns = "lab" }/' -e 's/^mdns_port = .*/mdns_port = 53530/' \
        -e 's/^mdns_loopback_only = .*/mdns_loopback_only = true/' "$here/deploy/node.toml" > "p$k.toml"
    "$bin" node --config "p$k.toml" > "p$k.log" 2>&1 &
    pids+=($!)
done
echo "room running in $work (Ctrl-C stops it)"
wait

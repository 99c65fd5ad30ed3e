#!/usr/bin/env bash
# A room across real network interfaces: five network namespaces (the simulator, the camera
# agent, three node agents), each with its own address on a veth pair to one bridge; the nodes
# find the camera agent by multicast mDNS across the bridge (no static address). Then, each step
# waiting on the camera agent's status lines with a deadline:
#   1. the room converges (objective within 1% of G*);
#   2. one node's link is cut: the camera agent drops it, the rounds go on without it;
#   3. the link is restored: the node rejoins (resuming from its state file), the room reconverges;
#   4. 50 ms delay and 5% loss on every node's link (tc netem): the room still converges; the
#      round rate with and without is printed (skipped, saying so, where the kernel has no netem);
#   5. the camera agent's link is cut: the nodes keep running (and their light); restored, they
#      reattach and the room reconverges.
# Traffic goes only to the namespaces' own addresses (10.77.0.0/24 on a bridge of this test's
# own); every wait is bounded. Needs root (ip netns); exits 0 with a clear skip otherwise.
# No process, namespace or interface is left behind, whatever happens.
# Usage: tests/netns/run.sh [PATH/TO/roomlight]   (default: target/debug/roomlight)
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
bin=$(realpath "${1:-$here/target/debug/roomlight}")
if [ "$(id -u)" != 0 ] || ! command -v ip >/dev/null 2>&1; then
    echo "netns test: SKIPPED (needs root and iproute2 for network namespaces)"
    exit 0
fi
[ -x "$bin" ] || { echo "netns test: no binary at $bin (cargo build -p roomlight)" >&2; exit 1; }

p=rl$$                          # this run's prefix: interface names stay under 15 characters
if ! ip netns add "$p-probe" 2>/dev/null; then
    echo "netns test: SKIPPED (this machine does not allow network namespaces)"
    exit 0
fi
ip netns del "$p-probe"
work=$(mktemp -d)
names=(sim cam n0 n1 n2)
pids=()
ok=0
# Every process in this run's namespaces: `$!` of `in_ns … &` is the subshell running `ip netns
# exec`, and killing it left the agents themselves running.
in_namespaces() { for n in "${names[@]}"; do ip netns pids "$p-$n" 2>/dev/null || true; done; }
cleanup() {
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
    in_namespaces | xargs -r kill 2>/dev/null || true
    for _ in $(seq 50); do [ -z "$(in_namespaces)" ] && break; sleep 0.1; done
    in_namespaces | xargs -r kill -9 2>/dev/null || true
    for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
    for n in "${names[@]}"; do ip netns del "$p-$n" 2>/dev/null || true; done
    ip link del "$p-br" 2>/dev/null || true
    if [ "$ok" = 1 ]; then
        rm -rf "$work"
    else
        echo "netns test: FAILED; logs kept in $work" >&2
        for log in "$work"/*.log; do echo "--- $log (last lines)" >&2; tail -n 15 "$log" >&2; done
    fi
    if ip netns list | grep -q "^$p-"; then echo "netns test: namespaces left behind" >&2; exit 1; fi
    if pgrep -f -- "$work/" >/dev/null; then echo "netns test: processes left behind" >&2; exit 1; fi
}
trap cleanup EXIT

ip link add "$p-br" type bridge
ip link set "$p-br" up
k=1
for n in "${names[@]}"; do
    ns="$p-$n"
    ip netns add "$ns"
    ip link add "$p-$n-h" type veth peer name "$p-$n-c"
    ip link set "$p-$n-c" netns "$ns"
    ip link set "$p-$n-h" master "$p-br" up
    ip -n "$ns" link set lo up
    ip -n "$ns" addr add "10.77.0.$k/24" dev "$p-$n-c"
    ip -n "$ns" link set "$p-$n-c" up
    ip -n "$ns" route add 224.0.0.0/4 dev "$p-$n-c"
    k=$((k + 1))
done
sim=10.77.0.1
cam=10.77.0.2

in_ns() { local n=$1; shift; ip netns exec "$p-$n" "$@"; }
started=$(date +%s.%N)
stamp() { awk -v a="$started" -v b="$(date +%s.%N)" -v m="$*" 'BEGIN { printf "[%6.1f s] %s\n", b - a, m }'; }

in_ns sim "$bin" sim --synthetic 30 --projectors 3 --listen "$sim:50050" --model-out "$work/model.json" > "$work/sim.log" 2>&1 &
pids+=($!)
# Waits until FILE has a line matching REGEX, at most SECONDS.
wait_line() {
    local file=$1 regex=$2 seconds=$3 what=$4
    local until=$(( $(date +%s) + seconds ))
    until grep -qE "$regex" "$file" 2>/dev/null; do
        if [ "$(date +%s)" -ge "$until" ]; then echo "netns test: waited ${seconds}s for $what" >&2; exit 1; fi
        sleep 0.1
    done
}
wait_line "$work/sim.log" "listening on" 30 "the simulator to listen"
gstar=$("$bin" optimum --model "$work/model.json" | sed -E 's/.*G\* ([^,]+),.*/\1/')

# TLS with client certificates, made by roomlight certs: the camera agent's name is the room's
# (what a node that finds it over mDNS verifies), with its address for tools that name it.
"$bin" certs init --out "$work/ca" > /dev/null
"$bin" certs issue --ca "$work/ca" --name netns --ip "$cam" --out "$work/camera" > /dev/null
cat > "$work/camera.toml" <<CONF
room = "netns"
token = "netns-t0k3n"
listen = "$cam:50051"
hardware = { sim = "http://$sim:50050" }
model = "$work/model.json"
heartbeat_ms = 200
deadline_ms = 1000
model_rounds = 5
mdns = true
tls = { cert = "$work/camera/netns.pem", key = "$work/camera/netns.key", ca = "$work/camera/ca.pem", require_client_cert = true }
CONF
in_ns cam env RUST_LOG=info "$bin" camera --config "$work/camera.toml" --status-lines > "$work/cam.log" 2> "$work/cam.err" &
pids+=($!)
wait_line "$work/cam.log" "camera listening on" 30 "the camera agent to listen"

node_pid=()
start_node() {
    local k=$1
    [ -f "$work/p$k/p$k.pem" ] || "$bin" certs issue --ca "$work/ca" --name "p$k" --out "$work/p$k" > /dev/null
    cat > "$work/p$k.toml" <<CONF
room = "netns"
token = "netns-t0k3n"
camera = { mdns = "netns" }
mdns_wait_s = 10
hardware = { sim = "http://$sim:50050" }
projector = "p$k"
state_file = "$work/p$k.state.json"
tls = { ca = "$work/p$k/ca.pem", cert = "$work/p$k/p$k.pem", key = "$work/p$k/p$k.key" }
CONF
    in_ns "n$k" env RUST_LOG=info "$bin" node --config "$work/p$k.toml" > "$work/p$k.log" 2>&1 &
    pids+=($!)
    node_pid[$k]=$!
}
for k in 0 1 2; do start_node "$k"; done

# Waits until a camera status line written after line FROM satisfies the awk CONDITION (fields:
# $2 round, $4 captures, $6 objective, $8 live; g = G*), at most SECONDS; prints that line.
wait_status() {
    local from=$1 seconds=$2 what=$3 condition=$4
    local until=$(( $(date +%s) + seconds ))
    while :; do
        local line
        line=$(tail -n "+$((from + 1))" "$work/cam.log" | awk -v g="$gstar" "\$1 == \"round\" && ($condition) { print; exit }")
        if [ -n "$line" ]; then echo "$line"; return; fi
        if [ "$(date +%s)" -ge "$until" ]; then
            echo "netns test: waited ${seconds}s for $what; last status: $(grep '^round' "$work/cam.log" | tail -n 1)" >&2
            exit 1
        fi
        sleep 0.1
    done
}
lines() { wc -l < "$work/cam.log"; }
converged='$8 == 3 && $6 <= g * 1.01'
# Captures per second over the status lines after line FROM.
rate() {
    local from=$1 seconds=$2 before after
    before=$(tail -n "+$((from + 1))" "$work/cam.log" | awk '$1 == "round" { c = $4 } END { print c + 0 }')
    sleep "$seconds"
    after=$(tail -n "+$((from + 1))" "$work/cam.log" | awk '$1 == "round" { c = $4 } END { print c + 0 }')
    awk -v a="$before" -v b="$after" -v s="$seconds" 'BEGIN { printf "%.1f", (b - a) / s }'
}

stamp "1. converge: G* = $gstar, three nodes found the camera agent over mDNS"
line=$(wait_status 0 90 "the room to converge with 3 nodes" "$converged")
stamp "   converged: $line"
clean_rate=$(rate "$(lines)" 3)
stamp "   $clean_rate captures/s on clean links"

# Admissions the camera agent logged ("joined", one per projector attached).
joined() { grep -c "joined" "$work/cam.err" || true; }

stamp "2. cut p2's link"
from=$(lines)
ip link set "$p-n2-h" down
line=$(wait_status "$from" 15 "the camera agent to drop p2" '$8 == 2')
stamp "   dropped: $line"
at=$(wait_status "$from" 5 "a status after the drop" '$8 == 2' | awk '{print $4}')
line=$(wait_status "$from" 30 "5 more captures without p2" "\$8 == 2 && \$4 >= $at + 5")
stamp "   rounds go on without it: $line"
kill -0 "${node_pid[2]}" || { echo "netns test: p2 exited while cut off" >&2; exit 1; }
stamp "   p2 kept running (and its light)"

stamp "3. restore p2's link"
from=$(lines)
before=$(joined)
ip link set "$p-n2-h" up
line=$(wait_status "$from" 60 "p2 to rejoin" '$8 == 3')
[ "$(joined)" -gt "$before" ] || { echo "netns test: p2 is live without being admitted again" >&2; exit 1; }
stamp "   rejoined (admitted again, with the state it kept): $line"
line=$(wait_status "$from" 90 "the room to reconverge" "$converged")
stamp "   reconverged: $line"

stamp "4. 50 ms delay and 5% loss on every node's link"
if tc qdisc add dev "$p-n0-h" root netem delay 50ms loss 5% 2>/dev/null; then
    tc qdisc add dev "$p-n1-h" root netem delay 50ms loss 5%
    tc qdisc add dev "$p-n2-h" root netem delay 50ms loss 5%
    from=$(lines)
    slow_rate=$(rate "$from" 5)
    stamp "   $slow_rate captures/s with delay and loss (clean: $clean_rate)"
    line=$(wait_status "$from" 120 "the room to converge under delay and loss" "$converged")
    stamp "   converged: $line"
    for n in n0 n1 n2; do tc qdisc del dev "$p-$n-h" root; done
else
    stamp "   SKIPPED: this kernel has no netem (sch_netem); delay and loss not tested"
fi

stamp "5. cut the camera agent's link"
from=$(lines)
at=$(grep '^round' "$work/cam.log" | tail -n 1 | awk '{print $4}')
before=$(joined)
ip link set "$p-cam-h" down
sleep 3   # fifteen heartbeats: the camera agent has dropped every node by now
for k in 0 1 2; do
    kill -0 "${node_pid[$k]}" || { echo "netns test: p$k exited while the camera agent was cut off" >&2; exit 1; }
done
stamp "   the nodes kept running (and their light) while it was cut off"
ip link set "$p-cam-h" up
line=$(wait_status "$from" 90 "the nodes to reattach and the room to reconverge" "$converged && \$4 >= $at + 5")
[ "$(joined)" -ge $((before + 3)) ] || { echo "netns test: not every node was admitted again ($(joined) admissions, $before before)" >&2; exit 1; }
stamp "   reattached (3 admissions) and reconverged: $line"

ok=1
stamp "netns test: PASSED"

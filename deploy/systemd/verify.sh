#!/usr/bin/env bash
# Checks the systemd units with `systemd-analyze verify`, as they would be installed, with
# ExecStart pointed at BINARY (verify refuses a unit whose program is missing). Any output
# fails, not only errors: verify merely warns of an unknown key or a value it cannot parse.
# Usage: deploy/systemd/verify.sh PATH/TO/roomlight
set -euo pipefail
bin=${1:?usage: verify.sh PATH/TO/roomlight}
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for unit in roomlight-camera.service roomlight-node@.service; do
    sed "s#/usr/bin/roomlight#$bin#" "$here/$unit" > "$work/$unit"
done
# A template is verified through an instance of it.
cp "$work/roomlight-node@.service" "$work/roomlight-node@p0.service"
if ! out=$(cd "$work" && systemd-analyze verify ./roomlight-camera.service ./roomlight-node@p0.service 2>&1); then
    echo "$out" >&2
    exit 1
fi
if [ -n "$out" ]; then
    echo "systemd-analyze verify warned:" >&2
    echo "$out" >&2
    exit 1
fi
echo "systemd units verified: roomlight-camera.service, roomlight-node@.service"

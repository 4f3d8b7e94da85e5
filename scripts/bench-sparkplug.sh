#!/usr/bin/env bash
# The Sparkplug B edge node under load (docs/BENCHMARKS.md): TAGS float tags
# changing once a second, published by server/sparkplug/examples/edge_bench.rs
# through Debian's mosquitto to a Python host (paho-mqtt, the Tahu payload
# classes on protobuf's upb backend) that decodes every message and measures
# change-to-receipt latency from each metric's own timestamp.
#
#   bash scripts/bench-sparkplug.sh [TAGS] [DEVICES] [SECONDS]
#
# Builds the example in release; the host runs in target/bench-venv (made
# here: protobuf 5 for upb, which mqtt-spb-wrapper's pin would refuse, so its
# packages are installed without their pins).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
tags="${1:-100000}"
devices="${2:-100}"
seconds="${3:-30}"
warmup=15
export PATH="$PATH:/usr/sbin"
command -v mosquitto >/dev/null || { echo "mosquitto not found (apt-get install mosquitto)" >&2; exit 1; }
target="${CARGO_TARGET_DIR:-$root/target}"
venv="$target/bench-venv"
if [ ! -x "$venv/bin/python" ]; then python3 -m venv "$venv"; fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps \
    mqtt-spb-wrapper==2.1.2 paho-mqtt==1.6.1 protobuf==5.29.5
(cd "$root" && cargo build -q --release -p gridscada-sparkplug --example edge_bench)

tmp="$(mktemp -d)"
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; rm -rf "$tmp"; }
trap cleanup EXIT
port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
printf 'listener %s 127.0.0.1\nallow_anonymous true\npersistence false\nmessage_size_limit 0\nmax_queued_messages 100000\n' "$port" >"$tmp/mosquitto.conf"
mosquitto -c "$tmp/mosquitto.conf" >"$tmp/mosquitto.log" 2>&1 &
pids+=($!)
mpid=$!
sleep 1
"$venv/bin/python" "$root/scripts/bench_sparkplug_host.py" --port "$port" --warmup "$warmup" --seconds "$seconds" &
host=$!
pids+=($host)
sleep 1
"$target/release/examples/edge_bench" "mqtt://127.0.0.1:$port" "$tags" "$devices" $((warmup + seconds + 2)) &
edge=$!
pids+=($edge)
# The broker's CPU over the measured window.
sleep "$warmup"
b0=$(awk '{ print $14 + $15 }' "/proc/$mpid/stat")
sleep "$seconds"
b1=$(awk '{ print $14 + $15 }' "/proc/$mpid/stat")
awk -v a="$b0" -v b="$b1" -v s="$seconds" -v rss="$(awk '/VmHWM/ { print int($2 / 1024) }' "/proc/$mpid/status")" \
    'BEGIN { printf "mosquitto: CPU %.1f %% of one core, peak RSS %s MiB\n", (b - a) / s, rss }'
wait "$host"
wait "$edge"

#!/usr/bin/env bash
# gridscada as a Sparkplug B edge node, against Debian's mosquitto and an
# independent Python host (paho-mqtt + the Eclipse Tahu payload through
# protobuf): births, every /api/tags value published, DCMD writes
# confirmed and audited, refused and malformed commands counted, a 20 s
# broker outage replayed as historical data, and the NDEATH will on kill -9.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), mosquitto, curl,
# python3 with paho-mqtt and protobuf (tests/requirements.txt).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
python="${PYTHON:-python3}"
outage="${SPARKPLUG_OUTAGE_S:-20}"

fail_setup() {
    echo "FAIL setup: $1"
    echo "0 passed, 1 failed"
    exit 1
}

[ -x "$bin" ] || fail_setup "no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ] || fail_setup "mosquitto not found (apt-get install mosquitto)"
command -v mosquitto >/dev/null || export PATH="$PATH:/usr/sbin"
command -v curl >/dev/null || fail_setup "curl not found"
"$python" -c 'import paho.mqtt.client, google.protobuf' 2>/dev/null \
    || fail_setup "$python has no paho-mqtt / protobuf (pip install -r tests/requirements.txt)"

tmp="$(mktemp -d)"
pid=""
cleanup() {
    if [ -n "$pid" ]; then kill -TERM "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; fi
    rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

free_port() { "$python" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
mport="$(free_port)"
hport="$(free_port)"
base="http://127.0.0.1:$hport"
# The broker of the test: loopback only, anonymous, nothing kept on disk
# (a restarted broker forgets everything, like a crashed one).
cat >"$tmp/mosquitto.conf" <<CONF
listener $mport 127.0.0.1
allow_anonymous true
persistence false
message_size_limit 0
CONF

# gridscada first: it retries the broker until the host has started it.
# The embedded demo, with its 11 kV ring: a safety tag's refusal of a DCMD is
# seen too.
"$bin" demo --http "127.0.0.1:$hport" --data "$tmp/data" \
    --mqtt "mqtt://127.0.0.1:$mport" >"$tmp/server.log" 2>&1 &
pid=$!
for _ in $(seq 1 150); do
    curl -fsS "$base/healthz" >/dev/null 2>&1 && [ -s "$tmp/data/credentials.txt" ] && break
    kill -0 "$pid" 2>/dev/null || { tail -20 "$tmp/server.log"; fail_setup "gridscada demo exited"; }
    sleep 0.2
done
curl -fsS "$base/healthz" >/dev/null 2>&1 || { tail -20 "$tmp/server.log"; fail_setup "gridscada demo never answered on $base"; }

"$python" "$here/sparkplug_host.py" --broker-port "$mport" --mosquitto-conf "$tmp/mosquitto.conf" \
    --base "$base" --creds "$tmp/data/credentials.txt" --outage "$outage" --edge-pid "$pid" | tee "$tmp/host.out"
host_rc=${PIPESTATUS[0]}
passed=$(awk '/ passed, / { print $1 }' "$tmp/host.out" | tail -1)
failed=$(awk '/ passed, / { print $3 }' "$tmp/host.out" | tail -1)
passed=${passed:-0}
failed=${failed:-1}
[ "$host_rc" = 0 ] || [ "$failed" != 0 ] || failed=1

# The host ended by killing gridscada (kill -9) to see its will; if it
# stopped before that, gridscada is stopped here.
kill -0 "$pid" 2>/dev/null && kill -TERM "$pid" 2>/dev/null
wait "$pid" 2>/dev/null
pid=""
if grep -q "panicked" "$tmp/server.log"; then
    echo "FAIL a panic in the server log"; grep -m3 "panicked" "$tmp/server.log"
    failed=$((failed + 1))
fi
[ "$failed" = 0 ] || tail -40 "$tmp/server.log"
echo "$passed passed, $failed failed"
[ "$failed" = 0 ]

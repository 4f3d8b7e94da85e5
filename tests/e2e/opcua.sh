#!/usr/bin/env bash
# The OPC UA server against a third-party client: Python asyncua (FreeOpcUa)
# connects to `gridscada demo --opcua PORT` and checks what it browses,
# reads, receives and writes against the HTTP API and the event log
# (tests/e2e/opcua_client.py says what each phase covers). Two demos: the
# embedded plant (browse, read every tag, subscriptions, refusals, security
# modes, /metrics) and tests/plants/three-panels (a confirmed setpoint write:
# no dispatch loop there rewrites setpoints).
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), curl, python3 with
# asyncua (tests/requirements.txt).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
passed=0
failed=0

fail_setup() {
    echo "FAIL setup: $1"
    echo "$passed passed, $((failed + 1)) failed"
    exit 1
}

[ -x "$bin" ] || fail_setup "no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
command -v curl >/dev/null || fail_setup "curl not found"
python3 -c 'import asyncua' 2>/dev/null || fail_setup "python3 has no asyncua (pip install -r tests/requirements.txt)"

tmp="$(mktemp -d)"
pid=""
cleanup() {
    if [ -n "$pid" ]; then kill -TERM "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; fi
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

# Runs one phase against a fresh demo started with "$@".
phase() {
    local name="$1"
    shift
    local http ua dir
    http="$(free_port)"
    ua="$(free_port)"
    dir="$tmp/$name"
    mkdir -p "$dir"
    "$bin" demo --http "127.0.0.1:$http" --data "$dir/data" --opcua "$ua" "$@" >"$dir/server.log" 2>&1 &
    pid=$!
    local up=""
    for _ in $(seq 1 150); do
        if [ -s "$dir/data/credentials.txt" ] && grep -q '"status":"ok"' <<<"$(curl -fsS "http://127.0.0.1:$http/healthz" 2>/dev/null)"; then
            up=1
            break
        fi
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.2
    done
    [ -n "$up" ] || { tail -20 "$dir/server.log"; fail_setup "gridscada demo ($name) never reported ok"; }
    grep -q "OPC UA:      opc.tcp://127.0.0.1:$ua/" "$dir/server.log" \
        || { tail -20 "$dir/server.log"; fail_setup "the demo ($name) did not announce its OPC UA endpoint"; }
    python3 "$here/opcua_client.py" "$name" "http://127.0.0.1:$http" "opc.tcp://127.0.0.1:$ua/" \
        "$dir/data/credentials.txt" "$dir" | tee "$dir/client.log"
    local line
    line="$(tail -1 "$dir/client.log")"
    passed=$((passed + $(echo "$line" | awk '{print $1+0}')))
    failed=$((failed + $(echo "$line" | awk '{print $3+0}')))
    case "$line" in *" passed, "*" failed") ;; *) failed=$((failed + 1)) ;; esac
    if ! kill -0 "$pid" 2>/dev/null; then
        echo "FAIL the demo ($name) died during the test"
        failed=$((failed + 1))
    fi
    if grep -q "panicked" "$dir/server.log"; then
        echo "FAIL the demo ($name) panicked:"
        grep -m3 -A3 "panicked" "$dir/server.log"
        failed=$((failed + 1))
    fi
    kill -TERM "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
    pid=""
}

phase plant
phase write --config "$root/tests/plants/three-panels"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

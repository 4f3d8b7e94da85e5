#!/usr/bin/env bash
# The OPC UA server against a third-party client: Python asyncua (FreeOpcUa)
# connects to `gridscada demo --opcua PORT` and checks what it browses,
# reads, receives and writes against the HTTP API and the event log
# (tests/e2e/opcua_client.py says what each phase covers). Two demos: the
# embedded demo plant with its 11 kV ring (browse, read every
# tag, subscriptions, refusals, a safety tag's refusal, security modes,
# /metrics) and tests/plants/three-panels (a confirmed setpoint write:
# no dispatch loop there rewrites setpoints). Then idle and half-Hello
# connections against the caps and the handshake timeout (opcua_slow.py),
# and docs/NORTHBOUND.md's client certificate trust procedure, step by
# step, on `serve` of a plant with [opcua] (opcua_connect.py connects).
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

# Starts a fresh demo named $1 with the rest of the arguments: sets http, ua,
# dir and pid.
start_demo() {
    local name="$1"
    shift
    http="$(free_port)"
    ua="$(free_port)"
    dir="$tmp/$name"
    mkdir -p "$dir"
    "$bin" demo --http "127.0.0.1:$http" --data "$dir/data" --opcua "$ua" "$@" >"$dir/server.log" 2>&1 &
    pid=$!
    wait_up "$name"
    grep -q "OPC UA:      opc.tcp://127.0.0.1:$ua/" "$dir/server.log" \
        || { tail -20 "$dir/server.log"; fail_setup "the demo ($name) did not announce its OPC UA endpoint"; }
}

# Waits (30 s at most) for the server $1 at $http to report ${2:-ok} (a
# plant without its devices is "degraded").
wait_up() {
    local up=""
    for _ in $(seq 1 150); do
        if grep -q "\"status\":\"${2:-ok}\"" <<<"$(curl -fsS "http://127.0.0.1:$http/healthz" 2>/dev/null)"; then
            up=1
            break
        fi
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.2
    done
    [ -n "$up" ] || { tail -20 "$dir/server.log"; fail_setup "gridscada ($1) never reported ok"; }
}

# Adds the "N passed, M failed" of the log $1 to the totals.
tally() {
    local line
    line="$(tail -1 "$1")"
    passed=$((passed + $(echo "$line" | awk '{print $1+0}')))
    failed=$((failed + $(echo "$line" | awk '{print $3+0}')))
    case "$line" in *" passed, "*" failed") ;; *) failed=$((failed + 1)) ;; esac
}

# Stops the server $1, failing if it died or panicked meanwhile.
stop_server() {
    if ! kill -0 "$pid" 2>/dev/null; then
        echo "FAIL the server ($1) died during the test"
        failed=$((failed + 1))
    fi
    if grep -q "panicked" "$dir/server.log"; then
        echo "FAIL the server ($1) panicked:"
        grep -m3 -A3 "panicked" "$dir/server.log"
        failed=$((failed + 1))
    fi
    kill -TERM "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
    pid=""
}

# Runs one phase of opcua_client.py against a fresh demo started with "$@".
phase() {
    local name="$1"
    start_demo "$@"
    for _ in $(seq 1 50); do [ -s "$dir/data/credentials.txt" ] && break; sleep 0.1; done
    python3 "$here/opcua_client.py" "$name" "http://127.0.0.1:$http" "opc.tcp://127.0.0.1:$ua/" \
        "$dir/data/credentials.txt" "$dir" | tee "$dir/client.log"
    tally "$dir/client.log"
    stop_server "$name"
}

ok() { passed=$((passed + 1)); echo "ok   $1"; }
bad() { failed=$((failed + 1)); echo "FAIL $1"; }

# Slow and idle connections (opcua_slow.py says what it checks).
slow_phase() {
    start_demo slow
    local op
    for _ in $(seq 1 50); do [ -s "$dir/data/credentials.txt" ] && break; sleep 0.1; done
    op="$(awk '$1 == "operator" {print $2, $3}' "$dir/data/credentials.txt")"
    # shellcheck disable=SC2086
    python3 "$here/opcua_slow.py" "opc.tcp://127.0.0.1:$ua/" "http://127.0.0.1:$http/metrics" $op \
        | tee "$dir/client.log"
    tally "$dir/client.log"
    stop_server slow
}

# docs/NORTHBOUND.md's client certificate trust procedure, step by step, on
# `serve` with [opcua] as a site configures it (no trust_all_clients).
trust_phase() {
    http="$(free_port)"
    ua="$(free_port)"
    dir="$tmp/trust"
    local plant="$dir/plant" pki="$dir/plant/data/opcua-pki" url pw="trust-phase-password-1"
    mkdir -p "$dir"
    cp -r "$root/tests/plants/three-panels" "$plant"
    printf '\n[opcua]\nlisten = "127.0.0.1:%s"\nhost = "127.0.0.1"\nsecurity = ["basic256sha256-sign-encrypt"]\n' \
        "$ua" >>"$plant/gridscada.toml"
    url="opc.tcp://127.0.0.1:$ua/"
    printf '%s\n' "$pw" | "$bin" user add engineer --role operator --config "$plant" >"$dir/user.log" 2>&1 \
        || { cat "$dir/user.log"; fail_setup "user add --config"; }
    "$bin" serve --config "$plant" --http "127.0.0.1:$http" >"$dir/server.log" 2>&1 &
    pid=$!
    wait_up trust '[a-z]*'
    connect() { python3 "$here/opcua_connect.py" "$url" "$dir" "$1" engineer "$pw" >"$dir/connect-$1.log" 2>&1; }

    # 1. An unknown client is refused; its certificate lands in rejected/.
    if connect client-a; then bad "an unknown client certificate is refused"; else ok "an unknown client certificate is refused"; fi
    local rejected
    rejected="$(find "$pki/rejected" -name '*.der' 2>/dev/null | head -1)"
    if [ -n "$rejected" ] && [ "$(find "$pki/rejected" -type f | wc -l)" -eq 1 ]; then
        ok "its certificate is in DATA/opcua-pki/rejected/ as the docs say ($(basename "$rejected"))"
    else
        bad "no certificate in $pki/rejected/: $(find "$pki" -type f | tr '\n' ' ')"
    fi
    # 2. opcua list shows it, with the thumbprint of the file's name.
    local thumb
    thumb="$(basename "$rejected" | sed -n 's/.*\[\([0-9a-fA-F]*\)\]\.der$/\1/p')"
    "$bin" opcua list --config "$plant" >"$dir/list.log" 2>&1
    if [ -n "$thumb" ] && sed -n '/^rejected/,$p' "$dir/list.log" | grep -qi "thumbprint: $thumb"; then
        ok "opcua list shows it under rejected, with its thumbprint"
    else
        bad "opcua list: $(cat "$dir/list.log")"
    fi
    if grep -q "valid: .* to " "$dir/list.log" && grep -q "subject: .*client-a" "$dir/list.log"; then
        ok "and its subject and validity"
    else
        bad "opcua list shows no subject or validity: $(cat "$dir/list.log")"
    fi
    # 3. The operator trusts it; the running server accepts the client.
    if "$bin" opcua trust "$rejected" --config "$plant" >"$dir/trust.log" 2>&1 \
        && grep -qi "thumbprint: $thumb" "$dir/trust.log" && grep -q "subject: .*client-a" "$dir/trust.log"; then
        ok "opcua trust prints the subject and thumbprint"
    else
        bad "opcua trust: $(cat "$dir/trust.log")"
    fi
    if [ ! -e "$rejected" ] && [ -f "$pki/trusted/$(basename "$rejected")" ]; then
        ok "the certificate moved from rejected/ to trusted/"
    else
        bad "after trust: $(find "$pki" -name '*.der' | tr '\n' ' ')"
    fi
    if connect client-a; then ok "the client connects, without a restart"; else bad "the trusted client is still refused: $(cat "$dir/connect-client-a.log")"; fi
    # 4. Trusted by hand with a copy, the rejected copy left behind.
    connect client-b
    local second
    second="$(find "$pki/rejected" -name '*.der' 2>/dev/null | head -1)"
    if [ -n "$second" ]; then
        cp "$second" "$pki/trusted/"
        if connect client-b; then
            ok "copied to trusted/ by hand (a copy left in rejected/), the client connects"
        else
            bad "a copy left in rejected/ still blocks: $(cat "$dir/connect-client-b.log")"
        fi
    else
        bad "client-b's certificate did not land in rejected/"
    fi
    # 5. A PEM certificate from the client's maker, trusted before its first try.
    python3 "$here/opcua_connect.py" --pem "$dir" client-c >"$dir/pem.log" 2>&1 || cat "$dir/pem.log"
    if "$bin" opcua trust "$dir/client-c.crt" --config "$plant" >"$dir/trust-c.log" 2>&1 && connect client-c; then
        ok "a PEM certificate trusted ahead connects at its first try"
    else
        bad "PEM: $(cat "$dir/trust-c.log" "$dir/connect-client-c.log")"
    fi
    if "$bin" opcua trust "$plant/gridscada.toml" --config "$plant" >"$dir/trust-bad.log" 2>&1; then
        bad "opcua trust took a file that is no certificate"
    elif grep -q "gridscada.toml: not an X.509 certificate" "$dir/trust-bad.log"; then
        ok "a file that is no certificate is refused, naming it"
    else
        bad "$(cat "$dir/trust-bad.log")"
    fi
    stop_server trust
}

# The embedded demo (its 11 kV ring too: a safety tag's refusal is seen
# through OPC UA).
phase plant
phase write --config "$root/tests/plants/three-panels"
slow_phase
trust_phase

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

#!/usr/bin/env bash
# Slow clients cannot make the HMI unreachable (issue 36, finding 1).
#
# `gridscada serve` runs under an open-file limit of 1024 (prlimit), as a
# shell would start it, and 1,100 TCP connections each send half a request
# and hold, from five loopback addresses (one of them the probe's) and
# re-opened as the server closes them. Throughout, /healthz must answer
# within 1 s; afterwards every held connection must have been closed within
# the header timeout, RSS must have stayed bounded, the log must not show
# "Too many open files", and /metrics must count the connections closed to
# make room.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), prlimit, curl,
# python3. Prints "N passed, M failed" last; exits non-zero on any failure.
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
ok() { echo "ok   $1"; passed=$((passed + 1)); }
bad() { echo "FAIL $1"; failed=$((failed + 1)); }

[ -x "$bin" ] || fail_setup "no gridscada binary at $bin"
command -v prlimit >/dev/null || fail_setup "prlimit not found (util-linux)"
command -v curl >/dev/null || fail_setup "curl not found"

tmp="$(mktemp -d)"
pid=""
cleanup() {
    if [ -n "$pid" ]; then kill -TERM "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; fi
    [ -n "${KEEP_TMP:-}" ] && echo "kept $tmp" || rm -rf "$tmp"
}
trap cleanup EXIT INT TERM

port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
base="http://127.0.0.1:$port"
# A plant of its own: the demo's configuration with the server's address,
# served by `serve` against the demo's simulated devices (`sim`).
mkdir -p "$tmp/plant"
cp -r "$root/tags/." "$tmp/plant/"
header_timeout=5
cat >>"$tmp/plant/gridscada.toml" <<TOML

[server.connections]
header_timeout_s = $header_timeout
TOML
sed -i "s|^http = .*|http = \"127.0.0.1:$port\"|" "$tmp/plant/gridscada.toml"
grep -q "^http = \"127.0.0.1:$port\"" "$tmp/plant/gridscada.toml" \
    || fail_setup "could not set [server] http in the copied gridscada.toml"
"$bin" check "$tmp/plant/gridscada.toml" >"$tmp/check.log" 2>&1 \
    || { cat "$tmp/check.log"; fail_setup "the copied plant does not pass check"; }
prlimit --nofile=1024:1024 "$bin" serve --config "$tmp/plant/gridscada.toml" --data "$tmp/data" \
    >"$tmp/server.log" 2>&1 &
pid=$!

up=""
for _ in $(seq 1 150); do
    if curl -sS -o /dev/null -m 2 "$base/healthz" 2>/dev/null; then up=1; break; fi
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.2
done
[ -n "$up" ] || { tail -20 "$tmp/server.log"; fail_setup "gridscada serve did not answer on $base"; }
limit_now="$(prlimit --pid "$pid" --nofile --output SOFT --noheadings | tr -d ' ')"
[ "$limit_now" = 1024 ] && ok "serve runs with an open-file limit of 1024" \
    || bad "serve's open-file limit is $limit_now, not 1024"

if python3 "$here/slow_clients.py" --port "$port" --pid "$pid" --slow 1100 --seconds 20 \
    --header-timeout "$header_timeout" >"$tmp/slow.out" 2>&1; then
    sed 's/^/  /' "$tmp/slow.out"
    ok "slow clients: every check of slow_clients.py passed"
else
    sed 's/^/  /' "$tmp/slow.out"
    bad "slow clients: slow_clients.py found failures (above)"
fi

if grep -qi "too many open files" "$tmp/server.log"; then
    bad "the server ran out of descriptors: $(grep -ci 'too many open files' "$tmp/server.log") log lines say 'Too many open files'"
else
    ok "the server never ran out of descriptors"
fi
metrics="$(curl -sS -m 5 "$base/metrics")"
room="$(sed -n 's/^gridscada_http_connections_closed_for_room_total \([0-9.e+]*\)$/\1/p' <<<"$metrics")"
max="$(sed -n 's/^gridscada_http_connections_max \([0-9.e+]*\)$/\1/p' <<<"$metrics")"
if [ -n "$room" ] && python3 -c "import sys; sys.exit(0 if float('$room') > 0 else 1)"; then
    ok "/metrics counts $room connections closed to make room (cap $max, fitted to 1024 descriptors)"
else
    bad "/metrics: gridscada_http_connections_closed_for_room_total is '${room:-missing}'"
fi
if [ -n "$max" ] && python3 -c "import sys; sys.exit(0 if float('$max') < 1024 else 1)"; then
    ok "the connection cap ($max) leaves descriptors for the rest of the server"
else
    bad "gridscada_http_connections_max is '${max:-missing}' under a 1024 open-file limit"
fi
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

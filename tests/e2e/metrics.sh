#!/usr/bin/env bash
# /metrics, /healthz and /readyz of a running `gridscada demo`, read by real
# clients: the exposition parsed by the Prometheus org's Python parsers (the
# strict OpenMetrics one and the classic text one), and a simulated device
# taken off line through the demo's fault injection to see /healthz and
# /metrics report it down, then up again.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), curl, python3 with
# prometheus_client (tests/requirements.txt).
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
ok() { echo "ok   $1"; passed=$((passed + 1)); }
bad() { echo "FAIL $1"; failed=$((failed + 1)); }

[ -x "$bin" ] || fail_setup "no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
command -v curl >/dev/null || fail_setup "curl not found"
python3 -c 'import prometheus_client' 2>/dev/null || fail_setup "python3 has no prometheus_client (pip install -r tests/requirements.txt)"

tmp="$(mktemp -d)"
pid=""
cleanup() {
    if [ -n "$pid" ]; then kill -TERM "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; fi
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM

port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
base="http://127.0.0.1:$port"
"$bin" demo --http "127.0.0.1:$port" --data "$tmp/data" >"$tmp/server.log" 2>&1 &
pid=$!

# Waits up to 30 s for /healthz to carry $1.
wait_health() {
    for _ in $(seq 1 150); do
        # Read the whole answer first: under pipefail, grep -q leaving at its
        # first match fails curl's write (exit 23) and so the pipeline.
        grep -q "$1" <<<"$(curl -sS "$base/healthz" 2>/dev/null)" && return 0
        kill -0 "$pid" 2>/dev/null || return 1
        sleep 0.2
    done
    return 1
}
wait_health '"status":"ok"' || { tail -20 "$tmp/server.log"; fail_setup "gridscada demo never reported ok on $base"; }

code="$(curl -sS -o "$tmp/ready" -w '%{http_code}' "$base/readyz")"
if [ "$code" = 200 ] && [ "$(cat "$tmp/ready")" = ready ]; then ok "/readyz answers 200 ready"; else bad "/readyz: $code $(cat "$tmp/ready")"; fi

# Some traffic for the latency histogram, and time for Modbus round trips.
for _ in 1 2 3; do curl -sS -o /dev/null "$base/healthz"; curl -sS -o /dev/null "$base/api/alarms"; done
sleep 1

ctype="$(curl -sS -o "$tmp/metrics.txt" -w '%{content_type}' "$base/metrics")"
case "$ctype" in
    application/openmetrics-text*) ok "/metrics is served as OpenMetrics ($ctype)" ;;
    *) bad "/metrics content type: $ctype" ;;
esac

# Both of the Prometheus org's parsers, and the figures they read.
if python3 - "$tmp/metrics.txt" <<'PY'
import sys
from prometheus_client.openmetrics.parser import text_string_to_metric_families as om_parse
from prometheus_client.parser import text_string_to_metric_families as text_parse

text = open(sys.argv[1]).read()
om = {f.name: f for f in om_parse(text)}
classic = {f.name: f for f in text_parse(text)}
problems = []
want = {
    "gridscada_build_info": "gauge",
    "gridscada_uptime_seconds": "gauge",
    "gridscada_http_requests": "counter",
    "gridscada_http_request_duration_seconds": "histogram",
    "gridscada_poll_requests": "counter",
    "gridscada_poll_round_trip_seconds": "histogram",
    "gridscada_device_connected": "gauge",
    "gridscada_historian_buffered": "gauge",
    "gridscada_alarms": "gauge",
    "process_cpu_seconds": "counter",
    "process_resident_memory_bytes": "gauge",
    "process_virtual_memory_bytes": "gauge",
    "process_open_fds": "gauge",
    "process_max_fds": "gauge",
    "process_start_time_seconds": "gauge",
}
for name, kind in want.items():
    f = om.get(name)
    if f is None:
        problems.append(f"OpenMetrics parser: no family {name}")
    elif f.type != kind:
        problems.append(f"{name}: type {f.type}, want {kind}")
    if name not in classic:
        problems.append(f"text parser: no family {name}")

def histograms(family):
    """Per label set (without le): buckets, count."""
    out = {}
    for s in family.samples:
        key = tuple(sorted((k, v) for k, v in s.labels.items() if k != "le"))
        h = out.setdefault(key, {"buckets": [], "count": None})
        if s.name.endswith("_bucket"):
            h["buckets"].append((float(s.labels["le"]), s.value))
        elif s.name.endswith("_count"):
            h["count"] = s.value
    return out

for name in ["gridscada_http_request_duration_seconds", "gridscada_poll_round_trip_seconds"]:
    f = om.get(name)
    if f is None:
        continue
    hs = histograms(f)
    if not hs:
        problems.append(f"{name}: no series")
    for key, h in hs.items():
        values = [v for _, v in sorted(h["buckets"])]
        if values != sorted(values):
            problems.append(f"{name}{dict(key)}: buckets not cumulative")
        if not values or values[-1] != h["count"]:
            problems.append(f"{name}{dict(key)}: +Inf bucket {values[-1:]} != count {h['count']}")

lat = histograms(om["gridscada_http_request_duration_seconds"])
healthz = lat.get((("method", "GET"), ("route", "/healthz"), ("status", "2xx")))
if not healthz or healthz["count"] < 3:
    problems.append(f"no latency series for GET /healthz 2xx: {sorted(lat)}")
if any(dict(k).get("route", "").startswith("/api/alarms?") for k in lat):
    problems.append("a raw URI as route label")
rt = histograms(om["gridscada_poll_round_trip_seconds"])
if sum(h["count"] for h in rt.values()) == 0:
    problems.append("no Modbus round trips counted")
devices = {dict(k)["device"] for k in rt}
print(f"{len(om)} families, {sum(len(f.samples) for f in om.values())} samples, "
      f"{len(devices)} devices with round trips")
for p in problems:
    print("  " + p)
sys.exit(1 if problems else 0)
PY
then ok "both Prometheus parsers read /metrics: families, types, histograms"; else bad "parsing /metrics"; fi

# A device down: the demo's fault injection (as its administrator).
creds="$tmp/data/credentials.txt"
read -r user password < <(awk '$1 == "administrator" { print $2, $3; exit }' "$creds" 2>/dev/null)
[ -n "${user:-}" ] || fail_setup "no administrator in $creds"
body="$(python3 -c 'import json,sys; print(json.dumps({"username": sys.argv[1], "password": sys.argv[2]}))' "$user" "$password")"
cookie="$(curl -sS -D - -o /dev/null -H 'Content-Type: application/json' -d "$body" "$base/api/session" \
    | tr -d '\r' | awk -F': ' 'tolower($1) == "set-cookie" { split($2, a, ";"); print a[1]; exit }')"
case "$cookie" in gridscada_session=?*) ;; *) fail_setup "login as $user failed" ;; esac
device="$(python3 -c 'import json,sys; print(json.load(sys.stdin)["devices"][0]["name"])' < <(curl -sS -b "$cookie" "$base/api/devices"))"
[ -n "$device" ] || fail_setup "no device in /api/devices"
sim() {
    curl -sS -o /dev/null -w '%{http_code}' -X POST -b "$cookie" \
        -H "Origin: $base" "$base/api/sim/devices/$device/$1"
}
code="$(sim offline)"
[ "$code" = 200 ] || [ "$code" = 204 ] || fail_setup "taking $device off line: HTTP $code"
if wait_health "\"not_good\":\[\"$device\"\]"; then
    code="$(curl -sS -o "$tmp/health.json" -w '%{http_code}' "$base/healthz")"
    if [ "$code" = 200 ] && grep -q '"status":"degraded"' "$tmp/health.json"; then
        ok "/healthz: 200 degraded, $device not good"
    else
        bad "/healthz with $device down: $code $(cat "$tmp/health.json")"
    fi
else
    bad "/healthz never named $device down: $(curl -sS "$base/healthz")"
fi
if grep -qx "gridscada_device_connected{device=\"$device\"} 0.0" <<<"$(curl -sS "$base/metrics")"; then
    ok "/metrics: $device not connected"
else
    bad "/metrics does not show $device down"
fi
code="$(curl -sS -o /dev/null -w '%{http_code}' "$base/readyz")"
[ "$code" = 200 ] && ok "/readyz stays 200 with a device down" || bad "/readyz with a device down: $code"
sim online >/dev/null
if wait_health '"status":"ok"'; then ok "/healthz back to ok once $device answers"; else bad "/healthz never recovered: $(curl -sS "$base/healthz")"; fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

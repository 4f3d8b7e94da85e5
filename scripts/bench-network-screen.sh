#!/usr/bin/env bash
# Benchmark: the network screen's colours reaching the browser after a
# switch changes, on a generated network of 10,000 switching devices and
# 20,000 sections (scripts/gen-network-plant.py) and, as the peer in the same
# run, on the demo's 11 kV ring (23 devices). Each is a `gridscada demo` of
# its own with Chromium on its network screen
# (tests/e2e/browser/bench/network-screen.mjs); prints one JSON line per
# plant and a table. Figures only. docs/BENCHMARKS.md keeps the latest.
#
# Usage: scripts/bench-network-screen.sh [--bin PATH] [--rounds N]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bin="$root/target/release/gridscada"
rounds=20
while [ $# -gt 0 ]; do
    case "$1" in
        --bin) bin="$2"; shift 2 ;;
        --rounds) rounds="$2"; shift 2 ;;
        *) echo "usage: $0 [--bin PATH] [--rounds N]" >&2; exit 2 ;;
    esac
done
[ -x "$bin" ] || { echo "bench-network-screen: no binary at $bin (cargo build --release -p gridscada)" >&2; exit 2; }
command -v chromium >/dev/null || [ -n "${CHROMIUM:-}" ] || { echo "bench-network-screen: no chromium (apt install chromium, or set CHROMIUM)" >&2; exit 2; }
browser="$root/tests/e2e/browser"
if [ ! -d "$browser/node_modules/playwright-core" ]; then
    (cd "$browser" && npm ci --no-audit --no-fund --loglevel=error)
fi

tmp="$(mktemp -d -t gridscada-bench-net-XXXXXX)"
pid=""
cleanup() { [ -n "$pid" ] && kill "$pid" 2>/dev/null; wait 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()'; }

# run LABEL "DEVICES" [demo args...]: one demo, its bench, its JSON line.
run() {
    local label=$1 devices=$2; shift 2
    local port data
    port="$(free_port)"
    data="$tmp/data-$label"
    "$bin" demo --http "127.0.0.1:$port" --data "$data" "$@" >"$tmp/server-$label.log" 2>&1 &
    pid=$!
    for _ in $(seq 1 600); do
        [ -s "$data/credentials.txt" ] && curl -fsS "http://127.0.0.1:$port/healthz" >/dev/null 2>&1 && break
        kill -0 "$pid" 2>/dev/null || { cat "$tmp/server-$label.log"; exit 1; }
        sleep 0.2
    done
    local rss_kib
    # shellcheck disable=SC2086
    (cd "$browser" && GRIDSCADA_URL="http://127.0.0.1:$port" GRIDSCADA_CREDENTIALS="$data/credentials.txt" \
        timeout 1200 node bench/network-screen.mjs "$label" "$rounds" $devices) >"$tmp/$label.json"
    rss_kib="$(awk '/VmRSS/ {print $2}' "/proc/$pid/status")"
    kill "$pid"; wait "$pid" 2>/dev/null || true; pid=""
    python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); d["server_rss_mb"]=round(int(sys.argv[2])/1024); print(json.dumps(d))' \
        "$tmp/$label.json" "$rss_kib" | tee "$tmp/$label.line"
}

python3 "$root/scripts/gen-network-plant.py" "$tmp/plant" >&2
# Open and close the first ring switch of ten rings: about 120 sections each.
run generated "$(seq -f 'r%g' 0 9 | sed 's/$/u0_s1/' | tr '\n' ' ')" --config "$tmp/plant"
run demo "f1 f2"

python3 - "$tmp/generated.line" "$tmp/demo.line" <<'EOF'
import json, sys
rows = [json.loads(open(p).read()) for p in sys.argv[1:]]
print()
print("| network | devices | sections | sections changed | screen load | p50 | p99 | max | server RSS |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for r in rows:
    print(f"| {r['label']} | {r['devices']:,} | {r['sections']:,} | {r.get('sections_changed', '?')} | "
          f"{r['screen_load_ms'] / 1000:.1f} s | {r['p50_ms']} ms | {r['p99_ms']} ms | {r['max_ms']} ms | {r['server_rss_mb']} MB |")
print(f"\n{len(rows[0]['open_ms']) * 2} operations each (open, then close again), from the status change to the last section's new colour on the screen.")
EOF

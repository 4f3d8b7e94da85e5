#!/usr/bin/env bash
# The performance figures of docs/BENCHMARKS.md that issue 19 asks for, in
# one run, one after the other (never side by side: each would load the
# other's cores), each with its own outer timeout:
#
#   1. store: historian ingest against a plain batched INSERT and a plain
#      COPY, and the roll-up trends of a day and a year (SQLite, PostgreSQL);
#   2. dispatch: solve times and the live look-ahead's branch and bound;
#   3. live push: 10,000 tags at 1 Hz to 100 WebSocket clients, against a
#      plain serialize-once broadcast;
#   4. replay: the sunny day at a 1 s step on the virtual clock, the main run
#      alone (--no-compare) and then the whole command (baseline beside it);
#      every shipped scenario's main run alone; and the sunny day's main run
#      beside the test command's browser tests (tests/e2e/browser.sh);
#   5. telecontrol: IEC 104 interrogation and spontaneous data against c104's
#      client, a DNP3 integrity poll and events at 2,000/s against dnp3py's
#      master, 50 IEC 104
#      stations on one server (scripts/bench-telecontrol.py);
#   6. memory: `serve` with 100,000 tags for MEMORY_SECONDS (default 600);
#   7. a million tags: `serve` with 1,000,000 tags on 500 devices (the
#      register walker serving them) for MILLION_SECONDS (default 1800; 0
#      leaves the stage out, e.g. for a quick pass).
#
#     bash scripts/bench-all.sh [LOG]      # default target/bench-all.log
#
# Needs the test venv (scripts/test-all.sh makes it) for pymodbus, and
# PostgreSQL from scripts/pg-test-cluster.sh (it starts a throwaway cluster
# where none runs). Prints the load average before each stage: the figures
# are only comparable on an otherwise idle machine.
set -uo pipefail
cd "$(dirname "$0")/.."
LOG=${1:-target/bench-all.log}
MEMORY_SECONDS=${MEMORY_SECONDS:-600}
MILLION_SECONDS=${MILLION_SECONDS:-1800}
PY=${PYTHON:-target/test-venv/bin/python}
mkdir -p "$(dirname "$LOG")"
: >"$LOG"
say() { echo "== $* (load: $(cut -d' ' -f1-3 /proc/loadavg), $(date -u +%H:%M:%S) UTC)" | tee -a "$LOG"; }
stage() { # NAME TIMEOUT_S COMMAND...
  local name=$1 limit=$2
  shift 2
  say "$name: $*"
  timeout --kill-after=30 "$limit" "$@" 2>&1 | tee -a "$LOG"
  local rc=${PIPESTATUS[0]}
  [ "$rc" = 0 ] || say "$name: exit $rc"
}

say "build"
cargo build --release -p gridscada --bin gridscada -p gridscada-store --example bench \
  -p gridscada-web --example ws_fanout -p gridscada-dnp3 --example dnp3_event_source \
  -p gridscada-modbus --example register_walker 2>&1 | tail -n 2 | tee -a "$LOG"
cargo bench -p gridscada-control --bench dispatch --no-run 2>&1 | tail -n 1 | tee -a "$LOG"
eval "$(bash scripts/pg-test-cluster.sh | grep '^export')"

stage store 1800 target/release/examples/bench
stage dispatch 900 cargo bench -p gridscada-control --bench dispatch
stage live-push 300 target/release/examples/ws_fanout 10000 100 15
stage replay-main 900 target/release/gridscada replay scenarios/sunny-day.toml --max \
  --no-compare --report target/bench-replay-main.json
stage replay-with-baseline 900 target/release/gridscada replay scenarios/sunny-day.toml --max \
  --report target/bench-replay.json
# Every shipped day's main run, alone.
replay_days() {
  local s
  for s in scenarios/*.toml; do
    target/release/gridscada replay "$s" --max --no-compare \
      --report "target/bench-replay-$(basename "$s" .toml).json" 2>&1 | tail -n 1
  done
}
export -f replay_days
stage replay-days 1800 bash -c replay_days
# The sunny day beside the browser tests (both cores taken by Chromium and
# the HMI's servers while they run).
replay_beside_browser() {
  GRIDSCADA_BIN=target/release/gridscada bash tests/e2e/browser.sh >target/bench-browser.log 2>&1 &
  local browser=$!
  sleep 45
  target/release/gridscada replay scenarios/sunny-day.toml --max --no-compare \
    --report target/bench-replay-beside-browser.json 2>&1 | tail -n 1
  echo "load while it ran: $(cut -d' ' -f1-3 /proc/loadavg)"
  wait "$browser" || echo "the browser tests beside it failed (target/bench-browser.log)"
}
export -f replay_beside_browser
stage replay-beside-browser 1800 bash -c replay_beside_browser
stage telecontrol 1200 env GRIDSCADA_BIN=target/release/gridscada "$PY" scripts/bench-telecontrol.py
stage memory $((MEMORY_SECONDS + 300)) env GRIDSCADA_BIN=target/release/gridscada \
  MALLOC_ARENA_MAX=2 "$PY" scripts/bench-memory.py --seconds "$MEMORY_SECONDS"
if [ "$MILLION_SECONDS" -gt 0 ]; then
  stage million-tags $((MILLION_SECONDS + 900)) env GRIDSCADA_BIN=target/release/gridscada \
    MALLOC_ARENA_MAX=2 "$PY" scripts/bench-memory.py --tags 1000000 --devices 500 \
    --seconds "$MILLION_SECONDS"
fi
say "done; log in $LOG"

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
#   5. telecontrol: IEC 104 interrogation and spontaneous data against c104's
#      client, a DNP3 integrity poll and events at 2,000/s against dnp3py's
#      master, 50 IEC 104
#      stations on one server (scripts/bench-telecontrol.py);
#   6. memory: `serve` with 100,000 tags for MEMORY_SECONDS (default 600).
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
  -p gridscada-web --example ws_fanout -p gridscada-dnp3 --example dnp3_event_source 2>&1 | tail -n 2 | tee -a "$LOG"
cargo bench -p gridscada-control --bench dispatch --no-run 2>&1 | tail -n 1 | tee -a "$LOG"
eval "$(bash scripts/pg-test-cluster.sh | grep '^export')"

stage store 1800 target/release/examples/bench
stage dispatch 900 cargo bench -p gridscada-control --bench dispatch
stage live-push 300 target/release/examples/ws_fanout 10000 100 15
stage replay-main 900 target/release/gridscada replay scenarios/sunny-day.toml --max \
  --no-compare --report target/bench-replay-main.json
stage replay-with-baseline 900 target/release/gridscada replay scenarios/sunny-day.toml --max \
  --report target/bench-replay.json
stage telecontrol 1200 env GRIDSCADA_BIN=target/release/gridscada "$PY" scripts/bench-telecontrol.py
stage memory $((MEMORY_SECONDS + 300)) env GRIDSCADA_BIN=target/release/gridscada \
  MALLOC_ARENA_MAX=2 "$PY" scripts/bench-memory.py --seconds "$MEMORY_SECONDS"
say "done; log in $LOG"

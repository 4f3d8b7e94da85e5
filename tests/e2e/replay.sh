#!/usr/bin/env bash
# Replays every scenario in scenarios/ through the whole stack (gridscada
# replay --max) and checks its expectations. Writes each report (JSON and
# HTML) to tests/e2e/artifacts/replay/. Prints "N passed, M failed" and exits
# non-zero when any scenario fails.
#   GRIDSCADA_BIN  the binary (default: target/release/gridscada, else target/debug/gridscada)
set -uo pipefail
cd "$(dirname "$0")/../.."
bin="${GRIDSCADA_BIN:-}"
if [ -z "$bin" ]; then
    if [ -x target/release/gridscada ]; then bin=target/release/gridscada; else bin=target/debug/gridscada; fi
fi
if [ ! -x "$bin" ]; then
    echo "replay.sh: no gridscada binary at '$bin' (build it or set GRIDSCADA_BIN)" >&2
    exit 2
fi
out=tests/e2e/artifacts/replay
mkdir -p "$out"
# One scenario: its verdict line goes to $out/NAME.verdict.
replay_one() {
    local scenario=$1 name start verdict
    name=$(basename "$scenario" .toml)
    start=$(date +%s)
    rm -f "$out/$name.optimum.json"
    # With a microgrid the day's perfect-foresight problem is written too, and
    # its optimum checked against HiGHS (tests/dispatch/foresight_highs.py).
    if GRIDSCADA_FORESIGHT_OUT="$out/$name.optimum.json" RUST_LOG=warn "$bin" replay "$scenario" --max \
        --report "$out/$name.json" --html "$out/$name.html" >"$out/$name.txt" 2>"$out/$name.log" &&
        { [ ! -s "$out/$name.optimum.json" ] ||
            python3 tests/dispatch/foresight_highs.py "$out/$name.json" "$out/$name.optimum.json" >>"$out/$name.txt"; }; then
        verdict=ok
    else
        verdict=FAILED
    fi
    echo "$verdict $name ($(( $(date +%s) - start )) s): $(grep -E '^(scenarios/|realized )' "$out/$name.txt" | tr '\n' ' ')" >"$out/$name.verdict"
}

# Two scenarios at a time: a replay does not keep both cores busy all the
# time, and its outcome does not depend on the machine's load (the virtual
# clock advances only when every task is idle), so two side by side fill
# CI's two cores better than one after the other.
jobs_at_once=${REPLAY_JOBS:-2}
running=0
for scenario in scenarios/*.toml; do
    rm -f "$out/$(basename "$scenario" .toml).verdict"
    replay_one "$scenario" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs_at_once" ]; then
        wait -n || true
        running=$((running - 1))
    fi
done
wait
passed=0
failed=0
failures=()
for scenario in scenarios/*.toml; do
    name=$(basename "$scenario" .toml)
    line=$(cat "$out/$name.verdict" 2>/dev/null || echo "FAILED $name (no verdict)")
    echo "$line"
    case "$line" in
        ok\ *) passed=$((passed + 1)) ;;
        *) failed=$((failed + 1)); failures+=("$name") ;;
    esac
done
echo "$passed passed, $failed failed"
if [ "$failed" -gt 0 ]; then
    for f in "${failures[@]}"; do
        echo "--- $f"
        grep -v '^  pass' "$out/$f.txt" || true
        tail -n 5 "$out/$f.log" || true
    done
    exit 1
fi

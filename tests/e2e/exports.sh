#!/usr/bin/env bash
# CSV exports (events, alarm history, dispatch history) of a running
# `gridscada demo`: a million events streamed in bounded server memory, all
# rows arriving, formulas defused (see exports_test.py).
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 (standard
# library only).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
export GRIDSCADA_BIN="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
[ -x "$GRIDSCADA_BIN" ] || { echo "FAIL setup: no gridscada binary at $GRIDSCADA_BIN"; echo "0 passed, 1 failed"; exit 1; }
exec timeout --kill-after=10 600 python3 "$here/exports_test.py"

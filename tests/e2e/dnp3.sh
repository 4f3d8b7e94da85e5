#!/usr/bin/env bash
# DNP3: gridscada's master, through the real binary (`demo --config`),
# against two independent Python outstations (dnp3py and py1815), with a
# tshark wire check and hostile outstations (bad CRC, a fragment that never
# completes, an object header claiming more objects than sent, garbage).
# The checks are in dnp3_test.py.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 with dnp3py
# and py1815 (tests/requirements.txt), tshark.
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
if [ ! -x "$bin" ]; then
    echo "FAIL setup: no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
    echo "0 passed, 1 failed"
    exit 1
fi
exec python3 "$here/dnp3_test.py" "$bin"

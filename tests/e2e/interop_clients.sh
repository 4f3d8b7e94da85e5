#!/usr/bin/env bash
# Interoperability: third-party clients (pymodbus, mbpoll) against the
# simulated demo plant run by `gridscada sim`, on free loopback ports.
# The checks are in interop_clients.py.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 with
# pymodbus (tests/requirements.txt), mbpoll.
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
if ! command -v python3 >/dev/null; then
    echo "FAIL setup: python3 not found"
    echo "0 passed, 1 failed"
    exit 1
fi

# The Python driver owns the simulator process and stops it; this trap only
# makes sure the driver does not outlive us.
python3 "$here/interop_clients.py" "$bin" "$root" &
pid=$!
trap 'kill -TERM "$pid" 2>/dev/null' INT TERM EXIT
wait "$pid"
rc=$?
trap - INT TERM EXIT
exit "$rc"

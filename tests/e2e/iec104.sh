#!/usr/bin/env bash
# IEC 60870-5-104: gridscada's controlling station against RTUs played by
# lib60870 (PyPI c104): interrogation, every monitored type with time tags and
# quality, clock sync, commands with select-before-operate through the
# audited write, a redundancy-group switch-over, a silent station (t1).
# The checks are in iec104_test.py.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 with c104
# (tests/requirements.txt).
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
exec python3 "$here/iec104_test.py" "$bin"

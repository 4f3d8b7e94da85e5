#!/usr/bin/env bash
# gridscada's SIMULATED telecontrol stations (`gridscada sim` on the test
# plant tests/plants/telecontrol) against independent masters: dnp3py's
# DNP3 master on the simulated outstation, lib60870's client (c104) on both
# addresses of the simulated IEC 104 RTU, and tshark over the whole session.
# The checks are in sim_stations_test.py.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 with c104
# and dnp3py (tests/requirements.txt; PYTHON to choose the interpreter),
# tshark with capture rights on lo.
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
if ! command -v tshark >/dev/null; then
    echo "FAIL setup: tshark is not installed"
    echo "0 passed, 1 failed"
    exit 1
fi
exec timeout 120 "${PYTHON:-python3}" "$here/sim_stations_test.py" "$bin"

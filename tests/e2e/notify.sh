#!/usr/bin/env bash
# Alarm notification end to end against real local peers: an SMTP sink
# (aiosmtpd, STARTTLS) and a signed webhook sink, fed by a running
# `gridscada demo` of tests/plants/three-panels (see notify_test.py).
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 with
# aiosmtpd (tests/requirements.txt).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
export GRIDSCADA_BIN="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
[ -x "$GRIDSCADA_BIN" ] || { echo "FAIL setup: no gridscada binary at $GRIDSCADA_BIN"; echo "0 passed, 1 failed"; exit 1; }
python3 -c 'import aiosmtpd' 2>/dev/null || { echo "FAIL setup: python3 has no aiosmtpd (pip install -r tests/requirements.txt)"; echo "0 passed, 1 failed"; exit 1; }
exec timeout --kill-after=10 300 python3 "$here/notify_test.py"

#!/usr/bin/env bash
# IEC 61850: gridscada's MMS client, through the real binary, against
# libiec61850's server (pyiec61850-ng) serving a model whose SCL gridscada
# imports; cross-checked by an independent client (open61850), with a
# tshark wire check and a hostile server. The checks are in
# iec61850_test.py.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), python3 with
# pyiec61850-ng and open61850 (tests/requirements.txt), tshark.
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
exec python3 "$here/iec61850_test.py" "$bin"

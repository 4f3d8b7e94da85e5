#!/usr/bin/env bash
# gridscada as the central Sparkplug B host: Debian's mosquitto on a free
# loopback port, three simulated edge nodes (tests/e2e/sparkplug_edge_sim.py,
# paho-mqtt + protobuf), and the checks in tests/e2e/sparkplug_central.py
# (all sites in /api/tags, Bad on an edge's death, Good again through its
# rebirth, writes as DCMD confirmed by the edge's DDATA, bad input counted).
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), mosquitto, and
# paho-mqtt and protobuf in the Python (tests/requirements.txt; the test
# venv target/test-venv is used when present).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
python="${PYTHON:-python3}"
[ -x "$root/target/test-venv/bin/python" ] && [ -z "${PYTHON:-}" ] && python="$root/target/test-venv/bin/python"
bin="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
mosquitto="$(command -v mosquitto || echo /usr/sbin/mosquitto)"

fail_setup() {
    echo "FAIL setup: $1"
    echo "0 passed, 1 failed"
    exit 1
}
[ -x "$bin" ] || fail_setup "no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
[ -x "$mosquitto" ] || fail_setup "mosquitto not found (apt-get install mosquitto)"
"$python" -c 'import paho.mqtt.client, google.protobuf' 2>/dev/null ||
    fail_setup "$python has no paho-mqtt or protobuf (pip install -r tests/requirements.txt)"

# The checks: sparkplug_central.py, or the script given (sparkplug_sites.sh
# runs sparkplug_sites.py with the same setup).
GRIDSCADA_BIN="$bin" MOSQUITTO="$mosquitto" exec "$python" "$here/${1:-sparkplug_central.py}"

#!/usr/bin/env bash
# Many sites: three gridscada edge nodes (three simulated plants, each the
# demo plant on its own Modbus ports) and one gridscada central host on one
# Debian mosquitto; the checks are in tests/e2e/sparkplug_sites.py (every
# site's tags at the centre, Bad on kill -9 of an edge, back through its
# rebirth, a write from the centre confirmed by the right site's device).
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

GRIDSCADA_BIN="$bin" MOSQUITTO="$mosquitto" exec "$python" "$here/sparkplug_sites.py"

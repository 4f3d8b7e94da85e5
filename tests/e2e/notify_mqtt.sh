#!/usr/bin/env bash
# The MQTT notification channel against Debian's mosquitto, with a paho-mqtt
# subscriber (see notify_mqtt_test.py).
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), mosquitto, python3
# with paho-mqtt and aiosmtpd (tests/requirements.txt; the test reuses
# notify_test.py's helpers).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
export GRIDSCADA_BIN="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
python="${PYTHON:-python3}"
fail_setup() { echo "FAIL setup: $1"; echo "0 passed, 1 failed"; exit 1; }
[ -x "$GRIDSCADA_BIN" ] || fail_setup "no gridscada binary at $GRIDSCADA_BIN"
command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ] || fail_setup "mosquitto not found (apt-get install mosquitto)"
"$python" -c 'import paho.mqtt, aiosmtpd' 2>/dev/null || fail_setup "$python has no paho-mqtt or aiosmtpd (pip install -r tests/requirements.txt)"
exec timeout --kill-after=10 300 "$python" "$here/notify_mqtt_test.py"

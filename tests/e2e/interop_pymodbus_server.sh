#!/usr/bin/env bash
# Interoperability: gridscada's poller against pymodbus servers (Modbus TCP,
# and Modbus RTU over a socat pseudo-terminal pair), every data type and word
# and byte order, plus writes. The checks are in interop_pymodbus_server.py.
#
# Needs: python3 with pymodbus and pyserial (tests/requirements.txt), socat,
# cargo (builds the interop_poll example unless INTEROP_POLL_BIN is set).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"

fail_setup() {
    echo "FAIL setup: $*"
    echo "0 passed, 1 failed"
    exit 1
}

if [ -z "${INTEROP_POLL_BIN:-}" ]; then
    echo "building the interop_poll example (server/modbus/examples/interop_poll.rs)"
    (cd "$root" && cargo build -q -p gridscada-modbus --example interop_poll) ||
        fail_setup "cargo build -p gridscada-modbus --example interop_poll failed"
    INTEROP_POLL_BIN="${CARGO_TARGET_DIR:-$root/target}/debug/examples/interop_poll"
fi
[ -x "$INTEROP_POLL_BIN" ] || fail_setup "no interop_poll binary at $INTEROP_POLL_BIN"
command -v python3 >/dev/null || fail_setup "python3 not found"

# The Python driver owns the servers and socat and cleans them up; this trap
# only makes sure it does not outlive us.
python3 "$here/interop_pymodbus_server.py" "$INTEROP_POLL_BIN" &
pid=$!
trap 'kill -TERM "$pid" 2>/dev/null' INT TERM EXIT
wait "$pid"
rc=$?
trap - INT TERM EXIT
exit "$rc"

#!/usr/bin/env bash
# gridscada behind a real reverse proxy: Debian's nginx, started unprivileged
# style from a temp dir, proxying /scada/ to `gridscada demo` served with
# base_path, trusted_proxies and public_origin. Log in, live push over the
# WebSocket, a confirmed tag write and login throttling per real client, all
# through nginx; a forged X-Forwarded-For straight to gridscada is ignored;
# forged Forwarded and X-Forwarded-For through nginx neither escape the
# lockout, reach the event log nor open /metrics (of a second server,
# `serve`). nginx runs the location block of docs/REVERSE_PROXY.md.
# The checks are in nginx_proxy.py.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), nginx, curl, python3
# with websockets (tests/requirements.txt), loopback addresses 127.0.0.2-12
# (Linux answers the whole of 127.0.0.0/8 on lo).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"

fail_setup() {
    echo "FAIL setup: $1"
    echo "0 passed, 1 failed"
    exit 1
}
[ -x "$bin" ] || fail_setup "no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
PATH="$PATH:/usr/sbin:/sbin"
command -v nginx >/dev/null || fail_setup "nginx not found (apt-get install nginx)"
command -v curl >/dev/null || fail_setup "curl not found"
python3 -c 'import websockets' 2>/dev/null || fail_setup "python3 lacks websockets (pip install -r tests/requirements.txt)"

# The Python driver owns gridscada and nginx and stops them; this trap only
# makes sure the driver does not outlive us.
python3 "$here/nginx_proxy.py" "$bin" "$root" &
pid=$!
trap 'kill -TERM "$pid" 2>/dev/null' INT TERM EXIT
wait "$pid"

#!/usr/bin/env bash
# HTTPS end to end, with real curl, openssl and a Python WebSocket client:
# `gridscada cert self-signed`, `gridscada demo` on the demo plant with
# [server.tls], login over HTTPS (Secure cookie, HSTS), the plain-HTTP
# redirect listener, wss:// on /api/live, and SIGHUP reloads: a mismatched
# pair is refused (the old certificate keeps serving, an event says why), a
# good new pair is served to new connections while a WebSocket opened before
# keeps working.
#
# Needs: GRIDSCADA_BIN (default target/debug/gridscada), curl, openssl,
# python3 with websockets (tests/requirements.txt).
# Prints "N passed, M failed" last; exits non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-${CARGO_TARGET_DIR:-$root/target}/debug/gridscada}"
python="${PYTHON:-python3}"
[ -x "$root/target/test-venv/bin/python" ] && [ -z "${PYTHON:-}" ] && python="$root/target/test-venv/bin/python"

passed=0
failed=0
ok() { echo "ok   $1"; passed=$((passed + 1)); }
bad() { echo "FAIL $1"; failed=$((failed + 1)); }
check() { # check NAME COMMAND...: passes when the command succeeds
    local name=$1; shift
    if "$@"; then ok "$name"; else bad "$name"; fi
}
fail_setup() {
    echo "FAIL setup: $1"
    [ -f "${tmp:-/nonexistent}/server.log" ] && tail -20 "$tmp/server.log"
    echo "$passed passed, $((failed + 1)) failed"
    exit 1
}
[ -x "$bin" ] || fail_setup "no gridscada binary at $bin (cargo build -p gridscada, or set GRIDSCADA_BIN)"
for c in curl openssl; do command -v $c >/dev/null || fail_setup "$c not found"; done
"$python" -c 'import websockets' 2>/dev/null || fail_setup "python websockets missing (pip install -r tests/requirements.txt)"

tmp="$(mktemp -d)"
pid=""
live_pid=""
cleanup() {
    [ -n "$live_pid" ] && kill "$live_pid" 2>/dev/null
    if [ -n "$pid" ]; then kill -TERM "$pid" 2>/dev/null; wait "$pid" 2>/dev/null; fi
    rm -rf "$tmp"
}
trap cleanup EXIT INT TERM

free_port() { "$python" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
port="$(free_port)"
rport="$(free_port)"
base="https://localhost:$port"
conf="$tmp/conf"
mkdir -p "$conf"
cp "$root"/tags/*.toml "$conf/"

# --- The certificate ---------------------------------------------------------
"$bin" cert self-signed --config "$conf/gridscada.toml" --host localhost --host 127.0.0.1 --days 2 \
    >"$tmp/cert.out" 2>&1 || fail_setup "cert self-signed: $(cat "$tmp/cert.out")"
check "cert self-signed writes the key with mode 0600" test "$(stat -c %a "$conf/key.pem")" = 600
check "cert self-signed prints the [server.tls] lines" grep -qx 'cert = "cert.pem"' "$tmp/cert.out"
if "$bin" cert self-signed --config "$conf" >"$tmp/again.out" 2>&1; then
    bad "cert self-signed refuses to overwrite without --force"
else
    check "cert self-signed refuses to overwrite without --force" grep -q -- "--force" "$tmp/again.out"
fi
check "the certificate names localhost and 127.0.0.1" sh -c \
    "openssl x509 -in '$conf/cert.pem' -noout -ext subjectAltName | grep -q 'DNS:localhost, IP Address:127.0.0.1'"

cat >>"$conf/gridscada.toml" <<EOF

[server.tls]
cert = "cert.pem"
key = "key.pem"
redirect_http = "127.0.0.1:$rport"
hsts_max_age_s = 600
EOF
check "gridscada check reads the pair" "$bin" check "$conf"

# A key that is not the certificate's: check names the file and why.
mkdir -p "$tmp/other"
"$bin" cert self-signed --out "$tmp/other" --host localhost >/dev/null 2>&1 || fail_setup "second pair"
sed -e 's#^key = "key.pem"#key = "'"$tmp"'/other/key.pem"#' -e 's#^cert = "cert.pem"#cert = "'"$conf"'/cert.pem"#' \
    "$conf/gridscada.toml" >"$tmp/mismatch.toml"
# The tag files beside it, whatever the plant's are.
for f in "$conf"/*.toml; do
    [ "$(basename "$f")" = gridscada.toml ] || cp "$f" "$tmp/"
done
"$bin" check "$tmp/mismatch.toml" >"$tmp/mismatch.out" 2>&1
check "check refuses a key of another certificate, naming the file" \
    grep -q "\[server.tls\] key $tmp/other/key.pem: does not belong to the certificate" "$tmp/mismatch.out"

# --- Serving -------------------------------------------------------------------
"$bin" demo --config "$conf" --http "127.0.0.1:$port" --data "$tmp/data" >"$tmp/server.log" 2>&1 &
pid=$!
for _ in $(seq 1 150); do
    curl -fsS --cacert "$conf/cert.pem" "$base/healthz" >/dev/null 2>&1 && [ -s "$tmp/data/credentials.txt" ] && break
    kill -0 "$pid" 2>/dev/null || fail_setup "gridscada demo exited"
    sleep 0.2
done
curl -fsS --cacert "$conf/cert.pem" "$base/healthz" >/dev/null 2>&1 || fail_setup "no HTTPS answer on $base"
check "the banner shows the https URL" grep -q "HMI and API: https://127.0.0.1:$port/" "$tmp/server.log"
check "plain HTTP on the HTTPS port gets no page" sh -c "! curl -fsS --max-time 5 http://127.0.0.1:$port/healthz >/dev/null 2>&1"
check "an untrusted client refuses the self-signed certificate" sh -c "! curl -fsS --max-time 5 $base/healthz >/dev/null 2>&1"

read -r user password < <(awk '$1 == "administrator" { print $2, $3; exit }' "$tmp/data/credentials.txt")
body="$("$python" -c 'import json,sys; print(json.dumps({"username": sys.argv[1], "password": sys.argv[2]}))' "$user" "$password")"
curl -sS --cacert "$conf/cert.pem" -D "$tmp/login.h" -o /dev/null -H 'Content-Type: application/json' \
    -H "Origin: $base" -d "$body" "$base/api/session"
setcookie="$(tr -d '\r' <"$tmp/login.h" | awk 'tolower($1) == "set-cookie:"' | head -1)"
cookie="$(printf '%s' "$setcookie" | sed -E 's/^[^:]*: *([^;]*).*/\1/')"
case "$cookie" in gridscada_session=?*) ok "log in over HTTPS" ;; *) fail_setup "login over HTTPS failed: $(cat "$tmp/login.h")" ;; esac
check "the session cookie is Secure" sh -c "printf '%s' '$setcookie' | grep -qi '; *Secure'"
check "HSTS with the configured max-age" grep -qi '^strict-transport-security: max-age=600' "$tmp/login.h"
check "an authenticated request over HTTPS" \
    curl -fsS --cacert "$conf/cert.pem" -o /dev/null -H "Cookie: $cookie" "$base/api/events?limit=1"

# --- The redirect listener ------------------------------------------------------
curl -sS -o /dev/null -D "$tmp/redir.h" "http://127.0.0.1:$rport/api/tags?x=1"
check "plain HTTP is redirected with 308" grep -q '^HTTP/1.1 308' "$tmp/redir.h"
check "the redirect keeps host, path and query" grep -qi "^location: https://127.0.0.1:$port/api/tags?x=1" <(tr -d '\r' <"$tmp/redir.h")
check "the redirect serves nothing else (a POST is redirected too)" sh -c \
    "curl -sS -o /dev/null -w '%{http_code}' -X POST -d x http://127.0.0.1:$rport/api/session | grep -qx 308"
curl -sS -o /dev/null -D "$tmp/forged.h" -H 'Host: evil.example' "http://127.0.0.1:$rport/"
check "a Host the server does not answer to gets 421, no redirect" sh -c \
    "grep -q '^HTTP/1.1 421' '$tmp/forged.h' && ! grep -qi '^location:' '$tmp/forged.h'"
check "following the redirect reaches the HMI over HTTPS" \
    curl -fsSL --cacert "$conf/cert.pem" -o /dev/null "http://localhost:$rport/healthz"

# --- A WebSocket over wss, held open across the reloads --------------------------
fingerprint() { # the SHA-256 fingerprint of the certificate served to a new connection
    openssl s_client -connect "127.0.0.1:$port" -servername localhost </dev/null 2>/dev/null \
        | openssl x509 -noout -fingerprint -sha256 2>/dev/null
}
before="$(fingerprint)"
[ -n "$before" ] || fail_setup "openssl s_client got no certificate"
check "openssl sees the generated certificate" test "$before" = "$(openssl x509 -in "$conf/cert.pem" -noout -fingerprint -sha256)"

"$python" "$here/tls_live.py" "wss://localhost:$port/api/live" "$conf/cert.pem" "$cookie" "$base" \
    "$tmp/live.ready" "$tmp/live.go" >"$tmp/live.out" 2>&1 &
live_pid=$!
for _ in $(seq 1 100); do [ -f "$tmp/live.ready" ] && break; kill -0 "$live_pid" 2>/dev/null || break; sleep 0.1; done
if [ -f "$tmp/live.ready" ]; then ok "a WebSocket over wss:// gets hello and heartbeats"; else bad "a WebSocket over wss:// ($(cat "$tmp/live.out"))"; fi

# A mismatched pair: refused, the old one keeps serving.
mkdir -p "$tmp/new"
"$bin" cert self-signed --out "$tmp/new" --host localhost --host 127.0.0.1 --days 3 >/dev/null 2>&1 || fail_setup "new pair"
cp "$conf/cert.pem" "$tmp/old-cert.pem"
cp "$tmp/new/cert.pem" "$conf/cert.pem"   # the new certificate with the old key
kill -HUP "$pid"
for _ in $(seq 1 50); do grep -q "TLS reload refused" "$tmp/server.log" && break; sleep 0.1; done
check "a mismatched pair is refused on SIGHUP, saying why" grep -q "TLS reload refused.*does not belong to the certificate" "$tmp/server.log"
check "the old certificate keeps serving after a refused reload" test "$(fingerprint)" = "$before"
check "the server is still up" kill -0 "$pid"

# The good new pair.
cp "$tmp/new/key.pem" "$conf/key.pem"
kill -HUP "$pid"
for _ in $(seq 1 50); do grep -q "TLS certificate reloaded" "$tmp/server.log" && break; sleep 0.1; done
after="$(fingerprint)"
check "new connections get the new certificate after SIGHUP" test "$after" = "$(openssl x509 -in "$tmp/new/cert.pem" -noout -fingerprint -sha256)"
check "the served fingerprint changed" test "$after" != "$before"
check "clients trusting the new certificate connect" curl -fsS --cacert "$tmp/new/cert.pem" -o /dev/null "$base/healthz"
check "clients trusting only the old one are refused" sh -c "! curl -fsS --cacert '$tmp/old-cert.pem' -o /dev/null $base/healthz 2>/dev/null"
touch "$tmp/live.go"
if wait "$live_pid"; then ok "the WebSocket opened before the reloads kept working"; else bad "the WebSocket opened before the reloads: $(cat "$tmp/live.out")"; fi
live_pid=""
check "the session survives the reload" \
    curl -fsS --cacert "$tmp/new/cert.pem" -o /dev/null -H "Cookie: $cookie" "$base/api/events?limit=1"
curl -fsS --cacert "$tmp/new/cert.pem" -H "Cookie: $cookie" "$base/api/events?limit=200" >"$tmp/events.json" 2>/dev/null
check "the refused and the done reload are events" sh -c \
    "grep -q 'TLS reload refused' '$tmp/events.json' && grep -q 'TLS certificate reloaded' '$tmp/events.json'"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]

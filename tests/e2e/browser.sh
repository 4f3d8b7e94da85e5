#!/usr/bin/env bash
# End-to-end tests of the web HMI in headless Chromium (Debian's package),
# driven by playwright-core. Starts a demo server on a free port with a fresh
# data directory, runs tests/e2e/browser/tests/*.test.js, stops the server,
# and prints "N passed, M failed". Screenshots go to tests/e2e/artifacts/.
#
# Environment: GRIDSCADA_BIN (default target/debug/gridscada, built if missing).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-$root/target/debug/gridscada}"
artifacts="$here/artifacts"

if [ ! -x /usr/bin/chromium ]; then
  echo "browser.sh: installing Debian's chromium"
  export DEBIAN_FRONTEND=noninteractive
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq chromium >/dev/null
fi
# The HMI is embedded into the binary at compile time: build unless a binary was given.
if [ -z "${GRIDSCADA_BIN:-}" ]; then
  (cd "$root" && cargo build -p gridscada)
fi
[ -x "$bin" ] || { echo "browser.sh: no gridscada binary at $bin"; exit 1; }

cd "$here/browser"
if [ -f package-lock.json ]; then npm ci --no-audit --no-fund --loglevel=error; else npm install --no-audit --no-fund --loglevel=error; fi

mkdir -p "$artifacts"
rm -f "$artifacts"/*.png "$artifacts"/*.csv "$artifacts"/*.log
data="$(mktemp -d -t gridscada-e2e-XXXXXX)"
port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()')"
"$bin" demo --http "127.0.0.1:$port" --data "$data" >"$artifacts/server.log" 2>&1 &
server=$!
cleanup() {
  kill "$server" 2>/dev/null || true
  wait "$server" 2>/dev/null || true
  rm -rf "$data"
}
trap cleanup EXIT

# Wait for the server and its generated credentials.
for _ in $(seq 1 150); do
  if [ -s "$data/credentials.txt" ] && curl -fsS "http://127.0.0.1:$port/healthz" >/dev/null 2>&1; then break; fi
  if ! kill -0 "$server" 2>/dev/null; then echo "browser.sh: the server exited:"; cat "$artifacts/server.log"; exit 1; fi
  sleep 0.2
done
[ -s "$data/credentials.txt" ] || { echo "browser.sh: no credentials.txt after 30 s"; cat "$artifacts/server.log"; exit 1; }
# Let the demo record a few seconds of history for the trend test.
sleep 3

tap="$artifacts/results.tap"
set +e
GRIDSCADA_URL="http://127.0.0.1:$port" GRIDSCADA_CREDENTIALS="$data/credentials.txt" GRIDSCADA_ARTIFACTS="$artifacts" \
  node --test --test-concurrency=1 \
    --test-reporter=spec --test-reporter-destination=stdout \
    --test-reporter=tap --test-reporter-destination="$tap" \
    tests/*.test.js
rc=$?
set -e
passed="$(grep -E '^# pass ' "$tap" | awk '{print $3}' | tail -1)"
failed="$(grep -E '^# fail ' "$tap" | awk '{print $3}' | tail -1)"
echo "screenshots: $artifacts"
echo "${passed:-0} passed, ${failed:-0} failed"
[ "$rc" -eq 0 ] && [ "${failed:-1}" -eq 0 ]

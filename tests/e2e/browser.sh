#!/usr/bin/env bash
# End-to-end tests of the web HMI in headless Chromium (Debian's package),
# driven by playwright-core. Starts two servers on free ports with fresh data
# directories (the demo plant, and tests/plants/three-panels), runs
# tests/e2e/browser/tests/*.test.js against the first and
# tests/e2e/browser/plant2/*.test.js against the second, side by side, then
# tests/e2e/browser/telecontrol/*.test.js against a third (the test plant
# tests/plants/telecontrol, over IEC 104 and DNP3) and
# tests/e2e/browser/network/*.test.js against a fourth (the demo again, on
# its own: the switching network's tests change its state), stops them, and prints
# "N passed, M failed". Screenshots, each run's report
# (spec-NAME.log, results-NAME.tap) and the servers' logs go to
# tests/e2e/artifacts/.
#
# Environment: GRIDSCADA_BIN (default target/debug/gridscada, built if missing);
# GRIDSCADA_BROWSER_SERIAL=1 runs the two plants one after the other.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-$root/target/debug/gridscada}"
# A relative path is the caller's: the script changes directory below.
case $bin in /*) ;; *) bin="$PWD/$bin" ;; esac
artifacts="${GRIDSCADA_E2E_ARTIFACTS:-$here/artifacts}"

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

# playwright-core needs Node.js 20 or later; Debian 12's nodejs is 18. Then
# Node.js 22 comes from the npm registry (the `node` package, a binary for
# this platform), under target/, first on PATH for these tests only.
node_major=$(node -p 'process.versions.node.split(".")[0]' 2>/dev/null || echo 0)
if [ "$node_major" -lt 20 ] || [ -n "${GRIDSCADA_TEST_NODE_FROM_NPM:-}" ]; then
  node_dir="$root/target/test-node"
  if [ ! -x "$node_dir/node_modules/.bin/node" ]; then
    echo "browser.sh: Node.js $(node -v 2>/dev/null || echo none) is too old for playwright-core; installing Node.js 22 from npm into $node_dir"
    npm install --prefix "$node_dir" --no-audit --no-fund --loglevel=error node@22 >/dev/null
  fi
  export PATH="$node_dir/node_modules/.bin:$PATH"
  echo "browser.sh: using Node.js $(node -v)"
fi

cd "$here/browser"
if [ -f package-lock.json ]; then npm ci --no-audit --no-fund --loglevel=error; else npm install --no-audit --no-fund --loglevel=error; fi

mkdir -p "$artifacts"
rm -f "$artifacts"/*.png "$artifacts"/*.csv "$artifacts"/*.log "$artifacts"/*.tap "$artifacts"/rc-*

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()'; }

servers=()
datas=()
cleanup() {
  for p in "${servers[@]}"; do kill "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
  for d in "${datas[@]}"; do rm -rf "$d"; done
}
trap cleanup EXIT

# start NAME PORT [demo args...]: a server with a fresh data folder; sets $data.
start() {
  local name=$1 port=$2; shift 2
  data="$(mktemp -d -t gridscada-e2e-XXXXXX)"
  datas+=("$data")
  "$bin" demo --http "127.0.0.1:$port" --data "$data" "$@" >"$artifacts/server-$name.log" 2>&1 &
  local pid=$!
  server_pid=$pid
  servers+=("$pid")
  for _ in $(seq 1 150); do
    if [ -s "$data/credentials.txt" ] && curl -fsS "http://127.0.0.1:$port/healthz" >/dev/null 2>&1; then return 0; fi
    if ! kill -0 "$pid" 2>/dev/null; then echo "browser.sh: the $name server exited:"; cat "$artifacts/server-$name.log"; exit 1; fi
    sleep 0.2
  done
  echo "browser.sh: the $name server gave no credentials.txt after 30 s"; cat "$artifacts/server-$name.log"; exit 1
}

# run NAME PORT DATA PID FILES...: the test files against one server, under
# a time limit; the spec report goes to $artifacts/spec-NAME.log, the exit
# status to $artifacts/rc-NAME.
run() {
  local name=$1 port=$2 dir=$3 pid=$4; shift 4
  local rc=0
  GRIDSCADA_URL="http://127.0.0.1:$port" GRIDSCADA_CREDENTIALS="$dir/credentials.txt" GRIDSCADA_ARTIFACTS="$artifacts" \
  GRIDSCADA_PID="$pid" \
    timeout --kill-after=20 900 node --test --test-concurrency=1 \
      --test-reporter=spec --test-reporter-destination=stdout \
      --test-reporter=tap --test-reporter-destination="$artifacts/results-$name.tap" \
      "$@" >"$artifacts/spec-$name.log" 2>&1 || rc=$?
  echo "$rc" >"$artifacts/rc-$name"
}

# The demo plant, and another plant (tests/plants/three-panels: other panel
# ids and zone counts, no microgrid, a plain device): nothing may depend on
# the demo.
port1="$(free_port)"
start demo "$port1"
data1=$data pid1=$server_pid
port2="$(free_port)"
start plant2 "$port2" --config "$root/tests/plants/three-panels"
data2=$data pid2=$server_pid
# Let the demo record a few seconds of history for the trend test.
sleep 3
# The two plants' tests side by side, each one test at a time: they spend
# most of their time waiting on the servers' clocks (dwell times, session
# expiry, scan periods), so together they take the time of the longer one.
# GRIDSCADA_BROWSER_SERIAL=1 runs them one after the other.
if [ -n "${GRIDSCADA_BROWSER_SERIAL:-}" ]; then
  run demo "$port1" "$data1" "$pid1" tests/*.test.js
  run plant2 "$port2" "$data2" "$pid2" plant2/*.test.js
else
  run demo "$port1" "$data1" "$pid1" tests/*.test.js &
  demo_run=$!
  run plant2 "$port2" "$data2" "$pid2" plant2/*.test.js &
  plant2_run=$!
  wait "$demo_run" "$plant2_run" || true
fi
# Then the telecontrol plant: its panels over IEC 104 and DNP3.
port3="$(free_port)"
start telecontrol "$port3" --config "$root/tests/plants/telecontrol"
run telecontrol "$port3" "$data" "$server_pid" telecontrol/*.test.js
# Then the switching network: the demo's 11 kV ring round its panels and
# microgrid, operated from the network screen, on a demo of its own (the
# tests open feeders, earth cables and trip panels).
port4="$(free_port)"
start network "$port4"
run network "$port4" "$data" "$server_pid" network/*.test.js

total_passed=0
total_failed=0
for name in demo plant2 telecontrol network; do
  echo "--- $name"
  cat "$artifacts/spec-$name.log" 2>/dev/null || true
  tap="$artifacts/results-$name.tap"
  rc="$(cat "$artifacts/rc-$name" 2>/dev/null || echo 1)"
  # A run that died before its summary has none: counted as failed below.
  p="$(grep -E '^# pass ' "$tap" 2>/dev/null | awk '{print $3}' | tail -1 || true)"
  f="$(grep -E '^# fail ' "$tap" 2>/dev/null | awk '{print $3}' | tail -1 || true)"
  [ "$rc" -ne 0 ] && [ "${f:-0}" -eq 0 ] && f=1
  total_passed=$((total_passed + ${p:-0}))
  total_failed=$((total_failed + ${f:-0}))
done

echo "screenshots: $artifacts"
echo "${total_passed} passed, ${total_failed} failed"
[ "$total_failed" -eq 0 ]

#!/usr/bin/env bash
# The HMI follows a redundant pair's failover without a new login, in
# headless Chromium (tests/e2e/browser/pair/failover.test.js): two
# `gridscada serve` processes on the demo plant and one PostgreSQL database
# (GRIDSCADA_TEST_PG_URL: a database of its own is created there and dropped
# at the end), the demo's devices from `gridscada sim`. The test logs in on
# the active server a, kills it (kill -9), and checks the page moves to b,
# shows b active and is still logged in. Then (pair/sites.test.js) a
# server of another site on the same database, "south", is read from b's
# event and alarm history screens through their Site choice.
#
# Server a listens on 127.0.0.1, server b on 127.0.0.2: two hosts, as two
# machines are, so the session cookie of one is not sent to the other and
# the login has to be carried by the HMI's failover ticket.
#
# Environment: GRIDSCADA_BIN (default target/debug/gridscada, built if
# missing), GRIDSCADA_TEST_PG_URL (eval "$(scripts/pg-test-cluster.sh)").
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
bin="${GRIDSCADA_BIN:-$root/target/debug/gridscada}"
artifacts="${GRIDSCADA_E2E_ARTIFACTS:-$here/artifacts}"
pg="${GRIDSCADA_TEST_PG_URL:?pair_browser.sh: GRIDSCADA_TEST_PG_URL is not set (eval \"\$(scripts/pg-test-cluster.sh)\")}"

[ -x /usr/bin/chromium ] || { echo "pair_browser.sh: no /usr/bin/chromium (apt-get install chromium)"; exit 1; }
if [ -z "${GRIDSCADA_BIN:-}" ]; then
  (cd "$root" && cargo build -p gridscada)
fi
[ -x "$bin" ] || { echo "pair_browser.sh: no gridscada binary at $bin"; exit 1; }
# Node.js 20 or later for playwright-core, as browser.sh sets it up.
node_major=$(node -p 'process.versions.node.split(".")[0]' 2>/dev/null || echo 0)
if [ "$node_major" -lt 20 ]; then
  node_dir="$root/target/test-node"
  if [ ! -x "$node_dir/node_modules/.bin/node" ]; then
    npm install --prefix "$node_dir" --no-audit --no-fund --loglevel=error node@22 >/dev/null
  fi
  export PATH="$node_dir/node_modules/.bin:$PATH"
fi
cd "$here/browser"
[ -d node_modules/playwright-core ] || npm ci --no-audit --no-fund --loglevel=error
mkdir -p "$artifacts"

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()'; }

tmp="$(mktemp -d -t gridscada-pair-XXXXXX)"
db="gs_pair_browser_$$"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
  psql -X -q "$pg" -c "DROP DATABASE IF EXISTS $db WITH (FORCE)" >/dev/null 2>&1 || true
  rm -rf "$tmp"
}
trap cleanup EXIT
psql -X -q -v ON_ERROR_STOP=1 "$pg" -c "CREATE DATABASE $db" >/dev/null
url="${pg%/*}/$db"
pa=$(free_port)
pb=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.2", 0)); print(s.getsockname()[1]); s.close()')
port_base=$((26000 + ($$ % 400) * 20))

# plant NAME: the demo plant's files in $tmp/NAME as server NAME of the
# pair, on the test database, its devices moved to ports from $port_base.
plant() {
  python3 - "$root/tags" "$tmp/$1" "$url" "$1" "$pa" "$pb" "$port_base" <<'PY'
import pathlib, sys
src, dst, url, name, pa, pb, base = sys.argv[1:]
dst = pathlib.Path(dst)
dst.mkdir(parents=True)
for f in pathlib.Path(src).glob("*.toml"):
    text = f.read_text()
    for p in range(15000, 15100):
        text = text.replace(f'127.0.0.1:{p}"', f'127.0.0.1:{int(base) + p - 15000}"')
    if f.name == "gridscada.toml":
        text = text.replace("sqlite://gridscada.db", url)
        text += f'\n[redundancy]\nname = "{name}"\n'
        for s, host in (("a", f"127.0.0.1:{pa}"), ("b", f"127.0.0.2:{pb}")):
            text += f'[[redundancy.server]]\nname = "{s}"\nurl = "http://{host}"\n'
    (dst / f.name).write_text(text)
PY
}
plant a
plant b
# The other site: a server alone, its devices (not simulated) elsewhere.
python3 - "$tmp/a" "$tmp/south" "$port_base" <<'PY'
import pathlib, sys
src, dst, base = sys.argv[1:]
dst = pathlib.Path(dst)
dst.mkdir(parents=True)
for f in pathlib.Path(src).glob("*.toml"):
    text = f.read_text()
    for p in range(int(base), int(base) + 100):
        text = text.replace(f'127.0.0.1:{p}"', f'127.0.0.1:{p + 5000}"')
    if f.name == "gridscada.toml":
        text = text[: text.index("\n[redundancy]")] + "\n"
        text = text.replace("\n[server]\n", '\n[server]\nsite = "south"\n', 1)
    (dst / f.name).write_text(text)
PY

"$bin" sim --config "$tmp/a/gridscada.toml" </dev/null >"$artifacts/pair-sim.log" 2>&1 &
pids+=($!)
password="pair-browser-password-$$"
printf '%s\n' "$password" | "$bin" user add op --role operator --config "$tmp/a/gridscada.toml" >/dev/null
printf 'operator op %s\n' "$password" >"$tmp/credentials.txt"

# serve NAME HOST:PORT: starts the server; sets $pid.
serve() {
  "$bin" serve --config "$tmp/$1/gridscada.toml" --http "$2" >"$artifacts/pair-$1.log" 2>&1 &
  pid=$!
  pids+=("$pid")
}
# active HOST:PORT: whether the server there holds the lease.
# (The page is read whole first: grep -q closing the pipe early would fail
# curl, and with it the pipeline.)
active() { grep -q '^gridscada_pair_active 1' <<<"$(curl -fsS "http://$1/metrics" 2>/dev/null)"; }

serve a "127.0.0.1:$pa"
pid_a=$pid
for _ in $(seq 1 150); do active "127.0.0.1:$pa" && break; sleep 0.2; done
active "127.0.0.1:$pa" || { echo "pair_browser.sh: server a did not become active"; tail -20 "$artifacts/pair-a.log"; exit 1; }
serve b "127.0.0.2:$pb"
for _ in $(seq 1 150); do curl -fsS "http://127.0.0.2:$pb/healthz" >/dev/null 2>&1 && break; sleep 0.2; done
curl -fsS "http://127.0.0.2:$pb/healthz" >/dev/null || { echo "pair_browser.sh: server b did not start"; tail -20 "$artifacts/pair-b.log"; exit 1; }

ps=$(free_port)
serve south "127.0.0.1:$ps"
for _ in $(seq 1 150); do curl -fsS "http://127.0.0.1:$ps/healthz" >/dev/null 2>&1 && break; sleep 0.2; done
# A login at the south site: an event of its own.
curl -fsS -o /dev/null -H 'Content-Type: application/json' \
  -d "{\"username\":\"op\",\"password\":\"$password\"}" "http://127.0.0.1:$ps/api/session" \
  || { echo "pair_browser.sh: cannot log in at the south site"; tail -20 "$artifacts/pair-south.log"; exit 1; }

GRIDSCADA_URL="http://127.0.0.1:$pa" GRIDSCADA_PAIR_OTHER="http://127.0.0.2:$pb" GRIDSCADA_PID="$pid_a" \
GRIDSCADA_CREDENTIALS="$tmp/credentials.txt" GRIDSCADA_ARTIFACTS="$artifacts" \
  timeout --kill-after=20 180 node --test --test-concurrency=1 --test-reporter=spec pair/failover.test.js pair/sites.test.js

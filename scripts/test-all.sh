#!/usr/bin/env bash
# The whole gridscada test suite, on a fresh Debian machine.
# It installs what the tests need first (Debian packages, Python test peers,
# a throwaway PostgreSQL cluster when none runs on 127.0.0.1:5432), then runs
# formatting, dependency and licence checks, lints, every Rust test, and the
# end-to-end tests.
#
#     bash scripts/test-all.sh               # everything
#     bash scripts/test-all.sh --setup-only  # stages 1-3 (packages, toolchain,
#                                            # venv, PostgreSQL), then stop
set -euo pipefail
setup_only=""
case "${1:-}" in
    "") ;;
    --setup-only) setup_only=1 ;;
    *) echo "usage: bash scripts/test-all.sh [--setup-only]" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."
root=$(pwd)
export CARGO_TERM_COLOR=never

step() { printf '\n==> %s  (at %d s)\n' "$*" $(( $(date +%s) - run_started )); }

# Every stage runs under an outer time limit (seconds), so a hung stage fails
# with its name instead of eating CI's 90 minutes. The whole run also has a
# budget (GRIDSCADA_TEST_BUDGET, 88 minutes by default): no stage may run past
# it, so a slow machine ends with the name of the stage it was in and a
# failure, not with CI's kill and no output.
run_started=$(date +%s)
budget_end=$(( run_started + ${GRIDSCADA_TEST_BUDGET:-5280} ))
limit() {
    local secs=$1; shift
    local rc=0
    local left=$(( budget_end - $(date +%s) ))
    if [ "$left" -le 0 ]; then
        echo "test-all: the run's budget is spent before '$*'" >&2
        return 124
    fi
    [ "$secs" -le "$left" ] || secs=$left
    # `|| rc=$?`: under set -e a bare failing command would leave the
    # function before the message below.
    timeout --kill-after=30 "$secs" "$@" || rc=$?
    if [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ]; then
        echo "test-all: '$*' did not finish within $secs s" >&2
    fi
    return "$rc"
}

# The tests talk only to servers of their own on loopback (127.0.0.1 to
# 127.0.0.9), never through a proxy set for the package registries. curl
# (>= 7.86) and Python's requests read the range 127.0.0.0/8; Python's
# urllib and websockets match the addresses one by one.
loopback="localhost,::1,127.0.0.0/8,$(seq -s, -f '127.0.0.%g' 1 9)"
export no_proxy="${no_proxy:+$no_proxy,}$loopback" NO_PROXY="${NO_PROXY:+$NO_PROXY,}$loopback"

# A command as root (sudo when not root), as an array so `limit` can run it.
root_cmd=()
[ "$(id -u)" -eq 0 ] || root_cmd=(sudo)

# --- 1. Debian packages the tests use ------------------------------------
# gcc and libc6-dev: the linker and C compiler that rustc and build scripts
# call; ca-certificates: cargo and pip over HTTPS; chromium: the browser
# tests, and reports.sh's PDF, which runs before them (a clean machine has no
# browser until this installs it).
debian_packages=(postgresql socat mbpoll libmodbus-dev pkg-config curl python3-venv nginx
    gcc libc6-dev ca-certificates mosquitto
    poppler-utils tshark chromium)
# Debian's nodejs comes without npm (the browser tests install playwright-core with it).
command -v npm >/dev/null 2>&1 || debian_packages+=(npm)
missing=()
for p in "${debian_packages[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    step "installing Debian packages: ${missing[*]}"
    limit 600 "${root_cmd[@]}" apt-get update -qq
    limit 1200 "${root_cmd[@]}" env DEBIAN_FRONTEND=noninteractive \
        apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# --- 1b. the Rust toolchain ------------------------------------------------
# rustup reads rust-toolchain.toml; a toolchain installed without its
# rustfmt or clippy gets them added. Without rustup, the cargo on PATH must
# be 1.88 or newer (Debian's own is older) and bring its own rustfmt/clippy.
step "Rust toolchain"
if command -v rustup >/dev/null 2>&1; then
    installed_components=$(limit 600 rustup component list --installed)
    for c in rustfmt clippy; do
        if ! grep -q "^$c" <<<"$installed_components"; then
            echo "adding the rustup component $c"
            limit 600 rustup component add "$c"
        fi
    done
else
    echo "no rustup: using $(command -v cargo || echo 'no cargo'); the toolchain pinned in rust-toolchain.toml is not enforced"
fi
command -v cargo >/dev/null 2>&1 || { echo "test-all: no cargo on PATH (install Rust with rustup, see README)" >&2; exit 1; }
cargo --version
cargo_minor=$(cargo --version | sed -n 's/^cargo 1\.\([0-9]*\).*/\1/p')
if [ "${cargo_minor:-0}" -lt 88 ]; then
    echo "test-all: $(cargo --version) is too old: the locked dependencies need 1.88 (Debian's own cargo is older; install Rust with rustup, see README)" >&2
    exit 1
fi
cargo fmt --version >/dev/null 2>&1 || { echo "test-all: cargo fmt is missing (rustup component add rustfmt)" >&2; exit 1; }
cargo clippy --version >/dev/null 2>&1 || { echo "test-all: cargo clippy is missing (rustup component add clippy)" >&2; exit 1; }

# --- 2. Python test peers, in a venv of their own -------------------------
venv="$root/target/test-venv"
# A half-made venv (no pip, or a python that no longer runs) is made afresh.
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -m pip --version >/dev/null 2>&1; then
    step "creating the Python test venv"
    rm -rf "$venv"
    limit 300 python3 -m venv "$venv"
fi
step "installing Python test peers"
limit 900 "$venv/bin/pip" install -q --disable-pip-version-check -r tests/requirements.txt
export PATH="$venv/bin:$PATH"
# The DNP3 master's test runs dnp3py's outstation with this python.
export GRIDSCADA_DNP3PY="$venv/bin/python"

# --- 3. PostgreSQL for the store tests ------------------------------------
step "PostgreSQL"
# Not `eval "$(...)"`: that would hide the script's failure.
pg_env=$(limit 600 bash scripts/pg-test-cluster.sh) || { echo "test-all: no PostgreSQL for the tests" >&2; exit 1; }
eval "$pg_env"
# A throwaway cluster started for this run is stopped when the run ends.
if [ -n "${GRIDSCADA_TEST_PG_STOP:-}" ]; then
    trap 'eval "$GRIDSCADA_TEST_PG_STOP" >/dev/null 2>&1 || true' EXIT
fi
export GRIDSCADA_REQUIRE_PG=1
limit 60 psql -X -w "$GRIDSCADA_TEST_PG_URL" -tAc 'SELECT version()' \
    || { echo "test-all: cannot connect to $GRIDSCADA_TEST_PG_URL" >&2; exit 1; }
if [ -n "$setup_only" ]; then
    step "setup done (--setup-only): packages, toolchain, venv and PostgreSQL ready"
    exit 0
fi

# --- 4. Rust: format, lint, tests -----------------------------------------
step "cargo fmt --check"
limit 300 cargo fmt --all -- --check
step "unused dependencies (cargo-machete)"
if ! command -v cargo-machete >/dev/null 2>&1; then
    limit 900 cargo install --locked --quiet cargo-machete
fi
limit 300 cargo machete
# A short script over `cargo metadata` rather than cargo-deny or cargo-about,
# which would take minutes to build on CI's two cores.
step "licences of the product's dependencies (scripts/licenses.py)"
limit 60 python3 scripts/licenses.py self-test
limit 300 python3 scripts/licenses.py check
# Clippy lints the workspace while cargo builds the tests (clippy-driver as
# the workspace's rustc, warnings denied), instead of a separate
# `cargo clippy --all-targets`, which would check every dependency a second
# time: about seven minutes of CI's two cores. The targets `cargo test` does
# not build (the benches) are linted the same way, without running them.
clippy_driver=$(command -v clippy-driver || true)
if [ -n "$clippy_driver" ]; then
    step "cargo test, linted by clippy as it builds (-D warnings)"
    rustflags_before=${RUSTFLAGS-}
    export RUSTFLAGS="${RUSTFLAGS:+$RUSTFLAGS }-D warnings"
    # The first build is a cold one of every dependency too (about 13
    # minutes on two cores): its limit is the build's, not a bench's.
    RUSTC_WORKSPACE_WRAPPER="$clippy_driver" limit 1800 cargo test --workspace --benches --no-run
    RUSTC_WORKSPACE_WRAPPER="$clippy_driver" limit 2400 cargo test --workspace --no-fail-fast
    export RUSTFLAGS="$rustflags_before"
    [ -n "$RUSTFLAGS" ] || unset RUSTFLAGS
else
    step "cargo clippy (no clippy-driver on PATH: linted in a pass of its own)"
    limit 1800 cargo clippy --workspace --all-targets -- -D warnings
    step "cargo test"
    limit 2400 cargo test --workspace --no-fail-fast
fi

# --- 5. End-to-end tests against third-party peers ------------------------
# A release build: scenario replay runs whole simulated days through the
# Modbus stack, and a debug build would take most of CI's time doing it.
step "building the release binary for end-to-end tests"
limit 1500 cargo build --release -p gridscada
export GRIDSCADA_BIN="${CARGO_TARGET_DIR:-$root/target}/release/gridscada"
failed_e2e=()
# One end-to-end stage under its outer limit, its outcome recorded.
e2e_stage() {
    local t=$1 secs started
    step "end-to-end: $t"
    started=$(date +%s)
    case "$t" in *sparkplug_sites.sh) secs=600 ;; *sparkplug_*.sh) secs=300 ;; *notify.sh) secs=600 ;; *pair_browser.sh) secs=300 ;; *) secs=1200 ;; esac
    if limit "$secs" bash "$t"; then
        echo "end-to-end: $t passed in $(( $(date +%s) - started )) s"
    else
        echo "end-to-end: $t FAILED after $(( $(date +%s) - started )) s"
        failed_e2e+=("$t")
    fi
}
# The replay (whole simulated days, CPU-bound, about 12 minutes) runs in the
# background beside the stages that mostly wait on clocks and peers: its
# outcomes do not depend on the machine's load, because the virtual clock
# advances only when every task is idle. The browser tests, which use both
# cores themselves, run after it.
replay_log="$root/tests/e2e/artifacts/replay-stage.log"
mkdir -p "$(dirname "$replay_log")"
step "end-to-end: tests/e2e/replay.sh (in the background; its output is shown when it ends)"
replay_started=$(date +%s)
limit 2400 bash tests/e2e/replay.sh >"$replay_log" 2>&1 &
replay_pid=$!
browser_stages=()
for t in tests/e2e/*.sh; do
    [ -e "$t" ] || continue
    case "$t" in
        *replay.sh) continue ;;
        *browser.sh) browser_stages+=("$t"); continue ;;
    esac
    e2e_stage "$t"
done
step "end-to-end: waiting for tests/e2e/replay.sh"
replay_rc=0
wait "$replay_pid" || replay_rc=$?
cat "$replay_log"
if [ "$replay_rc" -eq 0 ]; then
    echo "end-to-end: tests/e2e/replay.sh passed in $(( $(date +%s) - replay_started )) s"
else
    echo "end-to-end: tests/e2e/replay.sh FAILED after $(( $(date +%s) - replay_started )) s"
    failed_e2e+=(tests/e2e/replay.sh)
fi
for t in "${browser_stages[@]}"; do
    e2e_stage "$t"
done
if [ ${#failed_e2e[@]} -gt 0 ]; then
    echo "end-to-end failures: ${failed_e2e[*]} (after $(( ($(date +%s) - run_started) / 60 )) min)"
    exit 1
fi

step "all tests passed in $(( ($(date +%s) - run_started) / 60 )) min"

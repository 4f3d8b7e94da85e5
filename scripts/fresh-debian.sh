#!/usr/bin/env bash
# The README's test command on a fresh Debian whose own PostgreSQL runs.
#
#     sudo bash scripts/fresh-debian.sh               # the whole of scripts/test-all.sh
#     sudo bash scripts/fresh-debian.sh --setup-only  # its stages 1-3 only
#     options: --dir DIR (default /var/tmp/gridscada-fresh), --reuse (keep an
#     existing chroot there instead of making a new one), --command CMD (run
#     CMD in /src/gridscada instead of test-all, e.g. one end-to-end test)
#
# 1. debootstrap makes a Debian of this machine's release in DIR/root, from
#    the mirror this machine's apt uses; its apt gets this machine's sources.
# 2. Nothing else is put in it but what the README asks for: the Rust
#    toolchain (this machine's rustup folder, mounted read-only, and its
#    proxies in /root/.cargo/bin), and a `git clone` of this repository's
#    committed HEAD in /src/gridscada (uncommitted changes are not tested).
# 3. In a network, PID and mount namespace of its own (its 127.0.0.1:5432
#    is not this machine's; everything started in it ends with it), it
#    installs Debian's `postgresql`, whose own cluster then runs on 5432 as
#    after `apt-get install postgresql` (scram passwords over TCP, peer auth
#    on its socket), and runs `bash scripts/test-all.sh` as root.
#    The namespace has no route out: apt, pip, cargo and npm reach the package
#    registries through scripts/fresh-debian-proxy.py (an HTTP proxy on this
#    machine, reached over a Unix socket).
# Needs root (debootstrap, chroot, namespaces). Exit status: test-all's.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
dir=/var/tmp/gridscada-fresh
reuse=""
command=""
test_args=()
while [ $# -gt 0 ]; do
    case "$1" in
        --setup-only) test_args=(--setup-only) ;;
        --reuse) reuse=1 ;;
        --command) command=$2; shift ;;
        --dir) dir=$2; shift ;;
        *) sed -n '2,8p' "$0" >&2; exit 2 ;;
    esac
    shift
done
log() { echo "fresh-debian: $*" >&2; }
[ "$(id -u)" -eq 0 ] || { log "needs root (debootstrap, chroot, namespaces)"; exit 1; }
root="$dir/root"

# --- 1. the chroot ---------------------------------------------------------------
suite=$(. /etc/os-release && echo "$VERSION_CODENAME")
# The first Debian archive this machine's apt uses (not its security archive).
mirror=$(cat /etc/apt/sources.list /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list 2>/dev/null \
    | grep -oE 'https?://[^ ]+' | grep -v -e security -e snapshot | head -n 1 || true)
mirror=${mirror:-http://deb.debian.org/debian}
if [ -n "$reuse" ] && [ -x "$root/bin/bash" ]; then
    log "reusing the chroot in $root"
else
    command -v debootstrap >/dev/null 2>&1 || {
        log "installing debootstrap"
        timeout 900 apt-get install -y -qq debootstrap >/dev/null
    }
    rm -rf "$root"
    mkdir -p "$root"
    log "debootstrap $suite from $mirror into $root"
    timeout 1800 debootstrap "$suite" "$root" "$mirror" >"$dir/debootstrap.log" 2>&1 \
        || { tail -n 20 "$dir/debootstrap.log"; log "debootstrap failed"; exit 1; }
fi
# This machine's apt sources (its security and updates archives too).
if ls /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list >/dev/null 2>&1; then
    rm -f "$root/etc/apt/sources.list"
    cp /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list "$root/etc/apt/sources.list.d/" 2>/dev/null || true
fi
[ -f /etc/apt/sources.list ] && cp /etc/apt/sources.list "$root/etc/apt/sources.list"

# The Rust toolchain, as the README asks for it (rustup's servers are not
# reachable from here: this machine's toolchains, read-only).
rustup_home=${RUSTUP_HOME:-$HOME/.rustup}
rustup_bin=$(command -v rustup || true)
[ -n "$rustup_bin" ] && [ -d "$rustup_home/toolchains" ] \
    || { log "no rustup toolchain on this machine to give the chroot"; exit 1; }
mkdir -p "$root/root/.rustup" "$root/root/.cargo/bin"
cp "$rustup_bin" "$root/root/.cargo/bin/rustup"
for p in cargo rustc rustdoc rustfmt cargo-fmt cargo-clippy clippy-driver; do
    ln -sf rustup "$root/root/.cargo/bin/$p"
done

# The trust store this machine's environment points its tools to
# (SSL_CERT_FILE, PIP_CERT, NODE_EXTRA_CA_CERTS...: on a network whose TLS
# is inspected, it holds that network's CA), given to the chroot's tools under
# the same variable names, so that they reach the registries as this
# machine's do. Nothing else of this machine's environment goes in.
ca_vars=()
mkdir -p "$root/etc/ssl"
for v in SSL_CERT_FILE CURL_CA_BUNDLE PIP_CERT REQUESTS_CA_BUNDLE NODE_EXTRA_CA_CERTS GIT_SSL_CAINFO CARGO_HTTP_CAINFO; do
    f=${!v:-}
    if [ -n "$f" ] && [ -f "$f" ]; then
        cp "$f" "$root/etc/ssl/host-trust-$v.crt"
        ca_vars+=("$v=/etc/ssl/host-trust-$v.crt")
    fi
done
if [ -n "${SSL_CERT_FILE:-}" ] && [ -z "${CARGO_HTTP_CAINFO:-}" ] && [ -f "$SSL_CERT_FILE" ]; then
    ca_vars+=("CARGO_HTTP_CAINFO=/etc/ssl/host-trust-SSL_CERT_FILE.crt")
fi
[ ${#ca_vars[@]} -eq 0 ] || log "the chroot's tools trust what this machine's do: ${ca_vars[*]}"

# The repository, as committed.
rm -rf "$root/src/gridscada"
mkdir -p "$root/src"
git clone --quiet "$repo" "$root/src/gridscada"
log "cloned $(git -C "$repo" rev-parse --short HEAD) ($(git -C "$repo" rev-parse --abbrev-ref HEAD)) into /src/gridscada"

# --- 2. the registries' proxy ------------------------------------------------------
sock="$dir/proxy.sock"
rm -f "$sock"
/usr/bin/python3 "$repo/scripts/fresh-debian-proxy.py" serve "$sock" 2>"$dir/proxy.log" &
proxy_pid=$!
trap 'kill "$proxy_pid" 2>/dev/null || true' EXIT
for _ in $(seq 1 50); do [ -S "$sock" ] && break; sleep 0.1; done
[ -S "$sock" ] || { log "the proxy did not start ($dir/proxy.log)"; exit 1; }

# --- 3. in its own namespaces ----------------------------------------------------
# What runs inside the chroot: Debian's PostgreSQL, running, then the tests.
inner_chroot=$(cat <<'EOF'
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
echo "fresh-debian: installing Debian's postgresql in the chroot" >&2
timeout 600 apt-get update -qq --error-on=any
timeout 1200 apt-get install -y -qq postgresql >/dev/null
# The package made its cluster; start it as its init script would.
v=$(ls /usr/lib/postgresql | sort -V | tail -n 1)
pg_ctlcluster "$v" main start 2>/dev/null || true
pg_lsclusters >&2
pg_lsclusters -h | awk '$3 == 5432 && $4 == "online" { ok = 1 } END { exit !ok }' \
    || { echo "fresh-debian: Debian's cluster is not online on 5432" >&2; exit 1; }
grep -E '^(host|local)' /etc/postgresql/"$v"/main/pg_hba.conf >&2
cd /src/gridscada
if [ -n "${FRESH_DEBIAN_COMMAND:-}" ]; then
    echo "fresh-debian: $FRESH_DEBIAN_COMMAND" >&2
    exec bash -c "$FRESH_DEBIAN_COMMAND"
fi
echo "fresh-debian: bash scripts/test-all.sh $*" >&2
bash scripts/test-all.sh "$@"
EOF
)
inner_ns=$(cat <<'EOF'
set -euo pipefail
root=$1 sock=$2 proxy=$3 rustup_home=$4; shift 4
read -r -a ca_vars <<<"$CA_VARS"
ip link set lo up
mount -t proc proc "$root/proc"
mount --rbind /sys "$root/sys"
mount --rbind /dev "$root/dev"
mount -t tmpfs tmpfs "$root/dev/shm"
mount -t tmpfs tmpfs "$root/run"
mount -t tmpfs tmpfs "$root/tmp"
chmod 1777 "$root/tmp"
mount --bind "$rustup_home" "$root/root/.rustup"
mount -o remount,bind,ro "$root/root/.rustup"
/usr/bin/python3 "$proxy" bridge 3128 "$sock" &
for _ in $(seq 1 50); do (exec 3<>/dev/tcp/127.0.0.1/3128) 2>/dev/null && break; sleep 0.1; done
p=http://127.0.0.1:3128
# All of loopback, not only 127.0.0.1: the tests' second servers listen on
# 127.0.0.2 and up, and a request for them sent to the proxy gets its 502.
# curl (>= 7.86) and Python's requests read the range; test-all.sh adds the
# addresses one by one for Python's urllib and websockets.
no=127.0.0.0/8,localhost,::1
exec chroot "$root" /usr/bin/env -i HOME=/root TERM=dumb LANG=C.UTF-8 CI=true \
    PATH=/root/.cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    http_proxy=$p https_proxy=$p HTTP_PROXY=$p HTTPS_PROXY=$p no_proxy=$no NO_PROXY=$no "${ca_vars[@]}" FRESH_DEBIAN_COMMAND="$FRESH_DEBIAN_COMMAND" \
    bash -c "$INNER_CHROOT" fresh-debian "$@"
EOF
)
log "running in the chroot's own namespaces: ${command:-bash scripts/test-all.sh ${test_args[*]}}"
rc=0
FRESH_DEBIAN_COMMAND=$command CA_VARS="${ca_vars[*]}" INNER_CHROOT=$inner_chroot unshare --net --pid --mount --fork --propagation private \
    bash -c "$inner_ns" fresh-debian-ns "$root" "$sock" "$repo/scripts/fresh-debian-proxy.py" "$rustup_home" \
    "${test_args[@]}" || rc=$?
log "finished with exit status $rc (the chroot stays in $root; --reuse runs in it again)"
exit "$rc"

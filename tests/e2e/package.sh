#!/usr/bin/env bash
# The Debian package, end to end, on this machine (needs root, or sudo):
#
# - builds the .deb with cargo-deb from the release binary already built
#   (GRIDSCADA_BIN; nothing is recompiled), installs it with `dpkg -i`;
# - checks what landed: binary, unit (and `systemd-analyze verify`, and its
#   LimitNOFILE), the starter configuration as conffiles readable by the
#   group gridscada only (root:gridscada 0640), the system user `gridscada`,
#   the data folder /var/lib/gridscada owned by it with mode 0700, the docs
#   with the licence, NOTICE and the third-party licence list;
# - the first-start story of docs/INSTALL.md: `gridscada check` of the
#   installed configuration and `gridscada user add` for the first
#   administrator, both as the package's user;
# - runs the unit's ExecStart command line, read from the installed unit, by
#   hand as the package's user with the unit's groups, no capabilities and
#   no new privileges and the unit's open-file limit (systemd is not PID 1
#   in containers and CI; where it is, `systemctl start gridscada` runs the
#   real unit instead), with
#   /etc/gridscada/gridscada.env as its EnvironmentFile; /healthz answers,
#   the first administrator logs in, and the database lands in
#   /var/lib/gridscada owned by the user;
# - reinstalls over it (an upgrade: the data, a local edit of the conffile
#   and its group are kept), writes a self-signed certificate into
#   /etc/gridscada as docs/DEPLOYMENT.md shows, then `dpkg --purge`s it and
#   checks that nothing is left but a file of the administrator's own, as
#   docs/INSTALL.md says.
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$(pwd)

bin="${GRIDSCADA_BIN:-$root/target/release/gridscada}"
unit=/usr/lib/systemd/system/gridscada.service
conf=/etc/gridscada/gridscada.toml
data=/var/lib/gridscada
envfile=/etc/gridscada/gridscada.env

fail() { echo "package: FAIL: $*" >&2; exit 1; }
log() { echo "package: $*"; }
sudo_cmd=()
[ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo -n)
as_root() { "${sudo_cmd[@]}" "$@"; }
[ "$(id -u)" -eq 0 ] || sudo -n true 2>/dev/null \
    || fail "installing a package needs root or password-less sudo"

# cargo-deb finds the binary at target/release/gridscada of the target folder.
case "$bin" in
    */release/gridscada) export CARGO_TARGET_DIR="${bin%/release/gridscada}" ;;
    *) fail "GRIDSCADA_BIN=$bin is not a cargo release build (…/release/gridscada)" ;;
esac
[ -x "$bin" ] || fail "no release binary at $bin (cargo build --release -p gridscada)"
if ! command -v cargo-deb >/dev/null 2>&1; then
    log "installing cargo-deb"
    timeout 900 cargo install --locked --quiet cargo-deb || fail "could not install cargo-deb"
fi

# A package left by an earlier, interrupted run is purged first.
if dpkg-query -W -f='${Status}' gridscada 2>/dev/null | grep -q 'ok installed\|config-files'; then
    log "purging a gridscada package left installed by an earlier run"
    as_root dpkg --purge gridscada >/dev/null
fi

tmp=$(mktemp -d)
chmod 755 "$tmp"
server_pid=""
installed=""
own=""
cleanup() {
    if [ -n "$server_pid" ] && [ -n "${use_systemd:-}" ]; then
        as_root systemctl stop gridscada || true
    elif [ -n "$server_pid" ]; then
        as_root kill "$server_pid" 2>/dev/null || true
        wait "$server_pid" 2>/dev/null || true
    fi
    [ -n "$installed" ] && as_root dpkg --purge gridscada >/dev/null 2>&1 || true
    # What this test put in /etc/gridscada itself, should a check have failed.
    if [ -n "$own" ]; then
        as_root rm -f "$own" /etc/gridscada/cert.pem /etc/gridscada/key.pem
        as_root rmdir /etc/gridscada 2>/dev/null || true
    fi
    [ -n "${KEEP_TMP:-}" ] && echo "kept $tmp" || rm -rf "$tmp"
}
trap cleanup EXIT

# --- build ----------------------------------------------------------------
log "building the package from $bin"
cargo deb -p gridscada --no-build --strip --quiet -o "$tmp/" >"$tmp/deb.log" 2>&1 \
    || { cat "$tmp/deb.log"; fail "cargo deb failed"; }
deb=$(ls "$tmp"/gridscada_*.deb)
log "built $(basename "$deb"), $(( $(stat -c %s "$deb") / 1024 / 1024 )) MiB"

# --- install --------------------------------------------------------------
as_root env DEBIAN_FRONTEND=noninteractive dpkg -i "$deb" >"$tmp/dpkg.log" 2>&1 \
    || { cat "$tmp/dpkg.log"; fail "dpkg -i failed"; }
installed=1
[ -x /usr/bin/gridscada ] || fail "/usr/bin/gridscada missing"
[ -f "$unit" ] || fail "$unit missing"
for doc in INSTALL.md LICENSE NOTICE THIRD-PARTY-LICENSES.md; do
    [ -f "/usr/share/doc/gridscada/$doc" ] || fail "$doc not in /usr/share/doc/gridscada"
done
dpkg-query -W -f='${Conffiles}\n' gridscada | grep -q " $conf " \
    || fail "$conf is not a conffile"
getent passwd gridscada >/dev/null || fail "no system user gridscada"
data_mode_is_private() {
    [ "$(stat -c '%U:%G %a' "$data")" = "gridscada:gridscada 700" ] \
        || fail "$data is $(stat -c '%U:%G %a' "$data") $1, not gridscada:gridscada 700"
}
data_mode_is_private "after the install"
# The configuration may hold a metrics_token: the service's group only.
conf_modes_are_private() {
    for f in "$conf" /etc/gridscada/plant.toml; do
        [ "$(stat -c '%U:%G %a' "$f")" = "root:gridscada 640" ] \
            || fail "$f is $(stat -c '%U:%G %a' "$f") $1, not root:gridscada 640"
    done
}
conf_modes_are_private "after the install"
# Enabled as Debian does it (a wants symlink, also where systemd is not running).
[ -L /etc/systemd/system/multi-user.target.wants/gridscada.service ] \
    || fail "the unit is not enabled"
nofile=$(sed -n 's/^LimitNOFILE=//p' "$unit")
[ "$nofile" = 65536 ] || fail "the unit's LimitNOFILE is '${nofile}', not 65536"
server_nofile_want=$nofile
log "installed: binary, unit (enabled, LimitNOFILE=$nofile), conffiles root:gridscada 0640, user gridscada, $data 0700"
# postinst starts the service where systemd runs: stopped until configured.
if [ -d /run/systemd/system ]; then as_root systemctl stop gridscada || true; fi

if command -v systemd-analyze >/dev/null 2>&1; then
    systemd-analyze verify "$unit" >"$tmp/verify.log" 2>&1 \
        || { cat "$tmp/verify.log"; fail "systemd-analyze verify $unit"; }
    log "systemd-analyze verify: ok"
else
    log "systemd-analyze not installed: unit not verified"
fi

# What the unit runs, and as whom: the process below gets the same.
exec_start=$(sed -n 's/^ExecStart=//p' "$unit")
[ "$exec_start" = "/usr/bin/gridscada serve --config $conf --data $data" ] \
    || fail "unexpected ExecStart: $exec_start"
groups=$(sed -n 's/^SupplementaryGroups=//p' "$unit")
as_pkg_user() {
    as_root setpriv --reuid=gridscada --regid=gridscada --groups="${groups:-gridscada}" \
        --inh-caps=-all --bounding-set=-all --no-new-privs \
        env -i PATH=/usr/bin:/bin HOME="$data" "$@"
}

# --- first start, as docs/INSTALL.md tells it --------------------------------
as_pkg_user /usr/bin/gridscada check --config "$conf" >"$tmp/check.log" 2>&1 \
    || { cat "$tmp/check.log"; fail "gridscada check $conf"; }
log "gridscada check --config: $(tail -n 1 "$tmp/check.log")"
password="first-admin-$RANDOM-$RANDOM"
printf '%s\n' "$password" | as_pkg_user /usr/bin/gridscada user add admin \
    --role administrator --config "$conf" >"$tmp/user.log" 2>&1 \
    || { cat "$tmp/user.log"; fail "gridscada user add"; }
log "first administrator added: $(tail -n 1 "$tmp/user.log")"

# The port comes from the EnvironmentFile, as a site would set it.
port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
base="http://127.0.0.1:$port"
printf 'GRIDSCADA_HTTP=127.0.0.1:%s\n' "$port" | as_root tee "$envfile" >/dev/null
as_root chmod 600 "$envfile"
# Where systemd runs (a real machine), the service itself is started, with
# all of the unit's hardening; elsewhere (containers, CI) its command line.
use_systemd=""
if [ -d /run/systemd/system ] && command -v systemctl >/dev/null 2>&1; then
    use_systemd=1
fi
start_server() {
    if [ -n "$use_systemd" ]; then
        as_root systemctl restart gridscada
        for _ in $(seq 1 150); do
            curl -fsS "$base/healthz" >"$tmp/healthz" 2>/dev/null && {
                server_pid=$(systemctl show -p MainPID --value gridscada)
                return 0
            }
            sleep 0.2
        done
        as_root journalctl -u gridscada -n 30 --no-pager || true
        fail "the gridscada service did not answer on $base/healthz"
    fi
    # The unit's open-file limit; a container's own hard limit may be lower,
    # and raising it needs a capability the container does not give.
    if [ "$(ulimit -Hn)" != unlimited ] && [ "$(ulimit -Hn)" -lt "$nofile" ]; then
        server_nofile_want=$(ulimit -Hn)
        log "this machine's hard limit on open files is $server_nofile_want: serve gets that, not the unit's $nofile"
    fi
    # systemd reads the EnvironmentFile as root; the service gets the values.
    local -a env_args
    mapfile -t env_args < <(as_root grep -E '^[A-Z_]+=' "$envfile")
    # exec: the pid is the server's (sudo passes signals on), so kill stops it.
    ( cd "$data" && exec "${sudo_cmd[@]}" prlimit --nofile="$server_nofile_want:$server_nofile_want" setpriv --reuid=gridscada --regid=gridscada --groups="${groups:-gridscada}" \
        --inh-caps=-all --bounding-set=-all --no-new-privs \
        env -i PATH=/usr/bin:/bin "${env_args[@]}" $exec_start ) >"$tmp/serve.log" 2>&1 &
    server_pid=$!
    for _ in $(seq 1 150); do
        curl -fsS "$base/healthz" >"$tmp/healthz" 2>/dev/null && return 0
        kill -0 "$server_pid" 2>/dev/null || { tail -n 30 "$tmp/serve.log"; fail "gridscada serve exited"; }
        sleep 0.2
    done
    tail -n 30 "$tmp/serve.log"
    fail "gridscada serve did not answer on $base/healthz"
}
stop_server() {
    if [ -n "$use_systemd" ]; then
        as_root systemctl stop gridscada
        server_pid=""
        return
    fi
    as_root kill -TERM "$server_pid"
    wait "$server_pid" 2>/dev/null || true
    server_pid=""
}
start_server
log "serve (${use_systemd:+the service, }as the unit's ExecStart, user gridscada): /healthz $(head -c 200 "$tmp/healthz")"

body="$(python3 -c 'import json,sys; print(json.dumps({"username": "admin", "password": sys.argv[1]}))' "$password")"
status=$(curl -sS -o /dev/null -w '%{http_code}' -H 'Content-Type: application/json' \
    -H "Origin: $base" -d "$body" "$base/api/session")
[ "$status" = 200 ] || fail "the first administrator could not log in (HTTP $status)"
log "the first administrator logs in"

[ -f "$data/gridscada.db" ] || fail "no database in $data"
stray=$(as_root find "$data" ! -user gridscada)
[ -z "$stray" ] || fail "files in $data not owned by gridscada: $stray"
listener=$(ss -ltnpH "sport = :$port" | grep -o 'pid=[0-9]*' | head -n 1 | cut -d= -f2)
server_user=$(ps -o user= -p "${listener:-0}" | tr -d ' ')
[ "$server_user" = gridscada ] || fail "serve runs as '$server_user', not gridscada"
server_nofile=$(as_root awk '/^Max open files/ {print $4 ":" $5}' "/proc/$listener/limits")
[ "$server_nofile" = "$server_nofile_want:$server_nofile_want" ] \
    || fail "serve may open $server_nofile files, not $server_nofile_want"
data_mode_is_private "after the server ran"
log "data in $data, owned by gridscada: $(as_root ls "$data" | tr '\n' ' ')"
stop_server

# --- upgrade: reinstall over it ----------------------------------------------
echo "# edited on site" | as_root tee -a "$conf" >/dev/null
as_root env DEBIAN_FRONTEND=noninteractive dpkg -i --force-confold "$deb" >"$tmp/dpkg2.log" 2>&1 \
    || { cat "$tmp/dpkg2.log"; fail "reinstalling over the installed package failed"; }
grep -q '^# edited on site' "$conf" || fail "the upgrade overwrote the edited $conf"
conf_modes_are_private "after the upgrade"
[ -f "$data/gridscada.db" ] || fail "the upgrade lost $data/gridscada.db"
start_server
status=$(curl -sS -o /dev/null -w '%{http_code}' -H 'Content-Type: application/json' \
    -H "Origin: $base" -d "$body" "$base/api/session")
[ "$status" = 200 ] || fail "after the upgrade the administrator could not log in (HTTP $status)"
stop_server
log "upgrade: the edited configuration, the database and the administrator are kept"

# --- purge ------------------------------------------------------------------
# A first HTTPS certificate as docs/DEPLOYMENT.md makes it, and a file of the
# administrator's own, which the purge must keep and name.
as_root /usr/bin/gridscada cert self-signed --config "$conf" >"$tmp/cert.log" 2>&1 \
    || { cat "$tmp/cert.log"; fail "gridscada cert self-signed --config $conf"; }
[ -f /etc/gridscada/key.pem ] || fail "cert self-signed wrote no /etc/gridscada/key.pem"
own=/etc/gridscada/site-ca.pem
echo "# the site's own CA" | as_root tee "$own" >/dev/null
as_root dpkg --purge gridscada >"$tmp/purge.log" 2>&1 || { cat "$tmp/purge.log"; fail "dpkg --purge failed"; }
installed=""
left=()
for p in /usr/bin/gridscada "$unit" "$data" /usr/share/doc/gridscada \
    /etc/systemd/system/multi-user.target.wants/gridscada.service; do
    [ -e "$p" ] || [ -L "$p" ] && left+=("$p")
done
[ ${#left[@]} -eq 0 ] || fail "left after dpkg --purge: ${left[*]}"
kept=$(as_root ls -A /etc/gridscada | tr '\n' ' ')
[ "$kept" = "site-ca.pem " ] || fail "after dpkg --purge /etc/gridscada holds '$kept', not only the administrator's site-ca.pem"
grep -q "kept /etc/gridscada, which holds files the package did not make: site-ca.pem" "$tmp/purge.log" \
    || { cat "$tmp/purge.log"; fail "the purge did not name the file it kept"; }
as_root rm -r /etc/gridscada
dpkg-query -W gridscada >/dev/null 2>&1 && fail "dpkg still knows the package after --purge"
log "purged: nothing left but the administrator's own file in /etc/gridscada (named) and the system user gridscada (kept, as Debian does)"
log "passed"

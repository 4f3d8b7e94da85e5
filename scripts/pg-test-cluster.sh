#!/usr/bin/env bash
# Provides a PostgreSQL server for the gridscada-store tests and prints the URL
# to use, as a shell line on stdout (everything else goes to stderr):
#
#     eval "$(scripts/pg-test-cluster.sh)"      # sets GRIDSCADA_TEST_PG_URL
#     GRIDSCADA_REQUIRE_PG=1 cargo test -p gridscada-store
#
# - If nothing listens on 127.0.0.1:5432: installs PostgreSQL from Debian when it
#   is missing (apt-get, non-interactive; needs root), creates a throwaway
#   cluster in a temporary folder with initdb as the `postgres` system user
#   (initdb refuses root), trust authentication on 127.0.0.1 only, starts it on
#   127.0.0.1:5432 with pg_ctl, and creates the database `gridscada_test`.
#   The cluster lives until the machine goes away or `pg_ctl -D DIR stop`
#   (DIR is printed on stderr).
# - If something already listens on 5432: uses it with the credentials of the
#   environment, by default user `postgres`, password `postgres`
#   (override with PGUSER / PGPASSWORD), and creates `gridscada_test` there if it
#   does not exist. The tests then work in a fresh schema per test, so they do
#   not touch anything else in that database.
set -euo pipefail

HOST=127.0.0.1
PORT=5432
DB=gridscada_test

log() { echo "pg-test-cluster: $*" >&2; }

listening() {
    (exec 3<>"/dev/tcp/$HOST/$PORT") 2>/dev/null
}

find_bindir() {
    if command -v pg_config >/dev/null 2>&1 && [ -x "$(pg_config --bindir)/initdb" ]; then
        pg_config --bindir
        return
    fi
    # Debian keeps the server binaries out of PATH, one folder per major version.
    local d
    d=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1 || true)
    if [ -n "$d" ] && [ -x "$d/initdb" ]; then
        echo "$d"
    fi
}

if listening; then
    PGUSER=${PGUSER:-postgres}
    PGPASSWORD=${PGPASSWORD:-postgres}
    export PGPASSWORD
    log "something already listens on $HOST:$PORT; using it as user '$PGUSER'"
    BASE="postgres://$PGUSER:$PGPASSWORD@$HOST:$PORT"
    if command -v psql >/dev/null 2>&1; then
        if ! psql "$BASE/postgres" -tAc "SELECT 1 FROM pg_database WHERE datname = '$DB'" | grep -q 1; then
            psql "$BASE/postgres" -qc "CREATE DATABASE $DB" >&2 \
                || { log "could not create database $DB (wrong credentials? set PGUSER/PGPASSWORD)"; exit 1; }
        fi
    else
        log "psql not found; assuming database $DB exists"
    fi
    echo "export GRIDSCADA_TEST_PG_URL=$BASE/$DB"
    exit 0
fi

BINDIR=$(find_bindir)
if [ -z "$BINDIR" ]; then
    log "PostgreSQL is not installed; installing it from Debian"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update >&2
    apt-get install -y postgresql >&2
    BINDIR=$(find_bindir)
    [ -n "$BINDIR" ] || { log "PostgreSQL installed but initdb not found"; exit 1; }
fi

# Installing the package may have created and started Debian's own cluster on
# 5432 (where an init system runs): our throwaway cluster then takes another port.
if listening; then
    PORT=55432
    log "5432 was taken during the install; the throwaway cluster uses port $PORT"
fi

# initdb and postgres refuse to run as root: run them as the `postgres` system
# user (created by the Debian package), or a dedicated user if it is missing.
RUNAS=postgres
if ! id "$RUNAS" >/dev/null 2>&1; then
    RUNAS=gridscada-pgtest
    id "$RUNAS" >/dev/null 2>&1 || useradd --system --no-create-home "$RUNAS"
fi
as_user() {
    if [ "$(id -u)" = 0 ]; then
        su -s /bin/sh "$RUNAS" -c "$*"
    else
        sh -c "$*"
    fi
}

DIR=$(mktemp -d /tmp/gridscada-pgtest.XXXXXX)
chmod 755 "$DIR"
[ "$(id -u)" = 0 ] && chown "$RUNAS" "$DIR"
log "creating a throwaway cluster in $DIR/data (binaries: $BINDIR)"
as_user "'$BINDIR/initdb' -D '$DIR/data' -U postgres --auth=trust -E UTF8 --no-locale" >&2
# Default durability settings (fsync on), so benchmark figures mean something.
as_user "'$BINDIR/pg_ctl' -D '$DIR/data' -l '$DIR/log' -w -t 60 start \
    -o \"-h $HOST -p $PORT -k '$DIR' -c max_connections=200\"" >&2
as_user "'$BINDIR/createdb' -h $HOST -p $PORT -U postgres $DB" >&2
log "started; stop with: su -s /bin/sh $RUNAS -c \"$BINDIR/pg_ctl -D $DIR/data stop\""
echo "export GRIDSCADA_TEST_PG_URL=postgres://postgres@$HOST:$PORT/$DB"
# How to stop it (and remove its folder), for the caller's exit trap.
if [ "$(id -u)" = 0 ]; then
    stop="su -s /bin/sh $RUNAS -c \"'$BINDIR/pg_ctl' -D '$DIR/data' -m fast stop\"; rm -rf '$DIR'"
else
    stop="'$BINDIR/pg_ctl' -D '$DIR/data' -m fast stop; rm -rf '$DIR'"
fi
printf 'export GRIDSCADA_TEST_PG_STOP=%q\n' "$stop"

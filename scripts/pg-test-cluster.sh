#!/usr/bin/env bash
# Provides a PostgreSQL server for the gridscada-store tests and prints the URL
# to use, as a shell line on stdout (everything else goes to stderr):
#
#     eval "$(scripts/pg-test-cluster.sh)"      # sets GRIDSCADA_TEST_PG_URL
#     GRIDSCADA_REQUIRE_PG=1 cargo test -p gridscada-store
#
# Installs PostgreSQL from Debian when it is missing (apt-get,
# non-interactive; needs root). Then, in this order, the first that works:
#
# 1. Something listens on 127.0.0.1:5432 and takes the credentials of the
#    environment, by default user `postgres`, password `postgres` (override
#    with PGUSER / PGPASSWORD): it is used, and `gridscada_test` created there
#    if it does not exist. (A throwaway trust cluster from an earlier run, or a
#    server set up for the tests.)
# 2. As root, with Debian's own cluster on 5432 (after `apt-get install
#    postgresql`: scram passwords over TCP, peer authentication on its
#    socket): over the socket as the `postgres` OS user, a role
#    `gridscada_test` with a generated password (kept in
#    /var/lib/postgresql/.gridscada-test-password, so later runs reuse it) and
#    its own database `gridscada_test`.
# 3. Otherwise a throwaway cluster: in a temporary folder, with initdb as the
#    `postgres` system user (initdb refuses root), trust authentication on
#    127.0.0.1 only, on 5432 or, when that is taken, the first free port from
#    55432; it also prints GRIDSCADA_TEST_PG_STOP, the command that stops it
#    and removes its folder (scripts/test-all.sh runs it at exit).
#
# The tests work in a fresh schema per test, so they do not touch anything
# else in the database. A line on stderr says which of the three was chosen.
set -euo pipefail

HOST=127.0.0.1
PORT=5432
DB=gridscada_test
TEST_ROLE=gridscada_test

log() { echo "pg-test-cluster: $*" >&2; }

listening() {
    (exec 3<>"/dev/tcp/$HOST/$1") 2>/dev/null
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

is_root() { [ "$(id -u)" = 0 ]; }

BINDIR=$(find_bindir)
if [ -z "$BINDIR" ] || ! command -v psql >/dev/null 2>&1; then
    is_root || { log "PostgreSQL is not installed, and installing it needs root: apt-get install postgresql"; exit 1; }
    log "PostgreSQL is not installed; installing it from Debian"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update >&2
    apt-get install -y postgresql >&2
    BINDIR=$(find_bindir)
    [ -n "$BINDIR" ] || { log "PostgreSQL installed but initdb not found"; exit 1; }
fi
# Never wait for a password prompt, nor long for a server that does not answer.
export PGCONNECT_TIMEOUT=10

# psql as the `postgres` OS user over the local socket of the cluster on PORT
# (peer authentication), with SQL on stdin.
psql_peer() {
    su -s /bin/sh postgres -c "cd / && psql -X -q -v ON_ERROR_STOP=1 -p $PORT -d postgres $*"
}

# --- 1. the server on 5432, with the given credentials ------------------------
if listening "$PORT"; then
    PGUSER=${PGUSER:-postgres}
    PGPASSWORD=${PGPASSWORD:-postgres}
    export PGPASSWORD
    BASE="postgres://$PGUSER:$PGPASSWORD@$HOST:$PORT"
    if psql -X -w "$BASE/postgres" -tAc 'SELECT 1' >/dev/null 2>&1; then
        log "using the server on $HOST:$PORT as user '$PGUSER' (given credentials)"
        if ! psql -X -w "$BASE/postgres" -tAc "SELECT 1 FROM pg_database WHERE datname = '$DB'" | grep -q 1; then
            psql -X -w "$BASE/postgres" -qc "CREATE DATABASE $DB" >&2 \
                || { log "could not create database $DB as '$PGUSER'"; exit 1; }
        fi
        echo "export GRIDSCADA_TEST_PG_URL=$BASE/$DB"
        exit 0
    fi
    log "the server on $HOST:$PORT refuses user '$PGUSER' with the given password (set PGUSER/PGPASSWORD to use it)"

    # --- 2. Debian's cluster: a test role, made over its socket ----------------
    if is_root && id postgres >/dev/null 2>&1 && psql_peer "-tAc 'SELECT 1'" </dev/null >/dev/null 2>&1; then
        pwfile=/var/lib/postgresql/.gridscada-test-password
        if [ ! -s "$pwfile" ]; then
            (umask 077; head -c 18 /dev/urandom | base64 | tr -d '/+=' >"$pwfile")
            chown postgres: "$pwfile"
        fi
        pw=$(cat "$pwfile")
        # The role's password is set again each run: the file is the truth.
        psql_peer >&2 <<SQL
SELECT format('CREATE ROLE %I LOGIN', '$TEST_ROLE')
    WHERE NOT EXISTS (SELECT 1 FROM pg_roles WHERE rolname = '$TEST_ROLE') \gexec
-- CREATEDB: some tests make a database of their own and drop it.
ALTER ROLE $TEST_ROLE LOGIN CREATEDB PASSWORD '$pw';
SELECT format('CREATE DATABASE %I OWNER %I', '$DB', '$TEST_ROLE')
    WHERE NOT EXISTS (SELECT 1 FROM pg_database WHERE datname = '$DB') \gexec
SQL
        URL="postgres://$TEST_ROLE:$pw@$HOST:$PORT/$DB"
        if psql -X -w "$URL" -tAc 'SELECT 1' >/dev/null 2>&1; then
            log "using the local cluster on $HOST:$PORT: role '$TEST_ROLE' made over its socket as the postgres OS user (password in $pwfile)"
            echo "export GRIDSCADA_TEST_PG_URL=$URL"
            exit 0
        fi
        log "role '$TEST_ROLE' made over the socket, but it cannot log in over TCP (pg_hba.conf?)"
    fi

    # --- 3. our own cluster, beside it ----------------------------------------
    PORT=55432
    while listening "$PORT"; do PORT=$((PORT + 1)); done
    log "5432 is taken by a server we cannot use: a throwaway cluster on port $PORT instead"
fi

# --- 3. a throwaway cluster ------------------------------------------------------
# initdb and postgres refuse to run as root: run them as the `postgres` system
# user (created by the Debian package), or a dedicated user if it is missing.
RUNAS=postgres
if ! id "$RUNAS" >/dev/null 2>&1; then
    RUNAS=gridscada-pgtest
    id "$RUNAS" >/dev/null 2>&1 || useradd --system --no-create-home "$RUNAS"
fi
as_user() {
    if is_root; then
        su -s /bin/sh "$RUNAS" -c "$*"
    else
        sh -c "$*"
    fi
}

DIR=$(mktemp -d /tmp/gridscada-pgtest.XXXXXX)
chmod 755 "$DIR"
if is_root; then chown "$RUNAS" "$DIR"; fi
log "creating a throwaway cluster in $DIR/data on $HOST:$PORT (binaries: $BINDIR)"
as_user "'$BINDIR/initdb' -D '$DIR/data' -U postgres --auth=trust -E UTF8 --no-locale" >&2
# Default durability settings (fsync on), so benchmark figures mean something.
as_user "'$BINDIR/pg_ctl' -D '$DIR/data' -l '$DIR/log' -w -t 60 start \
    -o \"-h $HOST -p $PORT -k '$DIR' -c max_connections=200\"" >&2
as_user "'$BINDIR/createdb' -h $HOST -p $PORT -U postgres $DB" >&2
log "started; stop with: su -s /bin/sh $RUNAS -c \"$BINDIR/pg_ctl -D $DIR/data stop\""
echo "export GRIDSCADA_TEST_PG_URL=postgres://postgres@$HOST:$PORT/$DB"
# How to stop it (and remove its folder), for the caller's exit trap.
if is_root; then
    stop="su -s /bin/sh $RUNAS -c \"'$BINDIR/pg_ctl' -D '$DIR/data' -m fast stop\"; rm -rf '$DIR'"
else
    stop="'$BINDIR/pg_ctl' -D '$DIR/data' -m fast stop; rm -rf '$DIR'"
fi
printf 'export GRIDSCADA_TEST_PG_STOP=%q\n' "$stop"

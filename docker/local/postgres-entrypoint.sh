#!/bin/bash
# The stand-in postgres:15's entrypoint (postgres.Dockerfile): a new $PGDATA is initialised with the official image's
# variables (POSTGRES_USER, default postgres; POSTGRES_PASSWORD, required unless POSTGRES_HOST_AUTH_METHOD=trust;
# POSTGRES_DB, default the user's name), then the server listens on every address of the container.
set -euo pipefail
user=${POSTGRES_USER:-postgres}
db=${POSTGRES_DB:-$user}
auth=${POSTGRES_HOST_AUTH_METHOD:-scram-sha-256}
if [ "${1:-postgres}" = postgres ]; then
    [ $# -gt 0 ] && shift
    if [ ! -s "$PGDATA/PG_VERSION" ]; then
        if [ -z "${POSTGRES_PASSWORD:-}" ] && [ "$auth" != trust ]; then
            echo "error: the database is uninitialized and POSTGRES_PASSWORD is not set" >&2
            exit 1
        fi
        pwfile=$(mktemp)
        printf '%s\n' "${POSTGRES_PASSWORD:-}" > "$pwfile"
        initdb -D "$PGDATA" -U "$user" --pwfile="$pwfile" --auth-local=trust --auth-host="$auth" \
            --encoding=UTF8 --locale=C.UTF-8 --no-instructions
        rm -f "$pwfile"
        echo "host all all all $auth" >> "$PGDATA/pg_hba.conf"
        if [ "$db" != postgres ]; then
            echo "CREATE DATABASE \"$db\" OWNER \"$user\"" | postgres --single -D "$PGDATA" -j postgres > /dev/null
        fi
    fi
    exec postgres -D "$PGDATA" -c listen_addresses='*' "$@"
fi
exec "$@"

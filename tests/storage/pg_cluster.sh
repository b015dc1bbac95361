#!/usr/bin/env bash
# A throw-away PostgreSQL cluster on loopback for the storage tests (CTest runs it as a fixture around them).
#   pg_cluster.sh start DIR   initdb + start on a free port; writes the server's URL to DIR/url
#   pg_cluster.sh stop DIR    stops it and removes its data
# Uses Debian's postgresql-15 (scripts/install-deps.sh installs it). As root, the server runs as user postgres
# (initdb refuses root). Durability is off (fsync) for the tests, which check the store, not the disk;
# SGLC_PG_DURABLE=1 keeps PostgreSQL's defaults (for measurements).
set -euo pipefail
cmd=${1:?start or stop}
dir=${2:?state directory}
bin=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1 || true)

as_server_user() {
  if [ "$(id -u)" -eq 0 ]; then runuser -u postgres -- "$@"; else "$@"; fi
}

stop() {
  if [ -f "$dir/data-dir" ]; then
    local data
    data=$(cat "$dir/data-dir")
    [ -f "$data/pgdata/postmaster.pid" ] && as_server_user "$bin/pg_ctl" -D "$data/pgdata" -m immediate -w stop >/dev/null 2>&1 || true
    rm -rf "$data"
  fi
  rm -rf "$dir"
}

case "$cmd" in
  start)
    if [ -z "$bin" ] || [ ! -x "$bin/initdb" ]; then
      echo "pg_cluster: PostgreSQL's server programs are missing (run scripts/install-deps.sh as root)" >&2
      exit 1
    fi
    stop
    mkdir -p "$dir"
    data=$(mktemp -d /tmp/sglc-pg-test-XXXXXX)  # /tmp: the postgres user can reach it
    echo "$data" >"$dir/data-dir"
    [ "$(id -u)" -eq 0 ] && chown postgres: "$data"
    as_server_user "$bin/initdb" -D "$data/pgdata" -U postgres --auth=trust -E UTF8 --no-sync >"$dir/initdb.log" 2>&1 \
      || { cat "$dir/initdb.log" >&2; exit 1; }
    durability="-c fsync=off -c full_page_writes=off"
    [ "${SGLC_PG_DURABLE:-0}" = 1 ] && durability=""
    for attempt in $(seq 1 20); do
      port=$((20000 + RANDOM % 20000))
      (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && continue  # taken
      if as_server_user "$bin/pg_ctl" -D "$data/pgdata" -l "$data/server.log" -w -t 60 \
        -o "-c listen_addresses=127.0.0.1 -p $port -k $data -c max_connections=300 $durability" \
        start >/dev/null 2>&1; then
        echo "postgresql://postgres@127.0.0.1:$port/postgres" >"$dir/url"
        echo "pg_cluster: PostgreSQL on 127.0.0.1:$port ($data)"
        exit 0
      fi
    done
    cat "$data/server.log" >&2 || true
    echo "pg_cluster: could not start PostgreSQL" >&2
    exit 1
    ;;
  stop) stop ;;
  *) echo "usage: $0 start|stop DIR" >&2; exit 2 ;;
esac

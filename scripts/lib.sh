# Shared by the scripts that run a terrane-server beside a load (run.sh,
# bots-scale.sh, horizon.sh, python-cost.sh). Source it from the repository
# root:
#   terrane_scratch NAME          a scratch directory in $scratch, removed on exit
#                                 (with the server, if one is running)
#   terrane_start_server LOG ARGS...
#                                 starts build/bin/terrane-server (or
#                                 $TERRANE_SERVER, another build's) ARGS (add
#                                 --port 0), waits until it listens, sets
#                                 $server_pid, $server_port and, with --metrics,
#                                 $metrics_port; exits 1 with the log if it
#                                 does not come up within 60 s
#   terrane_stop_server           SIGTERM and wait (its exit status is returned)
#   terrane_cpu_seconds PID       CPU time (user + system) a process used so far
#   terrane_peak_kib PID          its peak resident memory (VmHWM), KiB
#   terrane_start_postgres DIR    a PostgreSQL of its own: initdb in DIR (as the
#                                 postgres user when run as root), listening on
#                                 127.0.0.1 only; sets $pg_pid, $pg_port, $pgbin
#                                 and $pg_url (database postgres, user terrane)
#   terrane_stop_postgres         a fast shutdown of it, by the postmaster's pid

terrane_scratch() {
  scratch=$(mktemp -d "${TMPDIR:-/tmp}/terrane-$1.XXXXXX")
  server_pid=
  trap terrane_cleanup EXIT INT TERM
}

terrane_cleanup() {
  terrane_stop_server || true
  rm -rf "$scratch"
}

terrane_start_server() {
  local log=$1
  shift
  local wants_metrics=0 arg
  for arg in "$@"; do [ "$arg" = --metrics ] && wants_metrics=1; done
  "${TERRANE_SERVER:-./build/bin/terrane-server}" "$@" >"$log" 2>&1 &
  server_pid=$!
  server_port=
  metrics_port=
  for _ in $(seq 1 600); do
    server_port=$(sed -n 's/.*listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$log" | head -n 1)
    metrics_port=$(sed -n 's|.*metrics on http://127\.0\.0\.1:\([0-9]*\)/metrics.*|\1|p' "$log" | head -n 1)
    [ -n "$server_port" ] && { [ "$wants_metrics" = 0 ] || [ -n "$metrics_port" ]; } && return 0
    if ! kill -0 "$server_pid" 2>/dev/null; then
      echo "terrane-server exited before listening:" >&2
      cat "$log" >&2
      server_pid=
      exit 1
    fi
    sleep 0.1
  done
  echo "terrane-server did not report its port within 60 s:" >&2
  cat "$log" >&2
  exit 1
}

terrane_cpu_seconds() {
  awk -v t="$(getconf CLK_TCK)" '{printf "%.2f\n", ($14 + $15) / t}' "/proc/$1/stat"
}

terrane_peak_kib() {
  awk '/VmHWM/ {print $2}' "/proc/$1/status"
}

terrane_stop_server() {
  local status=0
  if [ -n "${server_pid:-}" ] && kill -0 "$server_pid" 2>/dev/null; then
    kill -TERM "$server_pid" 2>/dev/null || true
    wait "$server_pid" || status=$?
  fi
  server_pid=
  return $status
}

terrane_start_postgres() {
  local dir=$1 v as_pg=()
  pgbin=
  for v in 17 16 15 14 13; do
    [ -x "/usr/lib/postgresql/$v/bin/postgres" ] && { pgbin=/usr/lib/postgresql/$v/bin; break; }
  done
  [ -n "$pgbin" ] || { echo "PostgreSQL is not installed (scripts/install-deps.sh installs it)" >&2; exit 2; }
  mkdir -p "$dir"
  if [ "$(id -u)" = 0 ]; then
    chmod 755 "$(dirname "$dir")"  # postgres must reach its directory inside
    chown postgres: "$dir"
    as_pg=(runuser -u postgres --)
  fi
  "${as_pg[@]}" "$pgbin/initdb" -D "$dir/data" -U terrane --auth=trust --encoding=UTF8 >"$dir/../initdb.log" 2>&1 ||
    { cat "$dir/../initdb.log" >&2; exit 1; }
  pg_port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  "${as_pg[@]}" "$pgbin/postgres" -D "$dir/data" -p "$pg_port" -c listen_addresses=127.0.0.1 \
    -c unix_socket_directories="$dir" -c max_connections=200 >"$dir/../postgres.log" 2>&1 &
  pg_pid=$!
  for _ in $(seq 1 600); do
    grep -q "ready to accept connections" "$dir/../postgres.log" && break
    kill -0 "$pg_pid" 2>/dev/null || { cat "$dir/../postgres.log" >&2; exit 1; }
    sleep 0.1
  done
  pg_dir=$dir
  pg_url="postgresql://terrane@127.0.0.1:$pg_port/postgres"
}

terrane_stop_postgres() {
  [ -n "${pg_pid:-}" ] || return 0
  # The postmaster itself (as root, pg_pid is runuser's): a fast shutdown.
  kill -INT "$(head -n 1 "$pg_dir/data/postmaster.pid" 2>/dev/null || echo "$pg_pid")" 2>/dev/null || true
  wait "$pg_pid" 2>/dev/null || true
  pg_pid=
}

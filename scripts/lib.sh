# Shared by the scripts that run a terrane-server beside a load (run.sh,
# bots-scale.sh, horizon.sh, python-cost.sh). Source it from the repository
# root:
#   terrane_scratch NAME          a scratch directory in $scratch, removed on exit
#                                 (with the server, if one is running)
#   terrane_start_server LOG ARGS...
#                                 starts build/bin/terrane-server ARGS (add
#                                 --port 0), waits until it listens, sets
#                                 $server_pid, $server_port and, with --metrics,
#                                 $metrics_port; exits 1 with the log if it
#                                 does not come up within 60 s
#   terrane_stop_server           SIGTERM and wait (its exit status is returned)
#   terrane_cpu_seconds PID       CPU time (user + system) a process used so far
#   terrane_peak_kib PID          its peak resident memory (VmHWM), KiB

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
  ./build/bin/terrane-server "$@" >"$log" 2>&1 &
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

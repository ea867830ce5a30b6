#!/usr/bin/env bash
# One world over several servers on this machine, to try it: a PostgreSQL of
# its own (initdb in a scratch directory, as the postgres user when run as
# root, listening on 127.0.0.1 only, stopped by its pid), N terrane-servers
# on it (server ids 1..N, each with a metrics endpoint), and a terrane-bots
# run spread over them (bot i on server i mod N). Prints the bots' report,
# then per server its CPU, peak memory, what it forwarded, received and
# read again for the others and the clients it redirected away and in, then the database's figures (commits, bytes
# written per acknowledged edit).
#   scripts/cluster.sh [SERVERS] [BOTS] [REPORT.json] [extra terrane-bots flags...]
# Defaults: 2 servers, 20 bots over 512 x 512 voxels around the spawn (every
# bot sees every edit: half of each edit's receivers are on another server),
# view 512, full-resolution radius 64, a sphere edit of radius <= 3 every 2 s
# per bot, 60 s. TERRANE_WORLD=DIR starts from a copy of that SQLite world
# (terrane-world migrate; e.g. worlds/scale, see scripts/bots-scale.sh);
# otherwise the default world is generated as the servers need it.
# TERRANE_SERVER_FLAGS adds flags to every server. Expects a release build
# (scripts/build.sh release) and PostgreSQL (scripts/install-deps.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
servers=${1:-2}
bots=${2:-20}
report=${3:-reports/cluster-$servers-$bots.json}
shift $(( $# >= 3 ? 3 : $# ))
case "$servers$bots" in
  *[!0-9]*|'') echo "cluster.sh: SERVERS and BOTS are positive numbers (got '$servers', '$bots')" >&2; exit 2 ;;
esac
[ "$servers" -ge 1 ] && [ "$bots" -ge 1 ] || { echo "cluster.sh: SERVERS and BOTS are at least 1" >&2; exit 2; }
. scripts/lib.sh  # terrane_cpu_seconds, terrane_peak_kib, terrane_start_postgres
[ -x build/bin/terrane-server ] || { echo "cluster.sh: no build (scripts/build.sh release)" >&2; exit 2; }

scratch=$(mktemp -d "${TMPDIR:-/tmp}/terrane-cluster.XXXXXX")
pg_pid=
server_pids=()
cleanup() {
  for p in "${server_pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  for p in "${server_pids[@]}"; do wait "$p" 2>/dev/null || true; done
  terrane_stop_postgres
  rm -rf "$scratch"
}
trap cleanup EXIT INT TERM

terrane_start_postgres "$scratch/pg"
url=$pg_url
echo "PostgreSQL on 127.0.0.1:$pg_port (data in $scratch/pg)" >&2

if [ -n "${TERRANE_WORLD:-}" ]; then
  ./build/bin/terrane-world migrate --world "$TERRANE_WORLD" --to "$url" >&2
fi

ports=()
metrics=()
for i in $(seq 1 "$servers"); do
  log="$scratch/server-$i.log"
  # shellcheck disable=SC2086
  ./build/bin/terrane-server --store "$url" --server-id "$i" --port 0 --metrics 127.0.0.1:0 \
    --max-clients $((bots + 64)) ${TERRANE_SERVER_FLAGS:-} >"$log" 2>&1 &
  server_pids+=($!)
  port=
  for _ in $(seq 1 600); do
    port=$(sed -n 's/.*listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$log" | head -n 1)
    mport=$(sed -n 's|.*metrics on http://127\.0\.0\.1:\([0-9]*\)/metrics.*|\1|p' "$log" | head -n 1)
    [ -n "$port" ] && [ -n "$mport" ] && break
    kill -0 "${server_pids[-1]}" 2>/dev/null || { echo "server $i exited:" >&2; cat "$log" >&2; exit 1; }
    sleep 0.1
  done
  [ -n "$port" ] || { echo "server $i did not start:" >&2; cat "$log" >&2; exit 1; }
  ports+=("$port")
  metrics+=("$mport")
done
connect=$(printf '127.0.0.1:%s,' "${ports[@]}")
connect=${connect%,}
echo "servers: $connect" >&2

psql_value() {
  "$pgbin/psql" -h 127.0.0.1 -p "$pg_port" -U terrane -d postgres -Atc "$1" 2>/dev/null || echo 0
}
# A server's /metrics (bash's /dev/tcp: no HTTP client needed).
metrics_text() {
  local fd
  exec {fd}<>"/dev/tcp/127.0.0.1/$1" || return 0
  printf 'GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n' >&"$fd"
  cat <&"$fd"
  exec {fd}<&-
}
# One metric summed over the servers.
sum_metric() {
  local total=0 mp v
  for mp in "${metrics[@]}"; do
    v=$(metrics_text "$mp" | awk -v n="$1" '$1 == n {print $2}' | head -n 1 | cut -d. -f1)
    total=$(( total + ${v:-0} ))
  done
  echo "$total"
}
writes0=$(sum_metric terrane_commits_total)
cpu0=()
for p in "${server_pids[@]}"; do cpu0+=("$(terrane_cpu_seconds "$p")"); done
commits0=$(psql_value "SELECT xact_commit FROM pg_stat_database WHERE datname = 'postgres'")
bytes0=$(psql_value "SELECT pg_current_wal_lsn() - '0/0'::pg_lsn")
start=$(date +%s.%N)

mkdir -p "$(dirname "$report")"
status=0
timer=()
[ -x /usr/bin/time ] && timer=(/usr/bin/time -f "bots: peak RSS %M KiB; CPU %U s user + %S s sys over %e s wall")
"${timer[@]}" ./build/bin/terrane-bots --connect "$connect" --bots "$bots" --duration 60 --behavior mixed \
  --spread 512 --ramp-up 20 --view-distance 512 --full-res-radius 64 --edit-interval 2 --edit-radius 3 \
  --seed 1 --progress off --report "$report" "$@" || status=$?

end=$(date +%s.%N)
commits1=$(psql_value "SELECT xact_commit FROM pg_stat_database WHERE datname = 'postgres'")
bytes1=$(psql_value "SELECT pg_current_wal_lsn() - '0/0'::pg_lsn")
acked=$(sed -n 's/.*"edits_acked": \([0-9]*\).*/\1/p' "$report" | head -n 1)
writes=$(( $(sum_metric terrane_commits_total) - writes0 ))
for i in $(seq 1 "$servers"); do
  p=${server_pids[$((i - 1))]}
  cp "$scratch/server-$i.log" "${report%.json}.server-$i.log"
  if ! kill -0 "$p" 2>/dev/null; then
    echo "server $i: exited during the run (its log: ${report%.json}.server-$i.log)"
    status=1
    continue
  fi
  cpu1=$(terrane_cpu_seconds "$p")
  hwm=$(terrane_peak_kib "$p")
  m=$(metrics_text "${metrics[$((i - 1))]}" || true)
  metric() { echo "$m" | awk -v n="$1" '$1 == n {print $2}' | head -n 1; }
  awk -v i="$i" -v h="$hwm" -v c0="${cpu0[$((i - 1))]}" -v c1="$cpu1" -v s="$start" -v e="$end" \
    -v f="$(metric terrane_edits_forwarded_total)" -v r="$(metric terrane_forwarded_edits_received_total)" \
    -v x="$(metric terrane_chunks_changed_elsewhere_total)" -v fg="$(metric terrane_chunks_forgotten_elsewhere_total)" \
    -v up="$(metric terrane_chunks_updated_elsewhere_total)" \
    -v rs="$(metric terrane_redirects_sent_total)" \
    -v rr="$(metric terrane_redirects_received_total)" 'BEGIN {
    printf "server %d: peak RSS %.0f MiB; CPU %.1f s over %.1f s wall (%.0f%% of one core); edits forwarded %d, received %d; chunks the others changed %d (updated from their units: %d; forgotten, held by no client here: %d; the rest read again); clients redirected away %d, in %d\n",
           i, h / 1024, c1 - c0, e - s, 100 * (c1 - c0) / (e - s), f, r, x, up, fg, rs, rr }'
done
awk -v c0="$commits0" -v c1="$commits1" -v b0="$bytes0" -v b1="$bytes1" -v s="$start" -v e="$end" -v a="${acked:-0}" \
  -v w="$writes" 'BEGIN {
  printf "database: %.0f write commits/s (the servers'"'"' ticks), %.0f transactions/s in all (reads, leases, notices); WAL %.1f MB, %.0f bytes per acknowledged edit\n",
         w / (e - s), (c1 - c0) / (e - s), (b1 - b0) / 1e6, (a > 0 ? (b1 - b0) / a : 0) }'
exit $status

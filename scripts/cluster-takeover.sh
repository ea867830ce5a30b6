#!/usr/bin/env bash
# Takeover time after kill -9 of a region's server, in a world shared by two
# servers on a PostgreSQL of its own (scratch directory, 127.0.0.1 only,
# stopped by its pid). Each run, on a fresh database:
#   1. servers 1 and 2 start; a Python client of each joins at the spawn and
#      loads it; ann (server 1) fills a box there, so server 1 writes the
#      region, and the fill is acknowledged;
#   2. server 1 is killed with SIGKILL;
#   3. bob (server 2) fills another box in that region, again and again,
#      until one is accepted: server 2 has taken the region over (its lease
#      ran out, server 2 claimed it and read it again).
# Prints per run the time from the kill to that acceptance and the tries it
# took, checks that ann's acknowledged fill is in bob's replica, then the
# median.
#   scripts/cluster-takeover.sh [RUNS] [LEASE_MS]     (defaults 3, 5000)
# Expects a release build (scripts/build.sh release: terrane-server and the
# Python package in build/python) and PostgreSQL (scripts/install-deps.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-3}
lease_ms=${2:-5000}
case "$runs$lease_ms" in
  *[!0-9]*|'') echo "cluster-takeover.sh: RUNS and LEASE_MS are positive numbers (got '$runs', '$lease_ms')" >&2; exit 2 ;;
esac
[ "$runs" -ge 1 ] && [ "$lease_ms" -ge 500 ] ||
  { echo "cluster-takeover.sh: RUNS is at least 1 and LEASE_MS at least 500" >&2; exit 2; }
[ -x build/bin/terrane-server ] && [ -d build/python/terrane ] ||
  { echo "cluster-takeover.sh: no build (scripts/build.sh release)" >&2; exit 2; }
. scripts/lib.sh  # terrane_start_postgres

scratch=$(mktemp -d "${TMPDIR:-/tmp}/terrane-takeover.XXXXXX")
server_pids=()
# The servers are disowned (one of them is killed on purpose: no job
# notice), so a stop waits for them by their pids, at most 10 s each.
stop_servers() {
  local p
  for p in "${server_pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  for p in "${server_pids[@]}"; do
    for _ in $(seq 1 100); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$p" 2>/dev/null || true
  done
  server_pids=()
}
cleanup() {
  stop_servers
  terrane_stop_postgres
  rm -rf "$scratch"
}
trap cleanup EXIT INT TERM
terrane_start_postgres "$scratch/pg"
echo "PostgreSQL on 127.0.0.1:$pg_port" >&2

# Starts server ID on database DB; sets $port and appends its pid.
start_server() {
  local id=$1 db=$2 log="$scratch/server-$1-$2.log"
  ./build/bin/terrane-server --store "postgresql://terrane@127.0.0.1:$pg_port/$db" --server-id "$id" \
    --port 0 --lease-ms "$lease_ms" >"$log" 2>&1 &
  server_pids+=($!)
  disown "$!"
  port=
  for _ in $(seq 1 600); do
    port=$(sed -n 's/.*listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$log" | head -n 1)
    [ -n "$port" ] && return 0
    kill -0 "${server_pids[-1]}" 2>/dev/null || { echo "server $id exited:" >&2; cat "$log" >&2; exit 1; }
    sleep 0.1
  done
  echo "server $id did not start:" >&2
  cat "$log" >&2
  exit 1
}

times=()
for run in $(seq 1 "$runs"); do
  db="takeover_$run"
  "$pgbin/psql" -h 127.0.0.1 -p "$pg_port" -U terrane -d postgres -qAtc "CREATE DATABASE $db" >/dev/null
  start_server 1 "$db"
  port1=$port
  pid1=${server_pids[-1]}
  start_server 2 "$db"
  port2=$port
  line=$(PYTHONPATH=build/python /usr/bin/python3 - "$port1" "$port2" "$pid1" "$lease_ms" <<'EOF'
import os, signal, sys, time
import terrane

port1, port2, pid1, lease_ms = (int(a) for a in sys.argv[1:5])
with terrane.connect(f"127.0.0.1:{port1}", name="ann", view_distance=96, full_res_radius=32) as ann, \
     terrane.connect(f"127.0.0.1:{port2}", name="bob", view_distance=96, full_res_radius=32) as bob:
    ann.wait_loaded(timeout=120)
    bob.wait_loaded(timeout=120)
    x, y, z = (int(v) for v in ann.position)
    g = ann.ground(x, z)
    g = y if g is None else g
    box = ((x + 1, g, z + 1), (x + 4, g + 3, z + 4))
    assert ann.fill_box(*box, "Brick").result(timeout=60), "ann's fill was not acknowledged"
    os.kill(pid1, signal.SIGKILL)
    killed = time.monotonic()
    tries, accepted = 0, None
    deadline = killed + 10 * lease_ms / 1000 + 30
    while accepted is None and time.monotonic() < deadline:
        tries += 1
        try:
            # The box beside ann's, in the same region: bob's server must write it.
            if bob.fill_box((x + 1, g, z + 5), (x + 4, g + 3, z + 8), "Snow").result(timeout=60):
                accepted = time.monotonic()
        except terrane.EditRejected:
            pass
    if accepted is None:
        sys.exit(f"no edit of bob's was accepted within {deadline - killed:.0f} s of the kill")
    bob.sync()
    kept = all(bob.voxel((bx, by, bz))[0] == "Brick"
               for bx in range(box[0][0], box[1][0]) for by in range(box[0][1], box[1][1])
               for bz in range(box[0][2], box[1][2]))
    print(f"{accepted - killed:.2f} {tries} {'kept' if kept else 'LOST'}")
EOF
  ) || { echo "run $run failed; the servers' logs:" >&2; tail -n 20 "$scratch"/server-*-"$db".log >&2; exit 1; }
  read -r seconds tries kept <<<"$line"
  echo "run $run: accepted ${seconds} s after the kill (${tries} tries); ann's acknowledged fill ${kept}"
  [ "$kept" = kept ] || { echo "cluster-takeover.sh: an acknowledged edit was lost" >&2; exit 1; }
  times+=("$seconds")
  stop_servers
done
printf '%s\n' "${times[@]}" | sort -n | awk -v l="$lease_ms" '{t[NR] = $1} END {
  printf "takeover after kill -9, lease %d ms: median %.2f s of %d runs (%.2f to %.2f)\n", l, t[int((NR + 1) / 2)], NR, t[1], t[NR] }'

#!/usr/bin/env bash
# One run of a scale scenario (docs/load-testing.md; figures in docs/results.md). Server and bots share this
# machine; the server starts cold on a copy of a pre-generated world. crowd
# and world are terrane-bots' presets of those names (client/bots/presets.cpp
# holds their values; terrane-bots --list-presets shows them); join and wave
# are world with overrides. Both: mixed bots, full-resolution radius 64,
# view distance 512, a sphere edit of radius <= 3 every 2 s per bot, 60 s
# measured.
#   crowd  N bots spread over 512 x 512 voxels around the spawn (every bot
#          sees every edit), ramp-up 20 s; world: worlds/scale
#          (terrane-world generate --world worlds/scale
#           --box -1024,-128,-1024,1024,256,1024).
#   world  N bots at constant density, 1,000 over 3,072 x 3,072 voxels (the
#          square scales with sqrt(N)), inside a 4,096 x 4,096 world so no
#          view reaches ungenerated ground; ramp-up N/5 s, and the 60 s
#          start once every bot has joined (--wait-joined); world:
#          worlds/world4k (terrane-world generate --world worlds/world4k
#          --box -2048,-128,-2048,2048,256,2048). Beyond 1,000 bots
#          the square and the views outgrow it: world 2000 takes
#          TERRANE_WORLD=worlds/world6k (--box -3072,-128,-3072,3072,256,3072).
#   join   the world scenario's joins alone: idle bots (no edits, no
#          walking) join at 5 a second, then 10 s; the report's "per join"
#          row is the server's CPU, records and stream bytes per joining
#          bot, from the first connection until every bot joined at full
#          resolution; world: worlds/world4k.
#   wave   the world scenario measured from the first connection
#          (--measure-from start): edits and their fan-out while the bots
#          join at 5 a second, then the 60 s after the last join; world:
#          worlds/world4k.
# Prints the bots' report (with the server's tick, commit and fan-out times
# from its metrics endpoint), the bots' and the server's peak memory and CPU
# time (/proc of the server just before it is stopped; GNU time for the
# bots). The server's log is kept beside the report (REPORT.server.log).
#   scripts/bots-scale.sh [crowd|world|join|wave] N [REPORT.json] [extra terrane-bots flags...]
# (A first argument that is a number means crowd.) Expects a release build.
# TERRANE_SCALE_TOKEN=T runs the server with --auth-token T and every bot
# with --token T (authentication on; limits are always on at their
# defaults); TERRANE_SERVER_FLAGS adds server flags; TERRANE_BOTS names
# another terrane-bots binary (another build's, to compare the two).
set -euo pipefail
cd "$(dirname "$0")/.."
scenario=crowd
case "${1:-}" in
  crowd|world|join|wave) scenario=$1; shift ;;
esac
bots=${1:?usage: scripts/bots-scale.sh [crowd|world|join|wave] N [REPORT.json] [flags...]}
report=${2:-reports/$scenario-$bots.json}
shift $(( $# >= 2 ? 2 : 1 ))
if [ "$scenario" = crowd ]; then
  world=${TERRANE_WORLD:-worlds/scale}
  scenario_flags=(--preset crowd)
else
  world=${TERRANE_WORLD:-worlds/world4k}
  if [ "$scenario" = world ]; then
    scenario_flags=(--preset world)
  elif [ "$scenario" = join ]; then
    scenario_flags=(--preset world --duration 10 --behavior idle)
  else
    # The world preset's ramp-up ((N + 4) / 5 s), then its minute.
    scenario_flags=(--preset world --duration $(( (bots + 4) / 5 + 60 )) --measure-from start --wait-joined 0)
  fi
fi
[ -d "$world" ] || { echo "bots-scale.sh: no world at $world (see the comment at the top for how to make it)" >&2; exit 2; }

. scripts/lib.sh
terrane_scratch scale

# A plain copy: nothing has the world open (terrane-world backup copies a
# world a server is using, page by page, and takes minutes for this size).
cp -r "$world" "$scratch/world"
token_flags=()
server_auth=()
if [ -n "${TERRANE_SCALE_TOKEN:-}" ]; then
  token_flags=(--token "$TERRANE_SCALE_TOKEN")
  server_auth=(--auth-token "$TERRANE_SCALE_TOKEN")
fi
# shellcheck disable=SC2086
terrane_start_server "$scratch/server.log" --world "$scratch/world" --port 0 --metrics 127.0.0.1:0 \
  --max-clients $((bots + 64)) "${server_auth[@]}" ${TERRANE_SERVER_FLAGS:-}
port=$server_port
# Warm-up (TERRANE_SCALE_WARMUP=1, not measured): 40 idle bots over the same
# area make the server load every chunk in view from its store first, so
# the measured run sees a warm server.
if [ "${TERRANE_SCALE_WARMUP:-0}" = 1 ]; then
  ./build/bin/terrane-bots --connect "127.0.0.1:$port" --bots 40 --duration 45 --behavior idle --spread 512 \
    --view-distance 512 --full-res-radius 64 --hash-checks 0 --seed 99 --progress off "${token_flags[@]}" >/dev/null || true
fi
cpu0=$(terrane_cpu_seconds "$server_pid")
start=$(date +%s.%N)

mkdir -p "$(dirname "$report")"
status=0
# The bots' own peak memory and CPU, when GNU time is installed.
timer=()
[ -x /usr/bin/time ] && timer=(/usr/bin/time -f "bots: peak RSS %M KiB; CPU %U s user + %S s sys over %e s wall")
"${timer[@]}" "${TERRANE_BOTS:-./build/bin/terrane-bots}" --connect "127.0.0.1:$port" --server-metrics "127.0.0.1:$metrics_port" \
  "${scenario_flags[@]}" --bots "$bots" --progress off --report "$report" "${token_flags[@]}" "$@" || status=$?

cpu1=$(terrane_cpu_seconds "$server_pid")
end=$(date +%s.%N)
hwm=$(terrane_peak_kib "$server_pid")
awk -v h="$hwm" -v c0="$cpu0" -v c1="$cpu1" -v s="$start" -v e="$end" 'BEGIN {
  printf "server: peak RSS %.0f MiB; CPU %.1f s over %.1f s wall (%.0f%% of one core)\n",
         h / 1024, c1 - c0, e - s, 100 * (c1 - c0) / (e - s) }'
terrane_stop_server || status=1
tail -n 1 "$scratch/server.log"
cp "$scratch/server.log" "${report%.json}.server.log"
exit $status

#!/usr/bin/env bash
# Sets everything up and runs Terrane's main job: the README's first command.
#   1. install system packages (scripts/install-deps.sh)
#   2. release build of the world tool, the server and the bots
#   3. generate the default world in worlds/default (kept between runs:
#      chunks already stored are not generated again)
#   4. copy it to a scratch world, so the bots' edits never change
#      worlds/default and every run starts from the same terrain
#   5. start terrane-server on the copy, with its metrics endpoint (ports 0:
#      read from its 'listening on 127.0.0.1:PORT' and 'metrics on
#      http://127.0.0.1:PORT/metrics' log lines)
#   6. run a terrane-bots load test against it and print the report, the
#      server's own figures included (reports/bots.json, reports/bots.html)
#   7. stop the server cleanly (SIGTERM) and remove the scratch world
# Safe to run any number of times. Exit status: the bots' (0 = every replica
# verified, no unexpected disconnects).
#
# Environment: TERRANE_WORLD (default worlds/default), TERRANE_BOTS (50),
# TERRANE_BOTS_DURATION (30 s), TERRANE_BOTS_ARGS (extra terrane-bots flags).
set -euo pipefail
cd "$(dirname "$0")/.."

world=${TERRANE_WORLD:-worlds/default}
bots=${TERRANE_BOTS:-50}
duration=${TERRANE_BOTS_DURATION:-30}

bash scripts/install-deps.sh
# The same flags as the test command (scripts/test.sh), so neither rebuilds
# after the other; the viewer is built too, to look at the world.
bash scripts/build.sh release terrane-world terrane-server terrane-bots terrane-admin terrane-view
./build/bin/terrane-world generate --world "$world"

. scripts/lib.sh
terrane_scratch run

./build/bin/terrane-world backup --world "$world" --to "$scratch/world"
# Two io threads: chunk loads on the world owner strand must not stall sockets.
terrane_start_server "$scratch/server.log" --world "$scratch/world" --port 0 --metrics 127.0.0.1:0 \
  --max-clients $((bots + 16)) --io-threads 2
port=$server_port
echo "run.sh: terrane-server on 127.0.0.1:$port (metrics: http://127.0.0.1:$metrics_port/metrics), world $world (scratch copy)"

mkdir -p reports
status=0
# shellcheck disable=SC2086  # TERRANE_BOTS_ARGS holds several flags
./build/bin/terrane-bots --connect "127.0.0.1:$port" --server-metrics "127.0.0.1:$metrics_port" --bots "$bots" --duration "$duration" --behavior mixed \
  --spread 128 --view-distance 128 --full-res-radius 48 --ramp-up 5 --seed 1 \
  --report reports/bots.json --html reports/bots.html ${TERRANE_BOTS_ARGS:-} || status=$?

terrane_stop_server || { echo "run.sh: terrane-server did not stop cleanly:" >&2; tail -n 20 "$scratch/server.log" >&2; status=1; }
grep -A 40 'stopped after' "$scratch/server.log"  # the server's totals and its traffic by message type
echo "run.sh: reports in reports/bots.json and reports/bots.html"
exit $status

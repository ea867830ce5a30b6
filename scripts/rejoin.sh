#!/usr/bin/env bash
# What a rejoin from a chunk cache costs against a cold join (issue: "Half
# the bytes per player", the client cache). One idle bot at view 1,024 /
# full resolution 128 (VIEW and FULL override) on the default world right
# after `terrane-world generate`, per trial a fresh copy of the world, a
# fresh server and an empty cache, three runs of 20 s against it with one
# --chunk-cache:
#   cold     the cache empty: a first join
#   fill     the rest of the view (chunks still estimates when cold ended
#            are not kept)
#   rejoin   the whole view in the cache: what is measured
# and prints, per run, the join's own bytes (Hello, Welcome, Holdings,
# ClientState and StreamBatch, both ways), all bytes received and sent, the
# time to the coarse view and to full resolution, and the chunks taken
# from the cache. Expects a release build.
#   scripts/rejoin.sh [TRIALS] [REPORT_DIR]   (3 trials; reports kept in REPORT_DIR)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/bin/terrane-server ] || { echo "rejoin.sh: build first (scripts/build.sh release)" >&2; exit 2; }
trials=${1:-3}
case "$trials" in ''|*[!0-9]*) echo "rejoin.sh: TRIALS must be a number, got '$trials'" >&2; exit 2 ;; esac
view=${VIEW:-1024}
full=${FULL:-128}
. scripts/lib.sh
terrane_scratch rejoin
reports=${2:-$scratch/reports}
mkdir -p "$reports"

echo "generating the default world..." >&2
./build/bin/terrane-world generate --world "$scratch/generated" >/dev/null

printf "%-6s %-7s %14s %12s %10s %10s %10s %10s\n" trial run "join's bytes" "received" "sent" "coarse ms" "full ms" "cached"
for trial in $(seq "$trials"); do
  rm -rf "$scratch/world" "$scratch/cache"
  cp -r "$scratch/generated" "$scratch/world"
  terrane_start_server "$scratch/server.log" --world "$scratch/world" --port 0 --max-view-distance "$view"
  for run in cold fill rejoin; do
    report=$reports/trial$trial-$run.json
    ./build/bin/terrane-bots --connect "127.0.0.1:$server_port" --bots 1 --behavior idle --duration 20 --wait-joined 600 \
      --view-distance "$view" --full-res-radius "$full" --hash-checks 1 --quiet 0 --progress off \
      --chunk-cache "$scratch/cache" --report "$report" >/dev/null || true
    /usr/bin/python3 - "$report" "$trial" "$run" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
own = sum(v["bytes_in"] + v["bytes_out"] for k, v in r["by_message_type"].items()
          if k in ("Hello", "Welcome", "Holdings", "ClientState", "StreamBatch"))
ms = lambda h: h.get("p50") or -1
print("%-6s %-7s %11.1f kB %9.1f kB %7.1f kB %10.1f %10.1f %10d%s" % (
    sys.argv[2], sys.argv[3], own / 1e3, r["bytes_received"] / 1e3, r["bytes_sent"] / 1e3,
    ms(r["join_coarse_ms"]), ms(r["join_full_ms"]), r["cache_chunks_loaded"],
    "" if r["passed"] else "  FAILED"))
PY
  done
  terrane_stop_server || true
done

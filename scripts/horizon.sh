#!/usr/bin/env bash
# How fast a new client sees its whole horizon (issue: "The whole horizon at
# once"). One idle bot joins a server started cold (a fresh process on a
# fresh copy of the world) at view 2,048 / full resolution 128, 1,024 / 128
# and 512 / 64, on three worlds:
#   generated   the default world right after `terrane-world generate`
#               (the default box, +-256 around the spawn, stored)
#   never       a world never generated: every chunk is made on demand
#   mc-1.16     a real region imported as a world (tests/data/mc-1.16)
# and prints the time to the whole coarse view, to full resolution, and the
# bytes received by then (the bots' join_coarse_ms, join_full_ms,
# join_coarse_bytes, join_bytes_received). TERRANE_SERVER_FLAGS adds server
# flags (--no-outer-horizon: the images as before level 6, 2^3 voxels per
# chunk within a quarter of the view and one voxel per chunk beyond). Expects a release build.
#   scripts/horizon.sh [REPORT_DIR]      (reports kept there; default: a scratch dir)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/bin/terrane-server ] || { echo "horizon.sh: build first (scripts/build.sh release)" >&2; exit 2; }
. scripts/lib.sh
terrane_scratch horizon
reports=${1:-$scratch/reports}  # inside scratch: removed at the end unless given
mkdir -p "$reports"

echo "preparing worlds..." >&2
./build/bin/terrane-world generate --world "$scratch/generated" >/dev/null
./build/bin/terrane-world import --world "$scratch/mc-1.16" tests/data/mc-1.16.vxraw.gz >/dev/null

run() {  # world view full
  local world=$1 view=$2 full=$3 name=$1-$2
  rm -rf "$scratch/run"
  [ "$world" = never ] || cp -r "$scratch/$world" "$scratch/run"
  terrane_start_server "$scratch/server.log" --world "$scratch/run" --port 0 --max-view-distance 2048 ${TERRANE_SERVER_FLAGS:-}
  local address=127.0.0.1:$server_port
  ./build/bin/terrane-bots --connect "$address" --bots 1 --behavior idle --duration 1 --wait-joined 600 \
    --view-distance "$view" --full-res-radius "$full" --hash-checks 1 --quiet 0 --progress off \
    --report "$reports/$name.json" >/dev/null || true
  terrane_stop_server || true
  /usr/bin/python3 - "$reports/$name.json" "$world" "$view" "$full" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
c, f = r["join_coarse_ms"], r["join_full_ms"]
print("%-10s %5s / %-4s %12.0f %12.0f %14.1f %14.1f %6s" % (sys.argv[2], sys.argv[3], sys.argv[4],
      c.get("p50") or -1, f.get("p50") or -1, r["join_coarse_bytes"] / 1000, r["join_bytes_received"] / 1000,
      "ok" if r["passed"] else "FAIL"))
PY
}

printf "%-10s %12s %12s %12s %14s %14s %6s\n" world "view / full" "coarse ms" "full ms" "coarse kB" "join kB" ""
for world in generated never mc-1.16; do
  for vf in "2048 128" "1024 128" "512 64"; do
    run $world $vf
  done
done

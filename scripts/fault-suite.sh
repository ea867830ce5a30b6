#!/usr/bin/env bash
# Terrane's cluster fault suite (tests/system/README.md): Jepsen-style drills
# of several terrane-servers sharing one PostgreSQL world, each server and
# PostgreSQL in a network namespace of its own, a register workload and a
# checker against the database's rows, edit log and audit triggers.
#   scripts/fault-suite.sh [DRILL|all|quick] [--repeats N] [--seed S] [--servers 2|3]
#                          [--build DIR] [--lease-ms MS] [--json FILE] [--logs DIR] [-v]
# Prints one table row per drill (repeats, acknowledged, refused, unknown,
# lost, double-written, out-of-order, takeover and client downtime p50/max,
# /health against reality); exits 1 when an acknowledged write was lost, a
# write applied twice, or a chunk written outside its writer's lease.
# Needs root (ip netns, blackhole routes), PostgreSQL (scripts/install-deps.sh)
# and a release build with the Python module (scripts/build.sh release;
# default build directory: build). Takes about a minute per drill and repeat.
set -euo pipefail
cd "$(dirname "$0")/.."
build=build
args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build=${2:?--build DIR}; shift 2 ;;
    --build=*) build=${1#--build=}; shift ;;
    *) args+=("$1"); shift ;;
  esac
done
[ -x "$build/bin/terrane-server" ] && [ -d "$build/python/terrane" ] ||
  { echo "fault-suite.sh: no release build with the Python module in $build (scripts/build.sh release)" >&2; exit 2; }
# The interpreter the module was built for (CMake's TERRANE_PYTHON), else python3.
python=$(sed -n 's/^TERRANE_PYTHON:INTERNAL=//p' "$build/CMakeCache.txt" 2>/dev/null || true)
[ -x "${python:-}" ] || python=$(command -v python3)
PYTHONPATH="$(cd "$build" && pwd)/python${PYTHONPATH:+:$PYTHONPATH}" \
  exec "$python" tests/system/fault_suite.py --build "$build" "${args[@]}"

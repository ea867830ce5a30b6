#!/usr/bin/env bash
# Sets everything up and runs Terrane's main job: the README's first command.
#   1. install system packages (scripts/install-deps.sh)
#   2. release build
#   3. generate the default world in worlds/default (kept between runs:
#      chunks already stored are not generated again)
#   4. print the world's storage report (terrane-world stats)
# Safe to run any number of times.
set -euo pipefail
cd "$(dirname "$0")/.."

world=${TERRANE_WORLD:-worlds/default}

bash scripts/install-deps.sh
TERRANE_WERROR=OFF bash scripts/build.sh release terrane-world
./build/bin/terrane-world generate --world "$world"
./build/bin/terrane-world stats --world "$world"

#!/usr/bin/env bash
# Configures and builds one flavour of Terrane.
#   scripts/build.sh release   -> build/          (optimised, -Werror in CI)
#   scripts/build.sh asan      -> build-asan/     (address + undefined sanitizers)
#   scripts/build.sh fuzz      -> build-fuzz/     (clang, libFuzzer targets)
#   scripts/build.sh tsan      -> build-tsan/     (thread sanitizer)
# Extra arguments name targets to build (default: all).
set -euo pipefail
cd "$(dirname "$0")/.."

flavour=${1:-release}
shift || true
jobs=${TERRANE_JOBS:-$(nproc)}
werror=${TERRANE_WERROR:-ON}

case "$flavour" in
  release)
    dir=build
    args=(-DCMAKE_BUILD_TYPE=Release) ;;
  asan)
    dir=build-asan
    args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DTERRANE_SANITIZE=address,undefined -DTERRANE_BUILD_BENCH=OFF) ;;
  fuzz)
    dir=build-fuzz
    args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ -DTERRANE_BUILD_FUZZ=ON
          -DTERRANE_BUILD_BENCH=OFF -DTERRANE_BUILD_TESTS=ON -DTERRANE_SANITIZE=address,undefined) ;;
  tsan)
    dir=build-tsan
    args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DTERRANE_SANITIZE=thread -DTERRANE_BUILD_BENCH=OFF) ;;
  *)
    echo "build.sh: unknown flavour '$flavour' (release, asan, fuzz or tsan)" >&2
    exit 2 ;;
esac

cmake -S . -B "$dir" -G Ninja -DTERRANE_WERROR="$werror" "${args[@]}" >/dev/null
if [ $# -gt 0 ]; then
  cmake --build "$dir" -j "$jobs" --target "$@"
else
  cmake --build "$dir" -j "$jobs"
fi

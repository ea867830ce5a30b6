#!/usr/bin/env bash
# Configures and builds one flavour of Terrane.
#   scripts/build.sh release   -> build/          (optimised, -Werror in CI)
#   scripts/build.sh asan      -> build-asan/     (address + undefined sanitizers)
#   scripts/build.sh fuzz      -> build-fuzz/     (clang, libFuzzer targets)
#   scripts/build.sh tsan      -> build-tsan/     (thread sanitizer)
# Extra arguments name targets to build (default: all, and for release the
# Python package's wheel in build/dist/).
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
    # -O1 and line tables only (-g1): the sanitizers' reports keep function
    # names, files and lines, and each file compiles in about half the time
    # of -O2 -g (18.0 s against 9.6 s for server/cluster/cluster_node.cpp).
    dir=build-asan
    # The test suites' own code at -O0: under both sanitizers a suite's file
    # compiles in about half the time of -O1 (31.7 s against 60.2 s for
    # tests/server/server_test.cpp), and the suites are more than half of it.
    # Built with clang: under both sanitizers it compiles a file in about
    # two thirds of GCC's time (replicator.cpp 31.5 s against 47.1 s, a
    # suite's server_test.cpp at -O0 21.5 s against 34.6 s), and the
    # release build keeps GCC's warnings and code.
    args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
          -DCMAKE_CXX_COMPILER=clang++
          -DTERRANE_SANITIZE=address,undefined -DTERRANE_BUILD_BENCH=OFF -DTERRANE_TEST_OPTIMIZE=-O0) ;;
  fuzz)
    dir=build-fuzz
    args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ -DTERRANE_BUILD_FUZZ=ON
          -DTERRANE_BUILD_BENCH=OFF -DTERRANE_BUILD_TESTS=ON -DTERRANE_SANITIZE=address,undefined) ;;
  tsan)
    # -O2 keeps the threaded tests' timing near the release build's; line
    # tables only (-g1) are enough for the reports' stacks (7.9 s against
    # 6.5 s for server/cluster/cluster_node.cpp).
    dir=build-tsan
    args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG"
          -DTERRANE_SANITIZE=thread -DTERRANE_BUILD_BENCH=OFF) ;;
  *)
    echo "build.sh: unknown flavour '$flavour' (release, asan, fuzz or tsan)" >&2
    exit 2 ;;
esac

cmake -S . -B "$dir" -G Ninja -DTERRANE_WERROR="$werror" "${args[@]}" >/dev/null
if [ $# -gt 0 ]; then
  cmake --build "$dir" -j "$jobs" --target "$@"
else
  cmake --build "$dir" -j "$jobs"
  # The Python package as a wheel (build/dist/terrane-*.whl), from the module
  # just built, offline: where the module and Debian's pip are there.
  if [ "$flavour" = release ] && ls "$dir"/python/terrane/_native*.so >/dev/null 2>&1 &&
     /usr/bin/python3 -m pip --version >/dev/null 2>&1; then
    TERRANE_BUILD_DIR="$PWD/$dir" /usr/bin/python3 -m pip wheel --quiet --no-build-isolation --no-index --no-deps \
      --disable-pip-version-check -w "$dir/dist" ./client/python ||
      echo "build.sh: the Python wheel was not made (above why); the module in $dir/python is built" >&2
  fi
fi

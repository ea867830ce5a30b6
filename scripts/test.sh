#!/usr/bin/env bash
# Sets everything up and runs every test: the README's test command.
#   1. install system packages (scripts/install-deps.sh)
#   2. release build, unit tests
#   3. ASan + UBSan build, unit tests
#   4. ThreadSanitizer build of the threaded tests (server, client, bots,
#      cluster; ctest label tsan) and their run, failing on any report
#   5. libFuzzer targets, a bounded run each (TERRANE_FUZZ_SECONDS, default 20)
#   6. heavy tests (large worlds, scale) on the release build, but not the
#      Docker images (scripts/docker-check.sh); skip with TERRANE_SKIP_HEAVY=1
# Prints each stage's wall time. Exits non-zero on the first failure.
set -euo pipefail
cd "$(dirname "$0")/.."

stage_start=0
stage() { stage_name=$1; stage_start=$(date +%s); echo; echo "=== $stage_name"; }
stage_done() { echo "=== $stage_name: $(( $(date +%s) - stage_start )) s"; }

total_start=$(date +%s)
ctest_jobs=${TERRANE_JOBS:-$(nproc)}

stage "install dependencies"
bash scripts/install-deps.sh
stage_done

stage "release build"
bash scripts/build.sh release
stage_done

stage "unit tests (release)"
ctest --test-dir build -L unit -j "$ctest_jobs" --output-on-failure
stage_done

stage "sanitizer build (address, undefined)"
bash scripts/build.sh asan
stage_done

stage "unit tests (address, undefined)"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  ctest --test-dir build-asan -L unit -j "$ctest_jobs" --output-on-failure
stage_done

stage "thread sanitizer build"
# Only the threaded tests' programs and the programs they start.
bash scripts/build.sh tsan terrane_server_tests terrane_client_tests \
  terrane-server terrane-world terrane-bots terrane-admin
stage_done

stage "threaded tests (thread sanitizer)"
# Every report fails the stage. Reports go to files, the servers' and tools'
# that the tests start too (a test may not notice a child's exit code);
# halt_on_error ends the process at its first.
tsan_logs=$PWD/build-tsan/tsan-reports
rm -rf "$tsan_logs" && mkdir -p "$tsan_logs"
tsan_failed=0
TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:log_path=$tsan_logs/report" \
  ctest --test-dir build-tsan -L tsan -j "$ctest_jobs" --output-on-failure || tsan_failed=1
if compgen -G "$tsan_logs/report.*" >/dev/null; then
  cat "$tsan_logs"/report.*
  echo "ThreadSanitizer reports: $(ls "$tsan_logs" | wc -l) processes (above, and in $tsan_logs)" >&2
  tsan_failed=1
fi
[ "$tsan_failed" = 0 ]
stage_done

stage "fuzz targets"
# Only the fuzz targets: the rest of the tree is built and tested above.
fuzz_targets=()
for f in tests/fuzz/*_fuzz.cpp; do
  name=$(basename "$f" _fuzz.cpp)
  fuzz_targets+=("fuzz-${name//_/-}")
done
bash scripts/build.sh fuzz "${fuzz_targets[@]}"
bash scripts/fuzz.sh "${TERRANE_FUZZ_SECONDS:-20}"
stage_done

if [ "${TERRANE_SKIP_HEAVY:-0}" != 1 ]; then
  stage "heavy tests (release)"
  # Not the Docker images (label docker): scripts/docker-check.sh builds
  # and runs them on its own, minutes and gigabytes.
  ctest --test-dir build -L heavy -LE docker -j 1 --output-on-failure --no-tests=ignore
  stage_done
fi

echo
echo "all tests passed in $(( $(date +%s) - total_start )) s"

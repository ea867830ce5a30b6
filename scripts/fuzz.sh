#!/usr/bin/env bash
# Runs every libFuzzer target in build-fuzz/bin for SECONDS each (default 20),
# starting from its seed corpus in tests/fuzz/corpus/<name>/ and any crash
# regression inputs kept there. New inputs go to a scratch directory, so the
# checked-in corpus only changes by hand.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-20}
shopt -s nullglob
targets=(build-fuzz/bin/fuzz-*)
if [ ${#targets[@]} -eq 0 ]; then
  echo "fuzz.sh: no fuzz targets built (run scripts/build.sh fuzz)" >&2
  exit 1
fi
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
for t in "${targets[@]}"; do
  name=${t##*/fuzz-}
  corpus=tests/fuzz/corpus/$name
  mkdir -p "$scratch/$name"
  seeds=()
  [ -d "$corpus" ] && seeds=("$corpus")
  echo "fuzz $name: ${seconds} s"
  "$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=0 \
    "$scratch/$name" "${seeds[@]}" 2>"$scratch/$name.log" || {
      echo "fuzz $name FAILED:" >&2
      tail -n 60 "$scratch/$name.log" >&2
      exit 1
    }
  grep -E '^(#[0-9]+\s+DONE|Done [0-9]+ runs)' "$scratch/$name.log" | tail -n 1 || true
done

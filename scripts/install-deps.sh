#!/usr/bin/env bash
# Installs every system package Terrane needs to build, test and run.
# Debian 12 (bookworm), as root. Safe to run any number of times: packages
# already present are left alone, and apt is only refreshed when something is
# missing. README, .ci/run and docker/ all call this one script.
set -euo pipefail

packages=(
  # toolchain
  build-essential g++ cmake ninja-build git pkg-config ca-certificates
  # libfuzzer targets and sanitizer runtimes
  clang libclang-rt-14-dev
  # libraries (see README "Dependencies")
  libasio-dev liblz4-dev flatbuffers-compiler libflatbuffers-dev libspdlog-dev
  libgtest-dev libgmock-dev libbenchmark-dev libsqlite3-dev zlib1g-dev
  # HTTP for the server's /metrics and /health (and the bots' scrape of them)
  libcpp-httplib-dev
  # the server's allocator (CMake's TERRANE_ALLOCATOR; docs/results.md,
  # "The allocator")
  libjemalloc-dev
  # benchmark-only comparison codec
  libzstd-dev
  # world files and reports
  sqlite3 python3
  # the terrane Python module (client/python) and its tests
  python3-dev pybind11-dev python3-numpy python3-pytest
  # pip install ./client/python offline, in a venv that sees these
  python3-pip python3-venv python3-setuptools python3-wheel
  # terrane-view: GLFW windows, libepoxy (GL function loader for GLX and
  # EGL alike), EGL + Mesa's software rasteriser for headless screenshots
  libglfw3-dev libepoxy-dev libegl-dev libgl-dev libegl-mesa0 libgl1-mesa-dri
  # validates docker/docker-compose.yml in the tests (no Docker engine needed)
  docker-compose
  # worlds shared by several servers: libpq, and PostgreSQL itself for the
  # tests (each test starts its own, in a scratch directory, on loopback)
  libpq-dev postgresql-15
  # promtool checks the metrics endpoint in the tests; prometheus scrapes it
  # in the operations test (started by the test itself, on loopback)
  prometheus
  # a real browser, headless, loads terrane-bots' HTML report in the tests
  # and runs its charts' script (tests/client/bots/report_html_test.cpp);
  # docs/load-testing.md's screenshot of a report is taken with it
  chromium
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

if [ "$(id -u)" -ne 0 ]; then
  echo "install-deps: missing packages: ${missing[*]}" >&2
  echo "install-deps: run as root (or install them yourself) and try again" >&2
  exit 1
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}"

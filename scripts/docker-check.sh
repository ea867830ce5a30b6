#!/usr/bin/env bash
# Terrane's Docker images built and run on this machine, offline:
#   scripts/docker-check.sh [--build DIR | --from-source]
# 1. installs Debian's engine (docker.io) and docker-compose when missing;
# 2. starts its own dockerd on a private socket in a scratch directory
#    (no iptables, no default bridge: nothing of the host's network changes);
# 3. makes a Debian 12 base image with debootstrap and `docker import`
#    (no image registry is needed: only deb.debian.org), cached in
#    $TERRANE_DOCKER_CACHE (default /var/cache/terrane-docker) with the
#    engine's images, so a second run is quick;
# 4. builds the server, bots and Prometheus images from docker/Dockerfile,
#    the binaries prebuilt by scripts/build.sh release (DIR, default build),
#    or with --from-source compiled in the image's build stage (the
#    repository as context, scripts/install-deps.sh and scripts/build.sh
#    inside; TERRANE_JOBS jobs, default 2; long: no compiler cache);
# 5. checks the compose file fails closed (no tokens file: refused, naming
#    TERRANE_TOKENS_FILE) and the server image too (no tokens: it stops);
# 6. runs the compose load test (server + 50 bots; the bots' report is
#    printed, their exit status is the run's), then checks the running
#    server: uid 999, healthy, restart policy, log rotation, limits, an
#    admin command and a backup into the backups volume, a `shutdown
#    --restart` that Docker restarts (exit 75);
# 7. runs the monitoring profile's Prometheus scraping the server and asks
#    Prometheus's HTTP API for a terrane_ metric;
# 8. stops everything it started, by pid.
# Exits 0 when all passed, 1 on a failure, 77 (skipped) where the engine
# cannot run here (not root, no cgroups, dockerd refuses), saying why.
# Needs root. One run at a time (a lock in the cache directory).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
build=build
from_source=
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build=${2:?--build DIR}; shift 2 ;;
    --build=*) build=${1#--build=}; shift ;;
    --from-source) from_source=1; shift ;;
    *) echo "usage: scripts/docker-check.sh [--build DIR | --from-source]" >&2; exit 2 ;;
  esac
done
build=$(cd "$build" 2>/dev/null && pwd) || { echo "docker-check: no build directory $build" >&2; exit 2; }

say() { printf 'docker-check: %s\n' "$*"; }
skip() { printf 'docker-check: SKIPPED: %s\n' "$*" >&2; exit 77; }
fail() { printf 'docker-check: FAILED: %s\n' "$*" >&2; exit 1; }

[ -n "$from_source" ] || for b in terrane-server terrane-bots terrane-world terrane-admin; do
  [ -x "$build/bin/$b" ] || fail "no $build/bin/$b: build it first (scripts/build.sh release $b)"
done
[ "$(id -u)" = 0 ] || skip "dockerd needs root here (running as uid $(id -u))"
[ -d /sys/fs/cgroup ] && [ -n "$(ls /sys/fs/cgroup 2>/dev/null)" ] || skip "no cgroup filesystem at /sys/fs/cgroup: containers cannot run"

# 1. The engine and compose, from Debian 12: docker.io (dockerd 20.10,
# containerd, runc) and docker-compose 1.29 (Python; Debian 12 has no
# compose v2 plugin). Debian's client (/usr/bin/docker) matches the daemon.
need=()
command -v dockerd >/dev/null || need+=(docker.io)
command -v docker-compose >/dev/null || need+=(docker-compose)
command -v debootstrap >/dev/null || need+=(debootstrap)
command -v curl >/dev/null || need+=(curl)
if [ ${#need[@]} -gt 0 ]; then
  say "installing ${need[*]} from Debian"
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${need[@]}" >/dev/null ||
    skip "could not install ${need[*]} from Debian (apt-get install failed)"
fi
docker=/usr/bin/docker
[ -x "$docker" ] || docker=$(command -v docker)

cache=${TERRANE_DOCKER_CACHE:-/var/cache/terrane-docker}
mkdir -p "$cache"
exec 9>"$cache/lock"
flock -n 9 || { say "another docker-check holds $cache/lock; waiting"; flock 9; }

# 2. dockerd on a private socket; its images persist in $cache/data (the
# cache), everything else of this run lives in the scratch directory.
scratch=$(mktemp -d /tmp/terrane-docker.XXXXXX)
sock=$scratch/docker.sock
export DOCKER_HOST=unix://$sock
dockerd_pid=
project=terrane-check
compose_files=(-f "$root/docker/docker-compose.yml")
cleanup() {
  set +e
  if [ -n "$dockerd_pid" ] && kill -0 "$dockerd_pid" 2>/dev/null; then
    if [ -n "${compose_env_set:-}" ]; then
      docker-compose -p "$project" "${compose_files[@]}" --profile monitoring down -v --timeout 30 >/dev/null 2>&1
    fi
    "$docker" ps -aq | xargs -r "$docker" rm -f >/dev/null 2>&1
    kill -TERM "$dockerd_pid"
    for _ in $(seq 1 300); do kill -0 "$dockerd_pid" 2>/dev/null || break; sleep 0.1; done
    kill -0 "$dockerd_pid" 2>/dev/null && kill -KILL "$dockerd_pid"
    wait "$dockerd_pid" 2>/dev/null
    say "dockerd (pid $dockerd_pid) stopped"
  fi
  # The managed containerd's mounts, if dockerd died without cleaning up.
  grep -o " $scratch[^ ]*" /proc/mounts | sort -r | xargs -r -n1 umount -l 2>/dev/null
  # This run's logs stay in the cache directory (not the secrets).
  rm -rf "$cache/last-run" && mkdir -p "$cache/last-run" && cp "$scratch"/*.log "$cache/last-run/" 2>/dev/null
  rm -rf "$scratch"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

say "starting dockerd on $sock (data root $cache/data)"
dockerd --iptables=false --ip-masq=false --bridge=none --host "$DOCKER_HOST" \
  --data-root "$cache/data" --exec-root "$scratch/exec" --pidfile "$scratch/dockerd.pid" \
  --log-level warn >"$scratch/dockerd.log" 2>&1 &
dockerd_pid=$!
for _ in $(seq 1 600); do
  "$docker" version >/dev/null 2>&1 && break
  kill -0 "$dockerd_pid" 2>/dev/null || { tail -n 20 "$scratch/dockerd.log" >&2; dockerd_pid=; skip "dockerd could not start here (its log above)"; }
  sleep 0.1
done
"$docker" version >/dev/null 2>&1 || { tail -n 20 "$scratch/dockerd.log" >&2; skip "dockerd did not answer within 60 s (its log above)"; }
say "engine: dockerd $("$docker" version --format '{{.Server.Version}}'), $("$docker" info --format '{{.Driver}}') storage, docker-compose $(docker-compose version --short 2>/dev/null)"

# 3. The base image: a debootstrapped bookworm (minbase) root, imported.
base=terrane-base:bookworm
if ! "$docker" image inspect "$base" >/dev/null 2>&1; then
  tarball=$cache/bookworm-minbase.tar
  if [ ! -s "$tarball" ]; then
    say "debootstrap bookworm (minbase) from deb.debian.org into $cache/rootfs"
    rm -rf "$cache/rootfs"
    debootstrap --variant=minbase bookworm "$cache/rootfs" http://deb.debian.org/debian >"$scratch/debootstrap.log" 2>&1 ||
      { tail -n 20 "$scratch/debootstrap.log" >&2; skip "debootstrap failed (deb.debian.org unreachable?)"; }
    # Security and point-release updates too, like debian:12's own sources.
    printf '%s\n' 'deb http://deb.debian.org/debian bookworm main' \
      'deb http://deb.debian.org/debian bookworm-updates main' \
      'deb http://deb.debian.org/debian-security bookworm-security main' >"$cache/rootfs/etc/apt/sources.list"
    rm -rf "$cache/rootfs/var/cache/apt/archives/"*.deb "$cache/rootfs/var/lib/apt/lists/"*
    tar -C "$cache/rootfs" -cf "$tarball.tmp" . && mv "$tarball.tmp" "$tarball"
    rm -rf "$cache/rootfs"
  fi
  say "importing $tarball as $base"
  "$docker" import --change 'CMD ["bash"]' "$tarball" "$base" >/dev/null
fi
"$docker" run --rm --network=host "$base" true >"$scratch/run.log" 2>&1 ||
  { cat "$scratch/run.log" >&2; skip "a container cannot run here (the error above)"; }

# 4. The images. The context holds the docker/ directory and the prebuilt
# binaries only (BuildKit builds only the stages the target needs), or with
# --from-source the repository (.dockerignore leaves out build directories).
context=$scratch/context
binaries=prebuilt
if [ -n "$from_source" ]; then
  context=$root
  binaries=build
else
  mkdir -p "$context/build/bin"
  cp -r "$root/docker" "$context/docker"
  cp "$build"/bin/terrane-{server,bots,world,admin} "$context/build/bin/"
fi
for target in server bots prometheus; do
  say "building terrane-$target (docker/Dockerfile, target $target, binaries: $binaries)"
  DOCKER_BUILDKIT=1 "$docker" build --network=host -f "$context/docker/Dockerfile" --target "$target" \
    --build-arg DEBIAN=$base --build-arg BINARIES=$binaries --build-arg TERRANE_JOBS="${TERRANE_JOBS:-2}" \
    -t "terrane-$target" "$context" \
    >"$scratch/build-$target.log" 2>&1 || { tail -n 30 "$scratch/build-$target.log" >&2; fail "docker build --target $target"; }
done
"$docker" images --format '  {{.Repository}}:{{.Tag}} {{.Size}}' | grep -E 'terrane-(server|bots|prometheus|base)' || true

# 5. Fail closed. The compose file without TERRANE_TOKENS_FILE:
out=$(env -u TERRANE_TOKENS_FILE docker-compose -p "$project" "${compose_files[@]}" up --no-build server 2>&1) &&
  fail "docker-compose up started without TERRANE_TOKENS_FILE: $out"
grep -q 'set TERRANE_TOKENS_FILE' <<<"$out" || fail "docker-compose up refused without naming TERRANE_TOKENS_FILE: $out"
say "compose without a tokens file refuses: $(grep -o 'set TERRANE_TOKENS_FILE[^:]*' <<<"$out" | head -n 1)"
# The image without a tokens file at /run/secrets/terrane_tokens:
set +e
out=$(timeout 120 "$docker" run --rm --network=none terrane-server 2>&1)
status=$?
set -e
[ $status -ne 0 ] || fail "the server image started without a tokens file: $out"
grep -q 'terrane_tokens' <<<"$out" || fail "the server image refused without naming the tokens file: $out"
say "the server image without tokens exits $status: $(grep 'terrane_tokens' <<<"$out" | head -n 1 | sed 's/^.*\] //')"

# The secrets: a tokens file with an admin and the bots' lines, readable by
# the image's uid 999 only, and the bots' token file.
mkdir -p "$scratch/secrets"
admin_token=$(head -c 18 /dev/urandom | base64 | tr '+/' '-_')
bots_token=$(head -c 18 /dev/urandom | base64 | tr '+/' '-_')
{
  echo "# docker-check's tokens: an operator and the load test's bots"
  echo "operator $admin_token admin"
  for i in $(seq 0 49); do echo "bot-$i $bots_token"; done
} >"$scratch/secrets/tokens"
printf '%s\n' "$bots_token" >"$scratch/secrets/bots-token"
chown 999:999 "$scratch/secrets/tokens" "$scratch/secrets/bots-token"
chmod 400 "$scratch/secrets/tokens" "$scratch/secrets/bots-token"
export TERRANE_TOKENS_FILE=$scratch/secrets/tokens TERRANE_BOTS_TOKEN_FILE=$scratch/secrets/bots-token
export TERRANE_PROMETHEUS_IMAGE=terrane-prometheus
compose_env_set=1
compose() { docker-compose -p "$project" "${compose_files[@]}" "$@"; }

# 6. The load test: server + bots; the bots' exit status is the run's.
say "compose load test: server + 50 bots (docker-compose up --abort-on-container-exit --exit-code-from bots)"
set +e
compose up --no-color --no-build --abort-on-container-exit --exit-code-from bots server bots >"$scratch/compose-up.log" 2>&1
bots_status=$?
set -e
# The bots' report, as the bots printed it.
sed -n 's/^bots_1 *| //p' "$scratch/compose-up.log" | grep -v "^$" | tail -n 70 || true
say "bots exit status $bots_status"
if [ $bots_status -ne 0 ]; then
  tail -n 60 "$scratch/compose-up.log" >&2
  fail "the compose load test failed (bots exit $bots_status)"
fi

# The server as deployed: (re)started alone, detached.
compose up --no-build -d server >/dev/null 2>&1 || fail "docker-compose up -d server"
server=$(compose ps -q server)
for _ in $(seq 1 1200); do
  [ "$("$docker" inspect -f '{{.State.Health.Status}}' "$server")" = healthy ] && break
  sleep 0.1
done
[ "$("$docker" inspect -f '{{.State.Health.Status}}' "$server")" = healthy ] || fail "the server did not become healthy"
say "server container: $("$docker" inspect -f 'user {{.Config.User}}, health {{.State.Health.Status}} (test: {{index .Config.Healthcheck.Test 1}}), restart {{.HostConfig.RestartPolicy.Name}}:{{.HostConfig.RestartPolicy.MaximumRetryCount}}, log {{.HostConfig.LogConfig.Type}} {{.HostConfig.LogConfig.Config}}, memory {{.HostConfig.Memory}}, cpus {{.HostConfig.NanoCpus}}, pids {{.HostConfig.PidsLimit}}' "$server")"
uid=$("$docker" exec "$server" id -u)
[ "$uid" = 999 ] || fail "the server runs as uid $uid, not 999"
"$docker" inspect -f '{{range .Config.Cmd}}{{.}} {{end}}{{range .Config.Env}}{{.}} {{end}}' "$server" | grep -q "$admin_token" &&
  fail "the admin token is in the container's command line or environment"
"$docker" exec "$server" terrane-admin-local status >"$scratch/status.txt" 2>&1 || { cat "$scratch/status.txt" >&2; fail "terrane-admin-local status"; }
say "terrane-admin-local status: $(head -n 3 "$scratch/status.txt" | tr '\n' ' ')"
"$docker" exec "$server" terrane-admin-local backup /backups/check-1 >"$scratch/backup.txt" 2>&1 || { cat "$scratch/backup.txt" >&2; fail "terrane-admin-local backup"; }
backup_volume=$("$docker" inspect -f '{{range .Mounts}}{{if eq .Destination "/backups"}}{{.Source}}{{end}}{{end}}' "$server")
[ -n "$(ls -A "$backup_volume/check-1" 2>/dev/null)" ] || fail "the backup is not in the backups volume ($backup_volume)"
say "backup into the backups volume: $(cat "$scratch/backup.txt" | head -n 1); on the host: $(ls "$backup_volume/check-1" | tr '\n' ' ')"
# shutdown --restart: exit 75, and Docker's on-failure policy restarts it.
started=$("$docker" inspect -f '{{.State.StartedAt}}' "$server")
"$docker" exec "$server" terrane-admin-local shutdown --in 0 --restart --reason docker-check >/dev/null 2>&1 || true
for _ in $(seq 1 1200); do
  [ "$("$docker" inspect -f '{{.RestartCount}} {{.State.Health.Status}}' "$server")" = "1 healthy" ] && break
  sleep 0.1
done
[ "$("$docker" inspect -f '{{.RestartCount}} {{.State.Health.Status}}' "$server")" = "1 healthy" ] ||
  fail "after shutdown --restart the server was not restarted: $("$docker" inspect -f '{{.RestartCount}} {{.State.Status}} exit {{.State.ExitCode}}' "$server")"
say "shutdown --restart: restarted by Docker (restart count $("$docker" inspect -f '{{.RestartCount}}' "$server"), started $started, then $("$docker" inspect -f '{{.State.StartedAt}}' "$server")), healthy again"

# 7. Prometheus (the monitoring profile) scraping the server.
say "monitoring profile: Prometheus scraping the server"
compose --profile monitoring up --no-build -d prometheus >/dev/null 2>&1 || fail "docker-compose --profile monitoring up -d prometheus"
answer=
for _ in $(seq 1 600); do
  answer=$(curl -fsS 'http://127.0.0.1:9090/api/v1/query?query=terrane_ticks_total' 2>/dev/null || true)
  grep -q '"value"' <<<"$answer" && break
  sleep 0.2
done
grep -q '"value"' <<<"$answer" || fail "Prometheus has no terrane_ticks_total: ${answer:-no answer}"
say "Prometheus: GET /api/v1/query?query=terrane_ticks_total -> $answer"

# A plain shutdown exits 0: the server stays stopped.
"$docker" exec "$server" terrane-admin-local shutdown --in 0 >/dev/null 2>&1 || true
"$docker" wait "$server" >/dev/null
state=$("$docker" inspect -f '{{.State.Status}} {{.State.ExitCode}} {{.RestartCount}}' "$server")
[ "$state" = "exited 0 1" ] || fail "after a plain shutdown: $state (want exited 0, not restarted again)"
say "plain shutdown: exit 0, left stopped"
say "PASSED in $SECONDS s"

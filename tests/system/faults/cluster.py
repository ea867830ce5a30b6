"""The drills' cluster: a PostgreSQL and N terrane-servers, each in a network
namespace of its own, joined to the root namespace (where the workload runs)
by veth pairs, with forwarding on so each server reaches PostgreSQL through
the root namespace.

    root ns: 10.213.<k>.1 on veth <tag>h<k>     (the clients, psql, the checker)
    PostgreSQL ns <tag>pg: 10.213.10.2:5432
    server i ns <tag>s<i>: 10.213.<i>.2:7777 (clients), :9100 (/metrics, /health)

A link is cut with blackhole routes on both sides (packets dropped, never
reset): server i from PostgreSQL is a route to 10.213.10.2 in server i's
namespace plus one to 10.213.i.2 in PostgreSQL's. The clients still reach
the server. Everything made here (namespaces, veths, processes by pid, the
scratch directory) goes in stop(), also after a failure.
"""
import csv
import glob
import io
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time

PG_NET = 10
CLIENT_PORT = 7777
METRICS_PORT = 9100


def sh(*args, check=True, **kw):
    return subprocess.run(list(args), check=check, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kw)


def pg_bin():
    dirs = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda d: int(d.split("/")[-2]), reverse=True)
    for d in dirs:
        if os.path.exists(os.path.join(d, "postgres")):
            return d
    raise SystemExit("fault suite: PostgreSQL is not installed (scripts/install-deps.sh installs it)")


def addr(k):
    return "10.213.%d.2" % k


class Server:
    def __init__(self, cluster, sid):
        self.cluster = cluster
        self.id = sid
        self.ns = "%ss%d" % (cluster.tag, sid)
        self.host = addr(sid)
        self.address = "%s:%d" % (self.host, CLIENT_PORT)
        self.health_url = (self.host, METRICS_PORT)
        self.proc = None
        self.log_path = os.path.join(cluster.dir, "server-%d.log" % sid)
        self.stopped = False   # SIGSTOPped
        self.starts = 0

    def start(self, wait=True):
        c = self.cluster
        log = open(self.log_path, "a")
        log.write("=== start %d at %.3f\n" % (self.starts, time.time()))
        log.flush()
        self.starts += 1
        cmd = ["ip", "netns", "exec", self.ns, os.path.join(c.bin, "terrane-server"),
               "--store", c.url, "--server-id", str(self.id), "--bind", self.host, "--port", str(CLIENT_PORT),
               "--open", "--metrics", "%s:%d" % (self.host, METRICS_PORT), "--lease-ms", str(c.lease_ms),
               "--redirect-margin", "0", "--edits-per-second", "200", "--view-distance", "96",
               "--full-res-radius", "32"] + c.server_flags
        # ip netns exec execs the server: the pid is the server's.
        self.proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        log.close()
        self.stopped = False
        if wait:
            self.wait_listening()
        self.cluster.mark(self.id)

    def wait_listening(self, timeout=90):
        deadline = time.time() + timeout
        mark = "listening on %s:%d" % (self.host, CLIENT_PORT)
        while time.time() < deadline:
            with open(self.log_path) as f:
                text = f.read()
            last = text.rsplit("=== start", 1)[-1]
            if mark in last and "metrics on" in last:
                return
            if self.proc.poll() is not None:
                raise RuntimeError("server %d exited (%s) before listening:\n%s" % (self.id, self.proc.returncode, last[-3000:]))
            time.sleep(0.1)
        raise RuntimeError("server %d did not listen within %d s" % (self.id, timeout))

    def alive(self):
        return self.proc is not None and self.proc.poll() is None

    def signal(self, sig):
        if self.alive():
            os.kill(self.proc.pid, sig)
            if sig == signal.SIGSTOP:
                self.stopped = True
            elif sig == signal.SIGCONT:
                self.stopped = False
            self.cluster.mark(self.id)

    def kill(self):
        self.signal(signal.SIGKILL)
        if self.proc is not None:
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                pass

    def terminate(self, timeout=15):
        if not self.alive():
            return
        if self.stopped:
            os.kill(self.proc.pid, signal.SIGCONT)
        os.kill(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait(10)

    def log_text(self):
        with open(self.log_path, errors="replace") as f:
            return f.read()


class Cluster:
    def __init__(self, build_dir, servers=2, lease_ms=5000, server_flags=(), keep=False):
        self.bin = os.path.join(os.path.abspath(build_dir), "bin")
        self.python = os.path.join(os.path.abspath(build_dir), "python")
        for b in ("terrane-server", "terrane-world"):
            if not os.access(os.path.join(self.bin, b), os.X_OK):
                raise SystemExit("fault suite: no %s in %s (scripts/build.sh release)" % (b, self.bin))
        self.tag = "f%d" % (os.getpid() % 100000)
        self.n = servers
        self.lease_ms = lease_ms
        self.server_flags = list(server_flags)
        self.keep = keep
        self.pgbin = pg_bin()
        self.dir = tempfile.mkdtemp(prefix="terrane-faults-")
        os.chmod(self.dir, 0o755)
        self.pg_ns = self.tag + "pg"
        self.pg_host = addr(PG_NET)
        self.url = "postgresql://terrane@%s:5432/postgres" % self.pg_host
        self.namespaces = []
        self.links = []
        self.cuts = set()
        self.servers = [Server(self, i) for i in range(1, servers + 1)]
        self.forward_before = None
        self.pg_dir = os.path.join(self.dir, "pg")
        self.pg_up = False
        self.transitions = []  # (time, server id or None for all): where /health may lag reality

    def mark(self, sid=None):
        self.transitions.append((time.time(), sid))

    def can_store(self, s):
        """Reality, as the drill made it: the server runs, is not paused, reaches PostgreSQL, which is up."""
        return self.pg_up and s.alive() and not s.stopped and s.id not in self.cuts

    # --- the network -------------------------------------------------------
    def _netns(self, ns, k):
        host_if, ns_if = "%sh%d" % (self.tag, k), "%sn%d" % (self.tag, k)
        sh("ip", "netns", "add", ns)
        self.namespaces.append(ns)
        sh("ip", "link", "add", host_if, "type", "veth", "peer", "name", ns_if)
        self.links.append(host_if)
        sh("ip", "link", "set", ns_if, "netns", ns)
        sh("ip", "addr", "add", "10.213.%d.1/24" % k, "dev", host_if)
        sh("ip", "link", "set", host_if, "up")
        sh("ip", "netns", "exec", ns, "ip", "addr", "add", "10.213.%d.2/24" % k, "dev", ns_if)
        sh("ip", "netns", "exec", ns, "ip", "link", "set", ns_if, "up")
        sh("ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up")
        sh("ip", "netns", "exec", ns, "ip", "route", "add", "default", "via", "10.213.%d.1" % k)

    def setup_network(self):
        with open("/proc/sys/net/ipv4/ip_forward") as f:
            self.forward_before = f.read().strip()
        with open("/proc/sys/net/ipv4/ip_forward", "w") as f:
            f.write("1")
        self._netns(self.pg_ns, PG_NET)
        for s in self.servers:
            self._netns(s.ns, s.id)

    def cut(self, sid):
        """Server sid can no longer reach PostgreSQL, nor PostgreSQL it: dropped, not reset."""
        s = self.servers[sid - 1]
        sh("ip", "netns", "exec", s.ns, "ip", "route", "add", "blackhole", self.pg_host + "/32")
        sh("ip", "netns", "exec", self.pg_ns, "ip", "route", "add", "blackhole", s.host + "/32")
        self.cuts.add(sid)
        self.mark(sid)

    def heal(self, sid):
        s = self.servers[sid - 1]
        sh("ip", "netns", "exec", s.ns, "ip", "route", "del", "blackhole", self.pg_host + "/32", check=False)
        sh("ip", "netns", "exec", self.pg_ns, "ip", "route", "del", "blackhole", s.host + "/32", check=False)
        self.cuts.discard(sid)
        self.mark(sid)

    # --- PostgreSQL --------------------------------------------------------
    def _as_pg(self, *args, check=True):
        return sh("ip", "netns", "exec", self.pg_ns, "runuser", "-u", "postgres", "--", *args, check=check)

    def setup_postgres(self):
        os.makedirs(self.pg_dir)
        shutil.chown(self.pg_dir, "postgres")
        self._as_pg(os.path.join(self.pgbin, "initdb"), "-D", self.pg_dir + "/data", "-U", "terrane",
                    "--auth=trust", "--encoding=UTF8")
        with open(self.pg_dir + "/data/pg_hba.conf", "a") as f:
            f.write("host all all 10.213.0.0/16 trust\n")
        self.pg_start()

    def pg_start(self, timeout=60):
        deadline = time.time() + timeout
        while True:
            r = self._as_pg(os.path.join(self.pgbin, "pg_ctl"), "-D", self.pg_dir + "/data", "-l",
                            self.pg_dir + "/postgres.log", "-w", "-t", "30", "-o",
                            "-p 5432 -c listen_addresses=%s -c unix_socket_directories=%s -c max_connections=200"
                            % (self.pg_host, self.pg_dir), "start", check=False)
            if r.returncode == 0:
                self.pg_up = True
                self.mark()
                return
            if time.time() > deadline:
                raise RuntimeError("PostgreSQL did not start: " + r.stdout)
            time.sleep(0.5)  # after kill -9, the old backends leave their shared memory in a moment

    def pg_stop(self, mode="immediate"):
        self.pg_up = False
        self.mark()
        self._as_pg(os.path.join(self.pgbin, "pg_ctl"), "-D", self.pg_dir + "/data", "-m", mode, "-w", "stop",
                    check=False)

    def pg_restart(self):
        self.pg_up = False
        self.mark()
        r = self._as_pg(os.path.join(self.pgbin, "pg_ctl"), "-D", self.pg_dir + "/data", "-l",
                        self.pg_dir + "/postgres.log", "-m", "fast", "-w", "-t", "60", "restart", check=False)
        if r.returncode != 0:
            raise RuntimeError("pg_ctl restart failed: " + r.stdout)
        self.pg_up = True
        self.mark()

    def postmaster_pid(self):
        try:
            with open(self.pg_dir + "/data/postmaster.pid") as f:
                return int(f.readline())
        except (OSError, ValueError):
            return None

    def pg_kill9(self):
        pid = self.postmaster_pid()
        if pid:
            self.pg_up = False
            self.mark()
            os.kill(pid, signal.SIGKILL)

    def psql(self, sql, timeout=60):
        """Rows of a query as lists of strings (psql's CSV, header dropped)."""
        r = subprocess.run([os.path.join(self.pgbin, "psql"), "-h", self.pg_host, "-p", "5432", "-U", "terrane",
                            "-d", "postgres", "-X", "-v", "ON_ERROR_STOP=1", "--csv", "-c", sql],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=timeout)
        if r.returncode != 0:
            raise RuntimeError("psql: %s\n%s" % (sql[:200], r.stderr))
        rows = list(csv.reader(io.StringIO(r.stdout)))
        return rows[1:]

    def psql_script(self, sql):
        r = subprocess.run([os.path.join(self.pgbin, "psql"), "-h", self.pg_host, "-p", "5432", "-U", "terrane",
                            "-d", "postgres", "-X", "-q", "-v", "ON_ERROR_STOP=1"], input=sql,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=60)
        if r.returncode != 0:
            raise RuntimeError("psql: %s" % r.stderr)

    # --- the whole ---------------------------------------------------------
    def start(self):
        self.setup_network()
        self.setup_postgres()
        # The first server makes the tables; the audit triggers go on them
        # before anything is written; then the others start.
        self.servers[0].start()
        from faults import audit
        audit.install(self)
        for s in self.servers[1:]:
            s.start()

    def stop(self):
        for s in self.servers:
            try:
                s.terminate()
            except Exception:
                if s.alive():
                    os.kill(s.proc.pid, signal.SIGKILL)
        for sid in list(self.cuts):
            self.heal(sid)
        if os.path.exists(self.pg_dir + "/data/postmaster.pid"):
            self.pg_stop("fast")
        for link in self.links:
            sh("ip", "link", "del", link, check=False)
        for ns in self.namespaces:
            sh("ip", "netns", "del", ns, check=False)
        self.links, self.namespaces = [], []
        if self.forward_before is not None:
            with open("/proc/sys/net/ipv4/ip_forward", "w") as f:
                f.write(self.forward_before)
            self.forward_before = None
        if not self.keep:
            shutil.rmtree(self.dir, ignore_errors=True)

    def save_logs(self, dest):
        os.makedirs(dest, exist_ok=True)
        for s in self.servers:
            if os.path.exists(s.log_path):
                shutil.copy(s.log_path, dest)
        if os.path.exists(self.pg_dir + "/postgres.log"):
            shutil.copy(self.pg_dir + "/postgres.log", dest)

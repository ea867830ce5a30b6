"""The register workload: single voxels (registers) on both sides of the
region borders between the servers' territories, each write a value no
other write of that register has (a per-register sequence number gives the
material and occupancy), by players each connected to one server, so half
of a player's writes or more go to a region another server writes
(forwarded). Each player waits for one write's answer before the next.

Every write is recorded: start and end (time.time()), the outcome
(acked: applied and stored; refused: a definite rejection; unknown: no
answer in time, the connection lost, or a rejection that says the edit may
still be applied) and the server used. A player whose write gets no answer
within the timeout, or whose connection closes, fails over to the next
server (home, home+1, ... round the ring).

The health poller asks each server's /health once a second."""
import http.client
import random
import threading
import time

import numpy as np

import terrane

from faults.checker import Write

Y = 100          # registers' height (air above the default world's ground, region y 0)
REGION = 256     # voxels per region side (8 chunks of 32: STORE_POSTGRESQL.md)

DB_TEXT = ("libpq", "server closed the connection", "could not connect", "connection to server", "SSL",
           "FATAL", "ERROR:", "terminating connection", "PQ", "SQLSTATE", "could not receive", "could not send")


def territory_plan(n):
    """Per server: an anchor voxel far from the others' (claimed first, so the
    border regions are each taken by the neighbour of its own anchor) and the
    border region it then claims, with its registers."""
    plan = [dict(anchor=(-300, Y + 10, 1), claim=(-3, Y + 10, 1), regs=[(-1, Y, 1), (-3, Y, 1)]),
            dict(anchor=(300, Y + 10, 1), claim=(2, Y + 10, 1), regs=[(0, Y, 1), (2, Y, 1)])]
    if n == 3:
        plan.append(dict(anchor=(1, Y + 10, -300), claim=(1, Y + 10, -4), regs=[(0, Y, -2), (2, Y, -2)]))
    return plan[:n]


def region_of(p):
    return tuple(c // REGION for c in p)


def voxel(m, o):
    a = np.zeros((2, 1, 1, 1), dtype=np.uint8)
    a[0, 0, 0, 0] = m
    a[1, 0, 0, 0] = o
    return a


class Workload:
    def __init__(self, cluster, seed, players_per_server=2, op_timeout=None, pace=0.02, span=0.0):
        self.c = cluster
        self.rng = random.Random(seed)
        self.seed = seed
        self.plan = territory_plan(cluster.n)
        self.registers = [r for p in self.plan for r in p["regs"]]
        self.owner_of = {region_of(r): i + 1 for i, p in enumerate(self.plan) for r in p["regs"]}
        self.players_per_server = players_per_server
        self.op_timeout = op_timeout or max(4.0, 1.5 * cluster.lease_ms / 1000)
        self.pace = pace
        self.lock = threading.Lock()
        self.next_seq = {r: 0 for r in self.registers}
        self.writes = []
        self.health = []      # (time, server id, status or None)
        self.connects = []    # (time, worker, server id, ok)
        self.stop_ev = threading.Event()
        self.threads = []
        self.materials = 22
        # span: the share of edits that write the two registers beside the
        # border of servers 1 and 2 at once: the server that sends one hands
        # its region over to the other (STORE_POSTGRESQL.md, Forwarded edits)
        self.span = span
        self.span_from = None  # only the players of this server send them (None: all)
        self.span_pair = ((-1, Y, 1), (0, Y, 1))
        self.edits = 0

    # --- the territories ----------------------------------------------------
    def _write_once(self, client, pos, m, o, timeout=30):
        return client.write_box(pos, voxel(m, o)).result(timeout=timeout, visible=False)

    def setup(self):
        """Each server claims its anchor's region, then its border region; checked in terrane_leases."""
        for i, p in enumerate(self.plan):
            s = self.c.servers[i]
            ax, ay, az = p["anchor"]
            with terrane.connect(s.address, name="anchor%d" % s.id, position=(ax + 0.5, ay, az + 0.5),
                                 view_distance=48, full_res_radius=16) as cl:
                cl.wait_loaded(timeout=120)
                self.materials = len(cl.materials) - 1
                assert self._write_once(cl, p["anchor"], 3, 200), "anchor write refused"
        for i, p in enumerate(self.plan):
            s = self.c.servers[i]
            with terrane.connect(s.address, name="claim%d" % s.id, position=(0.5, Y + 10, 0.5),
                                 view_distance=64, full_res_radius=32) as cl:
                cl.wait_loaded(timeout=120)
                assert self._write_once(cl, p["claim"], 3, 200), "claim write refused"
        held = {(int(a), int(b), int(c_)): int(o) for a, b, c_, o in
                self.c.psql("SELECT rx, ry, rz, owner FROM terrane_leases")}
        for region, sid in self.owner_of.items():
            if held.get(region) != sid:
                raise RuntimeError("region %s is held by %s, not server %d: %s" % (region, held.get(region), sid, held))

    def holder_map(self):
        return {(int(a), int(b), int(c_)): int(o) for a, b, c_, o in
                self.c.psql("SELECT rx, ry, rz, owner FROM terrane_leases WHERE expires_at > clock_timestamp()")}

    # --- the players --------------------------------------------------------
    def value_of(self, seq):
        # seq 0.. -> (material 1..materials, occupancy 1..255), unique per register
        return 1 + (seq // 255) % self.materials, 1 + seq % 255

    def _connect(self, widx, name, sid):
        s = self.c.servers[sid - 1]
        try:
            cl = terrane.connect(s.address, name=name, position=(0.5, Y + 10, 0.5), view_distance=64,
                                 full_res_radius=32)
            cl.wait_loaded(timeout=self.op_timeout + 5)
            self.connects.append((time.time(), widx, sid, True))
            return cl
        except Exception:
            self.connects.append((time.time(), widx, sid, False))
            return None

    def _player(self, widx, home):
        rng = random.Random(self.seed * 1000 + widx)
        name = "p%d" % widx
        sid = home
        client = None
        while not self.stop_ev.is_set():
            if client is None or client.closed:
                if client is not None:
                    client.close()
                client = self._connect(widx, name, sid)
                if client is None:
                    sid = sid % self.c.n + 1  # fail over round the ring
                    self.stop_ev.wait(0.5)
                    continue
            if self.span and self.span_from in (None, home) and rng.random() < self.span:
                regs = list(self.span_pair)
            else:
                regs = [rng.choice(self.registers)]
            cells = []
            with self.lock:
                self.edits += 1
                edit = self.edits
                for reg in regs:
                    seq = self.next_seq[reg]
                    self.next_seq[reg] += 1
                    cells.append(Write(id=len(self.writes), edit=edit, player=name, worker=widx, reg=reg,
                                       value=self.value_of(seq), server=sid, start=time.time()))
                    self.writes.append(cells[-1])
            arr = np.zeros((2, 1, 1, len(cells)), dtype=np.uint8)
            for k, c in enumerate(cells):
                arr[0, 0, 0, k], arr[1, 0, 0, k] = c.value
            w = Write()
            try:
                client.write_box(regs[0], arr).result(timeout=self.op_timeout, visible=False)
                w.outcome = "acked"
            except (terrane.EditRejected, terrane.EditOutcomeUnknown) as e:
                w.reason = str(e)
                unknown = isinstance(e, terrane.EditOutcomeUnknown)
                w.outcome = "unknown" if unknown else "refused"
                if w.outcome == "unknown":  # the server timed the edit out: fail over as on a timeout
                    client.close()
                    client = None
                    sid = sid % self.c.n + 1
            except (TimeoutError, ConnectionError) as e:
                w.reason = "%s: %s" % (type(e).__name__, e)
                w.outcome = "unknown"
                client.close()
                client = None
                sid = sid % self.c.n + 1
            except Exception as e:  # anything else: the outcome is not known
                w.reason = "%s: %s" % (type(e).__name__, e)
                w.outcome = "unknown"
            w.end = time.time()
            for c in cells:
                c.outcome, c.reason, c.end = w.outcome, w.reason, w.end
            if w.outcome == "refused":
                self.stop_ev.wait(0.2)
            elif self.pace:
                self.stop_ev.wait(rng.uniform(0, 2 * self.pace))
        if client is not None:
            client.close()

    def _health(self):
        while not self.stop_ev.is_set():
            t = time.time()
            for s in self.c.servers:
                status = None
                try:
                    h = http.client.HTTPConnection(s.host, s.health_url[1], timeout=0.8)
                    h.request("GET", "/health")
                    status = h.getresponse().status
                    h.close()
                except Exception:
                    status = None
                self.health.append((t, s.id, status, self.c.can_store(s)))
            self.stop_ev.wait(max(0.0, 1.0 - (time.time() - t)))

    def start(self):
        widx = 0
        for s in self.c.servers:
            for _ in range(self.players_per_server):
                th = threading.Thread(target=self._player, args=(widx, s.id), daemon=True)
                th.start()
                self.threads.append(th)
                widx += 1
        th = threading.Thread(target=self._health, daemon=True)
        th.start()
        self.threads.append(th)

    def stop(self):
        self.stop_ev.set()
        for th in self.threads:
            th.join(self.op_timeout + 30)

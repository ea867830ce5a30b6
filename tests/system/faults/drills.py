"""The drills: one fault each, aimed at a moment, its timing drawn from the
seed. A drill runs on a fresh cluster: the territories are set up, the
workload runs a few seconds, the fault comes, the workload runs on through
the recovery, then every fault is healed, the servers are stopped and the
checker reads PostgreSQL."""
import os
import random
import signal
import subprocess
import threading
import time

from faults import audit, checker
from faults.cluster import Cluster
from faults.workload import Workload, region_of

GRACE = 2.0  # seconds /health may lag a change of reality
# How long a drill holds a chunk row waiting for its moment: well under
# the lease (5 s) and the servers' lock_timeout (10 s). A write held longer
# makes its server's lease renewal wait on the lease rows that write locked,
# and the server loses its leases for a reason of the drill's making.
AIM_S = 3.0


class Drill:
    def __init__(self, cluster, workload, rng, log):
        self.c = cluster
        self.w = workload
        self.rng = rng
        self.log = log
        self.lease = cluster.lease_ms / 1000
        self.fault_start = None
        self.fault_end = None
        self.victim = None           # a server id, or None (PostgreSQL)
        self.victim_regions = set()
        self.notes = []
        self.aim = min(AIM_S, 0.6 * self.lease)

    def sleep(self, s):
        time.sleep(max(0.0, s))

    def pick_victim(self):
        self.victim = self.rng.randint(1, self.c.n)
        self.victim_regions = {r for r, sid in self.w.holder_map().items() if sid == self.victim}
        return self.c.servers[self.victim - 1]

    def wait_sql(self, sql, timeout):
        """Polls a count query inside the database (every 2 ms) until it is positive; True if it was."""
        # pg_stat_activity is read once per transaction unless its snapshot is cleared.
        q = ("DO $$ DECLARE t timestamptz := clock_timestamp(); BEGIN "
             "LOOP PERFORM pg_stat_clear_snapshot(); EXIT WHEN (%s) > 0; "
             "IF clock_timestamp() - t > interval '%f seconds' THEN "
             "RAISE EXCEPTION 'timeout'; END IF; PERFORM pg_sleep(0.002); END LOOP; END $$" % (sql, timeout))
        try:
            self.c.psql(q, timeout=timeout + 10)
            return True
        except Exception:
            return False

    def block_chunk(self, reg):
        """Holds the row lock of a register's chunk from a session of our own
        (psql reading stdin): a write transaction of that chunk stops inside,
        holding its lease row. Returns the psql process; release() ends it."""
        cx, cy, cz = (v // 32 for v in reg)
        p = subprocess.Popen([os.path.join(self.c.pgbin, "psql"), "-h", self.c.pg_host, "-p", "5432", "-U",
                              "terrane", "-d", "postgres", "-X", "-q"], stdin=subprocess.PIPE,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True)
        p.stdin.write("BEGIN; SELECT 1 FROM terrane_chunks WHERE x = %d AND y = %d AND z = %d FOR UPDATE;\n"
                      % (cx, cy, cz))
        p.stdin.flush()
        return p

    def release(self, p):
        try:
            p.stdin.write("COMMIT;\n\\q\n")
            p.stdin.close()
            p.wait(10)
        except Exception:
            p.kill()

    def victim_reg(self):
        regs = [r for r in self.w.registers if self.w.owner_of[region_of(r)] == self.victim]
        return self.rng.choice(regs)


# --- the drills -------------------------------------------------------------
def sigstop_past_lease(d):
    """SIGSTOP of a server for 1.5-2.5 lease times, then SIGCONT."""
    s = d.pick_victim()
    pause = d.lease * d.rng.uniform(1.5, 2.5)
    d.fault_start = time.time()
    s.signal(signal.SIGSTOP)
    d.sleep(pause)
    s.signal(signal.SIGCONT)
    d.fault_end = time.time()
    d.notes.append("server %d stopped %.1f s" % (d.victim, pause))


def pause_in_write_tx(d):
    """SIGSTOP of a server inside a write transaction (its lease row locked):
    its chunk row is held by a session of ours until its write waits on it,
    then the server is stopped and the row let go; it stays stopped past
    idle_in_transaction_session_timeout (10 s) and its lease."""
    s = d.pick_victim()
    reg = d.victim_reg()
    blocker = d.block_chunk(reg)
    aimed = d.wait_sql("SELECT count(*) FROM pg_stat_activity WHERE host(client_addr) = '%s' "
                       "AND wait_event_type = 'Lock' AND backend_xid IS NOT NULL" % s.host, d.aim)
    d.fault_start = time.time()
    s.signal(signal.SIGSTOP)
    d.release(blocker)
    pause = max(12.0, d.lease * d.rng.uniform(2.2, 3.0))
    d.sleep(pause)
    s.signal(signal.SIGCONT)
    d.fault_end = time.time()
    d.notes.append("server %d stopped %.1f s %s" % (d.victim, pause,
                                                   "inside a write transaction" if aimed else "(not caught inside a write)"))


def kill9_forwarded(d):
    """kill -9 of a server whose write transaction is under way (held at a
    chunk row lock of ours) while forwarded edits wait in its inbox; the
    server is started again 1.5-2.5 lease times later."""
    s = d.pick_victim()
    reg = d.victim_reg()
    blocker = d.block_chunk(reg)
    aimed = d.wait_sql("SELECT (SELECT count(*) FROM pg_stat_activity WHERE host(client_addr) = '%s' "
                       "AND wait_event_type = 'Lock') * (SELECT count(*) FROM terrane_inbox WHERE to_server = %d)"
                       % (s.host, s.id), d.aim)
    inbox = d.c.psql("SELECT count(*) FROM terrane_inbox WHERE to_server = %d" % s.id)[0][0]
    d.fault_start = time.time()
    s.kill()
    d.c.mark(s.id)
    d.release(blocker)
    d.notes.append("server %d killed %s, %s forwarded edits in its inbox" % (
        d.victim, "inside a write transaction" if aimed else "(not caught inside a write)", inbox))
    d.sleep(d.lease * d.rng.uniform(1.5, 2.5))
    s.start()
    d.fault_end = time.time()


def kill9_in_handover(d):
    """kill -9 of a server in the middle of a handover: at the drill's moment
    the other server's players start to send one edit in two across the
    border of servers 1 and 2, so that server hands its border region over
    (releases it) and forwards the edit to the victim (once: the victim
    then holds both). The victim is killed as soon as such an edit waits in
    its inbox while the sender no longer holds its region (released, or
    taken by the victim); started again 1.5-2.5 lease times later."""
    victim = d.rng.randint(1, 2)
    d.victim = victim
    s = d.c.servers[victim - 1]
    other = 3 - victim
    d.w.span_from = other
    d.w.span = 0.5
    given = region_of(d.w.span_pair[other - 1])  # the sender's border region
    aimed = d.wait_sql(
        "SELECT (SELECT count(*) FROM terrane_inbox WHERE to_server = %d AND from_server = %d)"
        " * (SELECT count(*) FROM terrane_leases WHERE (rx, ry, rz) = (%d, %d, %d)"
        "    AND NOT (owner = %d AND expires_at > clock_timestamp()))" % ((victim, other) + given + (other,)),
        15)  # no row held here: it may wait
    d.victim_regions = {r for r, sid in d.w.holder_map().items() if sid == victim} | {given}
    d.fault_start = time.time()
    s.kill()
    d.c.mark(s.id)
    left = d.c.psql("SELECT count(*) FROM terrane_inbox WHERE to_server = %d AND from_server = %d"
                    % (victim, other))[0][0]
    d.notes.append("server %d killed %s; %s of server %d's forwarded edits left in its inbox" % (
        victim, "in a handover of region %s" % (given,) if aimed else "(no handover seen)", left, other))
    d.sleep(d.lease * d.rng.uniform(1.5, 2.5))
    s.start()
    d.fault_end = time.time()


def pg_restart(d):
    """pg_ctl restart -m fast."""
    d.fault_start = time.time()
    d.c.pg_restart()
    d.fault_end = time.time()
    d.notes.append("restart took %.1f s" % (d.fault_end - d.fault_start))


def pg_kill9(d):
    """kill -9 of the postmaster, started again at once (when its old backends have gone)."""
    d.fault_start = time.time()
    d.c.pg_kill9()
    d.sleep(d.rng.uniform(0.0, 0.5))
    d.c.pg_start()
    d.fault_end = time.time()
    d.notes.append("PostgreSQL down %.1f s" % (d.fault_end - d.fault_start))


def _pg_outage(d, lo, hi):
    """PostgreSQL down for a drawn fraction of the lease: a fast shutdown (its
    sessions ended, no crash recovery after), started again so that it
    accepts connections when the time is up (a start takes about 0.5 s here)."""
    target = d.lease * d.rng.uniform(lo, hi)
    d.fault_start = time.time()
    d.c.pg_stop("fast")
    d.sleep(target - (time.time() - d.fault_start) - 0.5)
    d.c.pg_start()
    d.fault_end = time.time()
    d.notes.append("PostgreSQL down %.1f s (drawn %.1f s, lease %.1f s)" % (d.fault_end - d.fault_start, target,
                                                                           d.lease))


def pg_outage_under(d):
    """PostgreSQL down for 0.6-0.85 of a lease time: the servers should ride it out."""
    _pg_outage(d, 0.6, 0.85)


def pg_outage_over(d):
    """PostgreSQL down for 1.2-1.5 lease times."""
    _pg_outage(d, 1.2, 1.5)


def partition(d):
    """A server cut from PostgreSQL (both ways, dropped) for 19 s; its clients still reach it."""
    s = d.pick_victim()
    d.fault_start = time.time()
    d.c.cut(s.id)
    d.sleep(19.0)
    d.c.heal(s.id)
    d.fault_end = time.time()
    d.notes.append("server %d cut from PostgreSQL 19 s" % d.victim)


DRILLS = {
    "sigstop-past-lease": sigstop_past_lease,
    "pause-in-write-tx": pause_in_write_tx,
    "kill9-forwarded": kill9_forwarded,
    "kill9-in-handover": kill9_in_handover,
    "pg-restart": pg_restart,
    "pg-kill9": pg_kill9,
    "pg-outage-under": pg_outage_under,
    "pg-outage-over": pg_outage_over,
    "partition-19s": partition,
}
QUICK = "pg-restart"


# --- one run ----------------------------------------------------------------
def run(name, build, seed, servers, lease_ms, log, players=2, keep_logs=None):
    rng = random.Random("%s/%d" % (name, seed))
    c = Cluster(build, servers=servers, lease_ms=lease_ms)
    try:
        c.start()
        w = Workload(c, seed, players_per_server=players)
        w.setup()
        d = Drill(c, w, rng, log)
        w.start()
        t0 = time.time()
        time.sleep(rng.uniform(3.0, 6.0))
        DRILLS[name](d)
        time.sleep(2 * d.lease + 5)
        w.stop()
        t1 = time.time()
        # Heal everything, let the inboxes drain, stop the servers, read.
        for sid in list(c.cuts):
            c.heal(sid)
        for s in c.servers:
            if s.stopped:
                s.signal(signal.SIGCONT)
        if not c.pg_up:
            c.pg_start()
        deadline = time.time() + 3 * d.lease
        while time.time() < deadline:
            if c.psql("SELECT count(*) FROM terrane_inbox")[0][0] == "0":
                break
            time.sleep(0.5)
        exits = {}
        for s in c.servers:
            if s.proc is not None and s.proc.poll() is not None:
                exits[s.id] = s.proc.returncode
        for s in c.servers:
            s.terminate()
        log_rows = checker.read_log(c, w.registers)
        final = checker.read_final(c, w.registers)
        result = checker.check(w.writes, log_rows, final, w.registers)
        result["audit"] = audit.check(c)
        result.update(measure(d, w, c, t0, t1))
        result["exits"] = exits
        result["server_logs"] = {s.id: exit_lines(s) for s in c.servers}
        result["notes"] = d.notes
        result["inbox_left"] = c.psql("SELECT count(*) FROM terrane_inbox")[0][0]
        if keep_logs:
            c.save_logs(os.path.join(keep_logs, "%s-%d" % (name, seed)))
        return result
    finally:
        c.stop()


def exit_lines(s):
    """The server's lines that say why it stopped or what it could not store."""
    out = []
    for line in s.log_text().splitlines():
        if "[critical]" in line or "[error]" in line or "lost" in line.lower() and "lease" in line.lower():
            out.append(line[:300])
    return out[-8:]


def measure(d, w, c, t0, t1):
    acked = [x for x in w.writes if x.outcome == "acked"]
    # takeover: from the fault to the first ack of a write started after it
    # in the victim's regions; PostgreSQL faults: to the first ack anywhere
    # once PostgreSQL is back (writes resumed)
    takeover = None
    if d.fault_start is not None:
        if d.victim is None:
            cand = [x.end for x in acked if x.end >= (d.fault_end or d.fault_start)]
        else:
            cand = [x.end for x in acked if x.start >= d.fault_start and region_of(x.reg) in d.victim_regions]
        takeover = (min(cand) - d.fault_start) if cand else float("inf")
    # client downtime: per player, the longest gap without an acknowledged write
    downtime = []
    for widx in sorted({x.worker for x in w.writes}):
        ends = sorted(x.end for x in acked if x.worker == widx)
        points = [t0] + ends + [t1]
        downtime.append(max(b - a for a, b in zip(points, points[1:])))
    # /health against reality
    mismatch, ok200_cannot, not200_can = 0, 0, 0
    last = {}
    trans = list(c.transitions)
    for (t, sid, status, real) in w.health:
        if sid in last and last[sid] != real:
            trans.append((t, sid))
        last[sid] = real
    for (t, sid, status, real) in w.health:
        if any(0 <= t - tt < GRACE and (ts is None or ts == sid) for tt, ts in trans):
            continue
        if (status == 200) != real:
            mismatch += 1
            if status == 200:
                ok200_cannot += 1
            else:
                not200_can += 1
    db_text = [x.reason for x in w.writes if x.reason and any(k in x.reason for k in
                                                                ("libpq", "server closed the connection",
                                                                 "could not connect", "connection to server",
                                                                 "SSL", "FATAL", "ERROR:", "terminating connection",
                                                                 "SQLSTATE", "could not receive", "could not send",
                                                                 "PQ"))]
    reasons = {}
    for x in w.writes:
        if x.reason:
            key = x.reason[:120]
            reasons[key] = reasons.get(key, 0) + 1
    return dict(takeover=takeover, downtime=downtime, health_mismatch=mismatch, health_200_cannot=ok200_cannot,
                health_not200_can=not200_can, db_text=len(db_text), reasons=reasons, writes=len(w.writes),
                fault=(d.fault_start - t0 if d.fault_start else None,
                       d.fault_end - t0 if d.fault_end else None))

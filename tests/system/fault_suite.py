#!/usr/bin/env python3
"""Terrane's cluster fault suite: Jepsen-style drills of several
terrane-servers sharing one PostgreSQL world (tests/system/README.md).

    fault_suite.py [DRILL|all|quick] [--repeats N] [--seed S] [--servers 2|3]
                   [--build DIR] [--lease-ms MS] [--json FILE] [--logs DIR]

Runs as root (network namespaces). Prints one row per drill; exits 1 when
an acknowledged write was lost, a write was applied twice, or the audit
found a chunk written outside its writer's lease or a revision written by
two servers (or a run failed); 2 on a usage error; 77 where it cannot run
(not root, no PostgreSQL)."""
import argparse
import fcntl
import glob
import json
import os
import signal
import statistics
import sys
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.dont_write_bytecode = True
CANNOT_RUN = 77  # not root, or no PostgreSQL: CTest counts it as skipped


def pct(xs, p):
    xs = sorted(x for x in xs if x is not None)
    if not xs:
        return None
    return xs[min(len(xs) - 1, int(round(p * (len(xs) - 1))))]


def fmt_s(x):
    if x is None:
        return "-"
    if x == float("inf"):
        return "never"
    return "%.1f" % x


COLUMNS = ["drill", "runs", "acked", "refused", "unknown", "lost", "double", "out-of-order", "refused-applied",
           "audit", "takeover p50/max s", "downtime p50/max s", "health≠reality", "db-text", "exits"]


def row(name, results):
    runs = len(results)
    ok = [r for r in results if "error" not in r]
    s = lambda k: sum(r[k] for r in ok)
    take = [r["takeover"] for r in ok]
    down = [max(r["downtime"]) for r in ok if r["downtime"]]
    audit = sum(len(r["audit"]["outside"]) + len(r["audit"]["double_servers"]) for r in ok)
    exits = sum(len(r["exits"]) for r in ok)
    return [name, "%d%s" % (runs, "" if len(ok) == runs else " (%d failed)" % (runs - len(ok))),
            s("acked"), s("refused"), s("unknown"), s("lost"), s("double"), s("out_of_order"), s("refused_applied"),
            audit, "%s/%s" % (fmt_s(pct(take, 0.5)), fmt_s(pct(take, 1.0))),
            "%s/%s" % (fmt_s(pct(down, 0.5)), fmt_s(pct(down, 1.0))),
            "%d (%d 200 unable)" % (s("health_mismatch"), s("health_200_cannot")), s("db_text"), exits]


def table(rows):
    out = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in rows:
        out.append("| " + " | ".join(str(v) for v in r) + " |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("drill", nargs="?", default="all", help="a drill (tests/system/README.md), all, or quick "
                    "(pg-restart, one run)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--servers", type=int, default=2, choices=(2, 3))
    ap.add_argument("--build", default="build", help="the build directory (bin/, python/); default build")
    ap.add_argument("--lease-ms", type=int, default=5000)
    ap.add_argument("--players", type=int, default=2, help="players per server")
    ap.add_argument("--json", help="write every run's findings here")
    ap.add_argument("--logs", help="keep each run's server and PostgreSQL logs under this directory")
    ap.add_argument("-v", "--verbose", action="store_true", help="print each run's findings")
    a = ap.parse_args()
    # SIGTERM (a timeout, say) ends the run as Ctrl-C does: the cluster is taken down.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    if os.geteuid() != 0:
        print("fault suite: needs root (network namespaces, blackhole routes)", file=sys.stderr)
        return CANNOT_RUN
    if not glob.glob("/usr/lib/postgresql/*/bin/postgres"):
        print("fault suite: PostgreSQL is not installed (scripts/install-deps.sh installs it)", file=sys.stderr)
        return CANNOT_RUN
    from faults import drills
    names = list(drills.DRILLS) if a.drill == "all" else [drills.QUICK] if a.drill == "quick" else [a.drill]
    for n in names:
        if n not in drills.DRILLS:
            print("fault suite: no drill %r (%s)" % (n, ", ".join(drills.DRILLS)), file=sys.stderr)
            return 2
    lock = open("/tmp/terrane-fault-suite.lock", "w")
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        print("fault suite: another run holds /tmp/terrane-fault-suite.lock (the drills' addresses are fixed)",
              file=sys.stderr)
        return 2
    all_results, rows, failed = {}, [], False
    for n in names:
        results = []
        for k in range(a.repeats):
            seed = a.seed + k
            t = time.time()
            print("[%s] %s seed %d (%d servers, lease %d ms)..." % (time.strftime("%H:%M:%S"), n, seed, a.servers,
                                                                   a.lease_ms), file=sys.stderr, flush=True)
            try:
                r = drills.run(n, a.build, seed, a.servers, a.lease_ms, log=None, players=a.players,
                               keep_logs=a.logs)
            except Exception as e:
                r = dict(error="%s: %s" % (type(e).__name__, e), trace=traceback.format_exc())
                print(r["trace"], file=sys.stderr)
            r["seed"] = seed
            r["seconds"] = round(time.time() - t, 1)
            results.append(r)
            summary(n, r, a.verbose)
            if "error" in r or r["lost"] or r["double"] or r["audit"]["outside"] or r["audit"]["double_servers"]:
                failed = True
        all_results[n] = results
        rows.append(row(n, results))
    print(table(rows))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(all_results, f, indent=1, default=str)
    return 1 if failed else 0


def summary(name, r, verbose):
    if "error" in r:
        print("  %s seed %d: ERROR %s" % (name, r["seed"], r["error"]), file=sys.stderr)
        return
    print("  %s seed %d (%.0f s): %s; acked %d refused %d unknown %d lost %d double %d out-of-order %d "
          "refused-applied %d; audit: %d chunk writes, %d outside a lease, %d revisions by two servers; "
          "takeover %s s; downtime max %s s; health≠reality %d (200 while unable %d); db-text %d; exits %s"
          % (name, r["seed"], r["seconds"], "; ".join(r["notes"]), r["acked"], r["refused"], r["unknown"], r["lost"],
             r["double"], r["out_of_order"], r["refused_applied"], r["audit"]["writes"], len(r["audit"]["outside"]),
             len(r["audit"]["double_servers"]), fmt_s(r["takeover"]), fmt_s(max(r["downtime"] or [0])),
             r["health_mismatch"], r["health_200_cannot"], r["db_text"], r["exits"] or "none"),
          file=sys.stderr)
    detail = r["lost_writes"] + r["double_writes"] + r["refused_logged"] + r["ooo"] + r["rows_vs_log"]
    for line in detail[: (50 if verbose else 5)]:
        print("    " + line, file=sys.stderr)
    if verbose:
        for k, v in sorted(r["reasons"].items(), key=lambda kv: -kv[1]):
            print("    reason x%d: %s" % (v, k), file=sys.stderr)
        for sid, lines in r["server_logs"].items():
            for line in lines:
                print("    server %d: %s" % (sid, line), file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())

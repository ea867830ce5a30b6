#!/usr/bin/env python3
"""Print who edits what near a point, as it happens.

    PYTHONPATH=build/python python3 examples/python/watch.py --server 127.0.0.1:7777 --radius 48

Stands at --at (default: the server's spawn) holding --radius at full
resolution. Every update batch the server sends names the voxels that
changed (as the 4^3 units the server sends); presence says who is around.
For each changed region it prints the tick, the region, the materials it
now holds and the player nearest to it (the likely editor); and who comes
into view and leaves it. Stops after --count changes or --duration seconds
(default: never); Ctrl-C stops it too.
"""
import argparse
import collections
import sys
import threading
import time

import terrane


def describe(c, lo, hi):
    """'Brick 12, Air 4': the region's voxels by material, as the replica holds them now."""
    box = c.read_box(lo, hi)
    counts = collections.Counter(box[0].ravel().tolist())
    names = c.materials
    return ", ".join("%s %d" % (names[m] if m < len(names) else m, n) for m, n in counts.most_common())


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default="127.0.0.1:7777", help="HOST:PORT of the terrane-server")
    p.add_argument("--name", default="watcher")
    p.add_argument("--token", default="")
    p.add_argument("--at", help="X,Y,Z to watch from (default: the spawn)")
    p.add_argument("--radius", type=int, default=48, help="watch this far (full resolution), default 48")
    p.add_argument("--count", type=int, default=0, help="stop after this many changes (0: never)")
    p.add_argument("--duration", type=float, default=0, help="stop after this many seconds (0: never)")
    a = p.parse_args()
    at = None
    if a.at:
        try:
            at = tuple(float(v) for v in a.at.split(","))
            assert len(at) == 3
        except (ValueError, AssertionError):
            p.error("--at wants X,Y,Z, not '%s'" % a.at)
    if not 1 <= a.radius <= 256:
        p.error("--radius must be 1..256")

    done = threading.Event()
    lock = threading.Lock()
    players = {}   # id -> position, from the latest presence
    pending = []   # (arrival time, update) not yet printed
    printed = [0]

    with terrane.connect(a.server, name=a.name, token=a.token, position=at, view_distance=max(a.radius, 64),
                         full_res_radius=a.radius) as c:
        c.wait_loaded(timeout=120)
        print("watching %d voxels around (%.0f, %.0f, %.0f)" % (a.radius, *c.position), flush=True)

        def report(u):
            for lo, hi in u.regions:
                centre = [(l + h) / 2 for l, h in zip(lo, hi)]
                who = "nobody in view"
                if players:
                    pid, pos = min(players.items(), key=lambda kv: sum((p - q) ** 2 for p, q in zip(kv[1], centre)))
                    dist = sum((p - q) ** 2 for p, q in zip(pos, centre)) ** 0.5
                    who = "player %d at (%.0f, %.0f, %.0f), %.0f away" % (pid, *pos, dist)
                print("tick %d: %s-%s by %s: %s" % (u.tick, lo, hi, who, describe(c, lo, hi)), flush=True)
                printed[0] += 1
                if a.count and printed[0] >= a.count:
                    done.set()

        def flush(older_than):
            """Prints the updates that arrived before older_than (seconds ago)."""
            with lock:
                now = time.monotonic()
                while pending and now - pending[0][0] >= older_than:
                    report(pending.pop(0)[1])

        # An update is printed at the next presence (about twice a second
        # while anyone is in view), so its editor, who may have just
        # arrived, is known; or after a second if no presence comes.
        @c.on_presence
        def on_presence(p):
            with lock:
                now = {pl.id: pl.position for pl in p.players}
                for pid in sorted(now.keys() - players.keys()):
                    print("player %d came into view at (%.0f, %.0f, %.0f)" % (pid, *now[pid]), flush=True)
                for pid in sorted(players.keys() - now.keys()):
                    print("player %d left the view" % pid, flush=True)
                players.clear()
                players.update(now)
            flush(0)

        @c.on_update
        def on_update(u):
            with lock:
                pending.append((time.monotonic(), u))

        @c.on_disconnect
        def on_disconnect(d):
            print("disconnected: %s" % d.reason, flush=True)
            done.set()

        deadline = time.monotonic() + a.duration if a.duration > 0 else None
        try:
            while not done.wait(0.25):
                flush(1.0)
                if deadline and time.monotonic() > deadline:
                    break
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())

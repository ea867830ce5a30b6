#!/usr/bin/env python3
"""A bot walks to the nearest hillside and digs a tunnel into it.

    PYTHONPATH=build/python python3 examples/python/tunnel.py --server 127.0.0.1:7777

It looks along eight directions from where it stands for the first place
where the ground rises steeply (a hillside), walks to its foot with walk_to,
then digs forward a step at a time (dig, wait for the server's
acknowledgement, walk into the new space) until the tunnel is --length long
or comes out the other side. The last line says where the tunnel runs.
"""
import argparse
import sys

import terrane

DIRECTIONS = [(1, 0), (0, 1), (-1, 0), (0, -1)]


def hillsides(c, reach, rise):
    """(distance, foot (x, y, z), direction) of each hillside in reach, nearest first."""
    x0, _, z0 = (int(v) for v in c.position)
    found = []
    for dx, dz in DIRECTIONS:
        for k in range(1, reach):
            x, z = x0 + dx * k, z0 + dz * k
            g = c.ground(x, z)
            ahead = [c.ground(x + dx * i, z + dz * i) for i in range(1, 5)]
            if g is None or None in ahead or not c.holds((x, g - 1, z), (x + 1, g + 2, z + 1)):
                break
            if max(ahead) - g >= rise:
                found.append((k, (x, g, z), (dx, dz)))
                break
    return sorted(found)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default="127.0.0.1:7777", help="HOST:PORT of the terrane-server")
    p.add_argument("--name", default="tunneller")
    p.add_argument("--token", default="")
    p.add_argument("--length", type=int, default=16, help="voxels to dig at most (default 16)")
    p.add_argument("--reach", type=int, default=40, help="how far to look for a hillside (default 40)")
    p.add_argument("--rise", type=int, default=4, help="a hillside rises this much within 4 voxels (default 4)")
    a = p.parse_args()
    if a.length < 1 or a.reach < 2 or a.rise < 2:
        p.error("--length must be >= 1, --reach >= 2 and --rise >= 2")

    with terrane.connect(a.server, name=a.name, token=a.token, view_distance=128,
                         full_res_radius=max(48, a.reach + 8)) as c:
        c.wait_loaded(timeout=120)
        candidates = hillsides(c, a.reach, a.rise)
        if not candidates:
            print("no hillside within %d voxels of %s" % (a.reach, c.position), file=sys.stderr)
            return 2
        for distance, foot, (dx, dz) in candidates:
            try:
                c.walk_to(foot, speed=16)
                break
            except terrane.Unreachable as e:
                print("hillside %d voxels away at %s: %s" % (distance, foot, e))
        else:
            print("no hillside could be reached", file=sys.stderr)
            return 2
        x, y, z = foot
        print("at the foot of a hillside at %s, digging toward (%d, %d)" % (foot, dx, dz))
        dug = 0
        for k in range(1, a.length + 1):
            tx, tz = x + dx * k, z + dz * k
            inside = (c.ground(tx, tz) or y) > y + 3
            # A 3-wide, 3-high round tunnel, its floor at the foot's height.
            c.dig((tx + 0.5, y + 1.5, tz + 0.5), 2.0).result(30)
            c.fill_box((tx, y - 1, tz), (tx + 1, y, tz + 1), "Rock").result(30)  # a floor to walk on
            c.walk_to((tx, y, tz), speed=16)
            dug = k
            print("dug %d/%d" % (k, a.length), flush=True)
            if not inside and k > 3:
                break  # out the other side
        print("tunnel %d long from %s to %s" % (dug, (x + dx, y, z + dz), (x + dx * dug, y, z + dz * dug)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

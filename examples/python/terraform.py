#!/usr/bin/env python3
"""Smooth and paint a patch of ground, like a terrain brush tool.

    PYTHONPATH=build/python python3 examples/python/terraform.py \\
        --server 127.0.0.1:7777 --radius 12 --material Grass

Strokes a brush over every --spacing voxels of a disc of --radius around
--center (default: where the client stands): at each stroke it smooths the
surface (smooth, --strength) and then paints it (paint, --material), waiting
for the server to acknowledge each edit. It reports how rough the surface
was before and after: the mean height difference between neighbouring
columns.
"""
import argparse
import sys
import time

import terrane


def roughness(c, cx, cz, radius):
    """Mean |height difference| between neighbouring columns of the disc (columns the replica holds)."""
    heights = {}
    for x in range(cx - radius, cx + radius + 1):
        for z in range(cz - radius, cz + radius + 1):
            if (x - cx) ** 2 + (z - cz) ** 2 <= radius * radius:
                g = c.ground(x, z)
                if g is not None:
                    heights[(x, z)] = g
    diffs = [abs(h - heights[(x + 1, z)]) for (x, z), h in heights.items() if (x + 1, z) in heights]
    diffs += [abs(h - heights[(x, z + 1)]) for (x, z), h in heights.items() if (x, z + 1) in heights]
    return sum(diffs) / max(len(diffs), 1)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default="127.0.0.1:7777", help="HOST:PORT of the terrane-server")
    p.add_argument("--name", default="terraformer")
    p.add_argument("--token", default="")
    p.add_argument("--center", help="X,Z of the patch (default: where the client stands)")
    p.add_argument("--radius", type=int, default=12, help="radius of the patch in voxels (default 12, at most 40)")
    p.add_argument("--brush", type=float, default=3.0, help="brush radius (default 3)")
    p.add_argument("--spacing", type=int, default=3, help="voxels between strokes (default 3)")
    p.add_argument("--strength", type=float, default=0.6, help="smoothing strength in (0, 1] (default 0.6)")
    p.add_argument("--passes", type=int, default=1, help="smoothing passes (default 1)")
    p.add_argument("--material", default="Grass", help="paint material (default Grass)")
    a = p.parse_args()
    if not 1 <= a.radius <= 40 or a.spacing < 1 or a.passes < 1:
        p.error("--radius must be 1..40, --spacing and --passes at least 1")

    with terrane.connect(a.server, name=a.name, token=a.token, view_distance=128, full_res_radius=64) as c:
        c.wait_loaded(timeout=120)
        if a.center:
            try:
                cx, cz = (int(v) for v in a.center.split(","))
            except ValueError:
                p.error("--center wants X,Z integers, not '%s'" % a.center)
            c.move_to((cx + 0.5, c.ground(cx, cz) or c.position[1], cz + 0.5))
            c.wait_loaded(radius=a.radius + a.brush + 1, timeout=120)
        else:
            cx, _, cz = (int(v) for v in c.position)
        if a.material not in c.materials:
            p.error("unknown material '%s': this world has %s" % (a.material, ", ".join(c.materials)))
        before = roughness(c, cx, cz, a.radius)
        strokes = [(x, z) for x in range(cx - a.radius, cx + a.radius + 1, a.spacing)
                   for z in range(cz - a.radius, cz + a.radius + 1, a.spacing)
                   if (x - cx) ** 2 + (z - cz) ** 2 <= a.radius * a.radius]
        start = time.monotonic()
        edits = 0
        for n in range(a.passes):
            for i, (x, z) in enumerate(strokes):
                g = c.ground(x, z)
                if g is None:
                    continue
                c.smooth((x + 0.5, g, z + 0.5), a.brush, a.strength).result(60)
                edits += 1
                if n == a.passes - 1:
                    g = c.ground(x, z) or g
                    c.paint((x + 0.5, g - 0.5, z + 0.5), a.brush, a.material).result(60)
                    edits += 1
                if (i + 1) % 10 == 0 or i + 1 == len(strokes):
                    print("pass %d/%d: %d/%d strokes" % (n + 1, a.passes, i + 1, len(strokes)), flush=True)
        c.sync()
        after = roughness(c, cx, cz, a.radius)
        print("%d edits in %.1f s over radius %d at (%d, %d); roughness %.3f -> %.3f" %
              (edits, time.monotonic() - start, a.radius, cx, cz, before, after))
    return 0


if __name__ == "__main__":
    sys.exit(main())

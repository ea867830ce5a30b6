#!/usr/bin/env python3
"""Paste a VXRAW model (a house, a statue, a piece of another world) into the world.

    PYTHONPATH=build/python python3 examples/python/build_from_vxraw.py \\
        --server 127.0.0.1:7777 examples/python/models/house.vxraw

The model (VXRAW, common/vxraw/VXRAW.md; .gz too) is written with write_box in
pieces of at most 32^3 voxels, every voxel as the file has it (Air too, so a
house is hollow). The client moves beside each piece first (edits must lie
within its full-resolution radius) and waits for each piece's
acknowledgement; a piece refused for the edit rate is sent again.
--at X,Y,Z places the model's first voxel; by default the model stands on the
ground a few voxels from the client.
"""
import argparse
import gzip
import struct
import sys
import time

import numpy

import terrane

PIECE = 32


def read_vxraw(path):
    """(origin, array of shape (2, y, z, x)) of a VXRAW file; raises ValueError naming what is wrong."""
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rb") as f:
        data = f.read()
    if len(data) < 32 or data[:8] != b"VXRAW1\0\0":
        raise ValueError("%s: not a VXRAW file (the magic 'VXRAW1' is missing)" % path)
    sx, sy, sz, ox, oy, oz = struct.unpack_from("<6i", data, 8)
    if min(sx, sy, sz) <= 0 or sx * sy * sz > 1 << 28:
        raise ValueError("%s: sizes %d x %d x %d out of range" % (path, sx, sy, sz))
    if len(data) < 32 + 2 * sx * sy * sz:
        raise ValueError("%s: %d bytes, the header promises %d" % (path, len(data), 32 + 2 * sx * sy * sz))
    voxels = numpy.frombuffer(data, dtype=numpy.uint8, count=2 * sx * sy * sz, offset=32)
    box = voxels.reshape(sy, sz, sx, 2).transpose(3, 0, 1, 2).copy()
    bad = numpy.argwhere(box[0] >= 64)
    if len(bad):
        y, z, x = bad[0]
        raise ValueError("%s: material %d at offset %d is not 0..63" %
                         (path, box[0, y, z, x], 32 + 2 * ((y * sz + z) * sx + x)))
    box[1][box[0] == 0] = 0  # Air has occupancy 0
    return (ox, oy, oz), box


def hop_to(c, target, step=40.0):
    """Moves in hops the server's speed rule allows."""
    while True:
        p = c.position
        d = [t - v for t, v in zip(target, p)]
        n = sum(v * v for v in d) ** 0.5
        if n <= step:
            c.move_to(target)
            return
        c.move_to(tuple(v + dv * step / n for v, dv in zip(p, d)))


def write(c, at, piece, tries=20):
    """Sends one piece, again while refused for the rate."""
    for attempt in range(tries):
        try:
            return c.write_box(at, piece).result(60, visible=False)
        except terrane.EditRejected as e:
            if "rate" not in str(e) or attempt == tries - 1:
                raise
            time.sleep(0.1 * (attempt + 1))  # back off: the server's edit rate refilling


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", help="a .vxraw or .vxraw.gz file")
    p.add_argument("--server", default="127.0.0.1:7777", help="HOST:PORT of the terrane-server")
    p.add_argument("--name", default="builder")
    p.add_argument("--token", default="")
    p.add_argument("--at", help="X,Y,Z of the model's first voxel (default: on the ground near the client)")
    a = p.parse_args()
    try:
        _, box = read_vxraw(a.model)
    except (OSError, ValueError) as e:
        print(e, file=sys.stderr)
        return 2
    _, sy, sz, sx = box.shape
    with terrane.connect(a.server, name=a.name, token=a.token, view_distance=128, full_res_radius=64) as c:
        c.wait_loaded(timeout=120)
        if a.at:
            try:
                at = tuple(int(v) for v in a.at.split(","))
                assert len(at) == 3
            except (ValueError, AssertionError):
                p.error("--at wants X,Y,Z integers, not '%s'" % a.at)
        else:
            x, _, z = (int(v) for v in c.position)
            x += 4
            at = (x, c.ground(x, z) or 0, z)
        if int(box[0].max()) >= len(c.materials):
            print("%s: material %d is not one of this world's %d" % (a.model, box[0].max(), len(c.materials)),
                  file=sys.stderr)
            return 2
        pieces = [(y, z, x) for y in range(0, sy, PIECE) for z in range(0, sz, PIECE) for x in range(0, sx, PIECE)]
        start = time.monotonic()
        done = 0
        for i, (y, z, x) in enumerate(pieces):
            part = box[:, y:y + PIECE, z:z + PIECE, x:x + PIECE]
            corner = (at[0] + x, at[1] + y, at[2] + z)
            _, py_, pz, px = part.shape
            centre = (corner[0] + px / 2, corner[1] + py_ / 2, corner[2] + pz / 2)
            hop_to(c, (centre[0], centre[1] + PIECE, centre[2]))
            write(c, corner, part)
            done += part[0].size
            print("piece %d/%d at %s: %d voxels" % (i + 1, len(pieces), corner, part[0].size), flush=True)
        c.sync()
        print("pasted %d voxels (%d x %d x %d) in %d pieces at %s in %.1f s" %
              (done, sx, sy, sz, len(pieces), at, time.monotonic() - start))
    return 0


if __name__ == "__main__":
    sys.exit(main())

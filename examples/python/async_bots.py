#!/usr/bin/env python3
"""Many bots in one asyncio event loop, each building a wall of its own,
while a 10 ms ticker measures how long the loop is ever kept busy.

    PYTHONPATH=build/python python3 examples/python/async_bots.py \\
        --server 127.0.0.1:7777 --bots 50 --edits 30

A Swarm of --bots clients (one io pool, one callbacks thread) joins spread
around the spawn. Each bot is a coroutine: it lays --edits one-voxel Brick
boxes in a wall 6 wide on the ground near it, each sent through terrane.paced
(waits for the server's edit rate as an asyncio sleep) and awaited until the
bot's replica shows it; nothing blocks the loop and no thread waits per
await. Meanwhile a ticker task sleeps 10 ms at a time and keeps the longest
gap between its wake-ups. At the end every bot's wall is checked in its
replica, every replica is verified against the server's chunk hashes, and
one line reports the edits, the time and the ticker's longest gap.
"""
import argparse
import asyncio
import sys
import time

import terrane


async def ticker(stop, gaps):
    last = time.monotonic()
    while not stop.is_set():
        await asyncio.sleep(0.010)
        now = time.monotonic()
        gaps.append(now - last)
        last = now


WIDTH = 6


def wall(x, g, z, n):
    """The n voxels of a wall WIDTH wide on the ground g at (x, z), row by row."""
    return [(x + i % WIDTH, g + 1 + i // WIDTH, z) for i in range(n)]


def place(c, n):
    """The nearest column to c whose wall of n voxels on the ground c holds
    at full resolution (a bot may have joined inside a hill)."""
    x0, _, z0 = (int(v) for v in c.position)
    rows = (n + WIDTH - 1) // WIDTH
    for r in range(0, 25):
        for dx in range(-r, r + 1):
            for dz in (-r, r) if abs(dx) != r else range(-r, r + 1):
                x, z = x0 + dx, z0 + dz
                g = c.ground(x, z)
                if g is not None and c.holds((x, g + 1, z), (x + WIDTH, g + 1 + rows, z + 1)):
                    return x, g, z
    raise RuntimeError("%s holds no ground near %s at full resolution" % (c.name, (x0, z0)))


async def build(c, spot, n):
    x, g, z = spot
    for (vx, vy, vz) in wall(x, g, z, n):
        assert await terrane.paced(c.fill_box, (vx, vy, vz), (vx + 1, vy + 1, vz + 1), "Brick")
    return x, g, z


async def main(a):
    swarm = terrane.Swarm(a.bots, a.server, name=a.name, spread=a.spread, view_distance=64, full_res_radius=32)
    with swarm:
        await terrane.in_thread(swarm.wait_loaded, 300.0)
        spots = [place(c, a.edits) for c in swarm]
        stop, gaps = asyncio.Event(), []
        tick = asyncio.create_task(ticker(stop, gaps))
        start = time.monotonic()
        walls = await asyncio.gather(*(build(c, spot, a.edits) for c, spot in zip(swarm, spots)))
        took = time.monotonic() - start
        stop.set()
        await tick
        for c, (x, g, z) in zip(swarm, walls):
            for v in wall(x, g, z, a.edits):
                if c.voxel(v) != ("Brick", 255):
                    print("%s: %s of its wall is %s, not Brick" % (c.name, v, c.voxel(v)), file=sys.stderr)
                    return 1
        mismatches = await terrane.in_thread(swarm.verify, 300.0)
        print("%d bots, %d edits in %.2f s; longest gap of a 10 ms ticker: %.1f ms; %d chunks differ"
              % (a.bots, a.bots * a.edits, took, max(gaps) * 1000, mismatches))
        return 0 if mismatches == 0 else 1


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--server", default="127.0.0.1:7777", help="HOST:PORT of the terrane-server")
    p.add_argument("--name", default="async-bot", help="name prefix of the bots")
    p.add_argument("--bots", type=int, default=50, help="bots in the loop (default 50)")
    p.add_argument("--edits", type=int, default=30, help="edits per bot: the wall's voxels (default 30, up to 60)")
    p.add_argument("--spread", type=float, default=48.0, help="bots join within this many voxels of the spawn")
    a = p.parse_args()
    if not 1 <= a.bots <= 500 or not 1 <= a.edits <= 60:
        p.error("--bots must be 1..500 and --edits 1..60")
    sys.exit(asyncio.run(main(a)))

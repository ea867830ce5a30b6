#!/usr/bin/env python3
"""Writes house.vxraw: a small brick house (11 x 9 x 9) with a plank floor, a
door, windows of Ice and a stepped slate roof, for build_from_vxraw.py."""
import struct
import sys

import numpy

AIR, SLATE, BRICK, PLANKS, ICE, COBBLE = 0, 3, 5, 7, 18, 17
SX, SY, SZ = 11, 9, 9


def house():
    m = numpy.zeros((SY, SZ, SX), dtype=numpy.uint8)  # (y, z, x): VXRAW order
    m[0] = COBBLE                              # foundation
    m[1:5, :, 0] = m[1:5, :, -1] = BRICK       # walls
    m[1:5, 0, :] = m[1:5, -1, :] = BRICK
    m[1, 1:-1, 1:-1] = PLANKS                  # floor
    m[2:4, 0, 5] = AIR                         # the door
    m[3, 0, 2] = m[3, 0, 8] = m[3, -1, 2] = m[3, -1, 8] = ICE  # windows
    m[3, 4, 0] = m[3, 4, -1] = ICE
    for step in range(4):                      # the roof, stepping in from the long sides
        m[5 + step, step:SZ - step, :] = SLATE
        if SZ - 2 * step > 2:
            m[5 + step, step + 1:SZ - step - 1, 1:-1] = AIR
    return m


def write(path, m, origin=(0, 0, 0)):
    occ = numpy.where(m == AIR, 0, 255).astype(numpy.uint8)
    voxels = numpy.stack([m, occ], axis=-1)  # material, occupancy per voxel
    with open(path, "wb") as f:
        f.write(b"VXRAW1\0\0" + struct.pack("<6i", SX, SY, SZ, *origin) + voxels.tobytes())


if __name__ == "__main__":
    write(sys.argv[1] if len(sys.argv) > 1 else "house.vxraw", house())

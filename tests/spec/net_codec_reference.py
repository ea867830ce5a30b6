#!/usr/bin/env python3
"""A decoder of Terrane network codec units written from common/codec/NET_CODEC.md
alone (kinds 0..5, format versions 1 and 2), run against the document's own worked examples: every
example's bytes are read out of the document and must decode to the voxels
the document says. Exit status 0 when they all do.

    python3 tests/spec/net_codec_reference.py common/codec/NET_CODEC.md
"""
import math
import re
import sys

LIT, RUN, COPYZ, COPYY = 0, 1, 2, 3
AIR = (0, 0)


class DecodeError(Exception):
    pass


class Bits:
    def __init__(self, data):
        self.data, self.pos = data, 0

    def read(self, k):
        v = 0
        for j in range(k):
            byte, bit = divmod(self.pos + j, 8)
            if byte >= len(self.data):
                raise DecodeError("truncated")
            v |= ((self.data[byte] >> bit) & 1) << j
        self.pos += k
        return v

    def finish(self):
        while self.pos % 8:
            if self.read(1):
                raise DecodeError("non-zero padding")
        if self.pos // 8 != len(self.data):
            raise DecodeError("trailing bytes")


def truncated_binary(r, c):
    if c == 1:
        return 0
    b = math.ceil(math.log2(c))
    u = (1 << b) - c
    x = r.read(b - 1)
    if x < u:
        return x
    return 2 * x + r.read(1) - u


def exp_golomb(r, m, max_zeros=12):
    z = 0
    while r.read(1) == 0:
        z += 1
        if z > max_zeros:
            raise DecodeError("Exp-Golomb prefix too long")
    w = (1 << z) + r.read(z)
    return ((w - 1) << m | r.read(m)) + 1


def predict(vox, i, n):
    """Version 2: the occupancy predicted for voxel i from the voxels before it."""
    x, z, y = i % n, (i // n) % n, i // (n * n)
    X, Y, Z = (1, 0, 0), (0, 1, 0), (0, 0, 1)

    def occ(d):
        dx, dy, dz = d
        if x - dx < 0 or y - dy < 0 or z - dz < 0:
            return None
        return vox[((y - dy) * n + (z - dz)) * n + (x - dx)][1]

    def partial(d):
        o = occ(d)
        return o if o is not None and 1 <= o <= 254 else None

    def add(a, b):
        return tuple(p + q for p, q in zip(a, b))

    def mean(values):
        return min(max(sum(values) // len(values), 0), 255)

    planes = []
    for a, b in ((X, Y), (Z, Y), (X, Z)):
        oa, ob, oab = partial(a), partial(b), partial(add(a, b))
        if None not in (oa, ob, oab):
            planes.append(oa + ob - oab)
    if planes:
        return mean(planes)
    lines = []
    for a in (X, Y, Z):
        oa, oaa = partial(a), partial(add(a, a))
        if None not in (oa, oaa):
            lines.append(2 * oa - oaa)
    if lines:
        return mean(lines)
    near = [occ(a) for a in (X, Y, Z) if occ(a) is not None]
    return sum(near) // len(near) if near else 128


def residual(r, order):
    u = exp_golomb(r, order, max_zeros=8) - 1  # the length code carrying u + 1
    if u > 255:
        raise DecodeError("residual over 255")
    return -((u + 1) // 2) if u & 1 else u // 2


def decode(unit, n):
    if not unit or unit[0] & 15 not in (1, 2):
        raise DecodeError("bad version")
    version = unit[0] & 15
    kind, body = unit[0] >> 4, unit[1:]
    size = n ** 3
    if kind == 0:
        return [AIR] * size, 1
    if kind in (1, 2):
        m = body[0]
        if m == 0 or m >= 64:
            raise DecodeError("bad uniform material")
        occ = body[1] if kind == 2 else 255
        return [(m, occ)] * size, 2 + (kind == 2)
    if kind == 5:
        vox = [(body[2 * i], body[2 * i + 1]) for i in range(size)]
        return vox, 1 + 2 * size
    if kind not in (3, 4):
        raise DecodeError("bad kind")
    r = Bits(body)
    k = r.read(6) + 1
    palette = [r.read(6) for _ in range(k)]
    if len(set(palette)) != k:
        raise DecodeError("repeated palette material")
    partial = r.read(1)
    predicted = version == 2 and kind == 3 and partial
    order = r.read(2) if predicted else 0
    vox = [None] * size

    def occupancy(m, i):
        if m == 0:
            return 0
        if predicted:
            return (predict(vox, i, n) + residual(r, order)) % 256
        if partial and kind == 4:
            return r.read(8)
        if partial and r.read(1):
            return r.read(8)
        return 255

    if kind == 4:
        b = math.ceil(math.log2(k)) if k > 1 else 0
        for i in range(size):
            idx = r.read(b)
            if idx >= k:
                raise DecodeError("index beyond the palette")
            vox[i] = (palette[idx], occupancy(palette[idx], i))
    else:
        if r.read(1):  # custom rankings: after Lit, Run, CopyZ, CopyY
            first = r.read(2)
            rest = [t for t in range(4) if t != first]
            second = rest[r.read(2)]
            ranks = {LIT: [first, second] + [t for t in range(4) if t not in (first, second)]}
            for ctx in (RUN, COPYZ, COPYY):
                others = [t for t in range(4) if t != ctx]
                f = others[r.read(2)]
                ranks[ctx] = [f] + [t for t in others if t != f]
        else:
            ranks = {LIT: [RUN, COPYZ, LIT, COPYY], RUN: [COPYZ, LIT, COPYY],
                     COPYZ: [LIT, RUN, COPYY], COPYY: [COPYZ, LIT, RUN]}
        orders = {RUN: 0, COPYZ: 1 if n == 4 else 2, COPYY: 2}
        i, prev = 0, None
        while i < size:
            if prev is None:
                t = LIT
            else:
                rk = ranks[prev]
                if r.read(1) == 0:
                    t = rk[0]
                elif r.read(1) == 0:
                    t = rk[1]
                elif len(rk) == 3 or r.read(1) == 0:
                    t = rk[2]
                else:
                    t = rk[3]
            if t == LIT:
                if partial == 0 and i > 0:
                    p = palette.index(vox[i - 1][0])
                    j = truncated_binary(r, k - 1)
                    idx = j if j < p else j + 1
                else:
                    idx = truncated_binary(r, k)
                vox[i] = (palette[idx], occupancy(palette[idx], i))
                i += 1
            else:
                length = exp_golomb(r, orders[t])
                if i + length > size or (t == COPYZ and i < n) or (t == COPYY and i < n * n):
                    raise DecodeError("token out of range")
                back = {RUN: 1, COPYZ: n, COPYY: n * n}[t]
                for j in range(i, i + length):
                    vox[j] = vox[j - back]
                i += length
            prev = t
    r.finish()
    return vox, len(unit)


def example(doc, kind):
    m = re.search(r"\*\*Kind %d,[^*]*\*\* —\s*`([0-9a-f ]+)`" % kind, doc)
    if not m:
        raise SystemExit("NET_CODEC.md: no worked example of kind %d" % kind)
    return bytes.fromhex(m.group(1).replace(" ", ""))


def main():
    doc = open(sys.argv[1], encoding="utf-8").read()
    n = 4
    index = lambda x, y, z: (y * n + z) * n + x
    failures = []

    def check(kind, unit, want):
        try:
            got, used = decode(unit, n)
        except DecodeError as e:
            failures.append("kind %d: %s" % (kind, e))
            return
        if used != len(unit):
            failures.append("kind %d: %d bytes used of %d" % (kind, used, len(unit)))
        if got != want:
            bad = [i for i in range(len(want)) if got[i] != want[i]][:5]
            failures.append("kind %d: voxels %s differ: %s vs %s" % (kind, bad, [got[i] for i in bad], [want[i] for i in bad]))
        if got == want:
            print("kind %d: %d bytes decode as the document says" % (kind, len(unit)))

    check(0, example(doc, 0), [AIR] * 64)
    check(1, example(doc, 1), [(3, 255)] * 64)
    check(2, example(doc, 2), [(3, 128)] * 64)
    want3 = [AIR] * 64
    for z in range(4):
        for x in range(4):
            want3[index(x, 0, z)] = (1, 255)
            want3[index(x, 1, z)] = (5, 255) if (x, z) == (2, 1) else (2, 255)
    check(3, example(doc, 3), want3)
    m = re.search(r"The materials of voxels 0\.\.63:\s*`([0-9 \n]+)`", doc)
    if not m:
        raise SystemExit("NET_CODEC.md: kind 4's materials not found")
    check(4, example(doc, 4), [(int(v), 255) for v in m.group(1).split()])
    # Kind 5: the document shows the rule and the ends of the bytes.
    raw = bytes([0x51]) + bytes(b for i in range(64) for b in (1 + i % 63, (4 * i + 3) & 255))
    shown = re.search(r"`51`, then for voxel i = 0\.\.63 the bytes \(material,\s*occupancy\) = \(1 \+ i mod 63, 4i \+ 3\):\s*"
                      r"`([0-9a-f ]+) … ([0-9a-f ]+)`", doc)
    if not shown:
        raise SystemExit("NET_CODEC.md: kind 5's bytes not found")
    head, tail = (bytes.fromhex(g.replace(" ", "")) for g in shown.groups())
    if not raw[1:].startswith(head) or not raw.endswith(tail):
        failures.append("kind 5: the bytes shown do not follow the rule")
    check(5, raw, [(1 + i % 63, (4 * i + 3) & 255) for i in range(64)])
    m = re.search(r"\*\*Version 2, kind 3[^*]*\*\* —\s*`([0-9a-f ]+)`", doc)
    if not m:
        raise SystemExit("NET_CODEC.md: no worked example of version 2")
    plane = [AIR] * 64
    for z in range(4):
        for x in range(4):
            plane[index(x, 0, z)] = (1, 40 + 50 * x + 10 * z)
    check(3, bytes.fromhex(m.group(1).replace(" ", "")), plane)
    for f in failures:
        print("FAILED:", f)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()

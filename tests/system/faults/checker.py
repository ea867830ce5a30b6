"""The checker: the workload's record against what PostgreSQL holds.

- The edit log (terrane_edit_log, read after the drill) in id order is each
  region's commit order: ids are drawn inside the write transaction after
  its lease row is locked, and one region's write transactions run one at a
  time under that lock. A register's log rows are the 1-voxel boxes at it;
  the after-image (byte RLE) is the value, which names the write.
- The final value of each register: the chunk rows, through
  `terrane-world export --store` (read-only, replays the units kept beside
  each blob), after the servers stopped.

Findings:
- lost: an acknowledged write missing from the log, or a register whose
  final value is not that of its last logged write (the rows and the log
  disagree), or whose last logged write was refused;
- double-written: a write whose value is in the log more than once (applied
  twice);
- out-of-order: a logged write placed after a write its player made later
  (a player's edits apply in the order sent), or a copy of an acknowledged
  write placed after a write that started once it was acknowledged (a
  stale write over a later one: real-time order);
- refused-applied: a definitely refused write that is in the log.
"""
import os
import struct
import subprocess
import tempfile


class Write:
    """One register's part of an edit (a spanning edit writes two registers: two Writes, one edit id)."""
    __slots__ = ("id", "edit", "player", "worker", "reg", "value", "server", "start", "end", "outcome", "reason")

    def __init__(self, **kw):
        for k in self.__slots__:
            setattr(self, k, kw.get(k))


def decode_rle(hexblob, n):
    """n voxels of byte RLE (common/codec/BYTE_RLE.md): [(material, occupancy)]."""
    b = bytes.fromhex(hexblob)
    out, i = [], 0
    while i < len(b) and len(out) < n:
        lead = b[i]
        i += 1
        m = lead & 0x3F
        occ = 255 if m else 0
        if lead & 0x40:
            occ = b[i]
            i += 1
        count = 1
        if lead & 0x80:
            count = b[i] + 1
            i += 1
        out.extend([(m, occ)] * count)
    return out[:n]


def read_log(cluster, registers):
    """The log rows that wrote a register: (id, player, register, value), in id order."""
    regs = set(registers)
    rows = cluster.psql("SELECT id, player, x0, y0, z0, x1, y1, z1, encode(after, 'hex'), tick "
                        "FROM terrane_edit_log WHERE (x1 - x0) * (y1 - y0) * (z1 - z0) <= 64 ORDER BY id")
    log = []
    for (i, player, x0, y0, z0, x1, y1, z1, after, tick) in rows:
        x0, y0, z0, x1, y1, z1 = map(int, (x0, y0, z0, x1, y1, z1))
        sx, sz = x1 - x0, z1 - z0
        n = sx * (y1 - y0) * sz
        voxels = decode_rle(after, n)
        for k, v in enumerate(voxels):  # Box order: x fastest, then z, then y
            p = (x0 + k % sx, y0 + k // (sx * sz), z0 + (k // sx) % sz)
            if p in regs:
                log.append(dict(id=int(i), player=player, reg=p, value=v, tick=int(tick)))
    return log


def read_final(cluster, registers):
    xs = [r[0] for r in registers]
    ys = [r[1] for r in registers]
    zs = [r[2] for r in registers]
    box = (min(xs), min(ys), min(zs), max(xs) + 1, max(ys) + 1, max(zs) + 1)
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "regs.vxraw")
        r = subprocess.run([os.path.join(cluster.bin, "terrane-world"), "export", "--store", cluster.url,
                            "--box", ",".join(map(str, box)), "--raw", out],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=120)
        if r.returncode != 0:
            raise RuntimeError("terrane-world export: " + r.stdout)
        data = open(out, "rb").read()
    assert data[:8] == b"VXRAW1\0\0", "not VXRAW"
    sx, sy, sz, ox, oy, oz = struct.unpack("<6i", data[8:32])
    final = {}
    for (x, y, z) in registers:
        i = ((y - oy) * sz + (z - oz)) * sx + (x - ox)
        final[(x, y, z)] = (data[32 + 2 * i], data[33 + 2 * i])
    return final


def check(writes, log, final, registers):
    by_value = {}
    for w in writes:
        by_value[(w.reg, w.value)] = w
    in_log = {}
    per_reg = {r: [] for r in registers}
    unrecorded = []
    for pos, e in enumerate(log):
        w = by_value.get((e["reg"], e["value"]))
        if e["reg"] not in per_reg:
            continue
        if w is None:
            unrecorded.append(e)  # a value no write of the workload had (the initial setup aside)
            continue
        in_log.setdefault(w.id, []).append(pos)
        per_reg[e["reg"]].append((pos, w))

    out = dict(acked=0, refused=0, unknown=0, lost=0, double=0, out_of_order=0, refused_applied=0,
               lost_writes=[], double_writes=[], refused_logged=[], ooo=[], rows_vs_log=[], unrecorded=len(unrecorded))
    counted = set()
    for w in writes:
        if w.outcome is None:
            continue
        if w.edit not in counted:  # outcomes per edit; the rest per register written
            counted.add(w.edit)
            out[w.outcome] += 1
        n = len(in_log.get(w.id, []))
        if w.outcome == "acked" and n == 0:
            out["lost"] += 1
            out["lost_writes"].append(describe(w))
        if n > 1:
            out["double"] += 1
            out["double_writes"].append(describe(w) + " logged %d times" % n)
        if w.outcome == "refused" and n > 0:
            out["refused_applied"] += 1
            out["refused_logged"].append(describe(w) + " refused, yet logged")

    bad = {}  # misplaced write id -> (register, the write, [(why, the write it went over)])
    for reg, entries in per_reg.items():
        for i in range(len(entries)):
            pi, wi = entries[i]
            for j in range(i + 1, len(entries)):
                pj, wj = entries[j]
                # wj is placed after wi:
                if wj.edit == wi.edit:
                    continue
                if wj.worker == wi.worker and wj.start < wi.start:
                    why = "its player's later write"
                elif wj.outcome == "acked" and wj.end is not None and wi.start > wj.end:
                    why = "a write started after its ack"
                else:
                    continue
                bad.setdefault(wj.id, (reg, wj, []))[2].append((why, wi))
    for reg, wj, over in bad.values():
        why, last = over[-1]
        out["ooo"].append("register %s: %s applied after %d writes placed before it, the last %s (%s) %s %s" % (
            reg, describe(wj), len(over), why, last.player, last.value, last.outcome))
    for reg, entries in per_reg.items():  # the rows against the log
        last = entries[-1][1] if entries else None
        got = final.get(reg)
        want = last.value if last else None
        if last is not None and got != want:
            out["rows_vs_log"].append("register %s holds %s, its last logged write is %s" % (reg, got, want))
            out["lost"] += 1
        elif last is not None and last.outcome == "refused":
            out["rows_vs_log"].append("register %s holds %s, written by a refused write" % (reg, got))
    out["out_of_order"] = len(bad)
    return out


def describe(w):
    return "%s %s=%s via server %s [%.2f, %.2f] %s %s" % (
        w.player, w.reg, w.value, w.server, w.start, w.end or -1, w.outcome, w.reason or "")

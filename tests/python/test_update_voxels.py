"""Update events with each changed voxel's old and new value (opt-in),
against a real server on 127.0.0.1."""
import threading

import pytest

import terrane
from test_events import covers


def _spot(c):
    x, _, z = (int(v) for v in c.position)
    return x, c.ground(x, z), z


def _inside(p, lo, hi):
    return all(lo[i] <= p[i] < hi[i] for i in range(3))


def _merge(got, voxels, lo, hi):
    """Adds an update's changes inside [lo, hi) to got {p: (first old, last new)}."""
    for p, old, new in voxels:
        if _inside(p, lo, hi):
            got[p] = (got[p][0] if p in got else old, new)


def _queued_changes(c, lo, hi, want):
    """Changes inside [lo, hi) from the queued updates until they name every position of want (an edit may
    span chunks: one update per chunk)."""
    got = {}
    while not want <= got.keys():
        u = c.next_event("update", 30)
        assert u.voxels is not None
        _merge(got, u.voxels, lo, hi)
    return got


def _chunk_box(c, size):
    """A box of size^3 voxels inside the client's chunk (one update batch), 4 voxels in from its corner."""
    x, g, z = _spot(c)
    base = [(v // 32) * 32 + 4 for v in (x, g, z)]
    return tuple(base), tuple(b + size for b in base)


def test_updates_carry_no_voxels_unless_asked(server):
    with terrane.connect(server.address, name="plain", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        lo, hi = _chunk_box(c, 2)
        assert c.fill_box(lo, hi, "Brick").result(30)
        while True:
            u = c.next_event("update", 30)
            if covers(u, lo, hi):
                break
        assert u.voxels is None and not u.voxels_truncated


def test_an_update_carries_each_changed_voxel_as_the_replica_held_it_before_and_after(server):
    with terrane.connect(server.address, name="watcher", view_distance=64, full_res_radius=32) as w, \
         terrane.connect(server.address, name="editor", view_distance=64, full_res_radius=32) as e:
        w.wait_loaded(timeout=60)
        e.wait_loaded(timeout=60)
        x, g, z = _spot(e)
        lo, hi = (x, g - 1, z), (x + 3, g + 2, z + 3)  # ground and the Air above it
        w.sync(30)
        before = w.read_box(lo, hi)  # (2, y, z, x)
        brick = w.materials.index("Brick")
        want = {}
        for dy in range(hi[1] - lo[1]):
            for dz in range(hi[2] - lo[2]):
                for dx in range(hi[0] - lo[0]):
                    old = (int(before[0, dy, dz, dx]), int(before[1, dy, dz, dx]))
                    if old != (brick, 200):
                        want[(lo[0] + dx, lo[1] + dy, lo[2] + dz)] = (old, (brick, 200))
        assert want
        got = {}
        cv = threading.Condition()

        @w.on_update(voxels=True)
        def on_update(u):
            with cv:
                _merge(got, u.voxels, lo, hi)
                cv.notify_all()

        assert callable(on_update)
        assert e.fill_box(lo, hi, "Brick", 200).result(30)
        with cv:
            assert cv.wait_for(lambda: want.keys() <= got.keys(), 30), "the callbacks never saw every changed voxel"
            # Each voxel of the box that was not Brick/200 already, with what the
            # replica held before the edit; those already so are not listed.
            assert got == want
        # The queued updates carry the same; the replica shows "new".
        assert _queued_changes(w, lo, hi, want.keys()) == want
        assert w.voxel(lo) == ("Brick", 200)
        # Undone: the same voxels change back, the brick now being the old value.
        assert e.undo().result(30)
        w.sync(30)
        assert _queued_changes(w, lo, hi, want.keys()) == {p: (new, old) for p, (old, new) in want.items()}


def test_the_voxels_recorded_per_event_are_capped(server):
    with terrane.connect(server.address, name="capped", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        with pytest.raises(ValueError, match="max_voxels"):
            c.record_voxel_changes(1 << 30)
        lo, hi = _chunk_box(c, 4)  # 64 voxels in one chunk
        assert c.fill_box(lo, hi, "Brick").result(30)
        while not covers(c.next_event("update", 30), lo, hi):  # the Brick's update, taken from the queue
            pass
        c.record_voxel_changes(10)
        assert c.fill_box(lo, hi, "Rock").result(30)  # every voxel changes: Brick to Rock
        while True:
            u = c.next_event("update", 30)
            if covers(u, lo, hi):
                break
        assert len(u.voxels) == 10 and u.voxels_truncated
        rock, brick = c.materials.index("Rock"), c.materials.index("Brick")
        assert all(_inside(p, lo, hi) and old == (brick, 255) and new == (rock, 255) for p, old, new in u.voxels)
        c.record_voxel_changes(0)  # stops
        assert c.fill_box(lo, hi, "Brick").result(30)
        while True:
            u = c.next_event("update", 30)
            if covers(u, lo, hi):
                break
        assert u.voxels is None

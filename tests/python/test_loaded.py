"""Loaded events: chunks newly held at full resolution (opt-in), against a
real server on 127.0.0.1."""
import math
import threading

import pytest

import terrane


def test_loaded_events_name_the_chunks_newly_held_at_full_resolution(server):
    with terrane.connect(server.address, name="traveller", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        assert not c.report_loaded
        with pytest.raises(TimeoutError):
            c.next_event("loaded", 0)  # none while nobody asked
        loaded = set()
        cv = threading.Condition()

        @c.on_loaded
        def on_loaded(ev):
            assert ev.kind == "loaded" and ev.chunks
            with cv:
                loaded.update(ev.chunks)
                cv.notify_all()

        assert c.report_loaded
        x, y, z = c.position
        far = (x + 200.5, y, z)
        c.move_to(far)
        target = tuple(math.floor(v) // 32 for v in far)
        with cv:
            assert cv.wait_for(lambda: target in loaded, 60), "the chunk under the new place never loaded"
        # Held at full resolution when its event came; the queue has it too.
        cx, cy, cz = target
        assert c.holds((cx * 32, cy * 32, cz * 32), (cx * 32 + 32, cy * 32 + 32, cz * 32 + 32))
        queued = set()
        while target not in queued:
            queued.update(c.next_event("loaded", 30).chunks)
        c.wait_loaded(timeout=60)
        # Chunks already held are not reported again; switching off stops the queue.
        c.report_loaded = False
        c.sync(30)
        while True:
            try:
                c.next_event("loaded", 0)
            except TimeoutError:
                break
        c.move_to((x + 400.5, y, z))
        c.wait_loaded(timeout=60)
        with pytest.raises(TimeoutError):
            c.next_event("loaded", 0)

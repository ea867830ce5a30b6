"""Events: callbacks on their own thread, the queue behind next_event, and
the asyncio awaitables, against a real server on 127.0.0.1."""
import asyncio
import os
import subprocess
import sys
import threading

import pytest

import terrane
from support import BIN, Server


def covers(update, lo, hi):
    """Some changed region of the update contains the box [lo, hi)."""
    return any(all(a[i] <= lo[i] and hi[i] <= b[i] for i in range(3)) for a, b in update.regions)


def test_an_edit_reaches_update_callbacks_and_the_queue_with_the_replica_already_changed(server):
    with terrane.connect(server.address, name="watcher", view_distance=64, full_res_radius=32) as w, \
         terrane.connect(server.address, name="editor", view_distance=64, full_res_radius=32) as e:
        w.wait_loaded(timeout=60)
        e.wait_loaded(timeout=60)
        x, _, z = (int(v) for v in e.position)
        g = e.ground(x, z)
        lo, hi = (x, g, z), (x + 3, g + 2, z + 3)
        seen = threading.Event()
        at_event = []

        @w.on_update
        def on_update(u):
            if covers(u, lo, hi):
                at_event.append((u, w.voxel(lo)))
                seen.set()

        assert callable(on_update)  # the decorator returns the function
        assert e.fill_box(lo, hi, "Brick").result(30)
        assert seen.wait(30), "no update covering the edit reached the callback"
        update, voxel = at_event[0]
        assert update.kind == "update" and update.tick > 0
        assert voxel == ("Brick", 255), "the replica did not hold the edit when its event ran"
        assert all(len(c) == 2 for c in update.chunks)
        # The same update waits in the queue.
        while True:
            q = w.next_event("update", 30)
            if covers(q, lo, hi):
                break
        assert q.tick == update.tick
        with pytest.raises(TimeoutError):
            w.next_event("message", 0)


def test_presence_names_the_other_clients_in_view(server):
    with terrane.connect(server.address, name="a", view_distance=64, full_res_radius=32) as a, \
         terrane.connect(server.address, name="b", view_distance=64, full_res_radius=32) as b:
        a.wait_ready(30)
        b.wait_ready(30)
        found = threading.Event()
        bx, by, bz = b.position

        def near_b(p):
            return any(abs(pl.position[0] - bx) < 1 and abs(pl.position[2] - bz) < 1 for pl in p.players)

        a.on_presence(lambda p: near_b(p) and found.set())
        assert found.wait(30), "a never saw b in a Presence"
        assert any(abs(pl.position[0] - bx) < 1 for pl in a.presence)
        assert isinstance(a.presence[0].id, int)


def test_presence_says_who_came_into_view_and_who_left(server):
    with terrane.connect(server.address, name="watcher", view_distance=64, full_res_radius=32) as a:
        a.wait_ready(30)
        b = terrane.connect(server.address, name="visitor", view_distance=64, full_res_radius=32)
        b.wait_ready(30)
        bx, _, bz = b.position

        def next_presence(pred):
            while True:
                p = a.next_event("presence", timeout=30)
                if pred(p):
                    return p

        came = next_presence(lambda p: p.joined)
        visitor = [pl for pl in came.joined if abs(pl.position[0] - bx) < 1 and abs(pl.position[2] - bz) < 1]
        assert visitor and came.left == [], came.joined
        vid = visitor[0].id
        assert vid in [pl.id for pl in came.players]
        assert visitor[0].name == "visitor" and [pl.name for pl in a.presence if pl.id == vid] == ["visitor"]
        b.close()
        went = next_presence(lambda p: p.left)
        assert went.left == [vid] and vid not in [pl.id for pl in went.players] and went.joined == []


def test_operator_messages_and_the_disconnect_reach_callbacks_and_waits():
    srv = Server("--admin-token", "secret-token")
    try:
        c = terrane.connect(srv.address, name="listener")
        c.wait_ready(30)
        messages, reasons = [], []
        got_message, got_disconnect = threading.Event(), threading.Event()
        c.on_message(lambda m: (messages.append(m), got_message.set()))
        c.on_disconnect(lambda d: (reasons.append(d.reason), got_disconnect.set()))
        subprocess.run([os.path.join(BIN, "terrane-admin"), "--connect", srv.address, "--token", "secret-token",
                        "say", "hello", "scripts"], check=True, timeout=60, capture_output=True)
        assert got_message.wait(30)
        m = messages[0]
        assert m.kind == "message" and m.type == "say" and "hello scripts" in m.text
        assert c.next_event("message", 30).text == m.text
    finally:
        srv.stop()
    assert got_disconnect.wait(30)
    assert reasons and reasons[0]
    assert c.next_event("disconnect", 30).reason == reasons[0]
    # Nothing more will come: waits raise instead of hanging.
    with pytest.raises(ConnectionError):
        c.next_event("update", 30)
    c.close()


def test_a_failing_callback_is_reported_and_the_next_one_still_runs(server):
    reported = []
    old = sys.unraisablehook
    sys.unraisablehook = lambda u: reported.append(u.exc_value)
    try:
        with terrane.connect(server.address, name="fragile", view_distance=64, full_res_radius=32) as c:
            c.wait_loaded(timeout=60)
            ran = threading.Event()

            def broken(u):
                raise RuntimeError("a bug in a script's callback")

            c.on_update(broken)
            c.on_update(lambda u: ran.set())
            x, _, z = (int(v) for v in c.position)
            g = c.ground(x, z)
            assert c.fill_box((x, g, z), (x + 1, g + 1, z + 1), "Brick").result(30)
            assert ran.wait(30)
            # Reported before the next callback ran.
            assert reported
            assert "a bug in a script's callback" in str(reported[0])
    finally:
        sys.unraisablehook = old


def test_a_callback_may_close_its_own_client(server):
    c = terrane.connect(server.address, name="quitter", view_distance=64, full_res_radius=32)
    c.wait_loaded(timeout=60)
    closed = threading.Event()

    def close_on_update(u):
        c.close()
        closed.set()

    c.on_update(close_on_update)
    x, _, z = (int(v) for v in c.position)
    g = c.ground(x, z)
    c.fill_box((x, g, z), (x + 1, g + 1, z + 1), "Brick")
    assert closed.wait(30)
    assert c.closed


def test_bad_event_arguments_raise():
    srv = Server()
    try:
        with terrane.connect(srv.address, name="args") as c:
            with pytest.raises(ValueError, match="kind must be"):
                c.next_event("weather", 1)
            with pytest.raises(TypeError, match="callable"):
                c.on_update(42)
            with pytest.raises(ValueError, match="timeout"):
                c.next_event("update", -1)
    finally:
        srv.stop()


def test_asyncio_awaits_readiness_edits_and_events(server):
    async def main():
        c = terrane.connect(server.address, name="async", view_distance=64, full_res_radius=32)
        try:
            await terrane.ready(c)
            await terrane.loaded(c, timeout=60)
            x, _, z = (int(v) for v in c.position)
            g = c.ground(x, z)
            ok = await c.fill_box((x, g, z), (x + 2, g + 1, z + 2), "Brick")
            assert ok is True
            while True:
                ev = await terrane.event(c, "update", 30)
                if covers(ev, (x, g, z), (x + 2, g + 1, z + 2)):
                    break
            with pytest.raises(terrane.EditRejected):
                await c.redo()
        finally:
            c.close()

    asyncio.run(main())

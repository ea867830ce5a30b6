"""The terrane Python module against a real terrane-server on 127.0.0.1.

Run by CTest (label unit) as: python3 -m pytest tests/python, with
PYTHONPATH at the built module and TERRANE_BIN_DIR at the server binary.
Every wait has a deadline and waits for a condition.
"""
import signal
import socket
import time

import numpy
import pytest

import terrane
from support import Server


def test_ready_and_loaded_are_true_only_when_true(server):
    with terrane.connect(server.address, name="reader", view_distance=64, full_res_radius=32) as c:
        c.wait_ready(30)
        assert "Air" in c.materials[0]
        c.wait_loaded(timeout=60)
        assert c.loaded
        # At that moment the replica matches the server chunk for chunk.
        assert c.verify(60) == 0


def test_every_edit_kind_round_trips_and_a_second_client_sees_it(server):
    with terrane.connect(server.address, name="a", view_distance=64, full_res_radius=32) as a, \
         terrane.connect(server.address, name="b", view_distance=64, full_res_radius=32) as b:
        a.wait_loaded(timeout=60)
        b.wait_loaded(timeout=60)
        x, y, z = (int(v) for v in a.position)
        y -= 3
        assert a.fill_box((x, y, z), (x + 2, y + 2, z + 2), "Brick").result(30)
        # result() returns once the editor's own replica shows the edit.
        assert a.voxel((x + 1, y + 1, z + 1)) == ("Brick", 255)
        assert a.fill_sphere((x + 0.5, y + 4.5, z + 0.5), 1.5, 5).result(30)
        assert a.paint((x + 0.5, y + 0.5, z + 0.5), 1.0, "Snow").result(30)
        assert a.dig((x + 0.5, y + 4.5, z + 0.5), 1.0).result(30)
        assert a.undo().result(30)
        assert a.redo().result(30)
        # b's replica reaches the server's state, checked by chunk hash.
        deadline = time.monotonic() + 60
        while b.verify(60) != 0:
            assert time.monotonic() < deadline, "b never matched the server"
        assert a.verify(60) == 0
        box = b.read_box((x, y, z), (x + 2, y + 2, z + 2))
        assert box.shape == (2, 2, 2, 2) and box.dtype == numpy.uint8
        assert b.voxel((x + 1, y + 1, z + 1)) == a.voxel((x + 1, y + 1, z + 1))
        assert a.voxel((x, y, z))[0] in ("Brick", "Snow")


def test_queries_and_write_box_agree_with_the_server(server):
    with terrane.connect(server.address, name="q", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, y, z = (int(v) for v in c.position)
        g = c.ground(x, z)
        assert isinstance(g, int) and g <= y + 1
        hit = c.raycast((x + 0.5, g + 2.5, z + 0.5), (0, -1, 0), 64)
        assert hit is not None
        (hx, hy, hz), normal, distance, material = hit
        assert (hx, hz) == (x, z) and hy == g - 1 and normal == (0, 1, 0) and material != "Air"
        assert c.raycast((x + 0.5, g + 2.5, z + 0.5), (0, 1, 0), 8) is None  # open sky
        # A 4x3x2 block of two materials, written and read back from the server.
        lo = (x, g - 3, z)
        block = numpy.zeros((2, 3, 2, 4), dtype=numpy.uint8)
        block[0] = c.materials.index("Brick")
        block[0, :, 1, :] = c.materials.index("Snow")
        block[1] = 255
        assert c.write_box(lo, block).result(30)
        got = c.read_server_box(lo, (x + 4, g, z + 2))
        assert (got == block).all()
        # The replica has the write once it matches the server's hashes.
        deadline = time.monotonic() + 60
        while c.verify(60) != 0:
            assert time.monotonic() < deadline, "the replica never matched the server"
        assert (c.read_box(lo, (x + 4, g, z + 2)) == block).all()
        with pytest.raises(ValueError, match="shape"):
            c.write_box(lo, numpy.zeros((3, 1, 1, 1), dtype=numpy.uint8))
        bad = block.copy()
        bad[0, 0, 0, 0] = 60
        with pytest.raises(ValueError, match="material 60"):
            c.write_box(lo, bad)


def test_rejections_surface_their_reason(server):
    with terrane.connect(server.address, name="r", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, y, z = (int(v) for v in c.position)
        far = c.fill_box((x + 5000, y, z), (x + 5001, y + 1, z + 1), "Brick")
        with pytest.raises(terrane.EditRejected, match="outside the full-resolution region"):
            far.result(30)
        assert far.done() and far.outcome == "rejected"
        with pytest.raises(terrane.EditRejected, match="nothing to redo"):
            c.redo().result(30)


def test_an_edit_a_silent_server_never_answered_has_an_unknown_outcome_not_a_rejection(server):
    # The server is stopped (SIGSTOP) before it reads the edit: the client
    # notices the silence (its keepalives go unanswered, 15 s) and closes,
    # and the edit may or may not have been applied.
    with terrane.connect(server.address, name="patient", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, _, z = (int(v) for v in c.position)
        y = c.ground(x, z) + 2
        stored = c.fill_box((x, y, z), (x + 1, y + 1, z + 1), "Brick")
        assert stored.result(30) and stored.outcome == "applied"
        server.proc.send_signal(signal.SIGSTOP)
        try:
            f = c.fill_box((x, y + 1, z), (x + 1, y + 2, z + 1), "Snow")
            assert f.outcome == "pending" and not f.done()
            with pytest.raises(terrane.EditOutcomeUnknown, match="outcome unknown") as raised:
                f.result(60)
            assert not isinstance(raised.value, terrane.EditRejected)
            assert isinstance(raised.value, RuntimeError)
            assert f.done() and f.outcome == "unknown"
            assert "no answer from the server" in c.disconnect_reason
        finally:
            server.proc.send_signal(signal.SIGCONT)


def test_a_burst_of_edits_is_paced_below_the_servers_rate_not_disconnected(server):
    # The server allows 20 edits/s with a burst of 40 and closes a session
    # beyond them; 60 edits at once are paced by the client instead.
    with terrane.connect(server.address, name="eager", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, _, z = (int(v) for v in c.position)
        y = c.ground(x, z) + 2
        futures = [c.fill_box((x + i % 8, y + i // 8, z), (x + i % 8 + 1, y + i // 8 + 1, z + 1), "Brick")
                   for i in range(60)]
        assert all(f.result(60, visible=False) for f in futures)
        assert not c.closed, c.disconnect_reason


def test_bad_arguments_raise_clear_python_errors(server):
    with terrane.connect(server.address, name="bad") as c:
        c.wait_ready(30)
        with pytest.raises(ValueError, match="unknown material 'Unobtainium'"):
            c.fill_box((0, 0, 0), (1, 1, 1), "Unobtainium")
        with pytest.raises(ValueError, match="unknown material 63"):
            c.fill_box((0, 0, 0), (1, 1, 1), 63)
        with pytest.raises(TypeError):
            c.fill_box((0, 0, 0), (1, 1, 1), 2.5)
        with pytest.raises(TypeError):
            c.voxel("origin")
        with pytest.raises(ValueError, match="within"):
            c.voxel((1 << 30, 0, 0))
        with pytest.raises(ValueError, match="radius"):
            c.dig((0, 0, 0), 100)
        with pytest.raises(ValueError, match="max must exceed min"):
            c.read_box((0, 0, 0), (0, 5, 5))
    with pytest.raises(ValueError, match="not HOST:PORT"):
        terrane.connect("nowhere")


def test_a_closed_server_raises_and_never_hangs():
    # Nothing listens on a port just released.
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(ConnectionError):
        terrane.connect("127.0.0.1:%d" % port)
    srv = Server()
    c = terrane.connect(srv.address, name="left")
    c.wait_ready(30)
    srv.stop()
    with pytest.raises(ConnectionError):
        c.wait_loaded(timeout=60)
    with pytest.raises(ConnectionError):
        c.fill_box((0, 0, 0), (1, 1, 1), "Brick").result(30)
    c.close()

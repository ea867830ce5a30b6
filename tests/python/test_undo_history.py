"""Undo history across a player's sessions: kept for a player whose token
proves who it is (a tokens file), per connection otherwise; against a real
server on 127.0.0.1."""
import os
import tempfile

import pytest

import terrane
from support import Server


def _box(c):
    x, _, z = (int(v) for v in c.position)
    g = c.ground(x, z)
    return (x, g, z), (x + 2, g + 2, z + 2)


def test_an_identified_player_undoes_what_its_previous_session_did():
    tokens = os.path.join(tempfile.mkdtemp(prefix="terrane-py-tokens-"), "tokens.txt")
    with open(tokens, "w") as f:
        f.write("alice alice-secret\nbob bob-secret\n")
    server = Server("--tokens-file", tokens)
    try:
        with terrane.connect(server.address, name="alice", token="alice-secret", view_distance=64,
                             full_res_radius=32) as c:
            c.wait_loaded(timeout=60)
            lo, hi = _box(c)
            before = c.read_box(lo, hi)
            assert c.fill_box(lo, hi, "Brick").result(30)
        # The same player, a new connection: its edit is still its to undo.
        with terrane.connect(server.address, name="alice", token="alice-secret", view_distance=64,
                             full_res_radius=32) as c:
            c.wait_loaded(timeout=60)
            assert c.read_box(lo, hi)[0].min() == c.materials.index("Brick")
            assert c.undo().result(30)
            assert (c.read_box(lo, hi) == before).all()
            assert c.redo().result(30)
            assert c.voxel(lo) == ("Brick", 255)
        # Another player does not get it.
        with terrane.connect(server.address, name="bob", token="bob-secret", view_distance=64,
                             full_res_radius=32) as b:
            b.wait_loaded(timeout=60)
            with pytest.raises(terrane.EditRejected, match="nothing to undo"):
                b.undo().result(30)
    finally:
        server.stop()


def test_without_a_token_that_proves_the_player_the_history_is_per_connection(server):
    # An open server: anyone may take any name, so a name proves nothing.
    with terrane.connect(server.address, name="carol", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        lo, hi = _box(c)
        assert c.fill_box(lo, hi, "Brick").result(30)
    with terrane.connect(server.address, name="carol", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        with pytest.raises(terrane.EditRejected, match="nothing to undo"):
            c.undo().result(30)
        assert c.voxel(lo) == ("Brick", 255)

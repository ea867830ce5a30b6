"""walk_to over the voxel surface of a real server's world."""
import pytest

import terrane


def flat_ground(c, half=10):
    """Clears a (2 half + 1)^2 platform of Brick around the client, stands on it; returns (x, floor y, z)."""
    x, _, z = (int(v) for v in c.position)
    g = c.ground(x, z)
    lo, hi = (x - half, g, z - half), (x + half + 1, g + 24, z + half + 1)
    assert c.fill_box(lo, hi, "Air").result(30)
    assert c.fill_box((x - half, g - 1, z - half), (x + half + 1, g, z + half + 1), "Brick").result(30)
    # result() returned once the replica showed each edit.
    corners = [(x + dx, z + dz) for dx in (-half, 0, half) for dz in (-half, 0, half)]
    assert all(c.voxel((cx, g - 1, cz))[0] == "Brick" and c.voxel((cx, g, cz))[0] == "Air" for cx, cz in corners)
    c.move_to((x + 0.5, g, z + 0.5))
    return x, g, z


def test_walk_to_reaches_a_reachable_target(server):
    with terrane.connect(server.address, name="walker", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, g, z = flat_ground(c)
        # A wall across the way, too high to climb, with a gap at its end.
        assert c.fill_box((x + 3, g, z - 10), (x + 4, g + 4, z + 8), "Rock").result(30)
        assert c.voxel((x + 3, g + 3, z))[0] == "Rock"
        steps = c.walk_to((x + 8, g, z), speed=32)
        assert steps[-1] == (x + 8, g, z)
        prev = (x, g, z)
        for s in steps:
            assert abs(s[0] - prev[0]) <= 1 and abs(s[2] - prev[2]) <= 1 and abs(s[1] - prev[1]) <= 3
            assert c.voxel((s[0], s[1] - 1, s[2]))[0] != "Air" and c.voxel(s)[0] == "Air"
            prev = s
        assert any(s[0] == x + 3 and s[2] >= z + 8 for s in steps), "walked through the wall"
        px, py, pz = c.position
        assert (int(px), int(py), int(pz)) == (x + 8, g, z)
        assert not c.closed, c.disconnect_reason  # the server took every move


def test_walk_to_reports_an_unreachable_target(server):
    with terrane.connect(server.address, name="boxed", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, g, z = flat_ground(c)
        # A closed ring of wall, 4 high, around a 3 x 3 yard at (x - 6, z - 6).
        assert c.fill_box((x - 8, g, z - 8), (x - 3, g + 4, z - 3), "Rock").result(30)
        assert c.fill_box((x - 7, g, z - 7), (x - 4, g + 4, z - 4), "Air").result(30)
        assert c.voxel((x - 3 - 1, g + 3, z - 6))[0] == "Rock" and c.voxel((x - 6, g, z - 6))[0] == "Air"
        with pytest.raises(terrane.Unreachable, match="cannot be reached"):
            c.walk_to((x - 6, g, z - 6), speed=32)
        with pytest.raises(terrane.Unreachable, match="not held at full resolution"):
            c.walk_to((x + 5000, g, z), speed=32)
        with pytest.raises(ValueError, match="speed"):
            c.walk_to((x + 1, g, z), speed=0)
        # Where it stood, it still stands.
        assert (int(c.position[0]), int(c.position[2])) == (x, z)


def test_look_at_faces_the_point_and_target_is_what_is_there(server):
    with terrane.connect(server.address, name="looker", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, g, z = flat_ground(c)
        d = c.look_at((x + 0.5, g, z + 4.5))  # the top of the floor 4 ahead
        assert abs(sum(v * v for v in d) - 1) < 1e-5 and d[2] > 0 and d[1] < 0
        (hx, hy, hz), normal, distance, material = c.target(32)
        assert (hx, hy, hz) == (x, g - 1, z + 4) and material == "Brick" and normal == (0, 1, 0)
        with pytest.raises(ValueError, match="eye"):
            px, py, pz = c.position
            c.look_at((px, py + 1.6, pz))

"""Client.find over the replica: the voxels of a material nearest a point.
Against a real terrane-server on 127.0.0.1."""
import pytest

import terrane


def test_find_returns_the_nearest_voxels_of_a_material_in_order(server):
    with terrane.connect(server.address, name="finder", view_distance=64, full_res_radius=32) as c, \
         terrane.connect(server.address, name="hider", view_distance=64, full_res_radius=32) as h:
        c.wait_loaded(timeout=60)
        h.wait_loaded(timeout=60)
        x, _, z = (int(v) for v in c.position)
        g = c.ground(x, z)
        # Gold is nowhere in a generated world; another client places three.
        gold = "Gold" if "Gold" in c.materials else c.materials[-1]
        assert c.find(gold, within=24, max=10) == [], "the world already has " + gold
        near = (x + 0.5, g + 5.5, z + 0.5)
        spots = [(x + 3, g + 5, z), (x, g + 5, z - 6), (x + 9, g + 5, z + 9)]
        for s in spots:
            assert h.fill_box(s, (s[0] + 1, s[1] + 1, s[2] + 1), gold).result(30)
        c.sync(30)
        assert c.find(gold, near=near, within=24, max=10) == spots  # nearest first
        assert c.find(gold, near=near, within=24) == spots[:1]       # max=1 by default
        assert c.find(gold, near=near, within=7, max=10) == spots[:2]  # 12.7 away: outside
        ids = c.find(c.materials.index(gold), near=near, within=24, max=2)
        assert ids == spots[:2]
        with pytest.raises(ValueError, match="within"):
            c.find(gold, within=65)
        with pytest.raises(ValueError, match="max"):
            c.find(gold, max=0)
        with pytest.raises(ValueError, match="unknown material"):
            c.find("Unobtainium")

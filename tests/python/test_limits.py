"""What a script may ask of a default server, and what it is told when it
asks too much: moves paced within the speed budget, edit sizes refused up
front with the limit named, numpy values taken as Python's. Against a real
terrane-server on 127.0.0.1."""
import numpy
import pytest

import terrane


def test_a_long_move_right_after_joining_is_paced_not_dropped(server):
    with terrane.connect(server.address, name="hasty", view_distance=64, full_res_radius=32) as c:
        c.wait_ready(30)
        x, y, z = c.position
        c.move_to((x + 60, y, z))
        c.move_to((x + 60, y, z + 100))
        assert c.position == pytest.approx((x + 60, y, z + 100))
        c.sync(30)
        assert not c.closed, c.disconnect_reason
        # Farther than ten seconds of the budget: walk, or move in steps.
        with pytest.raises(ValueError, match=r"move_to: 10000 voxels at once; at most 2608"):
            c.move_to((x + 60 + 10000, y, z + 100))


def test_numpy_integers_and_array_likes_are_taken(server):
    with terrane.connect(server.address, name="numpyist", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, _, z = (int(v) for v in c.position)
        g = c.ground(x, z)
        brick = numpy.int64(c.materials.index("Brick"))
        assert c.fill_box((x, g + 1, z), (x + 1, g + 2, z + 1), brick).result(30)
        assert c.voxel((x, g + 1, z)) == ("Brick", 255)
        snow = c.materials.index("Snow")
        assert c.write_box((x, g + 2, z), [[[[snow]]], [[[255]]]]).result(30)
        assert c.voxel((x, g + 2, z)) == ("Snow", 255)
        with pytest.raises(TypeError, match="not bool"):
            c.fill_box((0, 0, 0), (1, 1, 1), numpy.bool_(True))
        with pytest.raises(ValueError, match="shape"):
            c.write_box((x, g + 2, z), [1, 2, 3])


def test_an_edit_over_the_size_limit_raises_value_error_naming_it(server):
    with terrane.connect(server.address, name="big", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        x, y, z = (int(v) for v in c.position)
        with pytest.raises(ValueError, match=r"fill_box: .*262144 voxels \(64\^3\)"):
            c.fill_box((x, y, z), (x + 65, y + 64, z + 64), "Brick")
        # A sphere's edit box is [c - r - 1, c + r + 1) on each axis: radius
        # 32 needs a box of 66^3, over the limit whatever the centre.
        with pytest.raises(ValueError, match=r"dig: .*262144 voxels \(64\^3\).*radius"):
            c.dig((x + 0.5, y + 0.5, z + 0.5), 32)
        # The largest radius the docs promise is taken by a default server.
        assert c.dig((x + 0.5, y + 0.5, z + 0.5), 30.5).result(30)


def test_the_servers_speed_reason_names_the_budget(server):
    # Pacing off (max_speed=0): the server drops the client and says what
    # the move was allowed, as a budget, not a speed the move broke.
    with terrane.connect(server.address, name="unpaced", view_distance=64, full_res_radius=32, max_speed=0) as c:
        c.wait_ready(30)
        x, y, z = c.position
        c.move_to((x + 200, y, z))
        assert c.next_event("disconnect", timeout=30)
        assert c.disconnect_reason.startswith("moving too fast: moved 200 voxels at once, over the ")
        assert "allowed then (the budget: 256 voxels a second since the last move, plus 48)" in c.disconnect_reason

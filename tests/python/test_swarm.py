"""terrane.Swarm: many clients on one shared io pool."""
import pytest

import terrane


def test_a_100_bot_swarm_joins_and_edits_with_no_mismatch(server):
    with terrane.Swarm(100, server.address, name="s", spread=24, view_distance=48, full_res_radius=24) as swarm:
        assert len(swarm) == 100 and swarm[-1].name == "s-99" and swarm[0].name == "s-0"
        swarm.wait_loaded(timeout=300)
        assert all(c.loaded for c in swarm)
        futures = []
        for c in swarm:
            x, _, z = (int(v) for v in c.position)
            g = c.ground(x, z)
            futures.append(c.fill_box((x, g, z), (x + 1, g + 1, z + 1), "Brick"))
        assert all(f.result(120) for f in futures)
        # Every update was queued to its holders before the acks went out,
        # and the hash answers that follow them come after them.
        assert swarm.verify(300) == 0
        assert not any(c.closed for c in swarm)
    assert all(c.closed for c in swarm.clients)


def test_swarm_arguments_are_checked(server):
    with pytest.raises(ValueError, match="n must be"):
        terrane.Swarm(0, server.address)
    with pytest.raises(ValueError, match="threads"):
        terrane.Swarm(2, server.address, threads=0)
    with pytest.raises(IndexError):
        with terrane.Swarm(2, server.address) as s:
            s[2]

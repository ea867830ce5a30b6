"""asyncio without an executor: awaits completed from the library's callbacks
thread through loop.call_soon_threadsafe, pacing as an asyncio sleep,
cancellation that cancels. Against a real terrane-server on 127.0.0.1."""
import asyncio
import concurrent.futures
import inspect
import socket
import threading
import time

import terrane


class NoExecutor(concurrent.futures.ThreadPoolExecutor):
    """A default executor that refuses work: an await that needs a thread fails."""

    def submit(self, fn, *args, **kwargs):
        raise AssertionError("an await took an executor thread")


def _spot(c):
    x, _, z = (int(v) for v in c.position)
    return x, c.ground(x, z), z


async def _started(tasks, timeout=30):
    """Waits on the loop until each task has run up to its first await (a
    condition, with a deadline): one pass of the loop at a time."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while any(inspect.getcoroutinestate(t.get_coro()) == inspect.CORO_CREATED for t in tasks):
        assert loop.time() < deadline, "the tasks never started"
        turn = loop.create_future()
        loop.call_soon(turn.set_result, None)
        await turn


async def _presence_id(a, b):
    """The id under which client a's presence lists client b (at b's position)."""
    while True:
        near_b = [p for p in a.presence if _dist(p.position, b.position) < 1]
        if near_b:
            return near_b[0].id
        await terrane.event(a, "presence", 30)


def test_edits_paced_on_the_loop_never_block_it(server):
    # 60 edits: past the burst, the server's rate (20 a second) paces them
    # for about two seconds. A ticker on the same loop keeps running.
    async def main():
        asyncio.get_running_loop().set_default_executor(NoExecutor())
        with terrane.connect(server.address, name="async-pacer", view_distance=64, full_res_radius=32) as c:
            c.wait_loaded(timeout=60)
            x, g, z = _spot(c)
            stop, gaps = asyncio.Event(), []

            async def ticker():
                last = time.monotonic()
                while not stop.is_set():
                    await asyncio.sleep(0.01)
                    gaps.append(time.monotonic() - last)
                    last = time.monotonic()

            tick = asyncio.create_task(ticker())
            start = time.monotonic()
            results = [await terrane.paced(c.fill_box, (x + i % 8, g + 1 + i // 8, z), (x + i % 8 + 1, g + 2 + i // 8,
                                           z + 1), "Brick") for i in range(60)]
            took = time.monotonic() - start
            stop.set()
            await tick
            assert results == [True] * 60
            assert c.voxel((x + 3, g + 1 + 59 // 8, z)) == ("Brick", 255)
            assert not c.closed, c.disconnect_reason
            # Paced: it took the rate's time, and the loop ran meanwhile.
            assert took > 1.0, took
            print("60 paced edits in %.2f s; longest ticker gap %.1f ms" % (took, max(gaps) * 1000))
            assert max(gaps) < 0.5, max(gaps)

    asyncio.run(main())


def test_many_awaits_hold_no_thread(server):
    async def main():
        asyncio.get_running_loop().set_default_executor(NoExecutor())
        with terrane.connect(server.address, name="async-many", view_distance=64, full_res_radius=32) as c:
            await terrane.loaded(c, timeout=60)
            x, g, z = _spot(c)
            threads = threading.active_count()
            futures = []
            for i in range(16):
                await terrane.pace(c)
                futures.append(c.fill_box((x + i, g + 1, z + 2), (x + i + 1, g + 2, z + 3), "Snow"))
            waits = [asyncio.ensure_future(f) for f in futures] + [asyncio.ensure_future(terrane.synced(c))]
            await asyncio.sleep(0)
            assert threading.active_count() <= threads, "awaits took threads"
            done = await asyncio.gather(*waits)
            assert done[:16] == [True] * 16
            assert all(c.voxel((x + i, g + 1, z + 2)) == ("Snow", 255) for i in range(16))

    asyncio.run(main())


def test_waiting_to_be_ready_and_loaded_holds_no_thread_and_a_cancelled_wait_stops(server):
    def waiting_threads():
        return [t for t in threading.enumerate() if t.name == "terrane-await"]

    async def main():
        asyncio.get_running_loop().set_default_executor(NoExecutor())
        with terrane.connect(server.address, name="async-loading", view_distance=64, full_res_radius=32) as c:
            waits = [asyncio.ensure_future(terrane.ready(c)), asyncio.ensure_future(terrane.loaded(c, timeout=60))]
            await _started(waits)
            assert waiting_threads() == [], "waits took threads"
            await asyncio.gather(*waits)
            assert c.loaded
        # Waits that cannot end (a listener that never says Welcome),
        # cancelled: they end at once and leave nothing waiting behind them.
        with socket.socket() as silent:
            silent.bind(("127.0.0.1", 0))
            silent.listen()
            with terrane.connect("127.0.0.1:%d" % silent.getsockname()[1], name="async-cancelled") as c:
                waits = [asyncio.ensure_future(terrane.ready(c, timeout=60)),
                         asyncio.ensure_future(terrane.loaded(c, timeout=60))]
                await _started(waits)
                assert not any(w.done() for w in waits)
                for w in waits:
                    w.cancel()
                for w in waits:
                    try:
                        await w
                    except asyncio.CancelledError:
                        pass
                assert all(w.cancelled() for w in waits)
                assert waiting_threads() == []

    asyncio.run(main())


def test_a_cancelled_await_is_cancelled_and_sends_nothing(server):
    async def main():
        with terrane.connect(server.address, name="async-cancel", view_distance=64, full_res_radius=32) as c:
            c.wait_loaded(timeout=60)
            x, g, z = _spot(c)
            # Spend the burst, so the next paced edit waits for the rate.
            for i in range(30):
                await terrane.pace(c)
                c.fill_box((x + i % 6, g + 1, z + 4 + i // 6), (x + i % 6 + 1, g + 2, z + 5 + i // 6), "Sand")
            await terrane.synced(c)
            target = (x, g + 3, z + 4)
            before = c.voxel(target)
            task = asyncio.ensure_future(terrane.paced(c.fill_box, target, (x + 1, g + 4, z + 5), "Brick"))
            await asyncio.sleep(0)
            task.cancel()
            try:
                await task
                raise AssertionError("not cancelled")
            except asyncio.CancelledError:
                pass
            # The edit was never sent: after a round trip the voxel is as it was.
            await terrane.synced(c)
            assert c.voxel(target) == before
            # An await of an edit in flight, cancelled, ends at once; the edit
            # is still answered (the library's future), and nothing waits for it.
            f = c.fill_box(target, (x + 1, g + 4, z + 5), "Brick")
            waiting = asyncio.ensure_future(f)
            await asyncio.sleep(0)
            waiting.cancel()
            try:
                await waiting
            except asyncio.CancelledError:
                pass
            assert waiting.cancelled()
            assert f.result(30)
            assert c.voxel(target) == ("Brick", 255)

    asyncio.run(main())


def test_an_await_after_the_connection_closes_raises(server):
    async def main():
        c = terrane.connect(server.address, name="async-closed", view_distance=64, full_res_radius=32)
        c.wait_loaded(timeout=60)
        x, g, z = _spot(c)
        f = c.fill_box((x, g + 1, z + 7), (x + 1, g + 2, z + 8), "Brick")
        assert await f
        c.close()
        assert await f  # answered before: still True
        try:
            await terrane.synced(c)
            raise AssertionError("synced after close returned")
        except ConnectionError:
            pass

    asyncio.run(main())


def test_awaiting_events_holds_no_thread_and_a_cancelled_one_takes_none(server):
    async def main():
        asyncio.get_running_loop().set_default_executor(NoExecutor())
        with terrane.connect(server.address, name="async-listener", view_distance=64, full_res_radius=32) as w, \
             terrane.connect(server.address, name="async-sayer", view_distance=64, full_res_radius=32) as e:
            w.wait_loaded(timeout=60)
            e.wait_loaded(timeout=60)
            while True:  # drain what joining queued
                try:
                    w.next_event(None, 0)
                except TimeoutError:
                    break
            threads = threading.active_count()
            listening = asyncio.ensure_future(terrane.event(w, "update", 30))
            cancelled = asyncio.ensure_future(terrane.event(w, "update", 30))
            await asyncio.sleep(0)
            assert threading.active_count() <= threads, "an await took a thread"
            cancelled.cancel()
            x, g, z = _spot(e)
            assert await terrane.paced(e.fill_box, (x, g + 1, z + 9), (x + 1, g + 2, z + 10), "Brick")
            first = await listening
            assert first.kind == "update"
            # Had the cancelled await gone on waiting in a thread, it would
            # have taken the next update; a second edit's update is there.
            assert await terrane.paced(e.fill_box, (x + 1, g + 1, z + 9), (x + 2, g + 2, z + 10), "Brick")
            await terrane.synced(w)
            seen = []
            while True:
                try:
                    seen.append(w.next_event("update", 0))
                except TimeoutError:
                    break
            assert cancelled.cancelled()
            assert any(any(lo[0] <= x + 1 < hi[0] and lo[2] <= z + 9 < hi[2] for lo, hi in u.regions) for u in seen), \
                [u.regions for u in seen]
            try:
                await terrane.event(w, "message", 0.05)
                raise AssertionError("no message was sent")
            except TimeoutError:
                pass

    asyncio.run(main())


def test_a_walk_steps_on_the_loop_and_a_cancelled_one_stops_where_it_stands(server):
    from test_walk import flat_ground

    async def main():
        asyncio.get_running_loop().set_default_executor(NoExecutor())
        with terrane.connect(server.address, name="async-walker", view_distance=64, full_res_radius=32) as c:
            c.wait_loaded(timeout=60)
            x, g, z = flat_ground(c)
            assert c.can_stand((x + 8, g, z)) and not c.can_stand((x + 8, g - 1, z))
            way = c.find_path((x + 8, g, z))
            assert way[-1] == (x + 8, g, z) and tuple(int(v) for v in c.position) == (x, g, z)  # not moved
            # Walked on the loop: a ticker runs meanwhile.
            ticks = 0

            async def ticker():
                nonlocal ticks
                while True:
                    await asyncio.sleep(0.01)
                    ticks += 1

            tick = asyncio.create_task(ticker())
            steps = await terrane.walk(c, (x + 8, g, z), speed=32)
            assert steps[-1] == (x + 8, g, z) and ticks > 0
            # Cancelled after its first step: it stops there.
            stepped = asyncio.Event()
            walking = asyncio.ensure_future(terrane.walk(c, (x - 8, g, z), speed=4, on_step=lambda _: stepped.set()))
            await asyncio.wait_for(stepped.wait(), 30)
            walking.cancel()
            try:
                await walking
                raise AssertionError("the walk was not cancelled")
            except asyncio.CancelledError:
                pass
            stopped = c.position
            assert int(stopped[0]) > x - 8
            # No thread walks on: the walk is a task of this loop, and it ended.
            tick.cancel()
            await terrane.synced(c)
            assert c.position == stopped and not c.closed, c.disconnect_reason

    asyncio.run(main())


def test_walk_within_a_distance_and_follow_a_player(server):
    from test_walk import flat_ground

    async def main():
        with terrane.connect(server.address, name="follower", view_distance=64, full_res_radius=32) as a:
            a.wait_loaded(timeout=60)
            x, g, z = flat_ground(a)
            # Come within 3 of a point: the walk stops short of it.
            steps = []
            walked = await terrane.walk(a, (x + 8.5, g, z + 0.5), speed=32, within=3, on_step=steps.append)
            assert walked == steps and walked
            assert 1.5 <= _dist(a.position, (x + 8.5, g, z + 0.5)) <= 3
            with terrane.connect(server.address, name="leader", position=(x - 6.5, g, z + 0.5), view_distance=64,
                                 full_res_radius=32) as b:
                b.wait_ready(30)

                bid = await asyncio.wait_for(_presence_id(a, b), 30)
                following = asyncio.ensure_future(terrane.follow(a, bid, distance=2, speed=32))

                async def within(d):
                    while _dist(a.position, b.position) > d:
                        await asyncio.sleep(0.02)

                await asyncio.wait_for(within(2.6), 30)
                b.move_to((x - 2.5, g, z + 7.5))   # the leader moves on; the follower comes after
                await asyncio.wait_for(within(2.6), 30)
                following.cancel()
                try:
                    await following
                except asyncio.CancelledError:
                    pass
                assert not a.closed, a.disconnect_reason

    asyncio.run(main())


def test_keep_away_from_a_point_and_from_a_player_and_a_cancelled_one_stops(server):
    from test_walk import flat_ground

    async def main():
        asyncio.get_running_loop().set_default_executor(NoExecutor())
        with terrane.connect(server.address, name="shy", view_distance=64, full_res_radius=32) as a:
            a.wait_loaded(timeout=60)
            x, g, z = flat_ground(a)
            start = a.position
            # From a point: walks until at least 6 away, reporting each step.
            steps = []
            walked = await terrane.keep_away(a, start, 6, speed=32, on_step=steps.append)
            assert walked == steps and walked
            assert _dist(a.position, start) >= 6
            assert all(a.voxel((s[0], s[1] - 1, s[2]))[0] == "Brick" for s in walked)  # on the platform
            assert await terrane.keep_away(a, start, 6, speed=32) == []  # that far already: no step
            try:
                await terrane.keep_away(a, start, 0)
                raise AssertionError("distance 0 was accepted")
            except ValueError:
                pass
            # From a player standing next to it.
            ax, _, az = a.position
            with terrane.connect(server.address, name="pest", position=(ax + 1, g, az), view_distance=64,
                                 full_res_radius=32) as b:
                b.wait_ready(30)

                bid = await asyncio.wait_for(_presence_id(a, b), 30)
                walked = await terrane.keep_away(a, bid, 5, speed=32)
                assert walked and _dist(a.position, b.position) >= 5
            # Cancelled after its first step: it stops there.
            here = a.position
            stepped = asyncio.Event()
            going = asyncio.ensure_future(terrane.keep_away(a, here, 9, speed=4, on_step=lambda _: stepped.set()))
            await asyncio.wait_for(stepped.wait(), 30)
            going.cancel()
            try:
                await going
                raise AssertionError("keep_away was not cancelled")
            except asyncio.CancelledError:
                pass
            stopped = a.position
            assert _dist(stopped, here) < 9
            await terrane.synced(a)
            assert a.position == stopped and not a.closed, a.disconnect_reason

    asyncio.run(main())


def _dist(p, q):
    return sum((a - b) ** 2 for a, b in zip(p, q)) ** 0.5

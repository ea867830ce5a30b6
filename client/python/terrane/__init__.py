"""Terrane for scripts: connect to a terrane-server, query its world, edit it, walk it.

    import terrane
    with terrane.connect("127.0.0.1:7777", name="digger") as c:
        c.wait_loaded()
        x, z = 10, 10
        c.dig((x, c.ground(x, z), z), 3).result()

The classes come from the C++ client library (terrane._native); waits release
the GIL.

asyncio, natively: ``await future`` (an EditFuture), ``await
terrane.paced(c.fill_box, lo, hi, "Brick")`` (the edit rate's wait as an
asyncio sleep, then the edit, awaited), ``await terrane.pace(c)`` (the
wait alone), ``await terrane.synced(c)``, ``await terrane.event(c, kind)``,
``await terrane.walk(c, target)``, ``follow`` and ``keep_away`` (their
searches aside) hold no thread: the library's callbacks thread completes
them through
``loop.call_soon_threadsafe``, and cancelling one cancels it. An edit sent
without ``pace`` may wait for the rate (blocking the loop): in a
coroutine, send edits through ``paced``. ``await terrane.ready(c)``,
``loaded`` and ``in_thread(fn, *args)`` run the blocking wait on a thread
of their own (not the loop's default executor).
"""
__version__ = "0.1.0"  # the project's version (CMakeLists.txt), read by pip from here

import asyncio as _asyncio
import math as _math
import threading as _threading

from terrane._native import (  # noqa: F401
    Client,
    Disconnect,
    EditFuture,
    EditOutcomeUnknown,
    EditRejected,
    Loaded,
    Message,
    Player,
    Presence,
    Reconnected,
    Swarm,
    Unreachable,
    Update,
    connect,
)

__all__ = [
    "Client", "Disconnect", "EditFuture", "EditOutcomeUnknown", "EditRejected", "Loaded", "Message", "Player", "Presence",
    "Reconnected", "Swarm", "Unreachable", "Update", "connect", "ready", "loaded", "event", "walk", "pace", "paced",
    "synced", "in_thread", "follow", "keep_away", "AIR",
]

AIR = "Air"


def _wake(loop, waiter):
    """From the callbacks thread: completes waiter on its loop."""
    def resolve():
        if not waiter.done():
            waiter.set_result(None)
    try:
        loop.call_soon_threadsafe(resolve)
    except RuntimeError:  # the loop is closed: nobody waits
        pass


async def _woken(register):
    """Waits on the loop until register(fn)'s fn is called (from any thread)."""
    loop = _asyncio.get_running_loop()
    waiter = loop.create_future()
    register(lambda: _wake(loop, waiter))
    await waiter


async def in_thread(fn, *args):
    """Runs a blocking wait on a thread of its own; the loop stays free.
    Cancelling the await leaves the wait to end at its timeout."""
    loop = _asyncio.get_running_loop()
    waiter = loop.create_future()

    def run():
        try:
            value, error = fn(*args), None
        except BaseException as e:  # noqa: B902 - handed to the awaiting task
            value, error = None, e

        def resolve():
            if waiter.done():
                return
            if error is not None:
                waiter.set_exception(error)
            else:
                waiter.set_result(value)
        try:
            loop.call_soon_threadsafe(resolve)
        except RuntimeError:
            pass

    _threading.Thread(target=run, name="terrane-await", daemon=True).start()
    return await waiter


async def pace(client):
    """Waits, as an asyncio sleep, until client may send its next edit within
    the server's edit rate; that edit then goes at once."""
    delay = client._reserve_edit()
    if delay > 0:
        await _asyncio.sleep(delay)


async def paced(edit, *args, **kwargs):
    """``await terrane.paced(c.fill_box, lo, hi, "Brick")``: paces the edit
    (terrane.pace), sends it and awaits its EditFuture. True once applied and
    in the replica; raises as EditFuture.result does."""
    await pace(edit.__self__)
    return await edit(*args, **kwargs)


async def synced(client):
    """Awaitable Client.sync: everything the server sent so far is applied."""
    await _woken(client._when_synced)
    if client.closed:
        client.sync(0)  # raises ConnectionError with the reason


async def _polled(check, timeout, what):
    """Awaits check() (which returns or raises TimeoutError at once) on the
    loop, every 10 ms, holding no thread; a cancelled await stops polling."""
    loop = _asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        try:
            return check()
        except TimeoutError:
            if loop.time() >= deadline:
                raise TimeoutError("not %s within the timeout" % what) from None
        await _asyncio.sleep(0.01)


async def ready(client, timeout=30.0):
    """Awaitable Client.wait_ready, holding no thread."""
    return await _polled(lambda: client.wait_ready(0), timeout, "welcomed")


async def loaded(client, radius=None, timeout=60.0):
    """Awaitable Client.wait_loaded, holding no thread."""
    return await _polled(lambda: client.wait_loaded(radius, 0), timeout, "loaded")


async def event(client, kind=None, timeout=30.0):
    """Awaitable Client.next_event, holding no thread; a cancelled await takes
    no event from the queue."""
    loop = _asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        waiter = loop.create_future()
        client._when_event(lambda: _wake(loop, waiter))
        try:
            return client.next_event(kind, 0)  # queued already (or raises ConnectionError once closed)
        except TimeoutError:
            pass
        left = deadline - loop.time()
        if left <= 0:
            raise TimeoutError("no %s within the timeout" % ("event" if kind is None else kind + " event"))
        try:
            await _asyncio.wait_for(waiter, left)
        except _asyncio.TimeoutError:
            pass  # the loop's next turn raises, unless one came meanwhile


async def walk(client, target, speed=8.0, timeout=120.0, within=0.0, on_step=None):
    """Client.walk_to on the event loop: the way is searched (Client.find_path,
    on a thread of its own) and each step waits as an asyncio sleep, so
    cancelling the await stops the walker where it stands. within: stop once
    the feet are within that many voxels of target (0: at the place to stand
    nearest it). on_step(place) is called after each step. Returns the places
    walked; raises Unreachable, TimeoutError or ConnectionError as walk_to."""
    if not 0 < speed <= 64:
        raise ValueError("walk: speed must be in (0, 64] voxels per second")
    if not within >= 0:
        raise ValueError("walk: within must be >= 0 voxels")
    loop = _asyncio.get_running_loop()
    deadline = loop.time() + timeout
    walked = []
    for _ in range(4):  # the way may change under the walker: searched again a few times
        if within and _math.dist(client.position, target) <= within:
            return walked
        left = deadline - loop.time()
        if left <= 0:
            break
        steps = await in_thread(client.find_path, target, left)
        if not await _steps(client, steps, speed, deadline, walked, on_step,
                            lambda at: within and _math.dist(at, target) <= within):
            continue  # blocked: search again
        return walked
    if deadline - loop.time() <= 0:
        raise TimeoutError("walk: the target was not reached within the timeout")
    raise Unreachable("walk: the way kept changing under the walker")


async def _steps(client, steps, speed, deadline, walked, on_step, arrived):
    """Takes steps on the loop until arrived(position); False if one is blocked."""
    loop = _asyncio.get_running_loop()
    at = client.position
    for s in steps:
        if arrived(at):
            return True
        if not client.can_stand(s):
            return False
        step = (s[0] + 0.5, s[1], s[2] + 0.5)
        pause = _math.dist(at, step) / speed
        if deadline is not None and loop.time() + pause > deadline:
            raise TimeoutError("walk: the target was not reached within the timeout")
        await _asyncio.sleep(pause)
        client.move_to(step)
        at = step
        walked.append(s)
        if on_step is not None:
            on_step(s)
    return True


async def follow(client, player_id, distance=3.0, speed=8.0, on_step=None):
    """Follows another client (a Player id from presence) until cancelled:
    walks toward it whenever it is farther than distance, a few steps at a
    time, searching again as it moves, and waits for the next change (an
    event) while it is near or out of reach. Raises Unreachable once the
    player is no longer in view (presence)."""
    if not 0 < speed <= 64 or not distance >= 0:
        raise ValueError("follow: speed must be in (0, 64] and distance >= 0")

    def where():
        for p in client.presence:
            if p.id == player_id:
                return p.position
        raise Unreachable("follow: player %d is not in view" % player_id)

    while True:
        target = where()
        near = _math.dist(client.position, target) <= distance + 0.5
        if not near:
            try:
                steps = await in_thread(client.find_path, target, 10.0)
            except Unreachable:
                steps = []
            if steps:
                await _steps(client, steps[:4], speed, None, [], on_step,
                             lambda at: _math.dist(at, where()) <= distance + 0.5)
                continue
        await _woken(client._when_event)  # something changed: a move, an edit, a presence


async def keep_away(client, target, distance, speed=8.0, timeout=120.0, on_step=None):
    """Walks until the feet are at least distance voxels from target: a point
    (x, y, z), or a Player id (an int, from presence; its position is read
    again at every step, and a player out of view counts as far enough).
    The place to walk to is searched straight away from the target first,
    then turning by 45 degrees each side, distance + 2 voxels from it; each
    step waits as an asyncio sleep, so cancelling the await stops the walker
    where it stands. on_step(place) is called after each step. Returns the
    places walked ([] when already that far); raises Unreachable when no
    place that far can be reached (walls, or beyond the full-resolution
    radius), TimeoutError or ConnectionError as walk."""
    if not 0 < speed <= 64:
        raise ValueError("keep_away: speed must be in (0, 64] voxels per second")
    if not distance > 0:
        raise ValueError("keep_away: distance must be > 0 voxels")
    by_player = isinstance(target, int)

    def where():
        """The target now; None once a player is out of view."""
        if not by_player:
            return target
        for p in client.presence:
            if p.id == target:
                return p.position
        return None

    def away(at):
        t = where()
        return t is None or _math.dist(at, t) >= distance

    loop = _asyncio.get_running_loop()
    deadline = loop.time() + timeout
    walked = []
    for _ in range(4):  # the target or the way may change: searched again a few times
        if away(client.position):
            return walked
        here, t = client.position, where()
        dx, dz = here[0] - t[0], here[2] - t[2]
        heading = _math.atan2(dz, dx) if dx or dz else 0.0
        reach = distance + 2
        steps = None
        for turn in (0, 1, -1, 2, -2, 3, -3, 4):  # straight away first, then turning each side
            left = deadline - loop.time()
            if left <= 0:
                raise TimeoutError("keep_away: not %g voxels away within the timeout" % distance)
            angle = heading + turn * _math.pi / 4
            goal = (t[0] + _math.cos(angle) * reach, here[1], t[2] + _math.sin(angle) * reach)
            try:
                steps = await in_thread(client.find_path, goal, left)
            except Unreachable:
                continue
            if steps:
                break
        if not steps:
            raise Unreachable("keep_away: no place %g voxels from the target can be reached" % distance)
        await _steps(client, steps, speed, deadline, walked, on_step, away)
        if away(client.position):
            return walked
    if deadline - loop.time() <= 0:
        raise TimeoutError("keep_away: not %g voxels away within the timeout" % distance)
    raise Unreachable("keep_away: the way kept changing under the walker")


async def _edit_outcome(future):
    await _woken(future._when_done)
    return future.result(0, False)  # answered (and shown, or the connection went): at once


def _future_await(self):
    """``await future``: EditFuture.result() without a thread (True once
    applied and in the replica; raises as result does)."""
    return _edit_outcome(self).__await__()


EditFuture.__await__ = _future_await

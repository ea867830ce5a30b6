"""Terrane for scripts: connect to a terrane-server, query its world, edit it, walk it.

    import terrane
    with terrane.connect("127.0.0.1:7777", name="digger") as c:
        c.wait_loaded()
        x, z = 10, 10
        c.dig((x, c.ground(x, z), z), 3).result()

The classes come from the C++ client library (terrane._native); waits release
the GIL. For asyncio, every blocking wait has an awaitable twin here:
``await terrane.ready(c)``, ``await terrane.loaded(c)``,
``await terrane.event(c, "update")``, ``await future`` (an EditFuture) and
``await terrane.walk(c, target)``; each runs the wait on the loop's default
executor, so the event loop never blocks.
"""
__version__ = "0.1.0"  # the project's version (CMakeLists.txt), read by pip from here

import asyncio as _asyncio
import functools as _functools

from terrane._native import (  # noqa: F401
    Client,
    Disconnect,
    EditFuture,
    EditOutcomeUnknown,
    EditRejected,
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
    "Client", "Disconnect", "EditFuture", "EditOutcomeUnknown", "EditRejected", "Message", "Player", "Presence",
    "Reconnected", "Swarm", "Unreachable", "Update", "connect", "ready", "loaded", "event", "walk", "AIR",
]

AIR = "Air"


async def _in_executor(fn, *args, **kwargs):
    loop = _asyncio.get_running_loop()
    return await loop.run_in_executor(None, _functools.partial(fn, *args, **kwargs))


async def ready(client, timeout=30.0):
    """Awaitable Client.wait_ready."""
    return await _in_executor(client.wait_ready, timeout)


async def loaded(client, radius=None, timeout=60.0):
    """Awaitable Client.wait_loaded."""
    return await _in_executor(client.wait_loaded, radius, timeout)


async def event(client, kind=None, timeout=30.0):
    """Awaitable Client.next_event."""
    return await _in_executor(client.next_event, kind, timeout)


async def walk(client, target, speed=8.0, timeout=120.0):
    """Awaitable Client.walk_to."""
    return await _in_executor(client.walk_to, target, speed, timeout)


def _future_await(self):
    return _in_executor(self.result).__await__()


EditFuture.__await__ = _future_await

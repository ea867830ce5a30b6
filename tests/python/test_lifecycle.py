"""Closing, exiting and interrupting: nothing hangs, nothing aborts, nothing leaks."""
import gc
import os
import signal
import subprocess
import sys
import textwrap
import threading
import weakref

import numpy
import pytest

import terrane
from support import Server


def run_script(code, server, timeout=120, until=None):
    """Runs a Python script (with SERVER set) to its end; returns the CompletedProcess."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (env.get("PYTHONPATH"), os.path.dirname(terrane.__path__[0])) if p)
    env["SERVER"] = server.address
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=env)


def test_callbacks_closing_each_others_clients_do_not_deadlock():
    srv = Server()
    try:
        clients = [terrane.connect(srv.address, name="x%d" % i) for i in range(4)]
        for c in clients:
            c.wait_ready(30)
        ran = []
        all_ran = threading.Event()

        def close_everything(d):
            for c in clients:
                c.close()
            ran.append(d)
            if len(ran) == 4:
                all_ran.set()

        for c in clients:
            c.on_disconnect(close_everything)
    finally:
        srv.stop()  # every client hears at once: four callbacks threads each close all four clients
    assert all_ran.wait(60), "the callbacks did not all finish"
    assert all(c.closed for c in clients)


def test_two_threads_closing_one_client_both_return(server):
    c = terrane.connect(server.address, name="twice")
    c.wait_ready(30)
    c.on_update(lambda u: None)  # a callbacks thread to stop
    threads = [threading.Thread(target=c.close) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not any(t.is_alive() for t in threads), "a close() never returned"
    assert c.closed


def test_close_frees_a_client_whose_callback_refers_to_it(server):
    c = terrane.connect(server.address, name="cycle")
    c.wait_ready(30)
    c.on_update(lambda u: c.voxel((0, 0, 0)))
    ref = weakref.ref(c)
    c.close()
    del c
    gc.collect()
    assert ref() is None, "the client outlived close() and its last reference"


def test_on_disconnect_after_the_end_still_fires(server):
    c = terrane.connect(server.address, name="late")
    c.wait_ready(30)
    c.close()
    got = threading.Event()
    c.on_disconnect(lambda d: got.set())
    assert got.wait(30)


def test_ctrl_c_interrupts_a_long_wait(server):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (env.get("PYTHONPATH"), os.path.dirname(terrane.__path__[0])) if p)
    code = textwrap.dedent("""
        import sys, terrane
        c = terrane.connect(sys.argv[1], name="sleeper")
        c.wait_ready(30)
        try:
            # Inside the try: the signal may arrive as soon as this is read.
            print("waiting", flush=True)
            c.next_event("message", 86400)
        except KeyboardInterrupt:
            print("interrupted", flush=True)
    """)
    p = subprocess.Popen([sys.executable, "-c", code, server.address], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert p.stdout.readline().strip() == "waiting"
        p.send_signal(signal.SIGINT)
        out, _ = p.communicate(timeout=30)
        assert "interrupted" in out and p.returncode == 0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_ctrl_c_ends_an_asyncio_script_at_once_outside_a_with_block(server):
    # Awaits hold no executor thread that Python's exit would wait for
    # (outside a with block, 60 s waits kept the process alive 39 s).
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (env.get("PYTHONPATH"), os.path.dirname(terrane.__path__[0])) if p)
    code = textwrap.dedent("""
        import asyncio, sys, terrane
        c = terrane.connect(sys.argv[1], name="async-sleeper")
        async def main():
            await terrane.ready(c)
            waits = [asyncio.ensure_future(terrane.event(c, "message", 60)) for _ in range(8)]
            await asyncio.sleep(0)
            print("waiting", flush=True)
            await asyncio.gather(*waits)
        try:
            asyncio.run(main())
        except KeyboardInterrupt:
            print("interrupted", flush=True)
    """)
    p = subprocess.Popen([sys.executable, "-c", code, server.address], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert p.stdout.readline().strip() == "waiting"
        p.send_signal(signal.SIGINT)
        out, _ = p.communicate(timeout=20)  # well under the waits' 60 s
        assert "interrupted" in out and p.returncode == 0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_exit_with_daemon_threads_still_waiting_is_clean(server):
    r = run_script("""
        import os, threading, terrane
        clients = []
        for i in range(3):
            c = terrane.connect(os.environ["SERVER"], name="d%d" % i)
            c.wait_ready(30)
            c.on_presence(lambda p: None)
            clients.append(c)
        def waiter(c):
            while True:
                try:
                    c.next_event("update", 30)
                except Exception:
                    pass
        started = [threading.Event() for _ in clients]
        for c, s in zip(clients, started):
            threading.Thread(target=lambda c=c, s=s: (s.set(), waiter(c)), daemon=True).start()
        for s in started:
            s.wait(30)
        print("exiting", flush=True)
    """, server)
    assert r.returncode == 0 and "exiting" in r.stdout, r.stdout + r.stderr


def test_more_bad_arguments_raise_clear_errors(server):
    with terrane.connect(server.address, name="args2", view_distance=64, full_res_radius=32) as c:
        c.wait_loaded(timeout=60)
        with pytest.raises(ValueError, match="too large"):
            c.fill_box((0, 0, 0), (1, 1, 1), 2 ** 70)
        with pytest.raises(TypeError, match="not bool"):
            c.fill_box((0, 0, 0), (1, 1, 1), True)
        with pytest.raises(TypeError, match="integers"):
            c.write_box((0, 0, 0), numpy.full((2, 1, 1, 1), 1.7))
        with pytest.raises(ValueError, match="occupancy 300"):
            c.write_box((0, 0, 0), numpy.array([[[[5]]], [[[300]]]]))
        with pytest.raises(ValueError, match="max_nodes"):
            c.walk_to((0, 0, 0), max_nodes=10 ** 9)
        with pytest.raises(TimeoutError):
            c.next_event(None, 0)
        # numpy's default integer arrays are fine.
        x, _, z = (int(v) for v in c.position)
        g = c.ground(x, z)
        block = numpy.array([[[[c.materials.index("Brick")]]], [[[255]]]])
        assert block.dtype == numpy.int64
        assert c.write_box((x, g + 3, z), block).result(30)
        assert c.voxel((x, g + 3, z)) == ("Brick", 255)
    with pytest.raises(ValueError, match="64 bytes"):
        terrane.Swarm(20, server.address, name="n" * 62)

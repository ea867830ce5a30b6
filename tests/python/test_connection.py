"""The connection's life from a script: reconnects, a hung server, a wrong
port, names, close. Against real terrane-servers on 127.0.0.1; every wait
has a deadline and waits for a condition."""
import signal
import socket
import threading

import pytest

import terrane
from support import Server


def _near(c):
    x, _, z = (int(v) for v in c.position)
    return x, c.ground(x, z), z


def test_after_a_reconnect_waits_return_only_once_the_replica_is_consistent():
    srv = Server()
    try:
        a = terrane.connect(srv.address, name="resumer", view_distance=64, full_res_radius=32, reconnect=True)
        a.wait_loaded(timeout=60)
        x, g, z = _near(a)
        for wait in ("wait_loaded", "sync"):
            srv.restart_after_kill()
            # At once: the wait covers the reconnect and the resume.
            getattr(a, wait)(timeout=60)
            # Ready only when true: the server reads a's box, and every
            # full-resolution chunk matches.
            a.read_server_box((x, g, z), (x + 1, g + 1, z + 1))
            assert a.verify(60) == 0
            assert a.next_event("reconnected", timeout=30).kind == "reconnected"
            # Another client's acknowledged edit next to a is in a's replica
            # after a's next wait.
            with terrane.connect(srv.address, name="changer", view_distance=64, full_res_radius=32) as b:
                b.wait_loaded(timeout=60)
                material = "Brick" if wait == "wait_loaded" else "Snow"
                assert b.fill_box((x, g + 1, z), (x + 1, g + 2, z + 1), material).result(30)
            a.sync(timeout=60)
            assert a.voxel((x, g + 1, z)) == (material, 255)
        a.close()
    finally:
        srv.stop()


def test_a_hung_server_is_noticed_even_with_reconnect_on(server):
    # SIGSTOP: the server's socket still accepts connections, but nothing
    # answers. The client closes (reconnecting would wait for ever).
    c = terrane.connect(server.address, name="watcher", view_distance=64, full_res_radius=32, reconnect=True,
                        silence_timeout=1.0)
    gone = threading.Event()
    reasons = []
    c.on_disconnect(lambda d: (reasons.append(d.reason), gone.set()))
    c.wait_loaded(timeout=60)
    server.proc.send_signal(signal.SIGSTOP)
    try:
        assert c.next_event("disconnect", timeout=30).reason.startswith("no answer from the server")
        assert c.closed and gone.wait(30), reasons
        assert "does not answer" in c.disconnect_reason
        with pytest.raises(ValueError, match="silence_timeout"):
            terrane.connect(server.address, silence_timeout=0.01)
    finally:
        server.proc.send_signal(signal.SIGCONT)
    c.close()


def test_a_port_that_is_not_a_terrane_server_says_so():
    # An HTTP server answering anything with 400.
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(4)
    port = listener.getsockname()[1]

    def serve():
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
            conn.close()

    threading.Thread(target=serve, daemon=True).start()
    try:
        c = terrane.connect("127.0.0.1:%d" % port, name="lost")
        with pytest.raises(ConnectionError, match="not a terrane-server") as raised:
            c.wait_ready(30)
        assert "HTTP/1.1 400" in str(raised.value)
        assert "frame length" not in str(raised.value)
        c.close()
    finally:
        listener.close()


def test_a_refused_connection_says_once_where_it_tried():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(ConnectionError) as raised:
        terrane.connect("127.0.0.1:%d" % port)
    assert str(raised.value).count("cannot connect to") == 1, str(raised.value)
    assert "127.0.0.1:%d" % port in str(raised.value)


def test_waits_after_close_raise(server):
    c = terrane.connect(server.address, name="closer", view_distance=64, full_res_radius=32)
    c.wait_loaded(timeout=60)
    c.close()
    with pytest.raises(ConnectionError, match="closed"):
        c.wait_loaded(timeout=5)
    with pytest.raises(ConnectionError, match="closed"):
        c.wait_ready(timeout=5)
    with pytest.raises(ConnectionError, match="closed"):
        c.sync(timeout=5)


def test_a_name_with_a_control_character_is_refused_and_forges_no_log_line(server):
    c = terrane.connect(server.address, name="mallory\nsession 99 (127.0.0.1:1) joined as 'admin' (admin)")
    with pytest.raises(ConnectionError, match="control character"):
        c.wait_ready(30)
    c.close()
    # The server said why in its log, on one line, and no forged line.
    with terrane.connect(server.address, name="after") as d:
        d.wait_ready(30)
    assert not any(line.startswith("session 99") for line in server.output), "".join(server.output)


def test_a_chunk_cache_is_kept_at_close_and_joined_from(server, tmp_path):
    cache = str(tmp_path / "cache")
    a = terrane.connect(server.address, name="keeper", view_distance=96, full_res_radius=32, chunk_cache=cache)
    a.wait_loaded(timeout=60)
    x, g, z = _near(a)
    below = a.voxel((x, g - 1, z))
    a.close()
    # One file per region held, under the world's id.
    assert list((tmp_path / "cache").rglob("*.region"))
    # A new client joins from them: its replica is the server's.
    with terrane.connect(server.address, name="returner", view_distance=96, full_res_radius=32,
                         chunk_cache=cache) as b:
        b.wait_loaded(timeout=60)
        assert b.voxel((x, g - 1, z)) == below
        assert b.verify(60) == 0
    with pytest.raises(ValueError):
        terrane.connect(server.address, chunk_cache="")
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    with pytest.raises(OSError):
        terrane.connect(server.address, chunk_cache=str(blocker / "cache"))

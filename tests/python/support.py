"""What the Python tests share: a real terrane-server on 127.0.0.1.

Every wait has a deadline and waits for a condition.
"""
import os
import re
import shutil
import subprocess
import tempfile
import threading

BIN = os.environ.get("TERRANE_BIN_DIR", "build/bin")
SOURCE_DIR = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


class Server:
    def __init__(self, *extra):
        self.dir = tempfile.mkdtemp(prefix="terrane-py-")
        self.extra = extra
        self.port = None
        self.start(0)

    def start(self, port):
        """Starts terrane-server on port (0: any free one) with this world."""
        self.proc = subprocess.Popen(
            [os.path.join(BIN, "terrane-server"), "--world", os.path.join(self.dir, "world"), "--port", str(port),
             *self.extra],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.output = []
        self.port = None
        ready = threading.Event()

        def read():
            for line in self.proc.stdout:
                self.output.append(line)
                m = re.search(r"listening on 127\.0\.0\.1:(\d+)", line)
                if m and self.port is None:
                    self.port = int(m.group(1))
                    ready.set()
            ready.set()

        self.reader = threading.Thread(target=read, daemon=True)
        self.reader.start()
        assert ready.wait(60) and self.port, "".join(self.output)
        self.address = "127.0.0.1:%d" % self.port

    def restart_after_kill(self):
        """kill -9, then a new process on the same port and world."""
        port = self.port
        self.proc.kill()
        self.proc.wait(60)
        self.reader.join(10)
        self.start(port)

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            assert self.proc.wait(60) == 0, "".join(self.output)
        self.reader.join(10)
        shutil.rmtree(self.dir, ignore_errors=True)

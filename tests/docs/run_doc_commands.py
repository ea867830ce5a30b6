"""Docs.CommandsRun: runs the commands the manual shows, as a reader runs
them. A fenced block after a line '<!-- tested -->' in README.md or
docs/*.md is run; the blocks of one page run in order in one scratch
directory (holding build/bin, build/python, examples and tests as links
into the build and the source), so a page's later blocks see its earlier
ones' worlds, servers and files.

  ```sh      each command (lines joined at a trailing '\\') runs with bash
             and must exit 0. A command ending in '&' (a server) runs in the
             background: the next command waits until its log says
             'listening on' and, for a server with --metrics, until its
             /health says 200 (conditions, with a deadline), and the page's
             background processes are stopped by pid with SIGTERM at the
             end and must exit 0.
  ```python  runs with the Python the module is built for
             (PYTHONPATH=build/python), and must exit 0.

The ports 7777, 7778 (game) and 9464 (metrics) in a page are replaced by
free ports; ADMIN_TOKEN and TERRANE_TOKEN are set in the environment;
where curl is not installed, a stand-in fetches 'curl -s[f] URL'.

usage: run_doc_commands.py SOURCE_DIR BIN_DIR PAGE|all [PYTHON PYTHON_MODULE_DIR]
       (PAGE as README.md or docs/NAME.md; without the Python pair, a page
       with Python blocks fails, saying so)"""
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
from markdown_pages import marked_blocks, pages, read

STARTUP_DEADLINE_S = 60
COMMAND_TIMEOUT_S = 180


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def commands(body):
    """Logical shell commands: continuation lines joined, blank and comment
    lines dropped."""
    out, current = [], ""
    for line in body:
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1] + " "
            continue
        current += line
        if current.strip() and not current.strip().startswith("#"):
            out.append(current.strip())
        current = ""
    return out


CURL_SHIM = """#!PYTHON
import sys, urllib.error, urllib.request
url = [a for a in sys.argv[1:] if not a.startswith("-")][-1]
try:
    with urllib.request.urlopen(url if "://" in url else "http://" + url, timeout=30) as r:
        sys.stdout.buffer.write(r.read())
except urllib.error.HTTPError as e:
    sys.exit(22)
"""

BACKGROUND = re.compile(r"^(.*?)\s+&\s*(#.*)?$")


class Page:
    def __init__(self, name, source_dir, bin_dir, python, module_dir):
        self.name = name
        self.dir = tempfile.mkdtemp(prefix="terrane-docs-")
        os.makedirs(os.path.join(self.dir, "build"))
        os.symlink(bin_dir, os.path.join(self.dir, "build", "bin"))
        if module_dir:
            os.symlink(module_dir, os.path.join(self.dir, "build", "python"))
        for d in ("examples", "tests", "docker", "scripts"):
            os.symlink(os.path.join(source_dir, d), os.path.join(self.dir, d))
        self.python = python
        self.ports = {"7777": str(free_port()), "7778": str(free_port()), "9464": str(free_port())}
        self.env = dict(os.environ, ADMIN_TOKEN="docs-admin-token-1", TERRANE_TOKEN="docs-player-token-1")
        if not shutil.which("curl"):
            # scripts/install-deps.sh does not install curl; the pages use it
            # for /health and /metrics, so stand in for 'curl -s[f] URL'.
            shim = os.path.join(self.dir, "shim")
            os.makedirs(shim)
            with open(os.path.join(shim, "curl"), "w") as f:
                f.write(CURL_SHIM.replace("PYTHON", sys.executable))
            os.chmod(os.path.join(shim, "curl"), 0o755)
            self.env["PATH"] = shim + os.pathsep + self.env.get("PATH", "")
        self.background = []  # (pid, Popen, command, log path)

    def substitute(self, text):
        for port, free in self.ports.items():
            text = re.sub(rf"\b{port}\b", free, text)
        return text

    def fail(self, what, output=""):
        raise AssertionError(f"{self.name}: {what}\n{output}")

    def run_sh(self, command):
        command = self.substitute(command)
        print(f"$ {command}", flush=True)
        m = BACKGROUND.match(command)
        if m:
            log = os.path.join(self.dir, f"background-{len(self.background)}.log")
            with open(log, "w") as out:
                p = subprocess.Popen(["bash", "-c", "exec " + m.group(1)], cwd=self.dir, env=self.env, stdout=out,
                                     stderr=subprocess.STDOUT)
            self.background.append((p.pid, p, command, log))
            self.wait_listening(p, log)
            return
        r = subprocess.run(["bash", "-o", "pipefail", "-c", command], cwd=self.dir, env=self.env,
                           capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
        tail = (r.stdout + r.stderr)[-3000:]
        print(tail, flush=True)
        if r.returncode != 0:
            self.fail(f"'{command}' exited {r.returncode}", tail)

    def wait_listening(self, p, log):
        deadline = time.monotonic() + STARTUP_DEADLINE_S
        while time.monotonic() < deadline:
            with open(log) as f:
                text = f.read()
            metrics = re.search(r"metrics on (http://[0-9.:]+)/metrics", text)
            if "listening on" in text and (metrics or "--metrics" not in p.args[-1]):
                if metrics:
                    self.wait_healthy(p, metrics.group(1) + "/health", deadline)
                print(text.strip().split("\n")[-1], flush=True)
                return
            if p.poll() is not None:
                self.fail(f"exited {p.returncode} before listening", text)
            time.sleep(0.05)  # polling a log file for the condition
        self.fail(f"not listening after {STARTUP_DEADLINE_S} s", open(log).read())

    def wait_healthy(self, p, url, deadline):
        """A server with a metrics endpoint is ready once /health says 200
        (it has ticked and stored)."""
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(url, timeout=5) as r:
                    if r.status == 200:
                        return
            except (urllib.error.URLError, OSError):
                pass
            if p.poll() is not None:
                self.fail(f"exited {p.returncode} before its /health said 200")
            time.sleep(0.05)  # polling /health for the condition
        self.fail(f"{url} did not say 200 within {STARTUP_DEADLINE_S} s")

    def run_python(self, body):
        if not self.python:
            self.fail("has a Python block and the terrane module is not built here")
        code = self.substitute("\n".join(body))
        print(code, flush=True)
        env = dict(self.env, PYTHONPATH=os.path.join(self.dir, "build", "python"))
        r = subprocess.run([self.python, "-c", code], cwd=self.dir, env=env, capture_output=True, text=True,
                           timeout=COMMAND_TIMEOUT_S)
        print(r.stdout + r.stderr, flush=True)
        if r.returncode != 0:
            self.fail(f"the Python block exited {r.returncode}", r.stdout + r.stderr)

    def stop(self):
        problems = []
        for pid, p, command, log in reversed(self.background):
            if p.poll() is None:
                os.kill(pid, signal.SIGTERM)
                try:
                    p.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    os.kill(pid, signal.SIGKILL)
                    p.wait()
                    problems.append(f"'{command}' did not stop within 60 s of SIGTERM")
                    continue
            if p.returncode != 0:
                problems.append(f"'{command}' exited {p.returncode}: " + open(log).read()[-2000:])
        self.background = []
        shutil.rmtree(self.dir, ignore_errors=True)
        if problems:
            self.fail("; ".join(problems))


def main(source_dir, bin_dir, page_name, python=None, module_dir=None):
    names = pages(source_dir) if page_name == "all" else [page_name]
    ran = 0
    for name in names:
        blocks = marked_blocks(read(os.path.join(source_dir, name)), "tested")
        if not blocks:
            continue
        page = Page(name, source_dir, bin_dir, python, module_dir)
        try:
            for line, lang, body in blocks:
                print(f"--- {name}:{line} ({lang})", flush=True)
                if lang == "python":
                    page.run_python(body)
                elif lang in ("sh", "bash"):
                    for command in commands(body):
                        page.run_sh(command)
                else:
                    page.fail(f"line {line}: a tested block in '{lang}', which this test cannot run")
                ran += 1
        finally:
            page.stop()
    print(f"{ran} tested blocks ran in {', '.join(names)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))

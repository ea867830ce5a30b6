"""pip install ./client/python in a fresh virtual environment, offline, with
Debian's tools, then `python -c "import terrane; print(terrane.__version__)"`
from outside the source tree.

    pip_install_check.py SOURCE_DIR BUILD_DIR PYTHON

The venv sees the system's packages (Debian's numpy, setuptools, wheel):
--no-build-isolation --no-index installs without a download. BUILD_DIR is
the test command's build folder, passed as TERRANE_BUILD_DIR so the install
reuses its objects. The version printed is the project's (CMakeLists.txt),
pip records numpy as a requirement, and the stub and py.typed are installed;
a wheel built the same way (as scripts/build.sh does) carries them too.
"""
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile


def main(source, build, python):
    project = open(os.path.join(source, "CMakeLists.txt")).read()
    version = re.search(r"project\(terrane VERSION ([0-9.]+)", project).group(1)
    scratch = tempfile.mkdtemp(prefix="terrane-pip-")
    try:
        venv = os.path.join(scratch, "venv")
        subprocess.run([python, "-m", "venv", "--system-site-packages", venv], check=True)
        bin_dir = os.path.join(venv, "bin")
        env = dict(os.environ, TERRANE_BUILD_DIR=build, PIP_NO_INPUT="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
        env.pop("PYTHONPATH", None)
        subprocess.run([os.path.join(bin_dir, "pip"), "install", "--no-build-isolation", "--no-index",
                        os.path.join(source, "client", "python")], check=True, env=env, cwd=scratch)
        out = subprocess.run([os.path.join(bin_dir, "python"), "-c", "import terrane; print(terrane.__version__)"],
                             check=True, env=env, cwd=scratch, capture_output=True, text=True).stdout.strip()
        assert out == version, "terrane.__version__ is %r, the project's version %r" % (out, version)
        where = subprocess.run([os.path.join(bin_dir, "python"), "-c",
                                "import os, terrane; print(os.path.dirname(terrane.__file__))"],
                               check=True, env=env, cwd=scratch, capture_output=True, text=True).stdout.strip()
        assert where.startswith(venv), "terrane imported from %s, not the venv" % where
        for f in ("__init__.pyi", "py.typed"):
            assert os.path.exists(os.path.join(where, f)), f + " not installed"
        show = subprocess.run([os.path.join(bin_dir, "pip"), "show", "terrane"], check=True, env=env,
                              capture_output=True, text=True).stdout
        assert re.search(r"^Requires: .*numpy", show, re.M), show
        # The wheel scripts/build.sh makes the same way carries the same files.
        wheels = os.path.join(scratch, "wheels")
        subprocess.run([os.path.join(bin_dir, "pip"), "wheel", "--no-build-isolation", "--no-index", "--no-deps",
                        "-w", wheels, os.path.join(source, "client", "python")], check=True, env=env, cwd=scratch)
        [wheel] = os.listdir(wheels)
        assert wheel.startswith("terrane-%s-" % version), wheel
        with zipfile.ZipFile(os.path.join(wheels, wheel)) as z:
            names = z.namelist()
        for f in ("terrane/__init__.py", "terrane/__init__.pyi", "terrane/py.typed"):
            assert f in names, (f, names)
        assert any(n.startswith("terrane/_native") and n.endswith(".so") for n in names), names
        print("terrane", out, "installed in a fresh venv and imported")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main(*sys.argv[1:4])

"""Builds terrane._native for pip with the project's CMake.

The extension has no sources of its own here: build_ext configures the
whole source tree (two folders up) in the build's temporary folder, builds
the target terrane_python for the interpreter that runs pip, and copies the
module it made. TERRANE_BUILD_DIR names a configured build folder to build
the target in instead (the test command's, so an install reuses its
objects); TERRANE_JOBS the number of compile jobs (default: every core);
TERRANE_CMAKE_ARGS more arguments for the configure step (split at spaces,
e.g. -DCMAKE_CXX_COMPILER_LAUNCHER=ccache).
"""
import glob
import os
import shutil
import subprocess
import sys
import sysconfig

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.dirname(os.path.dirname(HERE))


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build_dir = os.environ.get("TERRANE_BUILD_DIR") or os.path.join(os.path.abspath(self.build_temp), "cmake")
        if not os.path.exists(os.path.join(build_dir, "CMakeCache.txt")):
            subprocess.check_call([
                "cmake", "-S", SOURCE, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release",
                "-DPython3_EXECUTABLE=" + sys.executable, "-DTERRANE_BUILD_TESTS=OFF", "-DTERRANE_BUILD_BENCH=OFF",
                *os.environ.get("TERRANE_CMAKE_ARGS", "").split(),
            ])
        jobs = os.environ.get("TERRANE_JOBS") or str(os.cpu_count() or 1)
        subprocess.check_call(["cmake", "--build", build_dir, "--target", "terrane_python", "-j", jobs])
        # The module for this interpreter (a build folder made for another
        # Python has another suffix).
        suffix = sysconfig.get_config_var("EXT_SUFFIX")
        built = glob.glob(os.path.join(build_dir, "python", "terrane", "_native" + suffix))
        if len(built) != 1:
            raise RuntimeError("no terrane/_native%s in %s: was it configured for another Python than %s?"
                               % (suffix, os.path.join(build_dir, "python"), sys.executable))
        target = self.get_ext_fullpath(ext.name)
        os.makedirs(os.path.dirname(target), exist_ok=True)
        shutil.copyfile(built[0], target)


setup(ext_modules=[Extension("terrane._native", sources=[])], cmdclass={"build_ext": CMakeBuild})

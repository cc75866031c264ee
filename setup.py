"""`pip install --no-build-isolation .`: the pyfem package, its `pyfem` command and the C++ kernel.

The metadata is in pyproject.toml; this file only teaches setuptools to build the kernel module
pyfem/_kernels with the project's CMakeLists.txt (the same build as `make`, without the C++
tests), into setuptools' build directory rather than the source tree (the accuracy studies' tables
that `pyfem check` turns into mesh advice are package data, pyfem/data/, in pyproject.toml).
Everything comes from Debian's packages (setuptools, cmake, g++, pybind11-dev): no network is needed.
"""
import os
import subprocess
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent


class CMakeExtension(Extension):
    """An extension module built by CMakeLists.txt (target `_kernels`)."""

    def __init__(self, name: str, target: str):
        super().__init__(name, sources=[])
        self.target = target


class CMakeBuild(build_ext):
    """Configure and build the CMake target of each CMakeExtension into the wheel's directory."""

    def build_extension(self, ext):
        if not isinstance(ext, CMakeExtension):
            return super().build_extension(ext)
        output = Path(self.get_ext_fullpath(ext.name)).resolve()
        build_dir = Path(self.build_temp).resolve() / "cmake"
        build_dir.mkdir(parents=True, exist_ok=True)
        configure = ["cmake", "-S", str(ROOT), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
                     f"-DPython3_EXECUTABLE={sys.executable}", f"-DPYFEM_KERNEL_OUTPUT_DIR={output.parent}",
                     "-DPYFEM_BUILD_TESTS=OFF"]
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", str(min(os.cpu_count() or 1, 2)))
        subprocess.run(configure, check=True)
        subprocess.run(["cmake", "--build", str(build_dir), "--target", ext.target, "-j", jobs], check=True)
        if not output.is_file():
            raise RuntimeError(f"CMake built no {output.name} in {output.parent}")


setup(
    ext_modules=[CMakeExtension("pyfem._kernels", target="_kernels")],
    cmdclass={"build_ext": CMakeBuild},
    # setuptools' own build directory, apart from CMake's build/ of `make`.
    options={"build": {"build_base": "build/setuptools"}},
)

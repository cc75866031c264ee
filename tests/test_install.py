"""`pip install --no-build-isolation .` (README "Install") gives a `pyfem` command that works from any
directory, with the kernel compiled by the install (slow tier: it compiles, about 30 s on 2 cores)."""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from pyfem import scene_keys

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
SCENE = REPO / "workflows" / "scenes" / "default.toml"


def run(command, cwd, timeout=900):
    """Runs `command` in `cwd` without the source tree on the path; fails with its output."""
    env = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "VIRTUAL_ENV")}
    result = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True,
                            timeout=timeout)
    shown = " ".join(map(str, command))
    assert result.returncode == 0, f"{shown}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


def clone_of_the_working_tree(target: Path) -> Path:
    """The files a clone would hold (tracked and new, not ignored: no build/, no compiled kernel)."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = REPO / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    return target


def test_pip_install_gives_a_pyfem_command_that_works_from_any_directory(tmp_path):
    source = clone_of_the_working_tree(tmp_path / "source")
    assert not list((source / "pyfem").glob("_kernels*.so")), "the copy must not hold a compiled kernel"
    venv = tmp_path / "venv"
    run([PYTHON, "-m", "venv", "--system-site-packages", venv], cwd=tmp_path)
    pip = [venv / "bin" / "python", "-m", "pip"]
    run([*pip, "install", "--no-build-isolation", "--no-index", "."], cwd=source)

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    located = run([venv / "bin" / "python", "-c",
                   "import pyfem, pyfem._kernels; print(pyfem.__file__); print(pyfem._kernels.__file__)"],
                  cwd=elsewhere).stdout.split()
    site_packages = venv / "lib"
    assert all(Path(path).is_relative_to(site_packages) for path in located), located

    checked = run([venv / "bin" / "pyfem", "check", SCENE], cwd=elsewhere).stdout
    checks = 0
    for expected in ("seismic_input", "dofs:", "time per step:",
                     "for a 5 % error: Q2 elements"):  # the mesh advice reads the studies shipped in pyfem/data
        assert expected in checked, checked
        checks += 1
    assert checks == 4
    shipped = Path(located[0]).parent / "data"
    for study in ("accuracy_cost", "wall_stress", "lining_stress", "elliptical_opening", "interface_slip"):
        assert (shipped / f"{study}.csv").is_file(), study
    assert run([venv / "bin" / "pyfem", "keys"], cwd=elsewhere).stdout == scene_keys.reference()
    assert not list(elsewhere.iterdir()), "check and keys write nothing"

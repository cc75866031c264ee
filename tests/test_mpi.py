"""`mpirun -n N python3 -m pyfem run SCENE`: what a launch on the ranks does besides stepping (the
features x ranks matrix against the serial run is tests/test_distributed_model.py; local stepping
tests/test_mpi_lts.py; the static stage tests/test_mpi_stage.py).

- a bad key, found when the scene is read or after every rank has built its part: one line, exit 2;
- `parallel.model = "whole"` (the whole-model MPI mode, removed): one line naming what replaced it;
- a failure on one rank alone (rank 0 cannot start its run directory) ends every rank;
- a run directory holding the user's files is refused before anything is built.
Helpers for the other MPI files: `pyfem_run`, `kill_after_first_checkpoint`, `sigterm_to_rank_one`.
"""
import json
import os
import random
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from conftest import kill_9, rank_pids
from pyfem import checkpoint

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
ENV = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
TOLERANCE = 1.0e-10
MPIRUN = shutil.which("mpirun")

SCENES = {"free_field": ("workflows/scenes/box_vertical_sv.toml", ())}


def pyfem_run(ranks: int, scene: str, out_dir: Path, *extra: str) -> subprocess.CompletedProcess:
    command = [PYTHON, "-m", "pyfem", "run", scene, "--out", str(out_dir), *extra]
    if ranks > 1:
        assert MPIRUN is not None, "mpirun not found: scripts/setup.sh installs openmpi-bin"
        command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    result = subprocess.run(command, cwd=REPO, env=ENV, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


def summary(run_dir: Path) -> dict:
    return json.loads((run_dir / "run.json").read_text())


# A key refused when the scene is read, and one refused after every rank has built the model (local
# time stepping with float32 matrix blocks, which it does not step).
@pytest.mark.parametrize("settings, key", [(("time.duration=-1",), "time.duration"),
                                           (("time.local_stepping=true", 'time.matrix_precision="single"'),
                                            "time.local_stepping")])
def test_a_bad_key_under_mpirun_is_one_line_and_exit_2(settings, key, mpi_launcher):
    sets = [arg for setting in settings for arg in ("--set", setting)]
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem",
                             "run", SCENES["free_field"][0], *sets], cwd=REPO, env=ENV,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and key in errors[0], result.stderr
    assert "Traceback" not in result.stderr


def test_the_whole_model_mode_is_refused_in_one_line(tmp_path):
    """`[parallel] model = "whole"` (every rank building the whole model: removed) is not run as
    something else: one line naming the key, the value and what replaced it, exit 2, nothing written."""
    result = subprocess.run([PYTHON, "-m", "pyfem", "run", SCENES["free_field"][0], "--out", str(tmp_path / "run"),
                             "--set", 'parallel.model="whole"'], cwd=REPO, env=ENV, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "parallel.model" in errors[0] and '"whole"' in errors[0], result.stderr
    assert "distributed" in errors[0] and "removed" in errors[0] and "Traceback" not in result.stderr
    assert not (tmp_path / "run").exists()


def test_a_failure_on_one_rank_ends_every_rank(tmp_path, mpi_launcher):
    """Rank 0 cannot start its run directory after the ranks have built their parts (a FileExistsError
    raised in rank 0's process only): it says so and MPI_Abort ends the job, instead of rank 1 waiting
    forever in its next collective."""
    out = tmp_path / "blocked"
    code = ("import sys\nfrom mpi4py import MPI\nfrom pyfem import cli, distributed_model\n"
            "opened = distributed_model.DistributedRun._open\n"
            "def blocked(self, stepper):\n"
            "    if MPI.COMM_WORLD.rank == 0:\n"
            "        raise FileExistsError(17, 'File exists', str(self.out / 'monitors'))\n"
            "    return opened(self, stepper)\n"
            "distributed_model.DistributedRun._open = blocked\n"
            f"sys.exit(cli.main(['run', {SCENES['free_field'][0]!r}, '--out', {str(out)!r}]))\n")
    began = time.monotonic()
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-c", code],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
    assert result.returncode != 0
    assert "error: rank 0 of 2: FileExistsError" in result.stderr and "ending every rank" in result.stderr, \
        result.stderr[-3000:]
    assert time.monotonic() - began < 120


def test_a_directory_of_the_users_files_is_refused_under_mpirun_too(tmp_path):
    """A file of the user's in the run directory: one line, exit 2, before anything is shared, and the
    file as it was."""
    out = tmp_path / "blocked"
    out.mkdir()
    (out / "monitors").write_text("in the way\n")
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem",
                             "run", SCENES["free_field"][0], "--out", str(out)], cwd=REPO, env=ENV,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--out" in errors[0] and "not a run of pyfem (monitors)" in errors[0], result.stderr
    assert "Traceback" not in result.stderr
    assert (out / "monitors").read_text() == "in the way\n"  # nothing of the user's overwritten


CHECKPOINTED_RUN = ("--set", "output.checkpoint_interval=0.5", "--set", "time.duration=3.0")


def kill_after_first_checkpoint(ranks: int, scene: str, out: Path, window: float, extra: tuple = (),
                                env: dict | None = None) -> None:
    """Starts `pyfem run` on `ranks` ranks and kills it (kill -9: mpirun and every rank) at a random
    time within `window` s after its first checkpoint; env: the run's environment (ENV)."""
    command = [PYTHON, "-m", "pyfem", "run", scene, "--out", str(out), *CHECKPOINTED_RUN, *extra]
    if ranks > 1:
        command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    process = subprocess.Popen(command, cwd=REPO, env=env or ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    deadline = time.monotonic() + 300
    while not (out / checkpoint.CHECKPOINT_NAME).exists():
        assert process.poll() is None, "the run ended before its first checkpoint"
        assert time.monotonic() < deadline, "no checkpoint after 300 s"
        time.sleep(0.05)
    time.sleep(random.uniform(0.0, window))
    kill_9(process)
    assert json.loads((out / "run.json").read_text())["status"] == "running"  # as a killed run leaves it


def sigterm_to_rank_one(scene: str, out: Path, settings: tuple, rows: int) -> tuple:
    """Starts `pyfem run` of `scene` on 2 ranks, sends SIGTERM to rank 1 only once monitors/layer.csv
    holds more than `rows` lines (written every 2 s), waits for the run's end: (process, stderr)."""
    command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem", "run", scene,
               "--out", str(out), *settings]
    process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    layer = out / "monitors" / "layer.csv"
    deadline = time.monotonic() + 300
    while not (layer.exists() and len(layer.read_text().splitlines()) > rows):
        assert process.poll() is None, "the run ended before the signal"
        assert time.monotonic() < deadline, "no samples after 300 s"
        time.sleep(0.05)
    os.kill(rank_pids(process.pid)[1], signal.SIGTERM)
    _, stderr = process.communicate(timeout=300)
    return process, stderr

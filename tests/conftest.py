"""Shared test helpers: one place for tolerances."""
import os
from pathlib import Path

import numpy as np
import pytest

ROUNDOFF = 1e-10  # relative agreement expected between two evaluations of the same arithmetic
EXACT = 1e-12  # relative agreement of two arrangements of the same sums over a few hundred steps
# tests/test_absorption.py, about twice the largest discrepancy measured. The discrepancies are the
# meshes' dispersion: in the 1D columns (h = 1 m, 12 Hz Ricker) they fell 4x from h = 2 m.
REFLECTION_1D = 1.0e-3  # |R measured - R analytic|, 1D column, viscous face (up to 4.3e-4)
REFLECTION_HISTORY_1D = 1.0e-2  # reflected history's L2 error / incident's, 1D viscoelastic (up to 5.2e-3)
REFLECTION_OBLIQUE = 4.0e-3  # |R measured - R analytic| per coefficient, slab h = 2.5 m (up to 1.9e-3)
# A run's discrete energy balance under global stepping (run.json energy.balance_error, the balance over
# the work in play): an identity of the scheme, measured 1e-15..1e-14; a work term missing by any
# fraction that matters (contact, plastic, damping, input) breaks it by many orders more.
ENERGY_BALANCE = ROUNDOFF
# Local stepping's plain energy account (kinetic + strain - work, not the scheme's modified energy)
# closes to O(dt^2) only: docs/method.md states 4e-5 to 1.3e-4 of the work with all physics.
LOCAL_STEPPING_BALANCE = 1.3e-4

# `make test` runs the tier in two pytest-xdist workers, one per core: each worker's kernel (and
# the runs it starts) then takes one OpenMP thread, not both cores twice over. A test that needs
# two threads sets them itself (tests/test_threads.py, tests/test_internal_force.py).
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def rank_pids(mpirun_pid: int) -> dict:
    """{rank: pid} of the ranks mpirun started (its children, by OMPI_COMM_WORLD_RANK)."""
    ranks = {}
    for task in Path(f"/proc/{mpirun_pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            try:
                environ = Path(f"/proc/{child}/environ").read_bytes().split(b"\0")
            except OSError:
                continue
            for entry in environ:
                if entry.startswith(b"OMPI_COMM_WORLD_RANK="):
                    ranks[int(entry.split(b"=")[1])] = int(child)
    return ranks


def kill_9(process) -> None:
    """kill -9 of a run started with start_new_session=True: a serial run, or mpirun and every rank.
    Open MPI puts each rank in a process group of its own, so killing mpirun's group alone leaves the
    ranks stepping (and writing checkpoints) until they notice mpirun is gone; the ranks are killed
    first, then mpirun's group, and this returns once all of them are gone."""
    import signal
    import time

    try:
        ranks = list(rank_pids(process.pid).values())
    except OSError:  # mpirun already gone, or a serial run
        ranks = []
    for pid in ranks:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    process.wait(timeout=60)
    deadline = time.monotonic() + 60
    while any(Path(f"/proc/{pid}").exists() and "Z" not in _state(pid) for pid in ranks):
        assert time.monotonic() < deadline, "a rank outlived kill -9 by 60 s"
        time.sleep(0.02)


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


def rel_error(a, b):
    """Relative L2 error of `a` against the reference `b` (1 if b is zero and a is not)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    denom = np.linalg.norm(b)
    diff = np.linalg.norm(a - b)
    if denom == 0.0:
        return 0.0 if diff == 0.0 else 1.0
    return diff / denom


def observed_orders(hs, errors):
    """Observed convergence orders log(e_i/e_{i+1}) / log(h_i/h_{i+1}) between successive refinements."""
    hs = np.asarray(hs, dtype=float)
    errors = np.asarray(errors, dtype=float)
    return np.log(errors[:-1] / errors[1:]) / np.log(hs[:-1] / hs[1:])


def write_msh_with_quadratic_tetrahedra(path):
    """A .msh of one 10-node tetrahedron (gmsh's own second-order element, type 11), its volume the
    physical group "rock": an unsupported mesh (pyfem reads linear cells and builds P2/Q2 on them).

    Written as text rather than meshed: gmsh 4.8's in-process second-order meshing crashed
    (a segmentation fault) once in a full test run, and no gmsh option is touched this way.
    """
    nodes = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (0.5, 0, 0), (0.5, 0.5, 0), (0, 0.5, 0),
             (0, 0, 0.5), (0, 0.5, 0.5), (0.5, 0, 0.5)]
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", "1", '3 1 "rock"',
             "$EndPhysicalNames", "$Nodes", str(len(nodes))]
    lines += [f"{k + 1} {x} {y} {z}" for k, (x, y, z) in enumerate(nodes)]
    lines += ["$EndNodes", "$Elements", "1", "1 11 2 1 1 " + " ".join(str(k + 1) for k in range(10)),
              "$EndElements"]
    Path(path).write_text("\n".join(lines) + "\n")


@pytest.fixture
def unfitted_levels(monkeypatch):
    """Local stepping's rate levels as the mesh gives them, not capped to fit the output interval
    (pyfem.local_stepping.fit_levels_to_output): the small test scenes have few steps per output
    interval, where the cap would leave one or two levels, and these tests are about the kernel's
    accuracy and stability with several levels. The cap has its own test."""
    from pyfem import local_stepping

    # (the top level kept: fit_levels_to_output's and the distributed model's cap, both fitted_top's)
    monkeypatch.setattr(local_stepping, "fitted_top",
                        lambda counts, steps_per_output: len(np.trim_zeros(np.asarray(counts), "b")) - 1)


class RunsOnDemand(dict):
    """A module fixture's {key: run directory} whose runs are made when a test first asks for them
    (`make(key)` runs and returns the directory): a configuration that only slow-tier tests read
    costs the default tier nothing."""

    def __init__(self, make) -> None:
        super().__init__()
        self.make = make

    def __missing__(self, key):
        self[key] = self.make(key)
        return self[key]


@pytest.fixture(scope="session")
def mpi_launcher() -> str:
    """The MPI launcher, or a failure: the MPI tests never skip silently (scripts/setup.sh installs
    openmpi-bin, so a missing launcher is a broken set-up, not an optional feature)."""
    import shutil

    path = shutil.which("mpirun")
    assert path is not None, "mpirun not found: scripts/setup.sh installs openmpi-bin"
    return path

"""The kernel steps on every core it may use, whatever gmsh did before.

gmsh shares libgomp with the kernel and sets its thread count to General.NumThreads (1) when it
meshes; until 2026-11-23 every run after a gmsh call stepped on one thread (the benchmark, which
sets its threads itself, did not show it)."""
import os

from pyfem import _kernels, solver
from pyfem.scene import parse_scene


def test_stepper_uses_every_core_after_gmsh(monkeypatch, tmp_path):
    """Catches a stepper left on gmsh's one thread. On a one-core machine (where the right count is
    gmsh's own 1) the process is told it may use two cores, so the reset still shows: run, never skip.
    The run (the one model on one rank) meshes its box with gmsh itself and then steps: the threads
    are read after it, as its time loop left them."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    cores = len(os.sched_getaffinity(0))
    if cores < 2:
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
        cores = 2
    from pyfem._gmsh import gmsh, initialize

    initialize()
    gmsh.model.add("threads")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.mesh.generate(3)
    gmsh.finalize()
    _kernels.set_num_threads(1)  # what gmsh leaves behind (its General.NumThreads)
    assert _kernels.max_threads() == 1
    scene = parse_scene({"mesh": {"size": [2.0, 2.0, 2.0], "h": 1.0}, "materials": {"rock": {"E": 8e9, "nu": 0.24,
                                                                                          "rho": 2600.0}},
                         "time": {"duration": 0.001}})
    solver.run(scene, tmp_path / "every_core")
    assert (tmp_path / "every_core" / "run.json").exists()  # (it ran)
    assert _kernels.max_threads() == cores
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    solver.run(scene, tmp_path / "one_thread")
    assert _kernels.max_threads() == 1

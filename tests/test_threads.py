"""The kernel steps on every core it may use, whatever gmsh did before.

gmsh shares libgomp with the kernel and sets its thread count to General.NumThreads (1) when it
meshes; until 2026-11-23 every run after a gmsh call stepped on one thread (the benchmark, which
sets its threads itself, did not show it)."""
import os

import pytest

from pyfem import _kernels, solver
from pyfem.scene import parse_scene


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: nothing to lose")
def test_stepper_uses_every_core_after_gmsh(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    from pyfem._gmsh import gmsh, initialize

    initialize()
    gmsh.model.add("threads")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.mesh.generate(3)
    gmsh.finalize()
    _kernels.set_num_threads(1)  # what gmsh leaves behind (its General.NumThreads)
    scene = parse_scene({"mesh": {"size": [2.0, 2.0, 2.0], "h": 1.0}, "materials": {"rock": {"E": 8e9, "nu": 0.24,
                                                                                          "rho": 2600.0}},
                         "time": {"duration": 0.001}})
    simulation = solver.prepare(scene)
    solver.make_stepper(simulation)
    assert _kernels.max_threads() == len(os.sched_getaffinity(0))
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    solver.make_stepper(simulation)
    assert _kernels.max_threads() == 1

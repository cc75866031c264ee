"""Contact pairs on the triangle facets of tetrahedral meshes from gmsh (issue 14, docs/tetrahedra.md).

A user's .geo script with two layers meshed to tetrahedra and the surface between them named as an
interface: the `file` builder splits its triangles into node pairs as it does the quadrilaterals of
hexahedra (pyfem.interface_split). Linear tetrahedra only: on quadratic triangles the consistent load
of a uniform traction vanishes at the vertices, and P2 contact is refused (tests/test_tetrahedra.py).

- Bonded pairs reproduce the unsplit tetrahedral mesh to round-off while an SV pulse crosses the
  interface (every node, both copies of every pair).
- The pairs' lumped areas tile the interface (sum = its area), every area > 0.
- A block of tetrahedra on a held base slides under a one-sided pulse by Newmark's rigid-block
  displacement (the test of tests/test_contact.py on hexahedra), with friction dissipating energy.
"""
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import ROUNDOFF, rel_error
from pyfem.distributed_model import model_in_memory
from pyfem.initial_stress import STANDARD_GRAVITY
from pyfem.scene import parse_scene
from test_contact import newmark_sliding_block, run_block, shake_block


def two_layer_geo(folder: Path, size, lower: float, h: float, names=("lower", "upper")) -> Path:
    """A user's gmsh script: two boxes stacked in z (the lower one `lower` m thick), fragmented so
    that they share the surface between them, named "interface_1"; tetrahedra of size h."""
    lx, ly, lz = size
    path = folder / f"two_layer_h{h:g}.geo"
    path.write_text(
        'SetFactory("OpenCASCADE");\n'
        f"Box(1) = {{0, 0, 0, {lx}, {ly}, {lower}}};\n"
        f"Box(2) = {{0, 0, {lower}, {lx}, {ly}, {lz - lower}}};\n"
        "BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }\n"
        f"interface() = Surface In BoundingBox{{-1, -1, {lower - 1e-3}, {lx + 1}, {ly + 1}, {lower + 1e-3}}};\n"
        f'Physical Volume("{names[0]}") = {{1}};\n'
        f'Physical Volume("{names[1]}") = {{2}};\n'
        'Physical Surface("interface_1") = interface();\n'
        f"Mesh.MeshSizeMax = {h};\nMesh.MeshSizeMin = {h};\n")
    return path


def layered_scene(geo: Path, order: int, contact: bool, dt: float) -> "Scene":
    data = {
        "title": "two layers of tetrahedra, interface contact, vertical SV",
        "mesh": {"builder": "file", "file": str(geo), "order": order},
        "materials": {"lower": {"preset": "sandstone"}, "upper": {"preset": "non_sandstone"}},
        "time": {"duration": 0.5, "dt": dt},
        "wave": {"type": "SV", "angle": 0.0, "surface": 100.0, "medium": "lower",
                 "motion": {"ricker": {"f0": 5.0, "amplitude": 1.0e-3}}},
        "initial_stress": {"surface": 100.0, "rho": 2500.0, "k": [1.0, 1.0, 1.0]},
        "monitor": [{"name": "below", "point": [30.0, 5.0, 20.0]}, {"name": "above", "point": [30.0, 5.0, 45.0]}],
        "output": {"interval": 0.005, "xdmf_interval": 0.0},
    }
    if contact:  # strengths far above any stress of the pulse: every pair stays bonded
        data["contact"] = {"interfaces": ["interface_1"], "cohesion": 1.0e15, "friction_angle": 30.0,
                           "tensile_strength": 1.0e15}
    return parse_scene(data, source="test")


@pytest.mark.parametrize("order, h, dt", [(1, 6.0, 5.0e-4)])
def test_bonded_pairs_on_triangles_reproduce_the_unsplit_tetrahedra_to_roundoff(tmp_path, order, h, dt):
    geo = two_layer_geo(tmp_path, (60.0, 10.0, 60.0), 30.0, h)
    histories = []
    for contact in (True, False):
        simulation = model_in_memory(layered_scene(geo, order, contact, dt))
        stepper, _ = simulation.stepper()
        n = 3 * simulation.part.n_local
        u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        t, samples = 0.0, []
        steps = round(0.05 / dt)
        for _ in range(10):
            t = stepper.run(u, v, a, steps, t)
            samples.append(u.copy())
        histories.append((simulation, np.array(samples)))
    (split_sim, split_u), (whole_sim, whole_u) = histories
    assert split_sim.part.model.mesh.topology.cell_type.name == "tetrahedron"
    pairs = split_sim.part.pairs
    assert len(pairs) > 10
    assert split_sim.part.n_local == whole_sim.part.n_local + len(pairs)  # one copy per interface node
    # The lumped areas tile the 60 x 10 m interface, every share positive.
    assert np.all(pairs.area > 0.0)
    assert abs(pairs.area.sum() - 600.0) < 1e-9 * 600.0
    assert np.allclose(pairs.normal, [0.0, 0.0, 1.0], atol=1e-12)
    assert split_sim.contact.state_counts()[0] == len(pairs)  # all bonded
    distance, unsplit_node = cKDTree(whole_sim.part.coords).query(split_sim.part.coords)  # (the kernel's numbering)
    assert np.max(distance) < 1e-9
    split_nodal = split_u.reshape(len(split_u), -1, 3)
    whole_nodal = whole_u.reshape(len(whole_u), -1, 3)[:, unsplit_node]
    upper = split_sim.part.coords[:, 2] > 35.0
    assert np.max(np.abs(whole_nodal[:, upper])) > 5e-4  # the pulse has crossed the interface
    error = rel_error(split_nodal, whole_nodal)
    print(f"P{order}: {len(pairs)} pairs, bonded vs unsplit {error:.2e}")
    assert error < ROUNDOFF


def block_geo(folder: Path, h: float) -> Path:
    """A 2 x 1 x 1 m block of tetrahedra on a 1 m base, the surface between them "interface_1"."""
    return two_layer_geo(folder, (2.0, 1.0, 2.0), 1.0, h, names=("base", "block"))


def test_block_of_tetrahedra_slides_as_newmark_rigid_block(tmp_path):
    mu = 0.2
    amplitude, frequency = 0.5 * STANDARD_GRAVITY, 2.0

    def acceleration(t):
        t = np.asarray(t, dtype=float)
        return np.where(t < 0.5 / frequency, amplitude * np.sin(2 * np.pi * frequency * t), 0.0)

    scene = parse_scene({
        "title": "block of tetrahedra on a rigid base",
        "mesh": {"builder": "file", "file": str(block_geo(tmp_path, 0.5)), "order": 1},
        "materials": {"base": {"E": 1.0e10, "nu": 0.25, "rho": 2500.0},
                      "block": {"E": 1.0e10, "nu": 0.25, "rho": 2500.0}},
        "time": {"duration": 1.5, "safety": 0.8},
        "boundary": {"type": "free"},
        "initial_stress": {"surface": 2.0, "rho": 2500.0, "k": [1.0, 1.0, 1.0]},
        "contact": {"interfaces": ["interface_1"], "cohesion": 0.0, "friction_angle": math.degrees(math.atan(mu)),
                    "tensile_strength": 0.0},
        "output": {"interval": 0.01, "xdmf_interval": 0.0},
    }, source="test")
    simulation = model_in_memory(scene)
    assert simulation.part.model.mesh.topology.cell_type.name == "tetrahedron"
    shake_block(simulation, acceleration, [1.0, 0.0, 0.0])
    stepper, energies, u = run_block(simulation)
    slip = simulation.contact.relative_displacement(u)[:, 0].mean()
    _, reference = newmark_sliding_block(lambda t: float(acceleration(t)), mu * STANDARD_GRAVITY,
                                         simulation.scene["time"]["duration"])
    print(f"tetrahedra: slip {slip:.6f} m, Newmark rigid block {reference[-1]:.6f} m")
    assert abs(reference[-1]) > 0.05  # a real permanent displacement
    assert abs(slip - reference[-1]) < 0.05 * abs(reference[-1])
    # The weight m g is carried by the pairs' static normal forces.
    assert np.isclose(np.asarray(simulation.contact.normal_force()).sum(),
                      2500.0 * 2.0 * 1.0 * STANDARD_GRAVITY, rtol=0.05)
    final = energies[-1]
    scale = max(max(abs(e["external_work"]) for e in energies), max(e["kinetic"] + e["strain"] for e in energies))
    assert max(abs(e["balance"]) for e in energies) < 0.01 * scale
    assert final["friction_dissipation"] > 0.1 * scale


def test_a_gmsh_mesh_with_a_node_no_cell_uses_runs_with_contact(tmp_path):
    """gmsh 4.8 leaves one node that no tetrahedron uses in meshes/dipping_fault_tet.geo (a new-user
    trial's dipping fault); with the fault split for contact dolfinx crashed on it (exit 59, or a
    hang under mpirun). pyfem.mesh drops such nodes before dolfinx sees the split mesh: the scene
    runs, its fault's pairs slide, and the mesh's node count is that of the cells' nodes."""
    import json
    import subprocess
    import sys

    from pyfem._gmsh import gmsh
    from pyfem.geometry import gmsh_session, load_msh
    from pyfem.mesh import _model_arrays, _without_unused_nodes

    repository = Path(__file__).resolve().parents[1]
    with gmsh_session("unused"):
        load_msh(str(repository / "meshes" / "dipping_fault_tet.geo"))
        arrays = _model_arrays()
    used = np.unique(arrays["cells"])
    x, cells, facets, values = _without_unused_nodes(arrays["x"], arrays["cells"], arrays["facets"],
                                                     arrays["facet_values"])
    assert len(x) == len(used) and np.array_equal(np.unique(cells), np.arange(len(x)))
    assert np.allclose(x[cells], arrays["x"][arrays["cells"]]) and len(facets) == len(arrays["facets"])
    out = tmp_path / "run"
    result = subprocess.run([sys.executable, "-m", "pyfem", "run", "tests/scenes/dipping_fault_tet.toml", "--out",
                             str(out)], cwd=repository, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads((out / "run.json").read_text())
    assert summary["nodes"] == len(used) + summary["n_pairs"], "every node a cell's, the fault's copies added"
    assert max(summary["pair_states"]["sliding"]) > 0 and summary["pairs"]["fault_mid"]["max_slip"] > 1e-4
    print(f"{len(arrays['x']) - len(used)} unused node(s) dropped; {summary['n_pairs']} pairs")


def test_unused_nodes_are_dropped_and_the_rest_renumbered():
    """`_without_unused_nodes` on a two-tetrahedron mesh with two nodes no cell uses."""
    from pyfem.mesh import _without_unused_nodes

    x = np.arange(21.0).reshape(7, 3)
    cells = np.array([[0, 2, 3, 4], [2, 3, 4, 6]])
    facets = np.array([[2, 3, 4], [0, 1, 2]])  # the second on node 1, which no cell uses
    got_x, got_cells, got_facets, got_values = _without_unused_nodes(x, cells, facets, np.array([7, 8]))
    assert np.array_equal(got_x, x[[0, 2, 3, 4, 6]]) and np.array_equal(got_x[got_cells], x[cells])
    assert np.array_equal(got_x[got_facets], x[[[2, 3, 4]]]) and got_values.tolist() == [7]

"""Truncation faces and their types (docs/boundaries.md): which faces carry the boundary and the
input, rollers for plane strain with their reactions against the free field's stress, and a
layered cavern whose walls are free."""
import math

import numpy as np
import pytest

from conftest import rel_error
from pyfem import solver
from pyfem.distributed_model import model_in_memory
from pyfem.geometry import BOX_FACES
from pyfem.scene import parse_scene

E, NU, RHO = 8.0e9, 0.24, 2600.0


def slab_scene(wave_type="P", rollers=True, duration=0.5):
    """A 80 x 4 x 200 m slab (one element thick in y) below a free surface, vertical wave."""
    boundary = {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}} if rollers else {}
    return parse_scene({
        "title": f"slab {wave_type}",
        "mesh": {"builder": "box", "size": [80.0, 4.0, 200.0], "h": 4.0},
        "materials": {"rock": {"E": E, "nu": NU, "rho": RHO}},
        "time": {"duration": duration},
        "wave": {"type": wave_type, "angle": 0.0, "surface": 250.0,
                 "motion": {"ricker": {"f0": 5.0, "amplitude": 1.0e-3}}},
        "boundary": boundary,
        "monitor": [{"name": "centre", "point": [40.0, 2.0, 100.0]}],
        "output": {"interval": 0.005, "xdmf_interval": 0.0},
    })


def read_csv(path):
    with open(path) as handle:
        header = handle.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return {name: data[:, k] for k, name in enumerate(header)}


def test_plane_strain_slab_with_rollers_follows_the_free_field_and_reacts_its_stress(tmp_path):
    """Vertical P in a slab with roller y faces: the motion is the free field's and the rollers
    carry sigma_yy = lambda eps_zz of the free field (the resultant over each face)."""
    scene = slab_scene("P")
    summary = solver.run(scene, tmp_path / "run")
    faces = {face["name"]: face for face in summary["boundary_faces"]}
    assert faces["ymin"]["type"] == faces["ymax"]["type"] == "roller"
    assert [name for name, face in faces.items() if face["input"]] == ["xmin", "xmax", "zmin", "zmax"]
    monitor = read_csv(tmp_path / "run" / "monitors" / "centre.csv")
    assert np.max(np.abs(monitor["uz_ff"])) > 5e-4, "the wave arrived"
    error = rel_error(monitor["uz"], monitor["uz_ff"])
    print(f"slab P: relative error of uz against the free field {error:.2e}")
    assert error < 0.02
    assert np.max(np.abs(monitor["uy"])) <= 1e-12 * np.max(np.abs(monitor["uz"])), "plane strain: uy = 0"

    reactions = read_csv(tmp_path / "run" / "reactions.csv")
    simulation = model_in_memory(scene, solve_stage=False)  # (one rank, no contact: the kernel's numbering is the mesh's)
    face = next(f for f in simulation.part.model.faces if f.name == "ymax")
    points = simulation.part.coords[face.nodes]
    stress = simulation.freefield.stress(points, reactions["t"])       # (nt, k, 3, 3)
    expected = np.einsum("k,tk->t", face.area, stress[:, :, 1, 1])     # sum A sigma_yy (n = +y)
    assert np.max(np.abs(expected)) > 1e5, "the rollers are loaded"
    for name, sign in (("ymax", 1.0), ("ymin", -1.0)):
        error = rel_error(reactions[f"{name}_Fy"], sign * expected)
        print(f"{name}: reaction against the free field's sigma_yy: relative error {error:.2e}")
        assert error < 0.02
        # Rollers react along their normal only.
        assert np.max(np.abs(reactions[f"{name}_Fx"])) < 1e-9 * np.max(np.abs(expected))
        assert np.max(np.abs(reactions[f"{name}_Fz"])) < 1e-9 * np.max(np.abs(expected))


def test_layered_cavern_walls_are_traction_free():
    """The layered cavern's outer faces carry the boundary and the input; the lining's inner face and
    the cavern's ends are free: none of their nodes gets a dashpot or an input force."""
    from pyfem.operators import build_model

    scene = parse_scene({
        "title": "small cavern",
        "mesh": {"builder": "layered_cavern",
                 "parameters": {"preset": "coarse", "half_width_x": 60.0, "below": 40.0, "above": 40.0,
                                "margin_y": 40.0, "h_far": 15.0}},
        "materials": {"sandstone": {"preset": "sandstone"}, "non_sandstone": {"preset": "non_sandstone"},
                      "lining": {"preset": "concrete"}},
        "time": {"duration": 0.1},
        "wave": {"type": "SV", "medium": "sandstone", "motion": {"ricker": {"f0": 2.0, "amplitude": 1e-3}}},
    })
    model = build_model(scene)
    assert [face.name for face in model.faces] == list(BOX_FACES)
    assert {"lining_inner", "cavern_ends"} <= set(model.free_surfaces)
    simulation = model_in_memory(scene, solve_stage=False)  # (one rank, no contact: the kernel's numbering is the mesh's)
    assert simulation.part.kernel_of_dolfinx is None
    carrying = set(simulation.input_arrays["nodes"].tolist()) | set(simulation.part.dashpot_nodes.tolist())
    tags = model.facet_tags
    for name in ("lining_inner", "cavern_ends"):
        facets = tags.indices[tags.values == model.boundaries[name]]
        model.mesh.topology.create_connectivity(2, 0)
        wall_nodes = _facet_nodes(model, facets)
        assert len(wall_nodes) > 100
        assert not (set(wall_nodes.tolist()) & carrying), f"{name} carries no boundary and no input"


def _facet_nodes(model, facets):
    """Nodes (dof blocks) of the space on the given facets."""
    from dolfinx import fem

    dofs = fem.locate_dofs_topological(model.V, 2, facets)
    return np.unique(dofs)

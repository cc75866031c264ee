"""Geometry builders and gmsh -> dolfinx conversion: cell counts, names, checks."""
import importlib.util
import pathlib

import gmsh
import numpy as np
import pytest
from dolfinx import mesh as dolfinx_mesh

from conftest import write_msh_with_quadratic_tetrahedra
from pyfem.geometry import BOX_FACES, elements_per_direction, gmsh_session
from pyfem.mesh import create_mesh

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]


def box_scene(size=(2.0, 1.0, 1.5), h=0.5, origin=(1.0, 2.0, 3.0), materials=None):
    return {
        "mesh": {"builder": "box", "origin": list(origin), "size": list(size), "h": h, "order": 1},
        "materials": materials if materials is not None else {"rock": {"E": 1.0e9, "nu": 0.25, "rho": 2000.0}},
        "boundary": {"type": "viscoelastic", "centre": None},
    }


def two_layer_msh(directory) -> pathlib.Path:
    """Run meshes/make_two_layer_block.py into `directory`; returns the .msh path."""
    spec = importlib.util.spec_from_file_location("make_two_layer_block",
                                                  REPOSITORY / "meshes" / "make_two_layer_block.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    path = pathlib.Path(directory) / "two_layer_block.msh"
    script.make_two_layer_block(str(path))
    return path


@pytest.mark.parametrize("size, h, expected", [
    ((2.0, 1.0, 1.5), 0.5, (4, 2, 3)),      # h divides every edge
    ((1.0, 1.0, 1.0), 0.3, (4, 4, 4)),      # ceil(3.33) = 4
    ((0.1, 3.0, 0.7), 1.0, (1, 3, 1)),      # at least one element
])
def test_box_has_the_asked_number_of_cells(size, h, expected):
    assert elements_per_direction(size, h) == expected
    mesh, cell_tags, _, _, _ = create_mesh(box_scene(size=size, h=h))
    assert mesh.topology.cell_type == dolfinx_mesh.CellType.hexahedron
    assert mesh.topology.index_map(3).size_local == np.prod(expected)
    assert len(cell_tags.indices) == np.prod(expected)


def test_box_has_region_rock_and_six_faces_on_their_planes():
    origin, size, h = np.array([1.0, 2.0, 3.0]), np.array([2.0, 1.0, 1.5]), 0.5
    mesh, cell_tags, facet_tags, regions, boundaries = create_mesh(box_scene(size=size, h=h, origin=origin))
    assert list(regions) == ["rock"]
    assert np.all(cell_tags.values == regions["rock"])
    assert sorted(boundaries) == sorted(BOX_FACES)
    n_elements = np.array(elements_per_direction(size, h))
    checks = 0
    for name, tag in boundaries.items():
        axis, side = "xyz".index(name[0]), name[1:]
        facets = facet_tags.indices[facet_tags.values == tag]
        # A face normal to axis i has prod(n_j, j != i) quadrilaterals.
        assert len(facets) == np.prod(np.delete(n_elements, axis))
        midpoints = dolfinx_mesh.compute_midpoints(mesh, 2, facets)
        plane = origin[axis] + (size[axis] if side == "max" else 0.0)
        np.testing.assert_allclose(midpoints[:, axis], plane, rtol=0, atol=1e-12 * size.max())
        checks += 1
    assert checks == 6


def test_two_layer_file_gives_both_regions_and_the_interface(tmp_path):
    path = two_layer_msh(tmp_path)
    materials = {"sandstone": {"E": 8e9, "nu": 0.24, "rho": 2600.0}, "mudstone": {"E": 2e9, "nu": 0.3, "rho": 2400.0}}
    scene = {"mesh": {"builder": "file", "file": str(path), "order": 1}, "materials": materials,
             "boundary": {"centre": None}}
    mesh, cell_tags, facet_tags, regions, boundaries = create_mesh(scene)
    assert sorted(regions) == ["mudstone", "sandstone"]
    assert sorted(boundaries) == sorted(list(BOX_FACES) + ["interface_1"])
    # Lower layer z < 0.8, upper z > 0.8 (make_two_layer_block.INTERFACE_Z).
    for name, below in (("sandstone", True), ("mudstone", False)):
        cells = cell_tags.indices[cell_tags.values == regions[name]]
        assert len(cells) > 0
        z = dolfinx_mesh.compute_midpoints(mesh, 3, cells)[:, 2]
        assert np.all(z < 0.8) if below else np.all(z > 0.8)
    interface = facet_tags.indices[facet_tags.values == boundaries["interface_1"]]
    np.testing.assert_allclose(dolfinx_mesh.compute_midpoints(mesh, 2, interface)[:, 2], 0.8, atol=1e-12)


@pytest.mark.parametrize("materials, key", [
    ({"sandstone": {"E": 8e9, "nu": 0.24, "rho": 2600.0}}, "materials.mudstone"),
    ({"sandstone": {"E": 8e9, "nu": 0.24, "rho": 2600.0}, "mudstone": {"E": 2e9, "nu": 0.3, "rho": 2400.0},
      "granite": {"E": 5e10, "nu": 0.2, "rho": 2700.0}}, "materials.granite"),
])
def test_regions_and_materials_must_match(tmp_path, materials, key):
    path = two_layer_msh(tmp_path)
    scene = {"mesh": {"builder": "file", "file": str(path), "order": 1}, "materials": materials,
             "boundary": {"centre": None}}
    with pytest.raises(ValueError, match=key) as error:
        create_mesh(scene)
    assert "mudstone" in str(error.value) and "sandstone" in str(error.value)  # lists the regions found


def test_box_material_name_mismatch_names_the_key():
    with pytest.raises(ValueError, match="materials.granite"):
        create_mesh(box_scene(materials={"granite": {"E": 1e9, "nu": 0.2, "rho": 2000.0}}))


def test_gmsh_quadratic_tetrahedra_are_rejected(tmp_path):
    path = tmp_path / "tets.msh"
    write_msh_with_quadratic_tetrahedra(path)
    scene = box_scene()
    scene["mesh"] = {"builder": "file", "file": str(path), "order": 1}
    with pytest.raises(ValueError, match="Tetrahedron 10"):
        create_mesh(scene)


@pytest.mark.parametrize("mesh_settings, key", [
    ({"builder": "cavern"}, "mesh.builder"),
    ({"h": 0.0}, "mesh.h"),
    ({"size": [1.0, -1.0, 1.0]}, "mesh.size"),
    ({"origin": [0.0, 0.0]}, "mesh.origin"),
    ({"builder": "file", "file": "/nonexistent/block.msh"}, "mesh.file"),
])
def test_bad_mesh_settings_name_the_key(mesh_settings, key):
    scene = box_scene()
    scene["mesh"].update(mesh_settings)
    with pytest.raises(ValueError, match=key):
        create_mesh(scene)


GMSH_STATE_WITHOUT_CALLING_GMSH = """
from pyfem._gmsh import gmsh
from pyfem.geometry.box import gmsh_is_initialized

library = gmsh.lib
calls = []


class Untouchable:
    def __getattr__(self, name):
        calls.append(name)
        raise RuntimeError(f"gmsh.lib.{name} called while gmsh is not initialized")


gmsh.lib = Untouchable()
assert not gmsh_is_initialized()
gmsh.lib = library
gmsh.initialize(readConfigFiles=False)
assert gmsh_is_initialized()
gmsh.finalize()
gmsh.lib = Untouchable()
assert not gmsh_is_initialized()
assert not calls, calls
print("ok")
"""


def test_whether_gmsh_runs_is_known_without_calling_it():
    # gmsh 4.8 reads an uninitialised AbortOnError when called before initialize; when the
    # heap happens to hold 1 there, it calls exit(1). A CI run ended that way, silently.
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-c", GMSH_STATE_WITHOUT_CALLING_GMSH], cwd=REPOSITORY,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr


def test_a_running_gmsh_session_is_left_alone():
    gmsh.initialize(readConfigFiles=False)  # a no-op if already running
    gmsh.model.add("user_model")
    try:
        create_mesh(box_scene())
        assert gmsh.model.getCurrent() == "user_model"
        assert "pyfem" not in gmsh.model.list()
    finally:
        gmsh.model.setCurrent("user_model")
        gmsh.model.remove()

"""Interface splitting and contact node pairs: counts, areas, normals, masses, decoupling."""
import importlib.util
import pathlib

import numpy as np
import pytest

from conftest import ROUNDOFF, rel_error
from pyfem.interface_split import oriented_normals, split_topology
from pyfem.operators import build_model
from pyfem.scene import SceneError, parse_scene

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
SIZE = (4.0, 2.0, 4.0)
H = 1.0
RHO_LOWER, RHO_UPPER = 2600.0, 2000.0


def layered_scene(thicknesses=(2.0, 2.0), contact=("interface_1",), order=1, size=SIZE, h=H):
    materials = {"lower": {"E": 8.0e9, "nu": 0.24, "rho": RHO_LOWER},
                 "upper": {"E": 2.0e9, "nu": 0.30, "rho": RHO_UPPER}}
    names = ["lower", "upper"]
    layers = [{"material": names[k % 2], "thickness": t} for k, t in enumerate(thicknesses)]
    data = {"mesh": {"builder": "box", "size": list(size), "h": h, "order": order, "layers": layers},
            "materials": {name: materials[name] for name in sorted({layer["material"] for layer in layers})},
            "time": {"duration": 0.1}}
    if contact:
        data["contact"] = {"interfaces": list(contact), "cohesion": 1.0e6, "friction_angle": 30.0}
    return parse_scene(data)


def nodes_per_interface(order, size=SIZE, h=H):
    n_x, n_y = (round(size[0] / h), round(size[1] / h))
    return (order * n_x + 1) * (order * n_y + 1)


@pytest.mark.parametrize("order", [1, 2])
def test_two_layer_box_splits_into_pairs_with_exact_area_normal_and_mass(order):
    split = build_model(layered_scene(order=order))
    whole = build_model(layered_scene(contact=(), order=order))
    pairs = split.pairs
    # One pair per node of the interface plane (Q2: vertex, edge and face nodes).
    assert len(pairs) == nodes_per_interface(order)
    assert split.n_nodes == whole.n_nodes + len(pairs)
    assert np.allclose(pairs.coords[:, 2], 2.0, rtol=0, atol=1e-12)
    assert abs(pairs.area.sum() - SIZE[0] * SIZE[1]) < ROUNDOFF * SIZE[0] * SIZE[1]
    assert np.max(np.abs(pairs.normal - [0.0, 0.0, 1.0])) < ROUNDOFF
    assert abs(split.mass.sum() - whole.mass.sum()) < ROUNDOFF * whole.mass.sum()
    # Each pair's two masses add up to the unsplit node's mass at that point (mapped by coordinates).
    from scipy.spatial import cKDTree
    distance, unsplit = cKDTree(whole.node_coords).query(pairs.coords)
    assert np.max(distance) < 1e-12
    assert rel_error(pairs.mass.sum(axis=1), whole.mass[unsplit]) < ROUNDOFF
    # Side rule: i is below (dense layer), j above; equal element sizes make the ratio rho_i / rho_j.
    assert rel_error(pairs.mass[:, 0] / pairs.mass[:, 1], np.full(len(pairs), RHO_LOWER / RHO_UPPER)) < ROUNDOFF
    assert np.max(np.abs(split.node_coords[pairs.nodes[:, 0]] - split.node_coords[pairs.nodes[:, 1]])) < 1e-12


@pytest.mark.parametrize("order", [1, 2])
def test_split_stiffness_has_no_coupling_across_the_interface(order):
    model = build_model(layered_scene(order=order))
    z = model.node_coords[:, 2]
    upper = z > 2.0 + 1e-9
    upper[model.pairs.nodes[:, 1]] = True  # the side-j copies belong to the upper layer
    stiffness = model.stiffness.tocoo()
    row_node, column_node = stiffness.row // 3, stiffness.col // 3
    crossing = upper[row_node] != upper[column_node]
    assert np.count_nonzero(stiffness.data[crossing]) == 0
    # The check saw the couplings within each side (it is not vacuous).
    assert np.count_nonzero(stiffness.data[upper[row_node] & upper[column_node]]) > 0
    # A rigid translation of the upper side alone produces no force anywhere.
    u = np.zeros((model.n_nodes, 3))
    u[upper] = [1.0e-3, -2.0e-3, 0.5e-3]
    force = model.stiffness @ u.ravel()
    assert np.max(np.abs(force)) < ROUNDOFF * np.max(np.abs(model.stiffness.data)) * 1e-3


def test_contact_off_leaves_the_mesh_unsplit():
    model = build_model(layered_scene(contact=()))
    n_x, n_y, n_z = 4, 2, 4
    assert model.pairs is None and model.interface_tags == {}
    assert model.n_nodes == (n_x + 1) * (n_y + 1) * (n_z + 1)
    assert sorted(model.regions) == ["lower", "upper"]
    assert "interface_1" in model.boundaries  # the surface is tagged, just not split
    facets = model.facet_tags.indices[model.facet_tags.values == model.boundaries["interface_1"]]
    assert len(facets) == n_x * n_y


def test_outer_faces_hold_both_copies_and_keep_their_area():
    split = build_model(layered_scene())
    whole = build_model(layered_scene(contact=()))
    checks = 0
    for face_split, face_whole in zip(split.faces, whole.faces):
        assert face_split.name == face_whole.name
        assert abs(face_split.area.sum() - face_whole.area.sum()) < ROUNDOFF * face_whole.area.sum()
        if face_split.name[0] in "xy":  # side faces cross the interface: its line of nodes appears twice
            line_nodes = (SIZE[1] if face_split.name[0] == "x" else SIZE[0]) / H + 1
            assert len(face_split.nodes) == len(face_whole.nodes) + line_nodes
            checks += 1
    assert checks == 4


def test_several_interfaces_split_independently():
    scene = layered_scene(thicknesses=(1.0, 2.0, 1.0), contact=("interface_1", "interface_2"), order=2)
    model = build_model(scene)
    pairs = model.pairs
    assert pairs.names == ["interface_1", "interface_2"]
    checks = 0
    for name, z in (("interface_1", 1.0), ("interface_2", 3.0)):
        members = pairs.of_interface(name)
        assert len(members) == nodes_per_interface(2)
        assert np.allclose(pairs.coords[members, 2], z, rtol=0, atol=1e-12)
        assert abs(pairs.area[members].sum() - SIZE[0] * SIZE[1]) < ROUNDOFF * 8.0
        checks += 1
    assert checks == 2
    # Interface 2 has the dense layer ("lower" material, third layer) above it: masses follow the side rule.
    members = pairs.of_interface("interface_2")
    assert rel_error(pairs.mass[members, 1] / pairs.mass[members, 0],
                     np.full(len(members), RHO_LOWER / RHO_UPPER)) < ROUNDOFF


def test_msh_file_interface_splits(tmp_path):
    spec = importlib.util.spec_from_file_location("make_two_layer_block", REPOSITORY / "meshes" / "make_two_layer_block.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    path = tmp_path / "two_layer_block.msh"
    script.make_two_layer_block(str(path))
    scene = parse_scene({"mesh": {"builder": "file", "file": str(path)},
                         "materials": {"sandstone": {"preset": "sandstone"}, "mudstone": {"preset": "non_sandstone"}},
                         "time": {"duration": 0.1},
                         "contact": {"interfaces": ["interface_1"], "cohesion": 1.0e6, "friction_angle": 30.0}})
    model = build_model(scene)
    assert len(model.pairs) == (5 + 1) * (3 + 1)  # 2 m / 0.4 m by ceil(1 / 0.4) elements
    assert abs(model.pairs.area.sum() - 2.0) < ROUNDOFF
    assert np.max(np.abs(model.pairs.normal - [0, 0, 1])) < ROUNDOFF
    # The split interface is exterior to each side but is not an outer boundary face.
    assert sorted(face.name for face in model.faces) == ["xmax", "xmin", "ymax", "ymin", "zmax", "zmin"]


def test_split_topology_of_two_stacked_hexahedra():
    x = np.array([[i, j, k] for k in range(3) for j in range(2) for i in range(2)], dtype=float)
    node = lambda i, j, k: 4 * k + 2 * j + i  # noqa: E731
    cells = np.array([[node(0, 0, k), node(1, 0, k), node(1, 1, k), node(0, 1, k),
                       node(0, 0, k + 1), node(1, 0, k + 1), node(1, 1, k + 1), node(0, 1, k + 1)] for k in range(2)])
    middle = np.array([[node(0, 0, 1), node(1, 0, 1), node(1, 1, 1), node(0, 1, 1)]])
    x_split, cells_split, facets, values, tags, copy_of = split_topology(x, cells, middle, np.array([7]),
                                                                         {"interface_1": 7})
    assert len(x_split) == 16 and tags == {"interface_1": (7, 8)}
    assert np.array_equal(cells_split[0], cells[0])                 # side i (below) keeps its nodes
    assert set(cells_split[1, :4]) == set(range(12, 16))             # side j gets the copies
    assert np.array_equal(copy_of[12:], np.sort(middle[0]))
    assert np.array_equal(values, [7, 8]) and set(facets[1]) == set(range(12, 16))
    assert np.allclose(oriented_normals(np.array([[0, 0, -2.0], [-1.0, 0, 0], [0, -1.0, 0]])),
                       [[0, 0, 2.0], [1.0, 0, 0], [0, 1.0, 0]])


@pytest.mark.parametrize("change, key", [
    (lambda d: d["contact"].update(interfaces=["interface_9"]), "contact.interfaces.0"),
    (lambda d: d["mesh"]["layers"][0].update(thickness=3.0), "mesh.layers"),
    (lambda d: d["mesh"]["layers"][0].update(material="granite"), "mesh.layers.0.material"),
])
def test_bad_layer_and_interface_keys_are_scene_errors(change, key):
    data = {"mesh": {"builder": "box", "size": [4.0, 2.0, 4.0], "h": 1.0,
                     "layers": [{"material": "a", "thickness": 2.0}, {"material": "b", "thickness": 2.0}]},
            "materials": {"a": {"preset": "sandstone"}, "b": {"preset": "non_sandstone"}},
            "time": {"duration": 0.1},
            "contact": {"interfaces": ["interface_1"], "cohesion": 1.0e6, "friction_angle": 30.0}}
    change(data)
    with pytest.raises(SceneError) as caught:
        parse_scene(data)
    assert caught.value.key == key

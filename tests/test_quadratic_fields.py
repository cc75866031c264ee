"""fields.xdmf of a second-order model holds every node (issue 47, one model; pyfem/quadratic_fields.py):
the distributed model writes a Q2 box and a P2 tetrahedral box on its node mesh (the same cells with a
second-order geometry: Hexahedron_27 / Tetrahedron_10), on one rank (PYFEM_ONE_MODEL=1) and on two
(mpirun). Every node of the function space is a point of the file and its values are the serial run's
(whose RunWriter splits each cell into 8 linear ones over the same nodes) within 1e-12 m; the cell
data (stress, region) is per cell, the serial run's sub-cells' value.
"""
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pyfem.fields_file import read_fields

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"

# The rock, the wave and the outputs both meshes share (an SV pulse through a 20 m cube).
COMMON = """
[materials.rock]
preset = "sandstone"
[time]
duration = 0.03
[wave]
type = "SV"
angle = 20.0
surface = 20.0
medium = "rock"
motion = {ricker = {f0 = 40.0, amplitude = 0.001}}
[output]
interval = 0.005
xdmf_interval = 0.01
fields = ["displacement", "velocity", "stress"]
"""

BOX = """
title = "Q2 box fields"
[mesh]
builder = "box"
size = [20.0, 10.0, 20.0]
h = 10.0
order = 2
""" + COMMON

TET = """
title = "P2 tetrahedra fields"
[mesh]
builder = "file"
file = "box.geo"
order = 2
""" + COMMON

GEO = ('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 20, 10, 20};\nPhysical Volume("rock") = {1};\n'
       "Mesh.MeshSizeMax = 10;\nMesh.MeshSizeMin = 10;\n")


def run(scene: Path, out: Path, ranks: int, one_model: bool) -> Path:
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    env.pop("PYFEM_ONE_MODEL", None)
    if one_model:
        env["PYFEM_ONE_MODEL"] = "1"
    command = [PYTHON, "-m", "pyfem", "run", str(scene), "--out", str(out)]
    if ranks > 1:
        mpirun = shutil.which("mpirun")
        assert mpirun is not None, "mpirun not found: scripts/setup.sh installs openmpi-bin"
        command = [mpirun, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    result = subprocess.run(command, cwd=scene.parent, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return out / "fields.xdmf"


@pytest.fixture(scope="module", params=["box", "tet"])
def files(request, tmp_path_factory):
    base = tmp_path_factory.mktemp(request.param)
    (base / "box.geo").write_text(GEO)
    scene = base / "scene.toml"
    scene.write_text(BOX if request.param == "box" else TET)
    return request.param, {label: run(scene, base / label, ranks, one)
                           for label, ranks, one in (("serial", 1, False), ("one", 1, True), ("two", 2, True))}


def by_position(points: np.ndarray) -> np.ndarray:
    return np.lexsort(np.round(points, 6).T[::-1])


@pytest.mark.parametrize("path", ["one", "two"])
def test_every_node_of_a_second_order_model_is_in_the_fields_file(files, path):
    kind, paths = files
    serial, fields = read_fields(paths["serial"]), read_fields(paths[path])
    assert fields.cells.shape[1] == (27 if kind == "box" else 10)  # quadratic cells, not their corners
    text = paths[path].read_text()
    assert ("Hexahedron_27" if kind == "box" else "Tetrahedron_10") in text
    # Every node of the function space: a Q2 box of 2 x 1 x 2 cells has 5 x 3 x 5 nodes; a P2 mesh
    # its vertices and edge midpoints (the serial file's points: every node).
    n_nodes = 5 * 3 * 5 if kind == "box" else len(serial.points)
    assert len(fields.points) == n_nodes == len(np.unique(np.round(fields.points, 6), axis=0))
    assert np.unique(fields.cells).size == n_nodes
    # VTK's node order (ParaView's): edge midpoints, then (Q2) face centres and the cell centre.
    x = fields.points[fields.cells]
    if kind == "box":
        edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
        faces = [(0, 3, 7, 4), (1, 2, 6, 5), (0, 1, 5, 4), (3, 2, 6, 7), (0, 1, 2, 3), (4, 5, 6, 7)]
        for k, face in enumerate(faces):
            np.testing.assert_allclose(x[:, 20 + k], x[:, list(face)].mean(axis=1), atol=1e-9)
        np.testing.assert_allclose(x[:, 26], x[:, :8].mean(axis=1), atol=1e-9)
    else:
        edges = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    first = 8 if kind == "box" else 4
    for k, (a, b) in enumerate(edges):
        np.testing.assert_allclose(x[:, first + k], 0.5 * (x[:, a] + x[:, b]), atol=1e-9)
    mine, theirs = by_position(fields.points), by_position(serial.points)
    assert np.array_equal(np.round(fields.points[mine], 9), np.round(serial.points[theirs], 9))
    assert fields.times == serial.times and len(fields.times) >= 3
    for (t, point, cell), (_, serial_point, serial_cell) in zip(fields.steps, serial.steps):
        for name in ("displacement", "velocity"):
            assert point[name].shape == (n_nodes, 3)
            np.testing.assert_allclose(point[name][mine], serial_point[name][theirs], rtol=0, atol=1e-12)
    last, serial_last = fields.steps[-1], serial.steps[-1]
    assert np.abs(serial_last[1]["displacement"]).max() > 1e-6  # the wave arrived
    # Cell data per cell: each serial sub-cell's value is its parent's (the cell holding its nodes).
    serial_in_mine = np.empty(n_nodes, dtype=np.int64)  # serial point -> this file's point
    serial_in_mine[theirs] = mine
    cell_sets = [set(nodes) for nodes in fields.cells.tolist()]
    assert last[2]["stress"].shape == (len(fields.cells), 6) and np.abs(last[2]["stress"]).max() > 0
    for sub, nodes in enumerate(serial_in_mine[serial.cells].tolist()):
        parents = [c for c, cell in enumerate(cell_sets) if set(nodes) <= cell]
        assert len(parents) == 1
        np.testing.assert_allclose(last[2]["stress"][parents[0]], serial_last[2]["stress"][sub], rtol=1e-9, atol=1e-3)
        assert last[2]["region"][parents[0]] == serial_last[2]["region"][sub]


def test_the_file_is_an_hdf5_xdmf_time_series(files):
    """h5py opens the data; the XML names a temporal collection per field, one grid per time."""
    import h5py
    from xml.etree import ElementTree as ET

    _, paths = files
    root = ET.parse(paths["two"]).getroot()
    collections = root.findall("Domain/Grid[@CollectionType='Temporal']")
    assert {c.get("Name") for c in collections} >= {"displacement", "velocity", "stress"}
    with h5py.File(paths["two"].with_suffix(".h5"), "r") as data:
        for collection in collections:
            for grid in collection.findall("Grid"):
                item = grid.find("Attribute/DataItem")
                assert data[item.text.split(":", 1)[1]].shape[0] == int(item.get("Dimensions").split()[0])


def test_the_pair_fields_of_a_q2_contact_model_at_every_node(tmp_path):
    """A Q2 model with split interfaces in contact (tests/scenes/mpi_hard_contact.toml, coarser and
    shorter) on 2 ranks: displacement and the pair fields at every node (the two nodes of a pair
    apart), the serial file's (the pairs slid: pair_slip > 0)."""
    from test_distributed_model import last_fields

    scene = REPO / "tests" / "scenes" / "mpi_hard_contact.toml"
    overrides = ["mesh.order=2", "mesh.h=8.0", "time.duration=0.3", "output.xdmf_interval=0.1"]
    fields = {}
    for label, ranks, one in (("serial", 1, False), ("two", 2, True)):
        env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
        env.pop("PYFEM_ONE_MODEL", None)
        if one:
            env["PYFEM_ONE_MODEL"] = "1"
        command = [PYTHON, "-m", "pyfem", "run", str(scene), "--out", str(tmp_path / label)]
        command += [item for key in overrides for item in ("--set", key)]
        if ranks > 1:
            command = [shutil.which("mpirun"), "--allow-run-as-root", "--oversubscribe", "-n", "2"] + command
        result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        fields[label] = last_fields(tmp_path / label)
    serial, two = fields["serial"], fields["two"]
    assert len(read_fields(tmp_path / "two" / "fields.xdmf").points) == len(serial["displacement"])
    assert np.abs(serial["pair_slip"]).max() > 1e-5 and np.abs(serial["displacement"]).max() > 1e-3
    for name in ("displacement", "pair_slip", "pair_D", "pair_state"):
        assert two[name].shape == serial[name].shape
        np.testing.assert_allclose(two[name], serial[name], rtol=0, atol=1e-12 * max(1.0, np.abs(serial[name]).max()))

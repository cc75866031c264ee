"""fields.xdmf of a second-order model holds every node (issue 47, one model; pyfem/quadratic_fields.py):
the model writes a Q2 box and a P2 tetrahedral box on its node mesh (the same cells with a
second-order geometry: Hexahedron_27 / Tetrahedron_10), on one rank and on two (mpirun). Every node of
the function space is a point of the file, in VTK's node order; a mid-edge node holds its own value,
not the mean of the edge's ends (the field is not interpolated to Q1); two ranks write the one-rank
file's values within 1e-12 m and its cell data (stress, region) per cell. (Before the serial path went,
the one-rank file equalled the serial writer's, which split each cell into 8 linear ones, to 1e-12 m.)
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


def run(scene: Path, out: Path, ranks: int) -> Path:
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
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
    return request.param, {label: run(scene, base / label, ranks) for label, ranks in (("one", 1), ("two", 2))}


def by_position(points: np.ndarray) -> np.ndarray:
    return np.lexsort(np.round(points, 6).T[::-1])


@pytest.mark.parametrize("path", ["one", "two"])
def test_every_node_of_a_second_order_model_is_in_the_fields_file(files, path):
    kind, paths = files
    fields = read_fields(paths[path])
    assert fields.cells.shape[1] == (27 if kind == "box" else 10)  # quadratic cells, not their corners
    text = paths[path].read_text()
    assert ("Hexahedron_27" if kind == "box" else "Tetrahedron_10") in text
    # Every node of the function space: a Q2 box of 2 x 1 x 2 cells has 5 x 3 x 5 nodes; a P2 mesh
    # its vertices and edge midpoints.
    vertices = np.unique(fields.cells[:, :8 if kind == "box" else 4])
    n_nodes = 5 * 3 * 5 if kind == "box" else vertices.size + len({tuple(sorted(edge)) for cell in fields.cells.tolist()
                                                                   for edge in _tet_edges(cell)})
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
        edges = TET_EDGES
    first = 8 if kind == "box" else 4
    for k, (a, b) in enumerate(edges):
        np.testing.assert_allclose(x[:, first + k], 0.5 * (x[:, a] + x[:, b]), atol=1e-9)
    assert len(fields.times) >= 3
    last = fields.steps[-1]
    u = last[1]["displacement"]
    assert u.shape == (n_nodes, 3) and np.abs(u).max() > 1e-6  # the wave arrived
    # A mid-edge node holds its own value: the quadratic field, not its linear interpolation.
    u_cells = u[fields.cells]
    bent = max(np.abs(u_cells[:, first + k] - 0.5 * (u_cells[:, a] + u_cells[:, b])).max() for k, (a, b) in enumerate(edges))
    assert bent > 1e-3 * np.abs(u).max(), bent
    assert last[2]["stress"].shape == (len(fields.cells), 6) and np.abs(last[2]["stress"]).max() > 0
    if path == "one":
        return
    one = read_fields(paths["one"])  # two ranks write the one-rank file's values, node by node and cell by cell
    mine, theirs = by_position(fields.points), by_position(one.points)
    assert np.array_equal(np.round(fields.points[mine], 9), np.round(one.points[theirs], 9))
    assert fields.times == one.times
    for (t, point, cell), (_, one_point, one_cell) in zip(fields.steps, one.steps):
        for name in ("displacement", "velocity"):
            np.testing.assert_allclose(point[name][mine], one_point[name][theirs], rtol=0, atol=1e-12)
    centres = by_position(fields.points[fields.cells].mean(axis=1))
    one_centres = by_position(one.points[one.cells].mean(axis=1))
    np.testing.assert_allclose(last[2]["stress"][centres], one.steps[-1][2]["stress"][one_centres], rtol=1e-9, atol=1e-3)
    assert np.array_equal(last[2]["region"][centres], one.steps[-1][2]["region"][one_centres])


TET_EDGES = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]


def _tet_edges(cell):
    return [(cell[a], cell[b]) for a, b in TET_EDGES]


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
    apart), the one-rank file's (the pairs slid: pair_slip > 0)."""
    from test_distributed_model import last_fields

    scene = REPO / "tests" / "scenes" / "mpi_hard_contact.toml"
    overrides = ["mesh.order=2", "mesh.h=8.0", "time.duration=0.3", "output.xdmf_interval=0.1"]
    fields = {}
    for label, ranks in (("serial", 1), ("two", 2)):
        env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
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

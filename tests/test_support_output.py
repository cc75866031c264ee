"""The bolts' pictures and ParaView files (pyfem/support_output.py): which bolts the monitoring
section's plot shows, and that support.xdmf / static/support.xdmf hold the segments of
support.csv / static/support.csv as line cells (read back with meshio)."""
import json

import numpy as np
import pytest

from pyfem import solver
from pyfem.scene import parse_scene
from pyfem.support_output import BoltState, FEW_BOLTS, plot_section, section_bolts, section_y
from test_support_scene import column_settings


def straight_bolts(name, heads, direction, length=3.0, nodes=4, yielded=()):
    """A BoltState of straight bolts from `heads` along `direction`; segment force = 1000 x (bolt + 1);
    the segments listed in `yielded` (indices into the per-segment arrays) marked."""
    heads = np.asarray(heads, dtype=float)
    s = np.linspace(0.0, length, nodes)
    direction = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    positions = np.concatenate([head + s[:, None] * direction for head in heads])
    n = len(heads)
    force = np.repeat(1000.0 * (np.arange(n) + 1.0), nodes - 1)
    flags = np.zeros(n * (nodes - 1), dtype=bool)
    flags[list(yielded)] = True
    return BoltState(name, np.arange(n + 1) * nodes, np.tile(s, n), positions, force, np.zeros(n * nodes), flags,
                     5.0e3)


def test_the_section_plot_shows_the_row_nearest_the_plane_or_a_small_group_whole(tmp_path):
    # A pattern of three rows of 14 bolts (more than FEW_BOLTS) along -x at y = 0.75, 2.25, 3.75.
    around = 14
    assert around > FEW_BOLTS
    heads = [[0.0, y, z] for y in (0.75, 2.25, 3.75) for z in np.arange(around)]
    walls = straight_bolts("walls", heads, [-1.0, 0.0, 0.0], yielded=[3 * around + 1, 3 * around + 2, 0])
    # Section y = 2.0: the row at 2.25 (0.25 m off; the others 1.25 and 1.75 m), its 14 bolts.
    assert section_bolts(walls, 2.0).tolist() == list(range(around, 2 * around))
    assert section_bolts(walls, 0.0).tolist() == list(range(around))
    # Midway between two rows (y = 1.5): the one on the -y side.
    assert section_bolts(walls, 1.5).tolist() == list(range(around))
    assert section_bolts(walls, 3.0).tolist() == list(range(around, 2 * around))
    # A bolt crossing the plane is in it (distance 0), ahead of every row that does not cross it.
    # (bolts along (-1, 0.1, 0): the rows rise 0.3 m; the bolt from y = 1.9 crosses y = 2.0)
    crossing = straight_bolts("walls", heads + [[0.0, 1.9, 0.0]], [-1.0, 0.1, 0.0])
    assert section_bolts(crossing, 3.0).tolist() == list(range(around, 2 * around))
    assert section_bolts(crossing, 2.0).tolist() == [3 * around]
    # A small group is drawn whole, wherever its bolts are.
    cables = straight_bolts("cables", [[0.0, 50.0, 0.0], [0.0, 60.0, 0.0]], [0.0, 0.0, 1.0])
    assert section_bolts(cables, 2.0).tolist() == [0, 1]

    png = tmp_path / "plots" / "support.png"
    drawn = plot_section(png, [walls, cables], 2.0, "monitor A")
    assert png.stat().st_size > 10_000  # drawn, one panel per group
    assert list(drawn) == ["walls", "cables"]
    assert drawn["walls"]["bolts"] == list(range(around, 2 * around)) and drawn["cables"]["bolts"] == [0, 1]
    # The yielded segments of the drawn bolts are marked: bolt 14's second and third; segment 0 is
    # bolt 0's, not drawn.
    assert drawn["walls"]["yielded_segments"] == 2 and drawn["cables"]["yielded_segments"] == 0
    assert plot_section(tmp_path / "none.png", [], 0.0, "") == {} and not (tmp_path / "none.png").exists()


# the column of tests/test_support_scene.py (its rock and load), with a weak bond: the bolts slip
BOLT = {"diameter": 0.032, "yield_force": 3.2e5, "bond_stiffness": 1.0e9, "bond_strength": 2.0e3, "segment": 0.5}


def bolted_scene(monitor_y=None):
    """tests/test_support_scene.py's column: a 4 x 4 x 10 m box whose top 4 m the stage removes under a
    vertical 5 MPa; group "stage" (two vertical bolts, a weak bond: they slip) installed in the stage,
    group "late" (one bolt) at the start of the run."""
    scene = column_settings({"stage": dict(BOLT, lines=[[1.5, 1.5, 6.0, 1.5, 1.5, 1.0], [2.5, 2.5, 6.0, 2.5, 2.5, 2.0]]),
                             "late": dict(BOLT, lines=[[2.0, 1.0, 6.0, 2.0, 1.0, 3.0]])}, static_support=("stage",))
    if monitor_y is not None:
        scene["monitor"] = [{"name": "A", "point": [2.0, monitor_y, 5.0]}]
    scene["bolt_monitor"] = [{"name": "mid", "point": [1.6, 1.5, 4.2], "group": "stage"},
                             {"name": "near_late", "point": [2.0, 1.2, 5.8]}]
    return parse_scene(scene)


def read_csv(path):
    return np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")


def read_bolts(path):
    """(points, lines, point data, cell data) of a support.xdmf."""
    import meshio

    with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == 1
        _, point_data, cell_data = reader.read_data(0)
    assert [block.type for block in cells] == ["line"]
    return points, cells[0].data, point_data, {name: values[0] for name, values in cell_data.items()}


def test_support_xdmf_and_plots_after_the_stage_and_at_the_end(tmp_path):
    summary = solver.run(bolted_scene(monitor_y=1.4), tmp_path)
    assert summary["static"]["support"]["stage"]["slipping_nodes"] > 0  # the stage loaded the bolts
    for when, folder, groups in (("stage", tmp_path / "static", ["stage"]), ("end", tmp_path, ["stage", "late"])):
        rows = read_csv(folder / "support.csv")
        points, lines, point_data, cell_data = read_bolts(folder / "support.xdmf")
        assert sorted(set(rows["group"])) == sorted(groups)
        # One line cell per segment of support.csv, in its order; its middle is the row's position.
        assert len(lines) == len(rows) and np.max(np.abs(rows["axial_force"])) > 100.0
        assert np.allclose(0.5 * (points[lines[:, 0]] + points[lines[:, 1]]),
                           np.column_stack([rows["x"], rows["y"], rows["z"]]), atol=1e-12)
        assert np.array_equal(cell_data["segment_axial_force"], rows["axial_force"])
        assert np.array_equal(cell_data["bolt"], rows["bolt"].astype(float))
        # Point data: a node's axial force is the mean of its segments'; the bond slip of the csv is
        # the mean of the segment's two nodes'.
        force, count = np.zeros(len(points)), np.zeros(len(points))
        for end in (0, 1):
            np.add.at(force, lines[:, end], rows["axial_force"])
            np.add.at(count, lines[:, end], 1.0)
        assert np.allclose(point_data["axial_force"], force / count, rtol=1e-12, atol=1e-9)
        assert np.allclose(0.5 * (point_data["bond_slip"][lines[:, 0]] + point_data["bond_slip"][lines[:, 1]]),
                           rows["bond_slip"], rtol=1e-12, atol=1e-18)
        assert np.any(point_data["bond_slip"] != 0.0)
        if when == "end":
            assert np.array_equal(cell_data["peak_axial_force"], rows["peak_axial_force"])
    # The plots: the section y = 1.4 (monitor A); every group has at most FEW_BOLTS bolts: all drawn.
    assert (tmp_path / "static" / "support.png").stat().st_size > 10_000
    assert (tmp_path / "plots" / "support.png").stat().st_size > 10_000
    assert summary["support_plot"] == {"stage": {"bolts": [0, 1], "yielded_segments": 0},
                                       "late": {"bolts": [0], "yielded_segments": 0}}
    static_json = json.loads((tmp_path / "static" / "static.json").read_text())
    assert static_json["plots"]["support"] == {"stage": {"bolts": [0, 1], "yielded_segments": 0}}
    on_disk = json.loads((tmp_path / "run.json").read_text())
    assert on_disk["support_plot"] == summary["support_plot"]

    # Bolt monitors: "mid" the stage's bolt 0 (z 6 -> 1, 0.5 m segments), the segment whose middle
    # (z = 4.25, s = 1.75) is nearest z = 4.2; the whole bolt slips, N = tau min(s, L - s) = 3500 N
    # (tests/test_support_scene.py); "near_late" (no group) the late bolt's first segment.
    rows = read_csv(tmp_path / "support.csv")
    for name, group, s, exact in (("mid", "stage", 1.75, 2.0e3 * 1.75), ("near_late", "late", 0.25, None)):
        history = read_csv(tmp_path / "bolts" / f"{name}.csv")
        assert history.dtype.names == ("t", "axial_force", "bond_slip", "plastic_strain")
        assert len(history) >= 2 and history["t"][0] == 0.0
        where = on_disk["bolt_monitors"][name]
        assert (where["group"], where["bolt"], where["s"]) == (group, 0, s)
        row = rows[(rows["group"] == group) & (rows["bolt"] == 0) & np.isclose(rows["s"], s)]
        assert len(row) == 1
        assert np.isclose(history["axial_force"][-1], row["axial_force"][0], rtol=1e-9, atol=1e-9)
        assert np.isclose(history["bond_slip"][-1], row["bond_slip"][0], rtol=1e-9, atol=1e-15)
        assert where["peak_axial_force"] == np.max(np.abs(history["axial_force"]))
        if exact is not None:  # loaded in the stage: its force from the first sample on
            assert abs(history["axial_force"][0] - exact) < 1e-6 * exact
            assert abs(history["axial_force"][-1] - exact) < 1e-3 * exact
        else:  # installed at the start, in a model at rest (round-off motion): unloaded
            assert history["axial_force"][0] == 0.0 and np.max(np.abs(history["axial_force"])) < 1e-6


def test_the_section_is_the_first_monitors_y_or_the_models_middle():
    class Model:
        node_coords = np.array([[0.0, -3.0, 0.0], [0.0, 5.0, 1.0]])

    assert section_y({"monitor": [{"name": "A", "point": [1.0, 2.5, 3.0]}, {"name": "B", "point": [0, 9, 0]}]},
                     Model()) == (2.5, "monitor A")
    assert section_y({}, Model()) == (1.0, "the model's middle")


@pytest.mark.parametrize("change, key, allowed", [
    ({"bolt_monitor": [{"name": "m", "point": [1.0, 1.0, 1.0], "group": "walls"}]}, "bolt_monitor.0.group",
     "must name a [support.NAME] group: stage, late"),
    ({"bolt_monitor": [{"name": "m", "point": [1.0, 1.0, 11.0]}]}, "bolt_monitor.0.point", "must lie inside the box"),
    ({"support": None, "static": None, "bolt_monitor": [{"name": "m", "point": [1.0, 1.0, 1.0]}]}, "bolt_monitor.0",
     "need a [support.NAME] group"),
])
def test_bad_bolt_monitors_are_one_line_naming_the_key(change, key, allowed):
    from pyfem.scene import SceneError

    settings = bolted_scene().to_json()
    settings.update(change)
    settings = {name: value for name, value in settings.items() if value is not None}
    with pytest.raises(SceneError) as raised:
        parse_scene(settings)
    message = str(raised.value)
    print(message)
    assert raised.value.key == key and allowed in message and "\n" not in message

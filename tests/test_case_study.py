"""The paper's case study: stress at monitor points, and a shortened case 3 through its own scene file.

- Gradient weights at a point reproduce the exact gradient of any field in the space: linear
  fields on non-affine (curved-edge) Q1 hexahedra, quadratic fields on Q2; the monitor stress
  operator turns that gradient into sigma = lambda tr(eps) I + 2 G eps of the containing
  cell's material.
- workflows/scenes/case3_contact_coarse.toml, shortened with a --set style override to a few
  hundred steps, runs on the coarse layered-cavern mesh and writes what the case-study
  workflow reads (stress columns, pair CSVs, run.json), and the workflow's report runs on it.
"""
import json
import math
import pathlib
import sys

import numpy as np
import pytest

from conftest import ENERGY_BALANCE, LOCAL_STEPPING_BALANCE, ROUNDOFF
from pyfem.initial_stress import STANDARD_GRAVITY
from pyfem.operators import build_model, lame_parameters
from pyfem.output import MONITOR_COLUMNS, PAIR_COLUMNS, STRESS_COLUMNS, max_principal
from pyfem.scene import load_scene, parse_scene
from pyfem.effects import monitor_stress_operator

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
CASE3 = REPOSITORY / "workflows" / "scenes" / "case3_contact_coarse.toml"
sys.path.insert(0, str(REPOSITORY / "workflows"))


def box_scene(order: int, h: float = 2.0):
    return parse_scene({
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [6.0, 4.0, 8.0], "h": h, "order": order},
        "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}},
        "time": {"duration": 0.1},
    })


def random_inner_points(model, count: int, seed: int = 3) -> np.ndarray:
    lo, hi = model.bounds
    rng = np.random.default_rng(seed)
    return lo + 0.05 * (hi - lo) + 0.9 * (hi - lo) * rng.random((count, 3))


def distort(model) -> None:
    """Moves the nodes by a smooth non-affine map: the Q1 cells get non-parallel, skewed faces."""
    x = model.mesh.geometry.x
    lo, hi = x.min(axis=0), x.max(axis=0)
    s = (x - lo) / (hi - lo)
    # Zero on the box faces' normal directions, so the box stays a box.
    x[:, 0] += 0.3 * np.sin(np.pi * s[:, 0]) * np.sin(np.pi * s[:, 2])
    x[:, 2] += 0.4 * np.sin(np.pi * s[:, 2]) * np.cos(np.pi * s[:, 0]) * np.sin(np.pi * s[:, 1])
    model.node_coords[:] = model.V.tabulate_dof_coordinates()


def gradient_at(model, points, nodal_values):
    nodes, gradients, _ = model.point_gradient_weights(points)
    return np.einsum("mki,mkl->mil", nodal_values[nodes], gradients)


def test_gradient_weights_are_exact_for_linear_fields_on_distorted_q1_cells():
    model = build_model(box_scene(order=1))
    distort(model)
    matrix = np.array([[1.0, -2.0, 0.5], [0.3, 4.0, -1.0], [2.5, 0.1, -3.0]]) * 1e-3
    values = model.node_coords @ matrix.T + np.array([1.0, 2.0, 3.0])
    points = random_inner_points(model, 25)
    gradient = gradient_at(model, points, values)
    assert gradient.shape == (25, 3, 3)
    # Control: the map really is non-affine (a cell's Jacobian varies inside it).
    nodes, weights = model.point_weights(points)
    assert np.allclose(np.einsum("mk,mkc->mc", weights, model.node_coords[nodes]), points, atol=1e-12)
    assert np.max(np.abs(gradient - matrix)) <= ROUNDOFF * np.abs(matrix).max()


def test_gradient_weights_are_exact_for_quadratic_fields_on_q2():
    model = build_model(box_scene(order=2))
    x = model.node_coords

    def field(p):
        return np.column_stack([p[:, 0] ** 2 + p[:, 1] * p[:, 2], 3 * p[:, 1] ** 2 - p[:, 0], p[:, 0] * p[:, 2]])

    def exact_gradient(p):
        g = np.zeros((len(p), 3, 3))
        g[:, 0, 0], g[:, 0, 1], g[:, 0, 2] = 2 * p[:, 0], p[:, 2], p[:, 1]
        g[:, 1, 0], g[:, 1, 1] = -1.0, 6 * p[:, 1]
        g[:, 2, 0], g[:, 2, 2] = p[:, 2], p[:, 0]
        return g

    points = random_inner_points(model, 25)
    gradient = gradient_at(model, points, field(x))
    expected = exact_gradient(points)
    assert np.max(np.abs(gradient - expected)) <= ROUNDOFF * np.abs(expected).max()
    # Control: Q1 cannot represent this field, so the test can tell the orders apart.
    q1 = build_model(box_scene(order=1))
    assert np.max(np.abs(gradient_at(q1, points, field(q1.node_coords)) - expected)) > 1e-3


def test_monitor_stress_is_hookes_law_of_the_containing_cell_plus_geostatic():
    scene = box_scene(order=1)
    scene["initial_stress"] = {"surface": 20.0, "rho": 2500.0, "k": [1.4, 1.2, 1.15]}
    model = build_model(scene)
    points = np.array([[1.3, 2.1, 3.7], [4.9, 0.6, 7.2]])
    operator = monitor_stress_operator(scene, model, points)
    assert operator.regions == ["rock", "rock"]
    strain = np.array([[1.0, 0.5, 0.0], [0.5, -2.0, 0.25], [0.0, 0.25, 0.5]]) * 1e-5
    u = (model.node_coords @ strain.T).ravel()       # symmetric gradient: strain exactly
    stress = operator.dynamic_stress(u)
    lam, G = lame_parameters(8.0e9, 0.24)
    expected = lam * np.trace(strain) * np.eye(3) + 2 * G * strain
    assert np.max(np.abs(stress - expected)) <= ROUNDOFF * np.abs(expected).max()
    vertical = -2500.0 * STANDARD_GRAVITY * (20.0 - points[:, 2])
    assert np.allclose(operator.static[:, 0, 0], 1.4 * vertical, rtol=1e-14)
    assert np.allclose(operator.static[:, 2, 2], 1.15 * vertical, rtol=1e-14)


def test_max_principal_is_the_largest_eigenvalue_tension_positive():
    # Uniaxial tension 2 MPa along (1, 1, 0)/sqrt(2) with 1 MPa compression along z.
    s = 1.0e6
    voigt = np.array([[s, s, -s, s, 0.0, 0.0], [-3.0, -1.0, -2.0, 0.0, 0.0, 0.0]])
    assert np.allclose(max_principal(voigt), [2 * s, -1.0], rtol=1e-14)


def elastic_case3(overrides=()):
    """Case 3's scene file without its static stage and nonlinear tables (the cavity already hollow,
    the geostatic state): the monitors, pairs and report of the workflow, in seconds instead of the
    static stage's minutes (that one: `test_case_scenes_plan_their_static_stage`, and the slow tier)."""
    import tomllib

    data = tomllib.loads(CASE3.read_text())
    data.pop("static")
    data["mesh"]["parameters"].pop("excavated")
    for material in data["materials"].values():
        material.pop("plasticity", None)
        material.pop("damage", None)
    data["output"].pop("fields", None)  # the damage fields need the nonlinear tables
    # Short runs start at the record's window, without the 1 s lead-in that would run first at t < 0.
    data["wave"]["motion"]["record"]["lead_in"] = 0.0
    return parse_scene(data, source=str(CASE3), overrides=overrides, base_dir=CASE3.parent)


def test_case_scenes_plan_their_static_stage():
    """The three coarse case scenes carry the static stage (excavation, lining installed after
    relaxation), Mohr-Coulomb rock in a zone and the lining's damage law; `check` plans them."""
    from pyfem.solver import plan

    for name in ("case1_vertical_coarse", "case2_oblique_coarse", "case3_contact_coarse"):
        scene = load_scene(REPOSITORY / "workflows" / "scenes" / f"{name}.toml")
        assert scene["static"]["install"] == ["lining"] and scene["static"]["excavate"] == ["excavation"]
        assert scene["materials"]["lining"]["damage"] is not None
        assert scene["materials"]["sandstone"]["plasticity"]["zone"] is not None
    planned = plan(scene)
    stages = planned["static stage"]
    assert "dynamic relaxation" in stages["solver"] and "lining installed stress-free" in stages["stage 2 (support)"]
    # Its time is bounded before the motion's (a new user's run spent minutes in it unannounced).
    assert planned["static stage estimate"].startswith("2 stages of at most 6000 relaxation steps")
    # Case 3's wear is announced with its clock: from the window's start, t = 0 (the lead-in at t < 0).
    assert planned["interface wear"].startswith("eta falls from 1 at t = 0 s")  # record time: the window's start
    assert planned["interface wear"].endswith("0.844 at t = 3.9 s")


def test_case3_wear_starts_with_the_record_window_not_the_lead_in():
    """Case 3's deterioration clock: eta's t = 0 is the record window's start, 1 s into the run
    after the filter's tapered lead-in (wave.motion.record.lead_in), and t_s the window's 20 s; the
    kernel gets both (docs/method.md section 9). Before, the lead-in's second wore the interfaces
    by 5.5 % with nothing shaking them."""
    from pyfem.effects import contact_arguments, earthquake_clock
    from pyfem.interfaces import wear_words

    scene = load_scene(REPOSITORY / "workflows" / "scenes" / "case3_contact_coarse.toml")
    start, duration = earthquake_clock(scene)
    assert scene["wave"]["motion"]["record"]["lead_in"] == 1.0
    assert start == 0.0 and duration == 20.0  # record time: the window starts at t = 0, the lead-in before

    class NoPairs:
        pairs = type("P", (), {"nodes": np.zeros((0, 2)), "area": np.zeros(0), "normal": np.zeros((0, 3)),
                               "coords": np.zeros((0, 3))})()

    arguments = contact_arguments(scene, NoPairs())
    assert arguments["deterioration"] == (0.75, 5.0, 20.0, 0.883, 0.02, 0.032, start)
    # eta as run.json and `check` report it is the kernel's own Eq. 9 (wear_words calls wear_factor).
    words = wear_words(arguments["deterioration"], 3.9)
    assert words["eta_at_end"] == pytest.approx(0.75 + 0.25 * np.exp(-5.0 * 3.9 / 20.0), rel=1e-14)
    assert wear_words(arguments["deterioration"], -0.5)["eta_at_end"] == 1.0  # the lead-in (t < 0) does not wear


@pytest.fixture(scope="module")
def short_case3(tmp_path_factory):
    """Case 3 coarse (elastic, no static stage: `elastic_case3`) for 0.035 s (~300 steps)."""
    from pyfem.solver import run

    scene = elastic_case3(["time.duration=0.035", "output.xdmf_interval=0.0"])
    out = tmp_path_factory.mktemp("runs") / "case3_coarse"
    summary = run(scene, out)
    return scene, out, summary


def test_short_case3_finishes_with_energy_balance_and_all_outputs(short_case3):
    scene, out, summary = short_case3
    on_disk = json.loads((out / "run.json").read_text())
    assert on_disk["status"] == "finished"
    assert on_disk["steps"] >= 250
    assert set(on_disk["effects"]) >= {"seismic_input", "initial_stress", "contact", "deterioration"}
    print(f"{on_disk['dt_reason']}; energy balance {on_disk['energy']['balance_error']:.2e}")
    local = "local time stepping" in on_disk["dt_reason"]
    # global stepping's identity (local stepping's O(dt^2) plain account if "auto" turned it on):
    # catches a contact, input or damping work term missing from the account
    assert on_disk["energy"]["balance_error"] < (LOCAL_STEPPING_BALANCE if local else ENERGY_BALANCE)
    assert on_disk["n_pairs"] > 1000
    for name in ("A", "B", "C", "D"):
        assert on_disk["monitors"][name]["region"] == "lining"   # 1 cm inside the lining's inner face
        assert math.isfinite(on_disk["monitors"][name]["s1_max"])
    pairs_found = 0
    for name in ("wall_up_8", "wall_down_8", "wall_up_9", "wall_down_9", "crown_9"):
        with open(out / "pairs" / f"{name}.csv") as stream:
            assert stream.readline().strip().split(",") == PAIR_COLUMNS
        assert on_disk["pairs"][name]["interface"] in ("interface_8", "interface_9")
        pairs_found += 1
    assert pairs_found == 5


def test_short_case3_monitors_have_stress_columns_consistent_with_the_geostatic_state(short_case3):
    scene, out, _ = short_case3
    settings = scene["initial_stress"]
    checks = 0
    for monitor in scene["monitor"]:
        path = out / "monitors" / f"{monitor['name']}.csv"
        with open(path) as stream:
            header = stream.readline().strip().split(",")
        assert header[:len(MONITOR_COLUMNS)] == MONITOR_COLUMNS
        assert header[-len(STRESS_COLUMNS):] == STRESS_COLUMNS
        data = np.loadtxt(path, delimiter=",", skiprows=1)
        column = {name: data[:, header.index(name)] for name in header}
        # At t = 0 the state is the geostatic one: s1 = k_z sigma_v (the least compressed axis).
        vertical = -settings["rho"] * STANDARD_GRAVITY * (settings["surface"] - monitor["point"][2])
        # (The CSV holds 11 significant digits.)
        assert column["s1"][0] == pytest.approx(min(settings["k"]) * vertical, rel=1e-10)
        tensor = np.stack([column[name] for name in ("sxx", "syy", "szz", "sxy", "syz", "sxz")], axis=1)
        assert np.allclose(column["s1"], max_principal(tensor), rtol=1e-9)
        # The wave has arrived: the dynamic stress is not zero, and small next to the static one.
        assert 0.0 < np.max(np.abs(column["s1_dynamic"])) < 1e-2 * abs(vertical)
        checks += 1
    assert checks == len(scene["monitor"]) == 6


def test_case_study_report_reads_the_run(short_case3, tmp_path):
    import case_study

    _, out, _ = short_case3
    numbers = case_study.report(presets=("coarse",), runs_dir=out.parent, results=tmp_path, doc=False)
    case3 = numbers["coarse"][3]
    assert case3["cost"]["dofs"] > 100000
    assert set(case3["relative_history"]) == {"A", "B", "C"}
    assert 0.0 < case3["D_crown_range"][0] <= 1.0
    for name in ("fig4_input_record", "fig6_interlayer", "fig7_deterioration", "fig8_displacement",
                 "fig9_relative", "fig10_principal_stress"):
        assert (tmp_path / f"{name}.png").stat().st_size > 10000
    assert "| case 3 coarse |" in (tmp_path / "comparison.md").read_text()



def test_case_study_report_without_runs_refuses_and_erases_nothing(tmp_path, capsys):
    """A report asked for on a fresh clone (no finished runs) exits 2 and writes nothing: catches a
    report that empties docs/case_study.md's generated table and the committed results."""
    import case_study

    assert case_study.main(["--report-only", "--runs", str(tmp_path / "runs")]) == 2
    assert "no finished run" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()  # no results folder, no figures, no tables


@pytest.mark.slow
@pytest.mark.parametrize("case", ["case1_vertical_coarse", "case2_oblique_coarse", "case3_contact_coarse"])
def test_coarse_case_runs_to_its_end(case, tmp_path):
    """Each of the paper's three coarse cases runs its whole scene with all physics: the static
    stage, then 4.9 s of motion (the 1 s lead-in and the record's first 3.9 s; 20-40 min each on
    2 cores). The stage converged, the rock yielded, the wave reached the lining, the balance
    closed."""
    from pyfem import solver

    scene = load_scene(REPOSITORY / "workflows" / "scenes" / f"{case}.toml")
    summary = solver.run(scene, tmp_path / case)
    assert summary["status"] == "finished"
    assert summary["steps"] * summary["dt"] >= scene["time"]["duration"] - 1e-9
    assert all(stage["converged"] for stage in summary["static"]["stages"])
    assert sum(region["yielded_volume"] for name, region in summary["nonlinear_regions"].items()
               if name != "lining") > 0.0
    # global stepping's identity, or local stepping's plain account (O(dt^2), docs/method.md) when
    # "auto" turned it on: catches a contact, plastic or damage work term missing over the whole run.
    # The coarse case 3's account: 1.5e-4 of the work at 0.75 s (the lead-in), 3.9e-5 at 4.53 s.
    local = "local time stepping" in summary["dt_reason"]
    print(f"{case}: {summary['dt_reason']}; energy balance {summary['energy']['balance_error']:.2e}")
    assert summary["energy"]["balance_error"] < (LOCAL_STEPPING_BALANCE if local else ENERGY_BALANCE)
    peaks = [summary["monitors"][name]["displacement"] for name in ("A", "B", "C", "D")]
    assert all(math.isfinite(p) and p > 1e-3 for p in peaks), peaks  # centimetres of motion arrived

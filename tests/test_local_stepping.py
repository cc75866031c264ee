"""Local time stepping from a scene (`[time] local_stepping = true`, pyfem/local_stepping.py,
docs/local_stepping.md; the kernel's own checks are tests/cpp/test_local_stepper.cpp).

- A homogeneous box of tetrahedra refined around its centre (cells 1.5 m inside, 8 m outside)
  under an oblique SV wave: several rate levels, and the monitors follow the free field as closely
  as global stepping does (the truncation faces' nodes step at the finest rate).
- One rate level (a uniform mesh) is global stepping: the same histories.
- The set-up check of the LTS map (a power iteration of the undamped map from a random state)
  passes on the graded mesh's own levels and catches levels one rate too coarse.
- Contact pairs at their own rate: bonded pairs under local stepping are the unsplit mesh under
  the same levels to round-off; a weak interface slides as under global stepping (second order);
  pairs at a coarser level than the finest are global stepping at their own step.
- What the local stepper does not do yet is refused with one line naming time.local_stepping.
"""
import json
import pathlib

import numpy as np
import pytest

from conftest import ENERGY_BALANCE, LOCAL_STEPPING_BALANCE
from pyfem import distributed_lts, local_stepping, solver
from pyfem.distributed_model import model_in_memory
from pyfem.scene import SceneError, parse_scene

GRADED_GEO = """SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 200, 60, 200};
Physical Volume("rock") = {1};
Field[1] = Box;
Field[1].VIn = 1.5;
Field[1].VOut = 8;
Field[1].XMin = 80; Field[1].XMax = 120; Field[1].YMin = 20; Field[1].YMax = 40;
Field[1].ZMin = 80; Field[1].ZMax = 120; Field[1].Thickness = 15;
Background Field = 1;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
"""


def graded_scene(geo: pathlib.Path, local: bool, **extra):
    data = {
        "title": "graded tetrahedra, oblique SV",
        "mesh": {"builder": "file", "file": str(geo), "order": 1},
        "materials": {"rock": {"preset": "sandstone"}},
        "time": {"duration": 1.0, "safety": 0.8, "local_stepping": local},
        "wave": {"type": "SV", "angle": 30.0, "surface": 240.0, "medium": "rock",
                 "motion": {"ricker": {"f0": 5.0, "amplitude": 1.0e-3}}},
        "monitor": [{"name": "centre", "point": [100.0, 30.0, 100.0]}, {"name": "upper", "point": [60.0, 30.0, 160.0]},
                    {"name": "lower", "point": [140.0, 30.0, 40.0]}],
        "output": {"interval": 0.005, "xdmf_interval": 0.0},
    }
    data.update(extra)
    return parse_scene(data, source="test")


def run_to_the_end(model) -> np.ndarray:
    """u (m) after the model's steps from rest, by the stepper the model builds (`model_in_memory`'s
    `.stepper()`: global or local stepping as a run; the set-up check of the LTS map left out)."""
    stepper, _ = model.stepper(check_stability=False)
    n = 3 * model.part.n_local
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    stepper.run(u, v, a, model.n_steps, 0.0)
    return u


def levels_of(scene) -> np.ndarray:
    """The rate level of every node (one rank: the kernel's numbering is the function space's) that a
    run of `scene` with local stepping on steps at."""
    return model_in_memory(scene, solve_stage=False).lts.levels


def set_levels(model, levels: np.ndarray) -> None:
    """The model's local stepping at `levels` (by hand) from here on, its fine step kept."""
    model.lts = distributed_lts.RankLevels(np.ascontiguousarray(levels, dtype=np.int32), np.bincount(levels),
                                           model.lts.global_step, model.lts.time_step)


def test_graded_mesh_with_several_rates_follows_the_free_field_as_global_stepping(tmp_path, unfitted_levels):
    geo = tmp_path / "graded.geo"
    geo.write_text(GRADED_GEO)
    summaries = {local: solver.run(graded_scene(geo, local), tmp_path / f"run_{local}") for local in (False, True)}
    local = summaries[True]
    assert "local time stepping: 3 rate levels" in local["dt_reason"]
    assert local["dt_reason"].endswith("the row split")  # a linear model (pyfem/local_stepping.py row_split)
    levels = levels_of(graded_scene(geo, True))
    counts = np.bincount(levels)
    assert len(counts) == 3 and np.all(counts > 100)  # three rates, each with cells in it
    for name in ("centre", "upper", "lower"):
        glob, loc = (summaries[k]["monitors"][name]["freefield_error"] for k in (False, True))
        print(f"{name}: free-field error global {100 * glob:.3f} %, local stepping {100 * loc:.3f} %")
        assert summaries[True]["monitors"][name]["displacement"] > 1e-4  # the wave arrived
        assert loc < 0.0125                    # twice the largest measured (0.62 %, P1)
        assert loc < 1.5 * glob + 0.001        # and no worse than global stepping, to 0.1 %
    print(f"energy balance (local stepping's plain account) {local['energy']['balance_error']:.2e}")
    # measured 3.8e-5; the plain account's stated O(dt^2) bound: catches a level's work booked wrong
    assert local["energy"]["balance_error"] < LOCAL_STEPPING_BALANCE
    stability = local["local_stepping_stability"]  # the set-up check of the LTS map on this mesh
    assert stability["stable"] and stability["growth"] < 2.0 and stability["global_steps"] >= 200


def test_one_rate_level_is_global_stepping(tmp_path):
    box = {"builder": "box", "size": [60.0, 10.0, 60.0], "h": 5.0}
    runs = {}
    for local in (False, True):
        scene = graded_scene(pathlib.Path("unused.geo"), local, mesh=box,
                             monitor=[{"name": "centre", "point": [30.0, 5.0, 30.0]}])
        scene["wave"]["surface"] = 100.0
        scene["time"]["duration"] = 0.4
        model = model_in_memory(scene)
        if local:
            assert model.lts.levels.max() == 0  # a uniform mesh: one rate
        else:
            assert model.lts is None
        runs[local] = run_to_the_end(model)
    assert np.max(np.abs(runs[False])) > 1e-5
    assert np.linalg.norm(runs[True] - runs[False]) <= 1e-12 * np.linalg.norm(runs[False])


def test_check_predicts_what_local_stepping_would_save_where_the_scene_allows_it(tmp_path, unfitted_levels):
    """`check` with local stepping off (pyfem.local_stepping.predicted_speed_up): one rate level
    predicts exactly global stepping's speed; the preview's levels are those a run with it on uses;
    the graded mesh, whose finest level holds most nodes, is not worth it; the coarse case 1 (its rock
    zone's element loop at coarser rates than the lining's) is: the row split predicts 1.46x (its cells
    step at the finest rate of their nodes; the column split's, at the coarsest, measured 1.68x,
    docs/local_stepping.md "When it is on"); a scene it does not support (stiffness-proportional damping)
    gets no prediction."""
    box = {"builder": "box", "size": [60.0, 10.0, 60.0], "h": 5.0}
    uniform = solver.plan(graded_scene(pathlib.Path("unused.geo"), False, mesh=box,
                                       monitor=[{"name": "centre", "point": [30.0, 5.0, 30.0]}]))
    line = uniform["local stepping (off)"]
    print(line)
    assert "predicted 1.00x" in line and "nodes per level [" in line and "not worth it" in line

    geo = tmp_path / "graded.geo"
    geo.write_text(GRADED_GEO)
    off = model_in_memory(graded_scene(geo, False), solve_stage=False)
    assert off.lts is None  # off: the run steps globally
    on = model_in_memory(graded_scene(geo, True), solve_stage=False)
    _, preview_counts = distributed_lts.preview(off.part, off.loop, off.time_step)  # (nodes per level)
    assert len(preview_counts) == 3 and np.array_equal(preview_counts, on.lts.counts)
    graded = solver.plan(graded_scene(geo, False))["local stepping (off)"]
    print(graded)
    assert "3 rate levels" in graded and "not worth it" in graded

    from pyfem.scene import load_scene

    case1 = solver.plan(load_scene(pathlib.Path(__file__).resolve().parents[1] / "workflows" / "scenes"
                                   / "case1_vertical_coarse.toml", ["time.local_stepping=false"]))["local stepping (off)"]
    print(case1)
    speed_up = float(case1.split("predicted ")[1].split("x")[0])
    assert 1.3 < speed_up < 2.5 and "it would pay (time.local_stepping = true; the row split" in case1

    damped = graded_scene(geo, False, damping={"alpha": 0.0, "beta": 1.0e-4})
    assert "local stepping (off)" not in solver.plan(damped)


@pytest.mark.parametrize("change, named", [
    ({"damping": {"alpha": 0.0, "beta": 1.0e-4}}, "stiffness-proportional"),
    ({"time": {"duration": 1.0, "local_stepping": True, "matrix_precision": "single"}}, "matrix_precision"),
])
def test_what_local_stepping_does_not_do_yet_is_refused_by_key(change, named):
    box = {"builder": "box", "size": [40.0, 10.0, 40.0], "h": 10.0}
    scene = graded_scene(pathlib.Path("unused.geo"), True, mesh=box, monitor=[], **change)
    with pytest.raises(SceneError, match=r"time\.local_stepping") as error:
        model_in_memory(scene, solve_stage=False)
    assert named in str(error.value)


def test_stability_check_passes_the_levels_and_catches_levels_too_coarse(tmp_path):
    """The LTS map with the levels local_stepping gives keeps a random state's energy bounded; with
    every node one rate coarser (its step twice its cells' bound) the same check finds growth; and
    the map is stable up to the global scheme's critical step, not beyond it."""
    from pyfem import _kernels
    from pyfem.local_stepping import check_stability

    geo = tmp_path / "graded.geo"
    geo.write_text(GRADED_GEO)
    model = model_in_memory(graded_scene(geo, True), solve_stage=False)
    part, node_levels = model.part, model.lts.levels
    indptr, indices, blocks = part.matrix

    def kernel(levels, dt=model.time_step.dt):
        def make():
            stepper = _kernels.LocalStepper(indptr, indices, blocks, part.mass,
                                            np.ascontiguousarray(levels, dtype=np.int32), dt, 0.0)
            stepper.set_dashpots(np.ascontiguousarray(part.dashpot_nodes, dtype=np.int32),
                                 np.ascontiguousarray(part.dashpot_matrices, dtype=np.float64))
            return stepper
        return make

    n = part.n_local * 3
    good = check_stability(kernel(node_levels), n)
    coarse = check_stability(kernel(node_levels + 1), n)
    print(f"levels as set: growth {good['growth']:.3g}; one level coarser: {coarse['growth']:.3g} "
          f"(amplitude x{coarse['growth_per_step']:.4f} per global step)")
    assert good["stable"] and good["growth"] < 2.0
    assert not coarse["stable"] and coarse["growth"] > 1e3
    # Stable with the whole model's safety factor: the finest step up to the global scheme's critical
    # step (power iteration of the whole model, as the run reports it) keeps the map stable. The map's
    # own limit lies between 1.022 and 1.025 of it (240 global steps: energy 0.64 of its start at 1.0,
    # 1.02 and 1.022, as at 0.99; at 1.025 it grew 7.2e3-fold, 2.8 % of amplitude per global step; at
    # 1.02 over 1 200 steps it fell to 0.46). Bracketed at 1.02 / 1.025 (0.97 / 1.07 before): catches a
    # map whose limit moved by half a percent, e.g. below the critical step a safety factor relies on.
    critical = model.time_step.critical
    at_critical = check_stability(kernel(node_levels, critical), n)
    near = check_stability(kernel(node_levels, 1.02 * critical), n)
    above = check_stability(kernel(node_levels, 1.025 * critical), n)
    print(f"finest step 1.0 x critical: growth {at_critical['growth']:.3g}; 1.02 x: {near['growth']:.3g}; "
          f"1.025 x: {above['growth']:.3g}")
    assert at_critical["stable"] and near["stable"] and not above["stable"]
    assert near["growth"] < 1.0 and above["growth"] > 1e2


def test_kernel_local_stepper_takes_yielding_cells_at_their_level():
    """The kernel's LocalStepper with a Mohr-Coulomb region's cells in the element loop
    (`add_internal_force(component, level)`; docs/local_stepping.md "The scheme: the row split"):
    with one level it is the global Stepper with the same component, and the rock yielded."""
    from pyfem import _kernels, bench
    from pyfem.elements import nonlinear_component
    from pyfem.effects import bsr_arrays

    model = model_in_memory(bench._box_scene(3000), solve_stage=False)
    mass = model.part.mass
    assert model.part.kernel_of_dolfinx is None  # one rank: the kernel's numbering is the function space's
    law = {"law": "mohr_coulomb", "young_modulus": 8.0e9, "poisson_ratio": 0.24, "cohesion": 1.0e4,
           "friction_angle": 30.0, "tensile_strength": 5.0e3}
    regions = nonlinear_component(model.part.model, ["rock"], {"rock": law}, mean_dilatation=True)
    indptr, indices, blocks = bsr_arrays(regions.stiffness)
    dt, n = model.time_step.dt, 3 * model.part.n_local
    v0 = 0.5 * np.sin(np.arange(n) * 0.37)  # from u = 0, where a = 0 is both steppers' start
    runs = []
    for local in (False, True):
        component = regions.new_component("rock")
        if local:
            stepper = _kernels.LocalStepper(indptr, indices, blocks, mass,
                                            np.zeros(n // 3, dtype=np.int32), dt, 0.0)
            stepper.add_internal_force(component, 0)
        else:
            stepper = _kernels.Stepper(indptr, indices, blocks, mass, dt, 0.0, 0.0)
            stepper.add_internal_force(component)
        u, v, a = np.zeros(n), v0.copy(), np.zeros(n)
        stepper.run(u, v, a, 60, 0.0)
        runs.append((u, component.dissipation()))
    (u_global, dissipated_global), (u_local, dissipated_local) = runs
    kinetic = 0.5 * np.sum(np.repeat(mass, 3) * v0 ** 2)
    assert dissipated_global > 0.1 * kinetic  # the rock yielded: a fair share of the energy dissipated
    assert np.abs(u_local - u_global).max() <= 1e-11 * np.abs(u_global).max()
    assert dissipated_local == pytest.approx(dissipated_global, rel=1e-9)


def two_layer_plastic_scene(local: bool):
    """Hexahedra in two layers: stiff elastic sandstone below, soft Mohr-Coulomb mudstone above (a
    coarser rate level: a slower wave in cells of the same size) that a vertical SV pulse yields."""
    return parse_scene({
        "title": "two layers, the soft one yielding, vertical SV",
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [50.0, 40.0, 60.0], "h": 5.0, "order": 1,
                 "layers": [{"material": "stiff", "thickness": 30.0}, {"material": "soft", "thickness": 30.0}]},
        "materials": {"stiff": {"E": 32.0e9, "nu": 0.25, "rho": 2600.0},
                      "soft": {"E": 2.0e9, "nu": 0.25, "rho": 2600.0,
                               "plasticity": {"cohesion": 4.0e5, "friction_angle": 30.0, "tensile_strength": 2.0e5, "damage_max": 0.9, "damage_plastic_strain": 0.005}}},
        "time": {"duration": 0.4, "safety": 0.8, "local_stepping": local},
        "wave": {"type": "SV", "angle": 0.0, "surface": 100.0, "medium": "stiff",
                 "motion": {"ricker": {"f0": 10.0, "amplitude": 1.0e-3}}},
        "monitor": [{"name": "soft", "point": [25.0, 20.0, 45.0]}, {"name": "stiff", "point": [25.0, 20.0, 15.0]}],
        "output": {"interval": 0.004, "xdmf_interval": 0.0},
    }, source="test")


def test_yielding_layer_at_its_own_rate_follows_global_stepping(tmp_path, unfitted_levels):
    """The scene path of nonlinear local stepping (pyfem/local_stepping.py level_components): the
    yielding soft layer's cells at their coarser level, read back as one region for the monitors and
    run.json, against global stepping of the same scene."""
    from pyfem.local_stepping import cell_levels

    prepared = model_in_memory(two_layer_plastic_scene(True), solve_stage=False)
    cells = cell_levels(prepared.lts.levels, prepared.loop.counted.arrays["soft"].cell_nodes)
    print("nodes per level:", np.bincount(prepared.lts.levels), "soft cells per level:", np.bincount(cells))
    assert np.count_nonzero(cells > 0) >= 20  # soft cells at a coarser rate than the finest
    runs = {local: solver.run(two_layer_plastic_scene(local), tmp_path / f"run_{local}") for local in (False, True)}
    glob, loc = runs[False], runs[True]
    soft_global = glob["nonlinear_regions"]["soft"]
    soft_local = loc["nonlinear_regions"]["soft"]
    print("yielded volume global / local:", soft_global["yielded_volume"], soft_local["yielded_volume"],
          "dissipated:", soft_global["dissipated_energy"], soft_local["dissipated_energy"],
          "monitors:", {name: (glob["monitors"][name]["displacement"], loc["monitors"][name]["displacement"])
                        for name in ("soft", "stiff")})
    assert soft_global["yielded_volume"] > 0.1 * soft_global["volume"]  # the layer yielded
    assert soft_local["dissipated_energy"] == pytest.approx(soft_global["dissipated_energy"], rel=0.05)
    for name in ("soft", "stiff"):
        assert loc["monitors"][name]["displacement"] == pytest.approx(glob["monitors"][name]["displacement"], rel=0.02)


def two_layer_contact_scene(local: bool, contact: bool, cohesion: float = 1.0e15, friction_angle: float = 30.0,
                            soft_plasticity: dict | None = None, normal_lag: dict | None = None):
    """Two layers (stiff below, soft above: a coarser rate level) split at their interface into
    contact pairs, a vertical SV pulse; `cohesion` 1e15 keeps every pair bonded; `normal_lag` the
    [contact.normal_lag] table."""
    data = {
        "title": "two layers, interface contact, vertical SV, local stepping",
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [50.0, 40.0, 60.0], "h": 5.0, "order": 1,
                 "layers": [{"material": "stiff", "thickness": 30.0}, {"material": "soft", "thickness": 30.0}]},
        "materials": {"stiff": {"E": 32.0e9, "nu": 0.25, "rho": 2600.0}, "soft": {"E": 2.0e9, "nu": 0.25, "rho": 2600.0}},
        "time": {"duration": 0.3, "dt": 2.0e-4, "local_stepping": local},
        "wave": {"type": "SV", "angle": 0.0, "surface": 100.0, "medium": "stiff",
                 "motion": {"ricker": {"f0": 10.0, "amplitude": 1.0e-3}}},
        "monitor": [{"name": "soft", "point": [25.0, 20.0, 45.0]}, {"name": "stiff", "point": [25.0, 20.0, 15.0]}],
        "output": {"interval": 0.004, "xdmf_interval": 0.0},
    }
    if soft_plasticity is not None:
        data["materials"]["soft"]["plasticity"] = soft_plasticity
    if contact:
        data["initial_stress"] = {"surface": 100.0, "rho": 2600.0, "k": [1.0, 1.0, 1.0]}
        data["contact"] = {"interfaces": ["interface_1"], "cohesion": cohesion, "friction_angle": friction_angle,
                           "dynamic_friction_angle": friction_angle, "tensile_strength": cohesion}
        data["pair_monitor"] = [{"name": "middle", "point": [25.0, 20.0, 30.0]}]
        if normal_lag is not None:
            data["contact"]["normal_lag"] = normal_lag
    return parse_scene(data, source="test")


def split_and_unsplit_under_the_same_levels(split, whole):
    """Runs the split mesh (contact pairs) and the unsplit mesh (models in memory, one rank) to the
    end under the split mesh's levels (a pair's two copies share one level) by the row split: the
    same arithmetic while every pair stays bonded. Returns (split u, unsplit u, each split node's
    unsplit node), u as (nodes, 3), in the kernel's numbering of each."""
    from scipy.spatial import cKDTree

    distance, unsplit_node = cKDTree(whole.part.coords).query(split.part.coords)
    assert np.max(distance) < 1e-9
    mapped = np.zeros(whole.part.n_local, dtype=np.int32)
    mapped[unsplit_node] = split.lts.levels  # both copies of a pair node have one level
    set_levels(whole, mapped)
    assert split.time_step.dt == whole.time_step.dt
    histories = []
    for model in (split, whole):
        stepper, _ = model.stepper(check_stability=False)
        assert stepper.kernel.row_split  # (the one model's split)
        n = 3 * model.part.n_local
        u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        stepper.run(u, v, a, model.n_steps, 0.0)
        histories.append(u.reshape(-1, 3))
    return histories[0], histories[1], unsplit_node


def test_bonded_pairs_in_the_row_split_reproduce_the_unsplit_mesh():
    """The row split with contact pairs (the default, pyfem/local_stepping.py row_split): the two
    nodes of a pair at the finer of their levels and nothing else lowered (equalize_pair_levels), each
    pair at its nodes' own level (level_pairs); with every pair bonded the split mesh is the unsplit
    mesh under the same levels, both by the row split."""
    split = model_in_memory(two_layer_contact_scene(True, True))
    whole = model_in_memory(two_layer_contact_scene(True, False))
    assert split.time_step.reason.endswith("the row split") and whole.time_step.reason.endswith("the row split")
    levels, pairs = split.lts.levels, split.contact_arrays["pairs"]
    assert levels.max() >= 1 and np.all(levels[pairs[:, 0]] == levels[pairs[:, 1]])
    split_u, whole_u, unsplit_node = split_and_unsplit_under_the_same_levels(split, whole)
    assert np.abs(whole_u).max() > 1e-4  # the wave passed the interface
    assert split.contact.state_counts()[0] == len(pairs)  # all bonded
    assert np.abs(np.asarray(split.contact.contact_force())).max() > 0.0  # the correction acted
    assert np.abs(split_u - whole_u[unsplit_node]).max() <= 1e-10 * np.abs(whole_u).max()


def test_a_sliding_interface_under_local_stepping_follows_global_stepping(tmp_path):
    """Contact pairs at their own rate (LocalStepper.add_contact: an impulse before each drift of
    the pair's drift level; bonded pairs against the unsplit mesh: the row-split test above): a weak
    interface that slides follows global stepping at second order in dt; the scene path end to end,
    its energy account included (docs/local_stepping.md "Contact pairs", "The contact
    work under local stepping"). (Its first half, the column split's bonded pairs, went with the
    serial stepper builder, the column split's only user: the one model steps the row split.)"""
    # A weak interface (no cohesion, 5 deg) slides: against global stepping at two steps, the
    # difference falls at second order (the row split: 0.179 % / 0.045 %, order 2.00; the column
    # split with the pair rows at their drift level too; with a coarse neighbour's force as kicks it
    # was first order: 3.1 % and 1.8 %).
    differences = []
    for dt in (2.0e-4, 1.0e-4):
        finals = []
        for local in (False, True):
            scene = two_layer_contact_scene(local, True, cohesion=0.0, friction_angle=5.0)
            scene["time"]["dt"] = dt
            model = model_in_memory(scene)
            finals.append((run_to_the_end(model), model.contact.state_counts()))
        (u_global, counts_global), (u_local, counts_local) = finals
        assert counts_local[2] > 0 and counts_global[2] > 0  # pairs sliding at the end in both
        differences.append(np.abs(u_local - u_global).max() / np.abs(u_global).max())
    order = np.log2(differences[0] / differences[1])
    print("sliding interface, local against global stepping:", differences, "order", order)
    assert differences[0] < 0.01 and order > 1.7

    # The scene path: pair histories, state counts, the energy account with contact work and
    # friction, against global stepping.
    runs = {}
    for local in (True, False):
        out = tmp_path / f"sliding_{local}"
        solver.run(two_layer_contact_scene(local, True, cohesion=0.0, friction_angle=5.0), out)
        on_disk = json.loads((out / "run.json").read_text())
        energy = np.genfromtxt(out / "energy.csv", delimiter=",", names=True)
        runs[local] = (on_disk, energy, np.loadtxt(out / "pairs" / "middle.csv", delimiter=",", skiprows=1))
    (on_disk, energy, pair_rows), (on_disk_global, energy_global, pair_rows_global) = runs[True], runs[False]
    sliding = np.asarray(on_disk["pair_states"]["sliding"])
    print("sliding pairs (local / global, max over samples):", sliding.max(),
          np.asarray(on_disk_global["pair_states"]["sliding"]).max(), "friction dissipated:",
          energy["friction_dissipation"][-1], energy_global["friction_dissipation"][-1],
          "slip at the middle pair:", pair_rows[-1, 4], pair_rows_global[-1, 4])
    assert sliding.max() > 0 and energy["friction_dissipation"][-1] > 0.0  # the interface slipped
    work = max(np.abs(energy["external_work"]).max(), (energy["kinetic"] + energy["strain"]).max())
    print("balance / work:", np.abs(energy["balance"]).max() / work, "global:",
          np.abs(energy_global["balance"]).max() / work)
    # The plain account of local stepping, O(dt^2): 1.2e-4 of the work with the impulses' work
    # over their drifts (as kinetic energy added, the pairs' holding force drifted it by h^2 f^2 / m
    # per substep: docs/local_stepping.md "The energy account").
    # about twice the measured 1.29e-4 (global stepping 3.6e-15): catches the contact work booked wrong
    assert np.abs(energy["balance"]).max() < 2.6e-4 * work
    # the global run's account is an identity: catches the contact work 1 % off (1.7e-4 of the work)
    assert np.abs(energy_global["balance"]).max() < ENERGY_BALANCE * work
    assert pair_rows[-1, 4] == pytest.approx(pair_rows_global[-1, 4], rel=0.01)
    assert energy["friction_dissipation"][-1] == pytest.approx(energy_global["friction_dissipation"][-1], rel=0.02)


def lagged_sliding(local: bool, dt: float, normal_lag: dict | None, deterioration: dict | None = None,
                   one_level: bool = False) -> np.ndarray:
    """u at the end of the weak interface's run (no cohesion, 5 deg; sliding at the end) with
    `normal_lag` and `deterioration` ([contact] tables), at `dt`; `one_level`: every node at level 0."""
    scene = two_layer_contact_scene(local, True, cohesion=0.0, friction_angle=5.0, normal_lag=normal_lag)
    scene["time"]["dt"] = dt
    if deterioration is not None:
        scene["contact"]["deterioration"] = deterioration
    model = model_in_memory(scene)
    if one_level:
        set_levels(model, np.zeros_like(model.lts.levels))
    elif local:
        assert model.lts.levels.max() >= 1  # several rates
    u = run_to_the_end(model)
    assert model.contact.state_counts()[2] > 0  # pairs sliding at the end
    return u


LAG = {"length": 0.005, "velocity": 0.1}  # the slip rate dominates the decay rate (|V| + V*) / L


def test_rate_dependent_pairs_on_one_level_are_global_stepping():
    """The slip rate a pair keeps for its next correction (the deterioration's gamma(|V|), the
    normal lag's decay (|V| + V*) / L) is read where Stepper reads it: v(t) plus half the impulse,
    at the start of the level's substep, not the drift's velocity half a step later. So one rate
    level with both on is global stepping to round-off (the drift's velocity gave a difference of
    first order in dt)."""
    deterioration = {"R0": 0.5, "lambda": 2.0, "m": 0.5, "n": 0.02, "p": 0.3}  # gamma varies with |V|
    global_u = lagged_sliding(False, 2.0e-4, LAG, deterioration)
    local_u = lagged_sliding(True, 2.0e-4, LAG, deterioration, one_level=True)
    lag_free = lagged_sliding(False, 2.0e-4, None)
    print("one level against global stepping:", np.abs(local_u - global_u).max() / np.abs(global_u).max(),
          "the lag and deterioration's effect:", np.abs(lag_free - global_u).max() / np.abs(global_u).max())
    assert np.abs(lag_free - global_u).max() > 0.01 * np.abs(global_u).max()  # they acted
    assert np.abs(local_u - global_u).max() <= 1e-12 * np.abs(global_u).max()


def test_the_normal_lag_under_local_stepping_follows_global_stepping_at_second_order():
    """[contact.normal_lag] with the pairs at their own rate (here the finest of three levels; their
    ContactPairs carries the lag and integrates N* over its substeps, the soft layer's nodes step at
    coarser rates around them). Local against global stepping, both with the lag,
    falls at second order in dt as without it (the test above); and the lag acted (the motion
    differs from the lag-free run's by far more). Global stepping of a sliding pair is itself first
    order in dt (its dt -> dt/2 differences fall at order 1.0 with and without the lag: the
    stick-slip switches), so local stepping adds less than the scheme's own error."""
    differences = []
    for dt in (2.0e-4, 1.0e-4):
        global_u = lagged_sliding(False, dt, LAG)
        differences.append(np.abs(lagged_sliding(True, dt, LAG) - global_u).max() / np.abs(global_u).max())
    effect = np.abs(lagged_sliding(False, 1.0e-4, None) - global_u).max() / np.abs(global_u).max()
    order = np.log2(differences[0] / differences[1])
    print("lagged sliding, local against global stepping:", differences, "order", order, "the lag's effect", effect)
    assert effect > 20 * differences[1]  # the lag changed the motion by far more than local stepping
    assert differences[0] < 0.01 and order > 1.7


def three_layer_pairs_scene(local: bool, dt: float, cohesion: float, normal_lag: dict | None = None):
    """The two-layer scene with the soft layer cut in two at z = 45 m and the contact pairs on that
    cut (interface_2, soft against soft): an interface inside the coarse region."""
    scene = two_layer_contact_scene(local, True, cohesion=cohesion, friction_angle=5.0, normal_lag=normal_lag)
    scene["mesh"]["layers"] = [{"material": "stiff", "thickness": 30.0}, {"material": "soft", "thickness": 15.0},
                               {"material": "soft", "thickness": 15.0}]
    scene["contact"]["interfaces"] = ["interface_2"]
    scene["pair_monitor"] = [{"name": "middle", "point": [25.0, 20.0, 45.0]}]
    scene["time"]["dt"] = dt
    return scene


def pairs_at_a_coarse_level(model) -> np.ndarray:
    """Two rate levels by hand: level 1 (2 dt) above z = 22.5 m, truncation faces included, level 0
    below, made consistent for the pairs (the row split: local_stepping.equalize_pair_levels). The
    row split's automatic levels put these pairs at a coarser level only where the pair's own cells
    allow it; the levels by hand are the case of an interface inside coarse rock."""
    levels = np.where(model.part.coords[:, 2] >= 22.5, 1, 0).astype(np.int32)
    return local_stepping.equalize_pair_levels(levels, model.contact_arrays["pairs"])


@pytest.mark.parametrize("normal_lag", [None, LAG], ids=["instant", "lagged"])
def test_pairs_at_a_coarser_level_than_the_finest_are_global_stepping_at_their_own_step(normal_lag):
    """Contact pairs at level 1 of two (their ContactPairs corrects at 2 dt, the stiff layer below
    steps at dt). Bonded, the split mesh is the unsplit mesh under the same levels to round-off. A weak
    interface (no cohesion, 5 deg) that slips is as accurate as global stepping at the pairs' own step:
    against a converged reference (global stepping at dt / 8) local stepping's error at dt is global
    stepping's at 2 dt within 2 %, and halves with dt as that does (stick-slip makes a sliding pair
    first order in dt under global stepping too). So local stepping against global stepping at the
    same dt falls at first order here, not second: the pairs' own step, not the level split."""
    def prepared(local, dt, cohesion=0.0):
        model = model_in_memory(three_layer_pairs_scene(local, dt, cohesion, normal_lag))
        if local:
            levels = pairs_at_a_coarse_level(model)
            pair_levels = np.unique(levels[model.contact_arrays["pairs"]])
            assert list(pair_levels) == [1] and np.count_nonzero(levels == 0) > 100  # coarser than the finest
            set_levels(model, levels)
        return model

    def final(local, dt):
        return run_to_the_end(prepared(local, dt))

    # Bonded: the split mesh against the unsplit mesh under the same levels.
    split = prepared(True, 2.0e-4, cohesion=1.0e15)
    whole_scene = three_layer_pairs_scene(True, 2.0e-4, 1.0e15, normal_lag).to_json()
    del whole_scene["contact"], whole_scene["pair_monitor"]
    whole = model_in_memory(parse_scene(whole_scene, source="test"))
    split_u, whole_u, unsplit_node = split_and_unsplit_under_the_same_levels(split, whole)
    assert split.contact.state_counts()[0] == len(split.contact_arrays["pairs"])  # all bonded
    assert np.abs(whole_u).max() > 1e-4  # the wave passed the interface
    assert np.abs(split_u - whole_u[unsplit_node]).max() <= 1e-10 * np.abs(whole_u).max()
    bonded = split_u.reshape(-1)

    # Sliding: errors against the converged reference.
    reference = final(False, 2.5e-5)
    scale = np.abs(reference).max()
    print("the weak interface against the bonded one:", np.abs(reference - bonded).max() / scale)
    assert np.abs(reference - bonded).max() > 0.3 * scale  # the weak interface slipped (60-65 % of the motion)
    error = {}
    for dt in (4.0e-4, 2.0e-4, 1.0e-4):
        error["global", dt] = np.abs(final(False, dt) - reference).max() / scale
        if dt < 4.0e-4:
            error["local", dt] = np.abs(final(True, dt) - reference).max() / scale
    print("errors against global stepping at dt / 8:", error)
    for dt in (2.0e-4, 1.0e-4):
        assert error["local", dt] == pytest.approx(error["global", 2 * dt], rel=0.02)
    assert np.log2(error["local", 2.0e-4] / error["local", 1.0e-4]) > 0.9  # converges, at first order


def test_a_local_stepping_run_stopped_and_resumed_is_the_uninterrupted_run(tmp_path, monkeypatch):
    """Checkpoint and resume under local time stepping (LocalStepper.save_state, docs/checkpoint.md):
    a crash three samples after a periodic checkpoint, then --resume, gives the uninterrupted run's
    histories, fields and run.json peaks bit for bit, on a scene with several rate levels whose
    state matters across the checkpoint: a weak deteriorating interface sliding and a yielding soft
    layer (both before and after it)."""
    from pyfem.scene import parse_scene
    from test_checkpoint import assert_same_run, crash_after_a_periodic_checkpoint

    MPa = 1.0e6
    data = two_layer_contact_scene(True, True, cohesion=0.0, friction_angle=5.0,
                                   soft_plasticity={"cohesion": 0.05 * MPa, "friction_angle": 25.0,
                                                    "tensile_strength": 0.02 * MPa, "damage_max": 0.9, "damage_plastic_strain": 0.005}).to_json()
    data["contact"]["deterioration"] = {"R0": 0.75, "lambda": 5.0}
    data["output"]["checkpoint_interval"] = 1.0e-9
    scene = parse_scene(data, source="test")
    reference = tmp_path / "reference"
    summary = solver.run(scene, reference)
    assert "local_stepping_stability" in summary
    levels = levels_of(scene)
    assert levels.max() >= 1 and np.count_nonzero(levels > 0) > 100  # several rates

    checkpoint_t = 0.20  # the soft layer is yielding (0.18-0.22 s), the interface slides (0.14 s on)
    energy = np.genfromtxt(reference / "energy.csv", delimiter=",", names=True)
    at = int(np.argmin(np.abs(energy["t"] - checkpoint_t)))
    for name in ("internal_dissipation", "friction_dissipation"):
        assert 0.0 < energy[name][at] < 0.9 * energy[name][-1], f"{name} grows before and after the checkpoint"
    sliding = np.asarray(summary["pair_states"]["sliding"])
    assert sliding[:at + 1].max() > 0 and sliding[at + 1:].max() > 0

    out = tmp_path / "crashed"
    saved = crash_after_a_periodic_checkpoint(monkeypatch, scene, out, 10, checkpoint_t + 0.012)
    assert saved.t == pytest.approx(checkpoint_t)
    assert (out / "energy.csv").read_text().count("\n") == 1 + saved.outputs_done + 1 + 3, "rows past the checkpoint"
    from pyfem import local_stepping

    def not_again(*args, **kwargs):
        raise AssertionError("the LTS map's stability check ran again on resume")

    monkeypatch.setattr(local_stepping, "check_stability", not_again)
    resumed = solver.run(scene, out, resume=True)
    assert resumed["resumed"][0]["t"] == pytest.approx(checkpoint_t)
    assert_same_run(out, reference)
    assert resumed["local_stepping_stability"]["stable"]  # the first sitting's report, kept


def test_contact_pairs_on_roller_faces_are_refused_by_key():
    """Local stepping holds fixed and roller nodes, but does not correct a pair node that is held: a
    scene with both is refused before anything is solved, with one line naming time.local_stepping
    and a node that is both."""
    from pyfem.scene import parse_scene

    data = two_layer_contact_scene(True, True).to_json()
    data["boundary"] = {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}}
    with pytest.raises(SceneError, match=r"time\.local_stepping") as error:
        model_in_memory(parse_scene(data, source="test"), solve_stage=False)
    assert "contact pairs on fixed or roller faces" in str(error.value) and "node" in str(error.value)
    data["time"]["local_stepping"] = False  # without local stepping the same scene is a model
    assert model_in_memory(parse_scene(data, source="test"), solve_stage=False).part.constraints is not None


def test_interface_rows_are_the_fine_side_of_each_level_boundary():
    """A chain of 2-node cells with levels 0 0 0 1 1 2 2: the rows stepped at their own rate are the
    last level-0 node before level 1 and the last level-1 node before level 2 (each shares a cell with
    a coarser node and drifts at its own level); the coarse side (nodes 3 and 5, which drift finer
    than they step) is not."""
    from pyfem.local_stepping import drift_levels, interface_rows

    levels = np.array([0, 0, 0, 1, 1, 2, 2], dtype=np.int32)
    cells = np.array([[k, k + 1] for k in range(6)])
    assert list(drift_levels(levels, cells)) == [0, 0, 0, 0, 1, 1, 2]
    assert list(interface_rows(levels, cells)) == [2, 4]


def test_local_stepping_after_a_static_stage_resumes_without_solving_it_again(tmp_path, monkeypatch):
    """The paper-scale case study's path: a relaxation stage, then local time stepping. A crash
    after a periodic checkpoint, then --resume: the stage comes from static/hand_over.npz (its
    solver is never called), the components and pairs are rebuilt at their rate levels and take the
    checkpoint's state, and the histories are the uninterrupted run's bit for bit."""
    from pyfem.scene import parse_scene
    from test_checkpoint import assert_same_run, crash_after_a_periodic_checkpoint, never_solve_the_stage

    MPa = 1.0e6
    data = two_layer_contact_scene(True, True, cohesion=0.0, friction_angle=5.0,
                                   soft_plasticity={"cohesion": 0.05 * MPa, "friction_angle": 25.0,
                                                    "tensile_strength": 0.02 * MPa, "damage_max": 0.9, "damage_plastic_strain": 0.005}).to_json()
    data["static"] = {"solver": "relaxation"}
    data["time"]["duration"] = 0.24
    data["output"]["checkpoint_interval"] = 1.0e-9
    scene = parse_scene(data, source="test")
    reference = tmp_path / "reference"
    summary = solver.run(scene, reference)
    assert summary["static"]["stages"][-1]["converged"]
    assert np.count_nonzero(levels_of(scene) > 0) > 100  # several rates
    checkpoint_t = 0.16
    energy = np.genfromtxt(reference / "energy.csv", delimiter=",", names=True)
    at = int(np.argmin(np.abs(energy["t"] - checkpoint_t)))
    # The interface slides before the checkpoint and after it; the soft layer yields after it (0.18 s).
    assert energy["friction_dissipation"][-1] > energy["friction_dissipation"][at] > 0.0
    assert energy["internal_dissipation"][-1] > energy["internal_dissipation"][at]
    out = tmp_path / "crashed"
    saved = crash_after_a_periodic_checkpoint(monkeypatch, scene, out, 10, checkpoint_t + 0.012)
    assert saved.t == pytest.approx(checkpoint_t)

    never_solve_the_stage(monkeypatch)
    solver.run(scene, out, resume=True)
    assert_same_run(out, reference)


def test_levels_fit_the_output_interval_where_a_deep_hierarchy_costs_more_than_it_saves():
    """local_stepping.fit_levels_to_output: the run takes whole global steps per output interval, so
    with 85 steps per interval six levels (global step 32 dt_fine) need 96 fine steps where four
    (8 dt_fine) need 88. The coarse case 3's levels are capped at 3, 7.7 % less work by the node
    count; an interval of 96 steps keeps all six, and capping never makes a node coarser."""
    from pyfem.local_stepping import fit_levels_to_output, local_time_step
    from pyfem.clock import TimeStep

    levels = np.repeat(np.arange(6), [19756, 8710, 8880, 17869, 3039, 98]).astype(np.int32)
    capped = fit_levels_to_output(levels, 85)
    assert capped.max() == 3 and np.array_equal(capped, np.minimum(levels, 3))

    def work(lv):
        """Node-steps per output interval: the fine steps the run takes (the product's
        local_time_step) times each node's row once per step of its level."""
        fitted, _ = local_time_step(TimeStep(dt=1.0e-4, critical=1.25e-4, omega_max=1.0, reason="",
                                             steps_per_output=85), lv)
        return fitted.steps_per_output * np.sum(2.0 ** -lv)

    caps = {cap: work(np.minimum(levels, cap)) for cap in range(6)}
    # the product's cap is the cheapest of every cap the run could take: catches a wrong choice
    assert min(caps, key=caps.get) == 3
    # 88 fine steps instead of 96: catches local_time_step no longer fitting whole global steps
    step = TimeStep(dt=1.0e-4, critical=1.25e-4, omega_max=1.0, reason="", steps_per_output=85)
    fitted, _ = local_time_step(step, capped)
    assert fitted.steps_per_output == 88
    # 7.7 % less work (docs/local_stepping.md)
    assert caps[3] == pytest.approx(0.923 * caps[5], abs=0.002 * caps[5])
    assert np.array_equal(fit_levels_to_output(levels, 96), levels)
    assert np.all(fit_levels_to_output(levels, 85) <= levels)


def test_auto_turns_local_stepping_on_where_it_pays_over_the_whole_run():
    """`time.local_stepping = "auto"`, the default (local_stepping.auto_decision): the coarse case 1,
    whose rock steps at coarser rates than its lining, turns it on for its 4.9 s (the row split, the
    levels fitted to the output interval); the same model for 0.05 s does not, since the set-up check
    of the map would cost more than the run saves; a uniform mesh has one rate and nothing to gain; a
    scene local stepping does not support (stiffness-proportional damping) steps globally instead of
    being refused; `false` decides nothing."""
    from pyfem.scene import load_scene

    path = pathlib.Path(__file__).resolve().parents[1] / "workflows" / "scenes" / "case1_vertical_coarse.toml"
    whole = model_in_memory(load_scene(path), solve_stage=False)
    print(whole.lts_decision)
    assert whole.lts_decision.startswith('"auto": on: predicted ')
    assert whole.lts is not None and whole.lts.levels.max() >= 2
    assert whole.time_step.reason.endswith("the row split")
    assert whole.time_step.dt < whole.lts.global_step.dt  # the fitted fine step, below the scene's
    speed_up = float(whole.lts_decision.split("predicted ")[1].split("x")[0])
    assert local_stepping.AUTO_PAYS <= speed_up < 2.5

    # the same model and levels for 0.05 s (distributed_lts.choose's decision)
    on, short = local_stepping.decision_of(distributed_lts.work_sums_on_ranks(whole.part, whole.loop, whole.lts.levels),
                                           whole.lts.counts, whole.lts.global_step, 0.05)
    print(short)
    assert not on and short.startswith('"auto": off: predicted ')
    per_step = float(short.split("(")[1].split("x per step")[0])
    assert per_step == pytest.approx(float(whole.lts_decision.split("(")[1].split("x per step")[0]))
    assert float(short.split("predicted ")[1].split("x")[0]) < local_stepping.AUTO_PAYS <= per_step

    box = {"builder": "box", "size": [60.0, 10.0, 60.0], "h": 5.0}
    uniform = model_in_memory(graded_scene(pathlib.Path("unused.geo"), "auto", mesh=box,
                                           monitor=[{"name": "centre", "point": [30.0, 5.0, 30.0]}]), solve_stage=False)
    assert uniform.lts is None and "one rate level" in uniform.lts_decision

    data = two_layer_contact_scene("auto", False).to_json()  # two rate levels
    data["damping"] = {"alpha": 0.0, "beta": 1.0e-4}
    damped = model_in_memory(parse_scene(data, source="test"), solve_stage=False)
    print(damped.lts_decision)
    assert damped.lts is None
    assert damped.lts_decision.startswith('"auto": off: not available for scenes with stiffness-proportional')
    data["time"]["local_stepping"] = False
    off = model_in_memory(parse_scene(data, source="test"), solve_stage=False)
    assert off.lts is None and off.lts_decision is None


def test_auto_steps_globally_when_the_check_finds_the_map_unstable_also_after_a_resume(tmp_path, monkeypatch):
    """A model "auto" turns local stepping on for, whose set-up check reports an unstable map (forced
    here: the map has been stable on every model so far), runs as with local stepping off, bit for
    bit, with run.json and a warning saying why: when the check runs in the plan `run` prints
    first (simulation_plan) too. `check` leaves the check to the run. A crash and --resume steps
    globally again without checking again and without solving the static stage again."""
    from test_checkpoint import (assert_same_run, crash_after_a_periodic_checkpoint, history_files,
                                 never_solve_the_stage, stateful_scene)

    def scene_with(local):
        scene = stateful_scene(duration=0.3)
        scene["time"]["local_stepping"] = local
        return scene

    reference = solver.run(scene_with(False), tmp_path / "global")
    monkeypatch.setattr(local_stepping, "decision_of", lambda *args, **kwargs: (True, '"auto": on: forced by the test'))
    unstable = {"global_steps": 240, "growth": 3.5, "growth_per_step": 1.0026, "stable": False, "seconds": 0.1}
    checks = []
    monkeypatch.setattr(local_stepping, "check_stability", lambda *args, **kwargs: checks.append(1) or unstable)
    plan = solver.plan(scene_with("auto"))
    print(plan["local stepping"])
    assert "fine steps per output interval" in plan["dt"] and "runs when the run starts" in plan["local stepping"]
    assert not checks  # `check` leaves it to the run

    plans = []
    fell_back = solver.run(scene_with("auto"), tmp_path / "auto", on_plan=plans.append)
    assert len(checks) == 1  # in the printed plan's trial stepper; the run's stepper did not check again
    # its plan comes before the stage and the check, whose line follows
    assert plans[0]["local stepping (auto)"] == '"auto": on: forced by the test'
    print(fell_back["local_stepping"])
    assert fell_back["local_stepping"].startswith('"auto": off: its set-up check found the local time stepping '
                                                  "map unstable")
    assert fell_back["dt"] == reference["dt"] and fell_back["steps"] == reference["steps"]
    assert any("unstable on this model" in warning for warning in fell_back["warnings"])
    assert history_files(tmp_path / "auto") == history_files(tmp_path / "global")  # byte for byte

    out = tmp_path / "crashed"
    saved = crash_after_a_periodic_checkpoint(monkeypatch, scene_with("auto"), out, 10, 0.15)
    assert 0.0 < saved.t < 0.15 and not saved.meta["lts_stability"]["stable"]
    checks.clear()

    never_solve_the_stage(monkeypatch)
    resumed = solver.run(scene_with("auto"), out, resume=True)
    assert not checks  # the first sitting's report
    assert resumed["resumed"][0]["t"] == pytest.approx(saved.t)
    assert_same_run(out, tmp_path / "global")


def test_a_run_resumes_under_any_setting_of_local_stepping_that_steps_it_the_same_way(tmp_path, monkeypatch):
    """time.local_stepping is left out of a checkpoint's scene fingerprint (pyfem/checkpoint.py
    DECIDED_KEYS; also from checkpoints written before): the model's part (dt, steps, the levels'
    hash) holds what it decides. A run interrupted with local stepping off resumes under "auto"
    where auto decides off too, and is refused with one line saying how it stepped and what to set
    where auto would step it locally."""
    from pyfem import checkpoint
    from pyfem.scene import parse_scene
    from test_checkpoint import crash_after_a_periodic_checkpoint

    def scene_with(local):
        data = two_layer_contact_scene(local, False).to_json()
        data["output"]["checkpoint_interval"] = 1.0e-9
        return parse_scene(data, source="test")

    fingerprints = [checkpoint.scene_fingerprint(scene_with(local)) for local in ("auto", False, True)]
    assert fingerprints[0] == fingerprints[1] == fingerprints[2] and "local_stepping" not in fingerprints[0]["time"]
    out = tmp_path / "crashed"
    saved = crash_after_a_periodic_checkpoint(monkeypatch, scene_with(False), out, 10, 0.15)
    saved.meta["fingerprint"]["scene"]["time"]["local_stepping"] = False  # as checkpoints before it wrote
    assert "local_stepping" not in saved.saved_fingerprint()["scene"]["time"]

    monkeypatch.setattr(local_stepping, "decision_of", lambda *args, **kwargs: (True, '"auto": on: forced by the test'))
    with pytest.raises(SceneError, match=r"stepped globally \(time\.local_stepping\) and this one would not; "
                                         r"set time\.local_stepping = false") as error:
        solver.run(scene_with("auto"), out, resume=True)
    print(error.value)
    monkeypatch.setattr(local_stepping, "decision_of", lambda *args, **kwargs: (False, '"auto": off: forced by the test'))
    resumed = solver.run(scene_with("auto"), out, resume=True)
    assert resumed["status"] == "finished" and resumed["resumed"] and resumed["time_reached"] >= 0.3

"""Nonlinear materials in runs (issue 9): the laws of cpp_kernels/materials through the element
loop, the scene tables [materials.NAME.plasticity] / [materials.NAME.damage] and the outputs.

- single point: the five returns of issue 9 through the Python binding of a one-cell component,
  each on the yield surface;
- dynamic, independent answer: a weak Mohr-Coulomb layer under isotropic confinement p and a
  strong vertical SV wave never carries a shear stress above c cos(phi) + p sin(phi) (+2 %),
  which the elastic run exceeds many times; the energy balance closes with the plastic
  dissipation;
- concrete: tension damage starts where and when the principal strain reaches f_t / E, never
  decreases, stays below 1, and not where the elastic tension stays below f_t;
- zero cost when off: a scene without those tables runs today's matrix-only path (no element
  loop, no new columns, bitwise reproducible) and `check` says so.
"""
import json
import math
from pathlib import Path

import numpy as np
import pytest

from pyfem import _kernels, output, solver
from pyfem.distributed_model import model_in_memory
from pyfem.fields_file import read_fields
from pyfem.scene import parse_scene

REPO = Path(__file__).resolve().parents[1]

MPa = 1.0e6
# Relative agreement with issue 9's seven-digit reference returns.
REFERENCE = 1e-6
# Yield residual of a returned state, relative to the strength.
YIELD = 1e-10
# Energy balance of a run relative to the largest energy in play (round-off of the account).
BALANCE = 1e-12
# max |sxz| / (c cos phi + p sin phi) - 1 at the weak layer's monitors (measured 7e-7)
WEAK_LAYER_CAP = 1.5e-6

# ------------------------------------------------------------------ (a) single integration point

ISSUE_E, ISSUE_NU = 10.0e9, 0.25
ISSUE_C, ISSUE_PHI, ISSUE_PSI = 1.0 * MPa, 30.0, 10.0
# (trial principal stresses, expected return) in MPa, tension positive; f_t = inf unless given.
ISSUE_RETURNS = [
    ((-2.0, -5.0, -15.0), (-3.588742, -5.204767, -14.230327), math.inf),   # main plane
    ((-5.0, -5.0, -20.0), (-5.398078, -5.398078, -19.658335), math.inf),   # compression edge
    ((-2.0, -12.0, -12.0), (-2.798008, -11.858127, -11.858127), math.inf),  # extension edge
    ((3.0, 2.5, 2.0), (1.732051, 1.732051, 1.732051), math.inf),           # apex c cot(phi)
    ((2.0, 0.0, 0.0), (0.5, -0.5, -0.5), 0.5 * MPa),                       # tension cut-off
]
CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)


def one_cell_component(tensile_strength):
    """A unit-cube Q1 cell with one quadrature point at its centre and the issue's rock law (no damage)."""
    gradients = np.ascontiguousarray(((2.0 * CORNERS - 1.0) * 0.25)[None, None])  # dphi_a/dx at the centre
    return _kernels.HexahedronElements(
        np.arange(8, dtype=np.int32)[None], gradients, np.ones((1, 1)), "mohr_coulomb",
        {"young_modulus": ISSUE_E, "poisson_ratio": ISSUE_NU, "cohesion": ISSUE_C, "friction_angle": ISSUE_PHI,
         "dilation_angle": ISSUE_PSI, "tensile_strength": tensile_strength, "damage_max": 0.0})


def mohr_coulomb_yield(principal, tensile_strength):
    """Largest yield function (Pa) of sorted principal stresses (s1 >= s2 >= s3)."""
    s1, _, s3 = principal
    sin_phi, cos_phi = math.sin(math.radians(ISSUE_PHI)), math.cos(math.radians(ISSUE_PHI))
    value = (s1 - s3) + (s1 + s3) * sin_phi - 2.0 * ISSUE_C * cos_phi
    return max(value, s1 - tensile_strength) if math.isfinite(tensile_strength) else value


@pytest.mark.parametrize("trial, expected, tensile_strength", ISSUE_RETURNS)
def test_issue_returns_through_a_one_cell_component(trial, expected, tensile_strength):
    component = one_cell_component(tensile_strength)
    sigma = np.array(trial) * MPa
    strain = ((1.0 + ISSUE_NU) * sigma - ISSUE_NU * sigma.sum()) / ISSUE_E  # C^-1 : trial, principal axes xyz
    u = np.ascontiguousarray((CORNERS * strain).ravel())                     # u = eps x: uniform strain
    force = np.zeros(24)
    component.compute(u, force)
    component.commit()
    stress = component.stress()[0, 0]
    assert np.max(np.abs(stress[3:])) < 1e-9 * MPa                          # stays in the principal axes
    np.testing.assert_allclose(stress[:3] / MPa, expected, rtol=REFERENCE)
    principal = np.sort(stress[:3])[::-1]
    strength = 2.0 * ISSUE_C * math.cos(math.radians(ISSUE_PHI))
    assert mohr_coulomb_yield(principal, tensile_strength) <= YIELD * strength
    assert abs(mohr_coulomb_yield(principal, tensile_strength)) <= YIELD * strength  # on the surface
    assert component.plastic_strain()[0, 0] > 0.0
    assert component.damage_type()[0, 0] == (1 if math.isfinite(tensile_strength) else 2)
    assert component.damage()[0, 0] == 0.0
    # The element force is that of the returned stress: f_a = w (sigma - sigma0) grad phi_a.
    tensor = np.diag(stress[:3])
    np.testing.assert_allclose(force.reshape(8, 3), ((2.0 * CORNERS - 1.0) * 0.25) @ tensor,
                               rtol=1e-12, atol=1e-9 * MPa)


# ------------------------------------------------------------- (b) weak Mohr-Coulomb layer, SV

ROCK = {"E": 8.0e9, "nu": 0.25, "rho": 2600.0}
WEAK_C, WEAK_PHI = 0.1 * MPa, 30.0
# Isotropic initial stress p = rho_o g (z_s - z): k = [1, 1, 1], a light overburden high above, so
# p varies by +-2.5 % over the layer (about 1 MPa in it); each point's cap uses its own p.
OVERBURDEN = {"surface": 230.0, "rho": 500.0, "k": [1.0, 1.0, 1.0]}


def weak_layer_scene(plastic):
    """A 150 x 10 x 60 m box, a 10 m weak layer between two rock layers of the same elasticity
    (so the elastic run is the free field), vertical SV Ricker 5 Hz strong enough for an
    elastic shear stress nine times the layer's strength. The box is wide so that its centre
    stays one-dimensional (constant normal stresses) while the layer yields."""
    weak = dict(ROCK)
    if plastic:
        weak["plasticity"] = {"cohesion": WEAK_C, "friction_angle": WEAK_PHI, "tensile_strength": 1.0 * MPa,
                              "damage_max": 0.0}
    return parse_scene({
        "title": "weak layer " + ("plastic" if plastic else "elastic"),
        "mesh": {"builder": "box", "size": [150.0, 10.0, 60.0], "h": 5.0,
                 "layers": [{"material": "lower", "thickness": 25.0}, {"material": "weak", "thickness": 10.0},
                            {"material": "upper", "thickness": 25.0}]},
        "materials": {"lower": ROCK, "weak": weak, "upper": ROCK},
        "time": {"duration": 0.5},
        "wave": {"type": "SV", "angle": 0.0, "surface": 60.0, "medium": "lower",
                 "motion": {"ricker": {"f0": 5.0, "amplitude": 0.03}}},
        "initial_stress": OVERBURDEN,
        "monitor": [{"name": "layer", "point": [75.0, 5.0, 30.0]}, {"name": "layer_low", "point": [75.0, 5.0, 26.0]},
                    {"name": "rock", "point": [75.0, 5.0, 45.0]}],
        "output": {"interval": 0.005, "xdmf_interval": 0.1, "fields": ["displacement", "stress", "damage"]},
    })


@pytest.fixture(scope="module")
def weak_layer_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("weak_layer")
    return {plastic: (solver.run(weak_layer_scene(plastic), out / f"plastic_{plastic}"), out / f"plastic_{plastic}")
            for plastic in (True, False)}


def monitor(out_dir, name):
    return np.genfromtxt(out_dir / "monitors" / f"{name}.csv", delimiter=",", names=True)


def shear_cap(history):
    """c cos(phi) + p sin(phi) (Pa) with p the isotropic confinement at the point (its stress at t = 0)."""
    p = -history["szz"][0]
    assert np.allclose([history["sxx"][0], history["syy"][0]], -p, rtol=1e-12)  # isotropic
    return WEAK_C * math.cos(math.radians(WEAK_PHI)) + p * math.sin(math.radians(WEAK_PHI))


def test_weak_layer_shear_stress_is_capped_by_mohr_coulomb(weak_layer_runs):
    (plastic, plastic_dir), (elastic, elastic_dir) = weak_layer_runs[True], weak_layer_runs[False]
    checks = 0
    for name in ("layer", "layer_low"):
        history, reference = monitor(plastic_dir, name), monitor(elastic_dir, name)
        # The layer yielded at this monitor (else the cap would be checked on an elastic history).
        assert history["plastic_strain"][-1] > 1e-3
        assert np.all(history["damage_type"][history["plastic_strain"] > 0] == 2)  # shear
        cap = shear_cap(history)
        ratio = np.max(np.abs(history["sxz"])) / cap
        elastic_ratio = np.max(np.abs(reference["sxz"])) / shear_cap(reference)
        print(f"{name}: p = {-history['szz'][0] / MPa:.4f} MPa, cap {cap / MPa:.4f} MPa, max |sxz| / cap: "
              f"plastic {ratio:.7f}, elastic {elastic_ratio:.2f}")
        # measured 0.9999993 / 0.9999998: catches the yield surface off by 0.01 % (cohesion x 1.02: 0.3 %)
        assert abs(ratio - 1.0) < WEAK_LAYER_CAP
        assert elastic_ratio > 5.0
        checks += 1
    assert checks == 2
    # The rock above is elastic: no columns change meaning there, no plastic strain.
    rock = monitor(plastic_dir, "rock")
    assert np.all(rock["plastic_strain"] == 0.0) and np.all(rock["damage"] == 0.0)
    summary = plastic["nonlinear_regions"]["weak"]
    assert summary["law"] == "mohr_coulomb" and summary["yielded_volume"] > 0.5 * summary["volume"]
    assert summary["peak_damage"] == 0.0 and summary["damaged_volume"] == 0.0  # damage_max = 0


def test_weak_layer_energy_balance_closes_with_the_plastic_dissipation(weak_layer_runs):
    plastic, plastic_dir = weak_layer_runs[True]
    energy = plastic["energy"]
    dissipated = plastic["nonlinear_regions"]["weak"]["dissipated_energy"]
    print(f"balance error {energy['balance_error']:.2e} of {energy['reference_energy']:.4e} J; plastic "
          f"dissipation {energy['internal_dissipation']:.4e} J")
    assert energy["balance_error"] < BALANCE
    assert energy["internal_dissipation"] > 1e-3 * energy["reference_energy"]
    assert dissipated == pytest.approx(energy["internal_dissipation"], rel=1e-12)
    rows = np.genfromtxt(plastic_dir / "energy.csv", delimiter=",", names=True)
    assert list(rows.dtype.names)[-2:] == ["internal_stored", "internal_dissipation"]
    assert np.all(np.diff(rows["internal_dissipation"]) >= -1e-9 * energy["reference_energy"])
    assert np.max(np.abs(rows["balance"])) < BALANCE * energy["reference_energy"]


def test_the_section_after_the_earthquake_is_drawn_without_paraview(weak_layer_runs):
    """plots/section_end.png: the weak layer's plastic strain, damage and its type at the end of the
    run, in the section through the first monitor; run.json's figures are the regions' own peaks
    (catches an empty or mis-coloured section: the layer yielded, so its peak must show)."""
    summary, out = weak_layer_runs[True]
    assert (out / "plots" / "section_end.png").stat().st_size > 20000
    section = json.loads((out / "run.json").read_text())["section_end"]
    weak = summary["nonlinear_regions"]["weak"]
    assert weak["peak_plastic_strain"] > 0.0  # the layer yielded
    assert section["cells"] > 0 and 0.0 < section["peak_plastic_strain"] <= weak["peak_plastic_strain"] * (1 + 1e-12)
    # The elastic run's element loop is empty: no section of a nonlinear state.
    assert "section_end" not in json.loads((weak_layer_runs[False][1] / "run.json").read_text())


def test_weak_layer_fields_and_plan(weak_layer_runs):
    plastic, plastic_dir = weak_layer_runs[True]
    fields = read_fields(plastic_dir / "fields.xdmf")
    points, cells = fields.points, fields.cells
    _, _, cell_data = fields.steps[-1]
    plastic_strain = cell_data["plastic_strain"]
    assert set(cell_data) >= {"stress", "damage", "damage_type", "plastic_strain"}
    centroid_z = points[cells][:, :, 2].mean(axis=1)
    in_layer = (25.0 < centroid_z) & (centroid_z < 35.0)
    assert np.count_nonzero(in_layer) == 30 * 2 * 2  # 30 x 2 cells, two high
    assert np.count_nonzero(plastic_strain[in_layer] > 0) > 0.5 * np.count_nonzero(in_layer)
    assert np.all(plastic_strain[~in_layer] == 0.0) and np.all(cell_data["damage_type"][~in_layer] == 0)
    assert set(np.unique(cell_data["damage_type"][in_layer])) <= {0, 2}
    plan = solver.plan(weak_layer_scene(True))
    assert "weak" in plan["nonlinear regions"] and "mohr_coulomb, 120 cells, 960 points" in plan["nonlinear regions"]["weak"]
    assert "mean dilatation" in plan["nonlinear regions"]["weak"]
    assert "ns per point" in plan["element loop"] and "soften" in plan["element loop dt"]
    # One measurement: the element loop's time and the per-step breakdown's element_loop agree (a new
    # user read 6.3 ms "10 % of the step" beside 30.9 ms in the breakdown).
    import re

    loop_ms = float(re.match(r"([0-9.]+) ms per step", plan["element loop"]).group(1))
    assert f"element_loop {loop_ms:.3f} ms" in plan["time per step"]
    assert "crack band" not in plan["nonlinear regions"]["weak"]
    # With the rock's crack band, check names u_ref and the kappa_ref of the layer's 5 m cells.
    banded = weak_layer_scene(True)
    banded["materials"]["weak"]["plasticity"].update(damage_max=0.5, damage_plastic_displacement=0.01)
    line = solver.plan(banded)["nonlinear regions"]["weak"]
    assert "crack band u_ref = 0.01 m: kappa_ref 0.002-0.002 in its cells (h 5-5 m" in line


# ----------------------------------------------------------------------------- (c) concrete

CONCRETE = {"E": 28.0e9, "nu": 0.167, "rho": 2500.0}
F_T = 1.27 * MPa
DEPTHS = (1.0, 3.0, 6.0, 18.0)  # m below the free surface; the lining is the top 20 m


def lining_scene(damage):
    """An 80 m column of concrete (h = 4 m, below the crack band's 4.2 m), the top 20 m a lining
    layer with Eq. 21 damage, under a vertical P Ricker reflected at the free top: the dynamic
    tension grows with depth, above f_t at the bottom of the lining, far below it near the top."""
    lining = dict(CONCRETE)
    if damage:
        lining["damage"] = {"cohesion": 1.8 * MPa, "friction_angle": 46.0, "tensile_strength": F_T}
    return parse_scene({
        "title": "lining " + ("damage" if damage else "elastic"),
        "mesh": {"builder": "box", "size": [16.0, 8.0, 80.0], "h": 4.0,
                 "layers": [{"material": "base", "thickness": 60.0}, {"material": "lining", "thickness": 20.0}]},
        "materials": {"base": CONCRETE, "lining": lining},
        "time": {"duration": 0.3},
        "wave": {"type": "P", "angle": 0.0, "surface": 80.0, "medium": "base",
                 "motion": {"ricker": {"f0": 10.0, "amplitude": 0.004}}},
        "monitor": [{"name": f"depth_{depth:g}", "point": [8.0, 4.0, 80.0 - depth]} for depth in DEPTHS],
        "output": {"interval": 0.002, "xdmf_interval": 0.01, "fields": ["displacement", "stress", "damage"]},
    })


def largest_principal_strain(history, damage=None):
    """Largest principal strain (-) of the recorded stress, C^-1 sigma / (1 - d): the law's strain in
    tension (sigma = (1 - d) C : eps when every principal stress is tensile)."""
    stress = np.stack([history[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")], axis=1)
    tensor = np.zeros((len(stress), 3, 3))
    for k, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))):
        tensor[:, i, j] = tensor[:, j, i] = stress[:, k]
    E, nu = CONCRETE["E"], CONCRETE["nu"]
    strain = ((1 + nu) * tensor - nu * np.trace(tensor, axis1=1, axis2=2)[:, None, None] * np.eye(3)) / E
    largest = np.linalg.eigvalsh(strain)[:, -1]
    return largest if damage is None else largest / (1.0 - damage)


def test_concrete_tension_damage_starts_at_f_t_and_never_decreases(tmp_path):
    runs = {damage: solver.run(lining_scene(damage), tmp_path / f"damage_{damage}") for damage in (True, False)}
    threshold = F_T / CONCRETE["E"]
    cracked = intact = 0
    for depth in DEPTHS:
        history = monitor(tmp_path / "damage_True", f"depth_{depth:g}")
        elastic = largest_principal_strain(monitor(tmp_path / "damage_False", f"depth_{depth:g}"))
        d = history["damage"]
        assert np.all(np.diff(d) >= 0.0) and np.all((0.0 <= d) & (d < 1.0))
        if elastic.max() < 0.9 * threshold:  # never near f_t in the elastic run: no damage
            assert np.all(d == 0.0) and np.all(history["damage_type"] == 0)
            intact += 1
        elif d[-1] > 0.0:
            onset = int(np.argmax(d > 0.0))
            strain = largest_principal_strain(history, d)
            print(f"depth {depth:g} m: damage {d[-1]:.4f} from t = {history['t'][onset]:.3f} s; strain/eps_t before "
                  f"{strain[:onset].max() / threshold:.4f}, at onset {strain[onset] / threshold:.3f}; elastic peak "
                  f"{elastic.max() / threshold:.2f}")
            assert np.all(history["damage_type"][onset:] == 1)        # tension
            assert strain[:onset].max() < threshold * (1 + 1e-9)      # undamaged below eps_t = f_t / E
            assert strain[onset] >= threshold                          # damage appears beyond it
            assert elastic[:onset + 1].max() >= 0.95 * threshold       # where the elastic tension reaches f_t
            cracked += 1
    assert cracked >= 1 and intact >= 2
    summary = runs[True]["nonlinear_regions"]["lining"]
    assert summary["law"] == "concrete_damage" and 0.0 < summary["peak_damage"] < 1.0
    assert summary["tension_points"] > 0 and summary["shear_points"] == 0
    assert 0.0 < summary["damaged_volume"] < summary["volume"]
    energy = runs[True]["energy"]
    assert energy["balance_error"] < BALANCE and energy["internal_dissipation"] > 0.0
    # Every cell's damage over the whole run, from the XDMF: non-decreasing, in [0, 1).
    fields = read_fields(tmp_path / "damage_True" / "fields.xdmf")
    points, cells, samples = fields.points, fields.cells, fields.steps
    damage = np.array([cell_data["damage"] for _, _, cell_data in samples])
    assert damage.shape[0] > 20 and damage[-1].max() > 0.0
    assert np.all(np.diff(damage, axis=0) >= 0.0) and np.all((damage >= 0.0) & (damage < 1.0))
    # The crack band's opening (docs/materials.md "Crack opening"): where and only where the cells
    # cracked, never closing in the record (its largest so far), and run.json's peak is the field's.
    opening = np.array([cell_data["crack_opening"] for _, _, cell_data in samples])
    assert np.all(np.diff(opening, axis=0) >= 0.0)
    assert np.all((opening[-1] > 0.0) == (damage[-1] > 0.0))
    assert summary["peak_crack_opening"] == pytest.approx(opening[-1].max(), rel=1e-12)
    # Independently, from the displacements: a row cracked through (the P wave's tension pulls the
    # lining's top off) opens by the jump of u_z across it less its elastic part h sigma_zz / E, at
    # its largest over the record (fields every 0.01 s, so the sampled largest is a little low).
    cracked_through = np.flatnonzero(damage[-1] > 0.99)
    assert len(cracked_through) >= 4
    for cell in cracked_through:
        nodes = cells[cell]
        above = nodes[points[nodes, 2] > points[nodes, 2].mean()]
        below = nodes[points[nodes, 2] < points[nodes, 2].mean()]
        h = points[above, 2].mean() - points[below, 2].mean()
        jump = max(u["displacement"][above, 2].mean() - u["displacement"][below, 2].mean()
                   - h * c["stress"][cell, 5] / CONCRETE["E"] for _, u, c in samples)
        print(f"cell {cell}: opening {1e3 * opening[-1, cell]:.3f} mm, displacement jump {1e3 * jump:.3f} mm")
        assert 0.9 * opening[-1, cell] < jump <= opening[-1, cell] * (1.0 + 1e-3)
    by_opening = list(summary["cracked_volume_by_opening"].values())
    assert list(summary["cracked_volume_by_opening"]) == ["0.1", "0.2", "0.3", "1", "10"]
    assert all(a >= b for a, b in zip(by_opening, by_opening[1:])) and by_opening[0] <= summary["volume"]


# ------------------------------------------------------------------------- (d) zero cost when off

def test_a_scene_without_nonlinear_tables_runs_the_matrix_path(tmp_path):
    scene = lining_scene(False)
    scene["time"]["duration"] = 0.1
    scene["output"]["fields"] = ["displacement", "stress"]
    model = model_in_memory(scene)
    assert model.loop is None and model.monitors.stress.kernel_points is None
    assert len(model.monitors.index) == len(DEPTHS)  # (the monitors were located: their stress read from the matrix)
    assert "none" in solver.plan(scene)["element loop"] and "nonlinear regions" not in solver.plan(scene)
    stepper, _ = model.stepper()
    n = 3 * model.part.n_local
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    stepper.run(u, v, a, 10, 0.0)
    assert "internal_stored" not in stepper.energy()  # no component in the stepper
    first, second = (solver.run(scene, tmp_path / name) for name in ("first", "second"))
    for name in [f"monitors/depth_{depth:g}.csv" for depth in DEPTHS] + ["energy.csv"]:
        assert (tmp_path / "first" / name).read_bytes() == (tmp_path / "second" / name).read_bytes()
    header = (tmp_path / "first" / "monitors" / "depth_1.csv").read_text().splitlines()[0]
    assert header.endswith("s1,s1_dynamic")  # no damage columns
    assert (tmp_path / "first" / "energy.csv").read_text().startswith(
        "t,kinetic,strain,external_work,damping_work,balance\n")
    assert "nonlinear_regions" not in json.loads((tmp_path / "first" / "run.json").read_text())


def test_plasticity_zone_takes_only_its_cells_into_the_element_loop():
    """[plasticity] zone: the weak layer's cells with centroids in the box go to the element loop, the
    others stay in the matrix; the matrix then has the element loop's cells only where it should
    (its stiffness plus the element loop's linear force is the full model's for a linear law)."""
    from pyfem.elements import (cells_in_zone, nonlinear_component, region_cells, region_elastic_parameters,
                                scene_laws)
    from pyfem.operators import build_model

    scene = weak_layer_scene(True)
    scene["materials"]["weak"]["plasticity"]["zone"] = [50.0, -1.0, 0.0, 100.0, 11.0, 60.0]
    laws, _ = scene_laws(scene)
    assert laws["weak"]["zone"] == [50.0, -1.0, 0.0, 100.0, 11.0, 60.0]
    model = build_model(scene)
    nonlinear = nonlinear_component(model, list(laws), laws)
    cells = nonlinear.arrays["weak"].cells
    every = region_cells(model, "weak")
    assert 0 < len(cells) < len(every)
    x = nonlinear.arrays["weak"].points[..., 0]
    assert x.min() > 50.0 - 5.0 and x.max() < 100.0 + 5.0, "only cells of the box (h = 5 m)"
    assert np.array_equal(cells, cells_in_zone(model, every, [50.0, -1.0, 0.0, 100.0, 11.0, 60.0]))
    assert nonlinear.zones["weak"] == [50.0, -1.0, 0.0, 100.0, 11.0, 60.0]
    # The matrix keeps the weak cells outside the zone: K_matrix u + f_loop(u) = K_full u.
    elastic = {"law": "linear_elastic", "zone": laws["weak"]["zone"], **region_elastic_parameters(model, "weak")}
    linear = nonlinear_component(model, ["weak"], {"weak": elastic})
    assert np.array_equal(linear.arrays["weak"].cells, cells)
    u = np.random.default_rng(1).normal(size=model.n_dofs) * 1e-4
    force = np.zeros(model.n_dofs)
    linear.components[0].compute(u, force)
    full = model.stiffness @ u
    assert np.allclose(linear.stiffness @ u + force, full, rtol=1e-9, atol=1e-9 * np.abs(full).max())
    summary = nonlinear.region_summary()["weak"]
    assert summary["zone"] == [50.0, -1.0, 0.0, 100.0, 11.0, 60.0] and summary["yielded_points_near_zone_edge"] == 0
    with pytest.raises(Exception, match="zone"):
        bad = weak_layer_scene(True)
        bad["materials"]["weak"]["plasticity"]["zone"] = [50.0, 0.0, 0.0, 40.0, 10.0, 60.0]
        parse_scene(dict(bad))


def test_a_lead_in_that_yields_the_rock_is_reported(tmp_path):
    """Catches a lead-in (t < 0) that dissipates energy without a word: a record's zero-phase
    filter precursor is long-period motion, and a layer at its strength yields under it (a new
    user's bedding pairs slipped 1.9 mm before t = 0, unreported). The weak layer under El Centro
    at 10 g (window 1.5-2.5 s, high-pass 0.1 Hz: an 8.75 s lead-in) yields before t = 0; run.json's
    "lead_in" must equal energy.csv's plastic dissipation at t = 0 and a warning must say so."""
    settings = json.loads(json.dumps(dict(weak_layer_scene(True))))
    settings["wave"]["motion"] = {"record": {"file": str(REPO / "data" / "elcentro_1940_ns.txt"), "units": "g",
                                             "pga": 10.0, "window": [1.5, 2.5], "band": [0.1, 10.0]}}
    settings["time"]["duration"] = 0.2
    settings["output"]["xdmf_interval"] = 1.0
    out = tmp_path / "run"
    summary = solver.run(parse_scene(settings), out)
    energy = np.genfromtxt(out / "energy.csv", delimiter=",", names=True)
    at_zero = np.flatnonzero(energy["t"] <= 0.0)[-1]
    before = energy["internal_dissipation"][at_zero] - energy["internal_dissipation"][0]
    whole = energy["internal_dissipation"][-1] - energy["internal_dissipation"][0]
    assert energy["t"][0] < -8.0 and before > 0.01 * whole > 0.0  # the layer yielded before t = 0
    record = summary["lead_in"]["internal_dissipation"]
    assert record["before_t0"] == pytest.approx(before, rel=1e-12)
    assert record["share"] == pytest.approx(before / whole, rel=1e-12)
    assert any("lead-in (t < 0) was not quiet" in w and "plastically" in w for w in summary["warnings"])
    assert summary["lead_in"] == json.loads((out / "run.json").read_text())["lead_in"]


def test_a_quiet_lead_in_is_not_reported():
    """Catches a warning on every record: dissipation only after t = 0, or none, is not reported;
    without a lead-in there is nothing to report."""
    times = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
    columns = ["t", "internal_dissipation", "friction_dissipation"]
    energy = np.column_stack([times, [0.0, 0.0, 0.0, 5.0, 9.0], [1.0, 1.0, 1.0, 1.0, 1.0]])
    record, message = output.lead_in_activity(times, energy, columns, 2.0)
    assert message == "" and record["internal_dissipation"] == {"before_t0": 0.0, "run": 9.0, "share": 0.0}
    energy[1, 1] = energy[2, 1] = 0.5  # 0.5 of 9 J before t = 0
    record, message = output.lead_in_activity(times, energy, columns, 2.0)
    assert record["internal_dissipation"]["share"] == pytest.approx(0.5 / 9.0) and "0.5 J plastically (6 %" in message
    assert output.lead_in_activity(times[2:], energy[2:], columns, 0.0) is None

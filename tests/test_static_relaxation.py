"""The nonlinear static stage: dynamic relaxation with the kernel (pyfem/relaxation.py,
pyfem/distributed_stage.py on the one model; docs/static.md "The nonlinear stage").

- Linear materials relaxed equal the linear solve (Kirsch tunnel; lined tunnel with install).
- Salencon's cavity (Mohr-Coulomb, hydrostatic P0): plastic radius, wall convergence (psi = 0 and
  30 deg) and hoop stress against the closed form of pyfem/analytic/salencon.py. The issue's data (P0 =
  30 MPa, G 2.8 GPa, K 3.9 GPa, c 3.45 MPa, phi 30 deg) on the test_static.py tunnel, a = 5 m
  (lengths scale with a: wall convergence 60.84 mm for psi = 0, 140.52 mm for psi = 30).
- The hand-over: a dynamic run with no wave after a plastic stage stays at rest; the components
  and the contact pairs go on from the stage's state (rebase).
"""
import json
import math

import numpy as np
import pytest

from pyfem import solver, static
from pyfem.scene import parse_scene
from pyfem.analytic.salencon import compare_to_stage, salencon
from conftest import observed_orders
from stage_state import solved
from test_static import (CENTRE, KIRSCH_ORDER_MESHES, KIRSCH_ORDER_SECTION, LINING, P, RADIUS, ROCK, THICKNESS,
                         centroids, in_plane, kirsch_order_folder, kirsch_order_mesh, layered_box, meshes, polar,
                         tunnel_scene)

SHEAR_MODULUS, BULK_MODULUS = 2.8e9, 3.9e9
P0 = 30.0e6
COHESION, FRICTION = 3.45e6, 30.0
YOUNG = 9 * SHEAR_MODULUS * BULK_MODULUS / (3 * BULK_MODULUS + SHEAR_MODULUS)
POISSON = (3 * BULK_MODULUS - 2 * SHEAR_MODULUS) / (2 * (3 * BULK_MODULUS + SHEAR_MODULUS))

__all__ = ["meshes", "kirsch_order_folder"]  # the module-scoped mesh fixtures of test_static.py

# Relaxed against the direct linear solve (Kirsch tunnel), about twice the measured 4.6e-5
# (displacement, L2) and 6.7e-7 (stress, of the largest); the lined tunnel's lining stress 1.0e-6.
RELAXED_DISPLACEMENT, RELAXED_STRESS, RELAXED_LINING_STRESS = 1.0e-4, 1.5e-6, 2.0e-6
RELAXED_LINED_DISPLACEMENT = 2.0e-4  # the lined tunnel's two stages, measured 9.3e-5 and 7.9e-5
# Salencon's cavity (Q1, mean dilatation) against the closed form, about twice the measured: plastic
# radius +1.21 % (psi 0) / +2.01 % (psi 30), wall convergence -1.16 % / -3.13 %, hoop stress at
# 1.05 a and 1.755 a +1.46 % / -1.52 % (psi 0). For psi 30 twice the measured is above the earlier
# 3 % / 5 %, which stay.
SALENCON_RADIUS = {0.0: 0.025, 30.0: 0.03}
SALENCON_WALL = {0.0: 0.025, 30.0: 0.05}
SALENCON_HOOP = 0.03
# A dynamic run with no wave after a plastic stage: the peak velocity measured 0 (Salencon) and
# 1.85e-21 m/s (the layered box), round-off of a state handed over in equilibrium; a stage that hands
# over an out-of-balance force of its own tolerance (1e-5) moves the monitors by ~1e-9 m/s and more.
HANDED_OVER_REST_VELOCITY = 5.0e-21  # m/s


def salencon_scene(mesh_file, dilation, **extra):
    scene = tunnel_scene(mesh_file, stress=[-P0, -P0, -P0, 0.0, 0.0, 0.0],
                         static={"excavate": ["excavation"], "relaxation": 0.0}, **extra)
    rock = dict(scene["materials"]["rock"], E=YOUNG, nu=POISSON)
    rock["plasticity"] = {"cohesion": COHESION, "friction_angle": FRICTION, "dilation_angle": dilation,
                          "tensile_strength": 1.0e9, "damage_max": 0.0}
    return parse_scene(dict(scene, materials={"rock": rock}))


def test_relaxation_of_linear_materials_is_the_linear_solve(meshes):
    """solver = "relaxation" on the Kirsch tunnel (linear rock) gives the direct solve's displacement
    and stress to the relaxation's tolerance."""
    direct = solved(tunnel_scene(meshes["filled"]))
    relaxed = solved(tunnel_scene(meshes["filled"], static={"excavate": ["excavation"], "relaxation": 0.0,
                                                            "solver": "relaxation"}))
    stage = relaxed.stages[1]
    assert direct.stages[1]["solver"].startswith("direct")
    assert stage["solver"].startswith("dynamic relaxation") and stage["converged"] and stage["iterations"] > 100
    assert stage["residual"] <= static.RELAXATION_TOLERANCE
    u_error = (np.linalg.norm(relaxed.displacement - direct.displacement)
               / np.linalg.norm(direct.displacement))
    stress_error = (np.abs(relaxed.cell_stress - direct.cell_stress).max()
                    / np.abs(direct.cell_stress).max())
    print(f"relaxation vs direct: {stage['iterations']} steps, {stage['seconds']:.2f} s, displacement "
          f"{u_error:.2e}, stress {stress_error:.2e}")
    # catches the relaxation stopped short (a looser out-of-balance tolerance) or a wrong load
    assert u_error < RELAXED_DISPLACEMENT and stress_error < RELAXED_STRESS


def test_relaxation_with_an_installed_lining_is_the_linear_solve(meshes):
    """Two stages (relaxation 0.4, lining installed between): the lining's stress and the
    displacements of the relaxed stage equal the direct solve's."""
    from pyfem.elements import region_cells

    settings = {"excavate": ["excavation"], "install": ["lining"], "relaxation": 0.4}
    direct = solved(tunnel_scene(meshes["lined"], lined=True, static=settings))
    relaxed = solved(tunnel_scene(meshes["lined"], lined=True, static=dict(settings, solver="relaxation")))
    assert relaxed.stages[1]["solver"].startswith("dynamic relaxation") and direct.stages[1]["solver"].startswith("direct")
    cells = region_cells(relaxed.model, "lining")
    assert np.abs(direct.cell_stress[cells]).max() > 1e6, "the lining carries load"
    for name in ("displacement_first", "displacement"):
        a, b = getattr(relaxed, name), getattr(direct, name)
        print(f"{name} relaxed vs direct: {np.linalg.norm(a - b) / np.linalg.norm(b):.2e}")
        # measured 9.3e-5 (first stage) and 7.9e-5: catches a stage relaxed short or a wrong relaxation share
        assert np.linalg.norm(a - b) / np.linalg.norm(b) < RELAXED_LINED_DISPLACEMENT, name
    lining_error = (np.abs(relaxed.cell_stress[cells] - direct.cell_stress[cells]).max()
                    / np.abs(direct.cell_stress[cells]).max())
    print(f"lining stress relaxed vs direct: {lining_error:.2e}")
    # catches the lining loaded by a wrong share of the relaxation (or installed a stage off)
    assert lining_error < RELAXED_LINING_STRESS
    assert np.abs(relaxed.cell_stress_first[cells]).max() == 0.0


@pytest.mark.parametrize("dilation", [0.0, 30.0])
def test_salencon_cavity(meshes, dilation):
    """Mohr-Coulomb cavity under hydrostatic P0, unsupported: the plastic radius within 2.5 % (psi = 0)
    / 3 % (psi = 30 deg), the wall convergence within 2.5 % / 5 %, the hoop stress at the cells nearest
    the wall and nearest R0 against the closed form at their own radius within 3 % (SALENCON_*); the
    elastic rock beyond R0 stays elastic and the zone inside yields."""
    simulation = solved(salencon_scene(meshes["filled"], dilation))
    found = salencon_comparison(simulation, dilation, f"psi {dilation:g}")
    # the wall catches a yield surface off by 2 % (cohesion x 1.02: wall -2.8 % (psi 0), -6.1 % (psi 30))
    assert abs(found["radius_error"]) < SALENCON_RADIUS[dilation]
    assert abs(found["wall_error"]) < SALENCON_WALL[dilation]
    # The hoop stress for psi = 0 only: the closed form takes sigma_z as the intermediate stress, which
    # the 3D law does not assume; near the wall sigma_z exceeds sigma_theta (Reed 1988), and with
    # dilation the (z, r) plane yields too (the FE hoop stress at 1.05 a is then 6 % above).
    for where, error in found["hoop_errors"].items() if dilation == 0.0 else ():
        assert abs(error) < SALENCON_HOOP, where  # catches a hoop stress off by the FE error again


def salencon_comparison(simulation, dilation: float, label: str) -> dict:
    """A Salencon stage against the closed form, after checking that it converged and yielded where
    the closed form does (everything inside 0.9 R0, nothing beyond 1.15 R0): the relative errors of
    the plastic radius, the wall convergence and the hoop stress at the cells nearest the wall and
    R0 ({"wall", "R0"}), and the stage's `result` (compare_to_stage) and plastic strain per cell."""
    state = simulation.static
    assert all(stage["converged"] for stage in state.stages)
    plastic = state.cell_state["plastic_strain"]
    exact = salencon(np.array([RADIUS]), RADIUS, P0, SHEAR_MODULUS, BULK_MODULUS, COHESION, FRICTION, dilation)
    R0 = float(exact["R0"])
    assert R0 > 1.5 * RADIUS, "the closed form yields: the test is about plastic flow"
    result = compare_to_stage(simulation, CENTRE, RADIUS, cell_plastic_strain=plastic)
    r_cells = in_plane(centroids(simulation.model))[0] * RADIUS
    assert np.all(plastic[r_cells < 0.9 * R0] > 0.0), "everything inside 0.9 R0 yields"
    assert np.all(plastic[r_cells > 1.15 * R0] == 0.0), "nothing beyond 1.15 R0 yields"
    radius_error = result["plastic_radius"] / R0 - 1
    wall_error = result["wall_displacement"] / float(exact["u_r"][0]) - 1
    print(f"{label}: steps {[s['iterations'] for s in state.stages]}, {state.report['seconds']:.1f} s; plastic "
          f"radius {result['plastic_radius'] / RADIUS:.3f} a vs {R0 / RADIUS:.3f} a ({radius_error:+.2%}); wall "
          f"convergence {result['wall_displacement'] * 1e3:.2f} mm vs {float(exact['u_r'][0]) * 1e3:.2f} mm "
          f"({wall_error:+.2%})")
    hoop_errors = {}
    for where in ("wall", "R0"):
        r = result[f"r_{where}"]
        reference = float(salencon(np.array([r]), RADIUS, P0, SHEAR_MODULUS, BULK_MODULUS, COHESION, FRICTION,
                                   dilation)["sigma_theta"][0])
        hoop_errors[where] = result[f"sigma_theta_{where}"] / reference - 1
        print(f"  hoop stress at r = {r / RADIUS:.3f} a: {result[f'sigma_theta_{where}'] / 1e6:.2f} MPa vs "
              f"{reference / 1e6:.2f} ({hoop_errors[where]:+.2%})")
    return {"radius_error": radius_error, "wall_error": wall_error, "hoop_errors": hoop_errors, "result": result,
            "plastic": plastic}

# Salencon's order in h (psi = 0): the filled tunnel on the 480 m slab of test_static.py's Kirsch order
# (KIRSCH_ORDER_MESHES: (h_wall, h_far) = (1.2, 16), (0.6, 8) m; (0.3, 4) m in the slow tier). On the 240 m
# slab of test_salencon_cavity the rollers (24 a out, 14 R0) leave -1.2 % in the wall's convergence.
# Measured, the hoop stress at the centroids of the elastic cells 1.15 R0 < r < 2 R0 (relative L2):
# 1.29 / 0.55 / 0.20 %, orders 1.23 and 1.47. The plastic zone has no order against the closed form: the
# wall's convergence is -3.54 / -0.52 / +0.82 % off (it changes sign), the hoop stress within r < 1.3 a
# 4.98 / 1.84 / 3.84 %. There the model's 3D law has sigma_z = sigma_theta (the wall ring's cells: 13.94
# against 13.97 MPa, 12.76 against 12.91 MPa on the two finer meshes): the stress sits on the edge of the
# Mohr-Coulomb pyramid and flows in the (z, r) plane too, which the closed form, taking sigma_z as the
# intermediate stress, leaves out (Reed 1988). The finer meshes resolve that difference of the problems,
# not a discretisation error. The plastic radius (+1.76 / +1.97 / +1.31 %) is read off rings of 0.05 a
# (2.9 % of R0) and has no order to observe either; test_salencon_cavity holds it.
SALENCON_ORDER_ELASTIC = (1.0, 1.45)


def salencon_order_errors(folder, h_wall, h_far, cohesion=COHESION):
    """(wall convergence error, hoop stress error in the elastic zone 1.15 R0 < r < 2 R0) of Salencon's
    cavity (psi = 0) on the 480 m slab, after checking that the stage converged and the rock yielded near
    the wall and not far out."""
    scene = salencon_scene(kirsch_order_mesh(folder, h_wall, h_far), 0.0)
    scene["materials"]["rock"]["plasticity"]["cohesion"] = cohesion
    simulation = solved(scene)
    assert all(stage["converged"] for stage in simulation.stages)
    centre = np.array([KIRSCH_ORDER_SECTION / 2, THICKNESS / 2, KIRSCH_ORDER_SECTION / 2])
    plastic = simulation.cell_state["plastic_strain"]
    result = compare_to_stage(simulation, centre, RADIUS, cell_plastic_strain=plastic)
    exact = salencon(np.array([RADIUS]), RADIUS, P0, SHEAR_MODULUS, BULK_MODULUS, COHESION, FRICTION, 0.0)
    R0, r = float(exact["R0"]), result["cell_r"]
    assert np.all(plastic[r < 0.9 * R0] > 0.0) and np.all(plastic[r > 1.15 * R0] == 0.0), "it yielded where it should"
    elastic = (r > 1.15 * R0) & (r < 2 * R0)
    assert np.count_nonzero(elastic) > 50
    hoop = salencon(r[elastic], RADIUS, P0, SHEAR_MODULUS, BULK_MODULUS, COHESION, FRICTION, 0.0)["sigma_theta"]
    return (result["wall_displacement"] / float(exact["u_r"][0]) - 1,
            np.linalg.norm(result["cell_sigma_theta"][elastic] - hoop) / np.linalg.norm(hoop))


def test_salencon_cavity_converges_in_h(kirsch_order_folder):
    """Salencon's cavity (psi = 0) on two meshes: the hoop stress in the elastic zone at order 1.23 (bounds
    1.0-1.45), the finer mesh's within about twice the measured 0.55 %, and the wall's convergence within
    about twice its measured -0.52 % (no order: see above). Catches a yield surface off by 2 % (cohesion x
    1.02 moves sigma(R0) and R0: the wall's error on the finer mesh goes past its bound) or a plastic zone
    whose radius does not converge (the elastic zone's error stalls)."""
    meshes_used = KIRSCH_ORDER_MESHES[:2]
    errors = np.array([salencon_order_errors(kirsch_order_folder, *mesh) for mesh in meshes_used])
    order = observed_orders([h_wall for h_wall, _ in meshes_used], errors[:, 1])[0]
    print(f"Salencon psi 0: wall errors {errors[:, 0]}; elastic zone's hoop errors {errors[:, 1]}, order {order:.3f}")
    assert SALENCON_ORDER_ELASTIC[0] < order < SALENCON_ORDER_ELASTIC[1]
    assert errors[1, 1] < 0.011 and abs(errors[1, 0]) < 0.0105


@pytest.mark.slow
def test_salencon_cavity_converges_in_h_on_three_meshes(kirsch_order_folder):
    """The same with (0.3, 4) m: the elastic zone's second order (measured 1.47, bounds 1.2-1.75), its
    finest error within about twice the measured 0.20 %, the wall's within twice its +0.82 %. Catches an
    error that stalls below the default tier's resolution."""
    errors = np.array([salencon_order_errors(kirsch_order_folder, *mesh) for mesh in KIRSCH_ORDER_MESHES])
    orders = observed_orders([h_wall for h_wall, _ in KIRSCH_ORDER_MESHES], errors[:, 1])
    print(f"Salencon psi 0: wall errors {errors[:, 0]}; elastic zone's hoop errors {errors[:, 1]}, orders {orders}")
    assert SALENCON_ORDER_ELASTIC[0] < orders[0] < SALENCON_ORDER_ELASTIC[1] and 1.2 < orders[1] < 1.75
    assert errors[2, 1] < 0.004 and abs(errors[2, 0]) < 0.0165


SALENCON_AS_WRITTEN = """\
title = "Salencon's cavity, the rock written with its strengths only"
[mesh]
builder = "file"
file = "{mesh}"
[materials.rock]
E = {E!r}
nu = {nu!r}
rho = 2600.0
[materials.rock.plasticity]
cohesion = {c!r}
friction_angle = {phi!r}
dilation_angle = 0.0
tensile_strength = 1.0e9
[time]
duration = 0.01
[boundary.face]
ymin = {{type = "roller"}}
ymax = {{type = "roller"}}
[initial_stress]
stress = [{s!r}, {s!r}, {s!r}, 0.0, 0.0, 0.0]
[static]
excavate = ["excavation"]
relaxation = 0.0
[output]
xdmf_interval = 0.0
"""


def test_salencon_cavity_written_with_the_strengths_only_is_perfectly_plastic(meshes, tmp_path):
    """A [plasticity] table with only the four strengths, as a new user writes Salencon's cavity, is
    perfectly plastic Mohr-Coulomb (no damage by default): it yields (the wall ring is plastic, the
    plastic zone reaches past 1.5 a) and reproduces the closed form at the tolerances of the table
    written with every key (SALENCON_*: radius and wall 2.5 %, hoop stress 3 %; the old default, damage
    0.9 with no scale, gave 1.49 m at the wall and stresses 94 % off)."""
    from pyfem.scene import load_scene

    path = tmp_path / "salencon.toml"
    path.write_text(SALENCON_AS_WRITTEN.format(mesh=meshes["filled"], E=YOUNG, nu=POISSON, c=COHESION,
                                               phi=FRICTION, s=-P0))
    scene = load_scene(path)
    assert scene["materials"]["rock"]["plasticity"]["damage_max"] == 0.0
    simulation = solved(scene)
    found = salencon_comparison(simulation, 0.0, "strengths only")
    # It yielded (salencon_comparison checks where), through the wall ring, and did not soften.
    plastic, result = found["plastic"], found["result"]
    assert np.max(plastic[result["cells_wall"]]) > 1e-3
    assert np.max(np.abs(simulation.cell_state["damage"])) == 0.0
    # the same closed form at the same tolerances as the table written with every key
    assert abs(found["radius_error"]) < SALENCON_RADIUS[0.0]
    assert abs(found["wall_error"]) < SALENCON_WALL[0.0]
    for where, error in found["hoop_errors"].items():
        assert abs(error) < SALENCON_HOOP, where

def test_plastic_stage_hands_over_at_rest(meshes, tmp_path):
    """After the Salencon stage (plastic zone around the wall), a dynamic run with no wave stays at
    rest: the element loop continues from the stage's stress and plastic strain (rebased), the
    monitors' t = 0 row is that stress, and the plastic strain does not grow."""
    monitor = {"name": "wall", "point": list(CENTRE + [0.0, 0.0, 1.05 * RADIUS])}
    scene = salencon_scene(meshes["filled"], 0.0, duration=0.05, monitor=[monitor])
    plans = []  # as the command line runs it: the plan (a trial stepper of its own) comes first
    summary = solver.run(scene, tmp_path / "run", on_plan=plans.append)
    assert "static stage" in plans[0]
    # catches a stage handed over out of equilibrium (stress or plastic strain not rebased)
    assert summary["monitors"]["wall"]["velocity"] < HANDED_OVER_REST_VELOCITY
    rows = np.genfromtxt(tmp_path / "run" / "monitors" / "wall.csv", delimiter=",", names=True)
    assert rows["plastic_strain"][0] > 0.0, "the monitor point yielded during the stage"
    assert np.ptp(rows["plastic_strain"]) < 1e-9 * rows["plastic_strain"][0]
    r, theta = in_plane(np.array([monitor["point"]]))
    stress = np.array([[rows["sxx"][0], rows["sxy"][0], rows["sxz"][0]],
                       [rows["sxy"][0], rows["syy"][0], rows["syz"][0]],
                       [rows["sxz"][0], rows["syz"][0], rows["szz"][0]]])
    hoop = -polar(stress, theta[0])[1]
    exact = float(salencon(np.array([r[0] * RADIUS]), RADIUS, P0, SHEAR_MODULUS, BULK_MODULUS, COHESION, FRICTION,
                           0.0)["sigma_theta"][0])
    print(f"monitor at t = 0: hoop {hoop / 1e6:.2f} MPa vs closed form {exact / 1e6:.2f}; peak velocity "
          f"{summary['monitors']['wall']['velocity']:.2e} m/s")
    assert abs(hoop / exact - 1) < 0.06
    assert np.ptp(rows["szz"]) < 1e-6 * abs(rows["szz"][0]), "the stress stays"


def test_relaxed_contact_stage_keeps_the_equilibrium_pair_forces():
    """A uniform stress with shear and a bonded interface, nothing excavated: the relaxed stage does
    not move and the pair forces are A sigma0 n (the linear stage's answer)."""
    linear = solved(layered_box())
    relaxed = solved(layered_box(solver="relaxation"))
    assert relaxed.stage.contact is not None and linear.stage.contact is None  # (the relaxed stage's pairs go on)
    scale = np.abs(linear.pair_forces).max()
    assert scale > 0.0
    assert np.abs(relaxed.pair_forces - linear.pair_forces).max() < 1e-6 * scale
    assert np.abs(relaxed.displacement).max() < 1e-12


def test_rebase_keeps_the_state_and_zeroes_the_force():
    """HexahedronElements.rebase: after a plastic step, the force at u = 0 of the rebased component
    is zero, its stress and plastic strain are kept, and a further increment du gives the stress
    the unrebased component gives at u + du."""
    from pyfem import _kernels

    gradients = np.zeros((1, 1, 8, 3))
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
    gradients[0, 0] = (corners - 0.5) * 0.5  # the trilinear gradients at the centre of a unit cube
    weights = np.ones((1, 1))
    nodes = np.arange(8, dtype=np.int32)[None]
    parameters = {"young_modulus": 10e9, "poisson_ratio": 0.25, "cohesion": 1e6, "friction_angle": 30.0,
                  "dilation_angle": 10.0, "tensile_strength": 0.5e6}
    sigma0 = np.array([[[-5e6, -5e6, -10e6, 0.0, 0.0, 0.0]]])

    def shear(g):
        u = np.zeros(24)
        u[3 * np.arange(8)] = g * corners[:, 2]  # u_x = g z
        return u

    def step(component, u):
        force = np.zeros(24)
        component.compute(u, force)
        component.commit()
        return force

    reference = _kernels.HexahedronElements(nodes, gradients, weights, "mohr_coulomb", parameters, initial_stress=sigma0)
    rebased = _kernels.HexahedronElements(nodes, gradients, weights, "mohr_coulomb", parameters, initial_stress=sigma0)
    for g in np.linspace(0, 2e-3, 21)[1:]:
        step(reference, shear(g))
        step(rebased, shear(g))
    assert rebased.plastic_strain()[0, 0] > 0.0, "the point yielded"
    before = rebased.stress().copy()
    rebased.rebase()
    assert np.array_equal(rebased.stress(), before)
    assert np.abs(step(rebased, np.zeros(24))).max() == 0.0
    for g in np.linspace(2e-3, 3e-3, 11)[1:]:
        step(reference, shear(g))
        step(rebased, shear(g - 2e-3))
    assert np.allclose(rebased.stress(), reference.stress(), rtol=1e-9, atol=1e-9 * 1e7)
    assert rebased.plastic_strain()[0, 0] == pytest.approx(reference.plastic_strain()[0, 0], rel=1e-9)


def test_contact_rebase_keeps_an_open_pair_open():
    """ContactPairs.rebase: a pair pulled open keeps its gap as an offset (it stays open when the
    new run starts from u = 0), and the total force becomes the static force."""
    from pyfem import _kernels

    pairs = np.array([[0, 1]], dtype=np.int32)
    contact = _kernels.ContactPairs(pairs, np.ones(1), np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 5.0e5]]),
                                    1.0e6, 1.0e5, 0.5, 0.5)
    mass = np.ones(2)
    blocks = np.zeros((2, 3, 3))
    stepper = _kernels.Stepper(np.array([0, 1, 2], dtype=np.int64), np.array([0, 1], dtype=np.int32), blocks, mass,
                               1.0e-3, 0.0, 0.0)
    stepper.add_contact(contact)
    u, v, a = np.zeros(6), np.zeros(6), np.zeros(6)
    v[5] = 1.0  # node 1 flies off along +n: tension beyond t_s A = 1e5 N at once
    stepper.run(u, v, a, 10, 0.0)
    assert contact.state()[0] == 3, "the pair opened"
    gap = float(contact.relative_displacement(u)[0, 2])
    assert gap > 0.0
    contact.rebase(u)
    assert contact.gap_offset()[0] == pytest.approx(gap)
    assert np.abs(contact.static_force()).max() == 0.0, "an open pair carries nothing"
    u[:], v[:], a[:] = 0.0, 0.0, 0.0
    v[5] = -0.1 * gap / 1.0e-3 / 20  # closing slowly: still open after 10 steps
    stepper.run(u, v, a, 10, 0.0)
    assert contact.state()[0] == 3 and np.abs(contact.contact_force()).max() == 0.0


def test_mean_dilatation_removes_q1_locking_in_plastic_flow(meshes):
    """Volumetric locking: with psi = 0 the plastic flow is isochoric, which fully integrated Q1
    cells (8 points) can follow only by locking; mean dilatation (B-bar, the Q1 default) frees them.
    Salencon's wall convergence with and without it against the closed form: without, it is
    clearly too stiff; with, within the issue's 5 %."""
    exact = float(salencon(np.array([RADIUS]), RADIUS, P0, SHEAR_MODULUS, BULK_MODULUS, COHESION, FRICTION,
                           0.0)["u_r"][0])
    errors = {}
    for mean_dilatation in (False, True):
        scene = salencon_scene(meshes["filled"], 0.0)
        scene["materials"]["rock"]["plasticity"]["mean_dilatation"] = mean_dilatation
        simulation = solved(scene)
        result = compare_to_stage(simulation, CENTRE, RADIUS,
                                  cell_plastic_strain=simulation.cell_state["plastic_strain"])
        errors[mean_dilatation] = result["wall_displacement"] / exact - 1
    print(f"Q1 wall convergence vs Salencon: without mean dilatation {errors[False]:+.2%}, with {errors[True]:+.2%}")
    assert abs(errors[True]) < 0.05
    # Measured: -3.20 % without, -1.16 % with (2026-11-24).
    assert errors[False] < errors[True] - 0.015, "full integration is stiffer (locks) under isochoric flow"


def test_layered_box_with_contact_and_yielding_hands_over_at_rest(tmp_path):
    """A layered box with a contact interface and a Mohr-Coulomb soft layer whose in-situ stress
    (with shear) is beyond its strength, settled under its own weight by the relaxation stage: the
    layer yields during the stage, and the dynamic run that continues its laws and pairs (no wave)
    stays at rest."""
    scene = layered_box(solver="relaxation", gravity=True)
    soft = dict(scene["materials"]["soft"])
    soft["plasticity"] = {"cohesion": 0.05e6, "friction_angle": 10.0, "tensile_strength": 0.05e6, "damage_max": 0.0}
    raw = {key: value for key, value in scene.items()}
    raw["materials"] = dict(scene["materials"], soft=soft)
    raw["time"] = {"duration": 0.02}
    raw["monitor"] = [{"name": "soft", "point": [2.0, 2.0, 4.5]}]
    raw["static"] = {"solver": "relaxation", "gravity": True}
    scene = parse_scene(raw)
    summary = solver.run(scene, tmp_path / "run")
    stage = summary["static"]["stages"][-1]
    simulation_regions = summary["nonlinear_regions"]["soft"]
    print(f"stage: {[s['iterations'] for s in summary['static']['stages']]} steps, residual {stage['residual']:.2e}; "
          f"soft layer yielded volume {simulation_regions['yielded_volume']:.3g} m^3; peak velocity "
          f"{summary['monitors']['soft']['velocity']:.2e} m/s")
    assert all(s["converged"] for s in summary["static"]["stages"])
    assert simulation_regions["yielded_volume"] > 0.0, "the soft layer yielded in the stage"
    # catches the pairs' or the layer's stage state handed over out of equilibrium
    assert summary["monitors"]["soft"]["velocity"] < HANDED_OVER_REST_VELOCITY


# ---------------------------------------------------------------------------------------------
# contact.split: the interfaces split before the stage (their law acts in it) or after it (welded)
# ---------------------------------------------------------------------------------------------

def spreading_layers(split=None, contact=True, stage_solver="relaxation"):
    """A soft layer (nu 0.45) on a hard one settling under its own weight with the xmax face and the
    top free: the soft layer spreads towards xmax and shears the interface, which with c = 0,
    t_s = 0 and 5 deg of friction cannot hold it."""
    raw = {
        "mesh": {"size": [8.0, 4.0, 8.0], "h": 1.0,
                 "layers": [{"material": "hard", "thickness": 4.0}, {"material": "soft", "thickness": 4.0}]},
        "materials": {"hard": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0},
                      "soft": {"E": 1.0e9, "nu": 0.45, "rho": 2400.0}},
        "time": {"duration": 0.01},
        "static": {"solver": stage_solver, "gravity": True,
                   "boundary": {"face": {"xmax": {"type": "free"}, "zmax": {"type": "free"},
                                         "zmin": {"type": "fixed"}}}},
    }
    if contact:
        raw["contact"] = {"interfaces": ["interface_1"], "cohesion": 0.0, "friction_angle": 5.0,
                          "tensile_strength": 0.0, **({"split": split} if split else {})}
    return parse_scene(raw)


@pytest.fixture(scope="module")
def spreading():
    """{"unsplit", "before_static", "after_static"}: the one models in memory, stage solved (stage_state.solved)."""
    runs = {"unsplit": solved(spreading_layers(contact=False))}
    for split in ("before_static", "after_static"):
        runs[split] = solved(spreading_layers(split))
    return runs


def on_unsplit(unsplit, split):
    """(node map, cell map): each node and cell of the split model's the unsplit model's at its place."""
    from scipy.spatial import cKDTree

    distance, nodes = cKDTree(unsplit.model.node_coords).query(split.model.node_coords)
    assert distance.max() < 1e-9
    distance, cells = cKDTree(centroids(unsplit.model)).query(centroids(split.model))
    assert distance.max() < 1e-9
    return nodes, cells


def test_a_stage_split_after_static_is_the_unsplit_mesh_stage(spreading):
    """contact.split = "after_static": the relaxed stage's displacement and cell stress are the
    unsplit mesh's (same body, no [contact]) to the relaxation's tolerance; the control
    "before_static" lets the pairs slide in the stage and differs."""
    unsplit = spreading["unsplit"].static
    scale_u, scale_s = np.abs(unsplit.displacement).max(), np.abs(unsplit.cell_stress).max()
    assert scale_u > 1e-4, "gravity moved the model"
    errors = {}
    for split in ("before_static", "after_static"):
        state = spreading[split].static
        assert all(stage["converged"] for stage in state.stages)
        nodes, cells = on_unsplit(spreading["unsplit"], spreading[split])
        u = state.displacement.reshape(-1, 3)
        errors[split] = (np.abs(u - unsplit.displacement.reshape(-1, 3)[nodes]).max() / scale_u,
                         np.abs(state.cell_stress - unsplit.cell_stress[cells]).max() / scale_s)
    states = np.bincount(spreading["before_static"].stage.contact.state(), minlength=4)
    print(f"split stages vs unsplit (displacement, stress): {errors}; before_static pair states {states}")
    assert states[2] + states[3] > 0, "before_static: pairs slid or opened in the stage"
    assert min(errors["before_static"]) > 0.05, "the control differs from the unsplit stage"
    # Measured: before_static 0.74 / 0.15, after_static 4.9e-7 / 1.3e-7 (2026-12-07).
    assert max(errors["after_static"]) < 1e-5
    assert spreading["after_static"].stage.contact is None, "the dynamic run gets new pairs"


def test_a_stage_split_after_static_hands_over_the_welded_traction(spreading):
    """The dynamic run's pair forces F0 are the welded stage's traction across the interface: their
    vertical resultant is the weight of the layer above (rollers and free faces carry none), and each
    interior pair's F0 is the unsplit model's stress (mean of the cells at its node) times its area
    and normal to the discretisation's error; the pairs are new ones with the scene's strengths."""
    from scipy.spatial import cKDTree

    from pyfem.initial_stress import STANDARD_GRAVITY

    split, unsplit = spreading["after_static"], spreading["unsplit"]
    pairs, F0 = split.part.pairs, split.pair_forces  # (the kernel's pairs and their F0, in one order)
    arrays = split.run.contact_arrays
    assert np.array_equal(arrays["static_force"], F0)
    assert arrays["cohesion"] == 0.0 and arrays["tensile_strength"] == 0.0
    weight = 2400.0 * STANDARD_GRAVITY * 8.0 * 4.0 * 4.0
    assert np.abs(F0).max() > 0.0, "the stage loaded the pairs"
    assert F0[:, 2].sum() == pytest.approx(-weight, rel=1e-6)
    tree, sigma = cKDTree(centroids(unsplit.model)), unsplit.static.cell_stress
    expected = np.array([area * sigma[tree.query_ball_point(x, 0.9)].mean(axis=0) @ n
                         for x, area, n in zip(pairs.coords, pairs.area, pairs.normal)])
    x = pairs.coords
    interior = (x[:, 0] > 0.5) & (x[:, 0] < 7.5) & (x[:, 1] > 0.5) & (x[:, 1] < 3.5)
    error = np.abs(F0 - expected)[interior].max() / np.abs(F0).max()
    sliding = static.pairs_over_strength(arrays)["sliding"]
    print(f"F0 vs unsplit A sigma n on {interior.sum()} interior pairs: {error:.2e}; {sliding} pairs beyond "
          f"their strength at the hand-over")
    assert error < 0.1  # measured 5.4e-2: cell-centroid stress against the nodal balance
    assert sliding > 0, "the welded traction exceeds the weak interface's strength"
    assert any("contact.split" in warning for warning in split.scene.warnings)


def test_a_linear_stage_keeps_pairs_bonded_either_way():
    """The linear stage ties the pairs whatever contact.split says: the two values give the same
    stage bit for bit."""
    states = [solved(spreading_layers(split, stage_solver="direct")) for split in ("before_static", "after_static")]
    assert np.abs(states[0].displacement).max() > 1e-4
    assert np.array_equal(states[0].displacement, states[1].displacement)
    assert np.array_equal(states[0].pair_forces, states[1].pair_forces)


SPLIT_SCENE = "tests/scenes/split_after_static.toml"


def wear_onset(ratio: float, duration: float, R0=0.75, lam=5.0, m=0.883, n=0.02, p=0.032) -> float:
    """The time D(t) = eta(t) gamma0 falls to `ratio` at rest: eta = R0 + (1 - R0) exp(-lambda t / t_s),
    gamma0 = m n^-p (docs/method.md section 9), t_s the run's duration (no record)."""
    gamma0 = m * n ** -p
    return -duration / lam * math.log((ratio / gamma0 - R0) / (1.0 - R0))


def test_a_pair_split_after_static_slips_when_the_wear_falls_below_its_static_ratio(tmp_path):
    """tests/scenes/split_after_static.toml: a uniform in-situ shear at 0.8 of the interface strength,
    the stage welded. The pair monitor stays bonded and still until D(t) falls below |T| / (mu N + c A)
    = 0.8, then slips, one-signed, within two steps of the predicted time; with R0 = 1 (no wear) it
    never slips."""
    from pyfem.scene import load_scene

    rows = {}
    for name, settings in (("worn", []), ("no_wear", ["contact.deterioration.R0=1.0"])):
        scene = load_scene(SPLIT_SCENE, settings)
        solver.run(scene, tmp_path / name)
        rows[name] = np.genfromtxt(tmp_path / name / "pairs" / "middle.csv", delimiter=",", names=True)
    worn = rows["worn"]
    N, T = worn["N"][0], worn["T"][0]
    mu = math.tan(math.radians(30.0))
    ratio = T / (mu * N + 1.0e6)  # per unit area: F0 = A sigma0 n
    assert ratio == pytest.approx(0.8, abs=1e-3)
    predicted = wear_onset(ratio, 0.1)
    moving = np.flatnonzero(np.abs(worn["slip"]) > 1e-9)
    assert len(moving), "the pair slipped"
    start = worn["t"][moving[0]]
    dt = json.loads((tmp_path / "worn" / "run.json").read_text())["dt"]
    print(f"static ratio {ratio:.4f}: slip predicted at {predicted * 1e3:.2f} ms, first seen at {start * 1e3:.2f} ms "
          f"(dt {dt * 1e3:.3f} ms, output every 1 ms); final slip {worn['dux'][-1] * 1e3:.3f} mm")
    assert np.all(worn["state"][worn["t"] < predicted - dt] == 0), "bonded until the wear reaches the ratio"
    assert predicted - dt <= start <= predicted + 1.0e-3 + 2 * dt
    dux = worn["dux"]
    assert np.all(np.sign(dux[moving]) == np.sign(dux[-1])) and np.all(np.diff(np.abs(dux)) >= -1e-12 * abs(dux[-1]))
    assert np.abs(rows["no_wear"]["slip"]).max() < 1e-12, "without wear the stuck pair stays stuck"

"""The static stage (docs/static.md): excavation load, relaxation, installed support, hand-over.

Kirsch: a circular tunnel (a = 5 m, axis y) in a plane-strain slab 240 x 240 m, 2 m thick, meshed by
meshes/tunnel_in_box.py --filled (the hole is the region "excavation", removed by the stage); far
field sigma_zz = -p, sigma_xx = -K p (p = 10 MPa, K = 0.5) through `[initial_stress] stress`;
rollers on every face during the stage. With compression positive and theta from +x towards +z
(Brady & Brown, Rock Mechanics for Underground Mining, ch. 7):
    sigma_rr = p/2 [(1+K)(1 - a^2/r^2) - (1-K)(1 - 4a^2/r^2 + 3a^4/r^4) cos 2theta]
    sigma_tt = p/2 [(1+K)(1 + a^2/r^2) + (1-K)(1 + 3a^4/r^4) cos 2theta]
    u_r      = -p a^2/(4 G r) [(1+K) - (1-K)(4(1-nu) - a^2/r^2) cos 2theta]   (the excavation increment)
The rollers at 24 a change the wall displacement by about 1 % (the Lame solution of a ring with a
held outer face), the stress by less.

Lined tunnel: the same slab with a 0.5 m ring "lining" (28 GPa) inside a = 5 m, hydrostatic p,
relaxation lambda before the lining joins: the lining carries p_s = (1-lambda) p / (1 + 2 G_r C_l),
C_l = (1+nu_l)((1-2nu_l) b^2 + a_i^2) / (E_l (b^2 - a_i^2)) (rock and thick ring in plane strain,
compatible at b), hoop stress -p_s b^2/(b^2 - a_i^2) (1 + a_i^2/r^2).
"""
import json
import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import observed_orders
from pyfem import solver, static
from stage_state import solved
from pyfem.scene import SceneError, parse_scene

RADIUS = 5.0
SECTION = 240.0
THICKNESS = 2.0
CENTRE = np.array([SECTION / 2, THICKNESS / 2, SECTION / 2])
P = 10.0e6
K = 0.5
ROCK = {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}
LINING = {"E": 28.0e9, "nu": 0.167, "rho": 2500.0}
LINING_THICKNESS = 0.5
STRESS_TOLERANCE = 0.03        # the 3 %
DISPLACEMENT_TOLERANCE = 0.05  # the 5 %
RATIO_TOLERANCE = 0.02         # the 2 %
REST_VELOCITY = 1.0e-6         # m/s


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    """The filled tunnel and the lined one, meshed by the script in its own process (as
    tests/test_cavity.py: no gmsh option of another test leaks in)."""
    folder = tmp_path_factory.mktemp("static_meshes")
    paths = {"filled": folder / "filled.msh", "lined": folder / "lined.msh"}
    common = [sys.executable, "meshes/tunnel_in_box.py", "--radius", str(RADIUS), "--size", str(SECTION)]
    subprocess.run(common[:2] + [str(paths["filled"])] + common[2:] + ["--filled"], check=True, timeout=300)
    subprocess.run(common[:2] + [str(paths["lined"])] + common[2:] + ["--lining", str(LINING_THICKNESS)],
                   check=True, timeout=300)
    return paths


def tunnel_scene(mesh_file, order=1, static=None, stress=None, lined=False, duration=0.01, **extra):
    materials = {"rock": dict(ROCK)}
    if lined:
        materials["lining"] = dict(LINING)
    return parse_scene({
        "title": "static stage",
        "mesh": {"builder": "file", "file": str(mesh_file), "order": order},
        "materials": materials,
        "time": {"duration": duration},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "initial_stress": {"stress": stress or [-K * P, -0.5 * P, -P, 0.0, 0.0, 0.0]},
        "static": static or {"excavate": ["excavation"], "relaxation": 0.0},
        "output": {"xdmf_interval": 0.0},
        **extra,
    })


def polar(vector_or_tensor, theta):
    """(rr, tt) of a stress tensor (3, 3) or (r, t) of a displacement (3,) in the x-z plane."""
    c, s = math.cos(theta), math.sin(theta)
    value = np.asarray(vector_or_tensor)
    if value.ndim == 1:
        return value[0] * c + value[2] * s, -value[0] * s + value[2] * c
    rr = value[0, 0] * c * c + value[2, 2] * s * s + 2 * value[0, 2] * s * c
    tt = value[0, 0] * s * s + value[2, 2] * c * c - 2 * value[0, 2] * s * c
    return rr, tt


def kirsch_stress(r_over_a, theta):
    """(sigma_rr, sigma_tt) in the code's sign (compression negative) (Pa)."""
    q2, q4, c2 = r_over_a ** -2, r_over_a ** -4, math.cos(2 * theta)
    rr = 0.5 * P * ((1 + K) * (1 - q2) - (1 - K) * (1 - 4 * q2 + 3 * q4) * c2)
    tt = 0.5 * P * ((1 + K) * (1 + q2) + (1 - K) * (1 + 3 * q4) * c2)
    return -rr, -tt


def kirsch_radial_displacement(r_over_a, theta):
    G, nu = ROCK["E"] / (2 * (1 + ROCK["nu"])), ROCK["nu"]
    return -(P * RADIUS / (4 * G * r_over_a)) * ((1 + K) - (1 - K) * (4 * (1 - nu) - r_over_a ** -2)
                                                  * math.cos(2 * theta))


def centroids(model):
    n_basis = model.V.element.basix_element.dim
    n_vertices = 4 if model.mesh.topology.cell_type.name == "tetrahedron" else 8  # the first nodes of a cell
    nodes = model.V.dofmap.list.array.reshape(-1, n_basis)[:, :n_vertices]
    return model.node_coords[nodes].mean(axis=1)


def in_plane(points):
    """(r / a, theta) of points about the tunnel axis."""
    x = np.asarray(points) - CENTRE
    return np.hypot(x[..., 0], x[..., 2]) / RADIUS, np.arctan2(x[..., 2], x[..., 0])


TARGETS = {"sidewall": 0.0, "crown": 90.0}


def test_initial_stress_order_is_the_scenes():
    """[sxx, syy, szz, syz, sxz, sxy] in the scene, [xx, yy, zz, xy, yz, xz] in the kernel: each
    component lands where its name says."""
    from pyfem.elements import quadrature_initial_stress
    from pyfem.initial_stress import stress_field_from_scene, stress_tensor

    given = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]  # sxx syy szz syz sxz sxy
    tensor = stress_tensor(given)
    assert tensor.tolist() == [[1.0, 6.0, 5.0], [6.0, 2.0, 4.0], [5.0, 4.0, 3.0]]
    scene = {"initial_stress": {"stress": given, "surface": None, "rho": None, "k": [1.0, 1.0, 1.0]}}
    field = stress_field_from_scene(scene)
    assert np.array_equal(field(np.zeros((2, 3))), np.repeat(tensor[None], 2, axis=0))
    voigt = quadrature_initial_stress(np.zeros((1, 1, 3)), field)
    assert voigt.reshape(6).tolist() == [1.0, 2.0, 3.0, 6.0, 4.0, 5.0]  # xx yy zz xy yz xz


@pytest.mark.parametrize("order", [1, 2])
def test_kirsch_excavation(meshes, order):
    """Excavation of the filled tunnel: hoop and radial stress at the cell centroids nearest
    r = 1.05 a and 2 a (crown and sidewall) and the displacement of the wall and 2 a nodes against
    Kirsch's solution. sigma_rr at the wall, where it vanishes, is compared with p."""
    state = solved(tunnel_scene(meshes["filled"], order))
    model = state.model
    assert "excavation" not in model.regions and "tunnel_wall" in model.free_surfaces
    tolerance = static.stage_tolerance(state.scene)  # Q1: MUMPS; Q2 (51 698 unknowns): CG + GAMG
    assert state.stages[1]["residual"] < tolerance and state.report["out_of_balance"] < tolerance
    cell_points = centroids(model)
    checks = 0
    for where, degrees in TARGETS.items():
        for r_target in (1.05, 2.0):
            theta = math.radians(degrees)
            target = CENTRE + RADIUS * r_target * np.array([math.cos(theta), 0.0, math.sin(theta)])
            cell = int(np.argmin(np.linalg.norm((cell_points - target)[:, [0, 2]], axis=1)))
            r, angle = in_plane(cell_points[cell])
            rr, tt = polar(state.cell_stress[cell], angle)
            rr_exact, tt_exact = kirsch_stress(r, angle)
            hoop_error = abs(tt - tt_exact) / abs(tt_exact)
            radial_error = abs(rr - rr_exact) / (P if r_target < 1.5 else abs(rr_exact))
            print(f"Q{order} {where} r = {r:.3f} a: hoop {tt / 1e6:.3f} MPa vs {tt_exact / 1e6:.3f} "
                  f"({hoop_error:.2%}), radial {rr / 1e6:.3f} vs {rr_exact / 1e6:.3f} ({radial_error:.2%})")
            assert hoop_error < STRESS_TOLERANCE and radial_error < STRESS_TOLERANCE, (where, r_target)
            checks += 1
    # Displacements of the excavation increment at the nodes nearest the wall and 2 a.
    r_node, theta_node = in_plane(model.node_coords)
    u = state.displacement.reshape(-1, 3)
    for r_target in (1.0, 2.0):
        radial = {}
        for where, degrees in TARGETS.items():
            distance = np.abs(r_node - r_target) + np.abs(theta_node - math.radians(degrees)) * r_target
            node = int(np.argmin(distance))
            radial[where] = (polar(u[node], theta_node[node])[0],
                             kirsch_radial_displacement(r_node[node], theta_node[node]))
        scale = abs(radial["crown"][1])
        for where, (value, exact) in radial.items():
            # At 2 a the sidewall's u_r nearly cancels (4 % of the crown's): measured against the crown's.
            reference = abs(exact) if abs(exact) > 0.1 * scale else scale
            error = abs(value - exact) / reference
            print(f"Q{order} {where} r = {r_target:g} a: u_r {value * 1e3:.4f} mm vs {exact * 1e3:.4f} "
                  f"({error:.2%})")
            assert error < DISPLACEMENT_TOLERANCE, (where, r_target)
            checks += 1
    assert checks == 8


# Kirsch's order in h: the filled tunnel in a slab of 480 m (rollers 48 a out: on the 240 m slab their
# floor, 0.5 % of the wall's displacement, hides the order), the wall's and the far size scaled together
# (h_wall, h_far) = (1.2, 16), (0.6, 8) m (default tier), and (0.3, 4) m (slow tier). Two errors: the
# wall nodes' u_r (relative L2 over the wall) and the polar stress (hoop and radial) at the centroids of
# the cells within a < r < 2 a (relative L2, of the hoop stress). Measured (Q1): u_r 2.96 / 0.99 / 0.33 %,
# orders 1.58 and 1.57; stress 1.74 / 0.67 / 0.34 %, orders 1.37 and 0.98 (the centroid stress of
# graded, curved Q1 cells is first order; the coarsest mesh is not yet asymptotic).
KIRSCH_ORDER_SECTION = 480.0
KIRSCH_ORDER_MESHES = ((1.2, 16.0), (0.6, 8.0), (0.3, 4.0))


def kirsch_order_mesh(folder, h_wall, h_far):
    """The filled tunnel on the 480 m slab, meshed once per folder (Salencon's order uses it too)."""
    path = folder / f"filled_{h_wall:g}.msh"
    if not path.exists():
        subprocess.run([sys.executable, "meshes/tunnel_in_box.py", str(path), "--radius", str(RADIUS), "--size",
                        str(KIRSCH_ORDER_SECTION), "--filled", "--h-wall", str(h_wall), "--h-far", str(h_far)],
                       check=True, timeout=300)
    return path


def kirsch_order_errors(folder, h_wall, h_far, young=ROCK["E"]):
    """(wall u_r error, stress error) of the filled tunnel excavated on the 480 m slab (relative L2)."""
    scene = tunnel_scene(kirsch_order_mesh(folder, h_wall, h_far))
    scene["materials"]["rock"]["E"] = young
    state = solved(scene)
    model = state.model
    centre = np.array([KIRSCH_ORDER_SECTION / 2, THICKNESS / 2, KIRSCH_ORDER_SECTION / 2])

    def polar_of(points):
        x = np.asarray(points) - centre
        return np.hypot(x[..., 0], x[..., 2]) / RADIUS, np.arctan2(x[..., 2], x[..., 0])

    r, theta = polar_of(model.node_coords)
    wall = np.flatnonzero(np.abs(r - 1.0) < 1e-6)
    u = state.displacement.reshape(-1, 3)[wall]
    u_r = u[:, 0] * np.cos(theta[wall]) + u[:, 2] * np.sin(theta[wall])
    exact_u = np.array([kirsch_radial_displacement(1.0, angle) for angle in theta[wall]])
    r, theta = polar_of(centroids(model))
    cells = np.flatnonzero(r < 2.0)
    found = np.array([polar(state.cell_stress[c], theta[c]) for c in cells])
    exact = np.array([kirsch_stress(r[c], theta[c]) for c in cells])
    assert len(wall) > 50 and len(cells) > 100
    return (np.linalg.norm(u_r - exact_u) / np.linalg.norm(exact_u),
            np.linalg.norm(found - exact) / np.linalg.norm(exact[:, 1]))


@pytest.fixture(scope="module")
def kirsch_order_folder(tmp_path_factory):
    return tmp_path_factory.mktemp("kirsch_order")


def test_kirsch_excavation_converges_in_h(kirsch_order_folder):
    """The excavated tunnel's order in h on two meshes (KIRSCH_ORDER_MESHES): the wall's u_r at order
    1.58 (bounds 1.3-1.9), the stress at 1.37 (1.1-1.65), the finer mesh's errors within about twice the
    measured (0.99 % and 0.67 %). Catches a stiffness 1 % off (u_r's error stalls at 1 %: the order
    collapses) or a load that does not converge to the excavation's."""
    meshes_used = KIRSCH_ORDER_MESHES[:2]
    errors = np.array([kirsch_order_errors(kirsch_order_folder, *mesh) for mesh in meshes_used])
    hs = [h_wall for h_wall, _ in meshes_used]
    u_order, stress_order = observed_orders(hs, errors[:, 0])[0], observed_orders(hs, errors[:, 1])[0]
    print(f"Kirsch Q1: wall u_r errors {errors[:, 0]}, order {u_order:.3f}; stress errors {errors[:, 1]}, "
          f"order {stress_order:.3f}")
    assert 1.3 < u_order < 1.9 and 1.1 < stress_order < 1.65
    assert errors[1, 0] < 0.02 and errors[1, 1] < 0.0135


@pytest.mark.slow
def test_kirsch_excavation_converges_in_h_on_three_meshes(kirsch_order_folder):
    """The same on three meshes: the second order of u_r (measured 1.57, bounds 1.3-1.9) and of the
    stress (0.98, bounds 0.75-1.25), the finest mesh's errors within about twice the measured (0.33 %,
    0.34 %). Catches an error that stalls below the default tier's resolution."""
    errors = np.array([kirsch_order_errors(kirsch_order_folder, *mesh) for mesh in KIRSCH_ORDER_MESHES])
    hs = [h_wall for h_wall, _ in KIRSCH_ORDER_MESHES]
    u_orders, stress_orders = observed_orders(hs, errors[:, 0]), observed_orders(hs, errors[:, 1])
    print(f"Kirsch Q1: wall u_r errors {errors[:, 0]}, orders {u_orders}; stress errors {errors[:, 1]}, "
          f"orders {stress_orders}")
    assert 1.3 < u_orders[1] < 1.9 and 0.75 < stress_orders[1] < 1.25
    assert errors[2, 0] < 0.0066 and errors[2, 1] < 0.0068


def test_iterative_solver_gives_the_direct_solution(meshes):
    """CG + GAMG (to tolerance 1e-9) and MUMPS give the same stage."""
    static = {"excavate": ["excavation"], "relaxation": 0.3}
    direct = solved(tunnel_scene(meshes["filled"], static=dict(static, solver="direct")))
    iterative = solved(tunnel_scene(meshes["filled"], static=dict(static, solver="iterative", tolerance=1e-9)))
    assert direct.stages[0]["solver"].startswith("direct") and iterative.stages[0]["solver"].startswith("iterative")
    assert iterative.stages[0]["iterations"] > 1 and iterative.stages[0]["residual"] < 1e-9
    difference = (np.max(np.abs(iterative.displacement - direct.displacement))
                  / np.max(np.abs(direct.displacement)))
    print(f"CG + GAMG in {iterative.stages[0]['iterations']} + {iterative.stages[1]['iterations']} iterations; "
          f"differs from MUMPS by {difference:.1e}")
    assert difference < 1e-6


def test_hand_over_keeps_the_model_at_rest(meshes, tmp_path):
    """After the stage (relaxation 0.4, viscoelastic x and z faces in the dynamic run), a run with no
    wave stays at rest; the t = 0 row of the monitors is the stage's stress; static/ and run.json
    report the stages. With the stage's support forces let go (the control: their opposite added, the
    held part of K u - f_exc, whose face sums are static.json's), the model moves."""
    from pyfem.static import hand_over_force_provider

    monitors = [{"name": "crown", "point": list(CENTRE + [0.0, 0.0, 1.05 * RADIUS])},
                {"name": "sidewall", "point": list(CENTRE + [1.05 * RADIUS, 0.0, 0.0])}]
    scene = tunnel_scene(meshes["filled"], static={"excavate": ["excavation"], "relaxation": 0.4},
                         duration=0.3, monitor=monitors)
    summary = solver.run(scene, tmp_path / "run")
    assert [stage["name"] for stage in summary["static"]["stages"]] == ["excavation", "support"]
    report = json.loads((tmp_path / "run" / "static" / "static.json").read_text())
    assert (tmp_path / "run" / "static" / "fields.xdmf").exists()
    assert report["stages"][0]["load_fraction"] == pytest.approx(0.4)
    static_max = report["max_displacement"]["value"]
    assert static_max > 1e-3
    for name in ("crown", "sidewall"):
        rows = np.loadtxt(tmp_path / "run" / "monitors" / f"{name}.csv", delimiter=",", skiprows=1)
        header = (tmp_path / "run" / "monitors" / f"{name}.csv").read_text().splitlines()[0].split(",")
        stress = rows[0, [header.index(k) for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")]]
        expected = report["monitors"][name]["stress"]
        assert np.allclose(stress, [expected[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")],
                           rtol=1e-9, atol=1e-3)
        assert summary["monitors"][name]["velocity"] < REST_VELOCITY
    # The whole field, and the control: the one model built in this process, stepped as the run steps it.
    from pyfem.distributed_model import model_in_memory

    rock_mass = ROCK["rho"] * THICKNESS * (SECTION ** 2 - math.pi * RADIUS ** 2)
    peaks = {}
    for control in (False, True):
        model = model_in_memory(scene)  # (a stepper takes the stage's state: one model per stepping)
        part = model.part
        assert np.sum(part.mass[:part.n_owned]) == pytest.approx(rock_mass, rel=1e-3), "no excavated cell is left"
        stepper, _ = model.stepper()
        if control:
            stepper.add_provider(hand_over_force_provider(-stage_support_force(model, report)))
        n = 3 * part.n_local
        u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        peak_v = peak_u = 0.0
        t = 0.0
        for _ in range(30):
            t = stepper.run(u, v, a, model.time_step.steps_per_output, t)
            peak_v, peak_u = max(peak_v, np.max(np.abs(v))), max(peak_u, np.max(np.abs(u)))
        peaks[control] = (peak_v, peak_u)
    print(f"at rest: peak |v| {peaks[False][0]:.2e} m/s, |u| {peaks[False][1]:.2e} m "
          f"(stage {static_max:.3e} m); without the support forces: |v| {peaks[True][0]:.2e} m/s")
    assert peaks[False][0] < REST_VELOCITY and peaks[False][1] < 1e-6 * static_max
    assert peaks[True][0] > 1e3 * REST_VELOCITY, "the control moves: the held support forces matter"


def stage_support_force(model, report):
    """(3 n,) the stage's support forces on its held faces (kernel numbering, N): the held part of
    K (u1 + u2) - f_exc, K every remaining cell's elastic stiffness (the stage installs nothing), as
    pyfem/distributed_linear.py finds them; checked against static.json's face resultants."""
    from pyfem.distributed_stage import kernel_nodal, owned_force, owned_rows, stage_matrix
    from pyfem.static import _stage_constraints, stage_boundary, stage_loads

    part, stage = model.part, model.stage
    assert not stage.installed_regions
    K = owned_rows(part, stage_matrix(part, np.zeros(0, dtype=np.int32)))
    f_exc = owned_force(part, kernel_nodal(part, stage_loads(part.scene, part.model, np.zeros(0, np.int32)).excavation))
    residual = (K @ stage.u_total - f_exc[:3 * part.n_owned]).reshape(-1, 3)
    _, _, constraints = _stage_constraints(part.model, stage_boundary(part.scene, part.model))
    held = np.zeros_like(residual)
    nodes = np.asarray(constraints.nodes, dtype=np.int64)
    held[nodes] = residual[nodes] - np.einsum("nab,nb->na", constraints.projection, residual[nodes])
    for face in part.model.faces:
        if face.name in report["support_forces"]:
            assert np.allclose(held[face.nodes].sum(axis=0), report["support_forces"][face.name], rtol=1e-6,
                               atol=1e-6 * np.abs(held).sum()), face.name
    assert np.abs(held).max() > 0.0
    return held.reshape(-1)


def test_check_prints_the_stages(meshes):
    static = {"excavate": ["excavation"], "install": ["lining"], "relaxation": 0.4}
    plan = solver.plan(tunnel_scene(meshes["lined"], lined=True, static=static))
    stages = plan["static stage"]
    assert "excavation removed" in stages["stage 1 (excavation)"] and "0.4" in stages["stage 1 (excavation)"]
    assert "lining installed stress-free" in stages["stage 2 (support)"]
    assert "roller" in stages["boundary"]


def test_lining_stress_follows_relaxation(meshes):
    """The lining joins after lambda of the excavation load is released: its hoop stress is
    (1 - lambda) times the lined-tunnel closed form (hydrostatic p), for two lambdas."""
    from pyfem.elements import region_cells

    b, a_i = RADIUS, RADIUS - LINING_THICKNESS
    G_r = ROCK["E"] / (2 * (1 + ROCK["nu"]))
    nu_l = LINING["nu"]
    C_l = (1 + nu_l) * ((1 - 2 * nu_l) * b * b + a_i * a_i) / (LINING["E"] * (b * b - a_i * a_i))
    means = {}
    for relaxation in (0.3, 0.7):
        state = solved(tunnel_scene(
            meshes["lined"], lined=True, stress=[-P, -P, -P, 0.0, 0.0, 0.0],
            static={"excavate": ["excavation"], "install": ["lining"], "relaxation": relaxation}))
        model = state.model
        cells = region_cells(model, "lining")
        r, theta = in_plane(centroids(model)[cells])
        hoop = np.array([polar(sigma, angle)[1] for sigma, angle in zip(state.cell_stress[cells], theta)])
        support_pressure = (1 - relaxation) * P / (1 + 2 * G_r * C_l)
        exact = -support_pressure * b * b / (b * b - a_i * a_i) * (1 + (a_i / (RADIUS * r)) ** 2)
        error = abs(hoop.mean() / exact.mean() - 1)
        print(f"lambda {relaxation}: lining hoop stress {hoop.mean() / 1e6:.3f} MPa vs "
              f"{exact.mean() / 1e6:.3f} ({error:.2%}); after stage 1: "
              f"{np.abs(state.cell_stress_first[cells]).max():g} Pa")
        assert error < STRESS_TOLERANCE
        assert np.abs(state.cell_stress_first[cells]).max() == 0.0
        means[relaxation] = hoop.mean()
    ratio = means[0.3] / means[0.7]
    print(f"hoop stress ratio {ratio:.6f}, (1 - 0.3)/(1 - 0.7) = {0.7 / 0.3:.6f}")
    assert abs(ratio / (0.7 / 0.3) - 1) < RATIO_TOLERANCE


def test_lining_bends_as_the_closed_form_under_a_biaxial_far_field(meshes):
    """K = 0.5 and lambda = 0.5: the lining both shortens and bends (its hoop stress varies around the
    ring by more than 3x). Every lining cell's hoop stress at its centroid against the lined tunnel's
    closed form there (pyfem/analytic/lined_tunnel.py, docs/lined_tunnel.md): measured 0.72 % of the peak with
    two Q1 elements through the 0.5 m lining, the truncation's floor (workflows/lining_stress_accuracy.py)."""
    from pyfem.elements import region_cells
    from pyfem.analytic.lined_tunnel import LinedTunnel

    relaxation = 0.5
    state = solved(tunnel_scene(
        meshes["lined"], lined=True,
        static={"excavate": ["excavation"], "install": ["lining"], "relaxation": relaxation}))
    model = state.model
    cells = region_cells(model, "lining")
    r, theta = in_plane(centroids(model)[cells])
    hoop = np.array([polar(sigma, angle)[1] for sigma, angle in zip(state.cell_stress[cells], theta)])
    closed_form = LinedTunnel(RADIUS, LINING_THICKNESS, LINING["E"], LINING["nu"], ROCK["E"], ROCK["nu"])
    exact = closed_form.hoop_stress(RADIUS * r, theta, (-K * P, -P, 0.0), relaxation)
    error = np.abs(hoop - exact).max() / np.abs(exact).max()
    print(f"lining hoop stress {hoop.min() / 1e6:.2f} to {hoop.max() / 1e6:.2f} MPa (closed form "
          f"{exact.min() / 1e6:.2f} to {exact.max() / 1e6:.2f}); largest error {error:.2%} of the peak")
    assert len(cells) > 100 and hoop.min() < 3 * hoop.max() < 0.0  # loaded, and bending
    assert error < 0.015


# The lined tunnel's order in h (K = 0.5, lambda = 0.5, as above) on the 480 m slab (on the 240 m slab the
# rollers' floor, 0.7 % of the lining's stress, hides it: docs/lined_tunnel.md), (h_wall, h_far) = (0.25,
# 16) and (0.125, 8) m: two and four Q1 elements through the lining. The polar stress (rr, tt, rt) at the
# centroids of the lining's cells and of the rock's within b < r < 2 b against the closed form (relative
# L2, of the hoop stress). Measured: lining 0.955 / 0.314 %, order 1.60; rock 0.716 / 0.256 %, order 1.48;
# with eight elements through (0.0625, 4; slow tier) 0.139 % and 0.123 %, orders 1.18 and 1.06.
LINED_ORDER_MESHES = ((0.25, 16.0), (0.125, 8.0), (0.0625, 4.0))


def lined_order_errors(folder, h_wall, h_far):
    """(lining error, rock error) of the lined tunnel on the 480 m slab, relative L2 of the polar stress."""
    from pyfem.elements import region_cells
    from pyfem.analytic.lined_tunnel import LinedTunnel

    path = folder / f"lined_{h_wall:g}.msh"
    if not path.exists():
        subprocess.run([sys.executable, "meshes/tunnel_in_box.py", str(path), "--radius", str(RADIUS), "--size",
                        str(KIRSCH_ORDER_SECTION), "--lining", str(LINING_THICKNESS), "--h-wall", str(h_wall),
                        "--h-far", str(h_far)], check=True, timeout=300)
    relaxation = 0.5
    simulation = solved(tunnel_scene(path, lined=True, static={"excavate": ["excavation"],
                                                               "install": ["lining"], "relaxation": relaxation}))
    model = simulation.model
    x = centroids(model) - np.array([KIRSCH_ORDER_SECTION / 2, THICKNESS / 2, KIRSCH_ORDER_SECTION / 2])
    r, theta = np.hypot(x[:, 0], x[:, 2]), np.arctan2(x[:, 2], x[:, 0])
    closed_form = LinedTunnel(RADIUS, LINING_THICKNESS, LINING["E"], LINING["nu"], ROCK["E"], ROCK["nu"])
    errors = []
    for cells in (region_cells(model, "lining"), np.flatnonzero((r >= RADIUS) & (r < 2 * RADIUS))):
        exact = closed_form.stresses(r[cells], theta[cells], (-K * P, -P, 0.0), relaxation)
        exact = np.column_stack([exact["rr"], exact["tt"], exact["rt"]])
        c, s = np.cos(theta[cells])[:, None], np.sin(theta[cells])[:, None]
        sigma = simulation.cell_stress[cells]
        sxx, szz, sxz = sigma[:, 0, 0][:, None], sigma[:, 2, 2][:, None], sigma[:, 0, 2][:, None]
        found = np.column_stack([sxx * c * c + szz * s * s + 2 * sxz * s * c, sxx * s * s + szz * c * c - 2 * sxz * s * c,
                                 (szz - sxx) * s * c + sxz * (c * c - s * s)])
        assert len(cells) > 100 and np.abs(exact[:, 1]).max() > 1e6  # loaded
        errors.append(np.linalg.norm(found - exact) / np.linalg.norm(exact[:, 1]))
    return errors


def test_lined_tunnel_converges_in_h(kirsch_order_folder):
    """Two and four elements through the lining (LINED_ORDER_MESHES): the lining's stress at order 1.60
    (bounds 1.3-1.9), the rock's at 1.48 (1.2-1.8), the finer mesh's errors within about twice the
    measured (0.314 %, 0.256 %). Catches a lining stiffness or an installation share that does not
    converge to the closed form (a lining 1 % stiffer stalls its stress error near its share of 1 %)."""
    meshes_used = LINED_ORDER_MESHES[:2]
    errors = np.array([lined_order_errors(kirsch_order_folder, *mesh) for mesh in meshes_used])
    hs = [h_wall for h_wall, _ in meshes_used]
    lining_order, rock_order = observed_orders(hs, errors[:, 0])[0], observed_orders(hs, errors[:, 1])[0]
    print(f"lined tunnel Q1: lining errors {errors[:, 0]}, order {lining_order:.3f}; rock errors {errors[:, 1]}, "
          f"order {rock_order:.3f}")
    assert 1.3 < lining_order < 1.9 and 1.2 < rock_order < 1.8
    assert errors[1, 0] < 0.0063 and errors[1, 1] < 0.0052


@pytest.mark.slow
def test_lined_tunnel_converges_in_h_on_three_meshes(kirsch_order_folder):
    """The same with eight elements through the lining (0.0625, 4): measured lining 0.955 / 0.314 /
    0.139 %, second order 1.18 (bounds 0.9-1.45); rock 0.716 / 0.256 / 0.123 %, 1.06 (0.8-1.3); the
    finest errors within about twice the measured. Catches an error that stalls below the default
    tier's resolution."""
    errors = np.array([lined_order_errors(kirsch_order_folder, *mesh) for mesh in LINED_ORDER_MESHES])
    hs = [h_wall for h_wall, _ in LINED_ORDER_MESHES]
    lining_orders, rock_orders = observed_orders(hs, errors[:, 0]), observed_orders(hs, errors[:, 1])
    print(f"lined tunnel Q1: lining errors {errors[:, 0]}, orders {lining_orders}; rock errors {errors[:, 1]}, "
          f"orders {rock_orders}")
    assert 0.9 < lining_orders[1] < 1.45 and 0.8 < rock_orders[1] < 1.3
    assert errors[2, 0] < 0.0028 and errors[2, 1] < 0.0025


def layered_box(order=1, **static):
    return parse_scene({
        "mesh": {"size": [4.0, 4.0, 6.0], "h": 1.0, "order": order,
                 "layers": [{"material": "hard", "thickness": 3.0}, {"material": "soft", "thickness": 3.0}]},
        "materials": {"hard": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0},
                      "soft": {"E": 2.0e9, "nu": 0.3, "rho": 2400.0}},
        "time": {"duration": 0.01},
        "initial_stress": {"stress": [-3.0e6, -4.0e6, -5.0e6, 0.5e6, 0.7e6, 0.9e6]},
        "contact": {"interfaces": ["interface_1"], "cohesion": 1.0e6, "friction_angle": 30.0},
        "static": static,
    })


def test_equilibrated_stress_moves_nothing_and_gives_the_pair_forces():
    """A uniform stress with shear, nothing excavated, a bonded contact interface: the body is in
    equilibrium (u = 0 to round-off) and the pairs' static forces are A sigma0 n."""
    from pyfem.initial_stress import pair_static_forces, stress_field_from_scene

    scene = layered_box()
    state = solved(scene)
    pairs = state.part.pairs  # (the pairs the kernel steps, in the order of the model's F0)
    expected = pair_static_forces(pairs.coords, pairs.area, pairs.normal, stress_field_from_scene(scene))
    scale = 5.0e6 * 6.0 / 2.0e9
    assert len(expected) > 0 and np.max(np.abs(expected)) > 0.0
    assert np.max(np.abs(state.displacement)) < 1e-12 * scale
    assert np.max(np.abs(state.stage.pair_forces - expected)) < 1e-10 * np.max(np.abs(expected))
    assert np.array_equal(state.pair_forces, state.stage.pair_forces), "the hand-over makes them the run's F0"


@pytest.mark.parametrize("order", [1, 2])
def test_gravity_column_settles_as_the_closed_form(order):
    """gravity = true, no initial stress, side rollers, a free top: u_z = rho g / M (z^2/2 - H z),
    M = lambda + 2 G, nodally exact; the floor carries the weight. The geostatic field in
    equilibrium with the same weight moves nothing (gravity false or true)."""
    from pyfem.initial_stress import STANDARD_GRAVITY
    from pyfem.operators import lame_parameters

    height, rho = 20.0, ROCK["rho"]
    box = {"mesh": {"size": [2.0, 2.0, height], "h": 1.0, "order": order}, "materials": {"rock": dict(ROCK)},
           "time": {"duration": 0.01}}
    scene = parse_scene(dict(box, static={"gravity": True, "boundary": {"face": {"zmax": {"type": "free"}}}}))
    simulation = solved(scene)
    lame_lambda, G = lame_parameters(ROCK["E"], ROCK["nu"])
    z = simulation.model.node_coords[:, 2]
    exact = rho * STANDARD_GRAVITY / (lame_lambda + 2 * G) * (0.5 * z * z - height * z)
    u = simulation.displacement.reshape(-1, 3)
    assert np.max(np.abs(u[:, 2] - exact)) < 1e-10 * np.max(np.abs(exact))
    weight = rho * STANDARD_GRAVITY * 2.0 * 2.0 * height
    assert simulation.face_support_forces["zmin"][2] == pytest.approx(weight, rel=1e-10)
    for gravity in (False, True):
        initial = {"surface": 100.0 + height, "rho": rho, "k": [1.4, 1.2, 1.0]}
        geostatic = parse_scene(dict(box, initial_stress=initial, static={"gravity": gravity}))
        state = solved(geostatic)
        assert np.max(np.abs(state.displacement)) < 1e-12 * np.max(np.abs(exact))


def test_bad_static_scenes(meshes):
    from pyfem.operators import build_model
    from pyfem.static import check_linear

    with pytest.raises(SceneError, match="static.excavate.0"):
        build_model(tunnel_scene(meshes["filled"], static={"excavate": ["nowhere"]}))
    with pytest.raises(SceneError, match="static.install.0"):
        solved(tunnel_scene(meshes["filled"], static={"excavate": ["excavation"],
                                                               "install": ["nowhere"]}))
    wall_fixed = {"excavate": ["excavation"], "boundary": {"face": {"tunnel_wall": {"type": "fixed"}}}}
    with pytest.raises(SceneError, match="static.boundary.face.tunnel_wall"):
        solved(tunnel_scene(meshes["filled"], static=wall_fixed))
    with pytest.raises(SceneError, match='static.solver = "direct" solves linear elastic stages only'):
        check_linear({"materials": {"rock": {"E": 8e9, "plasticity": {"cohesion": 1e6}}},
                      "static": {"solver": "direct"}})
    check_linear({"materials": {"rock": {"E": 8e9, "plasticity": {"cohesion": 1e6}}}, "static": {"solver": "auto"}})
    with pytest.raises(SceneError, match="needs a load"):
        parse_scene({"mesh": {"size": [2.0, 2.0, 2.0], "h": 1.0}, "materials": {"rock": dict(ROCK)},
                     "time": {"duration": 0.01}, "static": {}})
    with pytest.raises(SceneError, match="hold more faces"):
        solved(tunnel_scene(meshes["filled"], static={"excavate": ["excavation"],
                                                               "boundary": {"type": "free"}}))


def test_pairs_over_strength_counts_opening_and_sliding_pairs():
    """The hand-over's check of the stage's pair forces against the interface strength (D = 1):
    a pair in tension beyond t_s A opens, one whose shear exceeds mu_s N + c A slides."""
    from pyfem.static import pairs_over_strength

    normal = np.tile([0.0, 0.0, 1.0], (4, 1))
    area = np.full(4, 2.0)                       # m^2: c A = 2e6 N, t_s A = 2e6 N
    force = np.array([[0.0, 0.0, -1.0e6],        # compression 1e6 N (N = -n.F0), no shear: bonded
                      [0.0, 0.0, 3.0e6],         # tension 3e6 N > t_s A: opens
                      [2.6e6, 0.0, -1.0e6],      # shear 2.6e6 > 0.5 x 1e6 + 2e6: slides
                      [2.4e6, 0.0, -1.0e6]])     # shear 2.4e6 < 2.5e6: holds
    counts = pairs_over_strength({"static_force": force, "normal": normal, "area": area, "cohesion": 1.0e6,
                                  "tensile_strength": 1.0e6, "friction_static": 0.5})
    assert counts == {"opening": 1, "sliding": 1}


# The interfaces' distance from the excavation (static/interface_stress.png, static.json): a section
# 16 x 2 x 16 m of 1 m hexahedra, a 4 x 4 m excavation through it (x 6-10 m, z 4-8 m) and a bedding
# plane at z = 12 m, 4 m above the excavation's roof.
EXCAVATION_BOX = ((6.0, 10.0), (4.0, 8.0))  # (x range, z range) (m), through the whole y
BEDDING_Z = 12.0


def write_excavated_section_msh(path):
    """Twelve boxes meshed as 1 m hexahedra: the excavation (x 6-10, z 4-8) among the 8 blocks of
    "lower" below z = 12, "upper" above it, the plane z = 12 between them "interface_1"."""
    from pyfem._gmsh import gmsh
    from pyfem.geometry import gmsh_session

    columns, rows = ((0.0, 6.0), (6.0, 10.0), (10.0, 16.0)), ((0.0, 4.0), (4.0, 8.0), (8.0, 12.0), (12.0, 16.0))
    with gmsh_session("excavated section"):
        blocks = [gmsh.model.occ.addBox(x0, 0.0, z0, x1 - x0, 2.0, z1 - z0) for (x0, x1) in columns
                  for (z0, z1) in rows]
        gmsh.model.occ.fragment([(3, tag) for tag in blocks], [])
        gmsh.model.occ.synchronize()
        for _, tag in gmsh.model.getEntities(1):
            box = gmsh.model.getBoundingBox(1, tag)
            length = max(box[3] - box[0], box[4] - box[1], box[5] - box[2])
            gmsh.model.mesh.setTransfiniteCurve(tag, int(round(length)) + 1)
        for _, tag in gmsh.model.getEntities(2):
            gmsh.model.mesh.setTransfiniteSurface(tag)
            gmsh.model.mesh.setRecombine(2, tag)
        for _, tag in gmsh.model.getEntities(3):
            gmsh.model.mesh.setTransfiniteVolume(tag)
        regions = {"lower": [], "upper": [], "excavation": []}
        for _, tag in gmsh.model.getEntities(3):  # by position: the fragment renumbers
            box = gmsh.model.getBoundingBox(3, tag)
            x, z = 0.5 * (box[0] + box[3]), 0.5 * (box[2] + box[5])
            (ex0, ex1), (ez0, ez1) = EXCAVATION_BOX
            name = ("upper" if z > BEDDING_Z else "excavation" if ex0 < x < ex1 and ez0 < z < ez1 else "lower")
            regions[name].append(tag)
        for name, tags in regions.items():
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, tags), name)
        plane = [tag for _, tag in gmsh.model.getEntities(2)
                 if abs(gmsh.model.getBoundingBox(2, tag)[2] - BEDDING_Z) < 1e-6
                 and abs(gmsh.model.getBoundingBox(2, tag)[5] - BEDDING_Z) < 1e-6]
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, plane), "interface_1")
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


@pytest.mark.parametrize("stage_solver", ["direct", "relaxation"])
def test_interface_distance_from_the_excavation_is_the_hand_computed_one(tmp_path, stage_solver):
    """Every pair of the bedding plane lies at the distance of its point from the excavation's
    4 x 4 m section: hypot(dx, 4 m) with dx its x beyond [6, 10] m (4 to 7.21 m), not at 0 as when the
    surface was taken from where the excavation load acts (the interface's own static forces put every
    pair on it: all 51 pairs at 0 m after the direct solve); the pairs "near the wall" are those within
    near_wall of it."""
    from scipy.spatial import cKDTree

    from pyfem.static_plots import excavation_surface, interface_stress

    path = tmp_path / "section.msh"
    write_excavated_section_msh(path)
    scene = parse_scene({
        "title": "excavated section with a bedding plane",
        "mesh": {"builder": "file", "file": str(path), "order": 1},
        "materials": {"lower": dict(ROCK), "upper": dict(ROCK)},
        "time": {"duration": 0.01},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "initial_stress": {"stress": [-5.0e6, -5.0e6, -5.0e6, 0.0, 0.0, 0.0]},
        "static": {"excavate": ["excavation"], "relaxation": 0.0, "solver": stage_solver},
        "contact": {"interfaces": ["interface_1"], "cohesion": 1.0e6, "friction_angle": 30.0},
        "output": {"xdmf_interval": 0.0},
    })
    from mpi4py import MPI

    from pyfem.operators import build_model

    simulation = state = solved(scene)
    model = build_model(scene, MPI.COMM_SELF)  # (the mesh's faces and pairs in the function space's numbering)
    assert model.n_cells == 16 * 2 * 16 - 4 * 2 * 4
    # (the wall is found from the mesh, pyfem.distributed_view.stage_pictures: any excavation load will do)
    surface = excavation_surface(SimpleNamespace(excavation_load=np.ones(1), installed_cells=np.zeros(0, int)), model)
    (x0, x1), (z0, z1) = EXCAVATION_BOX
    x, z = surface[:, 0], surface[:, 2]
    on_wall = ((np.isclose(x, x0) | np.isclose(x, x1)) & (z >= z0 - 1e-9) & (z <= z1 + 1e-9)) | \
              ((np.isclose(z, z0) | np.isclose(z, z1)) & (x >= x0 - 1e-9) & (x <= x1 + 1e-9))
    assert on_wall.all() and len(surface) == 16 * 3, "the surface is the excavation's wall, its 16 x 3 nodes"
    pairs = model.pairs.coords
    assert len(pairs) == 17 * 3 and np.allclose(pairs[:, 2], BEDDING_Z)
    beyond = np.maximum.reduce([x0 - pairs[:, 0], pairs[:, 0] - x1, np.zeros(len(pairs))])
    by_hand = np.hypot(beyond, BEDDING_Z - z1)
    distance, _ = cKDTree(surface).query(pairs)
    np.testing.assert_allclose(distance, by_hand, rtol=0.0, atol=1e-9)
    arrays, part = simulation.run.contact_arrays, simulation.part
    assert np.allclose(part.pairs.coords, pairs), "one rank: the kernel's pairs are the model's, in its order"
    assert np.abs(simulation.run.in_situ_forces).max() > 0.0 and np.abs(state.pair_forces).max() > 0.0
    figure = interface_stress(tmp_path / "interface_stress.png", pairs, arrays["normal"], arrays["area"],
                              simulation.run.in_situ_forces, state.pair_forces, surface, near_wall=4.2)
    assert figure["pairs"] == 51 and figure["pairs_near_wall"] == int(np.sum(by_hand <= 4.2)) == 3 * 7

"""Tetrahedral meshes from gmsh as they come (issue 14, docs/tetrahedra.md): the `file` builder
reads a user's .geo script, gmsh meshes it to tetrahedra, and the model runs with linear (P1,
row-sum lumped) or quadratic (P2, HRZ-lumped) tetrahedra.

- P2 lumped masses are all positive and sum to the body's mass, where row sums would give every
  vertex a negative mass.
- A box from a .geo under an oblique SV wave (30 deg): the monitors inside follow the free field
  within 2 % (P1) and 0.5 % (P2).
- The tunnel of meshes/tunnel_in_box_tet.geo under a long SV wave: the wall's hoop stress follows
  Kirsch (the cavity check of tests/test_cavity.py; 3.6 % for P1 at 2 a, 5.2 % for P2).
- The static Kirsch excavation on P1 tetrahedra converges in h (the wall's u_r at order 1.45, the
  stress at 0.74, on two meshes; three in the slow tier); on P2 tetrahedra (u_r at 1.08, the stress at
  1.24, on two meshes; the same meshes in a 480 m slab at 1.58 and 1.52 in the slow tier).
- The static stage excavates on tetrahedra: a filled tunnel cut out of a slab follows Kirsch.
- What tetrahedra cannot do yet (one point per cell with hourglass control, contact on quadratic
  tetrahedra) and mixed meshes are refused with one line naming the key.
"""
import math
from pathlib import Path

import numpy as np
import pytest

from conftest import observed_orders
from pyfem import solver
from stage_state import solved
from pyfem.scene import SceneError, parse_scene
from test_cavity import (ANGLES, RADII, free_field_shear, kirsch, monitor_points, polar_stress, read_monitor,
                         tunnel_scene)

REPO = Path(__file__).resolve().parents[1]
TUNNEL_GEO = REPO / "meshes" / "tunnel_in_box_tet.geo"
# The dynamic tunnel against Kirsch (peak and history), about twice the measured with 0.8 m at the wall:
# P1 at 2 a 1.44-1.69 % (peak) and 1.60-1.78 % (history); P2 at both radii up to 2.53 % and 2.56 %
# (10 % before). P1 at 1.05 a is not held: see SCALED_FILLED_TUNNEL_GEO below.
KIRSCH_TOLERANCE = {1: 0.036, 2: 0.052}


def box_geo(folder: Path, h: float) -> Path:
    """A user's gmsh script: a 160 x 20 x 160 m box of rock meshed to tetrahedra of size h (m)."""
    path = folder / f"box_h{h:g}.geo"
    path.write_text('SetFactory("OpenCASCADE");\n'
                    "Box(1) = {0, 0, 0, 160, 20, 160};\n"
                    'Physical Volume("rock") = {1};\n'
                    f"Mesh.MeshSizeMax = {h};\nMesh.MeshSizeMin = {h};\n")
    return path


def box_scene(mesh_file: Path, order: int, **changes) -> "Scene":
    data = {
        "title": "tetrahedra, oblique SV",
        "mesh": {"builder": "file", "file": str(mesh_file), "order": order},
        "materials": {"rock": {"preset": "sandstone"}},
        "time": {"duration": 1.0, "safety": 0.8},
        "wave": {"type": "SV", "angle": 30.0, "surface": 200.0, "medium": "rock",
                 "motion": {"ricker": {"f0": 5.0, "amplitude": 1.0e-3}}},
        "monitor": [{"name": "centre", "point": [80.0, 10.0, 80.0]}, {"name": "upper", "point": [40.0, 10.0, 130.0]},
                    {"name": "lower", "point": [120.0, 10.0, 30.0]}],
        "output": {"interval": 0.005, "xdmf_interval": 0.0},
    }
    data.update(changes)
    return parse_scene(data, source="test")


def test_p2_tetrahedra_masses_are_positive_and_sum_to_the_mass(tmp_path):
    from pyfem.assembly import assemble_nodal_vector, uses_diagonal_scaling
    from pyfem.operators import build_model
    import ufl
    from dolfinx import fem

    model = build_model(box_scene(box_geo(tmp_path, 20.0), order=2))
    assert model.mesh.topology.cell_type.name == "tetrahedron" and uses_diagonal_scaling(model.V)
    from pyfem.plan import element_name

    assert element_name(model, 2) == "P2 tetrahedra"  # what `check` prints for the mesh
    body = 2600.0 * 160.0 * 20.0 * 160.0  # sandstone, kg
    assert np.all(model.mass > 0.0)
    assert model.mass.sum() == pytest.approx(body, rel=1e-12)
    # Row sums, which the scaling replaces, are negative at every vertex of a P2 tetrahedron.
    ones = fem.Constant(model.mesh, np.ones(3))
    row_sums = assemble_nodal_vector(2600.0 * ufl.inner(ones, ufl.TestFunction(model.V)) * ufl.dx, model.V)[:, 0]
    vertices = np.unique(model.V.dofmap.list.array.reshape(-1, 10)[:, :4])
    assert np.all(row_sums[vertices] < 0.0)
    print(f"P2 tetrahedra: {len(model.mass)} nodes, masses {model.mass.min():.4g} .. {model.mass.max():.4g} kg; "
          f"row sums at the vertices {row_sums[vertices].max():.4g} kg (negative)")
    # fields.xdmf writes every node: each P2 cell as 8 linear tetrahedra that tile it.
    from pyfem.output import field_mesh

    nodes, cell_type, cells, parent = field_mesh(model)
    assert cell_type == "tetra" and len(nodes) == len(model.mass) and len(cells) == 8 * model.n_cells
    x = model.node_coords[nodes][cells]
    volume = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6.0
    assert np.all(volume > 0.0) and volume.sum() == pytest.approx(160.0 * 20.0 * 160.0, rel=1e-12)


@pytest.mark.parametrize("order, h, tolerance", [(1, 5.0, 0.02), (2, 7.0, 0.005)])
def test_oblique_sv_on_tetrahedra_from_a_geo_follows_the_free_field(tmp_path, order, h, tolerance):
    summary = solver.run(box_scene(box_geo(tmp_path, h), order), tmp_path / "run")
    assert summary["energy"]["balance_error"] < 1e-10
    checks = 0
    for name, peak in summary["monitors"].items():
        assert peak["displacement"] > 5e-4, f"{name}: the wave arrived (1 mm pulse)"
        print(f"P{order} h = {h:g} m, {name}: differs from the free field by {100 * peak['freefield_error']:.2f} %")
        assert peak["freefield_error"] < tolerance, name
        checks += 1
    assert checks == 3


@pytest.mark.parametrize("order, wall_size", [(1, 0.8), (2, 0.8)])
def test_tunnel_geo_wall_follows_kirsch_on_tetrahedra(tmp_path, order, wall_size):
    """The example .geo, meshed by gmsh when the run starts, with 0.8 m at the wall instead of its
    0.4 m to keep the default tier short. P1 tetrahedra hold one strain per cell: at r = 1.05 a the
    hoop stress is that of the first row of cells, 11 % / 21 % above Kirsch even with the 0.4 m
    cells (measured 2026-11-24; P2 with 0.4 m: 1.0-1.5 %), so P1 is held to Kirsch at r = 2 a and
    P2 at both radii."""
    geo = TUNNEL_GEO.read_text()
    assert "0.4 + 0.12" in geo
    mesh_file = tmp_path / "tunnel.geo"
    mesh_file.write_text(geo.replace("0.4 + 0.12", f"{wall_size:g} + 0.12"))
    scene = tunnel_scene(mesh_file, order)
    scene["time"]["local_stepping"] = False  # global stepping ("auto" steps this graded mesh locally;
    # tests/test_cavity.py runs the tunnel under both)
    out = tmp_path / "run"
    summary = solver.run(scene, out)
    assert "(unnamed)" in summary["traction_free_surfaces"], "the wall is free, not an input face"
    times = read_monitor(out, "r1.05_t45")["t"]
    tau_peak = np.max(np.abs(free_field_shear(scene, times)))
    assert tau_peak > 1e3, "the wave arrived"
    checks = 0
    for name, (r, theta, point) in monitor_points().items():
        columns = read_monitor(out, name)
        stress = np.column_stack([columns[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")])
        _, tt, _ = polar_stress(stress, theta)
        _, k_tt, _ = kirsch(r, theta)
        tau_here = free_field_shear(scene, times, point)
        peak_ratio = np.max(np.abs(tt)) / (abs(k_tt) * tau_peak)
        history_error = np.linalg.norm(tt - k_tt * tau_here) / np.linalg.norm(k_tt * tau_here)
        print(f"P{order} tetrahedra, {wall_size} m at the wall, {name}: hoop peak / Kirsch {peak_ratio:.4f}, "
              f"history error {history_error:.2%}")
        if order == 2 or r >= 2.0:
            # catches a hoop stress off by a few % (a stiffness, a wall that carries traction)
            assert abs(peak_ratio - 1.0) < KIRSCH_TOLERANCE[order] and history_error < KIRSCH_TOLERANCE[order], name
            checks += 1
    assert checks == (len(RADII) * len(ANGLES) if order == 2 else len(ANGLES))


def test_what_tetrahedra_cannot_do_yet_is_refused_by_key(tmp_path):
    from pyfem.operators import build_model

    geo = box_geo(tmp_path, 40.0)
    # Nonlinear materials run on tetrahedra (tests/test_tetrahedra_nonlinear.py); one point per cell
    # with Q1's hourglass control does not.
    plastic = box_scene(geo, 1, materials={"rock": {"preset": "sandstone", "plasticity": {
        "cohesion": 1.0e6, "friction_angle": 30.0, "tensile_strength": 1.0e6, "integration": "reduced"}}})
    with pytest.raises(SceneError, match=r"materials\.rock\.plasticity\.integration.*tetrahedra"):
        build_model(plastic)
    plastic["materials"]["rock"]["plasticity"]["integration"] = "full"
    assert build_model(plastic).mesh.topology.cell_type.name == "tetrahedron"
    mixed = tmp_path / "mixed.geo"
    # Two separate boxes: one meshed to tetrahedra, the other transfinite and recombined to hexahedra.
    mixed.write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 40, 40, 40};\nBox(2) = {100, 0, 0, 40, 40, 40};\n'
                     'Physical Volume("rock") = {1, 2};\nMesh.MeshSizeMax = 20;\n'
                     "Transfinite Curve{13:24} = 3;\nTransfinite Surface{7:12};\nRecombine Surface{7:12};\n"
                     "Transfinite Volume{2};\n")
    with pytest.raises(SceneError, match="mixes"):
        build_model(box_scene(mixed, 1))
    # Contact pairs on quadratic triangles: refused (the consistent load of a uniform traction is 0
    # at their vertices, so node-to-node pairs have no sound static force there).
    from test_tetrahedra_contact import layered_scene, two_layer_geo

    with pytest.raises(SceneError, match=r"contact\.interfaces.*linear tetrahedra"):
        build_model(layered_scene(two_layer_geo(tmp_path, (60.0, 10.0, 60.0), 30.0, 20.0), 2, True, 1e-4))


FILLED_TUNNEL_GEO = """SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, 240, 2, 240};
Cylinder(2) = {120, 0, 120, 0, 2, 0, 5};
BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }
Physical Volume("rock") = {3};
Physical Volume("excavation") = {2};
Field[1] = MathEval;
Field[1].F = "min(16, WALL + 0.12 * abs(sqrt((x - 120)^2 + (z - 120)^2) - 5))";
Background Field = 1;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
"""


@pytest.mark.parametrize("order, wall_size", [(1, 0.4), (2, 0.8)])
def test_kirsch_excavation_on_tetrahedra(tmp_path, order, wall_size):
    """The static stage of tests/test_static.py (a filled circular tunnel, a = 5 m, in a 240 m
    plane-strain slab under p_z = 10 MPa, K = 0.5; the region "excavation" removed) on a user's
    .geo meshed to tetrahedra: hoop and radial stress near 1.05 a and 2 a at the crown and the
    sidewall against Kirsch within the static issue's 3 %: P2 in the nearest cell; P1 (one strain
    per cell: the nearest cell alone is off by up to 11 % at the wall, measured) as the mean over
    the cells within 1 m, compared with Kirsch's mean over the same cells."""
    import test_static as kirsch_static

    geo = tmp_path / "filled_tunnel.geo"
    geo.write_text(FILLED_TUNNEL_GEO.replace("WALL", f"{wall_size:g}"))
    state = solved(kirsch_static.tunnel_scene(geo, order))
    model = state.model
    assert model.mesh.topology.cell_type.name == "tetrahedron"
    assert "excavation" not in model.regions and "(unnamed)" in model.free_surfaces  # the cut wall is free
    assert np.max(np.abs(state.displacement)) > 1e-4  # the opening converged
    n_basis = model.V.element.basix_element.dim
    cell_points = model.node_coords[model.V.dofmap.list.array.reshape(-1, n_basis)[:, :4]].mean(axis=1)
    checks = 0
    for where, degrees in kirsch_static.TARGETS.items():
        for r_target in (1.05, 2.0):
            theta = math.radians(degrees)
            target = kirsch_static.CENTRE + kirsch_static.RADIUS * r_target * np.array(
                [math.cos(theta), 0.0, math.sin(theta)])
            distance = np.linalg.norm((cell_points - target)[:, [0, 2]], axis=1)
            # P2: the nearest cell; P1 (one strain per cell, scattered cell to cell): the mean of the
            # polar components over the cells within 1 m, as a user would read a P1 stress.
            near = [int(np.argmin(distance))] if order == 2 else np.flatnonzero(distance < 1.0)
            values = []
            for cell in near:
                r, angle = kirsch_static.in_plane(cell_points[cell])
                values.append(kirsch_static.polar(state.cell_stress[cell], angle)
                              + kirsch_static.kirsch_stress(r, angle) + (r,))
            rr, tt, rr_exact, tt_exact, r = np.mean(values, axis=0)
            hoop_error = abs(tt - tt_exact) / abs(tt_exact)
            radial_error = abs(rr - rr_exact) / (kirsch_static.P if r_target < 1.5 else abs(rr_exact))
            print(f"P{order} tetrahedra ({len(near)} cells) {where} r = {r:.3f} a: hoop {tt / 1e6:.3f} MPa vs "
                  f"{tt_exact / 1e6:.3f} ({hoop_error:.2%}), radial {rr / 1e6:.3f} vs {rr_exact / 1e6:.3f} "
                  f"({radial_error:.2%})")
            assert hoop_error < kirsch_static.STRESS_TOLERANCE, (where, r_target)
            assert radial_error < kirsch_static.STRESS_TOLERANCE, (where, r_target)
            checks += 1
    assert checks == 4


# ---------------------------------------------------------------- Kirsch's order on tetrahedra
# The filled tunnel of FILLED_TUNNEL_GEO with every size scaled by s (0.8 s m at the wall, growing by
# 0.12 s per metre): s = 2 and 1 in the default tier, 0.5 in the slow tier. Measured (P1): the wall's u_r
# 7.37 / 2.70 / 1.17 % (relative L2 over the wall's nodes), orders 1.45 and 1.21 (the rollers 24 a out
# leave a floor near 0.5 %); the polar stress of the cells within a < r < 2 a 14.3 / 8.5 / 4.4 % (relative
# L2 of the hoop stress; one strain per cell), orders 0.74 and 0.94. The single cell nearest 1.05 a is not
# a converging measure: at the sidewall, the crown and 45 deg it measured 4.9 / 16.1 / 8.6 %, 8.6 / 1.3 /
# 7.5 % and 8.3 / 2.6 / 2.6 % on the three meshes, the cell's centroid sampling a steep gradient at a
# distance from the point that changes from mesh to mesh. That sampling, not a wrong answer, is why
# test_tunnel_geo_wall_follows_kirsch_on_tetrahedra does not hold P1 at r = 1.05 a.
SCALED_FILLED_TUNNEL_GEO = FILLED_TUNNEL_GEO.replace(
    '"min(16, WALL + 0.12 * abs(sqrt((x - 120)^2 + (z - 120)^2) - 5))"',
    '"SCALE * min(16, 0.8 + 0.12 * abs(sqrt((x - 120)^2 + (z - 120)^2) - 5))"')


def kirsch_errors_on_tetrahedra(folder: Path, scale: float, order: int = 1, young: float = None,
                                section: float = 240.0):
    """(wall u_r error, stress error within 2 a) of the filled tunnel on tetrahedra, sizes scaled by `scale`,
    in a slab `section` m wide about the same axis (the rollers section / 2 from it)."""
    import test_static as kirsch_static

    geo = folder / f"filled_tunnel_s{scale:g}_P{order}_{section:g}.geo"
    low = (240.0 - section) / 2
    geo.write_text(SCALED_FILLED_TUNNEL_GEO.replace("SCALE", f"{scale:g}").replace(
        "Box(1) = {0, 0, 0, 240, 2, 240};", f"Box(1) = {{{low:g}, 0, {low:g}, {section:g}, 2, {section:g}}};"))
    scene = kirsch_static.tunnel_scene(geo, order)
    if young is not None:
        scene["materials"]["rock"]["E"] = young
    state = solved(scene)
    model = state.model
    n_basis = model.V.element.basix_element.dim
    points = model.node_coords[model.V.dofmap.list.array.reshape(-1, n_basis)[:, :4]].mean(axis=1)
    r, theta = kirsch_static.in_plane(points)
    cells = np.flatnonzero(r < 2.0)
    found = np.array([kirsch_static.polar(state.cell_stress[c], theta[c]) for c in cells])
    exact = np.array([kirsch_static.kirsch_stress(r[c], theta[c]) for c in cells])
    r, theta = kirsch_static.in_plane(model.node_coords)
    wall = np.flatnonzero(np.abs(r - 1.0) < 1e-6)
    u = state.displacement.reshape(-1, 3)[wall]
    u_r = u[:, 0] * np.cos(theta[wall]) + u[:, 2] * np.sin(theta[wall])
    exact_u = np.array([kirsch_static.kirsch_radial_displacement(1.0, angle) for angle in theta[wall]])
    assert model.mesh.topology.cell_type.name == "tetrahedron" and len(wall) > 50 and len(cells) > 100
    return (np.linalg.norm(u_r - exact_u) / np.linalg.norm(exact_u),
            np.linalg.norm(found - exact) / np.linalg.norm(exact[:, 1]))


def test_kirsch_excavation_on_tetrahedra_converges_in_h(tmp_path):
    """P1 tetrahedra, sizes scaled by 2 and 1: the wall's u_r at order 1.45 (bounds 1.2-1.75), the stress
    at order 0.74 (bounds 0.55-0.95), the finer mesh's errors within about twice the measured (2.70 %,
    8.5 %). Catches a tetrahedron's stiffness or load that does not converge to Kirsch (a stiffness 1 %
    off stalls u_r's error near 1 %; a wrong strain-displacement matrix stops the stress converging)."""
    scales = [2.0, 1.0]
    errors = np.array([kirsch_errors_on_tetrahedra(tmp_path, scale) for scale in scales])
    u_order, stress_order = (observed_orders(scales, errors[:, k])[0] for k in (0, 1))
    print(f"P1 tetrahedra Kirsch: wall u_r errors {errors[:, 0]}, order {u_order:.3f}; stress errors "
          f"{errors[:, 1]}, order {stress_order:.3f}")
    assert 1.2 < u_order < 1.75 and 0.55 < stress_order < 0.95
    assert errors[1, 0] < 0.054 and errors[1, 1] < 0.17


@pytest.mark.slow
def test_kirsch_excavation_on_tetrahedra_converges_in_h_on_three_meshes(tmp_path):
    """The same with s = 0.5 too: the second orders (measured 1.21 and 0.94; bounds 0.95-1.5 and
    0.75-1.15) and the finest errors within about twice the measured (1.17 %, 4.4 %). Catches an error
    that stalls below the default tier's resolution."""
    scales = [2.0, 1.0, 0.5]
    errors = np.array([kirsch_errors_on_tetrahedra(tmp_path, scale) for scale in scales])
    u_orders, stress_orders = (observed_orders(scales, errors[:, k]) for k in (0, 1))
    print(f"P1 tetrahedra Kirsch: wall u_r errors {errors[:, 0]}, orders {u_orders}; stress errors "
          f"{errors[:, 1]}, orders {stress_orders}")
    assert 0.95 < u_orders[1] < 1.5 and 0.75 < stress_orders[1] < 1.15
    assert errors[2, 0] < 0.024 and errors[2, 1] < 0.09


# P2 tetrahedra on the same family, s = 2 and 1 (1.6 and 0.8 m at the wall). Measured on the 240 m slab:
# the wall's u_r 1.648 / 0.782 % (order 1.08), the stress within 2 a 1.236 / 0.522 % (order 1.24); 7 s CPU.
# The rollers 24 a out bend both orders: on a 480 m slab about the same axis (rollers 48 a out) the same
# meshes give u_r 1.327 / 0.443 % (order 1.58) and the stress 1.126 / 0.393 % (order 1.52); 24 s CPU, the
# slow tier.
def test_kirsch_excavation_on_p2_tetrahedra_converges_in_h(tmp_path):
    """P2 tetrahedra, sizes scaled by 2 and 1: the wall's u_r at order 1.08 (bounds 0.85-1.3), the stress
    at 1.24 (bounds 1.0-1.5), the finer mesh's errors within about twice the measured (0.78 %, 0.52 %).
    Catches a P2 stiffness 1 % off (the rock's E x 1.01 in the model: u_r 2.62 / 1.76 %, order 0.57)."""
    scales = [2.0, 1.0]
    errors = np.array([kirsch_errors_on_tetrahedra(tmp_path, scale, order=2) for scale in scales])
    u_order, stress_order = (observed_orders(scales, errors[:, k])[0] for k in (0, 1))
    print(f"P2 tetrahedra Kirsch: wall u_r errors {errors[:, 0]}, order {u_order:.3f}; stress errors "
          f"{errors[:, 1]}, order {stress_order:.3f}")
    assert 0.85 < u_order < 1.3 and 1.0 < stress_order < 1.5
    assert errors[1, 0] < 0.0155 and errors[1, 1] < 0.0105


@pytest.mark.slow
def test_kirsch_excavation_on_p2_tetrahedra_converges_in_h_on_a_wider_slab(tmp_path):
    """The same two P2 meshes in a 480 m slab (rollers 48 a out): u_r at
    order 1.58 (bounds 1.3-1.85), the stress at 1.52 (bounds 1.25-1.8), the finer errors within about
    twice the measured (0.44 %, 0.39 %). Catches a stiffness 1 % off (E x 1.01 in the model: u_r 2.29 /
    1.42 %, order 0.69) that the 240 m slab's floor might partly hide."""
    scales = [2.0, 1.0]
    errors = np.array([kirsch_errors_on_tetrahedra(tmp_path, scale, order=2, section=480.0) for scale in scales])
    u_order, stress_order = (observed_orders(scales, errors[:, k])[0] for k in (0, 1))
    print(f"P2 tetrahedra Kirsch, 480 m slab: wall u_r errors {errors[:, 0]}, order {u_order:.3f}; stress "
          f"errors {errors[:, 1]}, order {stress_order:.3f}")
    assert 1.3 < u_order < 1.85 and 1.25 < stress_order < 1.8
    assert errors[1, 0] < 0.009 and errors[1, 1] < 0.008


@pytest.mark.parametrize("order", [1, 2])
def test_a_run_with_a_static_stage_on_tetrahedra_writes_the_stages_fields(tmp_path, order):
    """`run` with the excavation stage on a user's tetrahedral .geo writes static/fields.xdmf on the run's
    field mesh (until 2026-11-28 it assumed hexahedra and the run failed with a traceback): tetrahedra
    tiling the model, each written cell's stress its cell's stage stress (the cell of the model that
    holds the written cell's centroid: a written cell is a model cell or, in the serial writer's P2
    layout, one of its 8 parts)."""
    from scipy.spatial import cKDTree

    import test_static as kirsch_static

    from pyfem.fields_file import read_fields
    from pyfem.output import tensor6

    geo = tmp_path / "filled_tunnel.geo"
    geo.write_text(FILLED_TUNNEL_GEO.replace("WALL", "1.6"))
    summary = solver.run(kirsch_static.tunnel_scene(geo, order), tmp_path / "run")
    assert summary["status"] == "finished"
    simulation = solved(kirsch_static.tunnel_scene(geo, order))  # (the stage's stress as the model holds it)
    model = simulation.model
    fields = read_fields(tmp_path / "run" / "static" / "fields.xdmf")
    # 4-node tetrahedra, or (a P2 model on the distributed model) 10-node ones: their corners first.
    assert fields.times == [1.0, 2.0] and fields.cells.shape[1] == (4 if order == 1 or len(fields.cells) > model.n_cells
                                                                    else 10)
    x = fields.points[fields.cells[:, :4]]
    volume = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6.0
    corners = model.node_coords[model.V.dofmap.list.array.reshape(model.n_cells, -1)[:, :4]]
    whole = np.einsum("ij,ij->i", np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
                      corners[:, 3] - corners[:, 0])
    assert np.all(np.abs(volume) > 0.0) and np.abs(volume).sum() == pytest.approx(np.abs(whole).sum() / 6.0, rel=1e-12)
    # The model cell holding each written cell's centroid (barycentric coordinates all >= 0).
    centroids = x.mean(axis=1)
    _, near = cKDTree(corners.mean(axis=1)).query(centroids, k=min(12, model.n_cells))
    parent = np.full(len(centroids), -1)
    for k in range(near.shape[1]):
        todo = np.flatnonzero(parent < 0)
        c = corners[near[todo, k]]
        weights = np.linalg.solve((c[:, 1:] - c[:, :1]).transpose(0, 2, 1), (centroids[todo] - c[:, 0])[..., None])[..., 0]
        inside = np.all(weights >= -1e-9, axis=1) & (weights.sum(axis=1) <= 1.0 + 1e-9)
        parent[todo[inside]] = near[todo[inside], k]
    assert np.all(parent >= 0)
    stress = fields.steps[-1][2]["stress"]
    assert stress.shape == (len(fields.cells), 6), "the stages' stress is written per cell (Tensor6)"
    final = tensor6(simulation.cell_stress)[parent]
    assert np.abs(final).max() > 1e6  # MPa: the excavation's stress concentration
    assert np.allclose(stress, final, rtol=1e-9, atol=1e-9 * np.abs(final).max())


def test_p2_truncation_face_nodes_follow_the_free_field_at_second_order(tmp_path):
    """The input's traction term A sigma_ff n takes the row-sum (consistent) weights of the quadratic
    triangles, 0 at their vertices, while the springs and dashpots keep the HRZ weights: monitors on
    the truncation faces themselves converge at second order, as the interior does. With HRZ weights
    for the traction too (before 2026-11-24) they converged at order 0.7-1.2 (0.75-0.90 % at h = 10 m,
    0.33-0.57 % at h = 5 m)."""
    on_faces = [{"name": "xmin", "point": [0.0, 10.0, 80.0]}, {"name": "zmin", "point": [80.0, 10.0, 0.0]},
                {"name": "xmax", "point": [160.0, 10.0, 100.0]}]
    errors = {}
    for h in (10.0, 5.0):
        summary = solver.run(box_scene(box_geo(tmp_path, h), 2, monitor=on_faces), tmp_path / f"run_{h:g}")
        errors[h] = {m["name"]: summary["monitors"][m["name"]]["freefield_error"] for m in on_faces}
    for name in errors[5.0]:
        order = math.log2(errors[10.0][name] / errors[5.0][name])
        print(f"P2 face monitor {name}: {100 * errors[10.0][name]:.3f} % -> {100 * errors[5.0][name]:.3f} %, "
              f"order {order:.2f}")
        assert errors[5.0][name] < 0.003
        assert order > 1.7

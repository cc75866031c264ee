"""A non-circular opening: the static stage's excavation of an elliptical opening against the exact answer
(pyfem/analytic/elliptical_opening.py, docs/elliptical_opening.md).

The closed form (Muskhelishvili's potentials) is held to independent answers first: Inglis' hoop stress at
the wall, the literature's concentrations 1 + 2 b / a, a free wall, the far field, Kirsch's solution when
the ellipse is a circle, and its displacements through Hooke's law against its stresses.

Then the model: a tall elliptical opening (half-width 5 m, half-height 10 m: the crown's radius of
curvature is 2.5 m) in a plane-strain slab 480 x 480 m, 2 m thick, meshed by meshes/tunnel_in_box.py
--height 10 --filled, excavated by the static stage under sigma_xx = -1.5 p, sigma_zz = -p, sigma_xz =
0.25 p (p = 10 MPa). The crown's wall then carries a hoop stress of 6.7 p, where a circle would carry at
most 3.9 p.
"""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import observed_orders
from pyfem.analytic.elliptical_opening import EllipticalOpening, wall_errors

ROCK = {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}
P = 10.0e6
FAR = (-1.5 * P, -P, 0.25 * P)   # sigma_xx, sigma_zz, sigma_xz
HALF_WIDTH, HALF_HEIGHT = 5.0, 10.0
SECTION = 480.0


def test_wall_hoop_stress_is_inglis_and_the_wall_is_free():
    """The potentials' stress at the wall: the hoop stress equals Inglis' formula (summed over the far
    field's principal stresses), the normal and shear tractions vanish; wide, tall and round openings,
    far fields with shear."""
    theta = np.linspace(0.0, 2.0 * math.pi, 73)
    for a, b in ((5.0, 10.0), (10.0, 5.0), (5.0, 5.0), (5.0, 1.0)):
        opening = EllipticalOpening(a, b, ROCK["E"], ROCK["nu"], centre=(3.0, -2.0))
        for far in (FAR, (P, 0.0, 0.0), (0.0, -P, 0.0), (0.0, 0.0, P), (-0.3 * P, 0.7 * P, -0.4 * P)):
            x, z = opening.wall_point(theta)
            stress = opening.stresses(x, z, far)
            inglis = opening.wall_hoop_stress(theta, far)
            scale = np.abs(inglis).max()
            assert scale > 0.5 * P
            assert np.abs(stress["tt"] - inglis).max() < 1e-9 * scale, (a, b, far)
            assert np.abs(stress["nn"]).max() < 1e-9 * scale and np.abs(stress["nt"]).max() < 1e-9 * scale


def test_concentrations_are_the_textbooks():
    """Under a uniaxial far field S: 1 + 2 b / a at the ends of the axis across the load (Inglis 1913),
    -1 at the ends of the axis along it."""
    for a, b in ((5.0, 10.0), (10.0, 5.0), (5.0, 1.0)):
        opening = EllipticalOpening(a, b, ROCK["E"], ROCK["nu"])
        for theta, far, expected in ((0.5 * math.pi, (P, 0.0, 0.0), 1.0 + 2.0 * b / a),
                                     (0.0, (0.0, P, 0.0), 1.0 + 2.0 * a / b),
                                     (0.0, (P, 0.0, 0.0), -1.0), (0.5 * math.pi, (0.0, P, 0.0), -1.0)):
            x, z = opening.wall_point(theta)
            assert opening.stresses(x, z, far)["tt"] == pytest.approx(expected * P, rel=1e-12)


def test_far_field_is_recovered():
    opening = EllipticalOpening(HALF_WIDTH, HALF_HEIGHT, ROCK["E"], ROCK["nu"])
    stress = opening.stresses(np.array([4.0e4, -3.0e4]), np.array([-2.0e4, 5.0e4]), FAR)
    for key, value in zip(("sxx", "szz", "sxz"), FAR):
        assert np.abs(stress[key] - value).max() < 1e-6 * P   # the perturbation decays as (b / r)^2


def kirsch(r_over_a, theta, p, k):
    """(sigma_rr, sigma_tt, u_r / (p a / G)) of a circle under sigma_zz = -p, sigma_xx = -k p (Brady &
    Brown ch. 7; compression negative here)."""
    q2, q4, c2 = r_over_a ** -2, r_over_a ** -4, np.cos(2.0 * theta)
    rr = 0.5 * p * ((1 + k) * (1 - q2) - (1 - k) * (1 - 4 * q2 + 3 * q4) * c2)
    tt = 0.5 * p * ((1 + k) * (1 + q2) + (1 - k) * (1 + 3 * q4) * c2)
    nu = ROCK["nu"]
    ur = -(1.0 / (4.0 * r_over_a)) * ((1 + k) - (1 - k) * (4 * (1 - nu) - r_over_a ** -2) * c2)
    return -rr, -tt, ur


def test_a_circle_is_kirsch():
    a, k = 5.0, 0.5
    circle = EllipticalOpening(a, a, ROCK["E"], ROCK["nu"])
    r, theta = np.meshgrid([1.0, 1.05, 1.5, 2.0, 3.0], np.linspace(0.0, 2.0 * math.pi, 9))
    x, z = a * r * np.cos(theta), a * r * np.sin(theta)
    stress = circle.stresses(x, z, (-k * P, -P, 0.0))
    rr, tt, ur = kirsch(r, theta, P, k)
    assert np.abs(stress["nn"] - rr).max() < 1e-12 * P and np.abs(stress["tt"] - tt).max() < 1e-12 * P
    ux, uz = circle.displacement(x, z, (-k * P, -P, 0.0))
    radial = (ux * np.cos(theta) + uz * np.sin(theta)) * circle.shear_modulus / (P * a)
    assert np.abs(radial - ur).max() < 1e-12


def test_displacements_through_hooke_give_the_stresses():
    """Central differences of the displacement (the excavation's, so the far field is added back)
    through plane-strain Hooke's law reproduce the potentials' stress to 1e-8 of p, near the crown and
    away from the wall."""
    opening = EllipticalOpening(HALF_WIDTH, HALF_HEIGHT, ROCK["E"], ROCK["nu"])
    E, nu = ROCK["E"], ROCK["nu"]
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    h = 1.0e-4
    for x, z in ((0.3, 10.4), (7.0, 9.0), (-12.0, -3.0), (5.2, 0.5)):
        def u(dx, dz):
            return np.array(opening.displacement(x + dx, z + dz, FAR))
        du_dx, du_dz = (u(h, 0) - u(-h, 0)) / (2 * h), (u(0, h) - u(0, -h)) / (2 * h)
        exx, ezz, gxz = du_dx[0], du_dz[1], du_dz[0] + du_dx[1]
        stress = opening.stresses(x, z, FAR)
        hooke = (lam * (exx + ezz) + 2 * mu * exx + FAR[0], lam * (exx + ezz) + 2 * mu * ezz + FAR[1],
                 mu * gxz + FAR[2])
        for key, value in zip(("sxx", "szz", "sxz"), hooke):
            assert abs(value - stress[key]) < 1e-8 * P, (x, z, key)


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """workflows/elliptical_opening.py (its mesh and scene) and a folder for its meshes."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "workflows"))
    import elliptical_opening

    assert elliptical_opening.FAR_FIELD == FAR and elliptical_opening.SECTION == SECTION
    assert elliptical_opening.SHAPES["ellipse"] == (HALF_WIDTH, HALF_HEIGHT)
    return elliptical_opening, tmp_path_factory.mktemp("ellipse")


@pytest.mark.parametrize("order", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_excavated_elliptical_opening_follows_the_closed_form(study, order):
    """Hoop stress in every cell on the wall (at its centroid) and the wall's displacement against the
    exact answer. Measured (h = 0.3 m at the wall, 0.12 of the crown's radius of curvature): Q1 1.19 %
    of the peak in the worst cell, the peak cell 0.67 %, the wall's displacement 1.14 %; Q2 0.92 %,
    0.97 %, 0.41 % (docs/elliptical_opening.md)."""
    workflow, folder = study
    simulation = workflow.excavate(workflow.mesh(folder, "ellipse", 0.3), order)   # h = 0.12 rho at the crown
    assert "excavation" not in simulation.model.regions
    opening = EllipticalOpening(HALF_WIDTH, HALF_HEIGHT, ROCK["E"], ROCK["nu"], centre=(SECTION / 2, SECTION / 2))
    errors = wall_errors(simulation, opening, FAR)
    print(f"Q{order}: {errors['cells']} wall cells, worst hoop error {errors['worst']:.2%} of the peak, peak "
          f"cell {errors['hoop'] / 1e6:.2f} MPa vs {errors['exact_hoop'] / 1e6:.2f} ({errors['peak_cell']:.2%}), "
          f"wall displacement {errors['displacement']:.2%}")
    # The excavation concentrated the stress as an ellipse does: 6.1 p in the crown's cells, far above
    # the 3.9 p of a circle under this far field; the wall moved (3.1 cm at the sidewalls).
    assert errors["cells"] > 100 and errors["largest_hoop"] > 5.5 * P and errors["largest_displacement"] > 0.02
    assert errors["worst"] < 0.02 and errors["peak_cell"] < 0.02 and errors["displacement"] < 0.03


# The order in h: the wall's and the far size scaled together, (h_wall, h_far) = (0.6, 16), (0.3, 8) m
# (default tier; the second is the mesh above) and (0.15, 4) m (slow tier). Measured (Q1): the wall's
# displacement error 3.07 / 1.14 / 0.57 %, orders 1.44 and 1.00; the worst wall cell's hoop stress
# 1.47 / 1.19 / 0.53 % of the peak (orders 0.31, 1.15: not monotone, as the table of
# docs/elliptical_opening.md shows, so it is held to its bound and not to an order). The rollers 24
# half-heights out set a floor near 0.5 % of the wall's displacement, which bends the second order down.
ELLIPSE_ORDER_MESHES = ((0.6, 16.0), (0.3, 8.0), (0.15, 4.0))


def ellipse_order_errors(study, h_wall, h_far):
    import subprocess

    workflow, folder = study
    path = folder / f"ellipse_order_h{h_wall:g}_far{h_far:g}.msh"
    if not path.exists():
        subprocess.run([sys.executable, "meshes/tunnel_in_box.py", str(path), "--radius", str(HALF_WIDTH),
                        "--height", str(HALF_HEIGHT), "--size", str(SECTION), "--filled", "--h-wall", str(h_wall),
                        "--h-far", str(h_far)], check=True, timeout=600)
    simulation = workflow.excavate(path, 1)
    opening = EllipticalOpening(HALF_WIDTH, HALF_HEIGHT, ROCK["E"], ROCK["nu"], centre=(SECTION / 2, SECTION / 2))
    errors = wall_errors(simulation, opening, FAR)
    assert errors["largest_displacement"] > 0.02  # the wall moved
    return errors


def test_elliptical_opening_converges_in_h(study):
    """The wall's displacement at order 1.44 (bounds 1.15-1.75) over (0.6, 16) and (0.3, 8) m, the finer
    mesh's within about twice the measured 1.14 %, its worst cell within 2 % (measured 1.19 %). Catches
    an excavation load or a stiffness slightly off (the error stalls, the order falls below 1.15)."""
    meshes = ELLIPSE_ORDER_MESHES[:2]
    errors = [ellipse_order_errors(study, *mesh) for mesh in meshes]
    displacement = [e["displacement"] for e in errors]
    order = observed_orders([h for h, _ in meshes], displacement)[0]
    print(f"ellipse Q1: wall displacement errors {displacement}, order {order:.3f}; worst cells "
          f"{[e['worst'] for e in errors]}")
    assert 1.15 < order < 1.75
    assert displacement[1] < 0.023 and errors[1]["worst"] < 0.02


@pytest.mark.slow
def test_elliptical_opening_converges_in_h_on_three_meshes(study):
    """The same on three meshes: the second order of the wall's displacement (measured 1.00, bounds
    0.75-1.25; the truncation's floor bends it down from the first's 1.44), the finest mesh's within about
    twice the measured 0.57 %, its worst cell within about twice 0.53 %. Catches an error that stalls
    below the default tier's resolution."""
    errors = [ellipse_order_errors(study, *mesh) for mesh in ELLIPSE_ORDER_MESHES]
    displacement = [e["displacement"] for e in errors]
    orders = observed_orders([h for h, _ in ELLIPSE_ORDER_MESHES], displacement)
    print(f"ellipse Q1: wall displacement errors {displacement}, orders {orders}; worst cells "
          f"{[e['worst'] for e in errors]}")
    assert 1.15 < orders[0] < 1.75 and 0.75 < orders[1] < 1.25
    assert displacement[2] < 0.0115 and errors[2]["worst"] < 0.011

"""Geostatic initial stress and the static forces it puts on contact pairs."""
import numpy as np
import pytest

from conftest import ROUNDOFF, rel_error
from pyfem.initial_stress import STANDARD_GRAVITY, geostatic_stress, pair_static_forces
from pyfem.operators import build_model
from pyfem.scene import parse_scene
from pyfem.effects import contact_arguments

RHO, SURFACE = 2600.0, 560.0


def test_geostatic_stress_is_in_equilibrium_with_gravity():
    """div sigma0 + rho b = 0 with b = -g e_z (k_z = 1); sigma0 is linear in z, so central
    differences give the divergence exactly (to round-off)."""
    stress = geostatic_stress(SURFACE, RHO, k=[1.4, 1.2, 1.0])
    rng = np.random.default_rng(3)
    points = rng.uniform([0, 0, 100], [200, 50, 500], size=(20, 3))
    step = 1.0
    divergence = np.zeros((len(points), 3))
    for axis in range(3):
        shift = np.zeros(3)
        shift[axis] = step
        derivative = (stress(points + shift) - stress(points - shift)) / (2 * step)
        divergence += derivative[:, :, axis]
    body_force = np.tile([0.0, 0.0, -RHO * STANDARD_GRAVITY], (len(points), 1))
    assert np.max(np.abs(divergence + body_force)) < ROUNDOFF * RHO * STANDARD_GRAVITY
    # The lateral ratios and the sign: compression negative, zero at the surface.
    sigma = stress(points)
    assert np.all(sigma[:, 2, 2] < 0)
    assert rel_error(sigma[:, 0, 0], 1.4 * sigma[:, 2, 2]) < ROUNDOFF
    assert rel_error(sigma[:, 1, 1], 1.2 * sigma[:, 2, 2]) < ROUNDOFF
    assert np.all(stress(np.array([[0.0, 0.0, SURFACE]])) == 0.0)


def test_k_z_multiplies_the_vertical_stress():
    sigma = geostatic_stress(SURFACE, RHO, k=[1.4, 1.2, 1.15])(np.array([[0.0, 0.0, 60.0]]))[0]
    vertical = -RHO * STANDARD_GRAVITY * (SURFACE - 60.0)
    assert np.allclose(np.diag(sigma), [1.4 * vertical, 1.2 * vertical, 1.15 * vertical], rtol=1e-15)
    assert np.all(sigma[~np.eye(3, dtype=bool)] == 0.0)


@pytest.mark.parametrize("order", [1, 2])
def test_pair_forces_of_a_horizontal_interface_carry_the_overburden(order):
    scene = parse_scene({
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [6.0, 3.0, 4.0], "h": 1.0, "order": order,
                 "layers": [{"material": "a", "thickness": 1.5}, {"material": "b", "thickness": 2.5}]},
        "materials": {"a": {"preset": "sandstone"}, "b": {"preset": "non_sandstone"}},
        "time": {"duration": 0.1},
        "initial_stress": {"surface": 100.0, "rho": RHO, "k": [1.4, 1.2, 1.15]},
        "contact": {"interfaces": ["interface_1"], "cohesion": 1.0e6, "friction_angle": 30.0},
    })
    model = build_model(scene)
    forces = contact_arguments(scene, model)["static_force"]
    pairs = model.pairs
    sigma_zz = -1.15 * RHO * STANDARD_GRAVITY * (100.0 - 1.5)
    expected = np.zeros((len(pairs), 3))
    expected[:, 2] = sigma_zz * pairs.area  # = -rho g depth A n, n = +z: pushes node i (below) down
    assert rel_error(forces, expected) < ROUNDOFF
    assert abs(forces[:, 2].sum() - sigma_zz * 6.0 * 3.0) < ROUNDOFF * abs(sigma_zz) * 18.0
    assert np.max(np.abs(forces[:, :2])) < ROUNDOFF * np.max(np.abs(forces[:, 2]))  # normal round-off only


def test_any_stress_field_callable_gives_A_sigma_n():
    rng = np.random.default_rng(7)
    tensor = rng.normal(size=(3, 3))
    tensor = tensor + tensor.T

    def uniform(x):
        return np.broadcast_to(tensor, (len(x), 3, 3))

    coords = rng.normal(size=(5, 3))
    normal = rng.normal(size=(5, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    area = rng.uniform(1.0, 2.0, size=5)
    forces = pair_static_forces(coords, area, normal, uniform)
    assert rel_error(forces, area[:, None] * (normal @ tensor.T)) < ROUNDOFF
    assert np.all(pair_static_forces(coords, area, normal, None) == 0.0)
    with pytest.raises(ValueError, match="shape"):
        pair_static_forces(coords, area, normal, lambda x: np.zeros((len(x), 3)))

"""Assembled operators: lumped mass, stiffness, boundary faces, point weights.

Every check has an exact answer inside the discrete space (Q1, Q2 on
rectangular hexahedra), so tolerances are round-off.
"""
import importlib.util
import pathlib

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg

from conftest import ROUNDOFF, rel_error
from pyfem.geometry import BOX_FACES
from pyfem.operators import build_model, lame_parameters

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
ORIGIN = np.array([1.0, 2.0, 3.0])
SIZE = np.array([2.0, 1.0, 1.5])
E, NU, RHO = 8.0e9, 0.24, 2600.0


def box_scene(order, centre=None):
    return {
        "mesh": {"builder": "box", "origin": list(ORIGIN), "size": list(SIZE), "h": 0.5, "order": order},
        "materials": {"rock": {"E": E, "nu": NU, "rho": RHO}},
        "boundary": {"type": "viscoelastic", "centre": centre},
    }


@pytest.fixture(scope="module", params=[1, 2], ids=["Q1", "Q2"])
def box_model(request):
    return build_model(box_scene(request.param))


def infinity_norm(matrix) -> float:
    return float(abs(matrix).sum(axis=1).max())


def test_lumped_mass_totals_rho_times_volume_and_is_positive(box_model):
    assert box_model.mass.shape == (box_model.node_coords.shape[0],)
    assert rel_error(box_model.mass.sum(), RHO * np.prod(SIZE)) < 1e-12
    assert np.all(box_model.mass > 0.0)
    assert box_model.volume_of_region("rock") == pytest.approx(np.prod(SIZE), rel=1e-12)


def test_space_and_node_counts(box_model):
    n_per_axis = np.array([4, 2, 3]) * box_model.order + 1
    assert box_model.n_cells == 24
    assert box_model.node_coords.shape == (np.prod(n_per_axis), 3)
    assert box_model.n_dofs == 3 * np.prod(n_per_axis)
    assert box_model.stiffness.shape == (box_model.n_dofs, box_model.n_dofs)
    assert box_model.stiffness.blocksize == (3, 3)
    lo, hi = box_model.bounds
    np.testing.assert_allclose(lo, ORIGIN, atol=1e-14)
    np.testing.assert_allclose(hi, ORIGIN + SIZE, atol=1e-14)


def test_stiffness_is_symmetric_with_sorted_block_pattern(box_model):
    K = box_model.stiffness
    assert isinstance(K, scipy.sparse.bsr_matrix) and K.has_sorted_indices
    assert scipy.sparse.linalg.norm(K - K.T) <= ROUNDOFF * scipy.sparse.linalg.norm(K)
    # Every node couples at least to itself: one diagonal block per block row.
    assert np.all(np.diff(K.indptr) >= 1)


def rigid_body_modes(coords):
    """Three translations and three infinitesimal rotations about the box centre, (6, n_nodes, 3)."""
    relative = coords - (ORIGIN + 0.5 * SIZE)
    modes = [np.tile(np.eye(3)[axis], (len(coords), 1)) for axis in range(3)]
    modes += [np.cross(np.eye(3)[axis], relative) for axis in range(3)]
    return np.array(modes)


def test_rigid_body_modes_cost_no_force(box_model):
    K = box_model.stiffness
    checks = 0
    for mode in rigid_body_modes(box_model.node_coords):
        u = mode.ravel()
        force = K @ u
        assert np.abs(force).max() <= ROUNDOFF * infinity_norm(K) * np.abs(u).max()
        checks += 1
    assert checks == 6
    # and a non-rigid field does cost force (the check above is not vacuous)
    stretch = (box_model.node_coords * [1.0, 0.0, 0.0]).ravel()
    assert np.abs(K @ stretch).max() > 1e-3 * infinity_norm(K) * np.abs(stretch).max()


def test_homogeneous_strain_gives_traction_times_lumped_area(box_model):
    """K u for u = eps x equals sum over faces of area_i * sigma n (zero inside).

    For a homogeneous stress, int sigma : eps(phi_i) dx = int phi_i sigma n ds,
    exact in the discrete space; a full strain tensor with shear tests every
    component of K and of the face data together.
    """
    strain = np.array([[1.0, 0.3, -0.2], [0.3, -0.5, 0.4], [-0.2, 0.4, 0.7]]) * 1e-4
    lame_lambda, shear_modulus = lame_parameters(E, NU)
    stress = 2.0 * shear_modulus * strain + lame_lambda * np.trace(strain) * np.eye(3)
    displacement = box_model.node_coords @ strain.T
    force = (box_model.stiffness @ displacement.ravel()).reshape(-1, 3)

    expected = np.zeros_like(force)
    for face in box_model.faces:
        expected[face.nodes] += face.area[:, None] * (face.normal @ stress.T)
    assert rel_error(force, expected) < ROUNDOFF

    # Uniaxial stress: the x-forces on face xmax sum to sigma_xx * Ly * Lz.
    uniaxial_strain = np.diag([1.0, -NU, -NU]) * 1e-4
    force = (box_model.stiffness @ (box_model.node_coords @ uniaxial_strain.T).ravel()).reshape(-1, 3)
    xmax = next(face for face in box_model.faces if face.name == "xmax")
    total = force[xmax.nodes].sum(axis=0)
    assert rel_error(total, [E * 1e-4 * SIZE[1] * SIZE[2], 0.0, 0.0]) < ROUNDOFF


def test_strain_energy_of_a_nonuniform_field_is_exact(box_model):
    """u = (x^a y^a, 0, 0), a = order, in local coordinates: u.K.u = int sigma : eps dx exactly.

    eps_xx = a x^(a-1) y^a, eps_xy = a x^a y^(a-1) / 2, so
    sigma : eps = (lambda + 2G) a^2 x^(2a-2) y^(2a) + G a^2 x^(2a) y^(2a-2):
    a check that the quadrature of K is exact (reduced integration fails it).
    """
    a = box_model.order
    lame_lambda, shear_modulus = lame_parameters(E, NU)
    local = box_model.node_coords - ORIGIN
    displacement = np.zeros_like(local)
    displacement[:, 0] = local[:, 0] ** a * local[:, 1] ** a
    energy = displacement.ravel() @ (box_model.stiffness @ displacement.ravel())

    def monomial_integral(power_x, power_y):
        return SIZE[0] ** (power_x + 1) / (power_x + 1) * SIZE[1] ** (power_y + 1) / (power_y + 1) * SIZE[2]

    expected = a**2 * ((lame_lambda + 2.0 * shear_modulus) * monomial_integral(2 * a - 2, 2 * a)
                       + shear_modulus * monomial_integral(2 * a, 2 * a - 2))
    assert rel_error(energy, expected) < ROUNDOFF


def test_faces_areas_normals_impedances_and_distances(box_model):
    lame_lambda, shear_modulus = lame_parameters(E, NU)
    c_p, c_s = np.sqrt((lame_lambda + 2.0 * shear_modulus) / RHO), np.sqrt(shear_modulus / RHO)
    assert [face.name for face in box_model.faces] == list(BOX_FACES)
    n_per_axis = np.array([4, 2, 3]) * box_model.order + 1
    for face in box_model.faces:
        axis, sign = "xyz".index(face.name[0]), (1.0 if face.name.endswith("max") else -1.0)
        assert face.nodes.dtype == np.int32 and face.nodes.shape == (np.prod(np.delete(n_per_axis, axis)),)
        plane = ORIGIN[axis] + (SIZE[axis] if sign > 0 else 0.0)
        np.testing.assert_allclose(box_model.node_coords[face.nodes, axis], plane, atol=1e-12)
        assert np.all(face.area > 0.0)
        assert rel_error(face.area.sum(), np.prod(np.delete(SIZE, axis))) < 1e-12
        assert rel_error(face.normal, np.tile(sign * np.eye(3)[axis], (len(face.nodes), 1))) < ROUNDOFF
        assert rel_error(face.rho_cp, RHO * c_p * face.area) < 1e-12
        assert rel_error(face.rho_cs, RHO * c_s * face.area) < 1e-12
        assert rel_error(face.shear_modulus, shear_modulus * face.area) < 1e-12
        # default centre: the box centre, so R is half the box along the normal
        assert rel_error(face.plane_distance, np.full(len(face.nodes), 0.5 * SIZE[axis])) < ROUNDOFF


def test_plane_distance_uses_the_given_centre():
    centre = ORIGIN + [0.5, 0.25, -10.0]
    model = build_model(box_scene(1, centre=list(centre)))
    expected = {"xmin": 0.5, "xmax": SIZE[0] - 0.5, "ymin": 0.25, "ymax": SIZE[1] - 0.25,
                "zmin": 10.0, "zmax": SIZE[2] + 10.0}
    for face in model.faces:
        assert rel_error(face.plane_distance, np.full(len(face.nodes), expected[face.name])) < ROUNDOFF


def polynomial_field(points, order):
    """A full trilinear (order 1) or triquadratic (order 2) vector field with distinct components."""
    x, y, z = (points[:, i] - ORIGIN[i] for i in range(3))
    if order == 1:
        scalar = 1.0 + 2.0 * x - y + 0.5 * z + 0.7 * x * y - 0.3 * y * z + 0.2 * x * z + 1.1 * x * y * z
    else:
        scalar = (1.0 + x - 2.0 * x**2) * (0.5 - y + 3.0 * y**2) * (2.0 + z + z**2) + x**2 * y**2 * z**2
    return np.stack([scalar, 2.0 * scalar - x, scalar * 0.5 + y], axis=1)


def test_point_weights_reproduce_fields_of_the_space_exactly(box_model):
    rng = np.random.default_rng(7)
    points = ORIGIN + rng.random((20, 3)) * SIZE
    # also a node, a point on an inner element face, and a corner of the box
    points = np.vstack([points, box_model.node_coords[5], ORIGIN + [0.5, 0.3, 0.7], ORIGIN + SIZE])
    nodal_values = polynomial_field(box_model.node_coords, box_model.order)
    nodes, weights = box_model.point_weights(points)
    n_basis = (box_model.order + 1) ** 3
    assert nodes.shape == weights.shape == (len(points), n_basis)
    assert nodes.dtype == np.int32 and weights.dtype == np.float64
    interpolated = np.einsum("mk,mkc->mc", weights, nodal_values[nodes])
    assert rel_error(interpolated, polynomial_field(points, box_model.order)) < ROUNDOFF
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-13)


def test_point_outside_the_mesh_is_rejected(box_model):
    outside = ORIGIN + SIZE + [0.1, 0.0, 0.0]
    with pytest.raises(ValueError, match="outside the mesh"):
        box_model.point_weights(np.array([ORIGIN + 0.5 * SIZE, outside]))
    with pytest.raises(ValueError, match=r"\(m, 3\)"):
        box_model.point_weights(np.zeros((2, 2)))


def test_unsupported_order_is_rejected():
    with pytest.raises(ValueError, match="mesh.order"):
        build_model(box_scene(3))


@pytest.fixture(scope="module")
def two_layer_path(tmp_path_factory):
    spec = importlib.util.spec_from_file_location("make_two_layer_block",
                                                  REPOSITORY / "meshes" / "make_two_layer_block.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    path = tmp_path_factory.mktemp("two_layer") / "two_layer_block.msh"
    script.make_two_layer_block(str(path))
    return path, script


@pytest.mark.parametrize("order", [1, 2])
def test_two_layer_masses_volumes_and_face_impedances(two_layer_path, order):
    path, script = two_layer_path
    lx, ly, lz = script.BLOCK_SIZE
    layers = {"sandstone": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}, "mudstone": {"E": 2.0e9, "nu": 0.30, "rho": 2400.0}}
    volumes = {"sandstone": lx * ly * script.INTERFACE_Z, "mudstone": lx * ly * (lz - script.INTERFACE_Z)}
    scene = {"mesh": {"builder": "file", "file": str(path), "order": order}, "materials": layers,
             "boundary": {"centre": None}}
    model = build_model(scene)
    for name, volume in volumes.items():
        assert model.volume_of_region(name) == pytest.approx(volume, rel=1e-12)
    assert rel_error(model.mass.sum(), sum(layers[n]["rho"] * volumes[n] for n in layers)) < 1e-12

    # Each region's mass: raising one layer's density by d raises the total by d * its volume only.
    for name in layers:
        heavier = {n: dict(t) for n, t in layers.items()}
        heavier[name]["rho"] += 1000.0
        model_heavier = build_model(dict(scene, materials=heavier))
        assert rel_error(model_heavier.mass.sum() - model.mass.sum(), 1000.0 * volumes[name]) < 1e-10

    # The interface is internal: not an outer face. Side faces see both layers.
    assert [face.name for face in model.faces] == list(BOX_FACES)
    xmin = next(face for face in model.faces if face.name == "xmin")
    expected_rho_cp = 0.0
    for name, height in (("sandstone", script.INTERFACE_Z), ("mudstone", lz - script.INTERFACE_Z)):
        lame_lambda, shear_modulus = lame_parameters(layers[name]["E"], layers[name]["nu"])
        expected_rho_cp += np.sqrt(layers[name]["rho"] * (lame_lambda + 2.0 * shear_modulus)) * ly * height
    assert rel_error(xmin.rho_cp.sum(), expected_rho_cp) < 1e-12
    bottom = next(face for face in model.faces if face.name == "zmin")
    lame_lambda, shear_modulus = lame_parameters(layers["sandstone"]["E"], layers["sandstone"]["nu"])
    assert rel_error(bottom.shear_modulus, shear_modulus * bottom.area) < 1e-12

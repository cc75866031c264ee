"""Internal forces computed element by element (pyfem.elements, kernel HexahedronElements).

- exactness: a layer taken out of the stiffness matrix and run through the element loop with
  the linear elastic law equals the all-matrix run to round-off (Q1 and Q2, seismic input,
  boundary dashpots and springs, mass- and stiffness-proportional damping);
- the stress held at the quadrature points is C : eps(u) of the displacement;
- energy: the balance with the component's stored energy closes to round-off (also with mean
  dilatation, and beside sliding contact pairs), and the scheme's internal work equals the
  stored energy;
- threads: 1 and 2 threads give the same bits;
- zero cost when off: a component with no cells leaves the run bitwise unchanged;
- reset_energy computes without committing: a reset in the middle leaves the run bitwise unchanged.
"""
import pathlib
import tomllib

import numpy as np
import pytest

from conftest import EXACT, rel_error
from pyfem import _kernels
from pyfem.distributed_model import model_in_memory
from pyfem.elements import element_arrays, nonlinear_component, quadrature_rule, region_cells, region_elastic_parameters
from pyfem.operators import lame_parameters
from pyfem.scene import parse_scene

CONTACT_WORKFLOW = pathlib.Path(__file__).resolve().parents[1] / "workflows" / "scenes" / "contact_two_layer_sv.toml"
UPPER = {"E": 2.0e9, "nu": 0.3, "rho": 2400.0}
LOWER = {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}


def two_layer_scene(order: int, loop=()):
    """A 40 x 20 x 40 m box of two layers under a vertical SV Ricker pulse, viscoelastic faces,
    Rayleigh damping with both coefficients. `loop`: materials given a [plasticity] table, which puts
    their cells in the model's element loop (`split_stepper` gives them the linear elastic law)."""
    materials = {"lower": dict(LOWER), "upper": dict(UPPER)}
    for name in loop:
        materials[name]["plasticity"] = NEVER_YIELDS
    return parse_scene({
        "title": f"two layers Q{order}",
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [40.0, 20.0, 40.0], "h": 5.0, "order": order,
                 "layers": [{"material": "lower", "thickness": 20.0}, {"material": "upper", "thickness": 20.0}]},
        "materials": materials,
        "time": {"duration": 0.3},
        "wave": {"type": "SV", "angle": 0.0, "surface": 60.0, "medium": "lower",
                 "motion": {"ricker": {"f0": 8.0, "amplitude": 1.0e-3}}},
        "boundary": {"type": "viscoelastic"},
        "damping": {"alpha": 0.5, "beta": 2.0e-5},
        "output": {"interval": 0.01, "xdmf_interval": 0.0},
    })


# A [plasticity] table only to put a region in the element loop: split_stepper replaces its law.
NEVER_YIELDS = {"cohesion": 1.0e12, "friction_angle": 30.0, "tensile_strength": 1.0e12}
_MODELS = {}


def model_of(order, loop=()):
    """The one model of the two-layer scene in memory (pyfem.distributed_model.model_in_memory, one
    rank), once per order and element-loop regions: the all-matrix model (loop ()), or the model
    with `loop`'s cells out of the matrix and in the element loop."""
    key = (order, tuple(loop))
    if key not in _MODELS:
        _MODELS[key] = model_in_memory(two_layer_scene(order, loop))
    return _MODELS[key]


def matrix_stepper(model):
    """The kernel stepper the model builds (a fresh one at every call), and its dofs."""
    stepper, _ = model.stepper()
    return stepper, 3 * model.part.n_local


def split_stepper(model, **options):
    """The kernel stepper of a model built with element-loop regions (`model_of(order, loop)`), each
    region's law replaced by the linear elastic law of its material (fresh components; no initial
    stress), the other cells in the model's matrix. Returns (stepper, the element loop's
    NonlinearRegions)."""
    regions = model.loop.counted
    assert model.loop.halo is None and model.part.kernel_of_dolfinx is None  # one rank, one numbering
    for name in regions.arrays:
        regions.laws[name] = ("linear_elastic", region_elastic_parameters(model.part.model, name))
        regions.options[name] = {"mean_dilatation": bool(options.get("mean_dilatation", False)),
                                 **({"min_cells_for_threads": int(options["min_cells_for_threads"])}
                                    if "min_cells_for_threads" in options else {})}
        regions.initial_stress[name] = None
    regions.new_components()
    stepper, _ = model.stepper()
    return stepper, regions


def history(stepper, n_dofs, chunks=6, steps=50):
    """(u, v, a) after each chunk of steps from rest, and the last energy report."""
    u, v, a = np.zeros(n_dofs), np.zeros(n_dofs), np.zeros(n_dofs)
    stepper.reset_energy(u, v, a, 0.0)
    t, samples = 0.0, []
    for _ in range(chunks):
        t = stepper.run(u, v, a, steps, t)
        samples.append(np.concatenate([u, v, a]))
    return np.array(samples), stepper.energy()


def energy_scale(energy):
    return max(abs(energy["total"]), abs(energy["external_work"]), abs(energy["damping_work"]))


@pytest.mark.parametrize("order", [1, 2])
def test_element_loop_region_equals_the_all_matrix_run(order):
    whole, layer = model_of(order), model_of(order, ("upper",))
    assert layer.time_step.dt == whole.time_step.dt  # (the same stable step: every cell's bound)
    reference_stepper, n = matrix_stepper(whole)
    reference, reference_energy = history(reference_stepper, n)
    stepper, nonlinear = split_stepper(layer)
    split, energy = history(stepper, n)
    cells = nonlinear.components[0].n_cells
    assert 0 < cells < whole.part.model.n_cells
    assert layer.part.matrix[1].size < whole.part.matrix[1].size  # cells left the matrix
    assert np.max(np.abs(reference[:, :n])) > 1e-6  # the wave is in the box
    # Relative to the largest value of each field over the run: the pulse leaves through the
    # faces, and round-off from its peak stays in the small field left behind.
    checks = 0
    for part in range(3):  # u, v, a
        fields, fields_split = reference[:, part * n:(part + 1) * n], split[:, part * n:(part + 1) * n]
        peak = np.max(np.linalg.norm(fields, axis=1))
        assert np.max(np.linalg.norm(fields_split - fields, axis=1)) < EXACT * peak
        checks += 1
    assert checks == 3
    # The energy terms split between the matrix and the component.
    assert abs(energy["strain"] + energy["internal_stored"] - reference_energy["strain"]) < EXACT * reference_energy["strain"]
    assert abs(energy["damping_work"] - reference_energy["damping_work"]) < EXACT * reference_energy["damping_work"]
    assert energy["internal_stored"] > 1e-2 * reference_energy["strain"]  # the layer holds a share


@pytest.mark.parametrize("order, mean_dilatation", [(1, False), (2, False), (1, True)])
def test_energy_balance_closes_with_the_elastic_component(order, mean_dilatation):
    model = model_of(order, ("upper",))
    stepper, _ = split_stepper(model, mean_dilatation=mean_dilatation)
    _, energy = history(stepper, 3 * model.part.n_local)
    scale = energy_scale(energy)
    assert energy["external_work"] > 1e-3 * scale and energy["damping_work"] > 1e-3 * scale
    assert abs(energy["balance"]) < EXACT * scale, energy
    # From rest Psi_0 = 0: the scheme's internal work is the stored energy, no dissipation.
    assert abs(energy["internal_work"] - energy["internal_stored"]) < EXACT * scale
    assert energy["internal_dissipation"] == 0.0


@pytest.mark.parametrize("order", [1, 2])
def test_stress_at_the_quadrature_points_is_C_eps_of_the_displacement(order):
    model = model_of(order, ("upper",))
    stepper, nonlinear = split_stepper(model)
    n = 3 * model.part.n_local
    samples, _ = history(stepper, n, chunks=4)
    u = samples[-1, :n]
    arrays = nonlinear.arrays["upper"]
    nodal = u.reshape(-1, 3)[arrays.cell_nodes]                                 # (c, k, 3)
    gradient = np.einsum("cki,cqkl->cqil", nodal, arrays.gradients)             # du_i/dx_l
    strain = 0.5 * (gradient + gradient.transpose(0, 1, 3, 2))
    lame_lambda, shear_modulus = lame_parameters(UPPER["E"], UPPER["nu"])
    stress = lame_lambda * np.trace(strain, axis1=2, axis2=3)[..., None, None] * np.eye(3) + 2 * shear_modulus * strain
    expected = np.stack([stress[..., 0, 0], stress[..., 1, 1], stress[..., 2, 2],
                         stress[..., 0, 1], stress[..., 1, 2], stress[..., 0, 2]], axis=-1)
    held = nonlinear.components[0].stress()
    assert held.shape == expected.shape == (len(arrays.cells), (order + 1) ** 3, 6)
    assert np.abs(expected).max() > 1e3  # Pa: the wave strains the layer
    assert rel_error(held, expected) < EXACT


def test_element_arrays_integrate_the_region_volume_with_dolfinx_quadrature():
    model = model_of(2).part.model
    arrays = element_arrays(model.V, region_cells(model, "upper"))
    assert arrays.weights.shape[1] == len(quadrature_rule(2)[1]) == 27
    assert abs(arrays.weights.sum() - model.volume_of_region("upper")) < EXACT * arrays.weights.sum()
    assert np.all(arrays.points[..., 2] >= 20.0 - 1e-9)  # the upper layer's points
    # Partition of unity: the basis gradients sum to zero at every point.
    assert np.abs(arrays.gradients.sum(axis=2)).max() < EXACT * np.abs(arrays.gradients).max()


def test_element_loop_beside_sliding_contact_equals_the_matrix_run_and_closes_the_balance():
    # The contact correction reads the internal force of the pair nodes (F = M a + K u + g).
    with open(CONTACT_WORKFLOW, "rb") as stream:
        data = tomllib.load(stream)
    data["mesh"]["order"] = 1
    data["time"].update(dt=1.0e-3, duration=0.6)
    data["contact"].update(cohesion=2.0e4, tensile_strength=2.0e4)
    data["wave"]["motion"]["ricker"]["amplitude"] = 0.05
    whole = model_in_memory(parse_scene(data, source="test", base_dir=CONTACT_WORKFLOW.parent))
    data["materials"]["mudstone"]["plasticity"] = NEVER_YIELDS
    layer = model_in_memory(parse_scene(data, source="test", base_dir=CONTACT_WORKFLOW.parent))
    assert list(layer.loop.counted.arrays) == ["mudstone"] and whole.loop is None
    reference_stepper, n = matrix_stepper(whole)
    reference, reference_energy = history(reference_stepper, n, chunks=6, steps=100)
    stepper, _ = split_stepper(layer)
    split, energy = history(stepper, n, chunks=6, steps=100)
    assert energy["friction_dissipation"] > 1e-3 * energy_scale(energy)  # pairs slid
    peak = np.max(np.linalg.norm(reference[:, :n], axis=1))
    assert np.max(np.linalg.norm(split[:, :n] - reference[:, :n], axis=1)) < EXACT * peak
    assert abs(energy["balance"]) < EXACT * energy_scale(energy)


def test_one_and_two_threads_give_the_same_bits():
    model = model_of(2, ("upper",))
    previous = _kernels.max_threads()
    runs = []
    try:
        for threads in (1, 2):
            _kernels.set_num_threads(threads)
            stepper, nonlinear = split_stepper(model, min_cells_for_threads=0)
            samples, energy = history(stepper, 3 * model.part.n_local, chunks=2)
            runs.append((samples, nonlinear.components[0].stress(), energy["internal_stored"]))
    finally:
        _kernels.set_num_threads(previous)
    assert np.array_equal(runs[0][0], runs[1][0])
    assert np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def test_a_component_without_cells_leaves_the_run_bitwise_unchanged():
    model = model_of(1)
    reference_stepper, n = matrix_stepper(model)
    reference, reference_energy = history(reference_stepper, n)
    stepper, _ = matrix_stepper(model)
    empty = _kernels.HexahedronElements(np.zeros((0, 8), dtype=np.int32), np.zeros((0, 8, 8, 3)), np.zeros((0, 8)),
                                        "linear_elastic", {"lame_lambda": 1e9, "shear_modulus": 1e9})
    stepper.add_internal_force(empty)
    samples, energy = history(stepper, n)
    assert np.array_equal(samples, reference)
    assert energy["balance"] == reference_energy["balance"]
    assert "internal_stored" in energy and "internal_stored" not in reference_energy


def test_reset_energy_does_not_commit_the_component_state():
    model = model_of(1, ("upper",))
    n = 3 * model.part.n_local
    reference, _ = history(split_stepper(model)[0], n, chunks=4)
    stepper, nonlinear = split_stepper(model)
    component = nonlinear.components[0]
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    stepper.reset_energy(u, v, a, 0.0)
    t = 0.0
    samples = []
    for chunk in range(4):
        t = stepper.run(u, v, a, 50, t)
        samples.append(np.concatenate([u, v, a]))
        if chunk == 1:
            stress = component.stress()
            dissipation, stored = component.dissipation(), component.stored_energy()
            for _ in range(2):
                stepper.reset_energy(u, v, a, t)
            assert np.array_equal(component.stress(), stress)
            assert (component.dissipation(), component.stored_energy()) == (dissipation, stored)
            # A compute at another displacement is a trial only.
            component.compute(2.0 * u, np.zeros(n))
            assert np.array_equal(component.stress(), stress)
            stepper.reset_energy(u, v, a, t)
            energy = stepper.energy()
            assert energy["balance"] == 0.0 and energy["internal_work"] == 0.0
            assert energy["internal_stored"] == stored
    assert np.array_equal(np.array(samples), reference)


def test_q2_tensor_form_equals_the_dense_gradients_on_distorted_cells_through_yield():
    """The kernel's sum factorisation of Q2 (element_arrays' tensor tables, tensor_q2.hpp) gives
    the trial stresses, forces and energies of the dense gradient tables on curved, distorted
    cells, for a Mohr-Coulomb region driven through yield; Q1 keeps the dense form."""
    from mpi4py import MPI
    import dolfinx.fem
    import dolfinx.mesh

    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [4.0, 6.0, 8.0]], [2, 3, 4],
                                   dolfinx.mesh.CellType.hexahedron)
    x = mesh.geometry.x
    x[:, :] += 0.3 * np.sin(1.3 * x[:, [1, 2, 0]] + 0.4)                       # non-affine cells
    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 2))
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    arrays = element_arrays(V, cells)
    assert arrays.tensor is not None
    assert element_arrays(dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1)), cells).tensor is None
    rock = {"young_modulus": 10e9, "poisson_ratio": 0.25, "cohesion": 1e6, "friction_angle": 30.0,
            "tensile_strength": 0.5e6, "dilation_angle": 10.0}
    sigma0 = np.zeros(arrays.weights.shape + (6,))
    sigma0[..., :3] = [-6e6, -6e6, -9e6]
    forms = {"dense": arrays.kernel_gradients(dense=True), "tensor": arrays.kernel_gradients()}
    components = {name: _kernels.HexahedronElements(arrays.cell_nodes, g, arrays.weights, "mohr_coulomb", rock,
                                                    initial_stress=sigma0) for name, g in forms.items()}
    n_dofs = 3 * V.dofmap.index_map.size_local
    rng = np.random.default_rng(5)
    yielded = 0.0
    for scale in (1e-5, 1e-3, 3e-3):                                            # elastic, then yielding
        u = scale * rng.standard_normal(n_dofs)
        results = {}
        for name, component in components.items():
            force = np.zeros(n_dofs)
            energy = component.compute(u, force)
            component.commit()
            results[name] = force, energy, component.stress(), component.plastic_strain()
        (f_dense, e_dense, s_dense, k_dense), (f_tensor, e_tensor, s_tensor, k_tensor) = results.values()
        assert np.abs(f_dense).max() > 0.0
        # The dense tables carry basix's own ~1e-12 round-off; the tensor tables are exact.
        assert rel_error(f_tensor, f_dense) < 1e-9
        assert rel_error(s_tensor, s_dense) < 1e-9
        assert np.abs(k_tensor - k_dense).max() <= 1e-9 * max(np.abs(k_dense).max(), 1e-30)
        assert abs(e_tensor["stored"] - e_dense["stored"]) < 1e-9 * abs(e_dense["stored"])
        yielded = max(yielded, float((k_dense > 0).mean()))
    assert yielded > 0.2                                                          # the region did yield


@pytest.mark.parametrize("cell, order", [("hexahedron", 1), ("hexahedron", 2), ("tetrahedron", 1),
                                         ("tetrahedron", 2)])
def test_reference_form_equals_the_dense_gradients_and_float32_costs_its_round_off(cell, order):
    """The geometry as per-point inverse Jacobians with the reference gradients shared by the cells
    (kernel_gradients' default for Q1, P1, P2, and for Q2 with mean dilatation) gives the dense
    gradients' forces, stresses and plastic strains to round-off, through yield, with and without mean
    dilatation; held as float32 (single_geometry) it differs, by float32's round-off of the geometry
    (~6e-8 relative; bounded at 3e-7)."""
    from mpi4py import MPI
    import dolfinx.fem
    import dolfinx.mesh

    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [4.0, 6.0, 8.0]], [2, 3, 4],
                                   getattr(dolfinx.mesh.CellType, cell))
    x = mesh.geometry.x
    x[:, :] += 0.3 * np.sin(1.3 * x[:, [1, 2, 0]] + 0.4)                       # non-affine cells
    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", order))
    arrays = element_arrays(V, np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32))
    rock = {"young_modulus": 10e9, "poisson_ratio": 0.25, "cohesion": 1e6, "friction_angle": 30.0,
            "tensile_strength": 0.5e6, "dilation_angle": 10.0}
    sigma0 = np.zeros(arrays.weights.shape + (6,))
    sigma0[..., :3] = [-6e6, -6e6, -9e6]
    n_dofs = 3 * V.dofmap.index_map.size_local
    for mean_dilatation in (False, True):
        reference = arrays.kernel_gradients(mean_dilatation=mean_dilatation)
        assert isinstance(reference, tuple) and (len(reference) == 2) == (cell != "hexahedron" or order == 1
                                                                          or mean_dilatation)
        forms = {"dense": (arrays.kernel_gradients(dense=True), False), "reference": (reference, False),
                 "float32": (reference, True)}
        components = {name: _kernels.HexahedronElements(arrays.cell_nodes, g, arrays.weights, "mohr_coulomb", rock,
                                                        initial_stress=sigma0, mean_dilatation=mean_dilatation,
                                                        single_geometry=single)
                      for name, (g, single) in forms.items()}
        assert components["float32"].geometry_bytes == 9 * 4 + 8
        assert components["reference"].geometry_bytes == 9 * 8 + 8
        assert components["dense"].geometry_bytes == 3 * arrays.cell_nodes.shape[1] * 8 + 8
        rng = np.random.default_rng(5)
        for scale in (1e-5, 1e-3):                                              # elastic, then yielding
            u = scale * rng.standard_normal(n_dofs)
            results = {}
            for name, component in components.items():
                force = np.zeros(n_dofs)
                component.compute(u, force)
                component.commit()
                results[name] = force, component.stress(), np.asarray(component.plastic_strain())
            (f_dense, s_dense, k_dense), (f_ref, s_ref, k_ref), (f_single, s_single, _) = results.values()
            assert np.abs(f_dense).max() > 0.0
            assert rel_error(f_ref, f_dense) < 1e-11 and rel_error(s_ref, s_dense) < 1e-11
            assert np.abs(k_ref - k_dense).max() <= 1e-11 * max(np.abs(k_dense).max(), 1e-30)
            assert 1e-9 < rel_error(f_single, f_dense) < 3e-7
            assert rel_error(s_single, s_dense) < 3e-7
        assert (k_dense > 0).mean() > 0.5                                       # the region did yield


@pytest.mark.parametrize("u_ref", [0.0, 2.0e-3])
def test_rock_damage_crack_band_scales_with_each_cells_size(u_ref):
    """The rock law's crack band in the element loop (docs/materials.md "Crack band of the rock"):
    every point's damage is d_max (1 - exp(-kappa h / u_ref)) with h the cube root of its own cell's
    volume, so cells of different sizes soften by their plastic displacement kappa h; without it
    (u_ref = 0) by their strain, kappa / damage_plastic_strain, in every cell. Cells graded 1:4 in x,
    driven through yield by random displacements."""
    from mpi4py import MPI
    import dolfinx.fem
    import dolfinx.mesh

    mesh = dolfinx.mesh.create_box(MPI.COMM_WORLD, [[0.0, 0.0, 0.0], [1.0, 4.0, 4.0]], [4, 2, 2],
                                   dolfinx.mesh.CellType.hexahedron)
    x = mesh.geometry.x
    x[:, 0] = 16.0 * x[:, 0] ** 2                                   # cell widths 1, 3, 5, 7 m
    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    arrays = element_arrays(V, cells)
    rock = {"young_modulus": 2e9, "poisson_ratio": 0.3, "cohesion": 0.35e6, "friction_angle": 26.0,
            "tensile_strength": 0.25e6, "damage_max": 0.9, "damage_plastic_strain": 1e-3,
            "damage_plastic_displacement": u_ref}
    component = _kernels.HexahedronElements(arrays.cell_nodes, arrays.kernel_gradients(), arrays.weights,
                                            "mohr_coulomb", rock)
    volume = arrays.weights.sum(axis=1)
    h = np.asarray(component.characteristic_length())
    assert h == pytest.approx(np.cbrt(volume), rel=1e-12)
    assert h.max() / h.min() > 1.8                                   # the cells do differ
    n_dofs = 3 * V.dofmap.index_map.size_local
    rng = np.random.default_rng(3)
    for scale in (1e-5, 1e-3, 3e-3):                                   # elastic, then yielding
        component.compute(scale * rng.standard_normal(n_dofs), np.zeros(n_dofs))
        component.commit()
    kappa, damage = np.asarray(component.plastic_strain()), np.asarray(component.damage())
    assert (kappa > 0).mean() > 0.5 and damage.max() > 0.3              # yielded and softened
    scale_of_cell = u_ref / h if u_ref > 0 else np.full(len(h), rock["damage_plastic_strain"])
    expected = 0.9 * (1.0 - np.exp(-kappa / scale_of_cell[:, None]))
    assert np.abs(damage - expected).max() < 1e-12


def test_bad_arguments_are_value_errors_naming_the_parameter():
    nodes = np.zeros((2, 8), dtype=np.int32)
    gradients, weights = np.zeros((2, 8, 8, 3)), np.ones((2, 8))
    elastic = {"lame_lambda": 1e9, "shear_modulus": 1e9}
    with pytest.raises(ValueError, match="weights"):
        _kernels.HexahedronElements(nodes, gradients, np.ones((3, 8)), "linear_elastic", elastic)
    with pytest.raises(ValueError, match="gradients"):
        _kernels.HexahedronElements(nodes, np.zeros((2, 8, 8, 2)), weights, "linear_elastic", elastic)
    with pytest.raises(ValueError, match="known laws: linear_elastic"):
        _kernels.HexahedronElements(nodes, gradients, weights, "no_such_law", elastic)
    with pytest.raises(ValueError, match="shear_modulus' missing"):
        _kernels.HexahedronElements(nodes, gradients, weights, "linear_elastic", {"lame_lambda": 1e9})
    with pytest.raises(ValueError, match="unknown parameter 'E'"):
        _kernels.HexahedronElements(nodes, gradients, weights, "linear_elastic", {**elastic, "E": 1.0})
    with pytest.raises(ValueError, match="weights"):
        _kernels.HexahedronElements(nodes, gradients, np.zeros((2, 8)), "linear_elastic", elastic)
    with pytest.raises(ValueError, match="tensor form"):
        _kernels.HexahedronElements(nodes, (np.zeros((2, 8, 3, 3)),), weights, "linear_elastic", elastic)
    q2_nodes, q2_weights, order = np.zeros((1, 27), dtype=np.int32), np.ones((1, 27)), np.arange(27, dtype=np.int32)
    tensor = (np.zeros((1, 27, 3, 3)), order, order, np.eye(3), np.eye(3))
    _kernels.HexahedronElements(q2_nodes, tensor, q2_weights, "linear_elastic", elastic)
    with pytest.raises(ValueError, match="permutations"):
        _kernels.HexahedronElements(q2_nodes, (tensor[0], np.zeros(27, dtype=np.int32), *tensor[2:]), q2_weights,
                                    "linear_elastic", elastic)
    with pytest.raises(ValueError, match="reference_gradients"):
        _kernels.HexahedronElements(nodes, (np.zeros((2, 8, 3, 3)), np.zeros((8, 4, 3))), weights, "linear_elastic",
                                    elastic)
    with pytest.raises(ValueError, match="single_geometry"):
        _kernels.HexahedronElements(nodes, gradients, weights, "linear_elastic", elastic, single_geometry=True)
    with pytest.raises(ValueError, match="tensor form is for Q2"):
        _kernels.HexahedronElements(nodes, (np.zeros((2, 8, 3, 3)), order, order, np.eye(3), np.eye(3)), weights,
                                    "linear_elastic", elastic)
    component = _kernels.HexahedronElements(nodes + 5, gradients, weights, "linear_elastic", elastic)
    with pytest.raises(RuntimeError, match="commit"):
        component.commit()
    stepper = _kernels.Stepper(np.zeros(3, dtype=np.int64), np.zeros(0, dtype=np.int32), np.zeros((0, 3, 3)),
                               np.ones(2), 1e-3)
    with pytest.raises(ValueError, match="not a node"):
        stepper.add_internal_force(component)
    with pytest.raises(ValueError, match="not among region_names"):
        nonlinear_component(model_of(1).part.model, ["upper"], {"lower": {"law": "linear_elastic"}})


def test_a_samples_state_leaves_the_points_out_and_as_they_were():
    """Stepper.save_state(points=False), what the MPI ranks merge at every sample: the energy
    account and the components' energies, not their points or the nodal internal force; loading
    it restores the account and leaves every point's state as it was."""
    model = model_of(1, ("upper",))
    n = 3 * model.part.n_local
    stepper, nonlinear = split_stepper(model)
    component = nonlinear.components[0]
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    stepper.reset_energy(u, v, a, 0.0)
    t = stepper.run(u, v, a, 100, 0.0)
    whole, light = stepper.save_state(), stepper.save_state(points=False)
    assert component.stored_energy() > 0.0 and np.abs(component.stress()).max() > 0.0  # the pulse arrived
    assert set(light) == set(whole) - {"stepper/internal_force", "component/0/points", "component/0/state",
                                       "component/0/initial_stress"}
    assert all(light[key] == whole[key] for key in light)
    energy, stress = stepper.energy(), component.stress()
    stepper.run(u, v, a, 50, t)
    assert not np.array_equal(component.stress(), stress) and stepper.energy() != energy
    moved = component.stress()
    stepper.load_state(light, points=False)
    assert stepper.energy() == energy  # the account of the sample
    assert np.array_equal(component.stress(), moved)  # the points as they were
    with pytest.raises(ValueError, match="no block 'stepper/internal_force'"):
        stepper.load_state(light)  # a checkpoint needs every node and point

"""Element arrays of the regions whose material the kernel integrates point by point.

A region with a nonlinear material (plasticity, damage) is taken out of the stiffness matrix
and handed to the kernel as a `pyfem._kernels.HexahedronElements` component: per cell its nodes,
per quadrature point the basis gradients dphi/dx and the weight x |det J|, and a material law
with a state at every point (docs/ARCHITECTURE.md "Kernel"). The other cells stay in the matrix.

The quadrature is the one of `pyfem.operators.elastic_stiffness`: basix's default rule of
degree 2 * order on the hexahedron (2^3 Gauss points for Q1, 3^3 for Q2), and the geometry is
the mesh's coordinate element, as dolfinx's assembler has them; so a region given to the element
loop with the linear elastic law reproduces the all-matrix run to round-off.

The linear part of the stiffness is assembled with the same form as the full one, with lambda
and G set to zero on the element-loop cells (a DG0 coefficient, not a measure restricted by
subdomain ids): the form, its compiled kernel and the assembly path stay those of the full
matrix, so the linear cells' element matrices are the same numbers; the blocks that only the
removed cells fed are then exactly zero and are dropped from the pattern, so the kernel streams
nothing for them.

Usage (the solver, once [materials.X.plasticity] is wired):
    nonlinear = nonlinear_component(model, ["lining"], {"lining": {"law": "linear_elastic", ...}})
    stiffness = nonlinear.stiffness (+ boundary springs); dt from the full model.stiffness
    for component in nonlinear.components: stepper.add_internal_force(component)
"""
from __future__ import annotations

import dataclasses
import typing

import basix
import numpy as np
import scipy.sparse

SPACE_DIMENSION = 3


@dataclasses.dataclass
class ElementArrays:
    """Kernel arrays of a set of hexahedral cells (docs/ARCHITECTURE.md numbering).

    Attributes:
        cells: (c,) int32 local dolfinx cell indices.
        cell_nodes: (c, k) int32 node of each basis function, k = 8 (Q1) or 27 (Q2).
        gradients: (c, q, k, 3) float64 basis gradients dphi/dx at the quadrature points (1/m).
        weights: (c, q) float64 quadrature weight x |det J| (m^3).
        points: (c, q, 3) float64 physical coordinates of the quadrature points (m).
    """

    cells: np.ndarray
    cell_nodes: np.ndarray
    gradients: np.ndarray
    weights: np.ndarray
    points: np.ndarray

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays (the kernel borrows them for the whole run)."""
        return int(sum(getattr(self, f.name).nbytes for f in dataclasses.fields(self)))


@dataclasses.dataclass
class NonlinearRegions:
    """The element-loop regions of a model and the stiffness of all other cells.

    Attributes:
        stiffness: BSR (3n, 3n), (3, 3) blocks: elastic stiffness of the cells not in any
            component (N/m), no boundary springs; the kernel's K in place of Model.stiffness.
            The stable time step still comes from the full elastic stiffness.
        components: one pyfem._kernels.HexahedronElements per region, in region order.
        arrays: region name -> ElementArrays (quadrature points for output).
        laws: region name -> (law name, parameters dict).
    """

    stiffness: scipy.sparse.bsr_matrix
    components: list
    arrays: dict
    laws: dict

    @property
    def memory_bytes(self) -> int:
        """Bytes the element loop holds: borrowed arrays plus the kernels' state and buffers."""
        return sum(a.nbytes for a in self.arrays.values()) + sum(c.owned_bytes for c in self.components)


def quadrature_rule(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (q, 3) and weights (q,) on the reference hexahedron [0, 1]^3 of basix's default rule
    of degree 2 * order, the rule dolfinx uses for `quadrature_degree = 2 * order`."""
    points, weights = basix.make_quadrature(basix.QuadratureType.Default, basix.CellType.hexahedron, 2 * order)
    return np.asarray(points, dtype=np.float64), np.asarray(weights, dtype=np.float64)


def element_arrays(V, cells: np.ndarray) -> ElementArrays:
    """Nodes, basis gradients, weights and points of the given cells, vectorised over cells.

    Per point X_q of the reference rule: J = sum_g x_g (x) dpsi_g/dX (psi the mesh's coordinate
    element, x_g its geometry nodes), dphi/dx = dphi/dX J^-1, weight = w_q |det J|.

    Args:
        V: dolfinx vector Lagrange space of order 1 or 2 on a hexahedral mesh.
        cells: local cell indices.

    Returns:
        ElementArrays of the cells, in the given order.
    """
    mesh = V.mesh
    if mesh.topology.cell_type.name != "hexahedron":
        raise ValueError(f"element_arrays: hexahedral cells only, the mesh has {mesh.topology.cell_type.name}")
    element = V.element.basix_element
    if not element.dof_transformations_are_identity:
        raise NotImplementedError("element_arrays: the space needs dof transformations (not Lagrange Q1/Q2)")
    order = element.degree
    cells = np.asarray(cells, dtype=np.int32)
    reference_points, reference_weights = quadrature_rule(order)

    # tabulate(1, X): [value, d/dX, d/dY, d/dZ] x points x basis x value size.
    basis_gradients = element.tabulate(1, reference_points)[1:, :, :, 0].transpose(1, 2, 0)       # (q, k, 3)
    coordinate_element = _coordinate_element(mesh)
    coordinate_table = coordinate_element.tabulate(1, reference_points)[:, :, :, 0]              # (4, q, g)
    n_geometry = coordinate_table.shape[2]
    geometry_nodes = mesh.geometry.dofmap.array.reshape(-1, n_geometry)[cells]
    x = mesh.geometry.x[geometry_nodes]                                                           # (c, g, 3)
    jacobian = np.einsum("cgi,jqg->cqij", x, coordinate_table[1:])                              # dx_i/dX_j
    determinant = np.linalg.det(jacobian)
    if np.any(determinant == 0.0):
        raise ValueError("element_arrays: a degenerate cell (det J = 0 at a quadrature point)")
    inverse = np.linalg.inv(jacobian)                                                            # dX_j/dx_i
    gradients = np.einsum("qkj,cqji->cqki", basis_gradients, inverse)
    weights = reference_weights[None, :] * np.abs(determinant)
    points = np.einsum("qg,cgi->cqi", coordinate_table[0], x)

    n_basis = element.dim
    cell_nodes = V.dofmap.list.array.reshape(-1, n_basis)[cells]
    return ElementArrays(cells=cells, cell_nodes=np.ascontiguousarray(cell_nodes, dtype=np.int32),
                         gradients=np.ascontiguousarray(gradients), weights=np.ascontiguousarray(weights),
                         points=np.ascontiguousarray(points))


def _coordinate_element(mesh):
    """basix element of the mesh geometry (Lagrange of the coordinate map's degree)."""
    degree = mesh.geometry.cmap.degree
    if degree > 2:
        raise NotImplementedError(f"element_arrays: geometry of degree {degree} (only 1 and 2: the Lagrange "
                                  "variant of higher degrees is not known here)")
    return basix.create_element(basix.ElementFamily.P, basix.CellType.hexahedron, degree,
                                basix.LagrangeVariant.gll_warped)


def region_cells(model, name: str) -> np.ndarray:
    """Local cells (int32, sorted) of region `name` of the model."""
    if name not in model.regions:
        raise ValueError(f"region {name!r}: unknown; regions are {sorted(model.regions)}")
    cells = model.cell_tags.indices[model.cell_tags.values == model.regions[name]]
    return np.unique(cells).astype(np.int32)


def linear_stiffness(model, removed_cells: np.ndarray) -> scipy.sparse.bsr_matrix:
    """Elastic stiffness of every cell except `removed_cells`, BSR (3, 3) blocks (N/m).

    The form of `pyfem.operators.elastic_stiffness` with lambda and G zero on the removed
    cells; blocks that only removed cells fed are exactly zero and dropped.
    """
    from dolfinx import fem

    from pyfem.operators import elastic_stiffness

    materials = model._materials
    fields = {}
    for key in ("lame_lambda", "shear_modulus"):
        field = fem.Function(getattr(materials, key).function_space, name=key)
        field.x.array[:] = getattr(materials, key).x.array
        field.x.array[materials.dof_of_cell[np.asarray(removed_cells, dtype=np.int32)]] = 0.0
        fields[key] = field
    stiffness = elastic_stiffness(model.V, fields["lame_lambda"], fields["shear_modulus"],
                                  {"quadrature_degree": 2 * model.order})
    stiffness.eliminate_zeros()
    stiffness.sort_indices()
    return stiffness


def region_elastic_parameters(model, name: str) -> dict:
    """{"lame_lambda", "shear_modulus"} (Pa) of region `name`, from the model's material fields."""
    cells = region_cells(model, name)
    materials = model._materials
    values = {}
    for key in ("lame_lambda", "shear_modulus"):
        per_cell = getattr(materials, key).x.array[materials.dof_of_cell[cells]]
        if len(per_cell) and not np.all(per_cell == per_cell[0]):
            raise ValueError(f"region {name!r}: {key} is not constant over its cells")
        values[key] = float(per_cell[0]) if len(per_cell) else 0.0
    return values


def quadrature_initial_stress(points: np.ndarray, field) -> np.ndarray:
    """(c, q, 6) Voigt [xx, yy, zz, xy, yz, xz] static stress (Pa) of a field at the points (c, q, 3).

    Args:
        points: (c, q, 3) quadrature points (m).
        field: callable (m, 3) points -> (m, 3, 3) stress (Pa), e.g.
            `pyfem.initial_stress.stress_field_from_scene(scene)`.
    """
    flat = np.asarray(field(points.reshape(-1, SPACE_DIMENSION)), dtype=np.float64).reshape(-1, 3, 3)
    voigt = np.stack([flat[:, 0, 0], flat[:, 1, 1], flat[:, 2, 2], flat[:, 0, 1], flat[:, 1, 2], flat[:, 0, 2]],
                     axis=1)
    return np.ascontiguousarray(voigt.reshape(points.shape[0], points.shape[1], 6))


def nonlinear_component(model, region_names: typing.Sequence[str],
                        law_parameters: typing.Mapping[str, typing.Mapping] | None = None,
                        initial_stress=None, mean_dilatation: bool = False,
                        min_cells_for_threads: int | None = None) -> NonlinearRegions:
    """Kernel components for the regions whose material the element loop integrates, and the
    stiffness of all other cells.

    Stiffness-proportional Rayleigh damping (beta) of the component cells uses the law's initial
    elastic moduli (the kernel adds beta K0 v_{n+1/2}), so damping is unchanged by the split.

    Args:
        model: pyfem.operators.Model.
        region_names: regions (scene material names) to take out of the matrix.
        law_parameters: region -> {"law": name, **parameters (SI)}; a region not listed gets
            "linear_elastic" with the lambda and G of its material (Pa).
        initial_stress: None, or a callable (m, 3) points (m) -> (m, 3, 3) static stress (Pa)
            evaluated at the quadrature points (the laws' total stress starts there; the force
            uses sigma - sigma0).
        mean_dilatation: B-bar (mean volumetric strain per cell) in every component.
        min_cells_for_threads: kernel threshold below which a component runs on one thread
            (None: the kernel's default).

    Returns:
        NonlinearRegions: stiffness (the kernel's K without springs), components, arrays, laws.
    """
    from pyfem import _kernels

    region_names = list(dict.fromkeys(region_names))
    law_parameters = dict(law_parameters or {})
    unknown = sorted(set(law_parameters) - set(region_names))
    if unknown:
        raise ValueError(f"law_parameters: regions {unknown} are not among region_names {region_names}")
    components, arrays, laws, removed = [], {}, {}, []
    for name in region_names:
        cells = region_cells(model, name)
        given = dict(law_parameters.get(name) or {"law": "linear_elastic", **region_elastic_parameters(model, name)})
        law = given.pop("law", "linear_elastic")
        parameters = {key: float(value) for key, value in given.items()}
        region_arrays = element_arrays(model.V, cells)
        sigma0 = None if initial_stress is None else quadrature_initial_stress(region_arrays.points, initial_stress)
        options = {} if min_cells_for_threads is None else {"min_cells_for_threads": int(min_cells_for_threads)}
        components.append(_kernels.HexahedronElements(
            region_arrays.cell_nodes, region_arrays.gradients, region_arrays.weights, law, parameters,
            initial_stress=sigma0, mean_dilatation=mean_dilatation, **options))
        arrays[name] = region_arrays
        laws[name] = (law, parameters)
        removed.append(cells)
    removed_cells = np.concatenate(removed) if removed else np.zeros(0, dtype=np.int32)
    return NonlinearRegions(stiffness=linear_stiffness(model, removed_cells), components=components,
                            arrays=arrays, laws=laws)

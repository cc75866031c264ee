"""Element arrays of the regions whose material the kernel integrates point by point.

A region with a nonlinear material (plasticity, damage) is taken out of the stiffness matrix
and handed to the kernel as a `pyfem._kernels.HexahedronElements` component: per cell its nodes,
per quadrature point the basis gradients dphi/dx and the weight x |det J|, and a material law
with a state at every point (docs/ARCHITECTURE.md "Kernel"). The other cells stay in the matrix.

The quadrature on hexahedra is the one of `pyfem.operators.elastic_stiffness`: basix's default
rule of degree 2 * order (2^3 Gauss points for Q1, 3^3 for Q2), and the geometry is the mesh's
coordinate element, as dolfinx's assembler has them; so a region given to the element loop with
the linear elastic law reproduces the all-matrix run to round-off. On tetrahedra (affine cells)
the rule is basix's default of degree `order`: one point for P1 (its strain is constant), four for
P2 (its strain is linear, so B^T C B is quadratic and the 4-point rule integrates it exactly): the
linear elastic law reproduces the matrix (assembled with a higher-degree rule) to round-off too.

The linear part of the stiffness is assembled with the same form as the full one, with lambda
and G set to zero on the element-loop cells (a DG0 coefficient, not a measure restricted by
subdomain ids): the form, its compiled kernel and the assembly path stay those of the full
matrix, so the linear cells' element matrices are the same numbers; the blocks that only the
removed cells fed are then exactly zero and are dropped from the pattern, so the kernel streams
nothing for them.

The scene's [materials.NAME.plasticity] (law "mohr_coulomb") and [materials.NAME.damage] (law
"concrete_damage") tables select the regions and their laws (`scene_laws`); the solver does
    nonlinear = nonlinear_component(model, list(laws), laws, initial_stress=field, mean_dilatation=...)
    stiffness = nonlinear.stiffness (+ boundary springs); dt from the full model.stiffness
    for component in nonlinear.components: stepper.add_internal_force(component)
and reads the laws' state back for output (`NonlinearRegions.cell_averages`, `region_summary`,
`nearest_point`).
"""
from __future__ import annotations

import dataclasses
import math
import typing

import basix
import numpy as np
import scipy.sparse

SPACE_DIMENSION = 3

LAW_OF_TABLE = {"plasticity": "mohr_coulomb", "damage": "concrete_damage"}
"""Kernel law (cpp_kernels/materials) of each nonlinear sub-table of [materials.NAME]."""

ZONE_EDGE = 2.5
"""run.json counts the yielded points closer than this (m) to the edge of a [plasticity] zone."""

DAMAGED = 0.01
"""A point counts as damaged in run.json's damaged_volume when d > DAMAGED."""

CRACK_OPENINGS = (1.0e-4, 2.0e-4, 3.0e-4, 1.0e-3, 1.0e-2)
"""Crack openings (m) by which run.json grades a cracked lining (cracked_volume_by_opening):
0.1-0.3 mm are the crack-width limits of concrete design codes (EN 1992-1-1 Table 7.1N: 0.3 mm;
water-retaining structures 0.1-0.2 mm), 1 mm a crack well open, 10 mm a lining broken through
(the case study's, docs/case_study.md)."""


@dataclasses.dataclass
class ElementArrays:
    """Kernel arrays of a set of hexahedral or tetrahedral cells (docs/ARCHITECTURE.md numbering).

    Attributes:
        cells: (c,) int32 local dolfinx cell indices.
        cell_nodes: (c, k) int32 node of each basis function, k = 8 (Q1) or 27 (Q2) hexahedra,
            4 (P1) or 10 (P2) tetrahedra.
        reference_gradients: (q, k, 3) float64 basis gradients dphi/dX on the reference cell.
        inverse_jacobians: (c, q, 3, 3) float64 dX_m/dx_l at the quadrature points (1/m):
            dphi/dx = reference_gradients @ inverse_jacobians (the property `gradients`).
        weights: (c, q) float64 quadrature weight x |det J| (m^3).
        points: (c, q, 3) float64 physical coordinates of the quadrature points (m).
        tensor: for Q2 with its 27-point Gauss rule, the tensor-product tables of the kernel's
            sum factorisation (tensor_tables; cpp_kernels/tensor_q2.hpp), else None.
        uniform_gradients: (c, k, 3) float64 or None: one-point cells (q = 1,
            pyfem/reduced_integration.py) whose gradient is the cell's mean gradient (1/m), which
            `gradients` then returns in place of the centre point's.
    """

    cells: np.ndarray
    cell_nodes: np.ndarray
    reference_gradients: np.ndarray
    inverse_jacobians: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    tensor: tuple | None = None
    uniform_gradients: np.ndarray | None = None

    @property
    def gradients(self) -> np.ndarray:
        """(c, q, k, 3) basis gradients dphi/dx at the quadrature points (1/m), computed."""
        if self.uniform_gradients is not None:
            return self.uniform_gradients[:, None]
        return np.einsum("qkm,cqml->cqkl", self.reference_gradients, self.inverse_jacobians)

    def kernel_gradients(self, dense: bool = False, mean_dilatation: bool = False):
        """The `gradients` argument of pyfem._kernels.HexahedronElements: the tensor form
        (inverse Jacobians + tables) where there is one and mean dilatation is off, else the
        reference form (inverse Jacobians + the reference gradients, 72 B per point); the dense
        (c, q, k, 3) array for one-point cells with their mean gradients, or with `dense`."""
        if dense or self.uniform_gradients is not None:
            return np.ascontiguousarray(self.gradients)
        if self.tensor is not None and not mean_dilatation:
            return (self.inverse_jacobians, *self.tensor)
        return (self.inverse_jacobians, self.reference_gradients)

    def subset(self, rows: np.ndarray, node_numbers: np.ndarray | None = None) -> "ElementArrays":
        """The arrays of the cells at `rows` (indices into `cells`); node_numbers: the new number of
        every node (an MPI rank's local numbering, pyfem/distributed_model.py), None: unchanged."""
        cell_nodes = self.cell_nodes[rows]
        if node_numbers is not None:
            cell_nodes = node_numbers[cell_nodes]
        return dataclasses.replace(
            self, cells=self.cells[rows], cell_nodes=np.ascontiguousarray(cell_nodes, dtype=np.int32),
            inverse_jacobians=np.ascontiguousarray(self.inverse_jacobians[rows]),
            weights=np.ascontiguousarray(self.weights[rows]), points=np.ascontiguousarray(self.points[rows]),
            uniform_gradients=(None if self.uniform_gradients is None
                               else np.ascontiguousarray(self.uniform_gradients[rows])))

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays (the kernel borrows them for the whole run)."""
        return int(sum(getattr(self, f.name).nbytes for f in dataclasses.fields(self)
                       if isinstance(getattr(self, f.name), np.ndarray)))


def blank_point_values(found: np.ndarray) -> dict:
    """The law values of m points before any is read: {"found" (m,) bool, "stress" (m, 6) Voigt (Pa;
    NaN where not found), "damage" (m,), "damage_type" (m,) int32, "plastic_strain" (m,)} (0 where
    not found). `read_point_values` gives the same keys but "found"."""
    m = len(found)
    return {"found": np.asarray(found, dtype=bool), "stress": np.full((m, 6), np.nan), "damage": np.zeros(m),
            "damage_type": np.zeros(m, dtype=np.int32), "plastic_strain": np.zeros(m)}


def read_point_values(component, points: np.ndarray) -> dict:
    """The committed law values at one component's points (kernel point indices, int64), one batch
    read per accessor: the keys of `blank_point_values` but "found"."""
    return {"stress": np.asarray(component.stress(points)), "damage": np.asarray(component.damage(points)),
            "damage_type": np.asarray(component.damage_type(points)),
            "plastic_strain": np.asarray(component.plastic_strain(points))}


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
        initial_stress: region name -> (c, q, 6) static stress at the points (Pa) or None.
        options: region name -> keyword options of HexahedronElements (mean_dilatation, ...).
        zones: region name -> box [xmin, ymin, zmin, xmax, ymax, zmax] (m) its cells were taken from
            (`[plasticity] zone`), absent for a whole region.
        integration: region name -> "full" or "reduced" (one point per cell; its arrays then have
            q = 1 and its hourglass stiffness is in `stiffness`, pyfem/reduced_integration.py).
        hourglass: region name -> BSR K_hg of its cells, for the "reduced" regions (N/m).
    """

    stiffness: scipy.sparse.bsr_matrix
    components: list
    arrays: dict
    laws: dict
    initial_stress: dict = dataclasses.field(default_factory=dict)
    options: dict = dataclasses.field(default_factory=dict)
    zones: dict = dataclasses.field(default_factory=dict)
    integration: dict = dataclasses.field(default_factory=dict)
    hourglass: dict = dataclasses.field(default_factory=dict)

    @property
    def memory_bytes(self) -> int:
        """Bytes the element loop holds: borrowed arrays plus the kernels' state and buffers."""
        return sum(a.nbytes for a in self.arrays.values()) + sum(c.owned_bytes for c in self.components)

    @property
    def regions(self) -> list[str]:
        """Region names, in component order."""
        return list(self.arrays)

    @property
    def n_points(self) -> int:
        """Quadrature points of all components."""
        return int(sum(a.weights.size for a in self.arrays.values()))

    def new_components(self) -> list:
        """Builds every component afresh (initial state) into `components` and returns them: a
        component holds the state of one run, so each stepper gets its own."""
        self.components = [self.new_component(name) for name in self.arrays]
        return self.components

    def new_component(self, name: str, initial_stress="scene", rows: np.ndarray | None = None,
                      node_numbers: np.ndarray | None = None):
        """A fresh component of region `name` (not stored in `components`): its initial stress is
        the region's `initial_stress` ("scene"), or the (c, q, 6) array given, or zero (None).
        rows, node_numbers: only the region's cells at `rows`, nodes renumbered
        (`ElementArrays.subset`; an MPI rank's share, whose state is loaded afterwards)."""
        from pyfem import _kernels

        arrays = self.arrays[name]
        sigma0 = self.initial_stress.get(name) if isinstance(initial_stress, str) else initial_stress
        if rows is not None:
            arrays = arrays.subset(rows, node_numbers)
            sigma0 = None if sigma0 is None else np.ascontiguousarray(sigma0[rows])
        options = self.options.get(name, {})
        gradients = arrays.kernel_gradients(mean_dilatation=bool(options.get("mean_dilatation")))
        return _kernels.HexahedronElements(arrays.cell_nodes, gradients, arrays.weights, *self.laws[name],
                                           initial_stress=sigma0, **options)

    def nearest_point(self, cell: int, point) -> tuple[int, int] | None:
        """(component index, flat point index cell * q + point) of the quadrature point of local cell
        `cell` nearest to `point` (m), or None when the cell is in no component."""
        for index, arrays in enumerate(self.arrays.values()):
            position = int(np.searchsorted(arrays.cells, cell))
            if position < len(arrays.cells) and arrays.cells[position] == cell:
                distance = np.linalg.norm(arrays.points[position] - np.asarray(point, dtype=float), axis=1)
                return index, position * arrays.weights.shape[1] + int(np.argmin(distance))
        return None

    def point_values(self, locations: typing.Sequence) -> dict:
        """The committed state at points given as `nearest_point` gives them (None: not in a
        component): `blank_point_values` filled by `read_point_values` of each component."""
        values = blank_point_values(np.array([found is not None for found in locations], dtype=bool))
        for index, component in enumerate(self.components):
            rows = [j for j, found in enumerate(locations) if found is not None and found[0] == index]
            if rows:
                points = np.array([locations[j][1] for j in rows], dtype=np.int64)
                for key, read in read_point_values(component, points).items():
                    values[key][rows] = read
        return values

    def _active(self, components) -> list:
        """(component, name, arrays) of the regions whose component is given (`components` in region
        order, None: `self.components`; a None entry: a region not active yet, left out)."""
        components = self.components if components is None else components
        return [(component, name, arrays) for component, (name, arrays) in zip(components, self.arrays.items())
                if component is not None]

    def cell_averages(self, components=None) -> dict:
        """Per region, the committed state averaged over each cell's points (weights w |det J|):
        {"cells" (c,), "stress" (c, 6) Voigt xx yy zz xy yz xz (Pa), "damage" (c,),
        "plastic_strain" (c,), "damage_type" (c,) int32: the type of the cell's most damaged
        point (of its largest plastic strain when no point is damaged; 0 for neither),
        "crack_opening" (c,) (m): the cell's mean crack strain times its characteristic length,
        the crack band's opening at its largest so far (0 for laws without cracks)}.
        `components`: those to read (region order; None entries skipped), default `self.components`."""
        result = {}
        for component, name, arrays in self._active(components):
            weights = arrays.weights / arrays.weights.sum(axis=1, keepdims=True)
            damage, plastic = component.damage(), component.plastic_strain()
            kind = component.damage_type()
            most = np.where(damage.max(axis=1) > 0.0, damage.argmax(axis=1), plastic.argmax(axis=1))
            result[name] = {
                "cells": arrays.cells,
                "stress": np.einsum("cq,cqk->ck", weights, component.stress()),
                "damage": np.einsum("cq,cq->c", weights, damage),
                "plastic_strain": np.einsum("cq,cq->c", weights, plastic),
                "damage_type": kind[np.arange(len(kind)), most].astype(np.int32),
                "crack_opening": crack_opening(component, arrays),
            }
        return result

    def region_summary(self, components=None) -> dict:
        """Per region, for run.json: law, integration, cells, points, volume (m^3), damaged_volume (d > DAMAGED,
        m^3, by points), peak_damage, yielded_volume (plastic strain > 0, m^3), peak_plastic_strain,
        tension_points / shear_points (damage_type 1 / 2), dissipated_energy (J since the start);
        for laws that crack, peak_crack_opening (m: the largest cell mean of the crack band's
        opening, the field crack_opening) and cracked_volume_by_opening ({opening in mm: m^3 of
        cells whose opening exceeds it}: a cracked-through lining graded by how wide it opened).
        `components` as in `cell_averages`."""
        summary = {}
        for component, name, arrays in self._active(components):
            damage, plastic, kind = component.damage(), component.plastic_strain(), component.damage_type()
            summary[name] = {
                "law": self.laws[name][0],
                "integration": self.integration.get(name, "full"),
                "cells": int(arrays.weights.shape[0]),
                "points": int(arrays.weights.size),
                "volume": float(arrays.weights.sum()),
                "damaged_volume": float(arrays.weights[damage > DAMAGED].sum()),
                "peak_damage": float(damage.max(initial=0.0)),
                "yielded_volume": float(arrays.weights[plastic > 0.0].sum()),
                "peak_plastic_strain": float(plastic.max(initial=0.0)),
                "tension_points": int(np.count_nonzero(kind == 1)),
                "shear_points": int(np.count_nonzero(kind == 2)),
                "dissipated_energy": float(component.dissipation()),
            }
            if self.laws[name][0] == "concrete_damage":
                opening, cell_volume = crack_opening(component, arrays), arrays.weights.sum(axis=1)
                summary[name]["peak_crack_opening"] = float(opening.max(initial=0.0))
                summary[name]["cracked_volume_by_opening"] = {
                    f"{1e3 * w:g}": float(cell_volume[opening > w].sum()) for w in CRACK_OPENINGS}
            zone = self.zones.get(name)
            if zone is not None:  # yielding at the zone's edge: the zone may be too small
                low, high = np.asarray(zone[:3]), np.asarray(zone[3:])
                margin = np.minimum(arrays.points - low, high - arrays.points).min(axis=2)
                summary[name]["zone"] = list(zone)
                summary[name]["yielded_points_near_zone_edge"] = int(np.count_nonzero(
                    (plastic > 0.0) & (margin < ZONE_EDGE)))
        return summary


def crack_opening(component, arrays) -> np.ndarray:
    """Each cell's crack band opening (c,) (m): its points' crack strain (the law's d_t kappa_t,
    0 for laws without cracks) averaged with weights w |det J|, times the cell's characteristic
    length, the h the law regularises with (docs/materials.md "Crack opening")."""
    weights = arrays.weights / arrays.weights.sum(axis=1, keepdims=True)
    return np.einsum("cq,cq->c", weights, component.crack_strain()) * component.characteristic_length()


def voigt_tensor(voigt: np.ndarray) -> np.ndarray:
    """(..., 3, 3) symmetric tensors of (..., 6) Voigt vectors in the kernel's order xx, yy, zz, xy,
    yz, xz (tensor shear components, as the laws' stress)."""
    voigt = np.asarray(voigt, dtype=float)
    xx, yy, zz, xy, yz, xz = np.moveaxis(voigt, -1, 0)
    return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1), np.stack([xz, yz, zz], -1)], -2)


def quadrature_rule(order: int, cell: str = "hexahedron") -> tuple[np.ndarray, np.ndarray]:
    """Points (q, 3) and weights (q,) of the element loop's rule on the reference cell: on the
    hexahedron [0, 1]^3 basix's default rule of degree 2 * order, the rule dolfinx uses for
    `quadrature_degree = 2 * order`; on the tetrahedron basix's default rule of degree `order`
    (1 point for P1, 4 for P2: exact for the stiffness of affine cells)."""
    if cell == "tetrahedron":
        points, weights = basix.make_quadrature(basix.QuadratureType.Default, basix.CellType.tetrahedron, order)
    else:
        points, weights = basix.make_quadrature(basix.QuadratureType.Default, basix.CellType.hexahedron, 2 * order)
    return np.asarray(points, dtype=np.float64), np.asarray(weights, dtype=np.float64)


def element_arrays(V, cells: np.ndarray) -> ElementArrays:
    """Nodes, basis gradients, weights and points of the given cells, vectorised over cells.

    Per point X_q of the reference rule: J = sum_g x_g (x) dpsi_g/dX (psi the mesh's coordinate
    element, x_g its geometry nodes), dphi/dx = dphi/dX J^-1, weight = w_q |det J|.

    Args:
        V: dolfinx vector Lagrange space of order 1 or 2 on a hexahedral or tetrahedral mesh.
        cells: local cell indices.

    Returns:
        ElementArrays of the cells, in the given order.
    """
    mesh = V.mesh
    cell_type = mesh.topology.cell_type.name
    if cell_type not in ("hexahedron", "tetrahedron"):
        raise ValueError(f"element_arrays: hexahedral or tetrahedral cells only, the mesh has {cell_type}")
    element = V.element.basix_element
    if not element.dof_transformations_are_identity:
        raise NotImplementedError("element_arrays: the space needs dof transformations (not Lagrange Q1/Q2/P1/P2)")
    order = element.degree
    cells = np.asarray(cells, dtype=np.int32)
    reference_points, reference_weights = quadrature_rule(order, cell_type)

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
    weights = reference_weights[None, :] * np.abs(determinant)
    points = np.einsum("qg,cgi->cqi", coordinate_table[0], x)

    n_basis = element.dim
    cell_nodes = V.dofmap.list.array.reshape(-1, n_basis)[cells]
    return ElementArrays(cells=cells, cell_nodes=np.ascontiguousarray(cell_nodes, dtype=np.int32),
                         reference_gradients=np.ascontiguousarray(basis_gradients, dtype=np.float64),
                         inverse_jacobians=np.ascontiguousarray(inverse), weights=np.ascontiguousarray(weights),
                         points=np.ascontiguousarray(points),
                         tensor=tensor_tables(element, reference_points, basis_gradients))


def tensor_tables(element, reference_points: np.ndarray, basis_gradients: np.ndarray) -> tuple | None:
    """The tensor-product tables (node_order, point_order, basis, derivative) of a Q2 hexahedron
    and its 27-point Gauss rule for the kernel's sum factorisation (cpp_kernels/tensor_q2.hpp),
    or None for any other element or rule. Lexicographic index 9 i + 3 j + k of the node
    (x_i, x_j, x_k) or point (g_i, g_j, g_k); basis[g, n] = l_n(g), derivative[g, n] = l_n'(g) of
    the 1D Lagrange functions on the nodes. Checked: the tables reproduce the element's own
    reference gradients to round-off, or None is returned."""
    if element.degree != 2 or element.dim != 27 or len(reference_points) != 27:
        return None
    nodes_1d = np.unique(np.round(element.points, 12))
    gauss_1d = np.unique(np.round(reference_points, 12))
    if len(nodes_1d) != 3 or len(gauss_1d) != 3:
        return None

    def lexicographic_order(points, axis_values):
        index = np.abs(points[:, :, None] - axis_values[None, None, :]).argmin(axis=2)   # (27, 3)
        lex = 9 * index[:, 0] + 3 * index[:, 1] + index[:, 2]
        if sorted(lex.tolist()) != list(range(27)):
            return None
        order = np.empty(27, dtype=np.int32)
        order[lex] = np.arange(27, dtype=np.int32)
        return order

    node_order = lexicographic_order(element.points, nodes_1d)
    point_order = lexicographic_order(reference_points, gauss_1d)
    if node_order is None or point_order is None:
        return None
    basis = np.empty((3, 3))
    derivative = np.empty((3, 3))
    for n in range(3):
        others = [nodes_1d[m] for m in range(3) if m != n]
        scale = np.prod([nodes_1d[n] - o for o in others])
        basis[:, n] = (gauss_1d - others[0]) * (gauss_1d - others[1]) / scale
        derivative[:, n] = (2.0 * gauss_1d - others[0] - others[1]) / scale
    # Reference gradients from the tables, in the element's numbering, against basix's.
    lex = np.arange(27)
    i, j, k = lex // 9, (lex // 3) % 3, lex % 3
    rebuilt = np.empty((27, 27, 3))
    for p in range(27):
        for n in range(27):
            a, b, c = i[n], j[n], k[n]
            g, h, l = i[p], j[p], k[p]
            rebuilt[point_order[p], node_order[n]] = [derivative[g, a] * basis[h, b] * basis[l, c],
                                                      basis[g, a] * derivative[h, b] * basis[l, c],
                                                      basis[g, a] * basis[h, b] * derivative[l, c]]
    if np.abs(rebuilt - basis_gradients).max() > 1e-10 * np.abs(basis_gradients).max():
        return None
    return node_order, point_order, np.ascontiguousarray(basis), np.ascontiguousarray(derivative)


def _coordinate_element(mesh):
    """basix element of the mesh geometry (Lagrange of the coordinate map's degree)."""
    degree = mesh.geometry.cmap.degree
    if degree > 2:
        raise NotImplementedError(f"element_arrays: geometry of degree {degree} (only 1 and 2: the Lagrange "
                                  "variant of higher degrees is not known here)")
    return basix.create_element(basix.ElementFamily.P, getattr(basix.CellType, mesh.topology.cell_type.name), degree,
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


def add_matrices(first: scipy.sparse.bsr_matrix, *others) -> scipy.sparse.bsr_matrix:
    """The sum of BSR matrices with (3, 3) blocks, as BSR (3, 3) with sorted indices (N/m)."""
    total = first.tocsr()
    for other in others:
        total = total + other.tocsr()
    total = total.tobsr(blocksize=(3, 3))
    total.sort_indices()
    return total


def cells_in_zone(model, cells: np.ndarray, zone) -> np.ndarray:
    """The cells (sorted) whose centroid (mean of the geometry nodes) lies in the box zone =
    [xmin, ymin, zmin, xmax, ymax, zmax] (m); all of them for zone None."""
    cells = np.asarray(cells, dtype=np.int32)
    if zone is None or not len(cells):
        return cells
    mesh = model.mesh
    n_geometry = mesh.geometry.dofmap.offsets[1] - mesh.geometry.dofmap.offsets[0]
    centroids = mesh.geometry.x[mesh.geometry.dofmap.array.reshape(-1, n_geometry)[cells]].mean(axis=1)
    low, high = np.asarray(zone[:3], dtype=float), np.asarray(zone[3:], dtype=float)
    inside = np.all((centroids >= low) & (centroids <= high), axis=1)
    return cells[inside]


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


def initial_warnings(regions: NonlinearRegions, scene: typing.Mapping, comm=None) -> list[str]:
    """One line per thing a user should know about the regions' initial state: points whose initial
    stress is beyond the law's strength (returned or damaged at t = 0, the excess released as
    motion), concrete cells too large for the crack band (h > 2 E G_f / f_t^2: brittle), and
    concrete with one point per cell (blind to bending within a cell).

    comm: the ranks of a distributed model (pyfem/distributed_model.py), each holding the cells it
    counts of some regions: the counts are summed over the ranks (a collective, every rank the same
    lines); None: `regions` are the whole model's."""
    totals = {}  # region -> [points changed, points, cells too large, cells, largest h]
    for component, (name, arrays) in zip(regions.components, regions.arrays.items()):
        law, parameters = regions.laws[name]
        sigma0 = regions.initial_stress.get(name)
        changed = 0
        if sigma0 is not None:
            tolerance = 1e-9 * max(1.0, float(np.abs(sigma0).max()))
            changed = int(np.any(np.abs(component.stress() - sigma0) > tolerance, axis=2).sum())
        large, largest_h = 0, 0.0
        if law == "concrete_damage" and parameters.get("fracture_energy", 0.0) > 0.0:
            limit = 2.0 * parameters["young_modulus"] * parameters["fracture_energy"] / parameters["tensile_strength"] ** 2
            h = component.characteristic_length()
            large, largest_h = int(np.count_nonzero(h >= limit)), float(h.max(initial=0.0))
        totals[name] = [changed, int(arrays.weights.size), large, int(arrays.weights.shape[0]), largest_h]
    laws = dict(regions.laws)
    if comm is not None:  # every rank the same regions, in the same order
        pieces = comm.allgather((totals, laws))
        totals, laws = {}, {}
        for rank_totals, rank_laws in pieces:
            laws.update(rank_laws)
            for name, values in rank_totals.items():
                whole = totals.setdefault(name, [0, 0, 0, 0, 0.0])
                totals[name] = [a + b for a, b in zip(whole[:4], values[:4])] + [max(whole[4], values[4])]
    messages = []
    for name, (changed, points, large, _, largest_h) in totals.items():
        law, parameters = laws[name]
        table = {kernel_law: table for table, kernel_law in LAW_OF_TABLE.items()}.get(law)
        if table is None:
            continue
        if changed:
            messages.append(f"materials.{name}.{table}: {changed} of {points} points start "
                            "beyond the strength under [initial_stress]; their stress was returned to it "
                            "(damaged) at t = 0 and the excess is released as motion")
        if large:
            limit = 2.0 * parameters["young_modulus"] * parameters["fracture_energy"] / parameters["tensile_strength"] ** 2
            messages.append(f"materials.{name}.damage: {large} cells are larger "
                            f"than 2 E G_f / f_t^2 = {limit:.3g} m (up to {largest_h:.3g} m): the crack band "
                            "cannot regularise them and they crack brittly; refine the mesh there")
        if law == "concrete_damage" and regions.integration.get(name) == "reduced":
            messages.append(f"materials.{name}.damage.integration = \"reduced\": a one-point cell's law sees its "
                            "mean strain only, so bending within a cell does not crack it: a lining a few cells "
                            "thick cracks less (the small case 3: 3 050 instead of 3 820 m^3 after its static "
                            "stage; none instead of 3 700 m^3 in 1.5 s of shaking of a lining cast after full "
                            "relaxation; docs/materials.md \"One point per cell\")")
    return messages


def plastic_frequency_factor(poisson_ratio: float, friction_angle: float, dilation_angle: float) -> float:
    """Bound on how much non-associated Mohr-Coulomb flow can raise a frequency over the elastic one.

    On a yield plane with normal n and flow N the tangent is D - (D N)(D n)^T / (n . D N); the
    largest Rayleigh quotient of its symmetric part over that of D is 1 + (1/cos(theta) - 1)/2,
    theta the angle between D^1/2 N and D^1/2 n (0 for associated flow, psi = phi). Frequencies
    scale with the square root. Principal space, main plane; an estimate for the edges.

    Args:
        poisson_ratio: nu (-).
        friction_angle, dilation_angle: phi, psi (deg).
    """
    lame_over_shear = 2.0 * poisson_ratio / (1.0 - 2.0 * poisson_ratio)  # lambda / G
    elasticity = lame_over_shear * np.ones((3, 3)) + 2.0 * np.eye(3)        # D / G
    values, vectors = np.linalg.eigh(elasticity)
    root = vectors @ np.diag(np.sqrt(values)) @ vectors.T
    sin_phi, sin_psi = math.sin(math.radians(friction_angle)), math.sin(math.radians(dilation_angle))
    a = root @ np.array([1.0 + sin_psi, 0.0, -(1.0 - sin_psi)])
    b = root @ np.array([1.0 + sin_phi, 0.0, -(1.0 - sin_phi)])
    cosine = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.sqrt(1.0 + 0.5 * (1.0 / cosine - 1.0))


def scene_laws(scene: typing.Mapping) -> tuple[dict, dict]:
    """The element-loop laws of a validated scene: the regions whose material has a
    [plasticity] or [damage] table.

    Returns:
        (law_parameters, mean_dilatation): region -> {"law": name, **parameters (SI, deg)} as
        `nonlinear_component` takes them, and region -> bool (B-bar). Empty without such tables.
    """
    law_parameters, mean_dilatation = {}, {}
    excavated = set((scene.get("static") or {}).get("excavate") or ())  # gone from the model: no law
    for name, material in scene["materials"].items():
        if name in excavated:
            continue
        for table, law in LAW_OF_TABLE.items():
            settings = material.get(table)
            if settings is None:
                continue
            parameters = {key: value for key, value in settings.items() if key not in ("mean_dilatation", "zone")}
            if settings.get("zone") is not None:
                parameters["zone"] = list(settings["zone"])
            law_parameters[name] = {"law": law, "young_modulus": material["E"],
                                    "poisson_ratio": material["nu"], **parameters}
            mean_dilatation[name] = bool(settings.get("mean_dilatation") or False)
    return law_parameters, mean_dilatation


def split_law_parameters(given: typing.Mapping) -> tuple[str, list | None, str, dict]:
    """(law, zone or None, integration, the law's own parameters as floats) of one region's entry of
    `nonlinear_component`'s law_parameters (as `scene_laws` gives them)."""
    given = dict(given)
    law = given.pop("law", "linear_elastic")
    zone = given.pop("zone", None)
    integration = given.pop("integration", "full")
    return law, zone, integration, {key: float(value) for key, value in given.items()}


def nonlinear_component(model, region_names: typing.Sequence[str],
                        law_parameters: typing.Mapping[str, typing.Mapping] | None = None,
                        initial_stress=None, mean_dilatation: bool | typing.Mapping[str, bool] = False,
                        min_cells_for_threads: int | None = None) -> NonlinearRegions:
    """Kernel components for the regions whose material the element loop integrates, and the
    stiffness of all other cells.

    Stiffness-proportional Rayleigh damping (beta) of the component cells uses the law's initial
    elastic moduli (the kernel adds beta K0 v_{n+1/2}), so damping is unchanged by the split.

    Args:
        model: pyfem.operators.Model.
        region_names: regions (scene material names) to take out of the matrix.
        law_parameters: region -> {"law": name, **parameters (SI)}; a region not listed gets
            "linear_elastic" with the lambda and G of its material (Pa). Besides the law's own
            parameters: "zone" (a box, `cells_in_zone`) and "integration", "full" (default: the
            quadrature of the matrix) or "reduced" (Q1 only: one point per cell at its mean strain,
            the rest of the cells' elastic stiffness, K_hg, in the matrix; pyfem/reduced_integration.py).
        initial_stress: None, or a callable (m, 3) points (m) -> (m, 3, 3) static stress (Pa)
            evaluated at the quadrature points (the laws' total stress starts there; the force
            uses sigma - sigma0).
        mean_dilatation: B-bar (mean volumetric strain per cell) in every component, or
            region -> bool (absent: False).
        min_cells_for_threads: kernel threshold below which a component runs on one thread
            (None: the kernel's default).

    Returns:
        NonlinearRegions: stiffness (the kernel's K without springs), components, arrays, laws.
    """
    region_names = list(dict.fromkeys(region_names))
    law_parameters = dict(law_parameters or {})
    unknown = sorted(set(law_parameters) - set(region_names))
    if unknown:
        raise ValueError(f"law_parameters: regions {unknown} are not among region_names {region_names}")
    from pyfem.reduced_integration import hourglass_stiffness, lame_moduli, one_point_arrays

    arrays, laws, stresses, options, removed, zones, schemes, hourglass = {}, {}, {}, {}, [], {}, {}, {}
    for name in region_names:
        law, zone, schemes[name], parameters = split_law_parameters(
            law_parameters.get(name) or {"law": "linear_elastic", **region_elastic_parameters(model, name)})
        cells = cells_in_zone(model, region_cells(model, name), zone)
        if zone is not None:
            zones[name] = list(zone)
        if not len(cells):
            raise ValueError(f"materials.{name}.plasticity.zone = {law_parameters[name].get('zone')}: no cell of "
                             f"region {name!r} has its centroid in the box")
        region_arrays = element_arrays(model.V, cells)
        stresses[name] = (None if initial_stress is None
                          else quadrature_initial_stress(region_arrays.points, initial_stress))
        b_bar = bool(mean_dilatation if isinstance(mean_dilatation, bool) else mean_dilatation.get(name, False))
        options[name] = {"mean_dilatation": b_bar}
        if schemes[name] == "reduced":  # one point per cell, K_hg in the matrix (pyfem/reduced_integration.py)
            if law == "linear_elastic":
                lame = (parameters["lame_lambda"], parameters["shear_modulus"])
            else:
                lame = lame_moduli(parameters["young_modulus"], parameters["poisson_ratio"])
            one_point = one_point_arrays(region_arrays)
            hourglass[name] = hourglass_stiffness(region_arrays, one_point, *lame, b_bar, model.n_nodes)
            if stresses[name] is not None:  # the cell's mean initial stress, sum_q w_q sigma0_q / V
                stresses[name] = np.ascontiguousarray(
                    np.einsum("cq,cqk->ck", region_arrays.weights, stresses[name])[:, None, :]
                    / one_point.weights[:, :, None])
            region_arrays = one_point
            options[name]["mean_dilatation"] = False  # one point: its volumetric strain is the mean
        elif schemes[name] != "full":
            raise ValueError(f"integration of region {name!r}: {schemes[name]!r}, not 'full' or 'reduced'")
        if region_arrays.weights.shape[1] == 1:
            options[name]["mean_dilatation"] = False  # P1 tetrahedra: one point, its strain is the mean
        if min_cells_for_threads is not None:
            options[name]["min_cells_for_threads"] = int(min_cells_for_threads)
        arrays[name] = region_arrays
        laws[name] = (law, parameters)
        removed.append(cells)
    removed_cells = np.concatenate(removed) if removed else np.zeros(0, dtype=np.int32)
    stiffness = linear_stiffness(model, removed_cells)
    if hourglass:
        stiffness = add_matrices(stiffness, *hourglass.values())
    regions = NonlinearRegions(stiffness=stiffness, components=[], arrays=arrays, laws=laws,
                               initial_stress=stresses, options=options, zones=zones, integration=schemes,
                               hourglass=hourglass)
    regions.new_components()
    return regions

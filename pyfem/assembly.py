"""dolfinx assembly helpers shared by the operators, the interface pairs, the element arrays and
the static stage: nodal vectors, a facet measure over chosen facets, the lumped mass and the
elastic stiffness as a block-CSR matrix.

Numbering (docs/ARCHITECTURE.md): a node is a dof block of
VectorFunctionSpace(mesh, ("Lagrange", order)); dof = 3 * node + component.
This module imports no other pyfem module.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse
import ufl
from dolfinx import fem
from dolfinx import mesh as dolfinx_mesh
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

SPACE_DIMENSION = 3


def assemble_nodal_vector(linear_form: ufl.Form, V: fem.FunctionSpace) -> np.ndarray:
    """Assemble a linear form on the vector space V; returns (n_nodes, 3) owned + ghost values."""
    vector = fem_petsc.assemble_vector(fem.form(linear_form))
    vector.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    with vector.localForm() as local:
        values = local.array.copy()
    vector.destroy()
    return values.reshape(-1, SPACE_DIMENSION)


def facet_measure(mesh, facets: np.ndarray, quadrature: dict) -> ufl.Measure:
    """The ds measure over the given local facets only.

    A meshtags holding only these facets, always with marker 1, keeps the form signature the
    same for every facet set, so forms built on it compile once.
    """
    marker = 1
    facets = np.unique(np.asarray(facets, dtype=np.int32))
    tags = dolfinx_mesh.meshtags(mesh, mesh.topology.dim - 1, facets,
                                 np.full(len(facets), marker, dtype=np.int32))
    return ufl.Measure("ds", domain=mesh, subdomain_data=tags, subdomain_id=marker, metadata=quadrature)


def uses_diagonal_scaling(V: fem.FunctionSpace) -> bool:
    """Whether lumping on V must use HRZ diagonal scaling: quadratic (or higher) simplices, whose
    row sums are zero or negative at the vertices (P2 tetrahedron: -1/20 of the cell's mass per
    vertex; P2 triangle: 0 per vertex)."""
    return V.mesh.topology.cell_type.name in ("tetrahedron", "triangle") and V.ufl_element().degree() >= 2


def hrz_lumped_vector(coefficient, V: fem.FunctionSpace, measure: ufl.Measure, scale: bool = True) -> np.ndarray:
    """HRZ lumping (Hinton, Rock & Zienkiewicz 1976) of int coefficient phi_i over `measure` per node:
    the diagonal of the consistent matrix int c phi_i phi_j, scaled so that the total is int c.

    Per cell HRZ scales the cell's diagonal by int_cell c / sum_i M_ii; on affine simplices with c
    constant per cell (DG0 materials, the scene's straight-sided meshes) that ratio is the same
    number for every cell (M^e = c_e |J_e| M_ref), so one global factor is the per-cell HRZ
    exactly. Every value is positive for a positive c. scale=False: the diagonal alone (a weighting,
    e.g. of a facet normal whose components change sign). Returns (n_nodes,) values on V's nodes.
    """
    trial, test = ufl.TrialFunction(V), ufl.TestFunction(V)
    matrix = fem_petsc.assemble_matrix(fem.form(coefficient * ufl.inner(trial, test) * measure))
    matrix.assemble()
    diagonal = matrix.getDiagonal()  # the owned rows'
    matrix.destroy()
    held = fem.Function(V)  # the ghosts' diagonals from their owners (a distributed mesh)
    n_owned = V.dofmap.index_map.size_local
    held.x.array[:SPACE_DIMENSION * n_owned] = diagonal.array
    diagonal.destroy()
    held.x.scatter_forward()
    values = held.x.array.copy().reshape(-1, SPACE_DIMENSION)[:, 0]
    if not scale:
        return values
    ones = fem.Constant(V.mesh, np.ones(SPACE_DIMENSION, dtype=PETSc.ScalarType))
    # The row sums' total is int c exactly (the basis is a partition of unity); totals of the owned
    # nodes, summed over the ranks.
    comm = V.mesh.comm
    total = assemble_nodal_vector(coefficient * ufl.inner(ones, test) * measure, V)[:n_owned, 0].sum()
    trace = values[:n_owned].sum()
    if comm.size > 1:
        total, trace = comm.allreduce(float(total)), comm.allreduce(float(trace))
    return values * (total / trace) if trace != 0.0 else values


def lumped_mass(V: fem.FunctionSpace, rho: fem.Function, quadrature: dict) -> np.ndarray:
    """Lumped mass per node (kg): row sums M_i = int rho phi_i dx; on quadratic simplices (P2
    tetrahedra) HRZ diagonal scaling (`hrz_lumped_vector`), whose masses are all positive and
    sum to the body's mass.

    Raises:
        ValueError: if a node gets a lumped mass <= 0 (e.g. serendipity elements).
    """
    if uses_diagonal_scaling(V):
        mass = hrz_lumped_vector(rho, V, ufl.dx(metadata=quadrature))
        return _checked_positive(mass)
    test = ufl.TestFunction(V)
    ones = fem.Constant(V.mesh, np.ones(SPACE_DIMENSION, dtype=PETSc.ScalarType))
    per_dof = assemble_nodal_vector(rho * ufl.inner(ones, test) * ufl.dx(metadata=quadrature), V)
    # The vector form puts the same row sum on each component; keep one.
    mass = per_dof[:, 0].copy()
    if not np.allclose(per_dof, mass[:, None], rtol=1e-12, atol=0.0):
        raise RuntimeError("lumped mass differs between components of a node")
    return _checked_positive(mass)


def _checked_positive(mass: np.ndarray) -> np.ndarray:
    if not np.all(mass > 0.0):
        worst = int(np.argmin(mass))
        raise ValueError(f"lumped mass of node {worst} is {mass[worst]:.6g} kg: explicit stepping needs every "
                         "mass > 0")
    return mass


def elastic_stiffness(V: fem.FunctionSpace, lame_lambda: fem.Function, shear_modulus: fem.Function,
                      quadrature: dict) -> scipy.sparse.bsr_matrix:
    """Stiffness of linear isotropic elasticity, no boundary conditions, as BSR (3, 3) blocks (N/m),
    on one rank (`elastic_stiffness_matrix` for a mesh distributed over ranks).

    K_ij = int (2 G eps(phi_j) + lambda tr(eps(phi_j)) I) : eps(phi_i) dx.
    """
    matrix = elastic_stiffness_matrix(V, lame_lambda, shear_modulus, quadrature)
    indptr, indices, data = matrix.getValuesCSR()
    n_dofs = matrix.getSize()[0]
    matrix.destroy()
    csr = scipy.sparse.csr_matrix((data, indices, indptr), shape=(n_dofs, n_dofs))
    csr.sort_indices()  # a no-op when PETSc already returned sorted rows
    bsr = csr.tobsr(blocksize=(SPACE_DIMENSION, SPACE_DIMENSION))
    bsr.sort_indices()
    if bsr.nnz != csr.nnz:
        raise RuntimeError(f"stiffness pattern is not 3x3 blocked ({csr.nnz} entries, {bsr.nnz} in blocks)")
    return bsr


def elastic_stiffness_matrix(V: fem.FunctionSpace, lame_lambda: fem.Function, shear_modulus: fem.Function,
                             quadrature: dict) -> PETSc.Mat:
    """The elastic stiffness of `elastic_stiffness` as dolfinx assembles it: a PETSc matrix, on
    a distributed mesh each rank's owned rows (the caller destroys it)."""
    trial, test = ufl.TrialFunction(V), ufl.TestFunction(V)

    def strain(u):
        return ufl.sym(ufl.grad(u))

    stress = 2.0 * shear_modulus * strain(trial) + lame_lambda * ufl.tr(strain(trial)) * ufl.Identity(SPACE_DIMENSION)
    form = fem.form(ufl.inner(stress, strain(test)) * ufl.dx(metadata=quadrature))
    matrix = fem_petsc.assemble_matrix(form)
    matrix.assemble()
    return matrix

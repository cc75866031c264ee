"""The static stage: in-situ stress, excavation with partial relaxation, support installed
stress-free, solved as a linear-elastic problem (PETSc through petsc4py) on the very model the
dynamic run uses, and handed over to that run in equilibrium (docs/static.md).

The model is the dynamic one: the cells of `[static] excavate` are never in it (pyfem/mesh.py
drops them before dolfinx builds the mesh), so the dynamic run has no excavated cell, no orphan
node and a traction-free excavation surface. What the excavation does to the rock is the
out-of-balance force of the in-situ stress sigma0 on the body that remains,

    f_exc = int_Gt phi sigma0 n dS + int_rock phi b dV - int_rock B^T sigma0 dV,

Gt the truncation faces (the outer rock keeps pushing on them with sigma0 n), b the body force
sigma0 is in equilibrium with (-div sigma0: zero for a uniform stress, the overburden's weight for
the geostatic form; with `gravity = true` the materials' own weight instead). For an
equilibrated sigma0 this is exactly -int_S phi sigma0 n dS over the traction-free surfaces S
the remaining body has (the excavation surface, or a cavity already in the mesh): the traction
the removed rock exerted is released, pointing into the opening.

Stages (u = 0 at the start, lambda = `relaxation`):
    1. the `install` regions are absent too (their cells out of K, nodes only they use held);
       K_rock u1 = lambda f_exc.
    2. the `install` regions join stress-free: K u2 = (1 - lambda) f_exc (+ their weight with
       gravity).
    stress: sigma0 + C : eps(u1 + u2) in the rock, C : eps(u2) in the installed regions.
Truncation faces are rollers during the stage unless `[static.boundary]` says otherwise; contact
pairs are bonded (their two nodes move together).

Hand-over: the dynamic run starts from u = v = 0 with this stress as its initial stress (monitors,
fields, the pairs' static forces F0). Its kernel solves for the increment over the stage's state,
which assumes the stage's external forces stay: the in-situ traction on Gt, the body force and the
support reactions of the stage (held as constant forces on the truncation faces) and the pair
forces F0. What the state is not in equilibrium with, the linear solve's out-of-balance
g = F_held - f_int(sigma_static), is applied to the dynamic run as a constant external force, so the
run is the one a total-stress formulation would make; a run with no wave stays at rest to that
out-of-balance (tests/test_static.py).

Linear only: a region with a [plasticity] or [damage] table stops the stage with an error (the
dynamic-relaxation stage for nonlinear materials is not written yet).
"""
from __future__ import annotations

import dataclasses
import math
import typing

import numpy as np
import scipy.sparse as sp

from pyfem.scene import SceneError

SPACE_DIMENSION = 3
# Largest reduced system solved by a direct factorisation (MUMPS Cholesky); above it CG + GAMG
# (the coarse layered cavern, 136 000 unknowns: 45 s with CG + GAMG, 200 s with MUMPS here).
DIRECT_SOLVER_LIMIT = 50_000
# A node's held directions: eigenvalues of the summed held projections above this are held.
_HELD_TOLERANCE = 1.0e-6
SUMMARY_KEYS = ("name", "solver", "iterations", "residual", "converged", "seconds", "max_displacement",
                "free_dofs", "load_fraction")
"""What run.json's "static" keeps of each Stage."""
LINEAR_TOLERANCE = 1.0e-8
"""Default static.tolerance of the linear solve (relative residual)."""
RELAXATION_TOLERANCE = 1.0e-5
"""Default static.tolerance of dynamic relaxation (out-of-balance force ratio ||r|| / ||f||)."""
LINEAR_ONLY = ("solves linear elastic stages only: a material with [plasticity] or [damage] needs "
               "static.solver = \"relaxation\" (or \"auto\", which chooses it)")


# ---------------------------------------------------------------------------------------------
# Scene checks and the stage's boundary
# ---------------------------------------------------------------------------------------------

def uses_relaxation(scene: typing.Mapping) -> bool:
    """The stage is solved by dynamic relaxation: static.solver = "relaxation", or "auto" with a
    [plasticity] or [damage] table."""
    solver = scene["static"]["solver"]
    if solver in ("direct", "iterative"):
        return False
    return solver == "relaxation" or bool(scene["static"].get("support") or scene["static"].get("step")) or any(material.get(table) is not None for material in scene["materials"].values()
                                         for table in ("plasticity", "damage"))


def stage_tolerance(scene: typing.Mapping) -> float:
    """static.tolerance, or its default for the stage's solver."""
    given = scene["static"]["tolerance"]
    if given is not None:
        return float(given)
    return RELAXATION_TOLERANCE if uses_relaxation(scene) else LINEAR_TOLERANCE


def check_linear(scene: typing.Mapping) -> None:
    """A linear solver (static.solver "direct" or "iterative") needs every material linear elastic.

    Raises:
        SceneError naming the solver and the first nonlinear material table.
    """
    if uses_relaxation(scene):
        return
    if scene["static"].get("support"):
        solver = scene["static"]["solver"]
        raise SceneError("static.solver", solver, f"static.solver = \"{solver}\" solves linear elastic stages "
                         "only: support groups (static.support) slip and yield, and need static.solver = "
                         "\"relaxation\" (or \"auto\", which chooses it)")
    for name, material in scene["materials"].items():
        for table in ("plasticity", "damage"):
            if material.get(table) is not None:
                solver = scene["static"]["solver"]
                raise SceneError("static.solver", solver, f"static.solver = \"{solver}\" {LINEAR_ONLY} "
                                 f"(materials.{name}.{table} is set)")


def stage_boundary(scene: typing.Mapping, model) -> dict[str, str]:
    """Type of each truncation face during the stage: `static.boundary.face.NAME.type`, else
    `static.boundary.type` (default "roller").

    Raises:
        SceneError: a `static.boundary.face.NAME` table names no truncation face.
    """
    boundary = scene["static"]["boundary"]
    names = [face.name for face in model.faces]
    per_face = boundary.get("face") or {}
    for name, table in per_face.items():
        if name not in names:
            raise SceneError(f"static.boundary.face.{name}", table,
                             "tables named after truncation faces: " + (", ".join(names) or "none found"))
    return {name: (per_face.get(name) or {}).get("type") or boundary["type"] for name in names}


def _install_cells(scene: typing.Mapping, model) -> tuple[list, np.ndarray]:
    """Names and local cells of the `install` regions."""
    from pyfem.elements import region_cells

    names = list(scene["static"]["install"])
    cells = []
    for index, name in enumerate(names):
        if name not in model.regions:
            raise SceneError(f"static.install.{index}", name, "must name a region of the model: "
                             + ", ".join(sorted(model.regions)))
        cells.append(region_cells(model, name))
    if names and len(names) == len(model.regions):
        raise SceneError("static.install", names, "must leave some region in place for stage 1 (the rock)")
    if not cells:
        return names, np.zeros(0, dtype=np.int32)
    return names, np.unique(np.concatenate(cells)).astype(np.int32)


# ---------------------------------------------------------------------------------------------
# Loads: f_exc from dolfinx forms
# ---------------------------------------------------------------------------------------------

def initial_stress_expression(scene: typing.Mapping, mesh):
    """(sigma0 as a UFL 3x3 expression, the body force b = -div sigma0 as a 3-vector or None), or
    (None, None) without [initial_stress]."""
    import ufl
    from dolfinx import fem

    from pyfem.initial_stress import STANDARD_GRAVITY, stress_tensor

    settings = scene.get("initial_stress")
    if settings is None:
        return None, None
    if settings.get("stress") is not None:
        return fem.Constant(mesh, stress_tensor(settings["stress"])), None
    k_x, k_y, k_z = settings["k"]
    weight = settings["rho"] * STANDARD_GRAVITY
    vertical = -weight * (settings["surface"] - ufl.SpatialCoordinate(mesh)[2])
    sigma0 = ufl.as_matrix([[k_x * vertical, 0, 0], [0, k_y * vertical, 0], [0, 0, k_z * vertical]])
    # d sigma_zz / dz = k_z rho g: the field balances a body force -k_z rho g e_z.
    return sigma0, fem.Constant(mesh, np.array([0.0, 0.0, -k_z * weight]))


@dataclasses.dataclass
class StageLoads:
    """Nodal loads (n_nodes, 3) of the stage (N)."""

    excavation: np.ndarray      # f_exc over the rock (stage-1 body)
    in_situ_traction: np.ndarray  # int_Gt phi sigma0 n over the rock's truncation facets
    body: np.ndarray            # int_rock phi b
    installed_weight: np.ndarray  # the installed regions' weight (gravity = true), else 0


def stage_loads(scene: typing.Mapping, model, installed_cells: np.ndarray) -> StageLoads:
    """f_exc = int_Gt phi sigma0 n + int_rock phi b - int_rock grad(phi) : sigma0 and the
    installed regions' weight, assembled by dolfinx over the rock's cells only (a DG0 indicator,
    as pyfem.elements.linear_stiffness zeroes moduli)."""
    import ufl
    from dolfinx import fem
    from dolfinx import mesh as dolfinx_mesh

    from pyfem.initial_stress import STANDARD_GRAVITY
    from pyfem.operators import assemble_nodal_vector, truncation_faces

    V, mesh = model.V, model.mesh
    materials = model._materials
    n_nodes = model.n_nodes
    rock = fem.Function(materials.rho.function_space)
    rock.x.array[:] = 1.0
    rock.x.array[materials.dof_of_cell[installed_cells]] = 0.0
    installed = fem.Function(materials.rho.function_space)
    installed.x.array[:] = 1.0 - rock.x.array
    v = ufl.TestFunction(V)
    metadata = {"quadrature_degree": 2 * model.order + 1}
    dx = ufl.dx(domain=mesh, metadata=metadata)
    zero = np.zeros((n_nodes, SPACE_DIMENSION))

    sigma0, body_force = initial_stress_expression(scene, mesh)
    gravity = scene["static"]["gravity"]
    if gravity:
        body_force = materials.rho * fem.Constant(mesh, np.array([0.0, 0.0, -STANDARD_GRAVITY]))
    body = zero if body_force is None else assemble_nodal_vector(rock * ufl.inner(body_force, v) * dx, V)
    installed_weight = zero
    if gravity and mesh.comm.allreduce(len(installed_cells)):  # (collective: the distributed model's ranks)
        installed_weight = assemble_nodal_vector(installed * ufl.inner(body_force, v) * dx, V)
    if sigma0 is None:
        return StageLoads(excavation=body.copy(), in_situ_traction=zero, body=body,
                          installed_weight=installed_weight)
    internal = assemble_nodal_vector(rock * ufl.inner(sigma0, ufl.grad(v)) * dx, V)
    faces, _ = truncation_faces(scene, mesh, model.facet_tags, model.boundaries, model.interface_tags)
    facets = (np.unique(np.concatenate([f for f, _ in faces.values()])) if faces
              else np.zeros(0, dtype=np.int32))
    marker = 1
    tags = dolfinx_mesh.meshtags(mesh, mesh.topology.dim - 1, facets.astype(np.int32),
                                 np.full(len(facets), marker, dtype=np.int32))
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags, subdomain_id=marker, metadata=metadata)
    traction = assemble_nodal_vector(rock * ufl.inner(ufl.dot(sigma0, ufl.FacetNormal(mesh)), v) * ds, V)
    return StageLoads(excavation=traction + body - internal, in_situ_traction=traction, body=body,
                      installed_weight=installed_weight)


# ---------------------------------------------------------------------------------------------
# The reduced system: held directions, bonded pairs, orphan nodes
# ---------------------------------------------------------------------------------------------

@dataclasses.dataclass
class FreeBasis:
    """u = T w: the displacements the stage allows, in reduced unknowns w.

    Attributes:
        T: (n_dofs, m) CSR, orthonormal 3 x m_g blocks per node (m_g free directions of its group).
        projection: (n_nodes, 3, 3) projection onto each node's free directions (I for most).
        group: (n_nodes,) group of each node (bonded pair nodes share one).
    """

    T: sp.csr_matrix
    projection: np.ndarray
    group: np.ndarray


def free_basis(n_nodes: int, held_nodes: np.ndarray, held_projection: np.ndarray, pairs: np.ndarray | None,
               inactive_nodes: np.ndarray) -> FreeBasis:
    """The free directions of every node during a stage.

    Args:
        n_nodes: nodes of the model.
        held_nodes: (k,) nodes of the held faces; held_projection (k, 3, 3) their free projections
            (pyfem.effects.boundary_constraints: 0 fixed, I - n n^T roller).
        pairs: (p, 2) contact pair nodes, bonded: both nodes of a pair move together; or None.
        inactive_nodes: nodes no active cell uses (held at zero unless bonded to an active node).
    """
    if pairs is not None and len(pairs):
        graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_nodes, n_nodes))
        _, group = sp.csgraph.connected_components(graph, directed=False)
    else:
        group = np.arange(n_nodes)
    n_groups = int(group.max(initial=-1)) + 1
    held = np.zeros((n_groups, 3, 3))
    np.add.at(held, group[held_nodes], np.eye(3)[None] - held_projection)
    active_members = (np.bincount(group, minlength=n_groups)
                      - np.bincount(group[inactive_nodes], minlength=n_groups))
    held[active_members == 0] = np.eye(3)
    special = np.flatnonzero(np.abs(held).reshape(n_groups, -1).max(axis=1) > 0.0)
    # Free directions of the held groups: eigenvectors of the summed held projections with eigenvalue 0.
    eigenvalues, eigenvectors = np.linalg.eigh(held[special])                       # (s, 3), (s, 3, 3)
    free = eigenvalues <= _HELD_TOLERANCE * np.maximum(1.0, eigenvalues.max(axis=1, initial=0.0))[:, None]
    n_columns = np.full(n_groups, 3, dtype=np.int64)
    n_columns[special] = free.sum(axis=1)
    offsets = np.concatenate([[0], np.cumsum(n_columns)])
    special_index = np.full(n_groups, -1, dtype=np.int64)
    special_index[special] = np.arange(len(special))
    plain = np.flatnonzero(special_index[group] < 0)
    held_nodes_all = np.flatnonzero(special_index[group] >= 0)
    # Plain nodes: identity blocks.
    rows = [(3 * plain[:, None] + np.arange(3)).ravel()]
    columns = [(offsets[group[plain]][:, None] + np.arange(3)).ravel()]
    values = [np.ones(3 * len(plain))]
    # Held nodes: T[3 node + a, offset + rank(e)] = eigenvector e's component a, for the free e.
    k = special_index[group[held_nodes_all]]
    rank = np.cumsum(free, axis=1) - 1                                              # (s, 3)
    mask = np.broadcast_to(free[k][:, None, :], (len(k), 3, 3))
    component_rows = 3 * held_nodes_all[:, None, None] + np.arange(3)[None, :, None]
    rows.append(np.broadcast_to(component_rows, mask.shape)[mask])
    columns.append(np.broadcast_to(offsets[group[held_nodes_all]][:, None, None] + rank[k][:, None, :],
                                   mask.shape)[mask])
    values.append(eigenvectors[k][mask])
    projection = np.repeat(np.eye(3)[None], n_nodes, axis=0)
    projection[held_nodes_all] = np.einsum("nae,ne,nbe->nab", eigenvectors[k], free[k].astype(float),
                                           eigenvectors[k])
    T = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
                      shape=(3 * n_nodes, int(offsets[-1])))
    return FreeBasis(T=T, projection=projection, group=group)


def rigid_body_modes(node_coords: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
    """(3 n, 6) translations and rotations about `centre` (default: the nodes' centroid): the near
    null space of elasticity."""
    x = node_coords - (node_coords.mean(axis=0) if centre is None else np.asarray(centre))
    n = len(x)
    modes = np.zeros((n, 3, 6))
    for axis in range(3):
        modes[:, axis, axis] = 1.0
    # Rotation about e_k: e_k x (x - c).
    for k in range(3):
        modes[:, :, 3 + k] = np.cross(np.eye(3)[k][None], x)
    return modes.reshape(3 * n, 6)


def check_held(basis: FreeBasis, node_coords: np.ndarray, inactive_nodes: np.ndarray, boundary: dict,
               comm=None, centre: np.ndarray | None = None) -> None:
    """The stage's boundary must hold the active body: no rigid-body motion may lie in the range of T.
    Under the distributed model (`comm`, pyfem/distributed_stage.py) each rank checks the nodes it
    steps, about the whole model's centroid `centre`, and the sums are taken over the ranks.

    Raises:
        SceneError (static.boundary) naming the motions left free.
    """
    modes = rigid_body_modes(node_coords, centre)
    rows = np.ones(len(node_coords), dtype=bool)
    rows[inactive_nodes] = False
    rows = np.repeat(rows, 3)
    # The part of each mode the stage forbids: modes - P modes, P the orthogonal projection onto the range
    # of T. T's columns are orthogonal, each of squared norm its group's node count (a bonded pair's two
    # nodes share columns), so P = T diag(1 / |column|^2) T^T (T T^T alone doubled a pair's nodes'
    # modes, and a floating model with pairs was not refused).
    norms = np.asarray(basis.T.multiply(basis.T).sum(axis=0)).ravel()
    outside = (modes - basis.T @ ((basis.T.T @ modes) / np.where(norms > 0.0, norms, 1.0)[:, None]))[rows]
    gram = outside.T @ outside
    scale = np.sum(modes[rows] ** 2, axis=0)
    if comm is not None:
        gram, scale = comm.allreduce(gram), comm.allreduce(scale)
    scale = np.max(scale)
    values, vectors = np.linalg.eigh(gram)
    free = vectors[:, values <= 1e-10 * scale]
    if free.shape[1]:
        names = ("x", "y", "z", "rotation about x", "rotation about y", "rotation about z")
        motions = sorted({names[int(np.argmax(np.abs(column)))] for column in free.T})
        raise SceneError("static.boundary", boundary, "the faces held during the stage (roller or "
                         "fixed) must keep the model from moving as a rigid body; these faces leave it "
                         f"free to move ({', '.join(motions)}): hold more faces "
                         "(static.boundary.type = \"roller\", the default)")


def _orthonormal_columns(vectors: np.ndarray, comm) -> np.ndarray:
    """The columns of `vectors` (this rank's rows of a matrix split by rows over `comm`) made
    orthonormal over the ranks (the Gram matrix summed; its null directions dropped)."""
    gram = comm.allreduce(vectors.T @ vectors)
    values, directions = np.linalg.eigh(gram)
    keep = values > 1e-12 * max(float(values.max(initial=0.0)), 1e-300)
    return vectors @ (directions[:, keep] / np.sqrt(values[keep]))


class LinearSolver:
    """K w = f for a symmetric positive definite reduced stiffness, with PETSc (petsc4py).

    Direct (MUMPS Cholesky when PETSc has MUMPS, else PETSc's LU) up to DIRECT_SOLVER_LIMIT
    unknowns or when asked; above, CG with smoothed-aggregation AMG (GAMG) given the rigid-body
    modes as near null space, to the relative residual `tolerance`. With `comm` of several ranks
    (the distributed model's linear stage, pyfem/distributed_linear.py) `matrix` is this rank's
    rows of the reduced system (global column numbers), the vectors its rows, and PETSc solves
    across the ranks (MUMPS in parallel, or CG + GAMG); on one rank the arithmetic is the serial one.
    """

    def __init__(self, matrix: sp.csr_matrix, tolerance: float, choice: str = "auto",
                 near_null_space: np.ndarray | None = None, comm=None):
        from petsc4py import PETSc

        self._comm = comm if comm is not None and comm.size > 1 else None
        rows, n = matrix.shape[0], matrix.shape[1]
        if self._comm is not None and near_null_space is not None:
            near_null_space = _orthonormal_columns(near_null_space, self._comm)
        self.method = choice if choice != "auto" else ("direct" if n <= DIRECT_SOLVER_LIMIT else "iterative")
        has_mumps = PETSc.Sys.hasExternalPackage("mumps")
        self.tolerance = tolerance
        self.matrix = matrix
        petsc_comm = PETSc.COMM_SELF if self._comm is None else self._comm
        self._petsc_comm = petsc_comm
        self._size = (rows, n)
        matrix = matrix.tocsr()
        matrix.sort_indices()
        csr = (matrix.indptr.astype(PETSc.IntType), matrix.indices.astype(PETSc.IntType),
               np.ascontiguousarray(matrix.data, dtype=np.float64))
        self._A = PETSc.Mat().createAIJ(size=(self._size, self._size), csr=csr, comm=petsc_comm)
        self._A.assemble()
        ksp = PETSc.KSP().create(petsc_comm)
        ksp.setOperators(self._A)
        pc = ksp.getPC()
        if self.method == "direct":
            ksp.setType("preonly")
            if has_mumps or self._comm is not None:  # (PETSc's own LU is serial)
                pc.setType("cholesky")
                pc.setFactorSolverType("mumps")
                self.name = "direct (MUMPS Cholesky)"
            else:
                pc.setType("lu")
                self.name = "direct (PETSc LU)"
        else:
            ksp.setType("cg")
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)  # the tolerance is on ||f - K w|| / ||f||
            pc.setType("gamg")
            if near_null_space is not None and near_null_space.shape[1]:
                basis = near_null_space if self._comm is not None else np.linalg.qr(near_null_space)[0]
                vectors = [self._vector(column) for column in basis.T]
                self._null_space = PETSc.NullSpace().create(vectors=vectors, comm=petsc_comm)
                self._A.setNearNullSpace(self._null_space)
            ksp.setTolerances(rtol=tolerance, atol=0.0, max_it=max(1000, 10 * int(math.sqrt(n))))
            self.name = "iterative (CG + GAMG)"
        self._ksp = ksp

    def _vector(self, whole: np.ndarray):
        """A PETSc vector of `whole` (n,) (copied)."""
        from petsc4py import PETSc

        return PETSc.Vec().createWithArray(np.array(whole, dtype=np.float64), size=self._size,
                                           comm=self._petsc_comm)

    def _norm(self, x: np.ndarray) -> float:
        if self._comm is None:
            return float(np.linalg.norm(x))
        return math.sqrt(self._comm.allreduce(float(x @ x)))

    def solve(self, rhs: np.ndarray) -> tuple[np.ndarray, int, float]:
        """(w, iterations, ||f - K w|| / ||f||).

        Raises:
            RuntimeError: the factorisation failed (a singular stiffness: the model is not held)
                or CG did not reach the tolerance.
        """
        from petsc4py import PETSc

        norm = self._norm(rhs)
        if norm == 0.0:
            return np.zeros_like(rhs), 0, 0.0
        b = self._vector(rhs)
        x = b.duplicate()
        try:
            self._ksp.solve(b, x)
        except PETSc.Error as error:
            raise RuntimeError(f"the static stage's stiffness could not be factorised ({error}): it is "
                               "singular when the held faces leave the model free to move as a rigid body; "
                               "hold more faces ([static.boundary])") from None
        w = x.getArray().copy()
        if self._comm is None:
            residual = float(np.linalg.norm(rhs - self.matrix @ w)) / norm
        else:  # (this rank's rows of K w: PETSc's product over the ranks)
            product = b.duplicate()
            self._A.mult(x, product)
            residual = self._norm(rhs - product.getArray()) / norm
        if self._comm is not None:  # (every rank raises alike below)
            from mpi4py import MPI

            if not self._comm.allreduce(bool(np.all(np.isfinite(w))), op=MPI.LAND):
                w = np.full_like(w, np.nan)
        iterations = max(1, self._ksp.getIterationNumber()) if self.method == "iterative" else 1
        # A direct solve is not iterated to the tolerance: a residual far above round-off there means
        # a (nearly) singular stiffness.
        limit = self.tolerance if self.method == "iterative" else max(self.tolerance, 1.0e-6)
        if not np.all(np.isfinite(w)) or residual > limit:
            raise RuntimeError(f"the static solve ({self.name}) reached a relative residual {residual:.3g} "
                               f"after {iterations} iterations, above static.tolerance = {self.tolerance:g} "
                               f"(KSP reason {self._ksp.getConvergedReason()}); a singular stiffness "
                               "(a model free to move) does this: hold more faces ([static.boundary])")
        return w, iterations, residual


# ---------------------------------------------------------------------------------------------
# The stage
# ---------------------------------------------------------------------------------------------

def _stage_constraints(model, boundary: dict[str, str]):
    """(held nodes, free projections, BoundaryConstraints or None) of the stage's fixed and roller faces."""
    from pyfem.effects import boundary_constraints

    faces = [dataclasses.replace(face, kind=boundary[face.name]) for face in model.faces]
    constraints = boundary_constraints(faces)
    if constraints is None:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3, 3)), None
    return constraints.nodes.astype(np.int64), constraints.projection, constraints


def face_support_resultants(faces, boundary: dict[str, str], support: np.ndarray) -> dict[str, list]:
    """Resultant support force (N) of each held face: a node's reaction is split among the faces
    holding it along the directions each holds (a roller its normal, a fixed face any), by least
    squares, so an edge node's vertical reaction goes to the floor and not to a side roller."""
    entries = []   # (node, face index, direction)
    held = [face for face in faces if boundary[face.name] in ("roller", "fixed")]
    for index, face in enumerate(held):
        nodes = np.asarray(face.nodes, dtype=np.int64)
        if boundary[face.name] == "fixed":
            directions = np.repeat(np.eye(3)[None], len(nodes), axis=0)
        else:
            directions = np.asarray(face.normal, dtype=float)[:, None, :]
        for k in range(directions.shape[1]):
            entries.append((nodes, np.full(len(nodes), index), directions[:, k, :]))
    resultants = np.zeros((len(held), 3))
    if not entries:
        return {}
    nodes = np.concatenate([e[0] for e in entries])
    face_of = np.concatenate([e[1] for e in entries])
    direction = np.concatenate([e[2] for e in entries])
    order = np.argsort(nodes, kind="stable")
    nodes, face_of, direction = nodes[order], face_of[order], direction[order]
    starts = np.flatnonzero(np.concatenate([[True], nodes[1:] != nodes[:-1]]))
    ends = np.concatenate([starts[1:], [len(nodes)]])
    single = ends - starts == 1  # held along one direction only (most roller nodes): its component
    one = starts[single]
    np.add.at(resultants, face_of[one],
              np.einsum("nc,nc->n", direction[one], support[nodes[one]])[:, None] * direction[one])
    for start, end in zip(starts[~single], ends[~single]):
        R = support[nodes[start]]
        D = direction[start:end]                                  # (k, 3) held directions
        alpha = np.linalg.lstsq(D.T, R, rcond=None)[0]
        np.add.at(resultants, face_of[start:end], alpha[:, None] * D)
    return {face.name: resultants[k].tolist() for k, face in enumerate(held)}


# ---------------------------------------------------------------------------------------------
# The nonlinear stage: dynamic relaxation with the kernel
# ---------------------------------------------------------------------------------------------

def _pair_force_vector(n_nodes: int, contact_arrays: dict) -> np.ndarray:
    """(3 n_nodes,) the pairs' static forces as nodal forces: F0 on node i, -F0 on node j."""
    force = np.zeros((n_nodes, 3))
    pairs = np.asarray(contact_arrays["pairs"], dtype=np.int64)
    F0 = np.asarray(contact_arrays["static_force"], dtype=np.float64)
    np.add.at(force, pairs[:, 0], F0)
    np.add.at(force, pairs[:, 1], -F0)
    return force.ravel()


WELDED_STRENGTH = 1.0e300
"""Cohesion and tensile strength (Pa) of a welded pair in the stage (`contact.split = "after_static"`):
finite, as the kernel requires, and beyond any force, so the pair stays bonded (the kernel's bonded
pair is the unsplit mesh to round-off)."""


def welded(scene: typing.Mapping) -> bool:
    """The stage runs with the pairs welded (`contact.split = "after_static"`)."""
    return "contact" in scene and scene["contact"].get("split", "before_static") == "after_static"


def stage_pair_arrays(scene: typing.Mapping, contact_arrays: dict | None) -> dict | None:
    """The pairs' arrays as the relaxation stage runs them (every model): no deterioration (the wear's
    clock starts with the record), a broken bond released at once (`contact.release_time` is the
    dynamic run's) and, with `contact.split = "after_static"`, welded (cohesion and
    tensile strength `WELDED_STRENGTH`, so no force breaks the bond)."""
    if contact_arrays is None:
        return None
    arrays = dict(contact_arrays, deterioration=None, release_time=None)
    if welded(scene):
        arrays.update(cohesion=WELDED_STRENGTH, tensile_strength=WELDED_STRENGTH)
    return arrays


def _stage_stepper(stiffness, mass: np.ndarray, constraints, load: np.ndarray, components: list, contact,
                   ramp: float = 0.0):
    """A kernel Stepper for one relaxation stage: the matrix cells, the scaled mass (dt = 1, no
    damping yet), the stage's held faces, the constant load, the components and the pairs."""
    from pyfem.effects import bsr_arrays, kernel_threads

    kernel_threads()
    return stage_kernel(bsr_arrays(stiffness.tobsr(blocksize=(3, 3))), mass, constraints, load, components,
                        contact, ramp)


def stage_kernel(matrix: tuple, mass: np.ndarray, constraints, load: np.ndarray, components: list, contact,
                 ramp: float = 0.0, halo: list = ()):
    """The kernel Stepper of a relaxation stage from its matrix's (indptr, indices, blocks): the
    scaled mass, dt = 1 and no damping yet, the held faces, the load rising over `ramp`, the
    components, an MPI rank's `halo` components (their energy their owner's) and the pairs."""
    from pyfem import _kernels
    from pyfem.relaxation import PSEUDO_STEP

    stepper = _kernels.Stepper(*matrix, mass, PSEUDO_STEP, 0.0, 0.0)
    if constraints is not None:
        stepper.set_constraints(np.ascontiguousarray(constraints.nodes, dtype=np.int32),
                                np.ascontiguousarray(constraints.projection, dtype=np.float64))
    if np.any(load):
        stepper.add_provider(hand_over_force_provider(load, ramp))
    for component in components:
        stepper.add_internal_force(component)
    for component in halo:
        stepper.add_internal_force(component, count_energy=False)
    if contact is not None:
        stepper.add_contact(contact)
    return stepper


def unconverged_warning(name: str, tolerance: float, max_steps: int, result, ramp: float) -> str:
    """The warning of a relaxation stage that did not reach its tolerance (both models)."""
    from pyfem.relaxation import PSEUDO_STEP, load_factor

    applied_share = load_factor(result.steps * PSEUDO_STEP, ramp)
    ramp_words = ("" if applied_share >= 1.0 else
                  f"; the load was still rising: {100.0 * applied_share:.0f} % of it applied (its ramp is "
                  f"{ramp:.0f} steps)")
    return (f"static: the {name} stage did not reach static.tolerance = {tolerance:g} in static.max_steps = "
            f"{max_steps} relaxation steps (out-of-balance ratio {result.residual:.3g} of the whole load{ramp_words}): "
            "the model may be collapsing (plastic flow without end) or need more steps; its state is handed over as "
            "it is and the dynamic run starts at rest from it, the out-of-balance not applied: the static state is "
            "wrong by about that share of the load (not in equilibrium with all of it)")


# ---------------------------------------------------------------------------------------------
# Hand-over to the dynamic run
# ---------------------------------------------------------------------------------------------

def static_stress(strain_stress, installed: np.ndarray, u_total: np.ndarray,
                  u_support: np.ndarray) -> np.ndarray:
    """(m, 3, 3) static stress at points (Pa): sigma0 + C : eps(u1 + u2) in the rock, C : eps(u2) in the
    installed regions (stress-free when they joined).

    Args:
        strain_stress: callable u -> (m, 3, 3) C : eps(u) at the points.
        installed: (m,) bool, the point lies in an installed region.
        u_total: u1 + u2 (dofs, m); u_support: u2 (dofs, m).
    """
    total = strain_stress(u_total)
    if np.any(installed):
        total[installed] = strain_stress(u_support)[installed]
    return total


def warn_pairs_over_strength(scene, contact_arrays: dict, comm=None) -> None:
    """The warning of pairs the stage hands over beyond their strength at D = 1 (a linear stage keeps
    them bonded; `contact.split = "after_static"` welds them); `comm`: the distributed model's ranks'
    pairs counted together."""
    over = pairs_over_strength(contact_arrays)
    if comm is not None:
        over = {key: comm.allreduce(count) for key, count in over.items()}
    if not (over["opening"] or over["sliding"]):
        return
    beyond = (f"static: {over['opening']} contact pairs are in tension beyond their tensile strength and "
              f"{over['sliding']} beyond their shear strength at the end of the stage")
    if welded(scene):
        scene.warn(f"{beyond} (contact.split = \"after_static\": the stage ran welded): they open or slide in the "
                   "first steps of the dynamic run, before the wave arrives")
    else:
        scene.warn(f"{beyond} (a linear stage keeps pairs bonded): they open or slide in the first steps of the "
                   "dynamic run, a sudden release that is not the earthquake's; static.solver = \"relaxation\" "
                   "lets them open or slide during the stage")


def monitor_static_stress(monitors, installed_regions, u_total: np.ndarray, u_support: np.ndarray,
                          components: list | None) -> np.ndarray:
    """(m, 3, 3) the stage's stress at the monitors (pyfem.effects.MonitorStress, its `static` still
    the in-situ stress): sigma0 + C : eps(u_total) in the rock, C : eps(u_support) in the installed
    regions, and where the monitor's cell is in the element loop (a relaxed stage's `components`, in
    the monitors' kernel_points' order) the law's stress at its point. Both models' hand-over."""
    from pyfem.elements import voigt_tensor

    installed = np.array([region in installed_regions for region in monitors.regions], dtype=bool)
    sigma = static_stress(monitors.dynamic_stress, installed, u_total, u_support)
    sigma[~installed] += monitors.static[~installed]
    if components is not None and monitors.kernel_points is not None:
        for j, found in enumerate(monitors.kernel_points):
            if found is not None:
                sigma[j] = voigt_tensor(components[found[0]].stress(np.array([found[1]], dtype=np.int64)))[0]
    return sigma


def normal_and_shear(force: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, T) of pair forces (p, 3) on unit normals (p, 3): N = -n.F, compression positive, and
    T = |F + N n|, the shear's magnitude."""
    force = np.asarray(force, dtype=float).reshape(-1, 3)
    normal = np.asarray(normal, dtype=float).reshape(-1, 3)
    compression = -np.einsum("pc,pc->p", normal, force)
    return compression, np.linalg.norm(force + compression[:, None] * normal, axis=1)


def pairs_over_strength(contact_arrays: dict) -> dict:
    """How many pairs the static forces F0 put beyond the interface strength at D = 1.

    With N = -n.F0 (compression positive) and T = |F0 - (n.F0) n|: tension beyond t_s A opens a
    pair, |T| > mu_s N + c A slides it (docs/method.md section 9).

    Returns:
        {"opening": count, "sliding": count}
    """
    area = np.asarray(contact_arrays["area"], dtype=float)
    compression, shear = normal_and_shear(contact_arrays["static_force"], contact_arrays["normal"])
    opening = (compression < 0.0) & (-compression > contact_arrays["tensile_strength"] * area)
    sliding = (compression >= 0.0) & (shear > contact_arrays["friction_static"] * compression
                                      + contact_arrays["cohesion"] * area)
    return {"opening": int(np.count_nonzero(opening)), "sliding": int(np.count_nonzero(sliding))}


def hand_over_force_provider(force: np.ndarray, ramp: float = 0.0):
    """A kernel force provider holding `force` (dofs, N) at its nonzero nodes: constant for the
    whole run (ramp = 0), or rising smoothly from 0 at t = 0 to 1 at t = ramp (3 x^2 - 2 x^3, zero
    slope at both ends) and constant after (the kernel's HeldForce)."""
    from pyfem import _kernels

    nodal = np.asarray(force, dtype=np.float64).reshape(-1, 3)
    nodes = np.flatnonzero(np.any(nodal != 0.0, axis=1)).astype(np.int32)
    return _kernels.HeldForce(nodes, np.ascontiguousarray(nodal[nodes]), float(ramp))


def plan_report(scene: typing.Mapping, model, comm=None) -> dict:
    """The `check` lines on the static stage: what each stage removes, installs and loads, the
    boundary and the solver it will use (nothing is solved). comm: the distributed model's (a
    collective): the whole model's unknowns and installed cells, each rank's owned ones summed."""
    settings = scene["static"]
    boundary = stage_boundary(scene, model)
    installed, installed_cells = _install_cells(scene, model)
    excavated = settings["excavate"]
    relaxation = settings["relaxation"]
    initial = scene.get("initial_stress")
    if initial is None:
        source = "none (the materials' weight only)"
    elif initial.get("stress") is not None:
        source = "uniform " + str(initial["stress"]) + " Pa (sxx, syy, szz, syz, sxz, sxy)"
    else:
        source = (f"geostatic, surface {initial['surface']:g} m, rho {initial['rho']:g} kg/m^3, "
                  f"k {initial['k']}")
    n_dofs, n_installed = model.n_dofs, len(installed_cells)
    if comm is not None:
        n_dofs = comm.allreduce(3 * model.V.dofmap.index_map.size_local)
        n_installed = comm.allreduce(int(np.count_nonzero(installed_cells < model.n_cells)))
    if uses_relaxation(scene):
        solver_words = (f"dynamic relaxation with the kernel (mass scaling, adaptive critical damping), out-of-balance "
                        f"ratio {stage_tolerance(scene):g}, at most {int(settings['max_steps'])} steps per stage")
    else:
        method = settings["solver"] if settings["solver"] != "auto" else (
            "direct" if n_dofs <= DIRECT_SOLVER_LIMIT else "iterative")
        solver_words = (f"{method} (up to {n_dofs} unknowns; direct up to {DIRECT_SOLVER_LIMIT}), tolerance "
                        f"{stage_tolerance(scene):g}")
    pair_words = {}
    if "contact" in scene:
        pair_words["contact pairs"] = (
            "welded during the stage (contact.split = \"after_static\"), split for the dynamic run with the "
            "welded stage's forces" if welded(scene) else
            "with their law during the stage (bond, slip, opening; no deterioration)" if uses_relaxation(scene)
            else "bonded during the stage (a linear stage)")
    hand_over_words = ("; plastic strain, damage and pair states go on" if uses_relaxation(scene) else "")
    if welded(scene) and uses_relaxation(scene):
        hand_over_words = "; plastic strain and damage go on, the pairs start bonded"
    return {
        "initial stress": source + (", gravity on" if settings["gravity"] else ""),
        "stage 1 (excavation)": (f"{', '.join(excavated) or 'no region'} removed (absent from the model)"
                                 + (f", {', '.join(installed)} not yet installed" if installed else "")
                                 + f"; {relaxation:g} of the excavation load released"),
        "stage 2 (support)": ((f"{', '.join(installed)} installed stress-free "
                               f"({n_installed} cells); " if installed else "")
                              + (f"support groups {', '.join(settings['support'])} installed; "
                                 if settings.get("support") else "")
                              + ("nothing installed; " if not installed and not settings.get("support") else "")
                              + f"the remaining {1.0 - relaxation:g} released"),
        "boundary": ", ".join(f"{name} {kind}" for name, kind in boundary.items()),
        "solver": solver_words,
        **pair_words,
        "hand-over": "static stress, pair forces and support reactions to the dynamic run (u = v = 0)"
                     + hand_over_words,
    }

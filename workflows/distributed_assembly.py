"""Prototype of the first step of issue 13's distributed model (docs/scaling.md "Next steps"):
dolfinx's distributed mesh and assembly, each rank keeping its owned rows in the kernel's owned +
ghost numbering. Not used by `pyfem run` yet (build_model refuses more than one rank).

On a hexahedral box of n^3 Q1 cells distributed by dolfinx (`GhostMode` as given), each rank:
1. assembles the elastic stiffness into a distributed PETSc matrix and takes its owned rows
   (`getValuesCSR`: owned rows, global columns);
2. counts the columns that are not local nodes of the function space (owned or ghost in its index
   map): with GhostMode.shared_facet, from 3 ranks on, the neighbours through an edge or a vertex
   only. They become extra ghosts: the kernel's local numbering (pyfem/distributed.py `Share`)
   is owned nodes, the index map's ghosts, then these; their values come from their owners, found
   from the ranks' owned ranges (`fetch_owned`, what a kernel exchange would be built from);
3. renumbers the columns into local nodes and forms y = K u on its owned rows from its local u (owned,
   ghost and extra-ghost values of a smooth displacement field), and compares it with PETSc's
   product A x;
4. the strain energy 1/2 u.K u summed over the ranks against the same box assembled on one rank
   (another numbering: the energy does not depend on it), and the lumped mass's total;
5. reports its peak memory and the share of the model it holds.

    /usr/bin/python3 workflows/distributed_assembly.py [n] [ghost_mode]
    mpirun --allow-run-as-root -n 2 /usr/bin/python3 workflows/distributed_assembly.py [n] [ghost_mode]

Prints one JSON line on rank 0.
"""
import json
import resource
import sys
import time

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI

YOUNG, POISSON, DENSITY = 2.0e10, 0.25, 2600.0


def box_operators(comm: MPI.Comm, n: int, ghost_mode: str):
    """The box's function space, assembled stiffness (PETSc) and lumped mass (owned + ghost values)."""
    domain = dmesh.create_box(comm, [np.zeros(3), np.full(3, float(n))], [n, n, n], dmesh.CellType.hexahedron,
                              ghost_mode=getattr(dmesh.GhostMode, ghost_mode))
    V = fem.VectorFunctionSpace(domain, ("Lagrange", 1))
    mu = YOUNG / (2.0 * (1.0 + POISSON))
    lam = YOUNG * POISSON / ((1.0 + POISSON) * (1.0 - 2.0 * POISSON))
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)

    def strain(x):
        return ufl.sym(ufl.grad(x))

    stress = 2.0 * mu * strain(u) + lam * ufl.tr(strain(u)) * ufl.Identity(3)
    quadrature = {"quadrature_degree": 2}
    matrix = fem_petsc.assemble_matrix(fem.form(ufl.inner(stress, strain(w)) * ufl.dx(metadata=quadrature)))
    matrix.assemble()
    ones = fem.Function(V)
    ones.x.array[:] = 1.0
    lumped = fem_petsc.assemble_vector(fem.form(DENSITY * ufl.inner(ones, w) * ufl.dx(metadata=quadrature)))
    lumped.ghostUpdate(addv=fem_petsc.PETSc.InsertMode.ADD, mode=fem_petsc.PETSc.ScatterMode.REVERSE)
    mass = fem.Function(V)
    mass.vector.array[:] = lumped.array  # owned values
    mass.x.scatter_forward()  # and the ghosts'
    return V, matrix, mass.x.array.copy()


def owned_rows_local(V, matrix):
    """The owned rows of `matrix` in local dofs: the local nodes are the index map's owned nodes, its
    ghosts, then the extra ghosts (global nodes of the owned rows' columns that the index map does
    not hold: with GhostMode.shared_facet, neighbours through an edge or a vertex only).

    Returns (indptr, local columns, values, extra ghosts' global nodes)."""
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    first, last = index_map.local_range
    mapped = np.concatenate([np.arange(first, last), index_map.ghosts]).astype(np.int64)  # global node
    indptr, columns, values = matrix.getValuesCSR()
    node, component = np.divmod(columns.astype(np.int64), bs)
    extra = np.setdiff1d(node, mapped)
    local_nodes = np.concatenate([mapped, extra])
    order = np.argsort(local_nodes)
    local_columns = bs * order[np.searchsorted(local_nodes[order], node)] + component
    return indptr, local_columns, values, extra


def fetch_owned(comm: MPI.Comm, V, values: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """(len(wanted), bs) the owners' values of the global nodes `wanted` (the extra ghosts), the
    owner of a node found from the ranks' owned ranges (what a kernel exchange would be built from)."""
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    first, last = index_map.local_range
    starts = np.array([r[0] for r in comm.allgather((first, last))] + [index_map.size_global])
    owner = np.searchsorted(starts, wanted, side="right") - 1
    asked = comm.alltoall([wanted[owner == q] for q in range(comm.size)])
    owned = values[:bs * index_map.size_local].reshape(-1, bs)
    replies = comm.alltoall([owned[np.asarray(nodes, dtype=np.int64) - first] for nodes in asked])
    out = np.zeros((len(wanted), bs))
    for q in range(comm.size):
        out[owner == q] = replies[q]
    return out


def smooth_field(V) -> np.ndarray:
    """A smooth displacement at every local dof (owned and ghost), the same function on every rank."""
    x = V.tabulate_dof_coordinates()
    field = np.stack([np.sin(0.1 * x[:, 0]) * np.cos(0.07 * x[:, 2]), 0.5 * np.sin(0.05 * x[:, 1] + 0.3),
                      np.cos(0.09 * x[:, 2]) * x[:, 0] * 1e-2], axis=1)
    return 1e-3 * field.reshape(-1)


def main(argv: list) -> int:
    n = int(argv[0]) if argv else 30
    ghost_mode = argv[1] if len(argv) > 1 else "shared_facet"
    comm = MPI.COMM_WORLD
    began = time.perf_counter()
    V, matrix, mass = box_operators(comm, n, ghost_mode)
    seconds = time.perf_counter() - began
    indptr, columns, values, missing = owned_rows_local(V, matrix)
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    n_owned = bs * index_map.size_local
    u = np.concatenate([smooth_field(V), fetch_owned(comm, V, smooth_field(V), missing).reshape(-1)])
    ours = np.add.reduceat(values * u[columns], indptr[:-1]) if len(values) else np.zeros(0)
    ours[np.diff(indptr) == 0] = 0.0
    x, y = matrix.createVecs()
    x.array[:] = u[:n_owned]
    matrix.mult(x, y)
    product_error = comm.allreduce(float(np.abs(ours - y.array).max()), op=MPI.MAX) / \
        comm.allreduce(float(np.abs(y.array).max()), op=MPI.MAX)
    energy = comm.allreduce(0.5 * float(u[:n_owned] @ ours), op=MPI.SUM)
    total_mass = comm.allreduce(float(mass[:n_owned].sum()) / 3.0, op=MPI.SUM)
    peak = comm.gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, root=0)
    shares = comm.gather([index_map.size_local, index_map.num_ghosts, len(missing)], root=0)
    reference = None
    if comm.rank == 0 and comm.size > 1:  # the same box on one rank, another numbering
        V1, matrix1, _ = box_operators(MPI.COMM_SELF, n, ghost_mode)
        u1 = smooth_field(V1)
        x1, y1 = matrix1.createVecs()
        x1.array[:] = u1
        matrix1.mult(x1, y1)
        reference = 0.5 * float(x1.dot(y1))
    if comm.rank == 0:
        print(json.dumps({
            "n": n, "ghost_mode": ghost_mode, "ranks": comm.size, "nodes": (n + 1) ** 3,
            "owned_ghost_extra_per_rank": shares, "assembly_seconds": round(seconds, 2),
            "owned_rows_product_error": product_error, "energy": energy,
            "energy_one_rank": reference,
            "energy_difference": None if reference is None else abs(energy - reference) / reference,
            "mass_error": abs(total_mass - DENSITY * n ** 3) / (DENSITY * n ** 3),
            "peak_mib_per_rank": [round(p) for p in peak]}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

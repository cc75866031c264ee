"""Prototype of the first step of issue 13's distributed model (docs/scaling.md "Next steps"):
dolfinx's distributed mesh and assembly, each rank keeping its owned rows in the kernel's owned +
ghost numbering. Its numbering, ghost-diagonal fetch and exchange are pyfem/distributed_model.py's
(`[parallel] model = "distributed"`, which `pyfem run` uses since 2026-11-29); this workflow keeps
the checks of that first step on a plain dolfinx box.

On a hexahedral box of n^3 Q1 cells distributed by dolfinx (`GhostMode` as given), each rank:
1. assembles the elastic stiffness into a distributed PETSc matrix and takes its owned rows
   (`getValuesCSR`: owned rows, global columns);
2. counts the columns that are not local nodes of the function space (owned or ghost in its index
   map): with GhostMode.shared_facet, from 3 ranks on, the neighbours through an edge or a vertex
   only. They become extra ghosts: the kernel's local numbering (pyfem/distributed_model.py)
   is owned nodes, the index map's ghosts, then these; their values come from their owners, found
   from the ranks' owned ranges (`fetch_owned`, what a kernel exchange would be built from);
3. renumbers the columns into local nodes and forms y = K u on its owned rows from its local u (owned,
   ghost and extra-ghost values of a smooth displacement field), and compares it with PETSc's
   product A x;
4. the strain energy 1/2 u.K u summed over the ranks against the same box assembled on one rank
   (another numbering: the energy does not depend on it), and the lumped mass's total;
5. builds the kernel's Stepper of its share as pyfem/distributed_model.py does from the
   whole matrix (`local_stiffness`: owned rows, the ghosts' rows to owned nodes as the owned rows'
   transposes, the ghosts' diagonal blocks from their owners; the lumped mass; `ghost_exchange`
   over the index map's and the extra ghosts) and steps a Gaussian bump STEPS steps from rest,
   against the box assembled and stepped whole on one rank (nodes matched by coordinates);
6. counts the halo the element loop would need (the other ranks' cells touching its owned nodes,
   pyfem.distributed_model.rank_regions "halo") and how much of it dolfinx's ghost cells leave out;
7. reports its peak memory and the share of the model it holds.

    /usr/bin/python3 workflows/distributed_assembly.py [n] [ghost_mode]
    mpirun --allow-run-as-root -n 2 /usr/bin/python3 workflows/distributed_assembly.py [n] [ghost_mode]

Prints one JSON line on rank 0.
"""
import json
import resource
import sys
import time

import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI

from pyfem.distributed_model import ghost_plan
from pyfem.distributed_parts import fetch_owned, local_stiffness, owned_rows_local

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


def halo_cells(comm: MPI.Comm, V) -> tuple[int, int]:
    """(cells of other ranks touching this rank's owned nodes, how many of them are not on this rank
    as dolfinx's ghost cells): the halo the element loop needs (pyfem.distributed_model.rank_regions
    "halo") and what of it the mesh's ghost mode leaves out."""
    domain = V.mesh
    node_map, cell_map = V.dofmap.index_map, domain.topology.index_map(3)
    n_cells = cell_map.size_local + cell_map.num_ghosts
    cell_nodes = V.dofmap.list.array.reshape(n_cells, -1)
    node_owner = np.concatenate([np.full(node_map.size_local, comm.rank), node_map.owners])
    cell_global = cell_map.local_to_global(np.arange(n_cells, dtype=np.int32))
    needs = [np.zeros(0, dtype=np.int64) for _ in range(comm.size)]  # per rank: my owned cells touching its nodes
    owned_cells = np.arange(cell_map.size_local)
    owner_of = node_owner[cell_nodes[owned_cells]]
    for q in range(comm.size):
        if q != comm.rank:
            needs[q] = cell_global[owned_cells[(owner_of == q).any(axis=1)]]
    received = np.concatenate(comm.alltoall(needs)).astype(np.int64)
    return len(received), int(np.setdiff1d(received, cell_global).size)


def bump(x: np.ndarray, n: int) -> np.ndarray:
    """A smooth initial displacement (m) at points x (k, 3): a Gaussian bump at the box's centre."""
    r2 = ((x - 0.5 * n) ** 2).sum(axis=1) / (0.15 * n) ** 2
    return 1e-3 * np.stack([np.exp(-r2), 0.5 * np.exp(-r2), -np.exp(-r2)], axis=1).reshape(-1)


STEPS, DT = 100, 1.0e-4  # s (the box's 1 m cells: critical step ~1.7e-4 s)


def smooth_field(V) -> np.ndarray:
    """A smooth displacement at every local dof (owned and ghost), the same function on every rank."""
    x = V.tabulate_dof_coordinates()
    field = np.stack([np.sin(0.1 * x[:, 0]) * np.cos(0.07 * x[:, 2]), 0.5 * np.sin(0.05 * x[:, 1] + 0.3),
                      np.cos(0.09 * x[:, 2]) * x[:, 0] * 1e-2], axis=1)
    return 1e-3 * field.reshape(-1)


def step_the_share(comm: MPI.Comm, V, rows, missing, local_nodes, mass, n: int) -> dict:
    """The kernel's Stepper of the rank's share (local matrix, lumped mass, ghost exchange), STEPS
    steps from the bump at rest: its owned nodes' coordinates and displacements, its seconds."""
    from pyfem import _kernels

    index_map = V.dofmap.index_map
    n_owned = index_map.size_local
    coordinates = V.tabulate_dof_coordinates()[:n_owned + index_map.num_ghosts]
    node_mass = mass.reshape(-1, 3)[:, 0]
    coordinates = np.concatenate([coordinates, fetch_owned(comm, index_map, coordinates[:n_owned], missing)])
    node_mass = np.concatenate([node_mass, fetch_owned(comm, index_map, node_mass[:n_owned, None], missing)[:, 0]])
    matrix = local_stiffness(comm, index_map, rows, len(local_nodes), local_nodes)
    stepper = _kernels.Stepper(*matrix, np.ascontiguousarray(node_mass), DT)
    stepper.set_partition(n_owned, ghost_plan(comm, index_map, local_nodes, n_owned).kernel_exchange(
        comm, len(local_nodes)))
    u = bump(coordinates, n)
    v, a = np.zeros_like(u), np.zeros_like(u)
    began = time.perf_counter()
    stepper.run(u, v, a, STEPS, 0.0)
    return {"coordinates": coordinates[:n_owned], "u": u[:3 * n_owned].reshape(-1, 3),
            "seconds": time.perf_counter() - began}


def compare_with_one_rank(comm: MPI.Comm, stepped: dict, n: int, ghost_mode: str) -> dict:
    """The ranks' displacements after STEPS steps against the same box stepped whole on one rank
    (its own numbering; nodes matched by their coordinates, whole metres), and that box's strain
    energy of `smooth_field` (the energy does not depend on the numbering)."""
    from pyfem import _kernels

    pieces = comm.gather((stepped["coordinates"], stepped["u"]), root=0)
    seconds = comm.allreduce(stepped["seconds"], op=MPI.MAX)
    if comm.rank != 0:
        return {}
    V1, matrix1, mass1 = box_operators(MPI.COMM_SELF, n, ghost_mode)
    x1, y1 = matrix1.createVecs()
    x1.array[:] = smooth_field(V1)
    matrix1.mult(x1, y1)
    energy = 0.5 * float(x1.dot(y1))
    indptr, columns, values = matrix1.getValuesCSR()
    size = matrix1.getSize()[0]
    whole = sp.csr_matrix((values, columns, indptr), shape=(size, size)).tobsr(blocksize=(3, 3))
    whole.sort_indices()
    stepper = _kernels.Stepper(np.ascontiguousarray(whole.indptr, dtype=np.int64),
                               np.ascontiguousarray(whole.indices, dtype=np.int32),
                               np.ascontiguousarray(whole.data), np.ascontiguousarray(mass1.reshape(-1, 3)[:, 0]), DT)
    coordinates = V1.tabulate_dof_coordinates()
    u = bump(coordinates, n)
    start = u.copy()
    v, a = np.zeros_like(u), np.zeros_like(u)
    began = time.perf_counter()
    stepper.run(u, v, a, STEPS, 0.0)
    alone = time.perf_counter() - began

    def keys(x):
        i = np.rint(x).astype(np.int64)
        return (i[:, 0] * (n + 1) + i[:, 1]) * (n + 1) + i[:, 2]

    order = np.argsort(keys(coordinates))
    ranks_u = np.zeros((len(coordinates), 3))
    for points, displacement in pieces:
        ranks_u[order[np.searchsorted(keys(coordinates)[order], keys(points))]] = displacement
    u, start = u.reshape(-1, 3), start.reshape(-1, 3)
    return {"energy_one_rank": energy, "steps": STEPS, "moved": float(np.abs(u - start).max() / np.abs(start).max()),
            "stepping_difference": float(np.abs(ranks_u - u).max() / np.abs(u).max()),
            "step_seconds_ranks": seconds, "step_seconds_one_rank": alone}


def main(argv: list) -> int:
    n = int(argv[0]) if argv else 30
    ghost_mode = argv[1] if len(argv) > 1 else "shared_facet"
    comm = MPI.COMM_WORLD
    began = time.perf_counter()
    V, matrix, mass = box_operators(comm, n, ghost_mode)
    seconds = time.perf_counter() - began
    rows, missing, local_nodes = owned_rows_local(V, matrix)
    index_map, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    n_owned = bs * index_map.size_local
    field = smooth_field(V)
    u = np.concatenate([field, fetch_owned(comm, index_map, field[:n_owned].reshape(-1, bs), missing).reshape(-1)])
    ours = rows @ u
    x, y = matrix.createVecs()
    x.array[:] = u[:n_owned]
    matrix.mult(x, y)
    product_error = comm.allreduce(float(np.abs(ours - y.array).max()), op=MPI.MAX) / \
        comm.allreduce(float(np.abs(y.array).max()), op=MPI.MAX)
    energy = comm.allreduce(0.5 * float(u[:n_owned] @ ours), op=MPI.SUM)
    total_mass = comm.allreduce(float(mass[:n_owned].sum()) / 3.0, op=MPI.SUM)
    stepped = step_the_share(comm, V, rows, missing, local_nodes, mass, n)
    peak = comm.gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, root=0)
    shares = comm.gather([index_map.size_local, index_map.num_ghosts, len(missing)], root=0)
    halo = comm.gather(halo_cells(comm, V), root=0)
    stepping = compare_with_one_rank(comm, stepped, n, ghost_mode)
    if comm.rank == 0:
        reference = stepping.pop("energy_one_rank")
        print(json.dumps({
            "n": n, "ghost_mode": ghost_mode, "ranks": comm.size, "nodes": (n + 1) ** 3,
            "owned_ghost_extra_per_rank": shares, "halo_cells_and_not_on_rank_per_rank": halo,
            "assembly_seconds": round(seconds, 2),
            "owned_rows_product_error": product_error, "energy": energy,
            "energy_one_rank": reference,
            "energy_difference": abs(energy - reference) / reference,
            "mass_error": abs(total_mass - DENSITY * n ** 3) / (DENSITY * n ** 3),
            "peak_mib_per_rank": [round(p) for p in peak], **stepping}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

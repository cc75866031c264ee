"""The linear static stage on the distributed model (static.solver "direct" or "iterative", or
"auto" without a [plasticity] or [damage] table; docs/static.md): pyfem.static.solve_static_stage's
two solves K u = f built from each rank's part of dolfinx's mesh and solved by PETSc across the
ranks (pyfem.static.LinearSolver with the ranks' communicator). No rank holds the whole model.

Each rank:
1. assembles the stage's loads and its owned rows of the two stage matrices (every cell; every cell
   but the installed ones) as the relaxation stage does (pyfem/distributed_stage.py);
2. makes the free basis u = T w of the nodes it steps (pyfem.static.free_basis: the held faces'
   free directions, its bonded contact pairs, whose two nodes it steps, moving together, nodes of no
   stage-1 cell held), numbers its reduced unknowns after the lower ranks', and receives the
   basis blocks of its ghosts from the ranks stepping them;
3. gives PETSc its rows of T^T K T (global columns), of T^T f and of T^T times the rigid-body modes
   about the whole model's centroid (GAMG's near null space);
4. after each solve, u = T w on the nodes it steps and the ghosts' from their owners.

The hand-over is the serial one (pyfem.static.solve_static_stage): the out-of-balance K u - f of
the final state on the nodes each rank steps gives the pair forces F0 (the half difference across
each bonded pair), the support reactions (the held directions) and the hand-over force (the free
directions' part, the solve's round-off, applied to the dynamic run as a constant force by the
rank stepping its node).

On one rank the arithmetic is the serial stage's, operation for operation (the same matrices,
basis, products and PETSc solve), so its displacement and hand-over equal the serial ones to the bit.
"""
from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI


def rank_basis(part, basis) -> tuple[sp.csr_matrix, int, int]:
    """(T over the rank's local nodes with global columns (3 n_local, M), this rank's first column,
    M): `basis` (pyfem.static.FreeBasis of the owned nodes, columns local) shifted by the columns of
    the lower ranks, and the ghosts' rows from the ranks stepping them. A collective."""
    comm, n, n_local = part.comm, part.n_owned, part.n_local
    T = basis.T.tocsr()
    columns = T.shape[1]
    first = comm.exscan(columns) or 0
    total = comm.allreduce(columns)
    # Each owned node's rows: its group's first column (global; -1: every direction held), its number
    # of columns and its 3 x 3 block T[3 node + a, first + e] (the ghost exchange carries them).
    packed = np.zeros((n_local, 11))
    packed[:, 0] = -1.0
    coo = T.tocoo()
    node = coo.row // 3
    base = np.full(n, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(base, node, coo.col)
    has = base < np.iinfo(np.int64).max
    count = np.zeros(n, dtype=np.int64)
    np.maximum.at(count, node, coo.col - base[node] + 1)
    block = np.zeros((n, 3, 3))
    block[node, coo.row % 3, coo.col - base[node]] = coo.data
    packed[:n, 0] = np.where(has, base + first, -1)
    packed[:n, 1] = count
    packed[:n, 2:] = block.reshape(n, 9)
    part.plan.update(comm, packed)
    ghosts = packed[n:]
    ghost_base, ghost_count = ghosts[:, 0].astype(np.int64), ghosts[:, 1].astype(np.int64)
    ghost_block = ghosts[:, 2:].reshape(-1, 3, 3)
    rows, cols, values = [], [], []
    for e in range(3):
        for a in range(3):
            nodes = np.flatnonzero((ghost_base >= 0) & (ghost_count > e))
            rows.append(3 * (n + nodes) + a)
            cols.append(ghost_base[nodes] + e)
            values.append(ghost_block[nodes, a, e])
    ghost_part = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows) - 3 * n, np.concatenate(cols))),
                               shape=(3 * (n_local - n), total))
    ghost_part.sort_indices()
    owned = sp.csr_matrix((T.data, T.indices + first, T.indptr), shape=(3 * n, total))
    whole = sp.csr_matrix((np.concatenate([owned.data, ghost_part.data]),
                           np.concatenate([owned.indices, ghost_part.indices]),
                           np.concatenate([owned.indptr, ghost_part.indptr[1:] + owned.indptr[-1]])),
                          shape=(3 * n_local, total))
    return whole, first, total


def solve_linear(part, contact_arrays: dict | None):
    """The linear stage on the ranks (module docstring); returns pyfem.distributed_stage.RankStage
    with the hand-over force and the pair forces F0."""
    from pyfem.distributed_stage import (RankStage, _largest_displacement, check_held_on_ranks, kernel_nodal,
                                         owned_force, owned_rows, stage_matrix)
    from pyfem.static import (LinearSolver, _install_cells, _stage_constraints, face_support_resultants,
                              free_basis, normal_and_shear, rigid_body_modes, stage_boundary, stage_loads,
                              stage_tolerance)

    start = time.perf_counter()
    scene, comm, model = part.scene, part.comm, part.model
    root = comm.rank == 0
    settings = scene["static"]
    n, n_local = part.n_owned, part.n_local
    boundary = stage_boundary(scene, model)
    installed_regions, installed_cells = _install_cells(scene, model)
    loads = stage_loads(scene, model, installed_cells)
    f_exc = owned_force(part, kernel_nodal(part, loads.excavation))[:3 * n]
    weight = owned_force(part, kernel_nodal(part, loads.installed_weight))[:3 * n]
    traction = owned_force(part, kernel_nodal(part, loads.in_situ_traction))
    held_nodes, held_projection, constraints = _stage_constraints(model, boundary)
    pairs = None if part.pairs is None or not len(part.pairs.nodes) else np.asarray(part.pairs.nodes, np.int64)

    full = stage_matrix(part, np.zeros(0, dtype=np.int32))
    installs = comm.allreduce(len(installed_cells)) > 0  # (a rank may hold none of the installed cells)
    rock = stage_matrix(part, installed_cells) if installs else full
    active = np.zeros(n, dtype=bool)  # a node of no stage-1 cell (only the installed regions use it) is held
    active[np.repeat(np.arange(n), np.diff(rock[0][:n + 1]))] = True
    check_held_on_ranks(part, boundary, constraints, active)
    K_full = owned_rows(part, full)
    K_rock = owned_rows(part, rock) if installs else K_full
    inactive = np.flatnonzero(~active) if installs else np.zeros(0, dtype=np.int64)
    basis_rock = free_basis(n, held_nodes, held_projection, pairs, inactive)
    basis_full = basis_rock if not installs else free_basis(n, held_nodes, held_projection, pairs,
                                                            np.zeros(0, dtype=np.int64))
    coords = part.coords[:n]
    centre = comm.allreduce(coords.sum(axis=0)) / comm.allreduce(n)
    modes = rigid_body_modes(coords, centre)
    relaxation = settings["relaxation"]
    support_load = (1.0 - relaxation) * f_exc + weight
    weighs = comm.allreduce(bool(np.any(weight)), op=MPI.LOR)
    weight_words = " + weight of the installed regions" if weighs else ""
    regions = list(model.regions)
    rock_regions = [name for name in regions if name not in installed_regions]
    stage_specs = [
        ("excavation", K_rock, basis_rock, rock_regions, relaxation * f_exc, relaxation,
         f"{relaxation:g} f_exc (released before {', '.join(installed_regions) or 'any support'})"),
        ("support", K_full, basis_full, regions, support_load, 1.0 - relaxation,
         f"{1.0 - relaxation:g} f_exc{weight_words}"),
    ]
    where = f" on {comm.size} MPI ranks (distributed model)" if comm.size > 1 else " (distributed model)"
    stages, increments, solvers = [], [], {}
    for name, K, basis, stage_regions, load, fraction, words in stage_specs:
        stage_start = time.perf_counter()
        key = (id(K), id(basis))
        if key not in solvers:
            T_local, _, total = rank_basis(part, basis)
            reduced = (basis.T.T @ (K @ T_local)).tocsr()
            solvers[key] = (LinearSolver(reduced, stage_tolerance(scene), settings["solver"],
                                         near_null_space=basis.T.T @ modes, comm=comm), total)
        solver, total = solvers[key]
        w, iterations, residual = solver.solve(basis.T.T @ load)
        u = np.zeros(3 * n_local)
        u[:3 * n] = basis.T @ w
        part.plan.update(comm, u.reshape(-1, 3))  # (the ghosts' from the ranks stepping them)
        largest, point, _ = _largest_displacement(comm, u[:3 * n], coords)
        stage_seconds = comm.allreduce(time.perf_counter() - stage_start, op=MPI.MAX)
        stages.append({"name": name, "active_regions": stage_regions, "load": words, "load_fraction": fraction,
                       "free_dofs": int(total), "solver": solver.name + where if iterations else "none: no load",
                       "iterations": iterations, "residual": residual, "seconds": stage_seconds,
                       "max_displacement": largest, "max_displacement_point": point, "converged": True,
                       "residual_history": [], "regions": {}})
        if root:
            print(f"static stage '{name}': {solver.name}{where}, {iterations} iterations, residual "
                  f"{residual:.2e}, {stage_seconds:.0f} s", flush=True)
        increments.append(u)
    u1, u2 = increments
    # The out-of-balance f_int - f_ext of the final state on the owned nodes (N): zero on the free
    # directions up to the solve's residual, the reactions on the held ones, the pair forces at pairs.
    applied = f_exc + weight
    residual = (K_full @ u2 + K_rock @ u1 - applied).reshape(-1, 3)
    pair_forces = None
    if contact_arrays is not None:
        pair_forces = np.zeros((0, 3))
        if pairs is not None:
            i, j = pairs[:, 0], pairs[:, 1]
            pair_forces = np.ascontiguousarray(0.5 * (residual[i] - residual[j]))
            mean = 0.5 * (residual[i] + residual[j])
            residual[i] = mean
            residual[j] = mean
    free_part = np.einsum("nab,nb->na", basis_full.projection, residual)
    support = np.zeros((n_local, 3))
    support[:n] = residual - free_part
    hand_over_force = np.zeros(3 * n_local)
    hand_over_force[:3 * n] = -free_part.ravel()

    def global_norm(x):
        return math.sqrt(comm.allreduce(float(x @ x)))

    load_norm = global_norm(applied)
    out_of_balance = global_norm(hand_over_force[:3 * n]) / load_norm if load_norm > 0.0 else 0.0
    mine = face_support_resultants(model.faces, boundary, support)  # (a rank without held face nodes: {})
    face_support = {face.name: comm.allreduce(np.asarray(mine.get(face.name, np.zeros(3)))).tolist()
                    for face in model.faces if boundary[face.name] in ("roller", "fixed")}
    largest, point, vector = _largest_displacement(comm, (u1 + u2)[:3 * n], coords)
    report = {"settings": dict(settings, ranks=comm.size, model="distributed"),
              "initial_stress": scene.get("initial_stress"), "excavated": list(settings["excavate"]),
              "installed": list(installed_regions), "boundary": boundary, "stages": stages,
              "seconds": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
              "max_displacement": {"value": largest, "point": point, "vector": vector},
              "out_of_balance": out_of_balance,
              "hand_over": "the dynamic run starts from u = v = 0 with the stage's stress; the in-situ traction, "
                           "body force, support forces and pair forces of the stage are held constant; " + (
                               "the out-of-balance above is applied as a constant external force"
                               if comm.allreduce(bool(np.any(hand_over_force)), op=MPI.LOR) else
                               "the out-of-balance above (a relaxed stage's error) is not applied"),
              "load_ramp_steps": None, "support_forces": face_support,
              "in_situ_tractions": {face.name: comm.allreduce(traction.reshape(-1, 3)[face.nodes].sum(axis=0)).tolist()
                                    for face in model.faces}}
    if contact_arrays is not None:
        area = np.asarray(contact_arrays["area"], dtype=float)
        N, T = normal_and_shear(pair_forces, contact_arrays["normal"])
        report["pairs"] = {"count": comm.allreduce(len(N)),
                           "normal_stress_min": comm.allreduce(float(np.min(N / area, initial=np.inf)), op=MPI.MIN),
                           "normal_stress_max": comm.allreduce(float(np.max(N / area, initial=-np.inf)), op=MPI.MAX),
                           "shear_stress_max": comm.allreduce(float(np.max(T / area, initial=-np.inf)), op=MPI.MAX),
                           "in_tension": comm.allreduce(int(np.count_nonzero(N < 0.0)))}
    return RankStage(counted=[], halo=[], contact=None, u_total=u1 + u2, u_support=u2, u_first=u1,
                     installed_regions=list(installed_regions), report=report, cell_averages=[{}, {}],
                     hand_over_force=hand_over_force, pair_forces=pair_forces)

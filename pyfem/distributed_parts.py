"""What a rank's part is made of, shared by the distributed model (pyfem/distributed_model.py), its
static stage (pyfem/distributed_stage.py) and its local stepping (pyfem/distributed_lts.py): the
kernel's numbering (owned nodes, the index map's ghosts, the extra ghosts), the rank's matrix rows,
the element loop's cells on the rank, the regions' summary over the ranks and the power iteration's
start vector. It imports none of those three modules.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from pyfem.scene import Scene, SceneError


# --- numbering: owned nodes, the index map's ghosts, the extra ghosts; the rank's matrix rows ----

def fetch_owned(comm: MPI.Comm, index_map, owned: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """(len(wanted), k) dolfinx's owners' rows of `owned` ((owned nodes, k) on every rank) for the
    global nodes `wanted` (the extra ghosts' coordinates and masses): pyfem.distributed_pairs.fetch."""
    from pyfem.distributed_pairs import Ownership, fetch

    wanted = np.asarray(wanted, dtype=np.int64)
    return fetch(comm, Ownership.of(comm, index_map).dolfinx_owner(wanted), np.arange(*index_map.local_range),
                 owned, wanted)


def to_kernel_numbering(comm: MPI.Comm, index_map, kernel_of_dolfinx: np.ndarray, local_nodes: np.ndarray,
                        values) -> np.ndarray:
    """(len(local_nodes), k) per-node values of the function space's local nodes (dolfinx's numbering,
    ghosts valid) in the kernel's numbering (`kernel_of_dolfinx`: each of those nodes' kernel number);
    the nodes dolfinx does not hold on this rank (extra ghosts, pair nodes moved here) from
    dolfinx's owners (`fetch_owned`). A collective."""
    values = np.asarray(values, dtype=np.float64).reshape(len(kernel_of_dolfinx), -1)
    out = np.zeros((len(local_nodes), values.shape[1]))
    out[kernel_of_dolfinx] = values
    missing = np.ones(len(local_nodes), dtype=bool)
    missing[kernel_of_dolfinx] = False
    out[missing] = fetch_owned(comm, index_map, values[:index_map.size_local], local_nodes[missing])
    return out


def owned_rows_global(matrix, n_owned: int, release: bool = False) -> tuple:
    """The owned rows of the PETSc `matrix` (getValuesCSR: owned rows, global columns) as (3, 3)
    blocks: (block_indptr, the blocks' global columns (nodes), blocks). Built block by block from
    PETSc's arrays (no scalar CSR copy: the set-up's memory peak is the matrix's).

    release: destroy the PETSc matrix once its arrays are read (one copy fewer at the peak)."""
    indptr, columns, values = matrix.getValuesCSR()
    if release:
        matrix.destroy()
    per_row = np.diff(indptr)
    k = per_row[0::3] // 3  # blocks in each block row: its three scalar rows have 3 k entries each
    if not (np.array_equal(per_row[1::3], per_row[0::3]) and np.array_equal(per_row[2::3], per_row[0::3])
            and np.all(per_row[0::3] % 3 == 0)):
        raise RuntimeError("stiffness: PETSc's owned rows are not (3, 3) blocked")
    block_indptr = np.zeros(n_owned + 1, dtype=np.int64)
    np.cumsum(k, out=block_indptr[1:])
    within = 3 * (np.arange(block_indptr[-1]) - np.repeat(block_indptr[:-1], k))  # the block's first column
    blocks = np.empty((len(within), 3, 3))
    for r in range(3):
        base = np.repeat(indptr[r:-1:3].astype(np.int64), k) + within
        if r == 0:
            node = columns[base].astype(np.int64)
            if np.any(node % 3):
                raise RuntimeError("stiffness: PETSc's owned rows are not (3, 3) blocked")
            node //= 3
        for c in range(3):
            blocks[:, r, c] = values[base + c]
    return block_indptr, node, blocks


def local_numbering(owned: np.ndarray, mapped: np.ndarray, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(every local node's global node, the extra ghosts) of the kernel's numbering: the `owned`
    nodes this rank steps, then the function space's other local nodes (`mapped`: its owned nodes
    and ghosts) in their order, then the *extra ghosts*, nodes of the owned rows' `columns` that
    neither holds, ascending. Without moved pair nodes: the function space's numbering, then the
    extra ghosts."""
    rest = mapped[~np.isin(mapped, owned)]
    known = np.concatenate([owned, rest])
    extra = np.setdiff1d(columns, known)
    return np.concatenate([known, extra]).astype(np.int64), extra


def localize(rows: tuple, local_nodes: np.ndarray) -> sp.bsr_matrix:
    """The rows (block_indptr, global columns, blocks) as BSR (3 rows, 3 local) with local columns
    (`local_nodes`: every local node's global node), sorted in each row."""
    from pyfem.distributed_pairs import positions

    block_indptr, node, blocks = rows
    try:
        local_columns = positions(local_nodes, node, "stiffness").astype(np.int32)
    except RuntimeError:
        raise RuntimeError("stiffness: a column outside the given local numbering") from None
    matrix = sp.bsr_matrix((blocks, local_columns, block_indptr),
                           shape=(3 * (len(block_indptr) - 1), 3 * len(local_nodes)))
    matrix.sort_indices()  # in place
    return matrix


def owned_rows_local(V, matrix, release: bool = False,
                     local_nodes: np.ndarray | None = None) -> tuple[sp.bsr_matrix, np.ndarray, np.ndarray]:
    """The owned rows of the PETSc `matrix` (`owned_rows_global`) with local columns: the local nodes
    are the index map's owned nodes, its ghosts, then the extra ghosts (`local_numbering`).

    local_nodes: the numbering to use (another matrix's of the same pattern), None: made here.

    Returns (rows: BSR (3 owned, 3 local), columns sorted in each row; the extra ghosts' global
    nodes; every local node's global node)."""
    index_map = V.dofmap.index_map
    first, last = index_map.local_range
    mapped = np.concatenate([np.arange(first, last), index_map.ghosts]).astype(np.int64)
    rows = owned_rows_global(matrix, last - first, release)
    if local_nodes is None:
        local_nodes, extra = local_numbering(mapped[:last - first], mapped, rows[1])
    else:
        extra = local_nodes[len(mapped):]
    return localize(rows, local_nodes), extra, local_nodes


def add_to_diagonal(rows: sp.bsr_matrix, nodes: np.ndarray, blocks: np.ndarray) -> None:
    """Adds (k, 3, 3) blocks to the diagonal blocks of the owned `nodes` (in place)."""
    n_owned = rows.shape[0] // 3
    row = np.repeat(np.arange(n_owned), np.diff(rows.indptr))
    diagonal = np.flatnonzero(rows.indices == row)
    if len(diagonal) != n_owned:
        raise RuntimeError(f"stiffness: {n_owned - len(diagonal)} owned nodes without a diagonal block")
    np.add.at(rows.data, diagonal[nodes], blocks)


def stepping(comm: MPI.Comm, ownership):
    """pyfem.distributed_pairs.Ownership of `ownership` (itself, or dolfinx's index map: its owners)."""
    from pyfem.distributed_pairs import Ownership

    return ownership if isinstance(ownership, Ownership) else Ownership.of(comm, ownership)


def local_stiffness(comm: MPI.Comm, ownership, rows: sp.bsr_matrix, n_local: int, local_nodes: np.ndarray):
    """(indptr, indices, blocks) of the rank's matrix from
    the owned rows' blocks (`rows`, sorted), each ghost row's blocks to owned
    nodes (the owned rows' transposed: K is symmetric) and the ghosts' diagonal blocks (from the
    ranks stepping them, `ownership`: an Ownership or dolfinx's index map). One copy of the owned
    blocks."""
    from pyfem.distributed_pairs import fetch

    ownership = stepping(comm, ownership)
    n_owned = rows.shape[0] // 3
    row = np.repeat(np.arange(n_owned), np.diff(rows.indptr))
    col = rows.indices
    diagonal = rows.data[col == row]  # the owned nodes' diagonal blocks, in node order
    if len(diagonal) != n_owned:
        raise RuntimeError(f"stiffness: {n_owned - len(diagonal)} owned nodes without a diagonal block")
    ghost = np.flatnonzero(col >= n_owned)
    ghosts = np.arange(n_owned, n_local)
    ghost_diagonal = fetch(comm, ownership.owner(local_nodes[n_owned:]), local_nodes[:n_owned],
                           diagonal.reshape(n_owned, 9), local_nodes[n_owned:]).reshape(-1, 3, 3)
    ghost_row = np.concatenate([col[ghost].astype(np.int64), ghosts])
    ghost_col = np.concatenate([row[ghost], ghosts])
    ghost_blocks = np.concatenate([rows.data[ghost].transpose(0, 2, 1), ghost_diagonal])
    order = np.lexsort((ghost_col, ghost_row))  # the ghost rows (after every owned row), sorted
    counts = np.concatenate([np.diff(rows.indptr), np.bincount(ghost_row - n_owned, minlength=n_local - n_owned)])
    block_indptr = np.zeros(n_local + 1, dtype=np.int64)
    np.cumsum(counts, out=block_indptr[1:])
    return (block_indptr, np.concatenate([col, ghost_col[order]]).astype(np.int32),
            np.concatenate([rows.data, ghost_blocks[order]]))


def owned_row_sums(matrix: tuple, n_owned: int) -> np.ndarray:
    """(n_owned,) per owned node the largest absolute row sum of its three rows of the kernel's
    (indptr, indices, blocks): the Gershgorin bound of its row (pyfem.local_stepping.node_levels)."""
    indptr, _, blocks = matrix
    sums = np.abs(np.asarray(blocks[:indptr[n_owned]]).reshape(-1, 3, 3)).sum(axis=2)
    row = np.repeat(np.arange(n_owned), np.diff(indptr[:n_owned + 1]))
    per_dof = np.stack([np.bincount(row, weights=sums[:, d], minlength=n_owned) for d in range(3)], axis=1)
    return per_dof.max(axis=1) if n_owned else np.zeros(0)


def drop_zero_blocks(matrix: tuple) -> tuple:
    """The kernel's (indptr, indices, blocks) without its all-zero blocks (the element loop's cells
    leave zero blocks where only they coupled two nodes; the whole model's matrix drops them too)."""
    indptr, indices, blocks = matrix
    keep = np.any(blocks.reshape(-1, 9) != 0.0, axis=1)
    if keep.all():
        return matrix
    row = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))[keep]
    kept_indptr = np.zeros_like(indptr)
    np.cumsum(np.bincount(row, minlength=len(indptr) - 1), out=kept_indptr[1:])
    return kept_indptr, np.ascontiguousarray(indices[keep]), np.ascontiguousarray(blocks[keep])


# --- the element loop on the ranks ---------------------------------------------------------------

def element_loop_cells(scene: Scene, model) -> dict:
    """Element-loop region -> (its local cells, owned and ghost, in its zone; its owned ones):
    `pyfem.elements.nonlinear_component`'s cells on this rank (none: {})."""
    from pyfem.elements import cells_in_zone, region_cells, scene_laws

    laws, _ = scene_laws(scene)
    out = {}
    for name, given in laws.items():
        cells = cells_in_zone(model, region_cells(model, name), given.get("zone"))
        owned = cells[cells < model.n_cells]
        if given.get("zone") is not None and model.mesh.comm.allreduce(len(owned)) == 0:
            raise SceneError(f"materials.{name}.plasticity.zone", given["zone"],
                             f"a box holding the centroid of a cell of region {name!r}")
        out[name] = (cells, owned)
    return out


def one_point_regions(scene: Scene) -> dict:
    """Element-loop region -> (lambda, G (Pa): its law's initial moduli, B-bar) of the regions with
    integration = "reduced" (one point per cell, pyfem/reduced_integration.py), in the scene's order
    (pyfem.elements.nonlinear_component's)."""
    from pyfem.elements import scene_laws, split_law_parameters
    from pyfem.reduced_integration import lame_moduli

    laws, mean_dilatation = scene_laws(scene)
    out = {}
    for name, given in laws.items():
        _, _, integration, parameters = split_law_parameters(given)
        if integration == "reduced":
            out[name] = (*lame_moduli(parameters["young_modulus"], parameters["poisson_ratio"]),
                         bool(mean_dilatation.get(name, False)))
    return out


def add_hourglass(matrix, scene: Scene, model, loop_cells: dict, leave_out=()) -> None:
    """Adds to the PETSc `matrix` (pyfem.assembly.elastic_stiffness_matrix's) the hourglass stiffness
    K_hg of the owned cells of the one-point regions but `leave_out` (`loop_cells`: element_loop_cells'),
    region by region as pyfem.elements.nonlinear_component adds them, and assembles it: each cell's
    K_hg is added once, by the rank owning it, and PETSc sends the rows of other ranks' nodes to them.
    A collective: every rank calls it when the scene has a one-point region."""
    from petsc4py import PETSc

    from pyfem.elements import element_arrays
    from pyfem.reduced_integration import hourglass_stiffness, one_point_arrays

    index_map = model.V.dofmap.index_map
    mapped = np.concatenate([np.arange(*index_map.local_range), index_map.ghosts]).astype(np.int64)
    global_dofs = (3 * np.repeat(mapped, 3) + np.tile(np.arange(3), len(mapped))).astype(PETSc.IntType)
    for name, (lame_lambda, shear_modulus, b_bar) in one_point_regions(scene).items():
        if name in leave_out or name not in loop_cells:
            continue
        full = element_arrays(model.V, loop_cells[name][1])
        local = hourglass_stiffness(full, one_point_arrays(full), lame_lambda, shear_modulus, b_bar,
                                    len(mapped)).tocsr()
        for row in np.flatnonzero(np.diff(local.indptr)):
            span = slice(local.indptr[row], local.indptr[row + 1])
            matrix.setValues(global_dofs[row:row + 1], global_dofs[local.indices[span]], local.data[span],
                             addv=PETSc.InsertMode.ADD_VALUES)
        matrix.assemble()


def _without_cells(materials, removed: np.ndarray) -> tuple:
    """(lambda, G) fields of `materials` zero on the `removed` local cells (pyfem.elements.linear_stiffness)."""
    from dolfinx import fem

    fields = []
    for key in ("lame_lambda", "shear_modulus"):
        values = fem.Function(getattr(materials, key).function_space, name=key)
        values.x.array[:] = getattr(materials, key).x.array
        values.x.array[materials.dof_of_cell[np.asarray(removed, dtype=np.int32)]] = 0.0
        fields.append(values)
    return tuple(fields)


def region_summary(comm: MPI.Comm, counted, components=None) -> dict:
    """NonlinearRegions.region_summary of the whole model from the ranks' counted cells: counts,
    volumes and energies summed, peaks the largest (rank 0; {} elsewhere). `components`: those to
    read (as NonlinearRegions.region_summary's), default the regions' own."""
    pieces = comm.gather(counted.region_summary(components), root=0)
    if comm.rank != 0:
        return {}
    summed = ("cells", "points", "volume", "damaged_volume", "yielded_volume", "tension_points", "shear_points",
              "dissipated_energy", "yielded_points_near_zone_edge")
    largest = ("peak_damage", "peak_plastic_strain", "peak_crack_opening")
    out: dict = {}
    for piece in pieces:
        for name, values in piece.items():
            if name not in out:
                out[name] = dict(values)
                continue
            whole = out[name]
            for key, value in values.items():
                if key in summed:
                    whole[key] += value
                elif key in largest:
                    whole[key] = max(whole[key], value)
                elif key == "cracked_volume_by_opening":
                    whole[key] = {w: whole[key][w] + v for w, v in value.items()}
    return out


# --- the time step ------------------------------------------------------------------------------

def start_vector(coords: np.ndarray) -> np.ndarray:
    """(n, 3) a pseudo-random vector that is a function of the node coordinates only (the same for
    any rank count and numbering): the power iteration's start."""
    phase = coords @ np.array([12.9898, 78.233, 37.719])  # of the node's own coordinates only
    return np.stack([np.sin(phase * (k + 1.0) + 0.5 * k) * 43758.5453 % 1.0 - 0.5 for k in range(3)], axis=1)


def power_iteration(matrix: tuple, mass: np.ndarray, coords: np.ndarray, n_owned: int, iterations: int,
                    comm=None, update=None) -> float:
    """The largest eigenvalue of M^-1/2 K M^-1/2 by power iteration from `start_vector` of the node
    coordinates, on the owned rows of `matrix` (the kernel's (indptr, indices, blocks) in local
    numbering, owned nodes first), the dot products summed over `comm` (None: one process) and
    `update(x)` bringing the ghosts' rows of x (n_local, 3) from their owners before each product.
    The serial run's and the distributed model's estimate (pyfem.solver.choose_time_step,
    pyfem.distributed_model.omega2_estimates): the start depends on the positions only, so the
    estimate is the same for any rank count and numbering but for the round-off of the sums."""
    import math

    indptr, indices, blocks = matrix
    n_local = len(indptr) - 1
    # The owned rows only (a ghost's row holds its blocks to owned nodes only).
    owned = sp.bsr_matrix((blocks[:indptr[n_owned]], indices[:indptr[n_owned]], indptr[:n_owned + 1]),
                          shape=(3 * n_owned, 3 * n_local))
    inverse_sqrt_mass = 1.0 / np.sqrt(mass)
    x = start_vector(coords)

    def total(values):
        return values if comm is None else comm.allreduce(values)

    x /= math.sqrt(total(float(np.sum(x[:n_owned] ** 2))))
    estimate = 0.0
    for _ in range(iterations):
        if update is not None:
            update(x)
        y = (owned @ (inverse_sqrt_mass[:, None] * x).reshape(-1)).reshape(-1, 3)
        y *= inverse_sqrt_mass[:n_owned, None]
        rayleigh, y_norm2 = total(np.array([float(np.sum(x[:n_owned] * y)), float(np.sum(y * y))]))
        estimate = float(rayleigh)
        if y_norm2 == 0.0:
            break
        x[:n_owned] = y / math.sqrt(y_norm2)
    return estimate

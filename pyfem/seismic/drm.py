"""The free field of any rock by the domain-reduction method (Bielak, Loukakis, Hisada and Yoshimura
2003), in two steps, on the distributed model (docs/boundaries.md, "Dipping layers: the
domain-reduction method").

Step 1, the auxiliary run: a scene of the same rock without the cavern, on a larger mesh whose nodes
include the main model's, under the closed-form input of its own truncation faces, is stepped with the
main model's time step; its displacement u0 is recorded at the nodes of the main model's DRM layer.

Step 2, the main run: the DRM layer is the cells that touch an input face (viscoelastic or viscous):
e = the nodes on those faces, b = the other nodes of those cells. With the lumped mass the coupling of b
and e is the stiffness's alone, and the effective forces
    P_b(t) = -K_be u0_e(t),    P_e(t) = +K_eb u0_b(t)
make the motion inside the layer's inner surface the total motion and the motion on e the scattered
part only, which the faces' springs and dashpots absorb; the faces carry no other input. The forces are
the kernel's SeismicInput with one table per node and component (P = the unit vector, tau = 0), sampled
at the steps' times, where the kernel evaluates them (Stepper: the forces at t_{n+1} with u_{n+1}).

Cost: the table is 3 x (b and e nodes) x (steps + 1) values, three arrays of it (g, g', g'') in
float64 on the ranks stepping those nodes, and each rank holds the whole recorded motion while the
forces are formed; the auxiliary run's time and memory are those of its own model.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyfem.scene import SceneError

KEY = "wave.free_field.auxiliary"


@dataclass
class DrmLayer:
    """The main model's DRM layer, the same on every rank: the global ids and coordinates of its nodes
    (sorted by global id) and which of them lie on the input faces (e) rather than inside (b)."""

    nodes: np.ndarray    # (m,) global node ids
    coords: np.ndarray   # (m, 3) m
    on_face: np.ndarray  # (m,) bool: e (on an input face) or b


def layer(part) -> DrmLayer:
    """The DRM layer of a rank's part (pyfem.distributed_model.RankModel); a collective.

    e: the nodes of the input faces; b: the nodes coupled to an e node by the stiffness (a common
    cell) that are not e nodes themselves.

    Raises:
        SceneError: no input face, or element-loop cells (their stiffness is not in the matrix).
    """
    from mpi4py import MPI

    from pyfem.seismic.forces import INPUT_TYPES

    comm = part.comm
    if comm.allreduce(len(part.loop_cells), op=MPI.MAX):
        raise SceneError("wave.free_field.method", "drm", "the rock of a linear elastic model: the DRM forces "
                         "come from the elastic stiffness (no [plasticity] or [damage] material yet)")
    faces = [face for face in part.model.faces if face.kind in INPUT_TYPES]
    mine = np.unique(np.concatenate([np.asarray(face.nodes, dtype=np.int64) for face in faces]
                                    or [np.zeros(0, dtype=np.int64)]))
    on_face = np.unique(np.concatenate(comm.allgather(part.local_nodes[mine])))
    if not len(on_face):
        raise SceneError("wave.free_field.method", "drm", "a model with viscoelastic or viscous truncation faces "
                         "(the DRM layer lies inside them)")
    indptr, indices, _ = part.matrix
    rows = np.repeat(np.arange(part.n_owned), np.diff(indptr)[:part.n_owned])
    columns = indices[:indptr[part.n_owned]]
    coupled = np.isin(part.local_nodes[columns], on_face)
    inner = np.unique(part.local_nodes[rows[coupled]])
    inner = np.setdiff1d(np.unique(np.concatenate(comm.allgather(inner))), on_face)
    nodes = np.concatenate([on_face, inner])
    order = np.argsort(nodes)
    nodes, face_flag = nodes[order], np.concatenate([np.ones(len(on_face), bool), np.zeros(len(inner), bool)])[order]
    owned = part.local_nodes[:part.n_owned]
    here = np.isin(owned, nodes)
    gathered = comm.allgather((owned[here], part.coords[:part.n_owned][here]))
    ids = np.concatenate([g for g, _ in gathered])
    xyz = np.concatenate([x for _, x in gathered]).reshape(-1, 3)
    coords = xyz[np.argsort(ids)]
    return DrmLayer(nodes=nodes, coords=coords, on_face=face_flag)


def record(aux_part, stepper, points: np.ndarray, dt: float, n_steps: int, t0: float) -> np.ndarray:
    """The auxiliary run: its displacement at `points` at t0 + k dt, k = 0 .. n_steps (n_steps + 1, m, 3),
    the same on every rank; a collective.

    Args:
        aux_part: the auxiliary scene's RankModel.
        stepper: its kernel Stepper (with its input forces) at the main model's dt.
        points: (m, 3) the main model's DRM layer nodes, m.

    Raises:
        SceneError (wave.free_field.auxiliary): a point in no cell of the auxiliary mesh.
    """
    comm, model = aux_part.comm, aux_part.model
    held = [found[found < model.n_cells] for found in model.cells_holding(points)]
    offers = np.array(comm.allgather(np.array([len(found) > 0 for found in held], dtype=bool))).reshape(comm.size, -1)
    missing = np.flatnonzero(~offers.any(axis=0))
    if len(missing):
        j = int(missing[0])
        raise SceneError(KEY, str(aux_part.scene.source), f"a mesh holding every node of the main model's DRM "
                         f"layer (node at {[round(float(x), 6) for x in points[j]]} m is in no cell of it)")
    chooser = np.argmax(offers, axis=0)  # the lowest rank holding each point
    mine = np.flatnonzero(chooser == comm.rank)
    nodes = weights = np.zeros((0, 8))
    if len(mine):
        cells = np.array([model.preferred_cell(held[j])[0] for j in mine], dtype=np.int32)
        nodes, weights = model.point_weights(points[mine], cells)
        nodes = aux_part.kernel_nodes(nodes)
    n = 3 * aux_part.n_local
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    stepper.reset_energy(u, v, a, t0)
    samples = np.zeros((n_steps + 1, len(mine), 3))
    for k in range(1, n_steps + 1):
        stepper.run(u, v, a, 1, t0 + (k - 1) * dt)
        if len(mine):
            samples[k] = np.einsum("jk,jki->ji", weights, u.reshape(-1, 3)[nodes])
    if not np.isfinite(samples).all():
        raise FloatingPointError("the auxiliary run became non-finite at the main model's time step "
                                 f"{dt:.6g} s ({KEY}: make its cells no smaller or stiffer than the main model's)")
    whole = np.zeros((n_steps + 1, len(points), 3))
    for index, values in comm.allgather((mine, samples)):
        whole[:, index] = values
    return whole


def effective_input(part, drm_layer: DrmLayer, motion: np.ndarray, dt: float, t0: float) -> dict:
    """The kernel's SeismicInput arrays of the DRM forces on the nodes this rank steps (its owned b and
    e nodes): P_b = -K_be u0_e, P_e = +K_eb u0_b, tabulated at t0 + k dt.

    Args:
        part: the main model's RankModel.
        drm_layer: `layer(part)`.
        motion: `record`'s (n_samples, m, 3) displacements of the layer's nodes.
    """
    indptr, indices, blocks = part.matrix
    n_owned = part.n_owned
    position = np.searchsorted(drm_layer.nodes, part.local_nodes)
    position = np.minimum(position, len(drm_layer.nodes) - 1)
    in_layer = drm_layer.nodes[position] == part.local_nodes
    side = np.where(in_layer, np.where(drm_layer.on_face[position], 1, -1), 0)  # e: 1, b: -1, else 0
    import scipy.sparse as sp

    rows = np.flatnonzero(side[:n_owned] != 0)
    n_samples = motion.shape[0]
    entry_row = np.repeat(np.arange(n_owned), np.diff(indptr)[:n_owned])
    entry_col = indices[:indptr[n_owned]]
    # b row, e column: -K u0_e; e row, b column: +K u0_b (the sign of the row's side)
    coupling = np.flatnonzero((side[entry_row] != 0) & (side[entry_col] == -side[entry_row]))
    row_of = np.full(n_owned, -1)
    row_of[rows] = np.arange(len(rows))
    matrix = sp.bsr_matrix((side[entry_row[coupling], None, None] * blocks[coupling],
                            position[entry_col[coupling]], np.searchsorted(row_of[entry_row[coupling]],
                                                                            np.arange(len(rows) + 1))),
                           shape=(3 * len(rows), 3 * len(drm_layer.nodes)))
    g = np.ascontiguousarray(matrix @ motion.reshape(n_samples, -1).T)  # (3 rows, samples)
    dg = np.ascontiguousarray(np.gradient(g, dt, axis=1)) if n_samples > 1 else np.zeros_like(g)
    ddg = np.ascontiguousarray(np.gradient(dg, dt, axis=1)) if n_samples > 1 else np.zeros_like(g)
    n_rows = len(rows)
    return {"table_t0": float(t0), "table_dt": float(dt), "g": g, "dg": dg, "ddg": ddg,
            "node_ptr": np.arange(0, 3 * n_rows + 1, 3, dtype=np.int64),
            "nodes": rows.astype(np.int32),
            "table": np.arange(3 * n_rows, dtype=np.int32),
            "tau": np.zeros(3 * n_rows),
            "P": np.ascontiguousarray(np.tile(np.eye(3), (n_rows, 1))),
            "Q": np.zeros((3 * n_rows, 3))}


def table_bytes(arrays: dict) -> int:
    """Bytes of a rank's DRM force table (g, g', g'' and the entries)."""
    return int(sum(v.nbytes for v in arrays.values() if isinstance(v, np.ndarray)))

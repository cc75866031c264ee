"""Contact pairs on the distributed model (docs/scaling.md "Contact on the distributed model").

The two nodes of a contact pair are separate vertices of the split mesh (pyfem.interface_split),
each owned by whichever rank dolfinx's topology picks (a shared vertex gets a random owner among
the ranks sharing it; a partitioner can put the two sides of an interface on different ranks, since
the split interface joins no facets). The kernel steps a pair on one rank, with both of its nodes
owned there (`Stepper.check_partition`). So the distributed model *moves* the stepping of a pair's
side-j node to the rank that owns its side-i node when dolfinx gave them different owners (the
stepping rank numbers it after its owned nodes; the rank that gave it away keeps it as a ghost):

- `Ownership`: the rank that steps each global node: dolfinx's owner, except the moved nodes;
- `global_pairs`: every pair of every interface (global node numbers, position, lumped area and
  normal, from the owners of the side-i nodes as `pyfem.interfaces.interface_pairs` computes them
  on one rank), on every rank, in an order that does not depend on the rank count (interface, then
  position);
- `pair_moves`: the nodes to move (side j, or a pair group's), and where;
- `move_rows`: the moved nodes' stiffness rows (global columns) to their new rank;
- `route_faces`: the moved nodes' truncation-face values (springs, dashpots, input) likewise;
- `route_to`: any per-node values to the rank that owns (dolfinx's sense) or steps each node.

Pairs that share a node (interfaces that meet in an L along the model's boundary) are stepped
together on one rank, as the whole model's pair groups are.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI


@dataclass
class Ownership:
    """Which rank steps each global node: the owner of dolfinx's index map (its ranks' contiguous
    ranges `starts`), except the `moved` nodes (sorted), stepped on `moved_to`."""

    starts: np.ndarray
    moved: np.ndarray
    moved_to: np.ndarray

    @classmethod
    def of(cls, comm: MPI.Comm, index_map, moved=None, moved_to=None) -> "Ownership":
        starts = np.array([r[0] for r in comm.allgather(index_map.local_range)] + [index_map.size_global],
                          dtype=np.int64)
        moved = np.zeros(0, dtype=np.int64) if moved is None else np.asarray(moved, dtype=np.int64)
        moved_to = np.zeros(0, dtype=np.int64) if moved_to is None else np.asarray(moved_to, dtype=np.int64)
        order = np.argsort(moved)
        return cls(starts, moved[order], moved_to[order])

    def dolfinx_owner(self, nodes: np.ndarray) -> np.ndarray:
        return np.searchsorted(self.starts, np.asarray(nodes, dtype=np.int64), side="right") - 1

    def owner(self, nodes: np.ndarray) -> np.ndarray:
        nodes = np.asarray(nodes, dtype=np.int64)
        out = self.dolfinx_owner(nodes)
        if len(self.moved) and len(nodes):
            at = np.minimum(np.searchsorted(self.moved, nodes), len(self.moved) - 1)
            hit = self.moved[at] == nodes
            out[hit] = self.moved_to[at[hit]]
        return out


def positions(have: np.ndarray, wanted: np.ndarray, what: str) -> np.ndarray:
    """Index in `have` (distinct global nodes) of each of `wanted`; RuntimeError naming `what` if absent."""
    have = np.asarray(have, dtype=np.int64)
    wanted = np.asarray(wanted, dtype=np.int64)
    order = np.argsort(have, kind="stable")
    if not len(have):
        if len(wanted):
            raise RuntimeError(f"{what}: a node not on this rank")
        return np.zeros(0, dtype=np.int64)
    ascending = have[order]
    if np.any(ascending[1:] == ascending[:-1]):
        raise RuntimeError(f"{what}: a node listed twice")
    found = np.minimum(np.searchsorted(ascending, wanted), len(order) - 1)
    if np.any(ascending[found] != wanted):
        raise RuntimeError(f"{what}: a node not on this rank")
    return order[found]


def fetch(comm: MPI.Comm, owner: np.ndarray, owned: np.ndarray, values: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """(len(wanted), k) rows of `values` ((len(owned), k) on every rank: its `owned` global nodes')
    from the rank `owner` names for each wanted global node."""
    wanted = np.asarray(wanted, dtype=np.int64)
    asked = comm.alltoall([wanted[owner == q] for q in range(comm.size)])
    replies = comm.alltoall([values[positions(owned, nodes, "fetch")] for nodes in asked])
    out = np.zeros((len(wanted), values.shape[1]), dtype=values.dtype)
    for q in range(comm.size):
        out[owner == q] = replies[q]
    return out


def route_to(comm: MPI.Comm, destination: np.ndarray, *arrays: np.ndarray) -> list[np.ndarray]:
    """Sends row k of every array to rank destination[k]; returns the arrays' rows received, in
    rank order (this rank's own rows among them)."""
    sent = comm.alltoall([[array[destination == q] for array in arrays] for q in range(comm.size)])
    return [np.concatenate([piece[k] for piece in sent]) for k in range(len(arrays))]


# --- the pairs -----------------------------------------------------------------------------------

def global_pairs(comm: MPI.Comm, V, facet_tags, interface_tags: dict, coords: np.ndarray, global_of_local: np.ndarray,
                 quadrature: dict):
    """pyfem.interfaces.NodePairs of every pair of the split interfaces, `nodes` global, `mass` None,
    as `pyfem.interfaces.interface_pairs` finds them on one rank: each rank lumps the side-i area and
    normal and the side-j area over its cells (summed into their owners), matches its owned side-i
    nodes with every rank's owned side-j nodes by position, and every rank gets every pair, sorted by
    interface and position."""
    from scipy.spatial import cKDTree

    from pyfem.interfaces import NodePairs, interfaces_meet, lumped_sides, pair_order

    n_owned = V.dofmap.index_map.size_local
    lo = np.min(comm.allgather(coords.min(axis=0)), axis=0)
    hi = np.max(comm.allgather(coords.max(axis=0)), axis=0)
    span = float(np.max(hi - lo))
    names = list(interface_tags)
    mine = []
    for index, name in enumerate(names):
        (nodes_i, area_i, normal_i), (nodes_j, _, _) = lumped_sides(V, facet_tags, interface_tags[name], quadrature,
                                                                     n_owned)
        side_j = comm.allgather((global_of_local[nodes_j], coords[nodes_j]))
        global_j = np.concatenate([piece[0] for piece in side_j]).astype(np.int64)
        coords_j = np.concatenate([piece[1] for piece in side_j]).reshape(-1, 3)
        total_i = comm.allreduce(len(nodes_i))
        if total_i != len(global_j):  # (every rank alike)
            raise interfaces_meet(name, f"{total_i} nodes on side i, {len(global_j)} on side j")
        match = np.zeros(0, dtype=np.int64)
        apart = False
        if len(nodes_i):
            distance, match = cKDTree(coords_j).query(coords[nodes_i])
            apart = bool(np.any(distance > 1e-9 * span))
        if comm.allreduce(apart, op=MPI.LOR):  # every rank raises, none waits in a collective
            raise interfaces_meet(name, "the nodes of its two sides do not coincide pairwise")
        normal = normal_i[nodes_i]
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        mine.append((np.full(len(nodes_i), index, dtype=np.int32),
                     np.column_stack([global_of_local[nodes_i], global_j[match]]).astype(np.int64),
                     coords[nodes_i], area_i[nodes_i], normal))
    pieces = [piece for rank_pieces in comm.allgather(mine) for piece in rank_pieces]
    arrays = [np.concatenate([piece[k] for piece in pieces]) for k in range(5)]
    interface, nodes, where, area, normal = arrays
    nodes, where, normal = nodes.reshape(-1, 2), where.reshape(-1, 3), normal.reshape(-1, 3)
    values, counts = np.unique(nodes[:, 1], return_counts=True)
    if np.any(counts > 1):  # (every rank alike)
        twice = np.flatnonzero(nodes[:, 1] == values[np.argmax(counts)])[0]
        raise interfaces_meet(names[int(interface[twice])], "two side-i nodes matched one side-j node")
    if np.any(area <= 0.0):
        raise ValueError("interface pairs: a lumped pair area is <= 0")
    order = pair_order(where, interface)  # as pyfem.interfaces.interface_pairs sorts
    return NodePairs(names=names, interface=interface[order], nodes=nodes[order], coords=where[order],
                     area=area[order], normal=normal[order])


def pair_moves(pairs, ownership: Ownership) -> tuple[np.ndarray, np.ndarray]:
    """(moved nodes, their new rank) of the pairs whose nodes dolfinx gave to different ranks. A
    pair is stepped on the rank dolfinx gave its side-i node. Pairs that share a node (interfaces
    that meet in an L along the model's boundary) form a group, stepped whole on one rank as the
    serial run steps it (pyfem.ranks.pair_groups): the rank of the side-i node of
    the group's first pair (in `pairs`' order)."""
    from pyfem.ranks import pair_groups

    nodes, group = pair_groups(pairs.nodes)
    pair_group = group[np.searchsorted(nodes, pairs.nodes[:, 0])]
    first = np.full(group.max(initial=-1) + 1, len(pairs), dtype=np.int64)
    np.minimum.at(first, pair_group, np.arange(len(pairs)))
    rank = ownership.dolfinx_owner(pairs.nodes[first, 0])[group]
    apart = ownership.dolfinx_owner(nodes) != rank
    return nodes[apart], rank[apart]


def move_rows(comm: MPI.Comm, ownership: Ownership, first: int, rows: tuple) -> tuple:
    """The owned rows (block_indptr, global columns, blocks) of dolfinx's owned nodes first, first + 1, ...
    -> (the global nodes this rank steps, their rows): the rows of the moved nodes sent to their new
    rank, those this rank receives after its own, ascending. Only the moved rows travel; the kept
    rows are copied once, into the new arrays (the set-up's memory peak stays two copies of the rows)."""
    indptr, columns, blocks = rows
    n = len(indptr) - 1
    nodes = first + np.arange(n, dtype=np.int64)
    if not len(ownership.moved):
        return nodes, rows
    owner = ownership.owner(nodes)
    counts = np.diff(indptr)
    row_of_block = np.repeat(np.arange(n), counts)
    outgoing = []
    for q in range(comm.size):
        chosen = (owner == q) if q != comm.rank else np.zeros(n, dtype=bool)
        take = chosen[row_of_block]
        outgoing.append((nodes[chosen], counts[chosen], columns[take], blocks[take]))
    got = [piece for piece in comm.alltoall(outgoing) if len(piece[0])]
    keep = owner == comm.rank
    if keep.all() and not got:
        return nodes, rows
    kept_blocks = keep[row_of_block]
    del row_of_block
    got_nodes = np.concatenate([piece[0] for piece in got]) if got else np.zeros(0, dtype=np.int64)
    got_counts = np.concatenate([piece[1] for piece in got]) if got else np.zeros(0, dtype=np.int64)
    order = np.argsort(got_nodes)
    starts = np.concatenate([[0], np.cumsum(got_counts)]).astype(np.int64)
    take = (np.concatenate([np.arange(starts[r], starts[r + 1]) for r in order]).astype(np.int64) if len(order)
            else np.zeros(0, dtype=np.int64))
    n_kept = int(np.count_nonzero(kept_blocks))
    new_columns = np.empty(n_kept + len(take), dtype=np.int64)
    new_blocks = np.empty((n_kept + len(take), 3, 3))
    np.compress(kept_blocks, columns, axis=0, out=new_columns[:n_kept])
    np.compress(kept_blocks, blocks, axis=0, out=new_blocks[:n_kept])
    if got:
        new_columns[n_kept:] = np.concatenate([piece[2] for piece in got])[take]
        new_blocks[n_kept:] = np.concatenate([piece[3] for piece in got])[take]
    new_nodes = np.concatenate([nodes[keep], got_nodes[order]]).astype(np.int64)
    new_indptr = np.zeros(len(new_nodes) + 1, dtype=np.int64)
    np.cumsum(np.concatenate([counts[keep], got_counts[order]]), out=new_indptr[1:])
    return new_nodes, (new_indptr, new_columns, new_blocks)


def face_node_fields(face) -> list[str]:
    """The per-node arrays of a truncation face (pyfem.operators.BoundaryFace) besides `nodes`."""
    return [f.name for f in dataclasses.fields(face) if isinstance(getattr(face, f.name), np.ndarray)
            and f.name != "nodes"]


def face_rows(face, keep: np.ndarray):
    """The face with the nodes `keep` (a mask or indices) selects, every per-node array alike."""
    return dataclasses.replace(face, nodes=face.nodes[keep], **{name: getattr(face, name)[keep]
                                                               for name in face_node_fields(face)})


def route_faces(comm: MPI.Comm, ownership: Ownership, faces: list, global_of_local: np.ndarray,
                local_nodes: np.ndarray) -> list:
    """The truncation faces of the nodes this rank steps: `faces` hold dolfinx's owned nodes
    (local numbering of the function space); a moved node's entries go to its new rank; returns
    the faces with `nodes` in the kernel's local numbering (`local_nodes`: its global nodes)."""
    out = []
    for face in faces:
        per_node = face_node_fields(face)
        nodes = global_of_local[face.nodes].astype(np.int64)
        if len(ownership.moved):
            received = route_to(comm, ownership.owner(nodes), nodes, *[getattr(face, name) for name in per_node])
        else:
            received = [nodes] + [getattr(face, name) for name in per_node]
        values = dict(zip(per_node, received[1:]))
        local = positions(local_nodes, received[0], f"face {face.name!r}").astype(np.int32)
        out.append(dataclasses.replace(face, nodes=local, **values))
    return out

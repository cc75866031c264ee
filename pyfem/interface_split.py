"""Interlayer interfaces, step 1: node splitting on the gmsh mesh arrays (numpy and scipy only,
no dolfinx; docs/method.md section 9, "Node pairs").

`split_topology` works on the gmsh mesh arrays (nodes, hexahedra, tagged
quadrilaterals) before dolfinx sees them. For every interface named in
scene["contact"]["interfaces"] the cells on side j get new copies of the
interface nodes, so the two sides share no node; dolfinx then builds the
mesh (and, for Q2, the edge/face/cell dofs) from the split topology
(`pyfem.mesh.split_interfaces`), so the stiffness has no coupling across the
interface and both sides carry their own lumped masses. Step 2, the node
pairs with their areas, normals and masses, is `pyfem.interfaces.interface_pairs`.

Side rule: each interface facet gets the unit normal with positive z
component (horizontal and dipping interfaces: it points up); for a vertical
facet the one with positive x, then positive y. Side i is the side that
normal points away from ("below" for a horizontal interface), side j the
side it points into; side j receives the new nodes. The pair normal n points
from side i towards side j.

Interfaces must not cross one another inside the model (a node on two split
interfaces would need more than two copies); interfaces that reach the outer
boundary are fine: the outer face groups then hold the facets of both sides.
"""
from __future__ import annotations

import typing

import numpy as np
import scipy.sparse

_ORIENTATION_TOLERANCE = 1e-8  # |n_z| below this (of |n|) counts as a vertical facet


def oriented_normals(vectors: np.ndarray) -> np.ndarray:
    """Flip each row of `vectors` (m, 3) so that it obeys the side rule of the module docstring.

    Positive z component; for vertical vectors positive x, then positive y.
    """
    vectors = np.array(vectors, dtype=float, copy=True)
    length = np.linalg.norm(vectors, axis=1)
    tolerance = _ORIENTATION_TOLERANCE * length
    key = np.where(np.abs(vectors[:, 2]) > tolerance, vectors[:, 2],
                   np.where(np.abs(vectors[:, 0]) > tolerance, vectors[:, 0], vectors[:, 1]))
    vectors[key < 0.0] *= -1.0
    return vectors


def facet_normals(x: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """Normals (f, 3) of planar facets, quadrilaterals (f, 4: the cross product of the diagonals) or
    triangles (f, 3: of two edges), oriented by the side rule; their length is twice the area."""
    if facets.shape[1] == 4:
        normals = np.cross(x[facets[:, 2]] - x[facets[:, 0]], x[facets[:, 3]] - x[facets[:, 1]])
    else:
        normals = np.cross(x[facets[:, 1]] - x[facets[:, 0]], x[facets[:, 2]] - x[facets[:, 0]])
    return oriented_normals(normals)


def incidence(rows: np.ndarray, n_columns: int) -> scipy.sparse.csr_matrix:
    """0/1 matrix with a 1 at (r, rows[r, k]) for every k."""
    n, k = rows.shape
    return scipy.sparse.csr_matrix((np.ones(n * k), (np.repeat(np.arange(n), k), rows.ravel())),
                                   shape=(n, n_columns))


def _adjacent_cells(facets: np.ndarray, cells: np.ndarray, n_nodes: int) -> list[np.ndarray]:
    """The cells having all nodes of each facet (one for outer, two for inner facets)."""
    shared = (incidence(facets, n_nodes) @ incidence(cells, n_nodes).T).tocsr()
    adjacent = []
    for f in range(len(facets)):
        row = slice(shared.indptr[f], shared.indptr[f + 1])
        adjacent.append(shared.indices[row][shared.data[row] == facets.shape[1]])
    return adjacent


def _positions(cell_nodes: np.ndarray, facet_nodes: np.ndarray) -> np.ndarray:
    """Local positions (4 or 3,) of the facet's nodes within the cell's node list."""
    return np.argmax(cell_nodes[None, :] == facet_nodes[:, None], axis=1)


def split_topology(x: np.ndarray, cells: np.ndarray, facets: np.ndarray, facet_values: np.ndarray,
                   interface_tags: typing.Mapping[str, int]):
    """Duplicate the nodes of the named interfaces on the mesh arrays (no dolfinx).

    Args:
        x: (n, 3) node coordinates (m).
        cells: (c, 8) hexahedra or (c, 4) tetrahedra, gmsh node order, 0-based rows of x.
        facets: (f, 4) tagged quadrilaterals of hexahedra or (f, 3) triangles of tetrahedra
            (0-based rows of x).
        facet_values: (f,) physical surface tag of each facet.
        interface_tags: interface name -> physical surface tag, the surfaces to split.

    Returns:
        (x_split, cells_split, facets_split, facet_values_split, interface_tags_split, copy_of):
        the new coordinates (copies appended), cells with side j renumbered,
        facets with every tagged quadrilateral expressed in the nodes of its
        cell (an interface quadrilateral appears twice: tag_i for the side-i
        cell, tag_j for the side-j cell), interface name -> (tag_i, tag_j),
        and copy_of (n_split,) the original node of every node.
    """
    x = np.asarray(x, dtype=float)
    cells = np.asarray(cells, dtype=np.int64)
    facets = np.asarray(facets, dtype=np.int64)
    facet_values = np.asarray(facet_values, dtype=np.int32)
    n_original = len(x)
    adjacent = _adjacent_cells(facets, cells, n_original)
    centroids = x[cells].mean(axis=1)
    quad_normals = facet_normals(x, facets)

    split_cells = cells.copy()
    copy_of = list(range(n_original))
    side_j_cell = {}  # interface facet index -> its side-j cell
    next_tag = int(max(facet_values.max(initial=0), 0)) + 1
    split_tags = {}
    for name, tag in interface_tags.items():
        members = np.flatnonzero(facet_values == tag)
        if len(members) == 0:
            raise ValueError(f"contact.interfaces: surface {name!r} has no facets")
        node_normal = np.zeros((len(copy_of), 3))
        member_nodes = []
        for f in members:
            if len(adjacent[f]) != 2:
                raise ValueError(f"contact.interfaces: {name!r} is not inside the model "
                                 f"(a facet has {len(adjacent[f])} adjacent cells; an interface needs 2)")
            a, b = adjacent[f]
            ids_a = split_cells[a, _positions(cells[a], facets[f])]
            ids_b = split_cells[b, _positions(cells[b], facets[f])]
            if np.any(ids_a != ids_b):
                raise ValueError(f"contact.interfaces: {name!r} crosses another split interface; "
                                 "interfaces may meet only on the outer boundary")
            side = np.dot(centroids[b] - centroids[a], quad_normals[f])
            side_j_cell[f] = b if side > 0.0 else a
            np.add.at(node_normal, ids_a, quad_normals[f])
            member_nodes.append(ids_a)
        interface_nodes = np.unique(np.concatenate(member_nodes))
        cells_of_node = incidence(split_cells, len(copy_of)).tocsc()
        new_id = {}
        for node in interface_nodes:
            touching = cells_of_node.indices[cells_of_node.indptr[node]:cells_of_node.indptr[node + 1]]
            distance = (centroids[touching] - x[copy_of[node]]) @ node_normal[node]
            upper = touching[distance > 0.0]
            if len(upper) == 0 or len(upper) == len(touching):
                raise ValueError(f"contact.interfaces: {name!r}: node at {x[copy_of[node]]} "
                                 "has cells on one side only")
            new_id[node] = len(copy_of)
            copy_of.append(copy_of[node])
            rows = split_cells[upper]
            rows[rows == node] = new_id[node]
            split_cells[upper] = rows
        split_tags[name] = (int(tag), next_tag)
        next_tag += 1

    copy_of = np.asarray(copy_of, dtype=np.int64)
    tag_j_of = {tag_i: tag_j for tag_i, tag_j in split_tags.values()}
    out_facets, out_values = [], []
    for f in range(len(facets)):
        value = int(facet_values[f])
        if len(adjacent[f]) == 0:
            raise ValueError(f"mesh: a facet of physical surface {value} is not a face of any cell")
        if f in side_j_cell:
            a = side_j_cell[f]
            b = adjacent[f][0] if adjacent[f][0] != a else adjacent[f][1]
            out_facets.append(split_cells[b, _positions(cells[b], facets[f])])  # side i
            out_values.append(value)
            out_facets.append(split_cells[a, _positions(cells[a], facets[f])])  # side j
            out_values.append(tag_j_of[value])
        else:
            c = adjacent[f][0]
            out_facets.append(split_cells[c, _positions(cells[c], facets[f])])
            out_values.append(value)
    return (x[copy_of], split_cells, np.array(out_facets, dtype=np.int64).reshape(-1, facets.shape[1]),
            np.array(out_values, dtype=np.int32), split_tags, copy_of)

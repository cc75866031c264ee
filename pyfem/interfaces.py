"""Interlayer interfaces: node splitting and contact node pairs (docs/method.md section 9, "Node pairs").

Two steps, both before the time loop:

1. `split_interfaces` works on the gmsh mesh arrays (nodes, hexahedra, tagged
   quadrilaterals) before dolfinx sees them. For every interface named in
   scene["contact"]["interfaces"] the cells on side j get new copies of the
   interface nodes, so the two sides share no node; dolfinx then builds the
   mesh (and, for Q2, the edge/face/cell dofs) from the split topology, so the
   stiffness has no coupling across the interface and both sides carry their
   own lumped masses.
2. `interface_pairs` matches the nodes (dof blocks) of side i and side j of
   each interface by their coordinates and computes per pair the lumped
   area int phi_i ds over the side-i facets, the unit normal from side i
   towards side j and both lumped masses.

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

import dataclasses
import typing

import numpy as np
import scipy.sparse
from mpi4py import MPI

# gmsh element type of the 8-node hexahedron and the dolfinx cell names used for it.
_GMSH_HEXAHEDRON_8 = 5
_ORIENTATION_TOLERANCE = 1e-8  # |n_z| below this (of |n|) counts as a vertical facet


@dataclasses.dataclass
class NodePairs:
    """Contact node pairs of all split interfaces, in one set of arrays.

    Attributes:
        names: interface names; `interface` indexes this list.
        interface: (n,) int32 interface index of each pair.
        nodes: (n, 2) int32 [i, j]: node of side i and node of side j.
        coords: (n, 3) position of the pair (m).
        area: (n,) lumped area int phi_i ds over the side-i facets (m^2).
        normal: (n, 3) unit normal from side i towards side j (area-weighted).
        mass: (n, 2) lumped masses of node i and node j (kg).
    """

    names: list[str]
    interface: np.ndarray
    nodes: np.ndarray
    coords: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    mass: np.ndarray

    def __len__(self) -> int:
        return len(self.area)

    def of_interface(self, name: str) -> np.ndarray:
        """Indices of the pairs of interface `name`."""
        return np.flatnonzero(self.interface == self.names.index(name))

    def nearest(self, point: typing.Sequence[float]) -> int:
        """Index of the pair nearest to `point` (m)."""
        distance = np.linalg.norm(self.coords - np.asarray(point, dtype=float), axis=1)
        return int(np.argmin(distance))


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


def _incidence(rows: np.ndarray, n_columns: int) -> scipy.sparse.csr_matrix:
    """0/1 matrix with a 1 at (r, rows[r, k]) for every k."""
    n, k = rows.shape
    return scipy.sparse.csr_matrix((np.ones(n * k), (np.repeat(np.arange(n), k), rows.ravel())),
                                   shape=(n, n_columns))


def _adjacent_cells(facets: np.ndarray, cells: np.ndarray, n_nodes: int) -> list[np.ndarray]:
    """The cells having all four nodes of each quadrilateral facet (one for outer, two for inner facets)."""
    shared = (_incidence(facets, n_nodes) @ _incidence(cells, n_nodes).T).tocsr()
    adjacent = []
    for f in range(len(facets)):
        row = slice(shared.indptr[f], shared.indptr[f + 1])
        adjacent.append(shared.indices[row][shared.data[row] == facets.shape[1]])
    return adjacent


def _positions(cell_nodes: np.ndarray, facet_nodes: np.ndarray) -> np.ndarray:
    """Local positions (4,) of the facet's nodes within the cell's node list."""
    return np.argmax(cell_nodes[None, :] == facet_nodes[:, None], axis=1)


def split_topology(x: np.ndarray, cells: np.ndarray, facets: np.ndarray, facet_values: np.ndarray,
                   interface_tags: typing.Mapping[str, int]):
    """Duplicate the nodes of the named interfaces on the mesh arrays (no dolfinx).

    Args:
        x: (n, 3) node coordinates (m).
        cells: (c, 8) hexahedra, gmsh node order, 0-based rows of x.
        facets: (f, 4) tagged quadrilaterals (0-based rows of x).
        facet_values: (f,) physical surface tag of each quadrilateral.
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
    quad_normals = np.cross(x[facets[:, 2]] - x[facets[:, 0]], x[facets[:, 3]] - x[facets[:, 1]])
    quad_normals = oriented_normals(quad_normals)  # |.| = 2 * quad area (planar quads)

    split_cells = cells.copy()
    copy_of = list(range(n_original))
    side_j_cell = {}  # interface facet index -> its side-j cell
    next_tag = int(max(facet_values.max(initial=0), 0)) + 1
    split_tags = {}
    for name, tag in interface_tags.items():
        members = np.flatnonzero(facet_values == tag)
        if len(members) == 0:
            raise ValueError(f"contact.interfaces: surface {name!r} has no quadrilaterals")
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
        incidence = _incidence(split_cells, len(copy_of)).tocsc()
        new_id = {}
        for node in interface_nodes:
            touching = incidence.indices[incidence.indptr[node]:incidence.indptr[node + 1]]
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
            raise ValueError(f"mesh: a quadrilateral of physical surface {value} is not a face of any cell")
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
    return (x[copy_of], split_cells, np.array(out_facets, dtype=np.int64).reshape(-1, 4),
            np.array(out_values, dtype=np.int32), split_tags, copy_of)


def split_interfaces(arrays: dict | None, interface_tags: typing.Mapping[str, int], comm: MPI.Comm,
                     model_rank: int = 0):
    """Split the named interfaces and build the dolfinx mesh and tags from the split arrays.

    Args:
        arrays: on `model_rank`, `pyfem.mesh._model_arrays()` of the gmsh model
            (x, cells, cell_values, facets, facet_values); ignored elsewhere.
        interface_tags: interface name -> physical surface tag.
        comm: MPI communicator of the mesh.
        model_rank: rank holding the arrays.

    Returns:
        (mesh, cell_tags, facet_tags, interface_tags_split) with
        interface_tags_split: name -> (tag of side-i facets, tag of side-j facets).
    """
    from dolfinx import cpp as _cpp
    from dolfinx.io import gmshio
    from dolfinx.mesh import CellType, create_mesh, meshtags_from_entities

    if comm.rank == model_rank:
        x, cells, facets, facet_values, split_tags, _ = split_topology(
            arrays["x"], arrays["cells"], arrays["facets"], arrays["facet_values"], interface_tags)
        cell_values = np.asarray(arrays["cell_values"], dtype=np.int32)
    else:
        x, cells = np.zeros((0, 3)), np.zeros((0, 8), dtype=np.int64)
        facets, facet_values = np.zeros((0, 4), dtype=np.int64), np.zeros(0, dtype=np.int32)
        cell_values, split_tags = np.zeros(0, dtype=np.int32), None
    split_tags = comm.bcast(split_tags, root=model_rank)

    ufl_domain = gmshio.ufl_mesh(_GMSH_HEXAHEDRON_8, 3)
    cells = cells[:, gmshio.cell_perm_array(CellType.hexahedron, 8)]
    mesh = create_mesh(comm, cells, x, ufl_domain)
    local_entities, local_values = _cpp.io.distribute_entity_data(mesh._mesh, 3, cells, cell_values)
    mesh.topology.create_connectivity(3, 0)
    cell_tags = meshtags_from_entities(mesh, 3, _cpp.graph.AdjacencyList_int32(local_entities),
                                       local_values.astype(np.int32))
    cell_tags.name = "Cell tags"
    facets = facets[:, gmshio.cell_perm_array(CellType.quadrilateral, 4)]
    local_entities, local_values = _cpp.io.distribute_entity_data(mesh._mesh, 2, facets, facet_values)
    mesh.topology.create_connectivity(2, 3)
    facet_tags = meshtags_from_entities(mesh, 2, _cpp.graph.AdjacencyList_int32(local_entities),
                                        local_values.astype(np.int32))
    facet_tags.name = "Facet tags"
    return mesh, cell_tags, facet_tags, split_tags


def interface_pairs(V, facet_tags, interface_tags: typing.Mapping[str, tuple[int, int]], mass: np.ndarray,
                    node_coords: np.ndarray, quadrature: dict) -> NodePairs:
    """Node pairs of the split interfaces with their lumped areas, normals and masses.

    The nodes of side i are the dof blocks with a nonzero lumped area on the
    side-i facets; those of side j likewise on the side-j facets; they are
    matched by coordinates (cKDTree) and every node must find its partner.

    Args:
        V: vector Lagrange space of the split mesh.
        facet_tags: facet MeshTags holding tag_i and tag_j of each interface.
        interface_tags: name -> (tag_i, tag_j) from `split_interfaces`.
        mass: (n_nodes,) lumped nodal masses (kg).
        node_coords: (n_nodes, 3) node coordinates (m).
        quadrature: form metadata (quadrature degree).

    Returns:
        NodePairs over all interfaces, in the order of `interface_tags`.
    """
    import ufl
    from dolfinx import fem
    from dolfinx import mesh as dolfinx_mesh
    from scipy.spatial import cKDTree

    from pyfem.operators import assemble_nodal_vector

    mesh = V.mesh
    test = ufl.TestFunction(V)
    marker = 1
    names = list(interface_tags)
    chunks = {key: [] for key in ("interface", "nodes", "coords", "area", "normal")}
    span = float(np.max(np.ptp(node_coords, axis=0))) if len(node_coords) else 1.0
    for index, name in enumerate(names):
        lumped = []
        for tag in interface_tags[name]:
            facets = facet_tags.indices[facet_tags.values == tag].astype(np.int32)
            side_tags = dolfinx_mesh.meshtags(mesh, mesh.topology.dim - 1, facets,
                                              np.full(len(facets), marker, dtype=np.int32))
            ds = ufl.Measure("ds", domain=mesh, subdomain_data=side_tags, subdomain_id=marker, metadata=quadrature)
            area = assemble_nodal_vector(ufl.inner(ufl.as_vector((1.0, 0.0, 0.0)), test) * ds, V)[:, 0]
            normal = assemble_nodal_vector(ufl.inner(ufl.FacetNormal(mesh), test) * ds, V)
            lumped.append((np.flatnonzero(area != 0.0), area, normal))
        (nodes_i, area_i, normal_i), (nodes_j, _, _) = lumped
        if len(nodes_i) != len(nodes_j):
            raise ValueError(f"interface {name!r}: {len(nodes_i)} nodes on side i, {len(nodes_j)} on side j")
        distance, match = cKDTree(node_coords[nodes_j]).query(node_coords[nodes_i])
        if np.any(distance > 1e-9 * span) or len(np.unique(match)) != len(match):
            raise ValueError(f"interface {name!r}: the nodes of the two sides do not coincide pairwise")
        normal = normal_i[nodes_i]  # outward from side i = towards side j
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        chunks["interface"].append(np.full(len(nodes_i), index, dtype=np.int32))
        chunks["nodes"].append(np.column_stack([nodes_i, nodes_j[match]]).astype(np.int32))
        chunks["coords"].append(node_coords[nodes_i])
        chunks["area"].append(area_i[nodes_i])
        chunks["normal"].append(normal)
    arrays = {key: np.concatenate(value) for key, value in chunks.items()}
    if np.any(arrays["area"] <= 0.0):
        raise ValueError("interface pairs: a lumped pair area is <= 0")
    arrays["mass"] = np.ascontiguousarray(mass[arrays["nodes"]])
    return NodePairs(names=names, **{k: np.ascontiguousarray(v) for k, v in arrays.items()})

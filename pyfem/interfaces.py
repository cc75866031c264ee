"""Interlayer interfaces, step 2: the contact node pairs of the split mesh (docs/method.md
section 9, "Node pairs").

Step 1, before dolfinx sees the mesh, duplicated the interface nodes
(`pyfem.interface_split.split_topology`, numpy only; `pyfem.mesh` builds the
dolfinx mesh from the split arrays). `interface_pairs` matches the nodes
(dof blocks) of side i and side j of each interface by their coordinates and
computes per pair the lumped area int phi_i ds over the side-i facets (row sums:
positive on quadrilaterals of Q1/Q2 hexahedra and on linear triangles; contact on
quadratic triangles, whose row sums vanish at the vertices, is refused by
`pyfem.mesh`), the unit normal from side i towards side j and both lumped masses.

The side rule (which side is i, which j, where the normal points) is
`pyfem.interface_split`'s.
"""
from __future__ import annotations

import dataclasses
import typing

import numpy as np
import ufl
from scipy.spatial import cKDTree

from pyfem.assembly import assemble_nodal_vector, facet_measure


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
        mass: (n, 2) lumped masses of node i and node j (kg); None in the distributed model's list
            of every pair (pyfem.distributed_pairs.global_pairs: `nodes` are global there).
    """

    names: list[str]
    interface: np.ndarray
    nodes: np.ndarray
    coords: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    mass: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.area)

    def select(self, keep: np.ndarray) -> "NodePairs":
        """The pairs `keep` (a mask or indices) selects, in their order."""
        return dataclasses.replace(self, interface=self.interface[keep], nodes=self.nodes[keep],
                                   coords=self.coords[keep], area=self.area[keep], normal=self.normal[keep],
                                   mass=None if self.mass is None else self.mass[keep])

    def of_interface(self, name: str) -> np.ndarray:
        """Indices of the pairs of interface `name`."""
        return np.flatnonzero(self.interface == self.names.index(name))

    def nearest(self, point: typing.Sequence[float]) -> int:
        """Index of the pair nearest to `point` (m); among pairs equally near (`nearest_pair`), the
        one of the lowest interface, then the lowest position (x, then y, then z): the choice does
        not depend on the pairs' order, so the distributed model's ranks make it alike."""
        return nearest_pair(self.coords, self.interface, point)[0]


def nearest_pair(coords: np.ndarray, interface: np.ndarray, point: typing.Sequence[float]) -> tuple[int, tuple]:
    """(index, key) of the pair that minimises the key (its distance to `point`, its interface, its
    position, the lengths rounded to 1e-9 m: pairs equally near on a regular grid stay equal after
    round-off, and one position is one key whatever the round-off of the mesh's coordinates); keys
    compare as tuples, so the ranks' best pairs can be compared with each other."""
    distance = np.round(np.linalg.norm(coords - np.asarray(point, dtype=float), axis=1), 9) + 0.0
    where = np.round(coords, 9) + 0.0
    index = int(np.lexsort((where[:, 2], where[:, 1], where[:, 0], interface, distance))[0])
    return index, (float(distance[index]), int(interface[index]), *map(float, where[index]))


def pair_order(coords: np.ndarray, interface: np.ndarray) -> np.ndarray:
    """The pairs' order by interface, then position (x, then y, then z, rounded to 1e-9 m: one
    position one key whatever the round-off of the mesh's coordinates, -0.0 as 0.0)."""
    where = np.round(coords, 9) + 0.0
    return np.lexsort((where[:, 2], where[:, 1], where[:, 0], interface))


def interfaces_meet(name: str, found: str):
    """The SceneError of an interface whose two sides do not pair up node by node: what
    pyfem.interface_split cannot split (an interface that crosses another or ends on it inside the
    model, a T or a cross: a node on two split interfaces needs more than two copies)."""
    from pyfem.errors import SceneError

    allowed = ("interfaces that neither cross nor end on another interface inside the model (they may reach "
               "the outer boundary); a T or a cross of split interfaces is not supported")
    return SceneError("contact.interfaces", name, allowed,
                      f"scene key 'contact.interfaces': interface {name!r}: {found}; allowed: {allowed}")


def lumped_sides(V, facet_tags, tags: tuple[int, int], quadrature: dict, n_nodes: int) -> list[tuple]:
    """Per side (i, j) of one interface (its facet tags `tags`): (the nodes among the first
    `n_nodes` with a nonzero lumped area on that side, the lumped areas int phi ds of every local
    node, the lumped int phi n ds) of the vector space V (owned + ghost values: summed into their
    owners, forwarded to the ghosts)."""
    mesh = V.mesh
    test = ufl.TestFunction(V)
    lumped = []
    for tag in tags:
        ds = facet_measure(mesh, facet_tags.indices[facet_tags.values == tag], quadrature)
        area = assemble_nodal_vector(ufl.inner(ufl.as_vector((1.0, 0.0, 0.0)), test) * ds, V)[:, 0]
        normal = assemble_nodal_vector(ufl.inner(ufl.FacetNormal(mesh), test) * ds, V)
        lumped.append((np.flatnonzero(area[:n_nodes] != 0.0), area, normal))
    return lumped


def interface_pairs(V, facet_tags, interface_tags: typing.Mapping[str, tuple[int, int]], mass: np.ndarray,
                    node_coords: np.ndarray, quadrature: dict) -> NodePairs:
    """Node pairs of the split interfaces with their lumped areas, normals and masses.

    The nodes of side i are the dof blocks with a nonzero lumped area on the
    side-i facets; those of side j likewise on the side-j facets; they are
    matched by coordinates (cKDTree) and every node must find its partner.

    Args:
        V: vector Lagrange space of the split mesh.
        facet_tags: facet MeshTags holding tag_i and tag_j of each interface.
        interface_tags: name -> (tag_i, tag_j) from `pyfem.mesh.split_interfaces`.
        mass: (n_nodes,) lumped nodal masses (kg).
        node_coords: (n_nodes, 3) node coordinates (m).
        quadrature: form metadata (quadrature degree).

    Returns:
        NodePairs over all interfaces, sorted by interface (in the order of `interface_tags`), then
        by position (x, then y, then z, to 1e-9 m).
    """
    names = list(interface_tags)
    chunks = {key: [] for key in ("interface", "nodes", "coords", "area", "normal")}
    span = float(np.max(np.ptp(node_coords, axis=0))) if len(node_coords) else 1.0
    for index, name in enumerate(names):
        (nodes_i, area_i, normal_i), (nodes_j, _, _) = lumped_sides(V, facet_tags, interface_tags[name], quadrature,
                                                                     len(node_coords))
        if len(nodes_i) != len(nodes_j):
            raise interfaces_meet(name, f"{len(nodes_i)} nodes on side i, {len(nodes_j)} on side j")
        distance, match = cKDTree(node_coords[nodes_j]).query(node_coords[nodes_i])
        if np.any(distance > 1e-9 * span) or len(np.unique(match)) != len(match):
            raise interfaces_meet(name, "the nodes of its two sides do not coincide pairwise")
        normal = normal_i[nodes_i]  # outward from side i = towards side j
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        chunks["interface"].append(np.full(len(nodes_i), index, dtype=np.int32))
        chunks["nodes"].append(np.column_stack([nodes_i, nodes_j[match]]).astype(np.int32))
        chunks["coords"].append(node_coords[nodes_i])
        chunks["area"].append(area_i[nodes_i])
        chunks["normal"].append(normal)
    arrays = {key: np.concatenate(value) for key, value in chunks.items()}
    # By interface, then position: the order does not depend on the mesh's numbering (the
    # distributed model's pairs, pyfem/distributed_pairs.py, are in this order too).
    order = pair_order(arrays["coords"], arrays["interface"])
    arrays = {key: value[order] for key, value in arrays.items()}
    if np.any(arrays["area"] <= 0.0):
        raise ValueError("interface pairs: a lumped pair area is <= 0")
    arrays["mass"] = np.ascontiguousarray(mass[arrays["nodes"]])
    return NodePairs(names=names, **{k: np.ascontiguousarray(v) for k, v in arrays.items()})


def wear_words(deterioration, t_end: float) -> dict:
    """The wear of the interfaces for run.json and `check`: when its clock starts, t_s, and eta at
    t_end (Eq. 9, computed by the kernel's wear_factor)."""
    from pyfem import _kernels

    R0, _, duration, _, _, _, start = deterioration
    eta = _kernels.wear_factor(*deterioration, t=t_end)
    which = " (the record window's start)" if start > 0.0 else ""
    return {"wear_start": start, "t_s": duration, "eta_at_end": eta,
            "note": f"eta falls from 1 at t = {start:.3g} s{which} "
                    f"towards R0 = {R0:g} over t_s = {duration:g} s, whether or not the ground shakes: {eta:.3f} at "
                    f"t = {t_end:.3g} s"}

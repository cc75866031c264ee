"""Gmsh model -> dolfinx mesh with region (cell) and boundary (facet) tags.

The scene's [mesh] table picks a builder from `pyfem.geometry`; the physical
groups of the gmsh model become dolfinx MeshTags and their names the keys of
`regions` (volumes) and `boundaries` (surfaces).

With a [contact] table, the interfaces it names are split before dolfinx sees
the mesh (`split_interfaces`, with the numpy node splitting of
`pyfem.interface_split`): the cells on one side of each interface get their own
copies of the interface nodes, so the two sides meet only through node pairs
(`pyfem.interfaces.interface_pairs`). Without [contact] the gmsh model goes through
`gmshio.model_to_mesh` unchanged.
"""
from __future__ import annotations

import typing

from pyfem._gmsh import gmsh
import numpy as np
from dolfinx import cpp as _cpp
from dolfinx import mesh as dolfinx_mesh
from dolfinx.io import gmshio
from mpi4py import MPI

from pyfem.geometry import build_box, build_layered_box, build_layered_cavern, gmsh_session, load_msh
from pyfem.geometry.file import volume_problem
from pyfem.interface_split import incidence, split_topology
from pyfem.errors import SceneError
from pyfem.excavation_steps import model_excavation

# gmsh element type numbers of the volume elements accepted as cells.
GMSH_HEXAHEDRON_8 = 5
GMSH_TETRAHEDRON_4 = 4
SUPPORTED_CELL_TYPES = {GMSH_HEXAHEDRON_8: "8-node hexahedra", GMSH_TETRAHEDRON_4: "4-node tetrahedra"}


def create_mesh(scene: typing.Mapping, comm: MPI.Comm = MPI.COMM_WORLD):
    """Build the gmsh model the scene asks for and convert it to a dolfinx mesh.

    The gmsh model lives on rank 0 only; dolfinx distributes the mesh over `comm`.

    Args:
        scene: validated scene; uses scene["mesh"] (builder, origin, size, h,
            layers, file), the names of scene["materials"] and, when present,
            scene["contact"]["interfaces"] (split into node pairs).
        comm: MPI communicator of the mesh.

    Returns:
        (mesh, cell_tags, facet_tags, regions, boundaries) where regions maps
        a region name to its cell tag and boundaries maps a surface name to its
        facet tag (for a split interface: the facets of side i).
    """
    return create_mesh_with_interfaces(scene, comm)[:5]


def create_mesh_with_interfaces(scene: typing.Mapping, comm: MPI.Comm = MPI.COMM_WORLD):
    """`create_mesh` plus the facet tags of both sides of every split interface.

    Returns:
        (mesh, cell_tags, facet_tags, regions, boundaries, interface_tags) with
        interface_tags: name -> (tag of the side-i facets, tag of the side-j
        facets) for every interface in scene["contact"]["interfaces"]; empty
        without [contact]. The side rule is `pyfem.interface_split`'s.
    """
    mesh_settings = scene["mesh"]
    builder = mesh_settings.get("builder")
    model_rank = 0
    model_facts = None
    with gmsh_session("pyfem"):
        if comm.rank == model_rank:
            if builder == "box" and mesh_settings.get("layers"):
                build_layered_box(mesh_settings["origin"], mesh_settings["size"], mesh_settings["h"],
                                  mesh_settings["layers"])
            elif builder == "box":
                build_box(mesh_settings["origin"], mesh_settings["size"], mesh_settings["h"])
            elif builder == "layered_cavern":
                build_layered_cavern(mesh_settings.get("parameters") or {})
            elif builder == "file":
                load_msh(mesh_settings["file"])
            else:
                raise ValueError(f"mesh.builder = {builder!r}: allowed here are 'box', 'layered_cavern' and 'file'")
            problem = volume_problem(model_excavation(scene, getattr(scene, "stage_model", False))) \
                if builder == "file" else None
            model_facts = (*_physical_groups_and_cell_types(), _height_range(), problem, _shared_surfaces())
        model_facts = comm.bcast(model_facts, root=model_rank)
        regions, boundaries, cell_types, heights, problem, shared = model_facts
        _check_support_surfaces_not_shared(scene, shared)
        source = ("mesh.file", mesh_settings["file"]) if builder == "file" else ("mesh.builder", builder)
        _check_cell_types(cell_types, *source)
        if problem:
            raise SceneError(*source, problem)
        check_surfaces_on_top(scene, *heights)
        excavated = _excavated_regions(scene, regions)
        if any(number == GMSH_TETRAHEDRON_4 for number, _ in cell_types):
            _check_tetrahedra_uses(scene)
        regions = {name: tag for name, tag in regions.items() if name not in excavated}
        _check_regions_match_materials(regions, scene["materials"], optional=excavated)
        interface_names = list((scene.get("contact") or {}).get("interfaces") or [])
        if not interface_names and not excavated:
            if comm.size == 1:
                mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, model_rank, gdim=3)
            else:  # gmshio's create_mesh with the partitioner of stable part numbers
                plain = gmshio.create_mesh
                gmshio.create_mesh = lambda *args: plain(*args, partitioner=stable_partitioner())
                try:
                    mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, model_rank, gdim=3)
                finally:
                    gmshio.create_mesh = plain
            return mesh, cell_tags, facet_tags, regions, boundaries, {}
        missing = [name for name in interface_names if name not in boundaries]
        if missing:
            index = interface_names.index(missing[0])
            raise SceneError(f"contact.interfaces.{index}", missing[0], "must name a physical surface of the "
                             "mesh: " + (", ".join(sorted(boundaries)) or "none"))
        arrays = None
        if comm.rank == model_rank:
            arrays = _model_arrays()
            if excavated:
                arrays = _without_cells(arrays, list(excavated.values()))
        if excavated:  # a surface only the excavated cells had is gone with them
            present = comm.bcast(set(np.unique(arrays["facet_values"]).tolist()) if comm.rank == model_rank
                                 else None, root=model_rank)
            boundaries = {name: tag for name, tag in boundaries.items() if tag in present}
        mesh, cell_tags, facet_tags, interface_tags = split_interfaces(
            arrays, {name: boundaries[name] for name in interface_names}, comm, model_rank)
    return mesh, cell_tags, facet_tags, regions, boundaries, interface_tags


def stable_partitioner():
    """dolfinx's cell partitioner (its default graph partitioner, ghost cells across facets) with the
    parts numbered by their lowest global cell: which rank got which part varied between runs (the
    two halves of a 2-rank run swapped) where the split did not, and a rank's sums, so a run's last
    digits, follow its part. (The split itself is not guaranteed to repeat.) On one rank nothing
    changes."""
    from dolfinx import graph

    base = graph.partitioner()

    def partition(comm, parts: int, cells, ghosting: bool):
        destinations = base(comm, parts, cells, ghosting)
        offsets, links = np.asarray(destinations.offsets), np.asarray(destinations.array)
        n_cells = len(offsets) - 1
        first = comm.exscan(n_cells) or 0
        lowest = np.full(parts, np.iinfo(np.int64).max, dtype=np.int64)
        np.minimum.at(lowest, links[offsets[:-1]], first + np.arange(n_cells, dtype=np.int64))
        comm.Allreduce(MPI.IN_PLACE, lowest, op=MPI.MIN)
        number = np.empty(parts, dtype=np.int32)
        number[np.argsort(lowest, kind="stable")] = np.arange(parts, dtype=np.int32)
        return _cpp.graph.AdjacencyList_int32(np.ascontiguousarray(number[links]), np.asarray(offsets, dtype=np.int32))

    return dolfinx_mesh.create_cell_partitioner(partition)


def split_interfaces(arrays: dict | None, interface_tags: typing.Mapping[str, int], comm: MPI.Comm,
                     model_rank: int = 0):
    """Split the named interfaces (`pyfem.interface_split.split_topology`) and build the dolfinx
    mesh and tags from the split arrays.

    Args:
        arrays: on `model_rank`, `_model_arrays()` of the gmsh model
            (x, cells, cell_values, facets, facet_values); ignored elsewhere.
        interface_tags: interface name -> physical surface tag.
        comm: MPI communicator of the mesh.
        model_rank: rank holding the arrays.

    Returns:
        (mesh, cell_tags, facet_tags, interface_tags_split) with
        interface_tags_split: name -> (tag of side-i facets, tag of side-j facets).
    """
    nodes_per_cell = comm.bcast(arrays["cells"].shape[1] if comm.rank == model_rank else None, root=model_rank)
    if comm.rank == model_rank:
        x, cells, facets, facet_values = _without_unused_nodes(arrays["x"], arrays["cells"], arrays["facets"],
                                                               arrays["facet_values"])
        x, cells, facets, facet_values, split_tags, _ = split_topology(x, cells, facets, facet_values, interface_tags)
        cell_values = np.asarray(arrays["cell_values"], dtype=np.int32)
    else:
        x, cells = np.zeros((0, 3)), np.zeros((0, nodes_per_cell), dtype=np.int64)
        facets = np.zeros((0, _FACET_NODES[nodes_per_cell]), dtype=np.int64)
        facet_values = np.zeros(0, dtype=np.int32)
        cell_values, split_tags = np.zeros(0, dtype=np.int32), None
    split_tags = comm.bcast(split_tags, root=model_rank)

    gmsh_type, cell_type, facet_type = _cell_types_of(cells.shape[1])
    ufl_domain = gmshio.ufl_mesh(gmsh_type, 3)
    cells = cells[:, gmshio.cell_perm_array(cell_type, cells.shape[1])]
    mesh = dolfinx_mesh.create_mesh(comm, cells, x, ufl_domain, partitioner=stable_partitioner())
    local_entities, local_values = _cpp.io.distribute_entity_data(mesh._mesh, 3, cells, cell_values)
    mesh.topology.create_connectivity(3, 0)
    cell_tags = dolfinx_mesh.meshtags_from_entities(mesh, 3, _cpp.graph.AdjacencyList_int32(local_entities),
                                                    local_values.astype(np.int32))
    cell_tags.name = "Cell tags"
    facets = facets[:, gmshio.cell_perm_array(facet_type, facets.shape[1])]
    local_entities, local_values = _cpp.io.distribute_entity_data(mesh._mesh, 2, facets, facet_values)
    mesh.topology.create_connectivity(2, 3)
    facet_tags = dolfinx_mesh.meshtags_from_entities(mesh, 2, _cpp.graph.AdjacencyList_int32(local_entities),
                                                     local_values.astype(np.int32))
    facet_tags.name = "Facet tags"
    return mesh, cell_tags, facet_tags, split_tags


def _without_unused_nodes(x: np.ndarray, cells: np.ndarray, facets: np.ndarray, facet_values: np.ndarray) -> tuple:
    """(x, cells, facets, facet_values) without the nodes no cell uses (gmsh can leave one in a
    tetrahedral mesh; dolfinx's create_mesh, given the split arrays, crashed or hung on it), the
    facets renumbered (a facet on such a node, which no cell has, dropped)."""
    used = np.zeros(len(x), dtype=bool)
    used[np.asarray(cells).ravel()] = True
    if used.all():
        return x, cells, facets, facet_values
    number = np.cumsum(used) - 1
    kept = used[facets].all(axis=1) if len(facets) else np.zeros(0, dtype=bool)
    return x[used], number[cells], number[facets[kept]], np.asarray(facet_values)[kept]


# Nodes per facet of the supported cells (by nodes per cell): quadrilaterals of hexahedra,
# triangles of tetrahedra.
_FACET_NODES = {8: 4, 4: 3}


def _cell_types_of(nodes_per_cell: int):
    """(gmsh type, dolfinx cell type, dolfinx facet type) of linear cells with this many nodes."""
    if nodes_per_cell == 8:
        return GMSH_HEXAHEDRON_8, dolfinx_mesh.CellType.hexahedron, dolfinx_mesh.CellType.quadrilateral
    if nodes_per_cell == 4:
        return GMSH_TETRAHEDRON_4, dolfinx_mesh.CellType.tetrahedron, dolfinx_mesh.CellType.triangle
    raise ValueError(f"cells with {nodes_per_cell} nodes: allowed are 8-node hexahedra and 4-node tetrahedra")


def _model_arrays() -> dict:
    """Nodes, cells (hexahedra or tetrahedra) and tagged facets (quadrilaterals or triangles) of the
    current gmsh model as arrays.

    Returns:
        dict with x (n, 3) node coordinates (m), cells (c, 8 or 4) int64 gmsh-ordered
        node indices (0-based rows of x), cell_values (c,) physical volume tags,
        facets (f, 4 or 3) int64 node indices of the facets of the physical
        surfaces, facet_values (f,) their physical surface tags.
    """
    tags, coords, _ = gmsh.model.mesh.getNodes()
    x = coords.reshape(-1, 3)
    # gmsh node tags need not be contiguous: index them through a lookup table.
    index_of_tag = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index_of_tag[tags.astype(np.int64)] = np.arange(len(tags))
    blocks = {3: ([], []), 2: ([], [])}
    for dim in (3, 2):
        for _, tag in gmsh.model.getPhysicalGroups(dim):
            for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                element_types, _, element_nodes = gmsh.model.mesh.getElements(dim, entity)
                for element_type, nodes in zip(element_types, element_nodes):
                    n_nodes = gmsh.model.mesh.getElementProperties(element_type)[3]
                    topology = index_of_tag[np.asarray(nodes, dtype=np.int64).reshape(-1, n_nodes)]
                    blocks[dim][0].append(topology)
                    blocks[dim][1].append(np.full(len(topology), tag, dtype=np.int32))
    cells, cell_values = np.concatenate(blocks[3][0]), np.concatenate(blocks[3][1])
    facet_nodes = _FACET_NODES[cells.shape[1]]
    facet_name = {4: "4-node quadrilaterals (faces of hexahedra)", 3: "3-node triangles (faces of tetrahedra)"}
    found = {block.shape[1] for block in blocks[2][0]}
    if found - {facet_nodes}:
        allowed = (f"physical surfaces must be made of {facet_name[facet_nodes]} "
                   f"(found {', '.join(str(k) for k in sorted(found))}-node faces)")
        raise SceneError("mesh.file", None, allowed, f"scene key 'mesh.file': {allowed}")
    if blocks[2][0]:
        facets, facet_values = np.concatenate(blocks[2][0]), np.concatenate(blocks[2][1])
    else:
        facets, facet_values = np.zeros((0, facet_nodes), dtype=np.int64), np.zeros(0, dtype=np.int32)
    return {"x": x.copy(), "cells": cells, "cell_values": cell_values, "facets": facets,
            "facet_values": facet_values}


def _excavated_regions(scene: typing.Mapping, regions: dict[str, int]) -> dict[str, int]:
    """The regions `[static] excavate` removes (name -> tag): the model is built without their cells.

    Raises:
        SceneError naming static.excavate.i for a name that is no region, or when nothing would remain.
    """
    names = model_excavation(scene, getattr(scene, "stage_model", False))  # (the sequence's: the first step's)
    static = scene.get("static") or {}
    keys = ([f"static.step.{k}.excavate.{i}" for k, step in enumerate(static["step"]) for i in range(len(step["excavate"]))]
            if static.get("step") else [f"static.excavate.{i}" for i in range(len(names))])
    for key, name in zip(keys, names):
        if name not in regions:
            raise SceneError(key, name, "must name a region (physical volume) of the mesh: "
                             + (", ".join(sorted(regions)) or "none"))
    if names and len(names) == len(regions):
        raise SceneError("static.excavate", names, "must leave at least one region of the mesh: "
                         + ", ".join(sorted(regions)))
    return {name: regions[name] for name in names}


def _without_cells(arrays: dict, removed_tags: list[int]) -> dict:
    """`_model_arrays` without the cells of the given physical volumes, the tagged quadrilaterals that
    are no face of a remaining cell, and the nodes no remaining cell uses (renumbered)."""
    keep = ~np.isin(arrays["cell_values"], removed_tags)
    cells, cell_values = arrays["cells"][keep], arrays["cell_values"][keep]
    used, compact = np.unique(cells, return_inverse=True)
    index = np.full(len(arrays["x"]), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    # A quadrilateral is a face of a remaining cell when its four nodes are nodes of that cell.
    facets = arrays["facets"]
    shared = incidence(facets, len(arrays["x"])) @ incidence(cells, len(arrays["x"])).T
    on_cell = np.asarray(shared.max(axis=1).todense()).ravel() >= facets.shape[1] if len(facets) else \
        np.zeros(0, dtype=bool)
    return {"x": arrays["x"][used].copy(), "cells": compact.reshape(cells.shape).astype(np.int64),
            "cell_values": cell_values, "facets": index[facets[on_cell]],
            "facet_values": arrays["facet_values"][on_cell]}


def _physical_groups_and_cell_types() -> tuple[dict[str, int], dict[str, int], list[tuple[int, str]]]:
    """Names and tags of the physical volumes and surfaces of the current gmsh
    model, and the gmsh element types (number, name) found in the physical volumes."""
    regions = {}
    cell_types = set()
    for dim, tag in gmsh.model.getPhysicalGroups(3):
        regions[_physical_name(dim, tag)] = tag
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            element_types, _, _ = gmsh.model.mesh.getElements(dim, entity)
            cell_types.update((int(t), gmsh.model.mesh.getElementProperties(t)[0]) for t in element_types)
    boundaries = {_physical_name(dim, tag): tag for dim, tag in gmsh.model.getPhysicalGroups(2)}
    return regions, boundaries, sorted(cell_types)


def _height_range() -> tuple[float, float]:
    """(lowest, highest) z of the current gmsh model's mesh nodes (m); (0, 0) without nodes."""
    _, coords, _ = gmsh.model.mesh.getNodes()
    if len(coords) == 0:
        return 0.0, 0.0
    z = np.asarray(coords, dtype=float).reshape(-1, 3)[:, 2]
    return float(z.min()), float(z.max())


SURFACE_KEYS = ("wave.surface", "initial_stress.surface")
"""The scene keys that place the ground surface, which must not lie below the model's top."""


def check_surfaces_on_top(scene: typing.Mapping, bottom: float, top: float) -> None:
    """Refuses a ground surface (`SURFACE_KEYS`) below the model's top z (its highest mesh node), for
    every builder: the box's is checked with the scene already, a file's or the layered cavern's
    only once the mesh is read. Tolerance 1e-9 of the model's height.

    Raises:
        SceneError naming the key, its value and the model's top z.
    """
    builder = scene["mesh"].get("builder")
    where = f"the highest node of mesh.file {scene['mesh']['file']}" if builder == "file" else \
        f"the highest node of the mesh.builder {builder!r} mesh"
    for key in SURFACE_KEYS:
        table, name = key.split(".")
        surface = (scene.get(table) or {}).get(name)
        if surface is not None and surface < top - 1e-9 * max(top - bottom, 1.0):
            raise SceneError(key, surface, f"the surface must not lie below the model's top z = {top:.6g} m "
                             f"({where}); give {key} >= {top:.6g}")


def _shared_surfaces() -> dict[str, list[str]]:
    """Physical surface name -> the other physical surfaces holding one of its geometric surfaces
    (a facet carries one physical surface's tag in the model: the other group loses it)."""
    holders = {}
    for dim, tag in gmsh.model.getPhysicalGroups(2):
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            holders.setdefault(int(entity), []).append(_physical_name(dim, tag))
    shared = {}
    for names in holders.values():
        for name in names:
            shared.setdefault(name, set()).update(other for other in names if other != name)
    return {name: sorted(others) for name, others in shared.items() if others}


def _check_support_surfaces_not_shared(scene: typing.Mapping, shared: dict[str, list[str]]) -> None:
    """A pattern's surface must own its facets.

    Raises:
        SceneError naming support.NAME.surface and the other physical surface that holds its facets.
    """
    for name, group in (scene.get("support") or {}).items():
        surface = group.get("surface")
        if surface in shared:
            others = ", ".join(f'"{other}"' for other in shared[surface])
            key, allowed = f"support.{name}.surface", "a surface in one physical group only"
            raise SceneError(key, surface, allowed, f'scene key \'{key}\' = "{surface}": its facets are also in '
                             f"the mesh's physical surface {others}, and a facet carries one physical surface's "
                             f"tag in the model (the other group loses it); allowed: {allowed}")


def _physical_name(dim: int, tag: int) -> str:
    """The name of a physical group; unnamed groups are called by their tag."""
    name = gmsh.model.getPhysicalName(dim, tag)
    return name if name else f"{'volume' if dim == 3 else 'surface'}_{tag}"


def _check_cell_types(cell_types: list[tuple[int, str]], key: str = "mesh.file", value=None) -> None:
    """The physical volumes hold elements, all of a supported type.

    Raises:
        SceneError naming `key` (mesh.file, or mesh.builder for a built mesh) and `value`.
    """
    allowed = " and ".join(f"{name} (gmsh type {number})" for number, name in SUPPORTED_CELL_TYPES.items())
    if not cell_types:
        raise SceneError(key, value, f"the physical volumes hold no elements; allowed: {allowed} "
                         "(mesh the volumes: gmsh -3, into tetrahedra or, recombined, hexahedra)")
    unsupported = [name for number, name in cell_types if number not in SUPPORTED_CELL_TYPES]
    if unsupported:
        raise SceneError(key, value, f"gmsh element types {', '.join(unsupported)} are not supported; "
                         f"allowed: {allowed}, one type per mesh (mesh.order = 2 builds Q2 or P2 from them)")
    if len({number for number, _ in cell_types}) > 1:
        raise SceneError(key, value, "the mesh mixes " + " and ".join(name for _, name in cell_types)
                         + f"; allowed: {allowed}, one type per mesh (dolfinx 0.5 meshes hold one cell type; "
                         "mesh all volumes as hexahedra or all as tetrahedra)")


def _check_tetrahedra_uses(scene: typing.Mapping) -> None:
    """What a tetrahedral mesh cannot do yet (docs/tetrahedra.md): one-point (reduced) integration of
    a nonlinear material (its hourglass control is Q1's; a P1 tetrahedron has one point already) and
    contact pairs on quadratic triangles (the consistent load
    of a uniform traction vanishes at their vertices: a vertex pair would carry no static force
    while its lumped area is positive, so its strength and the force it releases on opening would
    not match the continuum). Nonlinear materials, contact on linear triangles and excavation are
    supported.

    Raises:
        SceneError naming the key.
    """
    interfaces = list((scene.get("contact") or {}).get("interfaces") or [])
    if interfaces and scene["mesh"].get("order", 1) == 2:
        raise SceneError("contact.interfaces", interfaces, "linear tetrahedra (mesh.order = 1) or hexahedra: "
                         "contact pairs on the quadratic triangles of P2 tetrahedra are not supported (their "
                         "vertices carry no consistent load; docs/tetrahedra.md)")
    for name, material in (scene.get("materials") or {}).items():
        for table in ("plasticity", "damage"):
            if (material.get(table) or {}).get("integration") == "reduced":
                raise SceneError(f"materials.{name}.{table}.integration", "reduced", "\"full\" on tetrahedra "
                                 "(one point per cell with hourglass control is for Q1 hexahedra; a P1 "
                                 "tetrahedron has one point already; docs/tetrahedra.md)")


def _check_regions_match_materials(regions: dict[str, int], materials: typing.Mapping,
                                   optional: typing.Iterable[str] = ()) -> None:
    """Every region needs a [materials.NAME] table and every table a region (a table named in
    `optional`, an excavated region's, may be there or not: nothing reads it).

    Raises:
        SceneError naming the first mismatched materials.NAME, listing every mismatch and the
        regions found.
    """
    found = sorted(regions)
    problems = [(name, f"[materials.{name}] is missing for mesh region \"{name}\"")
                for name in found if name not in materials]
    problems += [(name, f"[materials.{name}] names no mesh region")
                 for name in materials if name not in regions and name not in set(optional)]
    if problems:
        allowed = ("[materials] must name exactly the regions (physical volumes) of the mesh: "
                   + (", ".join(found) or "none"))
        key = f"materials.{problems[0][0]}"
        raise SceneError(key, None, allowed,
                         f"scene key '{key}': " + "; ".join(text for _, text in problems) + "; " + allowed)

"""Meshes read from gmsh .msh files.

Physical volumes of the file are regions (one [materials.NAME] table each);
physical surfaces are named boundaries or interfaces.
"""
from __future__ import annotations

import os
import tempfile
import typing

import numpy as np

from pyfem._gmsh import gmsh


def load_msh(path: str | os.PathLike) -> None:
    """Open the .msh file `path` into the current gmsh model; a .geo script is meshed in 3D by gmsh.

    Args:
        path: a gmsh .msh file (or a .geo script) with physical volumes (regions) and,
            optionally, physical surfaces (named boundaries/interfaces).

    Raises:
        SceneError (key mesh.file): no such file, a file gmsh cannot read, or no physical volume.
    """
    from pyfem.errors import SceneError

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError("mesh.file", path, "no such file (expected a gmsh .msh file or .geo script)")
    if path.lower().endswith(".geo"):
        with tempfile.TemporaryDirectory(prefix="pyfem-geo-") as folder:
            msh = os.path.join(folder, "mesh.msh")
            _mesh_geo_script(path, msh)
            _merge(msh, path)
    else:
        _merge(path, path)
    if not gmsh.model.getPhysicalGroups(3):
        raise SceneError("mesh.file", path, "the file has no physical volume: the regions of the mesh "
                         "must be physical volumes (gmsh: Physical Volume(\"rock\") = {...}), "
                         "one [materials.NAME] each")


def _merge(msh: str, given: str) -> None:
    """gmsh.merge of a .msh into the current model (gmsh.open would replace the model that
    gmsh_session made current with a new unnamed one). SceneError (mesh.file = given) if unreadable."""
    from pyfem.errors import SceneError

    try:
        gmsh.merge(msh)
    except Exception as error:  # gmsh reports a file it cannot read as a bare Exception
        raise SceneError("mesh.file", given, f"a gmsh .msh file is expected; gmsh cannot read this one "
                         f"({' '.join(str(error).split())})") from None


# Meshes a .geo in a process of its own: the options a script sets (Mesh.MeshSizeMax, ...) are
# global to gmsh and would otherwise leak into the next script meshed by the same process.
_MESH_GEO = """
import sys, gmsh
gmsh.initialize(readConfigFiles=False)
gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1])
if len(gmsh.model.mesh.getElements(3)[0]) == 0:
    gmsh.model.mesh.generate(3)
gmsh.option.setNumber("Mesh.SaveAll", 0)
gmsh.write(sys.argv[2])
gmsh.finalize()
"""


def _mesh_geo_script(geo: str, msh: str) -> None:
    """gmsh meshes the .geo script `geo` in 3D with the script's own options (sizes, fields,
    recombination) and writes `msh`. SceneError (mesh.file) if it cannot."""
    import subprocess
    import sys

    from pyfem.errors import SceneError

    result = subprocess.run([sys.executable, "-c", _MESH_GEO, os.path.abspath(geo), msh], capture_output=True,
                            text=True, cwd=os.path.dirname(os.path.abspath(geo)) or None)
    if result.returncode != 0 or not os.path.isfile(msh):
        lines = [line for line in result.stderr.strip().splitlines() if line.strip()]
        reason = lines[-1] if lines else f"exit status {result.returncode}"
        raise SceneError("mesh.file", geo, f"gmsh could not mesh this .geo script ({reason})")


# The six tetrahedra of a gmsh-ordered hexahedron (bottom 0-3, top 4-7) around its diagonal 0-6.
_HEXAHEDRON_TETRAHEDRA = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])
# The faces of a gmsh-ordered tetrahedron and hexahedron (node positions).
_CELL_FACES = {4: np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]),
               8: np.array([[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])}
# A point lies inside a tetrahedron when its four barycentric coordinates all exceed this: a cell's
# centroid is at least ~1/8 (barycentric) from its own faces, so a conforming mesh never comes near it.
_INSIDE = 1.0e-6
# At most this many centroids of one volume are tested against another (evenly spaced in cell order).
_SAMPLE = 20000


def volume_problem(excavated: typing.Iterable[str] = ()) -> str | None:
    """What is wrong with the physical volumes of the current gmsh model (a mesh.file), in one
    sentence naming them, or None. Checked, in this order:

    - cells counted in two regions: a volume entity in two physical volumes, or the same cell
      (same nodes) in two volume entities;
    - overlapping or duplicate volumes: a cell centroid of one volume entity lies strictly inside a
      cell of another (barycentric coordinates > 1e-6 in one of its tetrahedra, hexahedra split into
      six), tested for the cells inside the two entities' common bounding box, each against its 8
      nearest tetrahedra of the other entity (a volume left out of gmsh's BooleanFragments is meshed
      on its own over the rock's cells: its centroids lie inside them);
    - an excavated region (names in `excavated`) that shares no cell face with a remaining region
      (it is no hole in the rock).
    """
    groups = {}   # volume entity -> names of its physical volumes
    names = {}
    for _, tag in gmsh.model.getPhysicalGroups(3):
        name = gmsh.model.getPhysicalName(3, tag) or f"volume_{tag}"
        names[tag] = name
        for entity in gmsh.model.getEntitiesForPhysicalGroup(3, tag):
            groups.setdefault(int(entity), []).append(name)
    for entity, in_groups in sorted(groups.items()):
        if len(in_groups) > 1:
            return (f"volume {entity} is in the physical volumes {_quoted(in_groups)}: its cells would be counted "
                    "in two regions; put each volume in one physical volume")
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    if len(node_tags) == 0:
        return None
    x = np.asarray(coords, dtype=float).reshape(-1, 3)
    index_of_tag = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    index_of_tag[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    cells = {}
    for entity in groups:
        blocks = []
        for element_type, element_nodes in zip(*gmsh.model.mesh.getElements(3, entity)[::2]):
            n_nodes = gmsh.model.mesh.getElementProperties(element_type)[3]
            if n_nodes in _CELL_FACES:
                blocks.append(index_of_tag[np.asarray(element_nodes, dtype=np.int64).reshape(-1, n_nodes)])
        if blocks and len({b.shape[1] for b in blocks}) == 1:
            cells[entity] = np.concatenate(blocks)
    if not cells:
        return None

    def label(entity):
        return f"volume {entity} ({_quoted(groups[entity])})"

    # The same cell in two entities.
    width = {c.shape[1] for c in cells.values()}
    if len(width) == 1:
        entities = sorted(cells)
        every = np.sort(np.concatenate([cells[e] for e in entities]), axis=1)
        owner = np.concatenate([np.full(len(cells[e]), e) for e in entities])
        _, inverse, counts = np.unique(every, axis=0, return_inverse=True, return_counts=True)
        twice = counts[inverse.ravel()] > 1
        if twice.any():
            holders = sorted({int(e) for e in owner[twice]})
            a, b = (holders + holders)[:2]
            return (f"{label(a)} and {label(b)} hold the same cells ({int((counts > 1).sum())} of them): they would be "
                    "counted twice; mesh each volume once")

    # Overlapping volumes.
    boxes = {e: (x[np.unique(c)].min(axis=0), x[np.unique(c)].max(axis=0)) for e, c in cells.items()}
    size = float(np.max(x.max(axis=0) - x.min(axis=0))) or 1.0
    entities = sorted(cells)
    for i, a in enumerate(entities):
        for b in entities[i + 1:]:
            low = np.maximum(boxes[a][0], boxes[b][0])
            high = np.minimum(boxes[a][1], boxes[b][1])
            if np.any(high - low <= 1e-9 * size):
                continue
            for inner, outer in ((a, b), (b, a)):
                share = _share_inside(x, cells[inner], cells[outer], low, high)
                if share > 0:
                    return (f"{label(inner)} and {label(outer)} overlap ({_percent(share)} of the cells of volume {inner} "
                            f"in the volumes' common bounding box lie inside cells of volume {outer}): the volumes must not share space; fragment them "
                            "(gmsh: BooleanFragments{ Volume{...}; Delete; }{ Volume{...}; Delete; })")

    # An excavated region must be a hole in the remaining rock: at least one shared cell face.
    excavated = [name for name in excavated]
    if excavated and len(width) == 1:
        faces_of = {}
        for entity, c in cells.items():
            faces = np.sort(c[:, _CELL_FACES[c.shape[1]]].reshape(-1, _CELL_FACES[c.shape[1]].shape[1]), axis=1)
            for name in groups[entity]:
                faces_of.setdefault(name, []).append(faces)
        faces_of = {name: np.unique(np.concatenate(f), axis=0) for name, f in faces_of.items()}
        remaining = [name for name in faces_of if name not in excavated]
        rest = np.unique(np.concatenate([faces_of[name] for name in remaining]), axis=0) if remaining else None
        for name in excavated:
            if name not in faces_of or rest is None:
                continue
            both = np.concatenate([faces_of[name], rest])
            if len(np.unique(both, axis=0)) == len(both):
                return (f"the excavated region {_quoted([name])} shares no cell face with the remaining regions "
                        f"{_quoted(remaining)}: removing it would open no hole in the rock (a volume left out of "
                        "gmsh's BooleanFragments overlaps the rock instead of cutting it)")
    return None


def _share_inside(x: np.ndarray, inner: np.ndarray, outer: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """The share of the cells of `inner` with their centroid in the box low-high (at most `_SAMPLE` of them,
    evenly spaced) whose centroid lies strictly inside a cell of `outer` (0 when none)."""
    from scipy.spatial import cKDTree

    centroids = x[inner].mean(axis=1)
    candidates = np.flatnonzero(np.all((centroids > low) & (centroids < high), axis=1))
    if len(candidates) == 0:
        return 0.0
    if len(candidates) > _SAMPLE:   # an even sample bounds the cost of a large mesh
        candidates = candidates[np.linspace(0, len(candidates) - 1, _SAMPLE).astype(np.int64)]
    tetrahedra = outer if outer.shape[1] == 4 else outer[:, _HEXAHEDRON_TETRAHEDRA].reshape(-1, 4)
    corners = x[tetrahedra]                                    # (t, 4, 3)
    k = min(8, len(tetrahedra))
    tree, scale = cKDTree(corners.mean(axis=1)), 1e-14 * _size_cubed(corners)
    found = 0
    for start in range(0, len(candidates), 20000):   # in chunks: (points, k, 3, 3) arrays
        points = centroids[candidates[start:start + 20000]]
        nearest = tree.query(points, k=k)[1].reshape(len(points), k)
        origin = corners[nearest, 0]                               # (p, k, 3)
        edges = np.stack([corners[nearest, j] - origin for j in (1, 2, 3)], axis=-1)   # (p, k, 3, 3)
        offset = points[:, None, :] - origin
        valid = np.abs(np.linalg.det(edges)) > scale
        lam = np.zeros(offset.shape)
        lam[valid] = np.linalg.solve(edges[valid], offset[valid][..., None])[..., 0]
        inside = valid & np.all(lam > _INSIDE, axis=-1) & (lam.sum(axis=-1) < 1.0 - _INSIDE)
        found += int(inside.any(axis=1).sum())
    return found / len(candidates)


def _size_cubed(corners: np.ndarray) -> float:
    """The cube of the largest extent of a set of points (a scale for volumes)."""
    points = corners.reshape(-1, 3)
    return float(np.max(points.max(axis=0) - points.min(axis=0))) ** 3


def _percent(share: float) -> str:
    """A share as whole per cent ("100 %", "3 %"), "< 1 %" below one."""
    return f"{100 * share:.0f} %" if share >= 0.005 else "< 1 %"


def _quoted(names) -> str:
    return ", ".join(f'"{name}"' for name in names)

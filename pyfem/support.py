"""Rock bolts and anchor cables placed in a model's mesh (docs/method.md "Rock bolts and cables").

A group of straight bolts given as lines head -> tip is cut into segments of about `segment` m;
each bolt node is located in the rock mesh (the model's point_weights: host cell and the
interpolation weights of its nodes, exact for every field of the space) and the group becomes one
kernel GroutedBolts component. `scene_groups` builds the scene's `[support.NAME]` groups (explicit
lines, or a pattern normal to a named surface: `pattern_lines`), `stiffness_bound` the bound of their
condensed stiffness that the stable step includes, `group_summary` and `segment_rows` what run.json,
`support.csv` and `static/support.csv` report.
"""
import dataclasses
import math

import numpy as np
import scipy.sparse as sp

from pyfem import _kernels
from pyfem.errors import SceneError
from pyfem.excavation_steps import static_steps


@dataclasses.dataclass
class BoltGroup:
    """One group of bolts in a model: the kernel component and where its nodes are."""
    component: object          # _kernels.GroutedBolts
    bolt_offsets: np.ndarray   # (b + 1,) int64: bolt j has the bolt nodes [offsets[j], offsets[j + 1])
    arc_length: np.ndarray     # (m,) s from the head (m)
    positions: np.ndarray      # (m, 3) coordinates of the bolt nodes (m)
    directions: np.ndarray     # (b, 3) unit axis head -> tip
    host_nodes: np.ndarray = None    # (m, k) int32 rock nodes of each bolt node's host cell
    host_weights: np.ndarray = None  # (m, k) their interpolation weights
    parameters: dict = None          # GroutedBolts' keyword parameters

    def fresh_component(self):
        """A new kernel component of the group's bolts, unloaded (the same geometry and parameters)."""
        return _kernels.GroutedBolts(self.bolt_offsets, self.arc_length, self.directions, self.host_nodes,
                                     self.host_weights, **self.parameters)


def discretise_lines(lines, segment: float, free_length: float = 0.0):
    """Bolt nodes of straight lines [x0, y0, z0, x1, y1, z1] (head to tip, m): each cut into
    ceil(length / segment) equal segments, or, with a free length, the free part and the grouted
    part cut separately so that a node falls on the end of the free length. Returns the offsets,
    the arc lengths, the positions and the unit directions."""
    lines = np.asarray(lines, dtype=np.float64).reshape(-1, 6)
    offsets, arcs, positions, directions = [0], [], [], []
    for head, tip in zip(lines[:, :3], lines[:, 3:]):
        length = float(np.linalg.norm(tip - head))
        if not length > 0.0:
            raise ValueError(f"lines: a bolt from {head.tolist()} to {tip.tolist()} has no length")
        if free_length >= length:
            raise ValueError(f"free_length: {free_length} m is not shorter than a bolt of {length:.6g} m")
        parts = [(0.0, free_length), (free_length, length)] if free_length > 0.0 else [(0.0, length)]
        s = [0.0]
        for lo, hi in parts:
            n = max(1, math.ceil((hi - lo) / segment - 1e-9))
            s.extend(lo + (hi - lo) * np.arange(1, n + 1) / n)
        s = np.array(s)
        s[-1] = length
        direction = (tip - head) / length
        arcs.append(s)
        positions.append(head + s[:, None] * direction)
        directions.append(direction)
        offsets.append(offsets[-1] + s.size)
    return (np.array(offsets, dtype=np.int64), np.concatenate(arcs), np.concatenate(positions),
            np.array(directions))


def locate(model, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(host nodes (m, k), weights (m, k), the host nodes' coordinates (m, k, 3)) of each point: the
    model's point_weights in its preferred cell (`Model.preferred_cell`). On a distributed mesh (more
    than one rank) the whole model's preferred cell among every rank's owned cells, the host nodes
    numbered globally (dolfinx's global node numbers) and the answer the same on every rank (a
    collective); on one rank the function space's local nodes (the serial numbering).

    Raises:
        PointOutsideMesh: the first point in no cell of the model (on every rank alike).
    """
    from pyfem.operators import PointOutsideMesh

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    comm = model.mesh.comm
    if comm.size == 1:
        nodes, weights = model.point_weights(points)
        return nodes, weights, np.asarray(model.node_coords)[nodes]
    owned_cells = model.n_cells
    best = []
    for found in model.cells_holding(points):
        found = found[found < owned_cells]
        best.append((None, None) if not len(found) else model.preferred_cell(found))
    offers = comm.allgather([None if centroid is None else tuple(centroid) for _, centroid in best])
    mine = []
    for j in range(len(points)):
        held = [(offer[j], q) for q, offer in enumerate(offers) if offer[j] is not None]
        if not held:
            raise PointOutsideMesh(j, points[j], *model.bounds)
        if min(held)[1] == comm.rank:
            mine.append(j)
    mine = np.array(mine, dtype=np.int64)
    index_map = model.V.dofmap.index_map
    mapped = np.concatenate([np.arange(*index_map.local_range), index_map.ghosts]).astype(np.int64)
    if len(mine):
        cells = np.array([best[j][0] for j in mine], dtype=np.int32)
        nodes, weights = model.point_weights(points[mine], cells)
        found = (mine, mapped[nodes], weights, np.asarray(model.node_coords)[nodes])
    else:
        found = None
    pieces = [piece for piece in comm.allgather(found) if piece is not None]
    k = pieces[0][1].shape[1]
    nodes, weights, coords = np.empty((len(points), k), np.int64), np.empty((len(points), k)), np.empty((len(points), k, 3))
    for index, piece_nodes, piece_weights, piece_coords in pieces:
        nodes[index], weights[index], coords[index] = piece_nodes, piece_weights, piece_coords
    return nodes, weights, coords


def bolt_group(model, lines, *, diameter: float, E: float, yield_force: float, bond_stiffness: float,
               bond_strength: float, segment: float, pretension: float = 0.0, free_length: float = 0.0,
               head_stiffness: float = 0.0) -> BoltGroup:
    """The bolts along `lines` in `model` (pyfem.operators.Model; every node inside its mesh) with
    the parameters of a support group (SI units; steel area pi diameter^2 / 4). On a distributed mesh
    the host nodes are global and the group has no kernel component (each rank makes its own:
    pyfem/distributed_support.py)."""
    offsets, arcs, positions, directions = discretise_lines(lines, segment, free_length)
    host_nodes, host_weights, _ = locate(model, positions)
    parameters = dict(axial_stiffness=E * math.pi * diameter**2 / 4.0, yield_force=yield_force,
                      bond_stiffness=bond_stiffness, bond_strength=bond_strength, pretension=pretension,
                      free_length=free_length, head_stiffness=head_stiffness)
    group = BoltGroup(None, offsets, arcs, positions, directions, host_nodes, host_weights, parameters)
    if model.mesh.comm.size == 1:
        group.component = group.fresh_component()
    return group


# ---------------------------------------------------------------------------------------------
# The scene's groups ([support.NAME], docs/scene-keys.md)
# ---------------------------------------------------------------------------------------------

HEAD_PLATE_FACTOR = 10.0
"""A cable's head plate: a spring of HEAD_PLATE_FACTOR x EA / free length (N/m; the segment without a
free length) tying its head node to the rock, stiff against the free length it locks off (a bolt, type
"bolt", has none). Stiffer plates gain little and stiffen the head's host nodes, which the step sees."""


@dataclasses.dataclass
class SupportGroup:
    """One `[support.NAME]` group of a scene placed in the model.

    Attributes:
        name: NAME.
        settings: the scene's table.
        lines: (b, 6) head and tip of each bolt (m).
        segment: the element length used (m).
        stage: "static": installed in the static stage with `static.install` (static.support);
            "start": at the start of the dynamic run.
        bolts: the placement and the kernel component the run steps.
    """

    name: str
    settings: dict
    lines: np.ndarray
    segment: float
    stage: str
    bolts: BoltGroup

    @property
    def component(self):
        return self.bolts.component

    def fresh(self) -> "SupportGroup":
        """The same group with a new, unloaded component (a trial stepper's)."""
        return dataclasses.replace(self, bolts=dataclasses.replace(self.bolts, component=self.bolts.fresh_component()))

    @property
    def axial_stiffness(self) -> float:
        return self.bolts.parameters["axial_stiffness"]

    @property
    def total_length(self) -> float:
        return float(np.linalg.norm(self.lines[:, 3:] - self.lines[:, :3], axis=1).sum())


def _line_key(name: str, settings: dict, bolt: int) -> tuple[str, object]:
    """The scene key and value a bolt of a group stands for (its line, or the pattern's length)."""
    if settings["lines"] is not None:
        return f"support.{name}.lines.{bolt}", settings["lines"][bolt]
    return f"support.{name}.length", settings["length"]


SEGMENTS_PER_BOLT = 4
"""The default segment is at most the shortest bolt's length / SEGMENTS_PER_BOLT: a bolt's axial force
falls to zero at both free ends, which one segment (a constant force) cannot show."""


def _default_segment(model, lines: np.ndarray, order: int) -> float:
    """About the node spacing of the cells the bolts cross (the median, over points every tenth of
    each bolt, of the host cell's largest extent along x, y, z divided by the element order), and at
    most the shortest bolt's length / SEGMENTS_PER_BOLT."""
    points = np.concatenate([line[:3] + np.linspace(0.0, 1.0, 11)[:, None] * (line[3:] - line[:3]) for line in lines])
    _, _, coordinates = locate(model, points)  # (m, k, 3)
    extent = (coordinates.max(axis=1) - coordinates.min(axis=1)).max(axis=1)
    shortest = float(np.min(np.linalg.norm(lines[:, 3:] - lines[:, :3], axis=1)))
    return min(float(np.median(extent)) / order, shortest / SEGMENTS_PER_BOLT)


def scene_groups(scene, model) -> list[SupportGroup]:
    """The scene's support groups placed in the model, in the scene's order.

    Raises:
        SceneError: a pattern's surface is not one of the mesh's, or has no axis; a bolt node lies
            in no cell of the model (outside it, or in a cavity or excavated region).
    """
    from pyfem.operators import PointOutsideMesh

    tables = scene.get("support") or {}
    steps = static_steps(scene["static"]) if scene.get("static") else []  # (a sequence's: every step's)
    static_groups = {name for step in steps for name in step["support"]}
    installed_regions = [name for step in steps for name in step["install"]]
    groups = []
    for name, settings in tables.items():
        if settings["lines"] is not None:
            lines = np.asarray(settings["lines"], dtype=np.float64).reshape(-1, 6)
        else:
            lines = pattern_lines(model, name, settings, installed_regions)
        outside, bolt = None, None
        try:
            segment = settings["segment"] or _default_segment(model, lines, scene["mesh"]["order"])
        except PointOutsideMesh as error:
            outside, bolt = error, error.index // 11
        if outside is None:
            offsets, arcs, positions, _ = discretise_lines(lines, segment, settings["free_length"])
            try:
                locate(model, positions)
            except PointOutsideMesh as error:
                outside, bolt = error, int(np.searchsorted(offsets, error.index, side="right") - 1)
        if outside is not None:
            error = outside
            key, value = _line_key(name, settings, bolt)
            head, tip = lines[bolt, :3].tolist(), lines[bolt, 3:].tolist()
            where = "" if settings["lines"] is not None else f" (bolt {bolt} of the pattern, from {head} to {tip})"
            excavated = list((scene.get("static") or {}).get("excavate") or [])
            allowed = "every bolt node in a cell of the model" + (
                f" (the model has none in the excavated regions {', '.join(excavated)})" if excavated else "")
            raise SceneError(key, value, allowed, f"scene key '{key}' = {value}{where}: its point "
                             f"{[round(x, 6) for x in error.point]} is {error.where}; allowed: {allowed}") from None
        E, diameter = settings["E"], settings["diameter"]
        head_stiffness = (HEAD_PLATE_FACTOR * E * math.pi * diameter**2 / 4.0 / max(settings["free_length"], segment)
                          if settings["type"] == "cable" else 0.0)
        try:
            bolts = bolt_group(model, lines, diameter=diameter, E=E, yield_force=settings["yield_force"],
                               bond_stiffness=settings["bond_stiffness"], bond_strength=settings["bond_strength"],
                               segment=segment, pretension=settings["pretension"],
                               free_length=settings["free_length"], head_stiffness=head_stiffness)
        except ValueError as error:  # the kernel's own checks (the scene's should have caught them)
            raise SceneError(f"support.{name}", None, str(error), f"scene key 'support.{name}': {error}") from None
        groups.append(SupportGroup(name, settings, lines, segment, "static" if name in static_groups else "start",
                                   bolts))
    return groups


# ---------------------------------------------------------------------------------------------
# A pattern normal to a named surface
# ---------------------------------------------------------------------------------------------

def _surface_triangles(model, name: str, key: str, installed_regions: list):
    """(vertex ids (t, 3), vertex coordinates, unit normals (t, 3) pointing into the rock) of the
    facets of the named surface, quadrilaterals cut in two."""
    from dolfinx.cpp.mesh import entities_to_geometry

    if name not in model.boundaries:
        raise SceneError(key, name, "must name a surface of the mesh: " + ", ".join(sorted(model.boundaries)))
    mesh = model.mesh
    tdim = mesh.topology.dim
    facets = model.facet_tags.find(model.boundaries[name])
    comm = mesh.comm
    if comm.size > 1:  # each rank its owned facets (gathered below)
        facets = facets[facets < mesh.topology.index_map(mesh.topology.dim - 1).size_local]
    if not comm.allreduce(len(facets)):
        raise SceneError(key, name, "must name a surface with facets in the model (this one has none left: "
                         "excavated?)")
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facet_cells = mesh.topology.connectivity(tdim - 1, tdim)
    vertices = entities_to_geometry(mesh._mesh, tdim - 1,
                                    np.asarray(facets, dtype=np.int32), False)
    x = mesh.geometry.x
    excluded = set()
    for region in installed_regions:
        if region in model.regions:
            excluded.update(model.cell_tags.find(model.regions[region]).tolist())
    triangles, normals = [], []
    for facet, corners in zip(facets, vertices):
        cells = [c for c in facet_cells.links(facet) if c not in excluded] or list(facet_cells.links(facet))
        inside = model.cell_centroids(np.array(cells[:1], dtype=np.int32))[0]
        # dolfinx orders a quadrilateral's vertices as a tensor product: (0, 1, 3) and (0, 3, 2) cover it.
        pieces = [corners[[0, 1, 2]]] if len(corners) == 3 else [corners[[0, 1, 3]], corners[[0, 3, 2]]]
        for piece in pieces:
            normal = np.cross(x[piece[1]] - x[piece[0]], x[piece[2]] - x[piece[0]])
            normal /= np.linalg.norm(normal)
            if np.dot(normal, inside - x[piece].mean(axis=0)) < 0.0:
                normal = -normal
            triangles.append(piece)
            normals.append(normal)
    # The whole surface on every rank: its triangles in the order of their centroids (x, y, z), the
    # vertices numbered by their coordinates, so that the pattern (its bolts' order, and where a
    # closed section's first bolt goes) is the same for any numbering and rank count.
    corners = np.concatenate(comm.allgather(x[np.array(triangles, dtype=np.int64).reshape(-1, 3)].reshape(-1, 3, 3)))
    normals = np.concatenate(comm.allgather(np.array(normals).reshape(-1, 3)))
    centroids = corners.mean(axis=1)
    order = np.lexsort((centroids[:, 2], centroids[:, 1], centroids[:, 0]))
    corners, normals = corners[order], normals[order]
    vertices, inverse = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    return inverse.reshape(-1, 3), vertices, normals


AXIS_TILT = 10.0
"""Degrees: a pattern's surface is extruded along one direction when its facets' normals tilt out of
the plane normal to it by at most this (their area-weighted rms): the flat triangles of a curved
wall meshed with tetrahedra tilt a little (measured 0.94 deg rms for 0.75 m triangles on a 3 m
tunnel's wall, tests/test_support_scene.py); an octahedron's (a coarse sphere's) 35 deg."""


def _surface_axis(triangles: np.ndarray, x: np.ndarray, normals: np.ndarray, key: str,
                  name: str) -> tuple[np.ndarray, bool]:
    """The direction the surface's normals are (nearly) perpendicular to (a tunnel's axis; for a plane,
    or a surface with no one such direction, the in-plane direction nearest y, else x), and whether
    the surface is extruded along it (not a plane). The axis is the eigenvector of the smallest
    eigenvalue of sum(area n n^T): that eigenvalue over the trace is the area-weighted mean of
    (n . axis)^2, the square of the normals' rms tilt out of the plane normal to the axis."""
    areas = 0.5 * np.linalg.norm(np.cross(x[triangles[:, 1]] - x[triangles[:, 0]],
                                          x[triangles[:, 2]] - x[triangles[:, 0]]), axis=1)
    tensor = (areas[:, None, None] * normals[:, :, None] * normals[:, None, :]).sum(axis=0)
    values, vectors = np.linalg.eigh(tensor)
    tilt = math.degrees(math.asin(math.sqrt(min(max(values[0], 0.0) / values.sum(), 1.0))))
    if tilt > AXIS_TILT:
        raise SceneError(key, name, f"a pattern needs a surface extruded along one direction (a tunnel's or "
                         f"cavern's wall, a plane): this one's normals tilt {tilt:.3g} deg (rms) out of the plane "
                         f"normal to any one direction (allowed: at most {AXIS_TILT:g} deg)")
    if values[1] <= 1e-6 * values[2] or values[0] > 0.25 * values[1]:  # a plane, or no one axis
        normal = vectors[:, 2]
        for axis in (np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])):
            along = axis - np.dot(axis, normal) * normal
            if np.linalg.norm(along) > 1e-6:
                return along / np.linalg.norm(along), False
    axis = vectors[:, 0]
    return (axis if axis[np.argmax(np.abs(axis))] > 0.0 else -axis), True


def _closed_start(chain: list, keys: list, x: np.ndarray, axis: np.ndarray) -> int:
    """Where a closed section's chain begins (its first bolt): of its points on the mesh edges most
    nearly along the axis (an extruded wall's lines along its length, not a quadrilateral's diagonal),
    the lowest in x, then y, then z: the same point whatever order the facets are read in."""
    points = np.array([point for point, _ in chain[:-1]])
    edges = np.array([x[b] - x[a] for a, b in keys[:-1]])
    along = np.abs(edges @ axis) / np.linalg.norm(edges, axis=1)
    best = np.flatnonzero(along >= along.max() - 1e-9)
    order = np.lexsort((points[best, 2], points[best, 1], points[best, 0]))
    return int(best[order[0]])


def _section_chains(triangles: np.ndarray, x: np.ndarray, axis: np.ndarray, t: float):
    """The section of the surface by the plane axis . p = t: chains (each a list of (point, triangle)
    from one end to the other; closed chains repeat their first point)."""
    distance = x[triangles] @ axis - t  # (T, 3)
    crossing = np.flatnonzero((distance.min(axis=1) < 0.0) & (distance.max(axis=1) > 0.0))
    points, neighbours = {}, {}
    for k in crossing:
        keys = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            da, db = distance[k, a], distance[k, b]
            if (da < 0.0) != (db < 0.0):
                va, vb = int(triangles[k, a]), int(triangles[k, b])
                edge = (min(va, vb), max(va, vb))
                if edge not in points:
                    d0 = distance[k, a] if va < vb else distance[k, b]
                    d1 = distance[k, b] if va < vb else distance[k, a]
                    points[edge] = x[edge[0]] + d0 / (d0 - d1) * (x[edge[1]] - x[edge[0]])
                keys.append(edge)
        if len(keys) == 2:
            neighbours.setdefault(keys[0], []).append((keys[1], k))
            neighbours.setdefault(keys[1], []).append((keys[0], k))
    chains, seen = [], set()
    starts = [key for key, links in neighbours.items() if len(links) == 1] + list(neighbours)
    for start in starts:
        if start in seen:
            continue
        chain, current, previous, keys = [(points[start], None)], start, None, [start]
        seen.add(start)
        while True:
            step = [(key, k) for key, k in neighbours[current] if key != previous or len(neighbours[current]) == 1]
            step = [(key, k) for key, k in step if key not in seen or (key == start and len(chain) > 2)]
            if not step:
                break
            key, k = step[0]
            chain.append((points[key], k))
            keys.append(key)
            if key == start:
                break
            seen.add(key)
            previous, current = current, key
        if len(chain) > 2 and keys[-1] == start:  # closed: begin at a canonical point (`_closed_start`)
            first = _closed_start(chain, keys, x, axis)
            chain = [(chain[first][0], None)] + chain[first + 1:] + chain[1:first + 1]
        if len(chain) > 1:
            chains.append(chain)
    return chains


FEATURE_ANGLE = 30.0
"""Degrees: a wall's normal at a point of a facet is interpolated from its corners' normals, each
the area-weighted mean of the normals of the facets around the corner within this angle of the
facet's own (a curved wall's flat facets tilt by about their size over its radius; a cavern's
corner between a wall and its crown is no curve to smooth over)."""


def _wall_normal(k: int, point: np.ndarray, triangles: np.ndarray, x: np.ndarray, normals: np.ndarray,
                 around: dict) -> np.ndarray:
    """The wall's unit normal at a point of triangle k (FEATURE_ANGLE)."""
    corners = x[triangles[k]]
    uv = np.linalg.lstsq(np.column_stack([corners[1] - corners[0], corners[2] - corners[0]]),
                         point - corners[0], rcond=None)[0]
    weights = np.clip([1.0 - uv.sum(), uv[0], uv[1]], 0.0, 1.0)
    direction = np.zeros(3)
    for weight, vertex in zip(weights, triangles[k]):
        near = np.array(around[int(vertex)])
        near = near[normals[near] @ normals[k] >= math.cos(math.radians(FEATURE_ANGLE))]
        sides = np.cross(x[triangles[near, 1]] - x[triangles[near, 0]], x[triangles[near, 2]] - x[triangles[near, 0]])
        mean = (np.linalg.norm(sides, axis=1)[:, None] * normals[near]).sum(axis=0)
        direction += weight * mean / np.linalg.norm(mean)
    return direction / np.linalg.norm(direction)


def pattern_lines(model, name: str, settings: dict, installed_regions: list) -> np.ndarray:
    """(b, 6) the bolts of a pattern: rows every spacing[1] along the surface's axis (centred, at least
    half a spacing from its ends), and in each row's section bolts every spacing[0] of arc length
    (centred on an open section; a closed one gets the whole number nearest its length / spacing[0],
    evenly), each of `length` along the surface's normal into the rock (away from `installed_regions`).
    """
    key = f"support.{name}.surface"
    surface = settings["surface"]
    around, along = settings["spacing"]
    triangles, x, normals = _surface_triangles(model, surface, key, installed_regions)
    axis, extruded = _surface_axis(triangles, x, normals, key, surface)
    if extruded:  # a facet's normal without its tilt along the axis: the wall's normal
        normals = normals - np.outer(normals @ axis, axis)
        normals /= np.linalg.norm(normals, axis=1)[:, None]
    by_vertex = {}  # vertex -> the triangles around it
    for k, corners in enumerate(triangles):
        for vertex in corners:
            by_vertex.setdefault(int(vertex), []).append(k)
    used = np.unique(triangles)
    lo, hi = float((x[used] @ axis).min()), float((x[used] @ axis).max())
    extent = hi - lo
    n_rows = max(1, int(math.floor(extent / along + 1e-9)))
    rows = lo + 0.5 * (extent - (n_rows - 1) * along) + along * np.arange(n_rows)
    heights = x[used] @ axis
    lines = []
    for row in rows:
        # The section is cut a hair off the nodes (a clean one) and its heads moved back onto the row:
        # the surface is extruded along the axis.
        t = row
        while np.min(np.abs(heights - t)) < 1e-9 * max(extent, 1.0):
            t += 1e-6 * along
        for chain in _section_chains(triangles, x, axis, t):
            p = np.array([point for point, _ in chain])
            owners = [k for _, k in chain[1:]]
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
            total = arc[-1]
            closed = np.allclose(p[0], p[-1])
            if closed:
                n = max(1, int(round(total / around)))
                stations = total / n * np.arange(n)
            else:
                n = max(1, int(math.floor(total / around + 1e-9)))
                stations = 0.5 * (total - (n - 1) * around) + around * np.arange(n)
            for s in stations:
                j = min(int(np.searchsorted(arc, s, side="right") - 1), len(owners) - 1)
                w = (s - arc[j]) / max(arc[j + 1] - arc[j], 1e-300)
                head = p[j] + w * (p[j + 1] - p[j]) - (t - row) * axis
                direction = _wall_normal(owners[j], head + (t - row) * axis, triangles, x, normals, by_vertex)
                lines.append(np.concatenate([head, head + settings["length"] * direction]))
    if not lines:
        raise SceneError(key, surface, "the pattern found no section of this surface to place bolts on")
    return np.array(lines)


# ---------------------------------------------------------------------------------------------
# What the stable step and the reports need
# ---------------------------------------------------------------------------------------------

def stiffness_bound(groups: list, n_nodes: int) -> sp.csr_matrix:
    """(3n, 3n) P^T diag(k_b L_k) P: an upper bound (in the order of positive semi-definite matrices)
    of the condensed stiffness the bolts add to the rock, P the map from the rock's displacements to
    the axial displacement d . sum_a N_a u_a at the bolt nodes. The condensed stiffness
    B - B (K_bar + B)^-1 B is below B = diag(k_b L_k) (the head plate's spring adds to B)."""
    total = sp.csr_matrix((3 * n_nodes, 3 * n_nodes))
    for group in groups:
        bolts = group.bolts
        m, k = bolts.host_nodes.shape
        bolt_of_node = np.repeat(np.arange(len(bolts.bolt_offsets) - 1), np.diff(bolts.bolt_offsets))
        d = bolts.directions[bolt_of_node]  # (m, 3)
        rows = np.repeat(np.arange(m), 3 * k)
        columns = (3 * bolts.host_nodes[:, :, None] + np.arange(3)).reshape(m, -1).ravel()
        values = (bolts.host_weights[:, :, None] * d[:, None, :]).reshape(m, -1).ravel()
        P = sp.csr_matrix((values, (rows, columns)), shape=(m, 3 * n_nodes))
        spring = bolts.parameters["bond_stiffness"] * bolts.component.bond_length()
        head = bolts.parameters["head_stiffness"]
        if head > 0.0:
            spring[bolts.bolt_offsets[:-1]] += head
        total = total + (P.T @ sp.diags(spring) @ P).tocsr()
    return total


def group_summary(group: SupportGroup) -> dict:
    """run.json's "support" entry of a group: bolts, total length, yielded segments, peak force."""
    component = group.component
    strain = np.asarray(component.plastic_strain())
    per_level = getattr(component, "bolts_per_level", None)  # local time stepping (pyfem/distributed_support.py)
    return {**({"bolts_per_level": per_level()} if per_level is not None else {}),
            "type": group.settings["type"], "installed": group.stage, "bolts": int(component.n_bolts),
            "total_length": group.total_length, "segments": int(component.n_segments),
            "yielded_segments": int(np.count_nonzero(strain != 0.0)),
            "slipping_nodes": int(np.count_nonzero(np.asarray(component.plastic_slip()) != 0.0)),
            "peak_axial_force": float(np.max(component.peak_axial_force(), initial=0.0)),
            "yield_force": group.settings["yield_force"]}


def segment_rows(group: BoltGroup, name: str) -> list[tuple]:
    """One row per segment: (group, bolt, s, x, y, z, axial_force, bond_slip, peak_axial_force),
    s and the position at the segment's middle, the bond slip the mean of its two nodes' (m)."""
    component = group.component
    force, peak = component.axial_force(), component.peak_axial_force()
    slip = component.bond_slip()
    rows = []
    for bolt in range(len(group.bolt_offsets) - 1):
        begin, end = group.bolt_offsets[bolt], group.bolt_offsets[bolt + 1]
        for k in range(begin, end - 1):
            e = k - bolt
            middle = 0.5 * (group.positions[k] + group.positions[k + 1])
            rows.append((name, bolt, 0.5 * (group.arc_length[k] + group.arc_length[k + 1]), *middle.tolist(),
                         float(force[e]), 0.5 * float(slip[k] + slip[k + 1]), float(peak[e])))
    return rows


CSV_COLUMNS = ("group", "bolt", "s", "x", "y", "z", "axial_force", "bond_slip")
"""support.csv's and static/support.csv's columns (docs/outputs); the end-of-run file adds peak_axial_force."""


def write_csv(path, rows: list, peak: bool) -> None:
    """One row per segment (`segment_rows`): s from the head (m), its middle (m), axial force (N,
    tension positive), bond slip (m); with `peak`, the largest |axial force| so far (N)."""
    from pathlib import Path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = CSV_COLUMNS + (("peak_axial_force",) if peak else ())
    with open(path, "w") as stream:
        stream.write(",".join(columns) + "\n")
        for row in rows:
            values = row if peak else row[:8]
            stream.write(",".join([values[0], str(values[1])] + [repr(float(v)) for v in values[2:]]) + "\n")



"""Structured hexahedral box: the homogeneous test model of the project.

`build_box` meshes an axis-aligned box with transfinite hexahedra in the gmsh
API and tags it: one physical volume "rock" and six physical surfaces
"xmin", "xmax", "ymin", "ymax", "zmin", "zmax".

`build_layered_box` stacks horizontal layers in the same box: one physical
volume per material (named by the material), the six faces (each made of
one surface per layer on the sides) and the layer interfaces
"interface_1", "interface_2", ... from the bottom up.

`gmsh_session` is the one place that starts gmsh, so builders can also run
inside a script that already uses gmsh without disturbing its models.
"""
from __future__ import annotations

import contextlib
import math
import typing

from pyfem._gmsh import gmsh, initialize as initialize_gmsh, is_initialized as gmsh_initialized
import numpy as np

BOX_REGION = "rock"
BOX_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


def gmsh_is_initialized() -> bool:
    """Whether the gmsh API is initialized in this process (pyfem._gmsh.is_initialized: gmsh
    4.8 cannot be asked without risking exit(1), see that module)."""
    return gmsh_initialized()


@contextlib.contextmanager
def gmsh_session(model_name: str) -> typing.Iterator[None]:
    """Run the body with a fresh, current gmsh model named `model_name`.

    Initializes gmsh (quietly) only if it is not running. gmsh stays
    initialized afterwards: a finalized gmsh prints an error on every probe of
    its state, and an idle gmsh costs nothing. The model is removed on exit
    and the previous terminal setting restored.

    Args:
        model_name: name of the gmsh model created for the body.
    """
    if not gmsh_is_initialized():
        initialize_gmsh(readConfigFiles=False)
        gmsh.option.setNumber("General.Terminal", 0)
    previous_terminal = gmsh.option.getNumber("General.Terminal")
    gmsh.option.setNumber("General.Terminal", 0)
    previous_model = gmsh.model.getCurrent()
    gmsh.model.add(model_name)
    try:
        yield
    finally:
        gmsh.model.setCurrent(model_name)
        gmsh.model.remove()
        if previous_model in gmsh.model.list():
            gmsh.model.setCurrent(previous_model)
        gmsh.option.setNumber("General.Terminal", previous_terminal)


def elements_per_direction(size: typing.Sequence[float], h: float) -> tuple[int, int, int]:
    """Number of elements along x, y, z: ceil(L_i / h), at least 1.

    Args:
        size: box edge lengths (Lx, Ly, Lz) (m), all > 0.
        h: target element size (m), > 0.

    Returns:
        (n_x, n_y, n_z).
    """
    size = _checked_vector("mesh.size", size)
    if np.any(size <= 0.0):
        raise ValueError(f"mesh.size = {list(size)}: every edge length must be > 0 (m)")
    if not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0.0):
        raise ValueError(f"mesh.h = {h!r}: the element size must be a finite number > 0 (m)")
    # The small tolerance keeps L/h = 10.000000000000002 at 10 elements.
    return tuple(max(1, math.ceil(length / h - 1e-9)) for length in size)


def build_box(origin: typing.Sequence[float], size: typing.Sequence[float], h: float) -> tuple[int, int, int]:
    """Mesh the box [origin, origin + size] with structured hexahedra in the current gmsh model.

    Every edge along axis i is split into n_i = ceil(L_i / h) equal elements.
    Tags: physical volume "rock", physical surfaces xmin..zmax.

    Args:
        origin: minimum corner (x, y, z) (m).
        size: edge lengths (Lx, Ly, Lz) (m).
        h: target element size (m).

    Returns:
        Elements per direction (n_x, n_y, n_z).
    """
    origin = _checked_vector("mesh.origin", origin)
    n_elements = elements_per_direction(size, h)
    size = np.asarray(size, dtype=float)

    volume = gmsh.model.occ.addBox(*origin, *size)
    gmsh.model.occ.synchronize()

    # Transfinite curves: each box edge is parallel to one axis.
    for _, curve in gmsh.model.getEntities(1):
        bounding_box = np.array(gmsh.model.getBoundingBox(1, curve))
        lo, hi = bounding_box[:3], bounding_box[3:]
        axis = int(np.argmax(hi - lo))
        gmsh.model.mesh.setTransfiniteCurve(curve, n_elements[axis] + 1)
    for _, surface in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(surface)
        gmsh.model.mesh.setRecombine(2, surface)
    gmsh.model.mesh.setTransfiniteVolume(volume)
    gmsh.model.mesh.setRecombine(3, volume)

    region = gmsh.model.addPhysicalGroup(3, [volume])
    gmsh.model.setPhysicalName(3, region, BOX_REGION)
    for name, surface in _box_faces(origin, size).items():
        tag = gmsh.model.addPhysicalGroup(2, [surface])
        gmsh.model.setPhysicalName(2, tag, name)

    gmsh.model.mesh.generate(3)
    return n_elements


def interface_name(index: int) -> str:
    """Name of the interface on top of layer `index` (1-based, bottom up)."""
    return f"interface_{index}"


def build_layered_box(origin: typing.Sequence[float], size: typing.Sequence[float], h: float,
                      layers: typing.Sequence[typing.Mapping]) -> tuple[int, int, int]:
    """Mesh a box of horizontal layers with structured hexahedra in the current gmsh model.

    Layer k (bottom up) spans z in [z_k, z_k + thickness_k] and gets
    ceil(thickness_k / h) elements through its thickness; x and y are split as
    in `build_box`. The layers share their interface surfaces (a conforming
    mesh). Tags: one physical volume per distinct material (its name),
    physical surfaces xmin..zmax and "interface_1" .. "interface_{n-1}"
    (interface k on top of layer k).

    Args:
        origin: minimum corner (x, y, z) (m).
        size: edge lengths (Lx, Ly, Lz) (m); Lz = sum of the thicknesses.
        h: target element size (m).
        layers: bottom-up list of {"material": name, "thickness": m}.

    Returns:
        Elements per direction (n_x, n_y, total n_z).
    """
    origin = _checked_vector("mesh.origin", origin)
    n_x, n_y, _ = elements_per_direction(size, h)
    size = np.asarray(size, dtype=float)
    thicknesses = [float(layer["thickness"]) for layer in layers]
    if abs(sum(thicknesses) - size[2]) > 1e-9 * size[2]:
        raise ValueError(f"mesh.layers: thicknesses sum to {sum(thicknesses):g} m, mesh.size z is {size[2]:g} m")
    tops = origin[2] + np.cumsum(thicknesses)
    bottoms = tops - np.asarray(thicknesses)
    volumes = [gmsh.model.occ.addBox(origin[0], origin[1], z0, size[0], size[1], t)
               for z0, t in zip(bottoms, thicknesses)]
    # Fragmenting makes neighbouring layers share one interface surface (conforming mesh).
    gmsh.model.occ.fragment([(3, v) for v in volumes[:1]], [(3, v) for v in volumes[1:]])
    gmsh.model.occ.synchronize()
    tolerance = 1e-6 * float(np.max(size))

    def layer_of(z: float) -> int:
        return int(np.searchsorted(tops, z - tolerance))

    n_z_total = 0
    for thickness in thicknesses:
        n_z_total += max(1, math.ceil(thickness / h - 1e-9))
    for _, curve in gmsh.model.getEntities(1):
        start, end = (np.array(gmsh.model.getValue(0, point, []))
                      for _, point in gmsh.model.getBoundary([(1, curve)]))
        axis = int(np.argmax(np.abs(end - start)))
        if axis == 2:
            count = max(1, math.ceil(abs(end[2] - start[2]) / h - 1e-9))
        else:
            count = (n_x, n_y)[axis]
        gmsh.model.mesh.setTransfiniteCurve(curve, count + 1)
    for _, surface in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(surface)
        gmsh.model.mesh.setRecombine(2, surface)
    by_material: dict[str, list[int]] = {}
    for _, volume in gmsh.model.getEntities(3):
        gmsh.model.mesh.setTransfiniteVolume(volume)
        gmsh.model.mesh.setRecombine(3, volume)
        z_centre = gmsh.model.occ.getCenterOfMass(3, volume)[2]
        by_material.setdefault(layers[layer_of(z_centre)]["material"], []).append(volume)
    for layer in layers:  # physical volumes in the order the layers name them first
        name = layer["material"]
        if name in by_material:
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, by_material.pop(name)), name)
    for name, surfaces in _box_faces(origin, size, single=False).items():
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, surfaces), name)
    lo, hi = origin - tolerance, origin + size + tolerance
    for k, z in enumerate(tops[:-1], start=1):
        found = gmsh.model.getEntitiesInBoundingBox(lo[0], lo[1], z - tolerance, hi[0], hi[1], z + tolerance, dim=2)
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [tag for _, tag in found]), interface_name(k))
    gmsh.model.mesh.generate(3)
    return n_x, n_y, n_z_total


def _box_faces(origin: np.ndarray, size: np.ndarray, single: bool = True) -> dict:
    """The gmsh surface(s) of each named box face, found by its bounding box.

    With `single`, each face must be one surface and the value is its tag;
    otherwise the value is the list of surface tags on that plane.
    """
    lo, hi = origin, origin + size
    tolerance = 1e-6 * float(np.max(size))
    faces = {}
    for axis, letter in enumerate("xyz"):
        for side, coordinate in (("min", lo[axis]), ("max", hi[axis])):
            box_lo = lo - tolerance
            box_hi = hi + tolerance
            box_lo[axis] = coordinate - tolerance
            box_hi[axis] = coordinate + tolerance
            found = gmsh.model.getEntitiesInBoundingBox(*box_lo, *box_hi, dim=2)
            if single:
                if len(found) != 1:
                    raise RuntimeError(f"box face {letter}{side}: expected one gmsh surface, found {found}")
                faces[letter + side] = found[0][1]
            else:
                faces[letter + side] = [tag for _, tag in found]
    return faces


def _checked_vector(key: str, value: typing.Sequence[float]) -> np.ndarray:
    """`value` as a finite float array of shape (3,), or ValueError naming `key`."""
    try:
        vector = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{key} = {value!r}: expected three numbers [x, y, z] (m)") from None
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"{key} = {value!r}: expected three finite numbers [x, y, z] (m)")
    return vector

"""Structured hexahedral box: the homogeneous test model of the project.

`build_box` meshes an axis-aligned box with transfinite hexahedra in the gmsh
API and tags it: one physical volume "rock" and six physical surfaces
"xmin", "xmax", "ymin", "ymax", "zmin", "zmax".

`gmsh_session` is the one place that starts gmsh, so builders can also run
inside a script that already uses gmsh without disturbing its models.
"""
from __future__ import annotations

import contextlib
import math
import typing

import gmsh
import numpy as np

BOX_REGION = "rock"
BOX_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


def gmsh_is_initialized() -> bool:
    """Whether the gmsh API is initialized in this process.

    gmsh 4.8 has no `isInitialized`: before the first `initialize` the API
    answers queries from static defaults (no model, AbortOnError 0), after
    `finalize` it raises. `initialize` always creates one model and sets
    AbortOnError to 2, which tells the states apart.
    """
    try:
        models = gmsh.model.list()
        abort_on_error = gmsh.option.getNumber("General.AbortOnError")
    except Exception:  # gmsh raises a bare Exception once finalized
        return False
    return len(models) > 0 or abort_on_error != 0


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
        gmsh.initialize(readConfigFiles=False)
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


def _box_faces(origin: np.ndarray, size: np.ndarray) -> dict[str, int]:
    """The gmsh surface tag of each named box face, found by its bounding box."""
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
            if len(found) != 1:
                raise RuntimeError(f"box face {letter}{side}: expected one gmsh surface, found {found}")
            faces[letter + side] = found[0][1]
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

"""Meshes read from gmsh .msh files.

Physical volumes of the file are regions (one [materials.NAME] table each);
physical surfaces are named boundaries or interfaces.
"""
from __future__ import annotations

import os

from pyfem._gmsh import gmsh


def load_msh(path: str | os.PathLike) -> None:
    """Open the .msh file `path` into the current gmsh model.

    Args:
        path: a gmsh .msh file with physical volumes (regions) and,
            optionally, physical surfaces (named boundaries/interfaces).

    Raises:
        SceneError (key mesh.file): no such file, a file gmsh cannot read, or no physical volume.
    """
    from pyfem.scene import SceneError

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError("mesh.file", path, "no such file (expected a gmsh .msh file)")
    # gmsh.merge adds to the model that gmsh_session made current, whereas
    # gmsh.open would replace it with a new unnamed one.
    try:
        gmsh.merge(path)
    except Exception as error:  # gmsh reports a file it cannot read as a bare Exception
        raise SceneError("mesh.file", path, f"a gmsh .msh file is expected; gmsh cannot read this one "
                         f"({' '.join(str(error).split())})") from None
    if not gmsh.model.getPhysicalGroups(3):
        raise SceneError("mesh.file", path, "the file has no physical volume: the regions of the mesh "
                         "must be physical volumes (gmsh: Physical Volume(\"rock\") = {...}), "
                         "one [materials.NAME] each")

"""Meshes read from gmsh .msh files.

Physical volumes of the file are regions (one [materials.NAME] table each);
physical surfaces are named boundaries or interfaces.
"""
from __future__ import annotations

import os

import gmsh


def load_msh(path: str | os.PathLike) -> None:
    """Open the .msh file `path` into the current gmsh model.

    Args:
        path: a gmsh .msh file with physical volumes (regions) and,
            optionally, physical surfaces (named boundaries/interfaces).
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"mesh.file = {path!r}: no such file (expected a gmsh .msh file)")
    # gmsh.merge adds to the model that gmsh_session made current, whereas
    # gmsh.open would replace it with a new unnamed one.
    gmsh.merge(path)
    if not gmsh.model.getPhysicalGroups(3):
        raise ValueError(f"mesh.file = {path!r}: the file has no physical volume (regions must be physical volumes)")

"""Meshes read from gmsh .msh files.

Physical volumes of the file are regions (one [materials.NAME] table each);
physical surfaces are named boundaries or interfaces.
"""
from __future__ import annotations

import os
import tempfile

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

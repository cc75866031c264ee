"""Gmsh geometry builders.

Each builder fills the current gmsh model with a mesh whose physical volumes
are regions and whose physical surfaces are named boundaries or interfaces;
`pyfem.mesh.create_mesh` turns it into a dolfinx mesh. `gmsh_session` starts
and stops gmsh around a builder.
"""
from pyfem.geometry.box import (BOX_FACES, BOX_REGION, build_box, build_layered_box, elements_per_direction,
                                gmsh_session, interface_name)
from pyfem.geometry.file import load_msh
from pyfem.geometry.layered_cavern import build_layered_cavern, layered_cavern_parameters

__all__ = ["BOX_FACES", "BOX_REGION", "build_box", "build_layered_box", "elements_per_direction", "gmsh_session",
           "interface_name", "load_msh", "build_layered_cavern", "layered_cavern_parameters"]

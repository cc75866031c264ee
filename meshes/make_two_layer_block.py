"""A two-layer block: the smallest mesh with two regions and an interface.

The block [0, 2] x [0, 1] x [0, 2] m is split at z = 0.8 m into a lower layer
"sandstone" and an upper layer "mudstone", meshed with structured hexahedra
(about h = 0.4 m). Physical groups:
- volumes "sandstone", "mudstone" (regions, one [materials.NAME] table each);
- surfaces "xmin", "xmax", "ymin", "ymax", "zmin", "zmax" (outer faces; the
  side faces span both layers) and "interface_1" (the internal layer plane).

Sample run (writes meshes/two_layer_block.msh):
    /usr/bin/python3 meshes/make_two_layer_block.py
"""
import math
import os
import sys

import gmsh

BLOCK_SIZE = (2.0, 1.0, 2.0)
INTERFACE_Z = 0.8
ELEMENT_SIZE = 0.4


def make_two_layer_block(path: str, element_size: float = ELEMENT_SIZE) -> None:
    """Mesh the two-layer block and write it to the .msh file `path`.

    Initializes gmsh if it is not running and leaves it running.

    Args:
        path: output .msh file.
        element_size: target hexahedron edge length (m).
    """
    gmsh.initialize(readConfigFiles=False)  # a no-op (with a warning) if running
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("two_layer_block")
    lx, ly, lz = BLOCK_SIZE
    lower = gmsh.model.occ.addBox(0.0, 0.0, 0.0, lx, ly, INTERFACE_Z)
    upper = gmsh.model.occ.addBox(0.0, 0.0, INTERFACE_Z, lx, ly, lz - INTERFACE_Z)
    # Fragmenting makes the two layers share the interface surface (conforming mesh).
    gmsh.model.occ.fragment([(3, lower)], [(3, upper)])
    gmsh.model.occ.synchronize()

    for _, curve in gmsh.model.getEntities(1):
        # End points, not the bounding box: OCC pads bounding boxes.
        start, end = (gmsh.model.getValue(0, point, []) for _, point in gmsh.model.getBoundary([(1, curve)]))
        length = math.dist(start, end)
        gmsh.model.mesh.setTransfiniteCurve(curve, max(1, math.ceil(length / element_size - 1e-9)) + 1)
    for _, surface in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(surface)
        gmsh.model.mesh.setRecombine(2, surface)
    for _, volume in gmsh.model.getEntities(3):
        gmsh.model.mesh.setTransfiniteVolume(volume)
        gmsh.model.mesh.setRecombine(3, volume)

    eps = 1e-6
    for name, z_range in (("sandstone", (0.0, INTERFACE_Z)), ("mudstone", (INTERFACE_Z, lz))):
        volumes = gmsh.model.getEntitiesInBoundingBox(-eps, -eps, z_range[0] - eps, lx + eps, ly + eps,
                                                      z_range[1] + eps, dim=3)
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [tag for _, tag in volumes]), name)
    planes = {
        "xmin": (-eps, -eps, -eps, eps, ly + eps, lz + eps),
        "xmax": (lx - eps, -eps, -eps, lx + eps, ly + eps, lz + eps),
        "ymin": (-eps, -eps, -eps, lx + eps, eps, lz + eps),
        "ymax": (-eps, ly - eps, -eps, lx + eps, ly + eps, lz + eps),
        "zmin": (-eps, -eps, -eps, lx + eps, ly + eps, eps),
        "zmax": (-eps, -eps, lz - eps, lx + eps, ly + eps, lz + eps),
        "interface_1": (-eps, -eps, INTERFACE_Z - eps, lx + eps, ly + eps, INTERFACE_Z + eps),
    }
    for name, box in planes.items():
        surfaces = gmsh.model.getEntitiesInBoundingBox(*box, dim=2)
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [tag for _, tag in surfaces]), name)

    gmsh.model.mesh.generate(3)
    gmsh.write(os.fspath(path))
    gmsh.model.remove()


if __name__ == "__main__":
    default = os.path.join(os.path.dirname(os.path.abspath(__file__)), "two_layer_block.msh")
    make_two_layer_block(sys.argv[1] if len(sys.argv) > 1 else default)

"""A circular tunnel in a box of rock, meshed with 8-node hexahedra by gmsh: the example of
the `file` mesh builder (README, docs/boundaries.md).

The tunnel (radius a, axis along y through (x_c, z_c)) crosses a box [0, Lx] x [0, t] x [0, Lz].
The x-z section is meshed with quadrilaterals, graded from `h_wall` at the tunnel wall to
`h_far`, and extruded in y. Physical groups: the volume "rock"; with `name_surfaces`, the six
outer faces "xmin" .. "zmax" and the tunnel wall "tunnel_wall". Without names, pyfem takes the
exterior facets on the bounding-box planes as the truncation faces, and the wall is free either
way.

    /usr/bin/python3 meshes/tunnel_in_box.py out.msh [--radius 5] [--unnamed]
"""
from __future__ import annotations

import argparse
import math
import signal


def build_tunnel_in_box(path: str, radius: float = 5.0, size: tuple = (120.0, 120.0), thickness: float = 2.0,
                        h_wall: float = 0.6, h_far: float = 8.0, layers: int = 1, name_surfaces: bool = True) -> None:
    """Mesh the tunnel-in-box model and write it to `path` (gmsh .msh 4.1).

    Args:
        path: output .msh file.
        radius: tunnel radius a (m); the tunnel axis is at the centre of the x-z section.
        size: (Lx, Lz) of the section (m).
        thickness: extent of the box along the tunnel axis y (m).
        h_wall, h_far: element sizes at the wall and far from it (m).
        layers: elements through the thickness.
        name_surfaces: name the outer faces (xmin .. zmax) and the wall (tunnel_wall).
    """
    handler = signal.getsignal(signal.SIGINT)
    import gmsh  # resets SIGINT: restored below

    signal.signal(signal.SIGINT, handler)
    lx, lz = size
    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.model.add("tunnel_in_box")
        occ = gmsh.model.occ
        # The section in the x-y plane of gmsh, then turned about x so that y becomes z.
        box = occ.addRectangle(0.0, 0.0, 0.0, lx, lz)
        hole = occ.addDisk(lx / 2, lz / 2, 0.0, radius, radius)
        section, _ = occ.cut([(2, box)], [(2, hole)])
        occ.rotate(section, 0, 0, 0, 1, 0, 0, math.pi / 2)   # (x, y, 0) -> (x, 0, y)
        occ.synchronize()
        # The rotation maps y to z and leaves the section at y = 0; extrude it along +y.
        extruded = occ.extrude(section, 0.0, thickness, 0.0, numElements=[layers], recombine=True)
        occ.synchronize()
        volumes = [tag for dim, tag in extruded if dim == 3]

        wall_curves = [tag for dim, tag in gmsh.model.getBoundary(section, oriented=False)
                       if dim == 1 and _is_on_circle(gmsh, tag, lx / 2, lz / 2, radius)]
        if not wall_curves:
            raise RuntimeError("tunnel_in_box: the tunnel wall curves were not found")
        distance = gmsh.model.mesh.field.add("Distance")
        gmsh.model.mesh.field.setNumbers(distance, "CurvesList", wall_curves)
        gmsh.model.mesh.field.setNumber(distance, "NumPointsPerCurve", 200)
        threshold = gmsh.model.mesh.field.add("Threshold")
        gmsh.model.mesh.field.setNumber(threshold, "InField", distance)
        gmsh.model.mesh.field.setNumber(threshold, "SizeMin", h_wall)
        gmsh.model.mesh.field.setNumber(threshold, "SizeMax", h_far)
        gmsh.model.mesh.field.setNumber(threshold, "DistMin", 0.5 * radius)
        gmsh.model.mesh.field.setNumber(threshold, "DistMax", 6.0 * radius)
        gmsh.model.mesh.field.setAsBackgroundMesh(threshold)
        # Every option the mesh depends on is set here: a gmsh that was initialized before keeps
        # the options others set (gmsh 4.8 has no way to restore the defaults).
        for option, value in (("Mesh.MeshSizeExtendFromBoundary", 0), ("Mesh.MeshSizeFromPoints", 0),
                              ("Mesh.MeshSizeFromCurvature", 0), ("Mesh.MeshSizeMin", 0.0),
                              ("Mesh.MeshSizeMax", 1.0e22), ("Mesh.MeshSizeFactor", 1.0),
                              ("Mesh.Algorithm", 6), ("Mesh.ElementOrder", 1), ("Mesh.SubdivisionAlgorithm", 0),
                              ("Mesh.RecombineAll", 1), ("Mesh.RecombinationAlgorithm", 1)):
            gmsh.option.setNumber(option, value)

        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, volumes), "rock")
        if name_surfaces:
            eps = 1e-6 * max(lx, lz)
            planes = {"xmin": (0, 0.0), "xmax": (0, lx), "ymin": (1, 0.0), "ymax": (1, thickness),
                      "zmin": (2, 0.0), "zmax": (2, lz)}
            named = set()
            for name, (axis, value) in planes.items():
                lo = [-eps - 1.0, -eps - 1.0, -eps - 1.0]
                hi = [lx + 1.0, thickness + 1.0, lz + 1.0]
                lo[axis], hi[axis] = value - eps, value + eps
                surfaces = [tag for _, tag in gmsh.model.getEntitiesInBoundingBox(*lo, *hi, 2)]
                named.update(surfaces)
                gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, surfaces), name)
            all_surfaces = {tag for dim, tag in gmsh.model.getBoundary([(3, v) for v in volumes], oriented=False)}
            wall = sorted(all_surfaces - named)
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, wall), "tunnel_wall")
        gmsh.model.mesh.generate(3)
        gmsh.write(path)
    finally:
        gmsh.finalize()
        signal.signal(signal.SIGINT, handler)


def _is_on_circle(gmsh, curve: int, xc: float, zc: float, radius: float) -> bool:
    """Whether a curve's bounding box lies within the tunnel's (after the turn to x-z)."""
    x0, _, z0, x1, _, z1 = gmsh.model.getBoundingBox(1, curve)
    margin = 1e-6 * radius + 1e-9
    return (x0 >= xc - radius - margin and x1 <= xc + radius + margin
            and z0 >= zc - radius - margin and z1 <= zc + radius + margin)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="output .msh file")
    parser.add_argument("--radius", type=float, default=5.0)
    parser.add_argument("--unnamed", action="store_true", help="name no surface (bounding-box faces)")
    args = parser.parse_args()
    build_tunnel_in_box(args.out, radius=args.radius, name_surfaces=not args.unnamed)


if __name__ == "__main__":
    main()

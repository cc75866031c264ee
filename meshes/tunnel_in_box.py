"""A circular tunnel in a box of rock, meshed with 8-node hexahedra by gmsh: the example of
the `file` mesh builder (README, docs/boundaries.md).

The tunnel (radius a, axis along y through (x_c, z_c)) crosses a box [0, Lx] x [0, t] x [0, Lz].
The x-z section is meshed with quadrilaterals, graded from `h_wall` at the tunnel wall to
`h_far`, and extruded in y. Physical groups: the volume "rock"; with `name_surfaces`, the six
outer faces "xmin" .. "zmax" and the tunnel wall "tunnel_wall". Without names, pyfem takes the
exterior facets on the bounding-box planes as the truncation faces, and the wall is free either
way.

With `filled` (`--filled`) the hole is meshed too, as the volume "excavation", for a static stage
that removes it (`[static] excavate = ["excavation"]`, docs/static.md); with `lining` = t
(`--lining t`) a ring of thickness t inside the radius is the volume "lining" (the size near the
wall is then at most t/2: two elements through it) and the rest of the hole "excavation".
With `lining` and `hollow` (`--hollow`) the core is left out: the lined tunnel in place, for a
dynamic run without a static stage (workflows/lined_wall_dynamic.py). With `height` (`--height b`) the
opening is an ellipse of half-width `radius` along x and half-height b along z (not with a lining;
docs/elliptical_opening.md). Without any option the script writes the mesh it always has.

    /usr/bin/python3 meshes/tunnel_in_box.py out.msh [--radius 5] [--height 10] [--unnamed] [--filled]
                                                 [--lining 0.5 [--hollow]] [--size 120] [--h-wall 0.6] [--h-far 8]
"""
from __future__ import annotations

import argparse
import math
import signal


def build_tunnel_in_box(path: str, radius: float = 5.0, size: tuple = (120.0, 120.0), thickness: float = 2.0,
                        h_wall: float = 0.6, h_far: float = 8.0, layers: int = 1, name_surfaces: bool = True,
                        filled: bool = False, lining: float = 0.0, hollow: bool = False,
                        height: float | None = None) -> None:
    """Mesh the tunnel-in-box model and write it to `path` (gmsh .msh 4.1).

    Args:
        path: output .msh file.
        radius: tunnel radius a (m); the tunnel axis is at the centre of the x-z section.
        size: (Lx, Lz) of the section (m).
        thickness: extent of the box along the tunnel axis y (m).
        h_wall, h_far: element sizes at the wall and far from it (m).
        layers: elements through the thickness.
        name_surfaces: name the outer faces (xmin .. zmax) and the wall (tunnel_wall).
        filled: mesh the hole as the volume "excavation" (the wall is then inside the mesh).
        lining: thickness (m) of a ring inside the radius meshed as the volume "lining" (implies
            `filled`; 0: none).
        hollow: with `lining`, leave the core out: the lined tunnel already in place, its inner face
            free (a dynamic run without a static stage).
        height: the opening's half-height along z (m): an ellipse of half-width `radius` along x
            (None: a circle of `radius`); not with `lining`.
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
        if not 0.0 <= lining < radius:
            raise ValueError(f"tunnel_in_box: lining = {lining!r} must lie in [0, radius = {radius!r})")
        height = radius if height is None else height
        if not height > 0.0 or (lining > 0.0 and height != radius):
            raise ValueError(f"tunnel_in_box: height = {height!r} must be > 0, and equal to the radius with a lining")
        extent = (radius, height)  # the opening's half-extents along x and z
        filled = filled or lining > 0.0
        if lining > 0.0:
            h_wall = min(h_wall, 0.5 * lining)
        box = occ.addRectangle(0.0, 0.0, 0.0, lx, lz)
        # gmsh wants the first radius the larger: a tall ellipse is drawn wide and turned.
        hole = occ.addDisk(lx / 2, lz / 2, 0.0, max(extent), min(extent))
        if height > radius:
            occ.rotate([(2, hole)], lx / 2, lz / 2, 0.0, 0.0, 0.0, 1.0, math.pi / 2)
        if filled:
            # The hole's pieces (core, lining ring in quarters) share their curves with the rock.
            tools = [(2, hole)]
            if lining > 0.0:
                core = occ.addDisk(lx / 2, lz / 2, 0.0, radius - lining, radius - lining)
                ring, _ = occ.cut(tools, [(2, occ.copy([(2, core)])[0][1])])
                tools = []
                if hollow:  # the section without the core; the ring's quarters fragment it below
                    box = occ.cut([(2, box)], [(2, core)])[0][0][1]
                else:
                    tools = [(2, core)]
                for x0, z0 in ((0.0, 0.0), (-radius, 0.0), (-radius, -radius), (0.0, -radius)):
                    quadrant = occ.addRectangle(lx / 2 + x0, lz / 2 + z0, 0.0, radius, radius)
                    quarter, _ = occ.intersect(occ.copy(ring), [(2, quadrant)])
                    tools += quarter
                occ.remove(ring)
            section, _ = occ.fragment([(2, box)], tools)
        else:
            section, _ = occ.cut([(2, box)], [(2, hole)])
        occ.rotate(section, 0, 0, 0, 1, 0, 0, math.pi / 2)   # (x, y, 0) -> (x, 0, y)
        occ.synchronize()
        # The rotation maps y to z and leaves the section at y = 0; extrude it along +y.
        extruded = occ.extrude(section, 0.0, thickness, 0.0, numElements=[layers], recombine=True)
        occ.synchronize()
        # Sort the volumes by where they lie: in the core, in the lining ring, or in the rock.
        pieces = {"rock": [], "lining": [], "excavation": []}
        for tag in (tag for dim, tag in extruded if dim == 3):
            if not _is_on_circle(gmsh, tag, lx / 2, lz / 2, extent, dim=3):
                pieces["rock"].append(tag)
            elif lining > 0.0 and not _is_on_circle(gmsh, tag, lx / 2, lz / 2, radius - lining, dim=3):
                pieces["lining"].append(tag)
            else:
                pieces["excavation"].append(tag)
        volumes = pieces["rock"]
        rock_section = [(dim, tag) for dim, tag in section
                        if not _is_on_circle(gmsh, tag, lx / 2, lz / 2, extent, dim=dim)]
        for dim, tag in section:
            if (lining > 0.0 and _is_on_circle(gmsh, tag, lx / 2, lz / 2, extent, dim=dim)
                    and not _is_on_circle(gmsh, tag, lx / 2, lz / 2, radius - lining, dim=dim)):
                # A quarter of the thin ring: structured (transfinite) quadrilaterals, as many
                # through the thickness as h_wall asks (the unstructured mesher leaves triangles).
                for _, curve in gmsh.model.getBoundary([(dim, tag)], oriented=False):
                    length = occ.getMass(1, curve)
                    points = (max(2, math.ceil(lining / h_wall - 1e-9)) if abs(length - lining) < 1e-6 * radius
                              else max(2, math.ceil(0.5 * math.pi * radius / h_wall))) + 1  # both arcs alike
                    gmsh.model.mesh.setTransfiniteCurve(curve, points)
                gmsh.model.mesh.setTransfiniteSurface(tag)

        wall_curves = [tag for dim, tag in gmsh.model.getBoundary(rock_section, oriented=False)
                       if dim == 1 and _is_on_circle(gmsh, tag, lx / 2, lz / 2, extent)]
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
        for name in ("lining", "excavation"):
            if pieces[name]:
                gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, pieces[name]), name)
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


def _is_on_circle(gmsh, curve: int, xc: float, zc: float, radius, dim: int = 1) -> bool:
    """Whether the bounding box of an entity (a curve by default) lies within the opening's (after
    the turn to x-z): `radius` a number for a circle, or the half-extents (along x, along z)."""
    rx, rz = (radius, radius) if isinstance(radius, (int, float)) else radius
    x0, _, z0, x1, _, z1 = gmsh.model.getBoundingBox(dim, curve)
    margin = 1e-6 * max(rx, rz) + 1e-9
    return (x0 >= xc - rx - margin and x1 <= xc + rx + margin
            and z0 >= zc - rz - margin and z1 <= zc + rz + margin)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="output .msh file")
    parser.add_argument("--radius", type=float, default=5.0)
    parser.add_argument("--height", type=float, default=None,
                        help="the opening's half-height along z (m): an ellipse of half-width --radius")
    parser.add_argument("--unnamed", action="store_true", help="name no surface (bounding-box faces)")
    parser.add_argument("--size", type=float, default=120.0, help="side of the square x-z section (m)")
    parser.add_argument("--h-wall", type=float, default=0.6, help="element size at the wall (m)")
    parser.add_argument("--h-far", type=float, default=8.0, help="element size far from the wall (m)")
    parser.add_argument("--filled", action="store_true", help="mesh the hole as the volume \"excavation\"")
    parser.add_argument("--lining", type=float, default=0.0,
                        help="thickness (m) of a ring inside the radius meshed as the volume \"lining\"")
    parser.add_argument("--hollow", action="store_true",
                        help="with --lining: no core, the lined tunnel in place (a dynamic run without a static stage)")
    args = parser.parse_args()
    try:
        build_tunnel_in_box(args.out, radius=args.radius, size=(args.size, args.size), h_wall=args.h_wall,
                            h_far=args.h_far, name_surfaces=not args.unnamed, filled=args.filled, lining=args.lining,
                            hollow=args.hollow, height=args.height)
    except ValueError as error:  # one line and exit 2
        parser.error(str(error))


if __name__ == "__main__":
    main()

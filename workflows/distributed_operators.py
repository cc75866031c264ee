"""Prototype, second step of issue 13's distributed model (docs/scaling.md "Next steps"): pyfem's
own model builders on dolfinx's distributed mesh. For a scene, every rank builds the mesh with
`pyfem.mesh.create_mesh_with_interfaces(scene, COMM_WORLD)` (gmsh on rank 0, dolfinx distributes
it), the materials, the lumped mass and the truncation faces (`pyfem.operators.boundary_face`: lumped
facet area, normal, rho c_p, rho c_s, shear modulus per node) exactly as `build_model` does on one
rank; rank 0 then builds the same on one rank (COMM_SELF) and compares node by node, matched by
coordinates: each node owned by exactly one rank, each owned value against the one-rank value.
Not used by `pyfem run` yet.

    mpirun --allow-run-as-root -n 3 /usr/bin/python3 workflows/distributed_operators.py [SCENE]

Prints one JSON line on rank 0.
"""
import json
import sys

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from pyfem import operators
from pyfem.assembly import lumped_mass
from pyfem.mesh import create_mesh_with_interfaces
from pyfem.scene import load_scene

QUADRATURE = {"quadrature_degree": 2}


def nodal_operators(scene, comm: MPI.Comm) -> dict:
    """{"mass": (coordinates, values), face name: (coordinates, [area, normal, rho_cp, rho_cs, G])} of
    the nodes this rank owns, built as build_model builds them."""
    mesh, cell_tags, facet_tags, regions, boundaries, interface_tags = create_mesh_with_interfaces(scene, comm)
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", scene["mesh"].get("order", 1)))
    materials = operators._cell_materials(mesh, cell_tags, regions, scene["materials"])
    coordinates = V.tabulate_dof_coordinates().astype(np.float64)
    centre = scene.get("boundary", {}).get("centre")
    if centre is None:  # the whole model's bounding box (every rank's nodes)
        low = np.min(comm.allgather(coordinates.min(axis=0)), axis=0)
        high = np.max(comm.allgather(coordinates.max(axis=0)), axis=0)
        centre = 0.5 * (low + high)
    truncation, free_surfaces = operators.truncation_faces(scene, mesh, facet_tags, boundaries, interface_tags)
    kinds = operators.face_kinds(scene, truncation)
    n_owned = V.dofmap.index_map.size_local
    mass = lumped_mass(V, materials.rho, QUADRATURE)
    out = {"mass": (coordinates[:n_owned], mass[:n_owned, None]), "free_surfaces": free_surfaces}
    for name, (facets, source) in truncation.items():
        face = operators.boundary_face(name, V, facets, materials, coordinates, np.asarray(centre, dtype=float),
                                       QUADRATURE, kind=kinds[name], source=source)
        owned = face.nodes < n_owned
        out[name] = (coordinates[face.nodes[owned]],
                     np.column_stack([face.area[owned], face.normal[owned], face.rho_cp[owned], face.rho_cs[owned],
                                      face.shear_modulus[owned]]))
    return out


def _by_point(coordinates: np.ndarray, values: np.ndarray) -> dict:
    """point (rounded to um) -> its nodes' value rows, sorted (the two sides of a split interface
    share a point: compared as a set)."""
    rows: dict = {}
    for x, value in zip(np.round(coordinates, 6), values):
        rows.setdefault(tuple(x), []).append(tuple(value))
    return {point: sorted(found) for point, found in rows.items()}


def compare(ranks: list, alone: dict) -> dict:
    """Per operator: nodes on one rank, nodes owned over the ranks, points whose node count differs
    (a node owned twice or by no rank), largest difference of the owned values from the one-rank
    ones (relative to each column's largest); the free surfaces' names and facet counts, equal or not."""
    result = {"free_surfaces_equal": all(piece["free_surfaces"] == alone["free_surfaces"] for piece in ranks),
              "faces": sorted(name for name in alone if name not in ("mass", "free_surfaces")),
              "faces_equal": all(set(piece) == set(alone) for piece in ranks)}
    for name in result["faces"] + ["mass"]:
        coordinates, values = alone[name]
        theirs = [piece[name] for piece in ranks if name in piece]
        points = np.concatenate([c for c, _ in theirs])
        found = np.concatenate([v for _, v in theirs])
        mine, serial = _by_point(points, found), _by_point(coordinates, values)
        scale = np.abs(values).max(axis=0)
        scale[scale == 0.0] = 1.0
        miscounted = sum(len(mine.get(point, [])) != len(rows) for point, rows in serial.items()) + \
            sum(point not in serial for point in mine)
        difference = max((float((np.abs(np.array(mine[point]) - np.array(rows)) / scale).max())
                          for point, rows in serial.items() if len(mine.get(point, [])) == len(rows)), default=0.0)
        result[name] = {"nodes": len(coordinates), "owned": int(len(points)), "miscounted_points": int(miscounted),
                        "difference": difference}
    return result


def main(argv: list) -> int:
    path = argv[0] if argv else "workflows/scenes/box_vertical_sv.toml"
    scene = load_scene(path)
    comm = MPI.COMM_WORLD
    pieces = comm.gather(nodal_operators(scene, comm), root=0)
    if comm.rank == 0:
        alone = nodal_operators(scene, MPI.COMM_SELF)
        print(json.dumps({"scene": path, "ranks": comm.size, "operators": compare(pieces, alone)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

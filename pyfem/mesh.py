"""Gmsh model -> dolfinx mesh with region (cell) and boundary (facet) tags.

The scene's [mesh] table picks a builder from `pyfem.geometry`; the physical
groups of the gmsh model become dolfinx MeshTags and their names the keys of
`regions` (volumes) and `boundaries` (surfaces).
"""
from __future__ import annotations

import typing

import gmsh
from dolfinx.io import gmshio
from mpi4py import MPI

from pyfem.geometry import build_box, gmsh_session, load_msh

# gmsh element type numbers of the volume elements accepted as cells.
GMSH_HEXAHEDRON_8 = 5
SUPPORTED_CELL_TYPES = {GMSH_HEXAHEDRON_8: "8-node hexahedron"}


def create_mesh(scene: typing.Mapping, comm: MPI.Comm = MPI.COMM_WORLD):
    """Build the gmsh model the scene asks for and convert it to a dolfinx mesh.

    The gmsh model lives on rank 0 only; dolfinx distributes the mesh over `comm`.

    Args:
        scene: validated scene; uses scene["mesh"] (builder, origin, size, h,
            file) and the names of scene["materials"].
        comm: MPI communicator of the mesh.

    Returns:
        (mesh, cell_tags, facet_tags, regions, boundaries) where regions maps
        a region name to its cell tag and boundaries maps a surface name to its
        facet tag.
    """
    mesh_settings = scene["mesh"]
    builder = mesh_settings.get("builder")
    model_rank = 0
    model_facts = None
    with gmsh_session("pyfem"):
        if comm.rank == model_rank:
            if builder == "box":
                build_box(mesh_settings["origin"], mesh_settings["size"], mesh_settings["h"])
            elif builder == "file":
                load_msh(mesh_settings["file"])
            else:
                raise ValueError(f"mesh.builder = {builder!r}: allowed here are 'box' and 'file'")
            model_facts = _physical_groups_and_cell_types()
        model_facts = comm.bcast(model_facts, root=model_rank)
        regions, boundaries, cell_types = model_facts
        _check_cell_types(cell_types)
        _check_regions_match_materials(regions, scene["materials"])
        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, comm, model_rank, gdim=3)
    return mesh, cell_tags, facet_tags, regions, boundaries


def _physical_groups_and_cell_types() -> tuple[dict[str, int], dict[str, int], list[tuple[int, str]]]:
    """Names and tags of the physical volumes and surfaces of the current gmsh
    model, and the gmsh element types (number, name) found in the physical volumes."""
    regions = {}
    cell_types = set()
    for dim, tag in gmsh.model.getPhysicalGroups(3):
        regions[_physical_name(dim, tag)] = tag
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            element_types, _, _ = gmsh.model.mesh.getElements(dim, entity)
            cell_types.update((int(t), gmsh.model.mesh.getElementProperties(t)[0]) for t in element_types)
    boundaries = {_physical_name(dim, tag): tag for dim, tag in gmsh.model.getPhysicalGroups(2)}
    return regions, boundaries, sorted(cell_types)


def _physical_name(dim: int, tag: int) -> str:
    """The name of a physical group; unnamed groups are called by their tag."""
    name = gmsh.model.getPhysicalName(dim, tag)
    return name if name else f"{'volume' if dim == 3 else 'surface'}_{tag}"


def _check_cell_types(cell_types: list[tuple[int, str]]) -> None:
    if not cell_types:
        raise ValueError("mesh: the gmsh model has no elements in its physical volumes")
    unsupported = [name for number, name in cell_types if number not in SUPPORTED_CELL_TYPES]
    if unsupported:
        raise ValueError(
            f"mesh: gmsh element types {unsupported} are not supported; "
            f"allowed: {list(SUPPORTED_CELL_TYPES.values())} (gmsh type {list(SUPPORTED_CELL_TYPES)})")


def _check_regions_match_materials(regions: dict[str, int], materials: typing.Mapping) -> None:
    """Every region needs a [materials.NAME] table and every table a region;
    one ValueError lists every mismatch."""
    found = sorted(regions)
    problems = [f"materials.{name}: missing table for mesh region {name!r}" for name in found if name not in materials]
    problems += [f"materials.{name}: no mesh region of that name" for name in materials if name not in regions]
    if problems:
        raise ValueError("; ".join(problems) + f" (regions found: {found})")

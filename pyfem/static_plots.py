"""Pictures of the static stage (docs/static.md "Outputs"), written into the run's static/ folder:

    static/section_stress.png    the stress after the stage in the section through the excavation
                                 (the plane y through the middle of the excavation surface, or of the model):
                                 max and min principal stress (MPa, tension positive), and with a
                                 relaxation stage the plastic strain and damage of the cut cells
    static/interface_stress.png  with contact: the interface pairs' normal stress (MPa, compression
                                 positive) before the stage (the in-situ state) and after it, against
                                 the distance from the excavation (m)

Each cell cut by the section is drawn as the convex hull of its vertices projected on the plane (a
quadrilateral for the layered cavern's cells, extruded along y); the excavated cells are not in the
model (pyfem/mesh.py drops them), and the excavation surface is the wall they left: the stage-1 body's
exterior facets off the truncation faces and the interfaces (`excavation_surface`).
"""
from __future__ import annotations


import matplotlib

matplotlib.use("Agg")  # files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from pyfem.plots import convex_hull  # noqa: E402

MPA = 1.0e-6


def cell_vertices(model) -> np.ndarray:
    """(cells, 8, 3) coordinates of each cell's vertices (m): the first 8 dofs of a Q1/Q2 cell."""
    n_basis = model.V.dofmap.dof_layout.num_dofs
    nodes = model.V.dofmap.list.array.reshape(-1, n_basis)[:, :8]
    return model.node_coords[nodes]


# Each facet of a cell as its local vertices (dolfinx's reference cells: a hexahedron's vertices in
# tensor-product order, a tetrahedron's any three of four).
_CELL_FACETS = {8: ((0, 1, 2, 3), (0, 1, 4, 5), (0, 2, 4, 6), (1, 3, 5, 7), (2, 3, 6, 7), (4, 5, 6, 7)),
                4: ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3))}


def excavation_surface(state, model) -> np.ndarray:
    """(k, 3) the nodes of the surface the excavation left (m); empty without an excavation load.

    Found from the mesh, not from the load: the stage-1 body's (the model without the installed
    regions) exterior facets that are neither on a truncation face nor on a split interface (the
    excavated cells are never in the model, pyfem/mesh.py, so their wall is exterior; a cavity
    already in the mesh counts too), and the nodes an installed region shares with the rest. The
    excavation load itself is no guide: it also has the round-off of the volume terms and the
    mismatch of the pairs' static forces on the interfaces, large enough to put every pair on it."""
    surface, _ = excavation_wall(state, model)
    return model.node_coords[surface] if surface is not None else np.zeros((0, 3))


def excavation_wall(state, model) -> tuple:
    """(surface, facets) of `excavation_surface`: a (nodes,) bool mask of the wall's nodes and the
    (f, 4 or 3) node indices of the wall's facets (an installed region's shared nodes are in the
    mask, not in the facets); (None, None) without an excavation load."""
    load = np.asarray(state.excavation_load)
    if not len(load) or not np.any(load):
        return None, None
    n_vertices = 8 if model.mesh.topology.cell_type.name == "hexahedron" else 4
    n_basis = model.V.dofmap.dof_layout.num_dofs
    cell_nodes = model.V.dofmap.list.array.reshape(-1, n_basis)[:, :n_vertices]
    installed = np.zeros(len(cell_nodes), dtype=bool)
    installed[np.asarray(getattr(state, "installed_cells", ()), dtype=np.int64)] = True
    rock = cell_nodes[~installed]
    facets = np.sort(np.concatenate([rock[:, list(local)] for local in _CELL_FACETS[n_vertices]]), axis=1)
    unique, counts = np.unique(facets, axis=0, return_counts=True)
    exterior = unique[counts == 1]
    on_face = np.zeros(len(exterior), dtype=bool)  # all its nodes on one truncation face (not on two:
    for face in model.faces:                        # a one-cell-thick slab's wall spans ymin to ymax)
        on = np.zeros(len(model.node_coords), dtype=bool)
        on[face.nodes] = True
        on_face |= on[exterior].all(axis=1)
    on_interface = np.zeros_like(on_face)
    if model.pairs is not None and len(model.pairs):
        paired = np.zeros(len(model.node_coords), dtype=bool)
        paired[np.asarray(model.pairs.nodes).ravel()] = True
        on_interface = paired[exterior].all(axis=1)
    surface = np.zeros(len(model.node_coords), dtype=bool)
    wall = exterior[~on_face & ~on_interface]
    surface[wall.ravel()] = True
    if installed.any():
        surface[np.intersect1d(cell_nodes[installed].ravel(), rock.ravel())] = True
    return surface, wall


def section_plane(vertices: np.ndarray, surface: np.ndarray) -> float:
    """y of the section (m): the middle of the excavation surface, else the middle of the model, to
    1e-9 m (the coordinates' round-off, which differs with the rank count, made 0 m 5e-15 m on one
    rank and -4e-15 m on two)."""
    if len(surface):
        middle = 0.5 * (surface[:, 1].min() + surface[:, 1].max())
    else:
        middle = 0.5 * (vertices[..., 1].min() + vertices[..., 1].max())
    return float(np.round(middle, 9)) + 0.0  # (+ 0.0: no -0.0)


def section_cells(vertex_y: np.ndarray, y0: float) -> np.ndarray:
    """(cells,) bool: the cells that the section y = y0 cuts, of the cells' vertices' y (cells, k).

    A plane through a layer of nodes (a monitor at a node's y, the middle of a regular mesh) touches
    the cells on both sides of it, and which of them "cut" by y.min <= y0 <= y.max was decided by the
    round-off of the node coordinates, which differs with the partition (dolfinx tabulates them per
    rank): the plane is taken 1e-9 of the model's height above y0 (below at the model's top), so that
    one layer of cells is cut for any rank count (pyfem/distributed_view.py draws the same cells)."""
    low, high = vertex_y.min(axis=1), vertex_y.max(axis=1)
    if not len(low):
        return np.zeros(0, dtype=bool)
    shift = 1e-9 * max(float(high.max() - low.min()), 1e-300)
    plane = y0 + shift if y0 + shift < high.max() else y0 - shift
    return (low <= plane) & (high >= plane)


def principal_stresses(stress: np.ndarray) -> np.ndarray:
    """(c, 3) principal stresses of (c, 3, 3) tensors, ascending (Pa, tension positive)."""
    return np.linalg.eigvalsh(0.5 * (stress + np.swapaxes(stress, 1, 2)))


def section_stress(png_path, vertices: np.ndarray, stress: np.ndarray, surface: np.ndarray,
                   cell_state: dict | None = None, title: str = "") -> dict:
    """Draws the stage's stress in the section through the excavation.

    Args:
        png_path: output image.
        vertices: (cells, 8, 3) cell vertices (m).
        stress: (cells, 3, 3) stress after the stage at the cell centroids (Pa, tension positive).
        surface: (k, 3) excavation surface points (m): the section passes through their middle.
        cell_state: relaxation stage only: {"plastic_strain", "damage"} per cell (cell means).
        title: figure title.

    Returns:
        {"y": section y (m), "cells": cells drawn, "s1_max", "s3_min" (Pa) over the drawn cells}.
    """
    y0 = section_plane(vertices, surface)
    cells = np.flatnonzero(section_cells(vertices[..., 1], y0))
    polygons = [convex_hull(vertices[c][:, [0, 2]]) for c in cells]
    principal = principal_stresses(stress[cells])
    panels = [("max principal stress (MPa)", principal[:, 2] * MPA, "RdBu_r", True),
              ("min principal stress (MPa)", principal[:, 0] * MPA, "viridis", False)]
    if cell_state is not None:
        panels.append(("plastic strain (-)", np.asarray(cell_state["plastic_strain"], dtype=float)[cells],
                       "magma_r", False))
        panels.append(("damage (-)", np.asarray(cell_state["damage"], dtype=float)[cells], "inferno_r", False))
    columns = len(panels)
    fig, axes = plt.subplots(1, columns, figsize=(4.2 * columns, 4.8), squeeze=False)
    for ax, (label, values, cmap, centred) in zip(axes[0], panels):
        collection = PolyCollection(polygons, array=values, cmap=cmap, edgecolors="face", linewidths=0.2)
        if centred:  # tension red, compression blue, zero white
            bound = max(float(np.max(np.abs(values))), 1e-12)
            collection.set_clim(-bound, bound)
        ax.add_collection(collection)
        ax.autoscale_view()
        ax.set_aspect("equal")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("x (m)")
        fig.colorbar(collection, ax=ax, shrink=0.8)
    axes[0][0].set_ylabel("z (m)")
    fig.suptitle(f"{title} after the static stage, section y = {y0:.3g} m".strip(), fontsize=10)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return {"y": y0, "cells": int(len(cells)), "s1_max": float(principal[:, 2].max(initial=-np.inf)),
            "s3_min": float(principal[:, 0].min(initial=np.inf))}


def pair_normal_stress(force: np.ndarray, normal: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(p,) normal stress of pair forces F (force of side j on node i) (Pa, compression positive)."""
    return -np.einsum("pc,pc->p", force, normal) / area


def interface_stress(png_path, coords: np.ndarray, normal: np.ndarray, area: np.ndarray, before: np.ndarray,
                     after: np.ndarray, excavation_points: np.ndarray, title: str = "",
                     near_wall: float = 2.0) -> dict:
    """Draws the interface pairs' normal stress before and after the stage against the distance from
    the excavation.

    Args:
        png_path: output image.
        coords, normal, area: (p, 3), (p, 3), (p,) pair positions (m), unit normals and areas (m^2).
        before, after: (p, 3) pair forces before and after the stage (N).
        excavation_points: (k, 3) points of the excavation surface (m); empty: distance from the
            pairs' centroid.
        title: figure title.
        near_wall: distance (m) within which pairs count as "at the wall" in the returned means.

    Returns:
        {"near_wall": near_wall, "pairs": count, "pairs_near_wall": count within near_wall,
        "before_mean", "after_mean" (Pa): their mean normal stress before and after, None without
        such pairs}.
    """
    from scipy.spatial import cKDTree

    reference = excavation_points if len(excavation_points) else coords.mean(axis=0, keepdims=True)
    distance, _ = cKDTree(reference).query(coords)
    normal_before = pair_normal_stress(before, normal, area)
    normal_after = pair_normal_stress(after, normal, area)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.scatter(distance, normal_before * MPA, s=3, c="0.6", label="before (in situ)")
    ax.scatter(distance, normal_after * MPA, s=3, c="C3", label="after the stage")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("distance from the excavation (m)")
    ax.set_ylabel("interface normal stress (MPa, compression +)")
    far = float(np.percentile(distance, 90)) if len(distance) > 10 else 0.0
    if far > 0.0:  # the nearer 90 % of the pairs (all pairs may lie on the loaded surface: then all)
        ax.set_xlim(0.0, far)
    ax.grid(alpha=0.3)
    ax.legend(markerscale=4, fontsize=8)
    fit_title(ax, f"{title} interface normal stress".strip())
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    near = distance <= near_wall
    return {"near_wall": near_wall, "pairs": int(len(distance)), "pairs_near_wall": int(near.sum()),
            "before_mean": float(normal_before[near].mean()) if near.any() else None,
            "after_mean": float(normal_after[near].mean()) if near.any() else None}


def fit_title(ax, text: str, fontsize: float = 10.0) -> None:
    """Sets the axes' title wrapped to lines that fit the figure's width (a long scene title was cut
    off, issue 51)."""
    import textwrap

    width_pt = ax.figure.get_figwidth() * 72.0
    chars = max(20, int(0.9 * width_pt / (0.6 * fontsize)))  # a character is about 0.6 em wide at most
    ax.set_title(textwrap.fill(text, chars), fontsize=fontsize)


def drawn_damage_type(damage: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """The damage type section_end.png draws per cell: 0 (none) where the cell is not damaged. A
    yielded cell without damage has the type of its largest plastic strain (NonlinearRegions.
    cell_averages: 2, shear), which was drawn as "shear" damage where the damage is 0 (issue 51).
    NaN (no nonlinear region) stays NaN."""
    damage = np.asarray(damage, dtype=float)
    return np.where(np.isfinite(damage) & (damage <= 0.0), 0.0, np.asarray(kind, dtype=float))


def section_state(png_path, vertices: np.ndarray, cell_values: dict, y0: float, title: str = "") -> dict:
    """The nonlinear regions' state at the end of a run in the section y = y0: the largest principal
    stress, plastic strain, damage and the damage's type (1 tension, 2 shear; 0 where the cell is not
    damaged, even if it yielded), per cell (cell means of the points; cells outside the nonlinear
    regions grey).

    Args:
        png_path: output image.
        vertices: (cells, 8 or 4, 3) each cell's vertex coordinates (m): `cell_vertices(model)`, or the
            distributed model's whole mesh on rank 0 (pyfem/distributed_view.py).
        cell_values: {"s1" (Pa), "plastic_strain", "damage", "damage_type"}: (n_cells,) arrays, NaN
            outside the nonlinear regions.
        y0: section plane (m).
        title: figure title.

    Returns:
        {"y", "cells", "peak_damage", "peak_plastic_strain"} over the drawn cells.
    """
    cells = np.flatnonzero(section_cells(vertices[..., 1], y0))
    polygons = [convex_hull(vertices[c][:, [0, 2]]) for c in cells]
    damage = cell_values["damage"][cells]
    kind = drawn_damage_type(damage, cell_values["damage_type"][cells])
    panels = [("max principal stress (MPa)", cell_values["s1"][cells] * MPA, "RdBu_r", True),
              ("plastic strain (-)", cell_values["plastic_strain"][cells], "magma_r", False),
              ("damage (-)", damage, "inferno_r", False),
              ("damage type (0 none, 1 tension, 2 shear)", kind, "viridis", False)]
    inside = [polygon for polygon, value in zip(polygons, cell_values["plastic_strain"][cells]) if np.isfinite(value)]
    zoom = None
    if inside:
        corners = np.concatenate(inside)
        low, high = corners.min(axis=0), corners.max(axis=0)
        margin = 0.15 * float(np.max(high - low))
        zoom = ((low[0] - margin, high[0] + margin), (low[1] - margin, high[1] + margin))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.8), squeeze=False)
    for ax, (label, values, cmap, centred) in zip(axes[0], panels):
        colour_map = plt.get_cmap(cmap).copy()
        colour_map.set_bad("0.85")  # the elastic cells
        collection = PolyCollection(polygons, array=np.ma.masked_invalid(values), cmap=colour_map,
                                    edgecolors="face", linewidths=0.2)
        finite = values[np.isfinite(values)]
        if centred and finite.size:
            bound = max(float(np.max(np.abs(finite))), 1e-12)
            collection.set_clim(-bound, bound)
        elif label.startswith("damage"):  # damage in [0, 1]; its type 0, 1, 2
            collection.set_clim(0, 2 if label.startswith("damage type") else 1)
        elif finite.size:
            collection.set_clim(0.0, max(float(finite.max()), 1e-12))
        ax.add_collection(collection)
        ax.autoscale_view()
        if zoom is not None:  # the nonlinear regions and a margin, not the whole far field
            ax.set_xlim(*zoom[0])
            ax.set_ylim(*zoom[1])
        ax.set_aspect("equal")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("x (m)")
        bar = fig.colorbar(collection, ax=ax, shrink=0.8)
        if label.startswith("damage type"):
            bar.set_ticks([0, 1, 2])
    axes[0][0].set_ylabel("z (m)")
    fig.suptitle(f"{title[:60]}: the nonlinear regions at the end of the run, section y = {y0:.3g} m".lstrip(": "),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    drawn = {name: cell_values[name][cells] for name in ("damage", "plastic_strain")}
    return {"y": float(y0), "cells": int(len(cells)),
            "peak_damage": float(np.nanmax(drawn["damage"], initial=0.0)),
            "peak_plastic_strain": float(np.nanmax(drawn["plastic_strain"], initial=0.0))}

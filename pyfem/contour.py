"""The openings' contours after the earthquake: plots/contour.png and run.json "contour".

For a run whose static stage excavated (the wall of `pyfem.static_plots.excavation_wall`), in the
section through the first monitor (else the wall's middle), snapped to the wall nodes' nearest y:

- each opening's contour: the wall nodes within a wall edge's length of the section, projected on it
  (one node per x-z position, the nearest the plane), one opening per connected piece of the wall,
  ordered by the angle theta about the opening's centre in the x-z plane (0 at +x, 90 deg at the
  crown, anticlockwise with z up);
- the wall displacement along the inward normal of the contour (convergence positive), after the stage
  and at the end (the stage's plus the run's, the opening's mean motion of the run removed: the
  free field's translation is no deformation), and the band of the run's values over the samples;
- the hoop stress t.sigma.t (t the contour's unit tangent in the x-z plane; tension positive) of the
  rock cells that touch each contour node (their mean; the cell-centroid stresses, half a cell inside
  the wall), after the stage and at the end, and its band over the samples where every such cell is
  elastic (a nonlinear cell's stress is its law's, read at the end only);
- with two openings or more: the width change across each pillar between two openings (the closest
  pair of their contour nodes, along the line joining them; positive: the pillar widens) over the run.

The dynamic part costs one gather of the contour's nodes and of its cells' nodes per sample. The ranges
and the pillar histories are not in checkpoints: a resumed run's cover the samples since the resume.
Drawn by the serial writer (pyfem.output.RunWriter) and by the distributed model from its whole mesh on
rank 0 (pyfem/distributed_view.py `Pictures.add_contours`).
"""
from __future__ import annotations

import numpy as np

MPA = 1.0e-6


class Contours:
    """The openings' contours of one run, tracked over its samples.

    Args:
        model: pyfem.operators.Model.
        state: the static stage's state (excavation_load, displacement, cell_stress, installed_cells).
        strain: cells -> pyfem.output.CellStrain of those cells (`cell_strain_operator`): their elastic stress.
        y0: the section's y (m) before snapping, or None: the wall's middle.
    """

    def __init__(self, model, state, strain, y0: float | None = None):
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        from pyfem.static_plots import excavation_wall

        self.openings = []
        surface, wall = excavation_wall(state, model)
        if surface is None or not len(wall):
            return
        coords = model.node_coords
        wall_nodes = np.unique(wall)
        y = coords[wall_nodes, 1]
        target = 0.5 * (y.min() + y.max()) if y0 is None else float(y0)
        size = float(np.ptp(coords, axis=0).max()) or 1.0
        # The nearest wall node's y; of two as near (above and below), the lower: not the first by
        # node number, which differs with the rank count (so below, of two nodes as near the plane).
        distance = np.abs(y - target)
        snapped = float(y[distance <= distance.min() + 1e-9 * size].min())
        # The section: the wall nodes within a typical wall edge's length of the plane (an unstructured
        # mesh's nodes seldom lie on the plane: issue 51), projected on it: the wall of an opening
        # prismatic along y projects onto its contour in the x-z plane. Of the nodes of one x-z
        # position (a mesh extruded along y) the one nearest the plane is kept.
        corners = wall.shape[1]
        # A facet's sides: its `corners` shortest corner-to-corner distances (a quadrilateral's sides,
        # not its diagonals), whatever the order of its corners (`excavation_wall` sorts them by node
        # number, which differs with the rank count: consecutive corners were sides or diagonals by it).
        lengths = np.stack([np.linalg.norm(coords[wall[:, a]] - coords[wall[:, b]], axis=1)
                            for a in range(corners) for b in range(a + 1, corners)], axis=1)
        edges = np.sort(lengths, axis=1)[:, :corners].ravel()
        band = float(np.median(edges))
        section = wall_nodes[np.abs(y - snapped) <= band + 1e-6 * size]
        self.y = float(np.round(snapped, 6)) + 0.0  # 1e-14 of round-off is 0 m
        # Openings: the connected pieces of the wall (its facets' edges).
        rows = np.concatenate([wall[:, k] for k in range(corners)])
        cols = np.concatenate([wall[:, (k + 1) % corners] for k in range(corners)])
        # The two nodes of a contact pair share a position: the wall of one opening that a split
        # interface crosses is one piece, not one per side of the interface.
        _, where = np.unique(np.round(coords[wall_nodes] / (1e-6 * size)), axis=0, return_inverse=True)
        where = where.ravel()
        first = np.full(where.max() + 1, -1, dtype=np.int64)
        first[where[::-1]] = wall_nodes[::-1]
        rows = np.concatenate([rows, wall_nodes])
        cols = np.concatenate([cols, first[where]])
        graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(coords), len(coords)))
        _, piece = connected_components(graph, directed=False)
        n_vertices = 8 if model.mesh.topology.cell_type.name == "hexahedron" else 4
        n_basis = model.V.dofmap.dof_layout.num_dofs
        cell_nodes = model.V.dofmap.list.array.reshape(-1, n_basis)[:model.n_cells]
        installed = np.zeros(len(cell_nodes), dtype=bool)
        installed[np.asarray(getattr(state, "installed_cells", ()), dtype=np.int64)] = True
        static_stress = np.asarray(state.cell_stress)
        static_u = np.asarray(state.displacement).reshape(-1, 3)
        for label in np.unique(piece[section]):
            nodes = section[piece[section] == label]
            if len(nodes) < 4:
                continue
            xz = coords[nodes][:, [0, 2]]
            centre = xz.mean(axis=0)
            theta = np.degrees(np.arctan2(xz[:, 1] - centre[1], xz[:, 0] - centre[0])) % 360.0
            theta[theta >= 360.0] = 0.0  # -1e-15 % 360 is 360
            # One node per point of the contour (a band's nodes may share their x-z position): the
            # nearest the plane.
            offset = np.abs(coords[nodes, 1] - snapped)
            nearest = np.lexsort((coords[nodes, 1], np.round(offset / (1e-9 * size))))
            _, first = np.unique(np.round(xz[nearest] / (1e-6 * size)), axis=0, return_index=True)
            keep = nearest[first]
            order = keep[np.argsort(theta[keep], kind="stable")]
            nodes, xz, theta = nodes[order], xz[order], theta[order]
            if len(nodes) < 4:
                continue
            tangent = np.roll(xz, -1, axis=0) - np.roll(xz, 1, axis=0)
            tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
            normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
            inward = np.einsum("kc,kc->k", normal, centre - xz) > 0
            normal[~inward] *= -1.0
            # The rock cells touching each contour node (vertex columns of the cells).
            touching = np.isin(cell_nodes[:, :n_vertices], nodes).any(axis=1) & ~installed
            cells = np.flatnonzero(touching)
            member = np.zeros((len(nodes), len(cells)))
            for k, node in enumerate(nodes):
                member[k] = (cell_nodes[cells, :n_vertices] == node).any(axis=1)
            member /= np.maximum(member.sum(axis=1, keepdims=True), 1.0)
            tangent3 = np.zeros((len(nodes), 3))
            tangent3[:, [0, 2]] = tangent
            normal3 = np.zeros((len(nodes), 3))
            normal3[:, [0, 2]] = normal
            opening = {
                "nodes": nodes, "xz": xz, "theta": theta, "normal": normal3, "tangent": tangent3,
                "cells": cells, "member": member,
                "strain": strain(cells), "static_stress": static_stress[cells],
                "stage_displacement": np.einsum("kc,kc->k", static_u[nodes], normal3),
            }
            opening["stage_hoop"] = self._hoop(opening, opening["static_stress"])
            self.openings.append(opening)
        for opening in self.openings:
            opening["band"] = None
            opening["hoop_band"] = None
            opening["end_displacement"] = opening["stage_displacement"].copy()
            opening["end_hoop"] = opening["stage_hoop"].copy()
        # Pillars: the closest pair of contour nodes of two openings.
        self.pillars = []
        for i in range(len(self.openings)):
            for j in range(i + 1, len(self.openings)):
                a, b = self.openings[i], self.openings[j]
                gap = np.linalg.norm(a["xz"][:, None, :] - b["xz"][None, :, :], axis=2)
                k, m = np.unravel_index(np.argmin(gap), gap.shape)
                direction = np.zeros(3)
                direction[[0, 2]] = (b["xz"][m] - a["xz"][k]) / gap[k, m]
                stage = float((static_u[b["nodes"][m]] - static_u[a["nodes"][k]]) @ direction)
                self.pillars.append({"openings": (i, j), "nodes": (int(a["nodes"][k]), int(b["nodes"][m])),
                                     "width": float(gap[k, m]), "direction": direction, "stage": stage,
                                     "t": [], "change": []})

    @staticmethod
    def _hoop(opening, stress: np.ndarray) -> np.ndarray:
        """(k,) hoop stress t.sigma.t of the contour nodes from the stress (cells, 3, 3) of their cells."""
        per_node = np.einsum("kc,cij->kij", opening["member"], stress)
        return np.einsum("ki,kij,kj->k", opening["tangent"], per_node, opening["tangent"])

    def nodes(self) -> np.ndarray:
        """The nodes a sample reads: the contours' and their cells'."""
        if not self.openings:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate([np.asarray(o["strain"].nodes).ravel() for o in self.openings]
                                        + [o["nodes"] for o in self.openings]).astype(np.int64))

    def update(self, t: float, u: np.ndarray) -> None:
        """Adds the sample at t (s) of the run's displacement u (dofs, m; over the static state)."""
        if not self.openings:
            return
        nodal = u.reshape(-1, 3)
        for opening in self.openings:
            dynamic = nodal[opening["nodes"]]
            relative = dynamic - dynamic.mean(axis=0)
            inward = opening["stage_displacement"] + np.einsum("kc,kc->k", relative, opening["normal"])
            elastic = opening["strain"]
            increment = elastic.stress(elastic.strain(u)) - elastic.static
            hoop = self._hoop(opening, opening["static_stress"] + increment)
            opening["end_displacement"], opening["end_hoop"] = inward, hoop
            for key, value in (("band", inward), ("hoop_band", hoop)):
                band = opening[key]
                opening[key] = (value.copy(), value.copy()) if band is None else \
                    (np.minimum(band[0], value), np.maximum(band[1], value))
        for pillar in self.pillars:
            i, j = pillar["nodes"]
            pillar["t"].append(float(t))
            pillar["change"].append(pillar["stage"] + float((nodal[j] - nodal[i]) @ pillar["direction"]))

    def set_end_stress(self, cell_stress: dict) -> None:
        """The end's stress of the cells in nonlinear regions: {cell: (3, 3) total stress (Pa)}; their
        contour nodes' hoop stress at the end is recomputed and their band dropped (the law's stress
        is not sampled)."""
        for opening in self.openings:
            hits = [k for k, cell in enumerate(opening["cells"]) if int(cell) in cell_stress]
            if not hits:
                continue
            if opening.get("end_stress") is None:
                opening["end_stress"] = opening["static_stress"].copy()
            stress = opening["end_stress"]
            for k in hits:
                stress[k] = cell_stress[int(opening["cells"][k])]
            nonlinear_nodes = opening["member"][:, hits].sum(axis=1) > 0
            end = self._hoop(opening, stress)
            opening["end_hoop"] = np.where(nonlinear_nodes, end, opening["end_hoop"])
            if opening["hoop_band"] is not None:
                low, high = opening["hoop_band"]
                opening["hoop_band"] = (np.where(nonlinear_nodes, np.nan, low), np.where(nonlinear_nodes, np.nan, high))

    def summary(self) -> dict | None:
        """run.json "contour": per opening its centre, nodes and extremes; per pillar its width change."""
        if not self.openings:
            return None
        openings = []
        for opening in self.openings:
            openings.append({
                "centre_xz": [float(v) for v in opening["xz"].mean(axis=0)], "nodes": int(len(opening["nodes"])),
                "stage_convergence_max": float(opening["stage_displacement"].max()),
                "end_convergence_max": float(opening["end_displacement"].max()),
                "stage_hoop_min": float(opening["stage_hoop"].min()), "end_hoop_min": float(opening["end_hoop"].min()),
                "stage_hoop_max": float(opening["stage_hoop"].max()), "end_hoop_max": float(opening["end_hoop"].max()),
            })
        pillars = [{"openings": list(p["openings"]), "width": p["width"], "stage_change": p["stage"],
                    "end_change": p["change"][-1] if p["change"] else p["stage"],
                    "peak_change": float(np.max(np.abs(p["change"]))) if p["change"] else abs(p["stage"])}
                   for p in self.pillars]
        return {"y": self.y, "openings": openings, "pillars": pillars}

    def plot(self, png_path, title: str = "") -> dict | None:
        """Draws plots/contour.png; returns `summary()` or None without an opening."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        if not self.openings:
            return None
        rows = len(self.openings) + (1 if self.pillars else 0)
        fig, axes = plt.subplots(rows, 2, figsize=(11, 3.3 * rows), squeeze=False)
        def closed(values):  # the contour is a loop: its last point again before 0, its first after 360
            return np.concatenate([values[-1:], values, values[:1]])

        for row, opening in enumerate(self.openings):
            theta = closed(opening["theta"]) + np.r_[-360.0, np.zeros(len(opening["theta"])), 360.0]
            name = f"opening {row + 1} (centre x = {opening['xz'][:, 0].mean():.4g} m, z = {opening['xz'][:, 1].mean():.4g} m)"
            ax = axes[row][0]
            if opening["band"] is not None:
                ax.fill_between(theta, closed(opening["band"][0]) * 1e3, closed(opening["band"][1]) * 1e3, color="C0", alpha=0.2,
                                label="range over the run")
            ax.plot(theta, closed(opening["stage_displacement"]) * 1e3, "k--", lw=1, label="after the stage")
            ax.plot(theta, closed(opening["end_displacement"]) * 1e3, "C0", lw=1.4, label="at the end")
            ax.set_ylabel("convergence (mm)")
            ax.set_title(f"{name}: wall displacement inward", fontsize=9)
            ax = axes[row][1]
            band = opening["hoop_band"]
            if band is not None and np.isfinite(band[0]).any():
                ax.fill_between(theta, closed(band[0]) * MPA, closed(band[1]) * MPA, color="C3", alpha=0.2,
                                label="range over the run (elastic cells)")
            ax.plot(theta, closed(opening["stage_hoop"]) * MPA, "k--", lw=1, label="after the stage")
            ax.plot(theta, closed(opening["end_hoop"]) * MPA, "C3", lw=1.4, label="at the end")
            ax.set_ylabel("hoop stress (MPa, tension +)")
            ax.set_title(f"opening {row + 1}: hoop stress at the wall cells", fontsize=9)
            for ax in axes[row]:
                ax.set_xlim(0.0, 360.0)
                ax.set_xticks([0, 90, 180, 270, 360])
                ax.set_xlabel("angle about the centre (deg; 0 at +x, 90 crown)")
                ax.grid(alpha=0.3)
                ax.legend(fontsize=7)
        if self.pillars:
            ax = axes[-1][0]
            for pillar in self.pillars:
                i, j = pillar["openings"]
                ax.plot(pillar["t"], np.array(pillar["change"]) * 1e3,
                        label=f"openings {i + 1}-{j + 1} ({pillar['width']:.3g} m wide)")
            ax.set_xlabel("t (s)")
            ax.set_ylabel("width change (mm, widening +)")
            ax.set_title("relative displacement across the pillars", fontsize=9)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
            axes[-1][1].axis("off")
        fig.suptitle(f"{title[:60]}: the openings' contours, section y = {self.y:.4g} m".lstrip(": "), fontsize=10)
        fig.tight_layout()
        fig.savefig(png_path, dpi=110)
        plt.close(fig)
        return self.summary()


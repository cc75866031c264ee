"""The run's picture of the deformed model: plots/deformed_section.png.

`DeformedSection` keeps, over the samples of a run, the displacement of the section through the
monitors (the plane y = median y of the monitors, else the model's middle) at the sample where it
is most deformed: the largest displacement relative to the section's mean (its rigid translation
with the free field removed). At the end of the run `plot` draws that section undeformed and
deformed, magnified, coloured by region (lining, rock layers): where the cavern deformed most, at
what time. Costs one gather of the section's nodes per sample.
"""
from __future__ import annotations

import numpy as np
from dolfinx.cpp.mesh import cell_num_entities


def vertex_nodes(model) -> np.ndarray:
    """(cells, 8 or 4) the vertex nodes of every cell of the model's dofmap (its first dofs)."""
    n_basis = model.V.dofmap.dof_layout.num_dofs
    n_vertices = cell_num_entities(model.mesh.topology.cell_type, 0)  # 8 hexahedron, 4 tetrahedron
    return model.V.dofmap.list.array.reshape(-1, n_basis)[:, :n_vertices]


class DeformedSection:
    """Tracks the most deformed sample of one section of the model.

    Args:
        node_coords: (nodes, 3) the model's node coordinates (m).
        vertices: (cells, 8 or 4) each cell's vertex nodes (`vertex_nodes`; the distributed model's
            whole mesh gathered on rank 0, pyfem.distributed_view.WholeMesh).
        monitor_points: (m, 3) monitor points (m) or None.
        region_ids: (cells,) region id of every cell (pyfem.output.cell_regions).
    """

    def __init__(self, node_coords: np.ndarray, vertices: np.ndarray, monitor_points, region_ids: np.ndarray):
        n_vertices = vertices.shape[1]
        y = node_coords[vertices][..., 1]
        self.y = (float(np.median(monitor_points[:, 1])) if monitor_points is not None and len(monitor_points)
                  else float(0.5 * (y.min() + y.max())))
        from pyfem.static_plots import section_cells

        cut = section_cells(y, self.y)  # one layer of cells where the plane runs through nodes
        self.nodes, compact = np.unique(vertices[cut], return_inverse=True)
        self.cell_nodes = compact.reshape(-1, n_vertices)
        self.regions = region_ids[cut]
        self.coords = node_coords[self.nodes]
        self.largest = -1.0
        self.t = None
        self.displacement = None

    def update(self, t: float, u: np.ndarray) -> None:
        """Keeps the section's displacement at t (s) if it is the most deformed so far; u (dofs, m)."""
        if not len(self.nodes):
            return
        section = u.reshape(-1, 3)[self.nodes]
        relative = section - section.mean(axis=0)
        largest = float(np.sqrt(np.max(np.einsum("nc,nc->n", relative, relative))))
        if largest > self.largest:
            self.largest, self.t, self.displacement = largest, float(t), relative

    def plot(self, png_path, region_names: dict, title: str = "") -> dict | None:
        """Draws the kept sample; returns {"t", "y", "largest" (m), "magnification"} or None."""
        from pyfem.plots import deformed_section

        if self.displacement is None:
            return None
        scale = deformed_section(png_path, self.coords, self.cell_nodes, self.displacement, self.regions,
                                 region_names, self.y, self.t, title)
        return {"t": self.t, "y": self.y, "largest": self.largest, "magnification": scale}

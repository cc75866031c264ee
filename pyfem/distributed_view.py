"""The whole mesh on rank 0 for the distributed model's pictures (pyfem/distributed_model.py): the
serial run's plots (pyfem/deformation.py, pyfem/static_plots.py, pyfem/contour.py) read the whole
model's nodes and cells; under mpirun each rank holds its part. `WholeMesh` gathers, once, every
rank's owned nodes (coordinates) and owned cells (their nodes, their region) to rank 0, numbered by
dolfinx's global node index (on one rank: the serial model's numbering, so the pictures and their
numbers are the serial run's to the bit); `NodeValues` brings, per sample, the values of a few of
those nodes (a section's, the contours') to rank 0. Memory on rank 0: the whole mesh's coordinates
and connectivity (no matrix).
"""
from __future__ import annotations

import numpy as np


class WholeMesh:
    """The whole mesh's geometry on rank 0 (None elsewhere). A collective.

    Attributes (rank 0):
        node_coords: (nodes, 3) every node's coordinates (m), by global index.
        cell_nodes: (cells, k) every cell's nodes (its dofmap row, global indices), the ranks' owned
            cells in rank order.
        cell_regions: (cells,) each cell's region id (pyfem.operators.cell_regions).
        n_vertices: 8 (hexahedra) or 4 (tetrahedra): the first columns of cell_nodes.
        cells_of_rank: (ranks + 1,) where each rank's owned cells start in cell_nodes.
    """

    def __init__(self, part) -> None:
        from dolfinx.cpp.mesh import cell_num_entities

        from pyfem.operators import cell_regions

        model, comm = part.model, part.comm
        index_map = model.V.dofmap.index_map
        self.first, self.last = index_map.local_range
        self.mapped = np.concatenate([np.arange(self.first, self.last), index_map.ghosts]).astype(np.int64)
        n_basis = model.V.dofmap.dof_layout.num_dofs
        n_cells = model.mesh.topology.index_map(3).size_local
        self.n_vertices = cell_num_entities(model.mesh.topology.cell_type, 0)
        cells = self.mapped[model.V.dofmap.list.array.reshape(-1, n_basis)[:n_cells]]
        pieces = comm.gather((self.first, model.node_coords[:self.last - self.first], cells,
                              cell_regions(model)[:n_cells]), root=0)
        self.root = comm.rank == 0
        self.node_coords = self.cell_nodes = self.cell_regions = self.cells_of_rank = None
        if not self.root:
            return
        n_nodes = sum(len(coords) for _, coords, _, _ in pieces)
        self.node_coords = np.zeros((n_nodes, 3))
        for first, coords, _, _ in pieces:
            self.node_coords[first:first + len(coords)] = coords
        self.cell_nodes = np.concatenate([nodes for *_, nodes, _ in pieces])
        self.cell_regions = np.concatenate([regions for *_, regions in pieces])
        self.cells_of_rank = np.cumsum([0] + [len(nodes) for *_, nodes, _ in pieces])

    @property
    def vertices(self) -> np.ndarray:
        """(cells, 8 or 4) each cell's vertex nodes (rank 0)."""
        return self.cell_nodes[:, :self.n_vertices]

    def owned_cells(self, comm, values: np.ndarray):
        """Every rank's values per owned cell (its first rows of `values`, in its dolfinx order) as the
        whole mesh's cells' (rank 0; None elsewhere). A collective."""
        pieces = comm.gather(np.asarray(values), root=0)
        return np.concatenate(pieces) if self.root else None


class NodeValues:
    """Per sample, the nodal values (u: the kernel's (3 n_local) vector) of the whole mesh's `nodes`
    (global indices, rank 0's; every rank passes the same or None) on rank 0: each node's from the
    rank that steps it (its owned nodes in the kernel's numbering: with contact a pair node may be
    stepped on another rank than dolfinx's owner). A collective."""

    def __init__(self, part, mesh: WholeMesh, nodes) -> None:
        comm = part.comm
        nodes = comm.bcast(None if nodes is None else np.asarray(nodes, dtype=np.int64), root=0)
        self.part = part
        stepped = np.asarray(part.local_nodes[:part.n_owned], dtype=np.int64)
        order = np.argsort(stepped)
        at = np.searchsorted(stepped[order], nodes)
        at[at >= len(stepped)] = 0
        found = stepped[order][at] == nodes if len(stepped) else np.zeros(len(nodes), dtype=bool)
        mine = np.flatnonzero(found)
        self.local = order[at[mine]]  # the kernel's local nodes
        self.where = comm.gather(mine, root=0)
        self.buffer = np.zeros(3 * len(mesh.node_coords)) if mesh.root else None
        self.nodes = nodes

    def __call__(self, u: np.ndarray) -> np.ndarray | None:
        """The whole model's (3 nodes) vector on rank 0, the wanted nodes' values filled (0
        elsewhere); None on the other ranks."""
        pieces = self.part.comm.gather(u.reshape(-1, 3)[self.local], root=0)
        if pieces is None:
            return None
        whole = self.buffer.reshape(-1, 3)
        for rows, piece in zip(self.where, pieces):
            whole[self.nodes[rows]] = piece
        return self.buffer


class Pictures:
    """The serial writer's pictures of the run (pyfem.output.RunWriter._plots) on the distributed
    model, drawn on rank 0 from the whole mesh: plots/deformed_section.png (pyfem/deformation.py),
    plots/section_end.png with an element loop (`end_state`), plots/contour.png after a stage that
    excavated (`add_contours`; the stage's own pictures: `stage_pictures`). Per sample the section's
    and the contours' nodes are gathered to rank 0. A collective (`update` and `end_state` too)."""

    def __init__(self, part, monitor_points) -> None:
        from pyfem.deformation import DeformedSection

        self.mesh = WholeMesh(part)
        self.deformed = None
        if self.mesh.root:
            self.deformed = DeformedSection(self.mesh.node_coords, self.mesh.vertices, monitor_points,
                                            self.mesh.cell_regions)
        self.values = NodeValues(part, self.mesh, self.deformed.nodes if self.mesh.root else None)
        self.monitor_points = monitor_points
        self.stage_view = None  # (WholeModel, the stage's state) of `stage_pictures`, rank 0
        self.part = part
        self.contours = None  # pyfem.contour.Contours after a stage that excavated (`add_contours`, rank 0)
        self.end_stress = {}
        self.end_values = None  # {"s1", "plastic_strain", "damage", "damage_type"} per cell (`end_state`)

    def add_contours(self, part, stage, scene) -> None:
        """The openings' contours (pyfem/contour.py) of a stage that excavated, from the stage's
        whole view (`stage_pictures`): the static displacement gathered once, the contour cells'
        strain operators from the whole mesh; then each sample gathers the contours' nodes and their
        cells' nodes too. A collective."""
        from pyfem.contour import Contours
        from pyfem.output import cell_strain_of

        mesh = self.mesh
        static_u = NodeValues(part, mesh, np.arange(len(mesh.node_coords)) if mesh.root else None)(stage.u_total)
        contours = None
        if mesh.root and self.stage_view is not None:
            whole, state = self.stage_view
            state.displacement = static_u.copy()
            element = part.model.V.element.basix_element

            def strain(cells):
                return cell_strain_of(scene, element, mesh.cell_nodes[cells], mesh.node_coords,
                                      mesh.cell_regions[cells], part.model.regions)

            points = self.monitor_points
            contours = Contours(whole, state, strain,
                                float(points[0][1]) if points is not None and len(points) else None)
            self.contours = contours if contours.openings else None
        wanted = None
        if mesh.root:
            wanted = self.deformed.nodes if self.contours is None else \
                np.union1d(self.deformed.nodes, self.contours.nodes())
        self.values = NodeValues(part, mesh, wanted)

    def update(self, t: float, u: np.ndarray) -> None:
        whole = self.values(u)
        if whole is not None:
            self.deformed.update(t, whole)
            if self.contours is not None:
                self.contours.update(t, whole)

    def end_state(self, comm, counted) -> None:
        """The element loop's cell means at the end (`counted`: the rank's NonlinearRegions of its
        owned cells) as the whole mesh's cells on rank 0, for plots/section_end.png (the serial
        writer's RunWriter._section_state). A collective."""
        from pyfem.static_plots import principal_stresses

        rows = [np.zeros((0, 14))]
        for region in counted.cell_averages().values():
            xx, yy, zz, xy, yz, xz = np.asarray(region["stress"]).T
            tensor = np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1), np.stack([xz, yz, zz], -1)], 1)
            rows.append(np.column_stack([region["cells"], principal_stresses(tensor)[:, 2], region["plastic_strain"],
                                         region["damage"], region["damage_type"], tensor.reshape(-1, 9)]))
        pieces = comm.gather(np.concatenate(rows), root=0)
        if not self.mesh.root or not sum(len(piece) for piece in pieces):
            return
        n_cells = len(self.mesh.cell_nodes)
        names = ("s1", "plastic_strain", "damage", "damage_type")
        self.end_values = {name: np.full(n_cells, np.nan) for name in names}
        self.end_stress = {}  # {whole cell: (3, 3) the law's stress (Pa)}: the contours' end (Contours.set_end_stress)
        for rank, piece in enumerate(pieces):
            cells = self.mesh.cells_of_rank[rank] + piece[:, 0].astype(np.int64)
            for k, name in enumerate(names):
                self.end_values[name][cells] = piece[:, k + 1]
            self.end_stress.update(zip(cells.tolist(), piece[:, 5:].reshape(-1, 3, 3)))

    def plot(self, plot_dir, regions: dict, title: str) -> dict:
        """Draws the pictures into plot_dir (rank 0); returns their run.json entries."""
        import sys

        from pyfem.static_plots import section_state

        names = {tag: name for name, tag in regions.items()}
        out = {}
        deformed = self.deformed.plot(plot_dir / "deformed_section.png", names, title)
        if deformed is not None:
            out["deformed_section"] = deformed
        if self.end_values is not None:
            coords, points = self.mesh.node_coords, self.monitor_points
            y0 = float(points[0][1]) if points is not None and len(points) else \
                float(0.5 * (coords[:, 1].min() + coords[:, 1].max()))
            try:
                out["section_end"] = section_state(plot_dir / "section_end.png", coords[self.mesh.vertices],
                                                   self.end_values, y0, title)
            except Exception as error:  # a picture must never fail a finished run
                print(f"warning: plots/section_end.png not drawn ({type(error).__name__}: {error})", file=sys.stderr)
        if self.contours is not None:  # (as pyfem.output.RunWriter._plots)
            try:
                if self.end_stress:
                    self.contours.set_end_stress(self.end_stress)
                contour = self.contours.plot(plot_dir / "contour.png", title)
            except Exception as error:  # a picture must never fail a finished run
                print(f"warning: plots/contour.png not drawn ({type(error).__name__}: {error})", file=sys.stderr)
                contour = None
            if contour is not None:
                out["contour"] = contour
        return out


class _Pairs:
    """The whole model's pair nodes (global) and positions, as pyfem.interfaces.NodePairs holds them."""

    def __init__(self, nodes: np.ndarray, coords: np.ndarray) -> None:
        self.nodes, self.coords = nodes, coords

    def __len__(self) -> int:
        return len(self.nodes)


class WholeModel:
    """What the serial pictures read of a pyfem.operators.Model (pyfem/static_plots.py
    `excavation_wall`, `cell_vertices`), built on rank 0 from a `WholeMesh`: the node coordinates,
    the cells' dofmap, the cell type, the truncation faces' nodes and the contact pairs (global
    numbering)."""

    def __init__(self, mesh: WholeMesh, cell_type: str, faces: list, pairs) -> None:
        from types import SimpleNamespace

        self.node_coords = mesh.node_coords
        self.n_cells = len(mesh.cell_nodes)
        self.mesh = SimpleNamespace(topology=SimpleNamespace(cell_type=SimpleNamespace(name=cell_type)))
        self.V = SimpleNamespace(dofmap=SimpleNamespace(dof_layout=SimpleNamespace(num_dofs=mesh.cell_nodes.shape[1]),
                                                        list=SimpleNamespace(array=mesh.cell_nodes.ravel())))
        self.faces = faces
        self.pairs = pairs


def whole_faces(part) -> list | None:
    """The truncation faces with their nodes in the global numbering (every rank's stepped nodes),
    on rank 0 (None elsewhere). A collective."""
    from types import SimpleNamespace

    mine = [(face.name, part.local_nodes[np.asarray(face.nodes, dtype=np.int64)]) for face in part.model.faces]
    pieces = part.comm.gather(mine, root=0)
    if part.comm.rank != 0:
        return None
    names = [name for name, _ in pieces[0]]
    return [SimpleNamespace(name=name, nodes=np.unique(np.concatenate(
        [nodes for rank in pieces for other, nodes in rank if other == name] or [np.zeros(0, np.int64)])))
        for name in names]


def whole_pairs(part, contact_arrays: dict | None, forces: dict) -> dict | None:
    """The whole model's pairs on rank 0 in its pair order (`RankModel.pair_index`): {"nodes" (global),
    "coords", "normal", "area", and each of `forces` (name: this rank's (p, 3) pair values)}; None
    without contact (and on the other ranks). A collective."""
    if part.pairs is None or contact_arrays is None:
        return None
    mine = {"index": np.asarray(part.pair_index, dtype=np.int64), "nodes": np.asarray(part.pair_global),
            "coords": np.asarray(part.pairs.coords), "normal": np.asarray(contact_arrays["normal"]),
            "area": np.asarray(contact_arrays["area"]), **{name: np.asarray(values) for name, values in forces.items()}}
    pieces = part.comm.gather(mine, root=0)
    if part.comm.rank != 0:
        return None
    index = np.concatenate([piece["index"] for piece in pieces])
    tails = {"nodes": (2,), "area": ()}  # the others (p, 3); a rank may hold no pair
    out = {}
    for key in mine:
        if key == "index":
            continue
        tail = tails.get(key, (3,))
        values = np.concatenate([piece[key].reshape((len(piece["index"]),) + tail) for piece in pieces])
        whole = np.zeros((part.n_pairs,) + tail, dtype=values.dtype)
        whole[index] = values
        out[key] = whole
    return out


def stage_pictures(pictures: "Pictures", part, stage, cell_stress: np.ndarray, in_situ_forces, contact_arrays,
                   folder, title: str) -> dict | None:
    """static/section_stress.png and, with contact, static/interface_stress.png of the distributed
    stage (pyfem.static_plots.write_static_plots of the serial stage): the stage's cell stress
    (`cell_stress`: the rank's local cells', pyfem.distributed_stage.write_fields; the element loop's
    cells get their laws' means as the serial hand_over gives them), plastic strain and damage, the
    pairs' forces before (`in_situ_forces`, this rank's pairs) and after the stage. Returns static.json
    "plots" on rank 0 (None elsewhere). A collective."""
    from types import SimpleNamespace

    from pyfem.elements import voigt_tensor
    from pyfem.static_plots import excavation_surface, interface_stress, section_stress

    model, comm, mesh = part.model, part.comm, pictures.mesh
    n_cells = model.mesh.topology.index_map(3).size_local
    stress = np.array(cell_stress[:n_cells], dtype=np.float64)
    state = {"plastic_strain": np.zeros(n_cells), "damage": np.zeros(n_cells)}
    relaxed = bool(stage.cell_averages)
    for region in (stage.cell_averages[-1] if relaxed else {}).values():
        stress[region["cells"]] = voigt_tensor(region["stress"])
        for key in state:
            state[key][region["cells"]] = region[key]
    stress = mesh.owned_cells(comm, stress)
    state = {key: mesh.owned_cells(comm, values) for key, values in state.items()}
    faces = whole_faces(part)
    # The pairs' forces as the stage hands them over: the relaxed pairs', else the hand-over's F0 (a linear
    # stage's, or the welded stage's of contact.split = "after_static"), set in contact_arrays.
    after = (np.asarray(stage.contact.static_force()) if stage.contact is not None else
             np.asarray(contact_arrays["static_force"]) if contact_arrays is not None else np.zeros((0, 3)))
    pairs = whole_pairs(part, contact_arrays, {"before": in_situ_forces, "after": after})
    if not mesh.root:
        return None
    installed = np.flatnonzero(np.isin(mesh.cell_regions, [model.regions[name] for name in stage.installed_regions]))
    # The serial stage's gate is a non-zero excavation load, which the in-situ stress's round-off
    # alone makes non-zero: the wall is found from the mesh (`excavation_wall`) either way.
    excavated = True
    whole = WholeModel(mesh, model.mesh.topology.cell_type.name, faces,
                       None if pairs is None else _Pairs(pairs["nodes"], pairs["coords"]))
    state_view = SimpleNamespace(excavation_load=np.ones(1) if excavated else np.zeros(0), installed_cells=installed,
                                 cell_stress=stress)
    surface = excavation_surface(state_view, whole)
    vertices = mesh.node_coords[mesh.cell_nodes[:, :8]]
    figures = {"section_stress": section_stress(folder / "section_stress.png", vertices, stress, surface,
                                                state if relaxed else None, title)}
    if pairs is not None and in_situ_forces is not None:
        figures["interface_stress"] = interface_stress(folder / "interface_stress.png", pairs["coords"],
                                                       pairs["normal"], pairs["area"], pairs["before"],
                                                       pairs["after"], surface, title)
    pictures.stage_view = (whole, state_view)
    return figures

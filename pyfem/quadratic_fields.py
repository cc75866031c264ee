"""The mesh a second-order model's fields are written on by dolfinx, so that fields.xdmf holds every
node of the function space (issue 47): the model's cells with a second-order geometry.

dolfinx's XDMFFile writes a point field only at the nodes of the mesh's geometry. The model's mesh
has a linear geometry (its vertices); a Q2 or P2 field written on it would keep only its corner
values. `NodeMesh` builds, once, on every rank, a mesh of the same cells whose coordinate element
has the model's degree (dolfinx.mesh.create_mesh; each rank keeps its own owned cells, no
repartitioning): its geometry nodes are the function space's nodes, so the file's topology is
Hexahedron_27 or Tetrahedron_10 (ParaView draws them as quadratic cells) and the Q2 / P2 values are
written as they are, at every node, exactly. Cell data is per cell as on the model's mesh.
"""

from __future__ import annotations

import numpy as np


class NodeMesh:
    """A second-order geometry mesh of the model's owned cells (collective: every rank builds its)."""

    def __init__(self, model) -> None:
        import ufl
        from dolfinx import cpp, fem
        from dolfinx import mesh as dolfinx_mesh

        V = model.V
        comm = model.mesh.comm
        self.n_cells = model.n_cells  # owned cells, local 0 .. n_cells - 1
        index_map = V.dofmap.index_map
        n_nodes = index_map.size_local + index_map.num_ghosts
        cell_nodes = V.dofmap.list.array.reshape(self.n_cells + model.mesh.topology.index_map(3).num_ghosts, -1)
        # The cells in the model's global node numbering (the degree-2 coordinate element's local order
        # is the Lagrange element's: vertices, edges, faces, interior).
        global_node = np.asarray(index_map.local_to_global(np.arange(n_nodes, dtype=np.int32)), dtype=np.int64)
        cells = global_node[cell_nodes[:self.n_cells]]
        x = V.tabulate_dof_coordinates()[:index_map.size_local]  # the owned nodes, in global order
        cell = model.mesh.ufl_cell().cellname()
        domain = ufl.Mesh(ufl.VectorElement("Lagrange", cell, model.order))

        def keep(comm, parts, graph, ghosting):
            """Every cell stays on its rank; a cell across a facet from another rank's is ghosted there
            (dolfinx finds the nodes the ranks share through these ghosts)."""
            offsets, links = np.asarray(graph.offsets), np.asarray(graph.array, dtype=np.int64)
            n = len(offsets) - 1
            starts = np.cumsum([0] + comm.allgather(n))
            destinations, counts = [], []
            for c in range(n):
                neighbours = np.searchsorted(starts, links[offsets[c]:offsets[c + 1]], side="right") - 1
                others = np.unique(neighbours[neighbours != comm.rank]) if ghosting else []
                destinations += [comm.rank, *others]
                counts.append(1 + len(others))
            return cpp.graph.AdjacencyList_int32(np.asarray(destinations, dtype=np.int32),
                                                 np.concatenate([[0], np.cumsum(counts)]).astype(np.int32))

        self.mesh = dolfinx_mesh.create_mesh(comm, cells, x, domain, ghost_mode=dolfinx_mesh.GhostMode.shared_facet,
                                             partitioner=dolfinx_mesh.create_cell_partitioner(keep))
        self.mesh.topology.create_connectivity(3, 0)  # (before any write: writing the tags hung without)
        # The model's (local, owned) cell of each owned cell: its input index less this rank's first
        # (the ghost cells, after the owned ones, take their values from their owners).
        first = comm.exscan(self.n_cells) or 0
        owned = self.mesh.topology.index_map(3).size_local
        self.parent = np.asarray(self.mesh.topology.original_cell_index, dtype=np.int64)[:owned] - first
        if owned != self.n_cells or np.any(np.sort(self.parent) != np.arange(self.n_cells)):
            raise RuntimeError("fields.xdmf: the output mesh does not hold this rank's owned cells")
        self.V = fem.VectorFunctionSpace(self.mesh, ("Lagrange", model.order))
        self.S = fem.FunctionSpace(self.mesh, ("Lagrange", model.order))
        # The model's local node of each owned node of the output space: through the geometry (same
        # cells, same local order), whose input index is the model's global node.
        n_all = len(self.mesh.topology.original_cell_index)
        geometry = self.mesh.geometry.dofmap.array.reshape(n_all, -1)
        wanted = np.asarray(self.mesh.geometry.input_global_indices, dtype=np.int64)
        order = np.argsort(global_node)
        position = np.minimum(np.searchsorted(global_node, wanted, sorter=order), len(order) - 1)
        model_node_of_geometry = np.where(global_node[order[position]] == wanted, order[position], -1)
        space = self.S.dofmap.list.array.reshape(n_all, -1)
        node = np.full(self.S.dofmap.index_map.size_local + self.S.dofmap.index_map.num_ghosts, -1, dtype=np.int64)
        node[space.ravel()] = model_node_of_geometry[geometry.ravel()]
        self.node = node[:self.S.dofmap.index_map.size_local]
        if np.any(self.node < 0):
            raise RuntimeError("fields.xdmf: a node of the output mesh is not a node of this rank's model")
        # DG0 on the output mesh: the dofs of its owned cells, in the model's owned cells' order.
        self.T = fem.TensorFunctionSpace(self.mesh, ("DG", 0))
        self.Q = fem.FunctionSpace(self.mesh, ("DG", 0))
        by_model = np.empty(self.n_cells, dtype=np.int64)
        by_model[self.parent] = np.arange(self.n_cells)
        self.tensor_dofs = self.T.dofmap.list.array.reshape(-1, 1)[by_model, 0]
        self.scalar_dofs = self.Q.dofmap.list.array.reshape(-1, 1)[by_model, 0]

    def vector(self, name: str):
        from dolfinx import fem

        return fem.Function(self.V, name=name)

    def scalar(self, name: str):
        from dolfinx import fem

        return fem.Function(self.S, name=name)

    def set_nodal(self, function, values: np.ndarray) -> None:
        """function (of `vector` or `scalar`) <- the model's local nodal values (n_nodes x block)."""
        block = function.function_space.dofmap.index_map_bs
        function.x.array.reshape(-1, block)[:len(self.node)] = np.asarray(values).reshape(-1, block)[self.node]
        function.x.scatter_forward()

    def region_tags(self, cell_tags):
        """The model's cell tags ("region") on the output mesh."""
        from dolfinx import mesh as dolfinx_mesh

        values = np.zeros(self.n_cells, dtype=np.int32)
        indices = np.asarray(cell_tags.indices)
        owned = indices < self.n_cells
        values[indices[owned]] = np.asarray(cell_tags.values)[owned]
        cells = np.arange(self.n_cells, dtype=np.int32)
        tags = dolfinx_mesh.meshtags(self.mesh, 3, cells, values[self.parent])
        tags.name = "region"
        return tags

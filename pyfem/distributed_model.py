"""The model (docs/scaling.md "The distributed model"): on N ranks (`mpirun -n N`) each rank builds
and steps only its part of dolfinx's distributed mesh, so the memory of a rank falls with the ranks;
a run without mpirun is its one-rank case, which holds the whole model.

Each rank:
1. meshes with `pyfem.mesh.create_mesh_with_interfaces(scene, COMM_WORLD)` (gmsh on rank 0,
   dolfinx's graph partitioner distributes the cells, GhostMode.shared_facet);
2. assembles its lumped mass, its owned rows of the elastic stiffness (PETSc) and its truncation
   faces as `pyfem.operators.build_model` does on one rank;
3. numbers its nodes as the kernel's share: its owned nodes (the
   function space's), the index map's ghosts, then the *extra ghosts*, nodes that an owned row
   reaches but the index map does not hold (with GhostMode.shared_facet, neighbours through an edge or a
   vertex only); their coordinates, masses and diagonal blocks come from their owners;
4. adds the springs, dashpots, input forces and constraints of its owned face nodes, and steps its
   share with the kernel's Stepper and one `MpiNodeExchange` per step (`Stepper.set_partition`);
5. with element-loop materials ([plasticity], [damage]): steps its owned cells (counted: their energy
   is its own) and, as its halo, the other ranks' cells that touch its owned nodes, whose arrays
   their owners send at set-up (`rank_regions`); the matrix holds the other cells.

The time step is `pyfem.clock.time_step_from` of the Gershgorin bound (the largest owned row over
the ranks) and a power iteration on the ranks' owned rows from a start vector that is a function of
the node coordinates (pyfem.distributed_parts.power_iteration, the serial run's too), so the step
does not depend on the rank count: on one rank it is the serial run's to the bit, on N to the
round-off of the sums (measured 2.4e-13 of dt_critical on 3 ranks of the contact scene).

Outputs (rank 0 writes, dolfinx writes the fields in parallel): monitors/NAME.csv with the serial
run's columns (u, v, a; the free field with a wave; the stress; the law's damage and plastic
strain), energy.csv (every rank's owned energies summed), reactions.csv with fixed or roller faces,
fields.xdmf (`_Fields`: the serial run's fields, the tensors as 3 x 3 cell data), run.json, and the
serial run's pictures (plots/input.png, deformed_section.png, section_end.png, contour.png,
static/section_stress.png, interface_stress.png and their run.json / static.json numbers) from the
whole mesh gathered on rank 0 (pyfem/distributed_view.py). Checkpoints: every rank its own file keyed by
position, rank 0's record written last (`DistributedRun.write_checkpoint`); a run resumes on any
rank count (docs/checkpoint.md "The distributed model").

Contact (pyfem/distributed_pairs.py): a pair is stepped on the rank dolfinx gave its side-i node;
its side-j node, when owned elsewhere, is moved there with its stiffness rows and face values, so
the kernel's numbering (owned nodes first) differs from the function space's, and what dolfinx
numbers (fields, monitors, element arrays) is mapped through `RankModel.kernel_of_dolfinx`.

The static stage (pyfem/distributed_stage.py): its dynamic relaxation on the ranks' parts, or a linear
stage's solves by PETSc across the ranks (pyfem/distributed_linear.py), handed over to the run as the
serial stage's is.

Local time stepping (pyfem/distributed_lts.py): the serial run's levels and row split on the ranks'
parts, one velocity exchange per level.

One point per cell (integration = "reduced"): each rank adds its owned one-point cells' hourglass
stiffness to the PETSc matrix (`pyfem.distributed_parts.add_hourglass`) and steps their one-point
arrays, sent to the other ranks' halo with their mean initial stress. Quadratic tetrahedra: their
HRZ-lumped masses with the ghosts' diagonals from their owners (pyfem.assembly.hrz_lumped_vector).
Any number of contact interfaces: a pair node's checkpoint key holds its roles in ROLE_BITS-bit words.

Rock bolts and cables (pyfem/distributed_support.py): placed alike on every rank; each bolt stepped
whole by every rank stepping one of its host nodes (its other host nodes extra ghosts), counted on one.

The linear static stage: pyfem/distributed_linear.py (PETSc on the ranks' rows).
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from mpi4py import MPI

from pyfem.scene import Scene, SceneError
from pyfem.clock import run_origin
from pyfem.ranks import KEY_RESOLUTION, point_keys, rows_of  # noqa: F401 (the checkpoint's position keys)
from pyfem.distributed_parts import (_without_cells, add_hourglass, add_to_diagonal, drop_zero_blocks,
                                     element_loop_cells, local_numbering, local_stiffness, localize,
                                     one_point_regions, owned_row_sums, owned_rows_global, region_summary,
                                     stepping, to_kernel_numbering)

# Bits of a pair node's roles per int64 word of its checkpoint key (RankModel.pair_side): up to 31
# interfaces one word, as many more as more interfaces need.
ROLE_BITS = 62
# The histories go to disk (and run.json's time reached) when this much wall time (s) passed since the last time.
FLUSH_SECONDS = 2.0


# --- what the distributed model does not do yet ------------------------------------------------

def check_supported(scene: Scene) -> None:
    """Raises SceneError naming the first part of the scene that the distributed model does not
    build yet (every rank says the same: the scene is the same on every rank)."""
    from pyfem import distributed_stage

    distributed_stage.check_supported(scene)


# --- the ghost exchange (the numbering: pyfem/distributed_parts.py) ------------------------------


@dataclass
class GhostPlan:
    """Who sends what to whom after a step: per neighbour rank, the local nodes this rank sends
    (its owned nodes the neighbour ghosts) and the local nodes it receives (its ghosts owned there),
    both in ascending global order."""

    neighbours: list
    send: list
    recv: list

    def kernel_exchange(self, comm: MPI.Comm, n_local: int, keep: np.ndarray | None = None):
        """The kernel's MpiNodeExchange of this plan, or of its nodes where `keep` (per local node) is
        true: a ghost's `keep` must be its owner's, so that both sides keep the same nodes in the
        plan's order (local time stepping's one exchange per level, pyfem/distributed_lts.py). A
        collective."""
        from pyfem import _kernels

        if keep is None:
            return _kernels.MpiNodeExchange(comm.py2f(), self.neighbours, self.send, self.recv, n_local)
        send = [np.ascontiguousarray(nodes[keep[nodes]], dtype=np.int32) for nodes in self.send]
        recv = [np.ascontiguousarray(nodes[keep[nodes]], dtype=np.int32) for nodes in self.recv]
        used = [j for j in range(len(self.neighbours)) if len(send[j]) or len(recv[j])]
        return _kernels.MpiNodeExchange(comm.py2f(), [self.neighbours[j] for j in used], [send[j] for j in used],
                                        [recv[j] for j in used], n_local)

    def update(self, comm: MPI.Comm, x: np.ndarray) -> None:
        """The ghosts' rows of x (n_local, ...) from their owners (the power iteration's exchange)."""
        requests = [comm.Isend(np.ascontiguousarray(x[nodes]), dest=q, tag=77)
                    for q, nodes in zip(self.neighbours, self.send)]
        for q, nodes in zip(self.neighbours, self.recv):
            buffer = np.empty((len(nodes),) + x.shape[1:], dtype=x.dtype)
            comm.Recv(buffer, source=q, tag=77)
            x[nodes] = buffer
        MPI.Request.Waitall(requests)

    def reduce(self, comm: MPI.Comm, x: np.ndarray, op=np.minimum) -> None:
        """The owned rows of x (n_local, ...) combined by `op` (a numpy ufunc) with every rank's rows of
        them as its ghosts: the reverse of `update`."""
        requests = [comm.Isend(np.ascontiguousarray(x[nodes]), dest=q, tag=78)
                    for q, nodes in zip(self.neighbours, self.recv)]
        for q, nodes in zip(self.neighbours, self.send):
            buffer = np.empty((len(nodes),) + x.shape[1:], dtype=x.dtype)
            comm.Recv(buffer, source=q, tag=78)
            op.at(x, nodes, buffer)
        MPI.Request.Waitall(requests)


def ghost_plan(comm: MPI.Comm, ownership, local_nodes: np.ndarray, n_owned: int) -> GhostPlan:
    """The exchange of the rank's ghosts (the index map's and the extra ones): each rank asks the
    ranks stepping them (`ownership`: an Ownership or dolfinx's index map) for its ghosts in
    ascending global order."""
    from pyfem.distributed_pairs import positions

    ghosts = local_nodes[n_owned:]
    owner = stepping(comm, ownership).owner(ghosts)
    order = np.argsort(ghosts)
    requests = [ghosts[order][owner[order] == q] for q in range(comm.size)]
    asked = comm.alltoall(requests)
    local_of_ghost = dict(zip(ghosts.tolist(), range(n_owned, len(local_nodes))))
    neighbours = [q for q in range(comm.size) if q != comm.rank and (len(requests[q]) or len(asked[q]))]
    send = [positions(local_nodes[:n_owned], asked[q], "ghost exchange").astype(np.int32) for q in neighbours]
    recv = [np.array([local_of_ghost[g] for g in requests[q]], dtype=np.int32) for q in neighbours]
    return GhostPlan(neighbours, send, recv)


# --- the rank's part of the model ---------------------------------------------------------------

@dataclass
class RankModel:
    """One rank's part of the model, in the kernel's local numbering (owned, ghosts, extra ghosts).

    model: pyfem.operators.Model of the distributed mesh (node_coords and mass: the function
    space's owned and ghost nodes, in its numbering; faces: the nodes this rank steps, in the
    kernel's numbering; stiffness: None). Without contact the kernel's numbering starts with the
    function space's; with contact the pair nodes moved to this rank come after its owned nodes and
    those it gave away among its ghosts (`kernel_of_dolfinx`, pyfem/distributed_pairs.py)."""

    comm: MPI.Comm
    scene: Scene
    model: object
    n_owned: int
    local_nodes: np.ndarray        # global node of every local node
    coords: np.ndarray             # (n_local, 3)
    mass: np.ndarray               # (n_local,)
    matrix: tuple                  # the kernel's (indptr, indices, blocks)
    plan: GhostPlan
    dashpot_nodes: np.ndarray
    dashpot_matrices: np.ndarray
    constraints: object = None
    alpha: float = 0.0
    beta: float = 0.0
    n_dofs_global: int = 0
    faces_report: list = field(default_factory=list)
    setup_seconds: float = 0.0
    estimates: tuple = (0.0, None)   # omega_max^2: the Gershgorin bound, the power iteration's (or None)
    loop_cells: dict = field(default_factory=dict)  # element-loop region -> its owned cells (local)
    ownership: object = None         # pyfem.distributed_pairs.Ownership: the rank stepping each global node
    kernel_of_dolfinx: np.ndarray | None = None  # the function space's local node -> the kernel's (None: the same)
    pairs: object = None             # pyfem.interfaces.NodePairs of the pairs this rank steps (kernel numbering)
    pair_index: np.ndarray | None = None   # each of `pairs`' index among the whole model's (interface, position)
    pair_global: np.ndarray | None = None  # (n, 2) each of `pairs`' global nodes
    n_pairs: int = 0                 # the whole model's
    moved_nodes: int = 0             # pair nodes stepped on another rank than dolfinx's owner (every rank's)
    n_extra: int = 0                 # extra ghosts: ghosts the function space's index map does not hold
    pair_side: np.ndarray | None = None    # (n_local, words): its roles, bit side + 2 interface of each pair it is in
    row_sums: np.ndarray | None = None     # per owned node: its largest absolute row sum of every cell's matrix
    support: list = field(default_factory=list)  # pyfem.distributed_support.RankGroup of each [support.NAME]

    def node_keys(self, nodes: np.ndarray) -> np.ndarray:
        """Checkpoint keys of local `nodes`: their positions, and with contact their roles (`pair_side`:
        a pair's nodes share their position)."""
        keys = point_keys(self.coords[nodes])
        if self.pair_side is None:
            return keys
        return np.column_stack([keys, self.pair_side[nodes]])

    def kernel_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The kernel's local numbers of the function space's local `nodes`."""
        if self.kernel_of_dolfinx is None:
            return nodes
        return self.kernel_of_dolfinx[nodes].astype(np.asarray(nodes).dtype)

    def dolfinx_order(self, values: np.ndarray) -> np.ndarray:
        """(3 n) kernel-numbered nodal values -> the function space's local nodes' (3 n_dolfinx)."""
        n = len(self.model.node_coords)
        if self.kernel_of_dolfinx is None:
            return values[:3 * n]
        return values.reshape(-1, 3)[self.kernel_of_dolfinx].reshape(-1)

    @property
    def n_local(self) -> int:
        return len(self.local_nodes)

    @property
    def extra_ghosts(self) -> int:
        """Ghosts the function space's index map does not hold (not counting moved pair nodes this
        rank steps, which are owned here)."""
        return self.n_extra


def _owned_face(face, n_owned: int):
    """The face's owned nodes (a ghost face node's values are its owner's)."""
    from pyfem.distributed_pairs import face_rows

    return face_rows(face, face.nodes < n_owned)


def _whole_faces(comm: MPI.Comm, faces: list) -> list[dict]:
    """solver.face_report of the whole model: node counts and areas summed over the ranks (each
    counts its owned nodes), facet counts summed (each rank's owned facets)."""
    report = []
    for face in faces:
        report.append({"name": face.name, "type": face.kind, "nodes": comm.allreduce(int(len(face.nodes))),
                       "facets": comm.allreduce(face.n_facets), "area": comm.allreduce(float(np.sum(face.area))),
                       "input": face.kind in ("viscoelastic", "viscous"), "source": face.source})
    return report


def build(scene: Scene, comm: MPI.Comm) -> RankModel:
    """This rank's part of the scene's model (module docstring, steps 1-4)."""
    from dolfinx import fem

    from pyfem.assembly import elastic_stiffness_matrix, lumped_mass
    from pyfem.distributed_pairs import Ownership, global_pairs, move_rows, pair_moves, positions, route_faces
    from pyfem.mesh import create_mesh_with_interfaces
    from pyfem.operators import Model, _cell_materials, boundary_face, face_kinds, truncation_faces
    from pyfem.seismic.forces import boundary_springs_and_dashpots
    from pyfem.effects import boundary_constraints, check_input_faces, damping_coefficients, warn_input_medium

    began = time.perf_counter()
    order = scene["mesh"].get("order", 1)
    mesh, cell_tags, facet_tags, regions, boundaries, interface_tags = create_mesh_with_interfaces(scene, comm)
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", order))
    materials = _cell_materials(mesh, cell_tags, regions, scene["materials"])
    quadrature = {"quadrature_degree": 2 * order}
    coords_d = V.tabulate_dof_coordinates().astype(np.float64, copy=True)  # the function space's numbering
    mass_d = lumped_mass(V, materials.rho, quadrature)
    index_map = V.dofmap.index_map
    first, last = index_map.local_range
    mapped = np.concatenate([np.arange(first, last), index_map.ghosts]).astype(np.int64)
    # Contact: each pair stepped where its side-i node is owned (pyfem/distributed_pairs.py).
    ownership, pairs = Ownership.of(comm, index_map), None
    if "contact" in scene.effects:
        pairs = global_pairs(comm, V, facet_tags, interface_tags, coords_d, mapped, quadrature)
        ownership = Ownership.of(comm, index_map, *pair_moves(pairs, ownership))
    matrix = elastic_stiffness_matrix(V, materials.lame_lambda, materials.shear_modulus, quadrature)
    n_dofs_global = matrix.getSize()[0]
    owned, global_rows = move_rows(comm, ownership, first, owned_rows_global(matrix, last - first, release=True))
    support, bolt_hosts = [], np.zeros(0, dtype=np.int64)
    if scene.get("support"):  # rock bolts and cables: every bolt's host nodes among the nodes of the ranks stepping it
        from pyfem.distributed_support import needed_nodes
        from pyfem.support import scene_groups

        placing = Model(mesh=mesh, V=V, cell_tags=cell_tags, facet_tags=facet_tags, regions=regions,
                        boundaries=boundaries, node_coords=coords_d, mass=mass_d, stiffness=None, faces=[],
                        interface_tags=interface_tags, _materials=materials)
        support = scene_groups(scene, placing)
        bolt_hosts = needed_nodes(support, ownership, comm.rank)
    local_nodes, extra = local_numbering(owned, mapped, np.concatenate([global_rows[1], bolt_hosts]))
    rows = localize(global_rows, local_nodes)  # every cell's: the time step's
    del global_rows
    n_owned = len(owned)
    kernel_of_dolfinx = positions(local_nodes, mapped, "numbering")
    identity = np.array_equal(kernel_of_dolfinx, np.arange(len(mapped)))
    centre = scene.get("boundary", {}).get("centre")
    if centre is None:  # the whole mesh's box (as build_model's)
        centre = 0.5 * (np.min(comm.allgather(coords_d.min(axis=0)), axis=0)
                        + np.max(comm.allgather(coords_d.max(axis=0)), axis=0))
    centre = np.asarray(centre, dtype=np.float64)
    truncation, free_surfaces = truncation_faces(scene, mesh, facet_tags, boundaries, interface_tags)
    kinds = face_kinds(scene, truncation)
    faces = [_owned_face(boundary_face(name, V, facets, materials, coords_d, centre, quadrature, kind=kinds[name],
                                       source=source), index_map.size_local)
             for name, (facets, source) in truncation.items()]
    faces = route_faces(comm, ownership, faces, mapped, local_nodes)  # the nodes this rank steps, its numbering
    model = Model(mesh=mesh, V=V, cell_tags=cell_tags, facet_tags=facet_tags, regions=regions,
                  boundaries=boundaries, node_coords=coords_d, mass=mass_d, stiffness=None, faces=faces,
                  free_surfaces=free_surfaces, interface_tags=interface_tags, _materials=materials)
    check_input_faces(scene, model)
    warn_input_medium(scene, model, comm)
    boundary = scene["boundary"]
    spring_nodes, springs, dashpot_nodes, dashpots = boundary_springs_and_dashpots(
        faces, n_owned, None, boundary["alpha_N"], boundary["alpha_T"])
    if len(spring_nodes):  # K_b on the owned face nodes' diagonal blocks
        add_to_diagonal(rows, spring_nodes, springs)
    # Coordinates and masses in the kernel's numbering; the nodes the function space does not hold
    # (extra ghosts, moved pair nodes) from dolfinx's owners.
    coords = to_kernel_numbering(comm, index_map, kernel_of_dolfinx, local_nodes, coords_d)
    mass = to_kernel_numbering(comm, index_map, kernel_of_dolfinx, local_nodes, mass_d)[:, 0]
    kernel_matrix = local_stiffness(comm, ownership, rows, len(local_nodes), local_nodes)
    del rows  # (the kernel's matrix holds the owned rows)
    plan = ghost_plan(comm, ownership, local_nodes, n_owned)
    mass = np.ascontiguousarray(mass)
    estimated = kernel_matrix
    if support:  # the time step bounds the bolts' condensed stiffness too (as pyfem.solver.prepare)
        from pyfem.distributed_support import add_rows, bound_rows, rank_groups

        support = rank_groups(support, ownership, comm.rank, local_nodes)
        estimated = add_rows(kernel_matrix, n_owned, bound_rows(support, n_owned, len(local_nodes)))
    estimates = omega2_estimates(scene, comm, plan, estimated, mass, coords, n_owned)
    row_sums = owned_row_sums(estimated, n_owned)  # every cell's (and the bolts' bound): local stepping's levels
    del estimated
    loop_cells = element_loop_cells(scene, model)
    if loop_cells:  # the matrix of the other cells (the whole model's NonlinearRegions.stiffness)
        del kernel_matrix
        removed = np.concatenate([cells for cells, _ in loop_cells.values()])
        matrix = elastic_stiffness_matrix(V, *_without_cells(materials, removed), quadrature)
        if one_point_regions(scene):  # their cells' hourglass stiffness stays in the matrix
            add_hourglass(matrix, scene, model, loop_cells)
        _, global_rows = move_rows(comm, ownership, first, owned_rows_global(matrix, last - first, release=True))
        rows = localize(global_rows, local_nodes)
        del global_rows
        if len(spring_nodes):
            add_to_diagonal(rows, spring_nodes, springs)
        kernel_matrix = drop_zero_blocks(local_stiffness(comm, ownership, rows, len(local_nodes), local_nodes))
        del rows
    alpha, beta = damping_coefficients(scene)
    rank_pairs = pair_index = pair_global = pair_side = None
    if pairs is not None:
        pair_index, pair_global, rank_pairs = _rank_pairs(comm, pairs, ownership, local_nodes, mass)
        # A bit per role (side + 2 interface), ROLE_BITS to an int64 word, as many words as the interfaces need.
        words = -(-2 * len(pairs.names) // ROLE_BITS)
        pair_side = np.zeros((len(local_nodes), words), dtype=np.int64)
        for side in (0, 1):
            here = np.isin(pairs.nodes[:, side], local_nodes)
            role = side + 2 * pairs.interface[here].astype(np.int64)
            np.bitwise_or.at(pair_side, (positions(local_nodes, pairs.nodes[here, side], "pairs"), role // ROLE_BITS),
                             np.left_shift(1, role % ROLE_BITS))
    return RankModel(comm=comm, scene=scene, model=model, n_owned=n_owned, local_nodes=local_nodes, coords=coords,
                     mass=mass, matrix=kernel_matrix, plan=plan, estimates=estimates,
                     loop_cells={name: owned for name, (_, owned) in loop_cells.items()},
                     dashpot_nodes=np.ascontiguousarray(dashpot_nodes, dtype=np.int32),
                     dashpot_matrices=np.ascontiguousarray(dashpots, dtype=np.float64),
                     constraints=boundary_constraints(faces), alpha=alpha, beta=beta, n_dofs_global=n_dofs_global,
                     faces_report=_whole_faces(comm, faces), ownership=ownership,
                     kernel_of_dolfinx=None if identity else kernel_of_dolfinx, pairs=rank_pairs,
                     pair_index=pair_index, pair_global=pair_global, pair_side=pair_side,
                     n_pairs=0 if pairs is None else len(pairs),
                     moved_nodes=len(ownership.moved), n_extra=len(extra), row_sums=row_sums, support=support,
                     setup_seconds=time.perf_counter() - began)


def _rank_pairs(comm: MPI.Comm, pairs, ownership, local_nodes: np.ndarray, mass: np.ndarray):
    """(their indices in `pairs`, their global nodes, pyfem.interfaces.NodePairs) of the pairs this
    rank steps (those whose side-i node it steps: dolfinx gave it that node, or its pair group's
    first, `pair_moves`), in the kernel's numbering, in `pairs`' order (interface, then position)."""
    from pyfem.distributed_pairs import positions
    from pyfem.interfaces import NodePairs

    keep = ownership.owner(pairs.nodes[:, 0]) == comm.rank
    mine = pairs.select(keep)
    nodes = positions(local_nodes, mine.nodes.ravel(), "contact pairs").reshape(-1, 2).astype(np.int32)
    found = NodePairs(names=mine.names, interface=np.ascontiguousarray(mine.interface, dtype=np.int32),
                      nodes=np.ascontiguousarray(nodes), coords=np.ascontiguousarray(mine.coords),
                      area=np.ascontiguousarray(mine.area), normal=np.ascontiguousarray(mine.normal),
                      mass=np.ascontiguousarray(mass[nodes]))
    return np.flatnonzero(keep), mine.nodes, found


# --- the element loop on the ranks -----------------------------------------------------------------


@dataclass
class RankRegions:
    """The element loop of a rank: `counted`, pyfem.elements.NonlinearRegions of its owned cells
    (their energy is this rank's; regions without an owned cell left out), and `halo`, the same of
    the other ranks' cells that touch its owned nodes (their forces act here, their energy is
    their owner's). A halo cell's arrays are computed by its owner and sent once at set-up, so a
    rank needs no cell beyond dolfinx's ghost cells."""

    counted: object
    halo: object | None


def _region_tables(scene: Scene) -> tuple[dict, dict, dict, dict]:
    """(laws, options, zones, integration) of pyfem.elements.nonlinear_component for the scene."""
    from pyfem.elements import scene_laws, split_law_parameters

    laws, mean_dilatation = scene_laws(scene)
    tables = ({}, {}, {}, {})
    for name, given in laws.items():
        law, zone, tables[3][name], parameters = split_law_parameters(given)
        tables[0][name] = (law, parameters)
        tables[1][name] = {"mean_dilatation": bool(mean_dilatation.get(name, False))}
        if zone is not None:
            tables[2][name] = list(zone)
    return tables


def rank_regions(part: RankModel) -> RankRegions | None:
    """This rank's element loop (`RankRegions`), None without element-loop materials."""
    from pyfem.elements import ElementArrays, NonlinearRegions, element_arrays, quadrature_initial_stress
    from pyfem.initial_stress import stress_field_from_scene
    from pyfem.reduced_integration import one_point_arrays

    if not part.loop_cells:
        return None
    comm, model = part.comm, part.model
    laws, options, zones, integration = _region_tables(part.scene)
    field = stress_field_from_scene(part.scene)
    one_point = one_point_regions(part.scene)

    def regions(arrays: dict, given_stresses: dict):
        stresses = {name: given_stresses.get(name) if name in one_point or field is None
                    else quadrature_initial_stress(a.points, field) for name, a in arrays.items()}
        # One point per cell (P1 tetrahedra, integration = "reduced"): its strain is the cell's mean,
        # no B-bar (as the serial model)
        cell_options = {name: dict(options[name], mean_dilatation=options[name]["mean_dilatation"]
                                   and a.weights.shape[1] > 1) for name, a in arrays.items()}
        found = NonlinearRegions(stiffness=None, components=[], arrays=arrays,
                                 laws={name: laws[name] for name in arrays}, initial_stress=stresses,
                                 options=cell_options, zones=zones, integration=integration)
        found.new_components()
        return found

    counted_arrays, counted_stresses = {}, {}
    for name, cells in part.loop_cells.items():
        counted_arrays[name] = element_arrays(model.V, cells)
        if name in one_point:  # one point per cell at its mean strain (pyfem.elements.nonlinear_component)
            full = counted_arrays[name]
            counted_arrays[name] = one_point_arrays(full)
            if field is not None:  # the cell's mean initial stress, sum_q w_q sigma0_q / V
                counted_stresses[name] = np.ascontiguousarray(
                    np.einsum("cq,cqk->ck", full.weights, quadrature_initial_stress(full.points, field))[:, None, :]
                    / counted_arrays[name].weights[:, :, None])
    # Each owned cell goes to every rank stepping one of its nodes (its halo there).
    index_map = model.V.dofmap.index_map
    mapped = np.concatenate([np.arange(*index_map.local_range), index_map.ghosts]).astype(np.int64)
    outgoing = [[] for _ in range(comm.size)]
    for name, arrays in counted_arrays.items():
        global_nodes = mapped[arrays.cell_nodes]
        node_rank = part.ownership.owner(global_nodes.ravel()).reshape(global_nodes.shape)
        for q in np.unique(node_rank):
            if q == comm.rank:
                continue
            rows = np.flatnonzero((node_rank == q).any(axis=1))
            outgoing[q].append((name, global_nodes[rows], arrays.inverse_jacobians[rows],
                                arrays.weights[rows], arrays.points[rows],
                                None if arrays.uniform_gradients is None else arrays.uniform_gradients[rows],
                                counted_stresses[name][rows] if name in counted_stresses else None))
        if part.kernel_of_dolfinx is not None:  # the kernel's numbering
            arrays.cell_nodes = np.ascontiguousarray(part.kernel_nodes(arrays.cell_nodes), dtype=np.int32)
    incoming = comm.alltoall(outgoing)
    order = np.argsort(part.local_nodes)
    template = element_arrays(model.V, np.zeros(0, dtype=np.int32))  # the reference tables, the same for every cell
    halo_arrays, halo_stresses = {}, {}
    for name in laws:
        pieces = [piece for from_rank in incoming for piece in from_rank if piece[0] == name]
        if not pieces:
            continue
        global_nodes = np.concatenate([piece[1] for piece in pieces])
        position = np.minimum(np.searchsorted(part.local_nodes[order], global_nodes), len(order) - 1)
        if np.any(part.local_nodes[order][position] != global_nodes):
            raise RuntimeError(f"element loop {name!r}: a halo cell's node is not on this rank")
        halo_arrays[name] = ElementArrays(
            cells=np.full(len(global_nodes), -1, dtype=np.int32),
            cell_nodes=np.ascontiguousarray(order[position], dtype=np.int32),
            reference_gradients=(template.reference_gradients if name not in one_point else
                                 np.ascontiguousarray(template.reference_gradients.mean(axis=0, keepdims=True))),
            inverse_jacobians=np.ascontiguousarray(np.concatenate([piece[2] for piece in pieces])),
            weights=np.ascontiguousarray(np.concatenate([piece[3] for piece in pieces])),
            points=np.ascontiguousarray(np.concatenate([piece[4] for piece in pieces])),
            tensor=None if name in one_point else template.tensor,
            uniform_gradients=(np.ascontiguousarray(np.concatenate([piece[5] for piece in pieces]))
                               if name in one_point else None))
        if name in one_point and field is not None:
            halo_stresses[name] = np.ascontiguousarray(np.concatenate([piece[6] for piece in pieces]))
    counted = regions({name: arrays for name, arrays in counted_arrays.items() if len(arrays.cells)},
                      counted_stresses)
    return RankRegions(counted=counted, halo=regions(halo_arrays, halo_stresses) if halo_arrays else None)


# --- the time step ------------------------------------------------------------------------------


def power_iteration(comm: MPI.Comm, plan: GhostPlan, matrix: tuple, mass: np.ndarray, coords: np.ndarray,
                    n_owned: int, iterations: int) -> float:
    """The largest eigenvalue of M^-1/2 K M^-1/2 (pyfem.distributed_parts.power_iteration, the serial
    run's) on the ranks' owned rows of the kernel's `matrix` with a ghost exchange per product."""
    from pyfem.distributed_parts import power_iteration as iterate

    return iterate(matrix, mass, coords, n_owned, iterations, comm, lambda x: plan.update(comm, x))


def omega2_estimates(scene: Scene, comm: MPI.Comm, plan: GhostPlan, matrix: tuple, mass: np.ndarray,
                     coords: np.ndarray, n_owned: int) -> tuple[float, float | None]:
    """(Gershgorin bound, power iteration's estimate or None) of omega_max^2 of the elastic
    stiffness of every cell with the springs, as pyfem.solver.choose_time_step takes them."""
    from pyfem import _kernels
    from pyfem.clock import POWER_ITERATIONS

    indptr, indices, blocks = matrix
    # A ghost row holds only its blocks to owned nodes: its row sums are below its owner's.
    bound = comm.allreduce(float(_kernels.gershgorin_bound(indptr, indices, blocks, mass)), op=MPI.MAX)
    power = None
    if scene["time"].get("power_iteration", True):
        power = power_iteration(comm, plan, matrix, mass, coords, n_owned, POWER_ITERATIONS)
    return bound, power


def choose_time_step(part: RankModel):
    """pyfem.solver.choose_time_step on the ranks (module docstring)."""
    from pyfem.clock import time_step_from

    return time_step_from(part.scene, *part.estimates, part.beta)


# --- monitors -------------------------------------------------------------------------------------

@dataclass
class RankMonitors:
    """The monitors whose cell this rank owns (the lowest rank owning a cell that contains the point):
    their indices in the scene's list, interpolation weights and stress operator in local numbering."""

    index: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    stress: object = None


def locate_monitors(part: RankModel, loop: RankRegions | None = None) -> RankMonitors:
    """Each scene monitor on exactly one rank; a point in no owned cell of any rank is the whole
    model's PointOutsideMesh (the scene key named)."""
    from pyfem.operators import PointOutsideMesh
    from pyfem.effects import attach_kernel_points, monitor_stress_operator

    monitors = part.scene.get("monitor", [])
    if not monitors:
        return RankMonitors(np.zeros(0, dtype=np.int64), np.zeros((0, 0), dtype=np.int32), np.zeros((0, 0)))
    model, comm = part.model, part.comm
    points = np.array([m["point"] for m in monitors], dtype=np.float64)
    owned_cells = model.n_cells
    # Per monitor this rank's preferred owned cell holding it (Model.preferred_cell) and its centroid;
    # the monitor goes to the rank whose cell is preferred over the others' (the whole model's choice).
    best = []
    for found in model.cells_holding(points):
        found = found[found < owned_cells]
        best.append((len(found),) + ((None, None) if not len(found) else model.preferred_cell(found)))
    offers = comm.allgather([(count, None if centroid is None else tuple(centroid)) for count, _, centroid in best])
    mine = []
    for j in range(len(points)):
        held = [(offer[j][1], q) for q, offer in enumerate(offers) if offer[j][1] is not None]
        if not held:
            lo, hi = model.bounds
            error = PointOutsideMesh(j, points[j], lo, hi)
            key = f"monitor.{j}.point"
            raise SceneError(key, monitors[j]["point"], "a point inside a cell of the model",
                             f"scene key '{key}' = {monitors[j]['point']} (monitor {monitors[j]['name']!r}): {error}; "
                             "allowed: a point inside a cell of the model")
        if min(held)[1] == comm.rank:
            mine.append(j)
    mine = np.array(mine, dtype=np.int64)
    if not len(mine):
        return RankMonitors(mine, np.zeros((0, 0), dtype=np.int32), np.zeros((0, 0)))
    cells = np.array([best[j][1] for j in mine], dtype=np.int32)
    nodes, weights = model.point_weights(points[mine], cells)
    nodes = part.kernel_nodes(nodes)
    stress = monitor_stress_operator(part.scene, model, points[mine], cells)
    if part.kernel_of_dolfinx is not None:
        stress = replace(stress, nodes=part.kernel_nodes(stress.nodes))
    if loop is not None:  # a monitor in an element-loop cell reads the law there (its owner counts the cell)
        attach_kernel_points(stress, points[mine], loop.counted)
    return RankMonitors(mine, nodes, weights, stress)


@dataclass
class RankPairMonitors:
    """The pair monitors this rank reports (the rank stepping the pair `NodePairs.nearest` picks
    among every rank's): their indices in the scene's list and their pairs' indices among the rank's;
    on every rank `where` (per monitor: the pair's index among the whole model's, its interface, its
    position), run.json's."""

    index: np.ndarray
    pairs: np.ndarray
    where: list

    @classmethod
    def none(cls) -> "RankPairMonitors":
        return cls(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), [])


def locate_pair_monitors(part: RankModel) -> RankPairMonitors:
    """Each scene pair monitor on the rank stepping its nearest pair, chosen as the whole model's
    `NodePairs.nearest` chooses (`nearest_pair`'s keys, over every rank's pairs); the far-pair warning."""
    from pyfem.interfaces import nearest_pair
    from pyfem.effects import warn_far_pair_monitor

    monitors, pairs, comm = part.scene.get("pair_monitor", []), part.pairs, part.comm
    index, chosen, where = [], [], []
    for j, monitor in enumerate(monitors):
        offer = None
        if len(pairs):
            k, key = nearest_pair(pairs.coords, pairs.interface, monitor["point"])
            offer = (key, int(part.pair_index[k]), float(pairs.area[k]), k, pairs.coords[k].tolist())
        offers = comm.allgather(offer)
        best, q = min((o, q) for q, o in enumerate(offers) if o is not None)
        key, whole_index, area, k, _ = best
        at = offers[q][4]
        warn_far_pair_monitor(part.scene, monitor, np.array(at), area)
        where.append((whole_index, pairs.names[key[1]], at))
        if q == comm.rank:
            index.append(j)
            chosen.append(k)
    return RankPairMonitors(np.array(index, dtype=np.int64), np.array(chosen, dtype=np.int64), where)


# --- the run --------------------------------------------------------------------------------------

def _stepper(part: RankModel, dt: float, input_arrays: dict | None, loop: RankRegions | None, contact=None,
             held_force: np.ndarray | None = None):
    """The kernel's Stepper of the rank's share:
    with the element loop its counted cells (their energy this rank's) and its halo cells (not);
    the bolts it steps (counted and halo, pyfem/distributed_support.py);
    `contact`: the kernel's ContactPairs of the pairs it steps (None: none); `held_force`: a linear
    stage's hand-over force on the nodes it steps (pyfem/distributed_linear.py), held constant."""
    from pyfem import _kernels
    from pyfem.effects import seismic_input_kernel

    single = part.scene["time"].get("matrix_precision", "double") == "single"
    stepper = _kernels.Stepper(*part.matrix, part.mass, dt, part.alpha, part.beta, True, single)
    if len(part.dashpot_nodes):
        stepper.set_dashpots(part.dashpot_nodes, part.dashpot_matrices)
    if part.constraints is not None:
        stepper.set_constraints(np.ascontiguousarray(part.constraints.nodes, dtype=np.int32),
                                np.ascontiguousarray(part.constraints.projection, dtype=np.float64))
    if input_arrays is not None and len(input_arrays["nodes"]):
        stepper.add_provider(seismic_input_kernel(input_arrays))
    if loop is not None:
        for component in loop.counted.components:
            stepper.add_internal_force(component)
        for component in ([] if loop.halo is None else loop.halo.components):
            stepper.add_internal_force(component, count_energy=False)
    k = 0 if loop is None else len(loop.counted.components) + (0 if loop.halo is None else len(loop.halo.components))
    for rank_group in part.support:  # the stage's (rebased) or fresh at t = 0
        if not rank_group.parts:
            rank_group.fresh()
        for bolts in rank_group.kernel_components():
            stepper.add_internal_force(bolts.component, count_energy=bolts.kind == "counted")
            bolts.prefix = f"component/{k}/"  # (its state in the stepper's save_state)
            k += 1
    if contact is not None:
        stepper.add_contact(contact)
    if held_force is not None and np.any(held_force):
        from pyfem.static import hand_over_force_provider

        stepper.add_provider(hand_over_force_provider(held_force))
    exchange = part.plan.kernel_exchange(part.comm, part.n_local)
    stepper.set_partition(part.n_owned, exchange)
    return stepper, exchange


class _Fields:
    """fields.xdmf written by dolfinx on every rank: displacement, velocity and acceleration (point
    data; a second-order model's on its node mesh, pyfem.quadratic_fields: every node); strain and stress (cell data at
    the cell centroids, 3 x 3 tensors, tension positive, initial + dynamic; in an element-loop cell
    the law's stress averaged over its points), damage (cell data damage, damage_type,
    plastic_strain, crack_opening; 0 outside the element loop), as RunWriter writes them for the
    whole model (which stores the tensors as XDMF Tensor6); the cell tags as "region"."""

    POINT = ("displacement", "velocity", "acceleration")
    PAIR = (("pair_state", 8), ("pair_slip", 3), ("pair_D", 7))  # columns of output.pair_values
    DAMAGE = ("damage", "damage_type", "plastic_strain", "crack_opening")

    def __init__(self, part: RankModel, path: Path, loop: RankRegions | None, append: bool = False) -> None:
        from dolfinx import fem, io

        from pyfem.output import cell_strain_operator, time_decimals

        model, wanted = part.model, part.scene["output"]["fields"]
        V = model.V
        self.loop = loop
        self.point = [name for name in self.POINT if name in wanted]
        self.functions = {name: fem.Function(V, name=name) for name in self.point}
        self.output = self.functions
        self.nodes = None  # a second-order model's fields go on its node mesh: every node in the file
        if model.order > 1:
            from pyfem.quadratic_fields import NodeMesh

            self.nodes = NodeMesh(model)
            self.output = {name: self.nodes.vector(name) for name in self.point}
        self.tensors = [name for name in ("strain", "stress") if name in wanted]
        self.scalars = list(self.DAMAGE) if "damage" in wanted else []
        self.cells = {}
        if self.tensors or self.scalars:
            self.n_cells = model.n_cells  # owned: a ghost cell's value comes from its owner
            self.strain = cell_strain_operator(part.scene, model) if self.tensors else None
            T = fem.TensorFunctionSpace(model.mesh, ("DG", 0)) if self.nodes is None else self.nodes.T
            Q = fem.FunctionSpace(model.mesh, ("DG", 0)) if self.nodes is None else self.nodes.Q
            self.cells.update({name: fem.Function(T, name=name) for name in self.tensors})
            self.cells.update({name: fem.Function(Q, name=name) for name in self.scalars})
            if self.nodes is None:
                self.tensor_dofs = T.dofmap.list.array.reshape(-1, 1)[:self.n_cells, 0]  # blocks of 9
                self.scalar_dofs = Q.dofmap.list.array.reshape(-1, 1)[:self.n_cells, 0]
            else:
                self.tensor_dofs, self.scalar_dofs = self.nodes.tensor_dofs, self.nodes.scalar_dofs
        self.comm, self.path, self.part = part.comm, path, part
        self.pair_functions = {}
        if part.pairs is not None:  # the interface fields on both nodes of every pair, 0 elsewhere (as RunWriter)
            S, parent = V.sub(0).collapse()
            self.pair_parent = np.asarray(parent, dtype=np.int64) // 3  # V's node of each of S's
            self.pair_node = self.pair_parent[:S.dofmap.index_map.size_local]
            self.pair_functions = {name: fem.Function(S, name=name) for name, _ in self.PAIR}
            self.pair_output = self.pair_functions
            if self.nodes is not None:
                self.pair_output = {name: self.nodes.scalar(name) for name, _ in self.PAIR}
        self.file = io.XDMFFile(part.comm, str(path), "a" if append else "w")
        if not append:  # (a resumed run's file has them)
            self.file.write_mesh(model.mesh if self.nodes is None else self.nodes.mesh)
            tags = model.cell_tags if self.nodes is None else self.nodes.region_tags(model.cell_tags)
            tags.name = "region"  # the cell tags, as the whole model's fields.xdmf has them (run.json "regions")
            self.file.write_meshtags(tags)
        output = part.scene["output"]
        self.decimals = time_decimals(output["interval"], output["xdmf_interval"])
        self.every = max(1, round(output["xdmf_interval"] / output["interval"]))

    def write(self, t: float, u: np.ndarray, v: np.ndarray, a: np.ndarray, pairs: np.ndarray | None = None) -> None:
        """u, v, a: the kernel's (its numbering); pairs: output.pair_values of this rank's pairs."""
        t = round(t, self.decimals)  # 0.3, not 0.30000000000000004 (as RunWriter)
        u, v, a = (self.part.dolfinx_order(x) for x in (u, v, a))
        for name, values in zip(self.POINT, (u, v, a)):
            if name not in self.functions:
                continue
            self.functions[name].x.array[:] = values
            if self.nodes is not None:
                self.nodes.set_nodal(self.output[name], values)
            self.file.write_function(self.output[name], t)
        if self.pair_functions:
            self._write_pairs(t, pairs)
        if not self.cells:
            return
        averages = self.loop.counted.cell_averages() if self.loop is not None else {}
        values = {}
        if self.tensors:
            strain = self.strain.strain(u)
            values["strain"] = strain[:self.n_cells]
            stress = self.strain.stress(strain)[:self.n_cells]
            for region in averages.values():
                xx, yy, zz, xy, yz, xz = region["stress"].T
                stress[region["cells"]] = np.stack([np.stack([xx, xy, xz], 1), np.stack([xy, yy, yz], 1),
                                                    np.stack([xz, yz, zz], 1)], 1)
            values["stress"] = stress
        for name in self.scalars:
            values[name] = np.zeros(self.n_cells)
            for region in averages.values():
                values[name][region["cells"]] = region[name]
        for name, function in self.cells.items():
            if name in self.tensors:
                function.x.array.reshape(-1, 9)[self.tensor_dofs] = values[name].reshape(-1, 9)
            else:
                function.x.array[self.scalar_dofs] = values[name]
            function.x.scatter_forward()
            self.file.write_function(function, t)

    def _write_pairs(self, t: float, pairs: np.ndarray) -> None:
        """The pair fields: each rank's pair values sent to dolfinx's owners of the two nodes."""
        from pyfem.distributed_pairs import route_to

        part = self.part
        nodes = part.pair_global.ravel()
        columns = [column for _, column in self.PAIR]
        values = np.repeat(pairs[:, columns], 2, axis=0)
        got_nodes, got_values = route_to(self.comm, part.ownership.dolfinx_owner(nodes), nodes, values)
        first, last = part.model.V.dofmap.index_map.local_range
        nodal = np.zeros((last - first, len(columns)))
        nodal[got_nodes - first] = got_values
        for k, (name, _) in enumerate(self.PAIR):
            function = self.pair_functions[name]
            function.x.array[:len(self.pair_node)] = nodal[self.pair_node, k]
            function.x.scatter_forward()
            if self.nodes is not None:
                at_nodes = np.zeros(len(self.part.model.node_coords))
                at_nodes[self.pair_parent] = function.x.array
                self.nodes.set_nodal(self.pair_output[name], at_nodes)
            self.file.write_function(self.pair_output[name], t)

    def reopen(self) -> None:
        """Continues the file after a close (a checkpoint closes it so that it is whole on disk)."""
        from dolfinx import io

        self.file = io.XDMFFile(self.comm, str(self.path), "a")

    def close(self) -> None:
        self.file.close()


def plan(run: "DistributedRun", per_step: float, trial: int, phase_seconds: dict, bytes_sent: int,
         lts_preview: bool = False) -> dict:
    """What `check` prints and `run` prints before it steps (rank 0's; {} on the others; a collective):
    every line of the serial plan (pyfem.solver.simulation_plan, from the builders of pyfem/plan.py)
    with the whole model's numbers, summed over the ranks where each rank holds its part (cells,
    nodes, faces' nodes and areas, element-loop cells, memory), then on more than one rank each
    rank's share (its owned and ghost nodes, element-loop cells, bytes sent, memory) and the balance
    of the element loop's work. per_step: the slowest rank's seconds per step of `trial` steps from
    rest; phase_seconds: this rank's stepper's phase times of those steps (rank 0's are shown, as
    run.json's "time_per_step"); bytes_sent: this rank's per step; lts_preview: with local stepping
    off, the speed-up it would give (`check`'s line, as the serial `check`'s)."""
    from pyfem.clock import phase_split
    from pyfem.effects import free_field_words
    from pyfem.interfaces import wear_words
    from pyfem.output import peak_memory_mib
    from pyfem.plan import (deferred_check_line, element_loop_plan, element_name, face_lines, interface_slip_plan,
                            lts_preview_lines, model_lines, resolution_plan, time_lines)
    from pyfem.static import plan_report, uses_relaxation

    part, scene, time_step, loop, comm = run.part, run.scene, run.time_step, run.loop, run.comm
    n_steps, contact_arrays, lts, lts_decision = run.n_steps, run.contact_arrays, run.lts, run.lts_decision
    n_cells = comm.allreduce(int(part.model.n_cells))
    phases = phase_split(phase_seconds, per_step * trial)
    element_loop = element_loop_plan(None if loop is None else loop.counted, per_step, time_step,
                                     phases["element_loop"]["ms_per_step"] * 1e-3, comm)
    stage = None
    if "static" in scene:
        stage = plan_report(scene, part.model, comm)
        if scene["static"].get("step"):  # an excavation sequence: its steps instead of the two stages
            from pyfem.distributed_sequence import sequence_lines

            stage = {key: value for key, value in stage.items() if not key.startswith("stage ")}
            stage = dict(list(stage.items())[:1] + list(sequence_lines(scene).items()) + list(stage.items())[1:])
        if not uses_relaxation(scene):
            stage["solver"] = stage_words(scene)
    slip = {}
    if part.pairs is not None:
        node_index = None
        if part.kernel_of_dolfinx is not None:  # a kernel node's function-space node (-1: none here)
            node_index = np.full(part.n_local, -1, dtype=np.int64)
            node_index[part.kernel_of_dolfinx] = np.arange(len(part.kernel_of_dolfinx))
        slip = interface_slip_plan(scene, part.model, comm, part.pairs, node_index)
    resolution = resolution_plan(scene, part.model, comm)
    preview = {}
    if lts_preview and lts is None:
        from pyfem import distributed_lts
        from pyfem.local_stepping import speed_up_of

        found = distributed_lts.preview(part, loop, time_step)
        if found is not None:
            p = speed_up_of(*found, time_step, {name: entry["ms_per_step"] for name, entry in phases.items()})
            preview = lts_preview_lines(p, scene, lts_decision, bool(element_loop.get("nonlinear regions")),
                                        part.pairs is not None, True)
    cells = (0, 0) if loop is None else (
        sum(len(arrays.cells) for arrays in loop.counted.arrays.values()),
        0 if loop.halo is None else sum(len(arrays.cells) for arrays in loop.halo.arrays.values()))
    support = None
    if part.support:  # rock bolts and cables (pyfem/distributed_support.py; a collective)
        from pyfem.distributed_support import plan_lines

        support = plan_lines(comm, part.support)
    shares = comm.gather((part.n_owned, part.n_local - part.n_owned, part.extra_ghosts, *cells, int(bytes_sent),
                          rank_memory_bytes(run), round(peak_memory_mib())), root=0)
    if comm.rank != 0:
        return {}
    ratio = 1 if lts is None else lts.ratio
    shown = {
        **model_lines(scene, element_name(part.model, scene["mesh"]["order"]), n_cells, part.n_dofs_global // 3),
        **({"ranks": f"{comm.size}: each builds and steps its part (docs/scaling.md \"The distributed model\")"}
           if comm.size > 1 else {}),
        **({"free field": free_field_words(scene)} if "seismic_input" in scene.effects else {}),
        **({"contact pairs": part.n_pairs} if part.pairs is not None else {}),
        **({"interface wear": wear_words(contact_arrays["deterioration"],
                                             run_origin(run.lead_in, time_step) + n_steps * time_step.dt)["note"]}
           if contact_arrays is not None and contact_arrays["deterioration"] is not None else {}),
        **face_lines(part.faces_report, part.model.free_surfaces),
        "dt": f"{time_step.dt:.6g} s ({time_step.reason})",
        **({"local stepping (auto)": lts_decision} if lts_decision else {}),
        **({"local stepping": f"{len(lts.counts)} rate levels on the ranks' parts (nodes per level, finest first: "
                              f"{', '.join(str(int(c)) for c in lts.counts)}; global step "
                              f"{time_step.dt * lts.ratio:.6g} s), the row split, one velocity exchange per level "
                              "(pyfem/distributed_lts.py); "
                              + deferred_check_line(int(math.log2(ratio)), per_step)}
           if lts is not None else {}),
        **preview,
        **element_loop,
        **({"static stage": stage} if stage is not None else {}),
        **({"support": support} if support else {}),
        **slip,
        **resolution,
        "steps": n_steps,
        "memory": f"{sum(s[6] for s in shares) / 2**20:.1f} MiB" + (" (the ranks' sum)" if comm.size > 1 else ""),
        **time_lines(scene, per_step, trial, phases, n_steps, run.lead_in,
                     how=f", {'fine steps, ' if ratio > 1 else ''}the slowest of {comm.size} ranks"
                     if comm.size > 1 else (", fine steps" if ratio > 1 else "")),
    }
    if comm.size > 1:  # each rank's share: on one rank these repeat the whole model's lines above
        shown.update({
            "owned / ghost (of which extra) nodes per rank": [f"{o} / {g} ({e})" for o, g, e, *_ in shares],
            "element loop cells / halo cells per rank": [f"{s[3]} / {s[4]}" for s in shares] if loop else "none",
            **({"pair nodes stepped on their pair's rank": f"{part.moved_nodes} (not dolfinx's owner: "
                                                           "pyfem/distributed_pairs.py)"} if part.pairs is not None else {}),
            "bytes sent per step per rank": [s[5] for s in shares],
            "memory per rank (MiB)": [round(s[6] / 2**20, 1) for s in shares],
            "peak memory per rank (MiB, the set-up and the trial)": [s[7] for s in shares],
            "setup seconds (slowest rank)": round(part.setup_seconds, 2)})
        imbalance = work_imbalance([s[3] + s[4] for s in shares], part.n_pairs)
        if imbalance is not None:
            shown["balance"] = imbalance
    return shown


def rank_memory_bytes(run: "DistributedRun") -> int:
    """Bytes this rank holds during the run, pyfem.solver.memory_estimate's items of its part: the
    kernel's matrix, state and scratch vectors, mass, input tables, dashpots, contact pairs and the
    element loop (its counted and halo cells)."""
    part = run.part
    total = sum(np.asarray(x).nbytes for x in part.matrix) + 6 * 8 * 3 * part.n_local + part.mass.nbytes
    if run.input_arrays is not None:
        total += sum(v.nbytes for v in run.input_arrays.values() if isinstance(v, np.ndarray))
    total += 2 * part.dashpot_matrices.nbytes
    if run.contact_arrays is not None:
        total += sum(v.nbytes for v in run.contact_arrays.values() if isinstance(v, np.ndarray))
        total += len(run.contact_arrays["area"]) * (3 * 3 * 8 + 8)  # kernel state per pair (an estimate)
    if run.loop is not None:
        total += run.loop.counted.memory_bytes + (0 if run.loop.halo is None else run.loop.halo.memory_bytes)
    return int(total)


def stage_words(scene: Scene) -> str:
    """check's line on the static stage of the distributed model."""
    from pyfem.static import uses_relaxation

    if not uses_relaxation(scene):
        return (f"linear: 2 solves of K u = f by PETSc across the ranks (static.solver = \"{scene['static']['solver']}\"; "
                "pyfem/distributed_linear.py) before the motion")
    return (f"dynamic relaxation on the ranks' parts before the motion: 2 stages of at most "
            f"{int(scene['static']['max_steps'])} relaxation steps each and a frequency probe (pyfem/distributed_stage.py)")


# Steps the `check` times on every rank (from rest, the element loop's points elastic).
TRIAL_STEPS = 20


def _ending_every_rank(work):
    """work() under mpirun: a scene error or a stop is every rank's (raised alike on each); any other
    error ends every rank (pyfem.ranks.abort_all), where the others would wait for it."""
    from pyfem.scene import scene_error_from

    comm = MPI.COMM_WORLD
    try:
        return work()
    except (SceneError, KeyboardInterrupt):
        raise
    except BaseException as error:
        if isinstance(error, ValueError) and scene_error_from(error) is not None:
            raise  # a bad scene, found alike by every rank's builders (the command line's one line)
        if comm.size > 1:
            from pyfem.ranks import abort_all

            abort_all(error)
        raise


def check(scene: Scene) -> dict:
    """`pyfem check` with the distributed model, on every rank (a collective): each rank builds its
    part as a run does and steps it TRIAL_STEPS steps from rest; rank 0 gets the plan (the model's
    size and shares, the time step, the measured time per step and the time loop it predicts, each
    rank's memory), the others {}. Nothing is written."""
    check_supported(scene)
    return _ending_every_rank(lambda: _check(scene))


def sequence_part(scene: Scene, comm: MPI.Comm) -> RankModel:
    """The rank's part of an excavation sequence's model: the scene's without the first step's regions
    only (pyfem.excavation_steps.model_excavation; pyfem/distributed_sequence.py). A collective."""
    stage_scene = Scene(dict(scene), scene.source)
    stage_scene.warnings, stage_scene.on_warning = scene.warnings, scene.on_warning
    stage_scene.stage_model = True
    return build(stage_scene, comm)


def _check(scene: Scene) -> dict:
    from pyfem.effects import kernel_threads

    comm = MPI.COMM_WORLD
    run = DistributedRun(scene, Path("."), comm)
    if "static" in scene:  # the stage's keys (its faces, its regions), as the run reads them
        from pyfem.static import _install_cells, stage_boundary

        stage_boundary(scene, run.part.model)
        _install_cells(scene, run.part.model)
        if scene["static"].get("step"):  # the sequence's regions, on its own model
            from pyfem.distributed_sequence import check_steps

            check_steps(sequence_part(scene, comm))
    kernel_threads()
    return run.measured_plan(fresh=False)


def work_imbalance(loop_cells: list, n_pairs: int) -> str | None:
    """`check`'s line when the ranks' element-loop cells (counted and halo) differ by more than 30 %
    of their mean: dolfinx's parts balance cells, not the element loop's work (nor the pairs', which
    fall on their side-i nodes' ranks), so the slowest rank sets the step, and the trial above, from
    rest, does not show a yielding loop's cost."""
    mean = sum(loop_cells) / max(1, len(loop_cells))
    if len(loop_cells) < 2 or mean == 0 or max(loop_cells) <= 1.3 * mean:
        return None
    return (f"the element-loop cells per rank ({', '.join(map(str, loop_cells))}) reach {max(loop_cells) / mean:.2f}x "
            "their mean: the distributed model's parts are dolfinx's, balanced by cell count, not by the work of the "
            f"element loop{' and the pairs' if n_pairs else ''} (docs/scaling.md)")


def run(scene: Scene, out_dir, on_plan=None, progress=None, resume: bool = False) -> dict:
    """`pyfem.solver.run` with the distributed model (module docstring); returns the summary on
    rank 0, {} on the others. resume: continue the interrupted run in out_dir from its checkpoint
    (on any rank count: its state is keyed by position). A scene error is every rank's (raised alike on each); a stop
    signal stops every rank at the same sample with a checkpoint (`pyfem.interrupts.StopSignals`); any
    other error ends every rank (pyfem.ranks.abort_all), where the others would wait for it."""
    from pyfem.interrupts import RunInterrupted, StopSignals

    check_supported(scene)
    comm = MPI.COMM_WORLD
    saved = read_checkpoint(out_dir) if resume else None  # refused before any work, on every rank alike
    if saved is not None:
        saved.check_scene(scene)

    def work():
        # Under mpirun a stop signal during the set-up waits for the first sample (every rank stops
        # there together, with a checkpoint); on one rank it ends the set-up, nothing written.
        began = time.perf_counter()
        with StopSignals(always_defer=comm.size > 1) as signals:
            try:
                distributed_run = DistributedRun(scene, Path(out_dir), comm, saved)
            except RunInterrupted as error:
                raise set_up_lost(error, began, "mesh, matrices")
            return distributed_run.go(on_plan, progress, signals)

    return _ending_every_rank(work)


def model_in_memory(scene: Scene, solve_stage: bool = True) -> "DistributedRun":
    """The model of `scene` built in this process on its ranks (one without mpirun), with its [static]
    stage solved and handed over (`solve_stage`), nothing written: what tests and studies inspect or
    step directly instead of a run. `.part` (RankModel: matrix, mass, coords, faces, pairs), `.loop`
    (element-loop regions), `.stage` (distributed_stage.RankStage: its report, displacements, forces),
    `.time_step`, `.n_steps`, `.input_arrays`, `.monitors`; `.stepper()` builds the kernel's stepper
    (global or local) with its exchange, as a run steps it (call it once: it takes the stage's pairs).
    Refuses what a run refuses (`check_supported`)."""
    check_supported(scene)
    model = DistributedRun(scene, Path("model-in-memory"), MPI.COMM_WORLD)  # (its out directory is never made)
    if solve_stage:
        model.solve_stage()
    return model


def stage_rank_file(rank: int) -> str:
    """One rank's part of a relaxed stage's hand-over (static/hand_over.npz names the rank count)."""
    return f"hand_over.rank{rank}.npz"


def set_up_lost(error, began: float, words: str):
    """A stop (pyfem.interrupts.RunInterrupted) in the set-up, before the run directory is touched:
    `error` with what was lost (its seconds since `began`, the words of what is done again), which
    the command line's one line says (pyfem.cli.interruption_text), as the whole model's run."""
    error.setup_seconds = time.perf_counter() - began
    error.setup_words = words
    return error


# --- checkpoints: each rank its own state, rank 0 the run's (docs/checkpoint.md "Distributed model") ---

def rank_file(out: Path, identifier: int, rank: int) -> Path:
    from pyfem.checkpoint import rank_file_name

    return out / rank_file_name(identifier, rank)


def read_checkpoint(out_dir):
    """The distributed run's checkpoint (its JSON part, pyfem.checkpoint.Checkpoint without state),
    or SceneError (key --resume) naming why not: none, finished, or the serial path's."""
    from pyfem import checkpoint as checkpoints

    saved = checkpoints.read_checkpoint(out_dir, state=False)
    if saved.meta.get("model") != "distributed":
        raise SceneError("--resume", str(out_dir), "the checkpoint of a run of the distributed model",
                         f"--resume {saved.path}: written by the serial path of an earlier version (its state in "
                         "one file, numbered as that model's), which this version no longer has; run the scene "
                         "again")
    return saved


def cut_fields(path: Path, after: float) -> None:
    """Removes from a dolfinx fields.xdmf (and its .h5) every time after `after` (s): what an
    interrupted run wrote after its checkpoint, written again by the resumed run."""
    import h5py
    from xml.etree import ElementTree as ET

    ET.register_namespace("xi", "http://www.w3.org/2001/XInclude")
    tree = ET.parse(path)
    removed = []
    for collection in tree.getroot().iter("Grid"):
        for grid in list(collection):
            stamp = grid.find("Time") if grid.tag == "Grid" else None
            if stamp is not None and float(stamp.get("Value")) > after * (1 + 1e-12):
                removed += [item.text.split(":", 1)[1] for item in grid.iter("DataItem")]
                collection.remove(grid)
    if removed:
        with h5py.File(path.with_suffix(".h5"), "a") as data:
            for name in removed:
                if name in data:
                    del data[name]
    temporary = path.with_name(path.name + ".tmp")
    tree.write(temporary)
    os.replace(temporary, path)


class DistributedRun:
    """One sitting of a distributed run: the model built on the ranks, its writer on rank 0, the
    time loop, the checkpoints (`write_checkpoint`) and the resume (`_resume`)."""

    def __init__(self, scene: Scene, out: Path, comm: MPI.Comm, saved=None) -> None:
        from pyfem.elements import initial_warnings, scene_laws
        from pyfem.output import DAMAGE_COLUMNS, FREEFIELD_COLUMNS, MONITOR_COLUMNS, STRESS_COLUMNS, energy_columns
        from pyfem.seismic.setup import scene_record, seismic_input_from_scene
        from pyfem.clock import record_lead_in, run_steps
        from pyfem.effects import flow_warnings

        self.scene, self.out, self.comm, self.saved = scene, out, comm, saved
        self.root = comm.rank == 0
        self.wall_start = time.perf_counter()
        part = self.part = build(scene, comm)
        part.setup_seconds = comm.allreduce(part.setup_seconds, op=MPI.MAX)
        self.time_step = choose_time_step(part)
        # The record is processed once: the input forces and the interfaces' wear clock share it.
        record = scene_record(scene) if {"seismic_input", "contact"} & set(scene.effects) else None
        self.lead_in = record_lead_in(record) if "seismic_input" in scene.effects else 0.0
        self.n_steps = run_steps(scene["time"]["duration"], self.lead_in, self.time_step)
        loop = self.loop = rank_regions(part)
        if loop is not None:  # every rank's warnings on every rank (run.json is rank 0's)
            for message in initial_warnings(loop.counted, scene, comm):  # (counts summed over the ranks)
                scene.warn(message)
            flow_warnings(scene, scene_laws(scene)[0], self.time_step)
        from pyfem import distributed_lts

        # Local time stepping (pyfem/distributed_lts.py): its levels, step and "auto"'s decision.
        self.lts, self.lts_decision = distributed_lts.choose(part, loop, self.time_step, scene["time"]["duration"])
        self.lts_layout = None  # the LocalStepper's parts (distributed_lts.RankLayout), with the stepper
        self.lts_stability = None  # the set-up check's report when it sent "auto" back to global stepping
        if self.lts is not None:
            self.time_step = self.lts.time_step
            self.n_steps = run_steps(scene["time"]["duration"], self.lead_in, self.time_step)
        report = saved.meta.get("lts_stability") if saved is not None else None
        if report and self.lts is not None:  # the first sitting's check of this map (the fingerprint's levels)
            if report["stable"]:  # is not run again (852 s on the paper-scale case 1)
                self.lts.stability = report
            elif scene["time"].get("local_stepping") == "auto":  # it sent "auto" back to global stepping
                self._step_globally(report)
        # The element loop's columns also carry the bolts' stored energy and dissipation (pyfem/support.py).
        self.energy_columns = energy_columns(part.pairs is not None, loop is not None or bool(part.support))
        self.freefield = input_arrays = None
        self.drm = None  # the domain-reduction method's report (its forces are made by go, _drm_input)
        if "seismic_input" in scene.effects and scene["wave"]["free_field"]["method"] == "drm":
            self.drm = {"method": "drm", "auxiliary": scene["wave"]["free_field"]["auxiliary"]}
        elif "seismic_input" in scene.effects:
            model = part.model
            view = _InputView(model.faces, part.coords, model.bounds)
            points = None
            if scene["wave"].get("reference_point") is not None:  # the whole model's face nodes, on every rank
                owned = np.unique(np.concatenate([face.nodes for face in model.faces] or [np.zeros(0, int)]))
                points = np.concatenate(comm.allgather(part.coords[owned.astype(np.int64)]))
            self.freefield, input_arrays = seismic_input_from_scene(scene, view, record, points)
        self.monitors = locate_monitors(part, loop)
        self.bolt_monitors = []  # pyfem.support_output.BoltMonitor of each [[bolt_monitor]] (every rank)
        if scene.get("bolt_monitor"):
            from pyfem.support_output import locate_bolt_monitors

            self.bolt_monitors = locate_bolt_monitors(scene, [rank_group.group for rank_group in part.support])
        self.input_arrays = input_arrays
        self.contact_arrays, self.pair_monitors = None, RankPairMonitors.none()
        self.pair_names = []
        if part.pairs is not None:
            from types import SimpleNamespace

            from pyfem.effects import contact_arguments

            self.contact_arrays = contact_arguments(scene, SimpleNamespace(pairs=part.pairs), record)
            self.pair_monitors = locate_pair_monitors(part)
            self.pair_names = [m["name"] for m in scene.get("pair_monitor", [])]
        self.pair_rows_kept, self.state_counts = [], []
        self.stage = None  # pyfem.distributed_stage.RankStage once the [static] stage ran (go)
        self.stage_read = False  # whether it was read from static/hand_over.npz (a resume), not solved
        self.contact = None  # the kernel's ContactPairs of this rank's pairs (set with the stepper)
        self.names = [m["name"] for m in scene.get("monitor", [])]
        self.points = np.array([m["point"] for m in scene.get("monitor", [])], dtype=float).reshape(-1, 3)
        self.columns = list(MONITOR_COLUMNS) + (FREEFIELD_COLUMNS if self.freefield is not None else []) + \
            (STRESS_COLUMNS if self.names else []) + (DAMAGE_COLUMNS if self.names and loop is not None else [])
        stress = self.monitors.stress
        regions = comm.gather(list(zip(self.monitors.index.tolist(), stress.regions)) if stress is not None else [],
                              root=0)
        self.monitor_regions = None
        if self.root:
            region_of = dict(pair for rank_regions in regions for pair in rank_regions)
            self.monitor_regions = [region_of[j] for j in range(len(self.names))]
        if saved is not None:
            self._check_model(saved)
        self.histories, self.fields = {}, None
        self.fields_file, self.fields_files = "fields.xdmf", []
        if scene["output"]["xdmf_interval"]:  # which rank writes which node and cell where
            import hashlib

            geometry = part.model.mesh.geometry
            digest = hashlib.sha256(np.ascontiguousarray(geometry.x).tobytes()
                                    + np.ascontiguousarray(geometry.dofmap.array).tobytes()).hexdigest()[:16]
            self.fields_layout = comm.allgather(digest)
        self.rows_kept, self.energy_rows, self.times = [], [], []
        self.in_situ_forces = None  # the pairs' static forces before the stage (this rank's), with a stage
        self.pictures = None  # pyfem.distributed_view.Pictures: what the serial writer draws (set by go)
        self.summary: dict = {}
        self.checkpoint_id = 0
        self.done = 0
        self.previous_timing = {"wall_seconds": 0.0, "loop_seconds": 0.0}
        self.last_flush = time.monotonic()

    # -- set-up -------------------------------------------------------------------------------------
    def stepper(self, check_stability: bool = True) -> tuple:
        """(the kernel's Stepper of this rank's part, its exchange), with the ContactPairs of the
        rank's pairs (`self.contact`; a rank without pairs has none). With local time stepping the
        LocalStepper and its levels' exchanges (pyfem/distributed_lts.py), after the set-up check of
        its map (`check_stability`; once): an unstable map is refused when local stepping was asked
        for, and "auto" falls back to global stepping."""
        if self.lts is not None and check_stability and self.lts.stability is None:
            self._check_lts()
        if self.lts is not None:
            from pyfem.distributed_lts import rank_stepper

            stepper, exchanges, self.lts_layout = rank_stepper(self.part, self.lts, self.loop, self.input_arrays,
                                                               self.contact_arrays, self.stage)
            self.contact = self.lts_layout.pairs
            return stepper, exchanges
        if self.stage is not None and self.stage.contact is not None:
            self.contact = self.stage.contact  # the stage's pairs go on (rebased; pyfem/distributed_stage.py hand_over)
        elif self.contact_arrays is not None and len(self.part.pairs):
            from pyfem.effects import make_contact_pairs

            self.contact = make_contact_pairs(self.contact_arrays)
        return _stepper(self.part, self.time_step.dt, self.input_arrays, self.loop, self.contact,
                        None if self.stage is None else self.stage.hand_over_force)

    def measured_plan(self, fresh: bool) -> dict:
        """`plan` (rank 0's; a collective) with the time per step measured on a stepper of its own, run
        TRIAL_STEPS steps from rest (local stepping: whole global steps; its set-up check is left to the
        run) and then dropped. fresh: the run goes on with this model (`run`'s plan), so the trial steps
        fresh element-loop components, pairs and bolts and the run's are put back, never touched (as
        pyfem.solver.simulation_plan's trial); `check` (False) drops the model after."""
        comm, loop = self.comm, self.loop
        regions = [] if loop is None else [r for r in (loop.counted, loop.halo) if r is not None]
        kept = [(r, r.components) for r in regions], self.contact, self.lts_layout
        bolts = [(group, group.parts) for group in self.part.support]
        if fresh:
            for r in regions:
                r.new_components()
            for group, _ in bolts:  # (the stepper makes fresh, unloaded ones)
                group.parts = []
        stepper, exchange = self.stepper(check_stability=False)
        n = 3 * self.part.n_local
        u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        stepper.reset_energy(u, v, a, 0.0)
        ratio = 1 if self.lts is None else self.lts.ratio
        trial = ratio * math.ceil(TRIAL_STEPS / ratio)
        comm.Barrier()
        began = time.perf_counter()
        stepper.run(u, v, a, trial, 0.0)
        per_step = comm.allreduce(time.perf_counter() - began, op=MPI.MAX) / trial
        phase_seconds = dict(stepper.phase_seconds())
        bytes_sent = int(exchange.bytes_sent_per_step)
        del stepper
        if fresh:
            for r, components in kept[0]:
                r.components = components
            self.contact, self.lts_layout = kept[1], kept[2]
            for group, parts in bolts:
                group.parts = parts
        return plan(self, per_step, trial, phase_seconds, bytes_sent, lts_preview=not fresh)

    def _check_lts(self) -> None:
        """The set-up check of the LTS map on the ranks (pyfem/distributed_lts.py), as the serial
        run's (pyfem.solver._make_local_stepper)."""
        from pyfem import local_stepping
        from pyfem.distributed_lts import check_stability_on_ranks
        from pyfem.local_stepping import lts_stability_line

        report = self.lts.stability = check_stability_on_ranks(self.part, self.lts, self.loop)
        if self.comm.rank == 0:  # the whole model's console line (its plan is printed after the check)
            print(f"{'local stepping:':<48}{lts_stability_line(report)}", flush=True)
        if report["stable"]:
            return
        if self.scene["time"].get("local_stepping") != "auto":
            raise local_stepping.unstable_words(report)[0]
        self._step_globally(report)

    def _step_globally(self, report: dict) -> None:
        """`"auto"` back to global stepping after the check found the map unstable (`report`)."""
        from pyfem import local_stepping
        from pyfem.clock import run_steps

        _, decision, warning = local_stepping.unstable_words(report)
        self.time_step, self.lts = self.lts.global_step, None
        self.n_steps = run_steps(self.scene["time"]["duration"], self.lead_in, self.time_step)
        self.lts_stability, self.lts_decision = report, decision
        self.scene.warn(warning)

    def _fingerprint(self) -> dict:
        from pyfem.checkpoint import scene_fingerprint

        return {"scene": scene_fingerprint(self.scene), "dofs": self.part.n_dofs_global, "dt": self.time_step.dt,
                "steps": self.n_steps, "ranks": self.comm.size,
                "time_origin": run_origin(self.lead_in, self.time_step),
                "levels": None if self.lts is None else self.lts.counts.tolist(),
                **({"deterioration": [float(x) for x in self.contact_arrays["deterioration"]]}
                   if self.contact_arrays is not None and self.contact_arrays.get("deterioration") is not None
                   else {})}

    def _check_model(self, saved) -> None:
        """Refuses (SceneError, key --resume, on every rank alike) a checkpoint of another model,
        rank count or partition (pyfem.checkpoint.Checkpoint.check_model)."""
        ours = self._fingerprint()
        saved.check_model(ours, self.scene, ours["time_origin"] + self.n_steps * self.time_step.dt)

    def _summary(self) -> dict:
        from pyfem import distributed_stage

        part, model, ts = self.part, self.part.model, self.time_step
        stability = self.lts.stability if self.lts is not None else self.lts_stability
        return {"title": self.scene["title"], "scene": self.scene.to_json(), "effects": list(self.scene.effects),
                "model": "distributed", "ranks": self.comm.size,
                "cells": self.comm.allreduce(model.n_cells), "nodes": part.n_dofs_global // 3,
                "dofs": part.n_dofs_global, "dt": ts.dt, "dt_critical": ts.critical, "dt_reason": ts.reason,
                "omega_max": ts.omega_max, "steps": self.n_steps, "rayleigh": {"alpha": part.alpha, "beta": part.beta},
                "regions": dict(sorted(model.regions.items(), key=lambda item: item[1])),
                "boundary_faces": part.faces_report, "traction_free_surfaces": dict(model.free_surfaces),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S"), "warnings": list(getattr(self.scene, "warnings", [])),
                **({"static": distributed_stage.brief(self.stage.report)} if self.stage is not None else {}),
                **({"local_stepping": self.lts_decision} if self.lts_decision else {}),
                **({"local_stepping_stability": stability} if stability else {}),
                "status": "running"}

    def _open(self, stepper) -> tuple:
        """Starts the run directory, or continues the interrupted one; returns (u, v, a)."""
        from pyfem.output import ENERGY_FORMAT, MONITOR_FORMAT, CsvHistory, _write_json, previous_run_dir

        out, part, saved = self.out, self.part, self.saved
        summary = self._summary()  # (collective)
        sizes = None
        if saved is None:
            if self.root:
                if (out / "run.json").exists():
                    previous = previous_run_dir(out)
                    shutil.move(str(out), str(previous))
                    print(f"note: the earlier run in {out} was moved to {previous}", file=sys.stderr)
                out.mkdir(parents=True, exist_ok=True)
            n = 3 * part.n_local
            u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
            stepper.reset_energy(u, v, a, run_origin(self.lead_in, self.time_step))
        else:
            meta = saved.meta
            self.checkpoint_id, self.done = int(meta["id"]), int(meta["outputs_done"])
            self.previous_timing = meta["timing"]
            u, v, a = self.load_rank_states(stepper, self.checkpoint_id, int(meta["fingerprint"]["ranks"]))
            if self.root:
                with np.load(saved.path, allow_pickle=False) as data:
                    self.times = data["writer_times"].tolist()
                    self.energy_rows = data["writer_energy"].tolist()
                    self.rows_kept = list(data["writer_rows"]) if "writer_rows" in data else []
                    self.pair_rows_kept = list(data["writer_pair_rows"]) if "writer_pair_rows" in data else []
                    self.state_counts = list(data["writer_state_counts"]) if "writer_state_counts" in data else []
                    if "writer_deformation" in data and self.pictures is not None:
                        deformed = self.pictures.deformed
                        deformed.largest, deformed.t = (float(x) for x in data["writer_deformation"])
                        deformed.displacement = np.array(data["writer_deformation_displacement"])
                summary = dict(summary, started=meta["started"], warnings=summary["warnings"],
                               resumed=meta.get("resumed", []) + [{"t": saved.t, "at": time.strftime("%Y-%m-%dT%H:%M:%S")}])
                sizes = meta["history_sizes"]
        self.summary = summary
        if self.root:
            motion = self._input_motion()
            if motion is not None:
                summary["input_motion"] = {key: value for key, value in motion.items() if not key.startswith("_")}
            _write_json(out / "run.json", summary)
            if motion is not None:  # at once, as the serial writer's (pyfem.output.RunWriter.start)
                from pyfem import plots
                from pyfem.output import input_title

                (out / "plots").mkdir(exist_ok=True)
                plots.input_motion(out / "plots" / "input.png", *motion["_series"], title=input_title(motion))
            if self.stage is not None:  # (a resumed run's stage, solved again, writes it again)
                (out / "static").mkdir(exist_ok=True)
                if self.stage.support_groups:  # static/support.csv, .png, .xdmf (before static.json: its plot)
                    from pyfem.distributed_stage import write_support

                    write_support(out / "static", self.stage, self.scene)
                _write_json(out / "static" / "static.json", self.stage.report)
            at = (lambda name: None) if sizes is None else sizes.get
            self.histories["energy"] = CsvHistory(out / "energy.csv", self.energy_columns, ENERGY_FORMAT,
                                                  at("energy"))
            if self.names:
                (out / "monitors").mkdir(exist_ok=True)
                for name in self.names:
                    self.histories[name] = CsvHistory(out / "monitors" / f"{name}.csv", self.columns, MONITOR_FORMAT,
                                                      at(name))
            if self.pair_names:
                from pyfem.output import PAIR_COLUMNS, PAIR_FORMAT

                (out / "pairs").mkdir(exist_ok=True)
                for name in self.pair_names:
                    self.histories[f"pairs/{name}"] = CsvHistory(out / "pairs" / f"{name}.csv", PAIR_COLUMNS,
                                                                 PAIR_FORMAT, at(f"pairs/{name}"))
            if part.constraints is not None:
                face_columns = ["t"] + [f"{f}_F{axis}" for f in part.constraints.face_names for axis in "xyz"]
                self.histories["reactions"] = CsvHistory(out / "reactions.csv", face_columns, ENERGY_FORMAT,
                                                         at("reactions"))
            if self.bolt_monitors:
                from pyfem.support_output import BOLT_MONITOR_COLUMNS

                (out / "bolts").mkdir(exist_ok=True)
                for monitor in self.bolt_monitors:
                    self.histories[f"bolts/{monitor.name}"] = CsvHistory(
                        out / "bolts" / f"{monitor.name}.csv", BOLT_MONITOR_COLUMNS, MONITOR_FORMAT,
                        at(f"bolts/{monitor.name}"))
        stage_stress = None  # the stage's cell stress, the static part of the run's fields
        if self.stage is not None:
            from pyfem.distributed_stage import cell_static_stress, write_fields

            self.comm.Barrier()  # (static/ made by rank 0)
            if self.stage_read:  # static/ holds the stage's fields, pictures and hand-over already
                from pyfem.output import cell_strain_operator

                stage_stress = cell_static_stress(self.stage, part, cell_strain_operator(self.scene, part.model))
            else:
                stage_stress = write_fields(out / "static" / "fields.xdmf", self.stage, part)
            if self.pictures is not None:
                if not self.stage_read:  # the serial stage's pictures and their static.json "plots"
                    from pyfem.distributed_view import stage_pictures

                    figures = stage_pictures(self.pictures, part, self.stage, stage_stress, self.in_situ_forces,
                                             self.contact_arrays, out / "static", self.scene.get("title", ""))
                    if self.root:
                        self.stage.report["plots"] = {**figures, **self.stage.report.get("plots", {})}  # (the bolts' "support")
                        _write_json(out / "static" / "static.json", self.stage.report)
                self.pictures.add_contours(part, self.stage, self.scene)
            if not self.stage_read:
                self._write_stage()  # (after the pictures: its report holds their "plots")
        if self.scene["output"]["xdmf_interval"]:
            append = False
            if saved is not None:
                # The interrupted run's fields file, cut back to the checkpoint, continues when this
                # sitting writes its nodes and cells in the same order (the same partition); else (another
                # rank count) or when the file cannot be read back (a crash in a write), a new file
                # starts at the checkpoint, and run.json "fields_files" lists them in order.
                self.fields_files = list(saved.meta.get("fields_files", ["fields.xdmf"]))
                previous = self.fields_files[-1]
                cut = True
                if self.root:
                    try:
                        cut_fields(out / previous, saved.t)
                    except Exception as problem:  # h5py, XML: a file cut short by the crash
                        cut = False
                        print(f"note: {previous} could not be cut back to t = {saved.t:.6g} s ({type(problem).__name__}: "
                              f"{problem}); the fields go on in a new file", file=sys.stderr)
                append = self.comm.bcast(cut, root=0) and saved.meta.get("fields_layout") == self.fields_layout
                self.fields_file = previous if append else f"fields_from_{saved.t:.6g}s.xdmf"
                if not append:
                    self.fields_files.append(self.fields_file)
                summary["fields_files"] = self.fields_files
            else:
                self.fields_files = [self.fields_file]
            self.comm.Barrier()
            self.fields = _Fields(part, out / self.fields_file, self.loop, append=append)
            if stage_stress is not None and getattr(self.fields, "strain", None) is not None:  # the matrix cells'
                self.fields.strain.static = stage_stress
        return u, v, a

    def _input_motion(self) -> dict | None:
        """pyfem.output.input_motion of this run (None without a [wave])."""
        from types import SimpleNamespace

        from pyfem.output import input_motion

        return input_motion(SimpleNamespace(freefield=self.freefield, scene=self.scene, lead_in=self.lead_in,
                                            time_step=self.time_step, n_steps=self.n_steps))

    # -- the samples ------------------------------------------------------------------------------------
    def sample(self, t: float, k: int, stepper, u, v, a) -> None:
        """Monitors, energy, reactions and fields at time t (sample k); every rank, rank 0 writes."""
        from pyfem.output import monitor_rows

        monitors, loop, comm = self.monitors, self.loop, self.comm
        mine = []
        if len(monitors.index):  # this rank's monitors, as the whole model's writer computes them
            stress = monitors.stress
            kernel = None  # the law's values where the cell is in the element loop (attach_kernel_points)
            if loop is not None and stress.kernel_points is not None:
                kernel = loop.counted.point_values(stress.kernel_points)
            rows = monitor_rows(t, u, v, a, monitors.nodes, monitors.weights, self.freefield,
                                self.points[monitors.index], stress, kernel)
            mine = list(zip(monitors.index.tolist(), rows))
        pairs = counts = None
        if self.contact_arrays is not None:  # this rank's pairs (a rank without pairs has no ContactPairs)
            from pyfem.output import pair_values

            writes = self.fields is not None and k % self.fields.every == 0
            if self.contact is None:
                pairs, counts = np.zeros((0, 9)), np.zeros(4, dtype=np.int64)
            else:
                counts = np.asarray(self.contact.state_counts(), dtype=np.int64).copy()
                if len(self.pair_monitors.index) or writes:
                    pairs = pair_values(self.contact, self.contact_arrays["normal"], u)
            counts = comm.reduce(counts, root=0)
            mine_pairs = comm.gather([(j, np.concatenate([[t], pairs[p]]))
                                      for j, p in zip(self.pair_monitors.index, self.pair_monitors.pairs)], root=0)
        energy = stepper.energy()  # (a rank without element-loop cells or pairs has no such terms: 0)
        sums = comm.reduce(np.array([energy.get(name, 0.0) for name in self.energy_columns[1:]]), root=0)
        reactions = None
        if self.part.constraints is not None:
            reactions = comm.reduce(self.part.constraints.face_resultants(stepper.reactions()), root=0)
        gathered = comm.gather(mine, root=0)
        bolt_rows = None
        if self.bolt_monitors:  # from the rank counting each monitor's bolt
            from pyfem.distributed_support import monitor_rows as bolt_monitor_rows

            bolt_rows = comm.gather(bolt_monitor_rows(t, self.bolt_monitors, self.part.support), root=0)
        if self.fields is not None and k % self.fields.every == 0:
            self.fields.write(t, u, v, a, pairs)
        if self.pictures is not None:
            self.pictures.update(t, u)
        if not self.root:
            return
        by_monitor = dict(pair for rank_rows in gathered for pair in rank_rows)
        energy_row = [t] + list(sums)
        self.histories["energy"].append(energy_row)
        self.energy_rows.append(energy_row)
        self.times.append(t)
        if self.names:
            rows = np.array([by_monitor[j] for j in range(len(self.names))])
            self.rows_kept.append(rows)
            for name, row in zip(self.names, rows):
                self.histories[name].append(row)
        if reactions is not None:
            self.histories["reactions"].append([t] + list(reactions.ravel()))
        if bolt_rows is not None:
            by_bolt_monitor = dict(pair for rank_rows in bolt_rows for pair in rank_rows)
            for j, monitor in enumerate(self.bolt_monitors):
                self.histories[f"bolts/{monitor.name}"].append(by_bolt_monitor[j])
        if counts is not None:
            self.state_counts.append(counts)
            if self.pair_names:
                by_pair = dict(pair for rank_rows in mine_pairs for pair in rank_rows)
                rows = np.array([by_pair[j] for j in range(len(self.pair_names))])
                self.pair_rows_kept.append(rows)
                for name, row in zip(self.pair_names, rows):
                    self.histories[f"pairs/{name}"].append(row)
        if time.monotonic() - self.last_flush > FLUSH_SECONDS:  # the rows so far on disk, and the time reached
            self.flush()

    def flush(self) -> None:
        from pyfem.output import flush_run

        self.last_flush = flush_run(self.histories, self.summary, self.times, self.out)

    # -- checkpoints -------------------------------------------------------------------------------
    def timing(self, loop_start: float) -> dict:
        now = time.perf_counter()
        return {"wall_seconds": self.previous_timing["wall_seconds"] + now - self.wall_start,
                "loop_seconds": self.previous_timing["loop_seconds"] + now - loop_start}

    def write_checkpoint(self, stepper, u, v, a, t: float, loop_start: float, final: bool = False) -> None:
        """Every rank's state to its file, then rank 0's record (`checkpoint.npz`, written last and
        atomically, names the files): a crash at any moment leaves the last whole checkpoint. A
        collective. final: the finished run's state (kept: a longer time.duration extends the run)."""
        from pyfem.checkpoint import CHECKPOINT_NAME, FORMAT, write_atomically

        comm, out = self.comm, self.out
        identifier = self.checkpoint_id + 1
        write_atomically(rank_file(out, identifier, comm.rank), self.rank_state(stepper, u, v, a))
        comm.Barrier()
        if self.root:
            sizes = {name: history.size() for name, history in self.histories.items()}
            meta = {"format": FORMAT, "model": "distributed", "id": identifier, "fingerprint": self._fingerprint(),
                    "t": t, "outputs_done": self.done, "timing": self.timing(loop_start),
                    "history_sizes": sizes, "started": self.summary["started"],
                    "fields_files": self.fields_files, "fields_layout": getattr(self, "fields_layout", None),
                    "resumed": self.summary.get("resumed", []), "written": time.time(),
                    "lts_stability": self.lts.stability if self.lts is not None else self.lts_stability,
                    **({"final": True} if final else {})}
            writer = {"meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
                      "writer_times": np.array(self.times), "writer_energy": np.array(self.energy_rows)}
            if self.rows_kept:
                writer["writer_rows"] = np.array(self.rows_kept)
            if self.pair_rows_kept:
                writer["writer_pair_rows"] = np.array(self.pair_rows_kept)
            if self.state_counts:
                writer["writer_state_counts"] = np.array(self.state_counts)
            if self.pictures is not None and self.pictures.deformed.displacement is not None:
                deformed = self.pictures.deformed  # its most deformed sample so far (as the serial writer's)
                writer["writer_deformation"] = np.array([deformed.largest, deformed.t])
                writer["writer_deformation_displacement"] = np.asarray(deformed.displacement)
            if self.fields is not None:
                self.fields.file.close()  # flushed to disk with the checkpoint (reopened below)
            write_atomically(out / CHECKPOINT_NAME, writer)
        elif self.fields is not None:
            self.fields.file.close()
        if self.fields is not None:
            self.fields.reopen()
        comm.Barrier()
        if self.root:  # the previous checkpoint's files (of any rank count: a resumed run's first)
            for path in out.glob("checkpoint.*.rank*.npz"):
                if not path.name.startswith(f"checkpoint.{identifier}.rank"):
                    path.unlink(missing_ok=True)
        self.checkpoint_id = identifier

    def _components(self) -> list:
        """(region, "counted" or "halo", ElementArrays, [(the region's cell rows, archive prefix)] of
        each kernel component of it) of the stepper's element loop, in its order: one component per
        region, or with local time stepping one per level (pyfem/distributed_lts.py)."""
        loop = self.loop
        if loop is None:
            return []
        kinds = [("counted", loop.counted)] + ([("halo", loop.halo)] if loop.halo is not None else [])
        if self.lts_layout is not None:
            regions = dict(kinds)
            return [(name, kind, regions[kind].arrays[name], [(rows, prefix) for (rows, _), prefix
                                                              in zip(region.parts, prefixes)])
                    for name, kind, region, prefixes in self.lts_layout.components]
        found = [(name, kind, arrays) for kind, regions in kinds for name, arrays in regions.arrays.items()]
        return [(name, kind, arrays, [(np.arange(len(arrays.cells)), f"component/{k}/")])
                for k, (name, kind, arrays) in enumerate(found)]

    def _pair_parts(self) -> list:
        """[(the rank's pair rows, archive prefix)] of the stepper's ContactPairs: one, or with local
        time stepping one per level."""
        if self.lts_layout is not None:
            return [(rows, prefix) for (rows, _), prefix in zip(self.lts_layout.pairs.parts,
                                                                self.lts_layout.pair_prefixes)]
        return [(np.arange(len(self.part.pairs)), "contact/")]

    def rank_state(self, stepper, u, v, a) -> dict:
        """This rank's part of a checkpoint, keyed by position, not by its numbering: its owned nodes'
        u, v, a and internal force, its constraints' reactions, its counted cells' per-point state,
        and its share of the energy account (a sum over the ranks); with local time stepping the
        LocalStepper's own state instead of the Stepper's (pyfem.distributed_lts.lts_rank_state)."""
        from pyfem.ranks import pair_blocks, state_rows

        part, n = self.part, self.part.n_owned
        kernel = stepper.save_state()
        out = {"node_keys": part.node_keys(np.arange(n)), "u": u[:3 * n], "v": v[:3 * n], "a": a[:3 * n]}
        if part.constraints is not None:
            out["reaction_keys"] = part.node_keys(part.constraints.nodes)
        if self.lts is not None:
            from pyfem.distributed_lts import lts_rank_state

            out.update(lts_rank_state(kernel, self.lts, n))
        else:
            force = np.frombuffer(kernel["stepper/internal_force"], dtype=np.float64)
            if len(force):
                out["internal_force"] = force[:3 * n]
            if part.constraints is not None:
                out["reactions"] = np.frombuffer(kernel["stepper/reactions"], dtype=np.float64)
            for name in ("stepper/energy", "stepper/provider_work", "stepper/provider_power",
                         "stepper/energy_started"):
                out[name] = np.frombuffer(kernel[name], dtype=np.uint8)
        if self.contact is not None:  # every pair's state, keyed by its interface and position
            out["pair_keys"] = self._pair_keys()
            for rows, prefix in self._pair_parts():
                for name in pair_blocks(kernel, prefix):
                    piece = state_rows(kernel[prefix + name], len(rows))
                    whole = out.setdefault(f"pairs/{name}", np.zeros((len(part.pairs), piece.shape[1]), np.uint8))
                    whole[rows] = piece
        for name, kind, arrays, parts in self._components():
            if kind != "counted":
                continue
            cells = len(arrays.weights)
            out[f"cells/{name}/keys"] = point_keys(arrays.points.mean(axis=1))
            for block in ("state", "initial_stress"):
                for rows, prefix in parts:
                    piece = state_rows(kernel[prefix + block], len(rows))
                    whole = out.setdefault(f"cells/{name}/{block}", np.zeros((cells, piece.shape[1]), np.uint8))
                    whole[rows] = piece
            for block in ("stored_energy", "dissipation"):
                out[f"cells/{name}/{block}"] = np.sum([np.frombuffer(kernel[prefix + block], dtype=np.float64)
                                                       for _, prefix in parts], axis=0)
        if part.support:  # the counted bolts' state, keyed by their nodes' positions (pyfem/distributed_support.py)
            from pyfem.distributed_support import rank_state as bolt_state

            out.update(bolt_state(part.support))
        return out

    def _pair_keys(self) -> np.ndarray:
        """(n, 4) int64 keys of this rank's pairs: interface index, then position."""
        pairs = self.part.pairs
        return np.column_stack([pairs.interface.astype(np.int64), point_keys(pairs.coords)])

    def load_rank_states(self, stepper, identifier: int, ranks: int) -> tuple:
        """The checkpoint's state for this rank's nodes and cells, from every rank file of checkpoint
        `identifier` (written by `ranks` ranks, any partition): returns (u, v, a); the kernel's state
        loaded (energy account on rank 0, summed; a region's scalars on its first counted component)."""
        from pyfem.ranks import pair_blocks

        part, comm = self.part, self.comm
        files = [dict(np.load(rank_file(self.out, identifier, q), allow_pickle=False)) for q in range(ranks)]
        rows = rows_of(np.concatenate([f["node_keys"] for f in files]), part.node_keys(np.arange(part.n_local)), "nodes")
        u, v, a = (np.ascontiguousarray(np.concatenate([f[x].reshape(-1, 3) for f in files])[rows].reshape(-1))
                   for x in "uva")
        reaction_rows = None
        if part.constraints is not None:
            reaction_rows = rows_of(np.concatenate([f["reaction_keys"] for f in files]),
                                    part.node_keys(part.constraints.nodes), "constrained nodes")
        started = True
        if self.lts is not None:
            from pyfem.distributed_lts import load_lts_state

            started = bool(files[0]["lts/started"][0])
            if started:  # the blocks a LocalStepper saves once it has run (a run of no steps starts it)
                zeros = np.zeros(3 * part.n_local)
                stepper.run(zeros, zeros.copy(), zeros.copy(), 0, 0.0)
                state = load_lts_state(stepper.save_state(), files, rows, reaction_rows, self.lts, comm.rank == 0)
            else:
                state = dict(stepper.save_state())
        else:
            state = self._stepper_blocks(dict(stepper.save_state()), files, rows, reaction_rows)
        first = {}  # region -> the lowest rank counting its cells takes its scalars
        counted_here = {name for name, kind, *_ in self._components() if kind == "counted"}
        lowest = comm.allgather(sorted(counted_here))
        for name in {n for names in lowest for n in names}:
            first[name] = min(q for q, names in enumerate(lowest) if name in names)
        parts = {}  # archive prefix -> the component or pairs holding it (a LocalStepper not started: loaded here)
        for name, kind, arrays, pieces in self._components():
            having = [f for f in files if f"cells/{name}/keys" in f]
            keys = point_keys(arrays.points.mean(axis=1))
            data = {block: np.concatenate([f[f"cells/{name}/{block}"] for f in having])
                    for block in ("state", "initial_stress")}
            totals = {block: np.sum([f[f"cells/{name}/{block}"].view(np.float64) for f in having], axis=0)
                      for block in ("stored_energy", "dissipation")}
            all_keys = np.concatenate([f[f"cells/{name}/keys"] for f in having])
            for index, (cells, prefix) in enumerate(pieces):
                found = rows_of(all_keys, keys[cells], f"cells of {name!r}")
                for block in ("state", "initial_stress"):
                    state[prefix + block] = np.ascontiguousarray(data[block][found]).tobytes()
                takes = kind == "counted" and comm.rank == first[name] and index == 0
                for block, total in totals.items():
                    state[prefix + block] = (total if takes else np.zeros_like(total)).tobytes()
            if self.lts_layout is not None:
                region = next(r for n, k, r, _ in self.lts_layout.components if n == name and k == kind)
                parts.update({prefix: component for (_, component), (_, prefix) in zip(region.parts, pieces)})
        if self.contact is not None:
            having = [f for f in files if "pair_keys" in f]
            found = rows_of(np.concatenate([f["pair_keys"] for f in having]), self._pair_keys(), "contact pairs")
            for (pair_rows, prefix), contact in zip(self._pair_parts(), self._pair_objects()):
                for name in pair_blocks(state, prefix) or pair_blocks(contact.save_state()):
                    data = np.concatenate([f[f"pairs/{name}"] for f in having])
                    state[prefix + name] = np.ascontiguousarray(data[found][pair_rows]).tobytes()
                parts[prefix] = contact
        if part.support:  # the bolts' parts, keyed by position (pyfem/distributed_support.py)
            from pyfem.distributed_support import load_state as load_bolts

            parts.update(load_bolts(part.support, state, files, comm))
        if self.lts is not None:
            stepper.load_state(state)
            if not started:  # an unstarted LocalStepper loads none of its parts' states: each loads its own
                for prefix, component in parts.items():
                    own = component.save_state()
                    component.load_state({name: state.get(prefix + name, block) for name, block in own.items()})
        else:
            stepper.load_state(state)
        return u, v, a

    def _pair_objects(self) -> list:
        """The kernel's ContactPairs of `_pair_parts`, in its order."""
        if self.lts_layout is not None:
            return [contact for _, contact in self.lts_layout.pairs.parts]
        return [self.contact]

    def _stepper_blocks(self, state: dict, files: list, rows: np.ndarray, reaction_rows) -> dict:
        """The global Stepper's own blocks of `state` (its save_state) from the checkpoint's rank
        files: the internal force of this rank's local nodes (`rows` in the files' owned nodes), its
        constraints' reactions, the energy account summed onto rank 0, the input's work onto the
        lowest rank with an input node."""
        comm = self.comm
        if len(state["stepper/internal_force"]):
            state["stepper/internal_force"] = np.ascontiguousarray(
                np.concatenate([f["internal_force"].reshape(-1, 3) for f in files])[rows]).tobytes()
        if reaction_rows is not None:
            state["stepper/reactions"] = np.ascontiguousarray(
                np.concatenate([f["reactions"].reshape(-1, 3) for f in files])[reaction_rows]).tobytes()
        state["stepper/energy_started"] = files[0]["stepper/energy_started"].tobytes()
        total = np.sum([f["stepper/energy"].view(np.float64) for f in files], axis=0)
        state["stepper/energy"] = (total if comm.rank == 0 else np.zeros_like(total)).tobytes()
        # The providers' work and power (the seismic input where a rank owns an input node, a linear
        # stage's hand-over force where it steps one of its nodes): only their sum enters the energy
        # account (external_work), so the totals go to the first provider of the lowest rank with one.
        counts = comm.allgather(len(np.frombuffer(state["stepper/provider_work"], dtype=np.float64)))
        taker = next((q for q, count in enumerate(counts) if count), None)
        for name in ("stepper/provider_work", "stepper/provider_power"):
            mine = np.zeros(counts[comm.rank])
            if comm.rank == taker:
                mine[0] = sum(float(f[name].view(np.float64).sum()) for f in files)
            state[name] = mine.tobytes()
        return state

    # -- the stage's hand-over, kept for a resume (static/hand_over.npz) ----------------------------------
    def _stage_file(self) -> dict | None:
        """The meta of this run directory's static/hand_over.npz when a resume takes the relaxation stage
        from it (written by the distributed model, of this model), else None (the stage is solved again).
        Read alike on every rank."""
        from pyfem.static import uses_relaxation
        from pyfem.static_output import HAND_OVER_NAME

        if self.saved is None or "static" not in self.scene or not uses_relaxation(self.scene):
            return None
        try:
            with np.load(self.out / "static" / HAND_OVER_NAME, allow_pickle=False) as data:
                meta = json.loads(bytes(data["meta"]).decode())
        except (OSError, ValueError, KeyError):
            return None
        if meta.get("model") != "distributed" or not all(
                (self.out / "static" / stage_rank_file(q)).exists() for q in range(int(meta["ranks"]))):
            return None
        ours = {key: value for key, value in self._fingerprint().items() if key not in ("ranks", "steps")}
        from pyfem.checkpoint import _first_difference

        return meta if _first_difference(meta["fingerprint"], ours) is None else None

    def _write_stage(self) -> None:
        """static/hand_over.npz of a relaxed stage (a collective): each rank's stage displacements by node
        position and its pairs' static forces in static/hand_over.rankQ.npz, then rank 0's record (the
        report, the installed regions, the monitors' static stress, the fingerprint), written last. The
        components and pairs are not in it: a resume builds them fresh and loads the checkpoint's state."""
        from pyfem.checkpoint import write_atomically
        from pyfem.static import uses_relaxation
        from pyfem.static_output import HAND_OVER_NAME

        if self.stage is None or not uses_relaxation(self.scene):
            return
        part, stage, n = self.part, self.stage, self.part.n_owned
        mine = {"node_keys": part.node_keys(np.arange(n)), "u_total": stage.u_total[:3 * n],
                "u_support": stage.u_support[:3 * n], "u_first": stage.u_first[:3 * n]}
        if self.contact_arrays is not None and self.contact_arrays.get("static_force") is not None and len(part.pairs):
            mine["pair_keys"] = self._pair_keys()
            mine["static_force"] = np.asarray(self.contact_arrays["static_force"], dtype=np.float64)
        write_atomically(self.out / "static" / stage_rank_file(self.comm.rank), mine)
        stress = self.monitors.stress
        static = self.comm.gather([(int(j), stress.static[k]) for k, j in enumerate(self.monitors.index)]
                                  if stress is not None else [], root=0)
        self.comm.Barrier()
        if self.root:
            monitor_stress = np.full((len(self.names), 3, 3), np.nan)
            for j, sigma in (item for items in static for item in items):
                monitor_stress[j] = sigma
            fingerprint = {key: value for key, value in self._fingerprint().items() if key not in ("ranks", "steps")}
            meta = {"model": "distributed", "ranks": self.comm.size, "fingerprint": fingerprint,
                    "report": stage.report, "installed_regions": list(stage.installed_regions)}
            write_atomically(self.out / "static" / HAND_OVER_NAME,
                             {"meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
                              "monitor_stress": monitor_stress})
        self.comm.Barrier()

    def _read_stage(self, meta: dict):
        """The stage of `_stage_file` as the dynamic run takes it (pyfem.distributed_stage.RankStage
        without components or pairs: they are built fresh and take the checkpoint's state), with the
        monitors' static stress and the pairs' static forces set as its hand-over leaves them."""
        from pyfem.distributed_stage import RankStage
        from pyfem.static_output import HAND_OVER_NAME

        part, folder = self.part, self.out / "static"
        files = [dict(np.load(folder / stage_rank_file(q), allow_pickle=False)) for q in range(int(meta["ranks"]))]
        rows = rows_of(np.concatenate([f["node_keys"] for f in files]), part.node_keys(np.arange(part.n_local)),
                       "nodes")
        u_total, u_support, u_first = (
            np.ascontiguousarray(np.concatenate([f[x].reshape(-1, 3) for f in files])[rows].reshape(-1))
            for x in ("u_total", "u_support", "u_first"))
        if self.contact_arrays is not None and len(part.pairs):
            having = [f for f in files if "pair_keys" in f]
            found = rows_of(np.concatenate([f["pair_keys"] for f in having]), self._pair_keys(), "contact pairs")
            self.contact_arrays["static_force"] = np.ascontiguousarray(
                np.concatenate([f["static_force"].reshape(-1, 3) for f in having])[found])
        stress = self.monitors.stress
        if stress is not None and len(self.monitors.index):
            with np.load(folder / HAND_OVER_NAME, allow_pickle=False) as data:
                stress.static = np.ascontiguousarray(np.asarray(data["monitor_stress"])[self.monitors.index])
        return RankStage(counted=[], halo=[], contact=None, u_total=u_total, u_support=u_support,
                         installed_regions=list(meta["installed_regions"]), report=meta["report"], u_first=u_first)

    # -- the run --------------------------------------------------------------------------------------
    def _set_up_stage(self, stage_file: dict | None = None) -> tuple:
        """`solve_stage`, then `stepper()`: (stepper, exchange)."""
        self.solve_stage(stage_file)
        return self.stepper()

    def solve_stage(self, stage_file: dict | None = None) -> None:
        """The [static] stage, solved and handed over (`self.stage`), or on a resume read from
        static/hand_over.npz (`stage_file`: `_stage_file`'s meta; the checkpoint's state is loaded
        over it). Writes nothing."""
        part, comm = self.part, self.comm
        self.stage_read = stage_file is not None
        if stage_file is not None:
            self.stage = self._read_stage(stage_file)
        elif "static" in self.scene:
            from pyfem import distributed_stage
            from pyfem.static import uses_relaxation

            if self.scene["static"].get("step"):  # an excavation sequence, on its own model (pyfem/distributed_sequence.py)
                self.stage = self._sequence()
            elif uses_relaxation(self.scene):
                self.stage = distributed_stage.solve(part, self.loop, self.contact_arrays)
            else:  # the linear stage: PETSc's solves across the ranks
                from pyfem.distributed_linear import solve_linear

                self.stage = solve_linear(part, self.contact_arrays)
            # The pairs' in-situ forces, before the hand-over makes the stage's their F0 (static/interface_stress.png)
            self.in_situ_forces = (None if self.contact_arrays is None else
                                   np.array(self.contact_arrays["static_force"], dtype=np.float64))
            distributed_stage.hand_over(self.stage, part, self.loop, self.monitors, self.contact_arrays)
            self.stage.report["monitors"] = distributed_stage.monitor_report(self.stage, self.monitors, self.names,
                                                                             comm)

    def _sequence(self):
        """The [[static.step]] sequence solved on the model without the first step's regions only, its
        end carried over by position to this run's part (pyfem/distributed_sequence.py). A collective."""
        from pyfem import distributed_sequence

        stage_part = sequence_part(self.scene, self.comm)
        stage_loop = rank_regions(stage_part)
        sequence = distributed_sequence.solve(stage_part, stage_loop)
        return distributed_sequence.carry(sequence, stage_part, stage_loop, self.part, self.loop)

    def go(self, on_plan, progress, signals) -> dict:
        """The time loop from the set-up to the summary (rank 0's; {} elsewhere); `signals`: the
        run's pyfem.interrupts.StopSignals."""
        from pyfem import checkpoint as checkpoints
        from pyfem.interrupts import RunInterrupted
        from pyfem.output import _write_json, energy_summary, monitor_peaks, peak_memory_mib
        from pyfem.effects import kernel_threads

        comm, root, part, ts = self.comm, self.root, self.part, self.time_step
        stage_file = self._stage_file()
        kernel_threads()
        if on_plan is not None:
            shown = self.measured_plan(fresh=True)
            if root:
                if self.saved is not None:  # the plan's estimates are a whole run's: say what this sitting does
                    words = ("" if "static" not in self.scene else
                             "; the static stage read from static/hand_over.npz, not solved again" if stage_file
                             else "; the static stage solved again (no hand-over file of this model)")
                    shown = {"resuming": f"from the checkpoint at t = {self.saved.t:.6g} s of "
                                         f"{self.scene['time']['duration']:g} s{words}", **shown}
                    if stage_file:  # not solved in this sitting: no estimate of its time
                        shown.pop("static stage estimate", None)
                on_plan(shown)
        try:
            if self.drm is not None and self.input_arrays is None:
                self.input_arrays = self._drm_input()
            stepper, exchange = self._set_up_stage(stage_file)
        except RunInterrupted as error:  # (one rank: under mpirun a stop waits for the first sample)
            raise set_up_lost(error, self.wall_start, "mesh, matrices" + (" and the static stage"
                                                                          if "static" in self.scene else ""))
        from pyfem.distributed_view import Pictures

        self.pictures = Pictures(part, self.points if self.names else None)
        ts = self.time_step  # (global stepping's when local stepping's set-up check sent "auto" back to it)
        n_outputs = self.n_steps // ts.steps_per_output
        origin = run_origin(self.lead_in, ts)  # record time: a record's lead-in at t < 0
        clock = checkpoints.CheckpointClock(self.scene["output"]["checkpoint_interval"],
                                            elapsed=time.perf_counter() - self.wall_start)
        status, started, reason = "failed", False, "ended by another rank's failure"
        loop_start = time.perf_counter()
        output_seconds = 0.0  # the samples' writing, this sitting's (run.json "time_per_step" "output")
        u = v = a = None
        try:
            with signals.deferred():
                u, v, a = self._open(stepper)
                started = True
                if self.saved is None:
                    self.sample(origin, 0, stepper, u, v, a)
            if progress is not None and root:
                progress.start(origin + self.done * ts.steps_per_output * ts.dt)
            while self.done < n_outputs:
                with signals.deferred():  # a stop waits for the sample: the state is whole
                    stepper.run(u, v, a, ts.steps_per_output, origin + self.done * ts.steps_per_output * ts.dt)
                    if self.lts is not None:  # its ghosts' u, v, a (a monitor's cell reads them) from their owners
                        for x in (u, v, a):
                            part.plan.update(comm, x.reshape(-1, 3))
                    self.done += 1
                    t = origin + self.done * ts.steps_per_output * ts.dt
                    if not comm.allreduce(bool(np.isfinite(u[:3 * part.n_owned]).all()), op=MPI.LAND):
                        raise FloatingPointError(f"the solution became non-finite at t = {t:.6g} s")
                    output_start = time.perf_counter()
                    self.sample(t, self.done, stepper, u, v, a)
                    output_seconds += time.perf_counter() - output_start
                    if comm.bcast(clock.due(), root=0) and self.done < n_outputs:
                        began = time.perf_counter()
                        self.write_checkpoint(stepper, u, v, a, t, loop_start)
                        clock.written(time.perf_counter() - began)
                    if comm.size > 1:
                        signals.stop_together(comm)
                if progress is not None and root:
                    progress(t)
            with signals.deferred():  # the final state, kept: a longer time.duration and --resume extend the run
                self.write_checkpoint(stepper, u, v, a, self.times[-1] if root else 0.0, loop_start, final=True)
            status = "finished"
        except KeyboardInterrupt as error:
            status = "interrupted"
            interrupted = error if isinstance(error, RunInterrupted) else RunInterrupted()
            if started:  # the state is that of the last sample (deferred blocks)
                with signals.deferred(reraise=False):
                    self.write_checkpoint(stepper, u, v, a, self.times[-1] if root else 0.0, loop_start)
            interrupted.time_reached = comm.bcast(self.times[-1] if root and self.times else None, root=0)
            interrupted.out_dir = self.out
            reason = f"interrupted by {interrupted.signal_name}"  # (as the whole model's run.json says)
            raise interrupted from error
        except BaseException as error:  # this rank's failure (another rank's ends this one by MPI_Abort)
            reason = f"{type(error).__name__}: {error}"
            if started and root:
                reached = f"t = {self.times[-1]:.6g} s" if self.times else "no sample"
                error.add_note(f"run failed; the results up to {reached} are kept in {self.out}")
            raise
        finally:
            for history in self.histories.values():
                history.close()
            # dolfinx's close is collective: after a failure, which may be this rank's alone, the
            # file is left as it is (run() then ends every rank) rather than every rank waiting
            if self.fields is not None and (status != "failed" or comm.size == 1):
                self.fields.close()
            if root and status != "finished" and self.summary:
                self.summary["status"] = status
                self.summary["time_reached"] = self.times[-1] if self.times else None
                self.summary["reason"] = reason  # (as the whole model's RunWriter.fail)
                if self.names and self.rows_kept:  # the peaks of what was computed
                    self.summary["monitors"] = monitor_peaks(np.array(self.rows_kept), self.columns, self.names,
                                                             np.array(self.times), self.monitor_regions)
                _write_json(self.out / "run.json", self.summary)
        timing = self.timing(loop_start)
        loop_seconds = comm.allreduce(timing["loop_seconds"], op=MPI.MAX)
        loop = self.loop
        cells = (0, 0) if loop is None else (
            sum(len(arrays.cells) for arrays in loop.counted.arrays.values()),
            0 if loop.halo is None else sum(len(arrays.cells) for arrays in loop.halo.arrays.values()))
        per_rank = comm.gather((part.n_owned, part.n_local - part.n_owned, part.extra_ghosts,
                                int(exchange.bytes_sent_per_step), *cells, round(peak_memory_mib(), 1)), root=0)
        # The time per step split into the kernel's phases (this sitting's steps): rank 0's as the whole
        # model's run.json "time_per_step", and every rank's ms per step of each phase.
        phases = comm.gather(dict(stepper.phase_seconds()), root=0)
        sitting = comm.allreduce(timing["loop_seconds"] - self.previous_timing["loop_seconds"], op=MPI.MAX)
        nonlinear = None if loop is None else region_summary(comm, loop.counted)
        if loop is not None and self.pictures is not None:
            self.pictures.end_state(comm, loop.counted)
        bolts = bounds = None
        if part.support:  # every group's bolts on rank 0 (pyfem/distributed_support.py)
            from pyfem.distributed_support import gather_groups

            bolts, bounds = gather_groups(comm, part.support), part.model.bounds
        if not root:
            return {}
        self.summary.update({
            "status": status, "time_reached": self.times[-1], "wall_seconds": timing["wall_seconds"],
            "loop_seconds": loop_seconds, "setup_seconds": part.setup_seconds,
            "seconds_per_step": loop_seconds / max(1, self.n_steps),
            "checkpoints": {"written": clock.count, "seconds": clock.seconds, "interval": clock.interval},
            # (the serial run's key: the process's peak resident memory; here the largest rank's, each in "mpi")
            "peak_memory_mib": max(row[-1] for row in per_rank),
            "energy": energy_summary(np.array(self.energy_rows), self.energy_columns),
            "monitors": (monitor_peaks(np.array(self.rows_kept), self.columns, self.names, np.array(self.times),
                                       self.monitor_regions) if self.names else {}),
            "mpi": {"ranks": comm.size, **{name: [row[k] for row in per_rank] for k, name in enumerate(
                ("owned_nodes", "ghost_nodes", "extra_ghost_nodes", "bytes_sent_per_step", "element_loop_cells",
                 "halo_cells", "peak_memory_mib"))}},
            **({"nonlinear_regions": nonlinear} if nonlinear is not None else {}),
            **({"free_field": self.drm} if self.drm is not None else {}),
        })
        from pyfem.clock import DISTRIBUTED_PHASES, PHASES, phase_split

        from pyfem.output import report_lead_in

        report_lead_in(self.summary, self.scene, self.lead_in, self.times, self.energy_rows, self.energy_columns)
        self.summary["time_per_step"] = phase_split(phases[0], sitting, output_seconds)
        self.summary["mpi"]["ms_per_step"] = {
            name: [round(1e3 * float(p.get(name, 0.0)) / max(1, int(p["steps"])), 4) for p in phases]
            for name in PHASES + DISTRIBUTED_PHASES if any(p.get(name) for p in phases)}
        if self.contact_arrays is not None:
            from pyfem.output import pair_peaks, pair_state_summary

            self.summary["pairs"] = (pair_peaks(np.array(self.pair_rows_kept), self.pair_names, self.pair_monitors.where)
                                     if self.pair_names else {})
            self.summary.update(pair_state_summary(np.array(self.times), np.array(self.state_counts), part.n_pairs,
                                                   self.contact_arrays.get("deterioration")))
            self.summary["mpi"]["moved_pair_nodes"] = part.moved_nodes
        self._history_plots()
        if bolts is not None:
            self._support_outputs(bolts, bounds)
        _write_json(self.out / "run.json", self.summary)
        return self.summary

    def _drm_input(self) -> dict:
        """The domain-reduction method's input forces (pyfem/seismic/drm.py): the auxiliary scene stepped
        at this model's time step, its motion on the DRM layer, the forces on this rank's layer nodes."""
        from pyfem.scene import load_scene
        from pyfem.seismic import drm

        began, comm = time.perf_counter(), self.comm
        if self.lts is not None:
            raise SceneError("time.local_stepping", self.scene["time"].get("local_stepping"),
                             "false with wave.free_field.method = \"drm\" (its forces are tabulated at the global step)")
        drm_layer = drm.layer(self.part)
        try:  # the auxiliary scene's own errors, said as of this key
            aux_scene = load_scene(self.drm["auxiliary"])
            if "wave" not in aux_scene or aux_scene["wave"]["free_field"]["method"] == "drm":
                raise SceneError("wave.free_field.method", "drm", "a scene with a [wave] of method \"half_space\"")
            aux = DistributedRun(aux_scene, self.out / "auxiliary", comm)
        except SceneError as error:
            raise SceneError(drm.KEY, self.drm["auxiliary"], f"a valid auxiliary scene; in it: {error}") from None
        dt = self.time_step.dt
        if dt > aux.time_step.critical:
            raise SceneError(drm.KEY, self.drm["auxiliary"], f"a model stable at the main model's step {dt:.6g} s "
                             f"(its critical step is {aux.time_step.critical:.6g} s)")
        stepper, _ = _stepper(aux.part, dt, aux.input_arrays, aux.loop)
        origin = run_origin(self.lead_in, self.time_step)
        motion = drm.record(aux.part, stepper, drm_layer.coords, dt, self.n_steps, origin)
        arrays = drm.effective_input(self.part, drm_layer, motion, dt, origin)
        self.drm.update({"auxiliary_nodes": aux.part.n_dofs_global // 3, "layer_nodes": len(drm_layer.nodes),
                         "face_nodes": int(drm_layer.on_face.sum()),
                         "auxiliary_seconds": comm.allreduce(time.perf_counter() - began, op=MPI.MAX),
                         "table_bytes": comm.allreduce(drm.table_bytes(arrays)),
                         "motion_bytes": int(motion.nbytes)})
        return arrays

    def _support_outputs(self, groups: list, bounds: tuple) -> None:
        """support.csv, support.xdmf (+ .h5), plots/support.png and run.json's "support" and
        "bolt_monitors" at the end of the run (rank 0; the whole model's RunWriter writes the same)."""
        from types import SimpleNamespace

        from pyfem.support import group_summary, segment_rows, write_csv
        from pyfem.support_output import bolt_state, plot_section, section_y, write_xdmf

        write_csv(self.out / "support.csv", [row for group in groups for row in segment_rows(group.bolts, group.name)],
                  peak=True)
        self.summary["support"] = {group.name: group_summary(group) for group in groups}
        for group in groups:  # local time stepping: the group's bolts per rate level (each its host nodes' finest)
            if group.bolt_levels.min(initial=0) >= 0 and len(group.bolt_levels):
                levels, counts = np.unique(group.bolt_levels, return_counts=True)
                self.summary["support"][group.name]["bolts_per_level"] = {int(k): int(c) for k, c in zip(levels, counts)}
        states = [bolt_state(group) for group in groups]
        end = self.times[-1] if self.times else 0.0
        write_xdmf(self.out / "support.xdmf", states, end)
        y0, where = section_y(self.scene, SimpleNamespace(node_coords=np.array(bounds)))
        drawn = plot_section(self.out / "plots" / "support.png", states, y0, where, f"end of the run, t = {end:.4g} s")
        if drawn:
            self.summary["support_plot"] = drawn
        monitors = {}
        for monitor in self.bolt_monitors:  # their segment and its peak over the samples
            rows = np.loadtxt(self.out / "bolts" / f"{monitor.name}.csv", delimiter=",", skiprows=1, ndmin=2)
            monitors[monitor.name] = dict(monitor.where(groups), peak_axial_force=float(np.max(np.abs(rows[:, 1]),
                                                                                                  initial=0.0)))
        if monitors:
            self.summary["bolt_monitors"] = monitors

    def _history_plots(self) -> None:
        """plots/ (rank 0): the energy account, each monitor's and pair monitor's history and the pair
        states, drawn from the closed history files as a serial run draws them (pyfem/plots.py)."""
        from pyfem import plots
        from pyfem.output import PAIR_STATES

        plot_dir = self.out / "plots"
        plot_dir.mkdir(parents=True, exist_ok=True)
        if self.pictures is not None:
            self.summary.update(self.pictures.plot(plot_dir, self.part.model.regions, self.scene.get("title", "")))
        plots.energy(plot_dir / "energy.png", np.array(self.energy_rows), self.energy_columns)
        for name in self.names:
            plots.monitor(plot_dir / f"monitor_{name}.png", self.out / "monitors" / f"{name}.csv")
        if self.contact_arrays is not None:
            counts = np.array(self.state_counts).reshape(-1, len(PAIR_STATES))
            plots.pair_states(plot_dir / "pair_states.png", np.array(self.times), counts, PAIR_STATES)
            for name in self.pair_names:
                plots.pair_monitor(plot_dir / f"pair_{name}.png", self.out / "pairs" / f"{name}.csv")


@dataclass
class _InputView:
    """What pyfem.seismic.setup.seismic_input_from_scene reads of a model: the rank's owned faces,
    its nodes' coordinates and the whole mesh's bounds."""

    faces: list
    node_coords: np.ndarray
    bounds: tuple


"""`mpirun -n N python3 -m pyfem run SCENE`: the explicit step distributed over MPI ranks.

docs/scaling.md "The distributed step" is the design; this is its first implementation:

- Every rank builds the whole serial model (mesh, matrices: the same bits on every rank) and the
  serial stepper, whose state is the run's state in one place. The static stage's relaxation
  (pyfem/static.py) is stepped by the ranks too, in the same shares (`DistributedStage`); its end
  state is merged into the serial stage stepper on every rank, so every rank hands the same stage
  over (a linear stage's PETSc solves are shared too: pyfem/static.py LinearSolver). The nodes are then
  split among the ranks (recursive coordinate bisection weighted by each node's work, `node_work`:
  the element loop's points and the pairs count; the nodes of pairs that share nodes go to one
  rank together, so every contact pair is whole on one rank).
- Each rank steps its share: its owned nodes numbered first, then its ghosts (the nodes its
  owned rows and its cells touch). Its matrix holds the blocks with an owned index, so K u is
  exact on the owned rows; its cells are those with an owned node (a cell another rank also
  computes is "halo": its forces act, its energy is counted by the rank owning the cell's
  lowest node); dashpots, constraints, input forces and pairs are those of owned nodes.
- After every step one message per neighbour rank carries v and a of the shared nodes
  (cpp_kernels/mpi_exchange.hpp); the next pass A then gives every ghost its owner's u.
- At every output sample the ranks gather on rank 0 what the sample reads (`merge`): u, v, a of
  the sampled nodes, the kernel state without its per-point blocks into the serial stepper, the
  monitors' law values; the whole state (every node and point) where fields, a checkpoint or the
  run's summary read it (`gather_whole`). The writer and checkpoints read the serial stepper as
  in a serial run; a checkpoint is the serial one, and `--resume` slices it again (any rank count).

Not done yet (docs/scaling.md): dolfinx's distributed mesh and assembly (the model is replicated,
so memory does not fall with the ranks), fields written in parallel, overlapping the exchange with
the interior rows.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time

import numpy as np
import scipy.sparse as sp

from pyfem.relaxation import RankSums


def world():
    """The communicator of an `mpirun` launch (one rank: a serial run): mpi4py's COMM_WORLD
    (imported here: `launched_rank` and the command line need no MPI)."""
    from mpi4py import MPI

    return MPI.COMM_WORLD


# Set by the launchers for each rank: Open MPI, PMIx (Open MPI 4+, srun --mpi=pmix), MPICH/Hydra, Slurm.
RANK_VARIABLES = ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID")


def launched_rank() -> int:
    """This process's rank as its launcher says, without initialising MPI (0: not launched as a rank)."""
    for name in RANK_VARIABLES:
        value = os.environ.get(name, "")
        if value.isdigit():
            return int(value)
    return 0


# The work of one node in a step, in units of a matrix row (its ~27 blocks), for weighted
# partitions (`node_work`). Measured on the coarse case 1 and 3 (2026-11-25, 2 threads, from rest,
# `pyfem check`): the element loop 61 ns per quadrature point at rest (a yielding point costs
# several times more), the stiffness product ~1 ns per block (27 per row), contact 156 ns per pair.
POINT_WORK = 2.3   # rows per element-loop quadrature point
PAIR_WORK = 6.0    # rows per contact pair
# A one-point cell (integration = "reduced") costs more than one of a full cell's points: its 8
# nodes' gather and scatter are the cell's, not shared among 8 points. On the coarse case 3 (22 960
# rock cells one point, the 3 360 lining cells full; 2026-11-27) the element loop fell from 33.3 to
# 15.4 ms at rest (1 thread) and from 40.4 to 13.2 ms yielding (2 threads): with the lining's share
# at the full run's cost per point, a one-point cell costs 3.1 and 1.8 points. Counted as:
ONE_POINT_CELL_POINTS = 2.5


def cell_points(nonlinear, name: str) -> float:
    """The work of one element-loop cell of region `name`, in quadrature points (POINT_WORK each)."""
    if nonlinear.integration.get(name, "full") == "reduced":
        return ONE_POINT_CELL_POINTS
    return float(nonlinear.arrays[name].weights.shape[1])


def bisection(points: np.ndarray, parts: int, weights: np.ndarray | None = None) -> np.ndarray:
    """Part (0..parts-1) of every point by recursive coordinate bisection: the longest extent is
    cut where the counts (with `weights`, the summed weights) stay in proportion to the parts on
    each side (parts need not be a power of two). Deterministic: ties in coordinate are broken by
    the point's index."""
    owner = np.zeros(len(points), dtype=np.int32)

    def split(index: np.ndarray, first: int, count: int) -> None:
        if count == 1 or len(index) == 0:
            owner[index] = first
            return
        extent = points[index].max(axis=0) - points[index].min(axis=0)
        axis = int(np.argmax(extent))
        order = index[np.lexsort((index, points[index, axis]))]
        left = count // 2
        if weights is None:
            cut = int(round(len(order) * left / count))
        else:
            # the left part's size whose summed weight is nearest its share (unit weights: the count's cut)
            cumulative = np.concatenate([[0.0], np.cumsum(weights[order])])
            target = cumulative[-1] * left / count
            above = int(np.searchsorted(cumulative, target))
            cut = above if above == 0 or cumulative[above] - target < target - cumulative[above - 1] else above - 1
            if len(order) >= count:  # every part keeps at least one node, however heavy one node is
                cut = min(max(cut, left), len(order) - (count - left))
        split(order[:cut], first, left)
        split(order[cut:], first + left, count - left)

    split(np.arange(len(points)), 0, parts)
    return owner


def pair_groups(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, group) of every node in a pair: pairs sharing a node form one group."""
    nodes = np.unique(pairs)
    local = np.searchsorted(nodes, pairs)
    graph = sp.coo_matrix((np.ones(len(pairs)), (local[:, 0], local[:, 1])), shape=(len(nodes), len(nodes)))
    _, group = sp.csgraph.connected_components(graph, directed=False)
    return nodes, group


@dataclasses.dataclass
class Partition:
    """Who owns what, the same on every rank (computed from the replicated model).

    Attributes:
        size: number of ranks.
        node_owner: (n_nodes,) rank of every node.
        pair_owner: (n_pairs,) rank of every contact pair (that of its nodes), or None.
        cell_owner: region name -> (c,) rank counting each element-loop cell (that of its lowest node).
    """

    size: int
    node_owner: np.ndarray
    pair_owner: np.ndarray | None
    cell_owner: dict

    def owned(self, rank: int) -> np.ndarray:
        return np.flatnonzero(self.node_owner == rank)


def node_work(simulation) -> np.ndarray:
    """(n_nodes,) the work of each node in a step, in matrix rows: 1, plus POINT_WORK per element-loop
    quadrature point of its cells (each cell's points shared among its nodes; a one-point cell counts
    ONE_POINT_CELL_POINTS), plus PAIR_WORK per
    contact pair shared between its two nodes. The element loop, where it is on, is most of a step
    (README benchmark), so a partition by node count leaves the rank with the cavern's zone waiting
    for nothing and the other waiting for it."""
    work = np.ones(len(simulation.mass))
    if simulation.nonlinear is not None:
        for name, arrays in simulation.nonlinear.arrays.items():
            cell_nodes = np.asarray(arrays.cell_nodes)
            share = POINT_WORK * cell_points(simulation.nonlinear, name) / cell_nodes.shape[1]
            np.add.at(work, cell_nodes.ravel(), share)
    if simulation.contact_arrays is not None and len(simulation.contact_arrays["pairs"]):
        np.add.at(work, np.asarray(simulation.contact_arrays["pairs"]).ravel(), 0.5 * PAIR_WORK)
    levels = getattr(simulation, "node_levels", None)
    if levels is not None:  # local time stepping: a node at level k steps 2^(L - k) times per global step
        work = work * 2.0 ** (int(levels.max()) - np.asarray(levels, dtype=float))
    return work


def partition(simulation, size: int, weighted: bool = True) -> Partition:
    """Splits the nodes of the simulation's model among `size` ranks (docstring of the module); with
    `weighted`, in proportion to their work (`node_work`), else to their count."""
    coordinates = simulation.model.node_coords
    owner = bisection(coordinates, size, node_work(simulation) if weighted else None)
    pair_owner = None
    if simulation.contact_arrays is not None and len(simulation.contact_arrays["pairs"]):
        pairs = simulation.contact_arrays["pairs"]
        nodes, group = pair_groups(pairs)
        # A group goes to the owner of its lowest node.
        first = np.full(group.max() + 1, len(owner), dtype=np.int64)
        np.minimum.at(first, group, nodes)
        owner[nodes] = owner[first[group]]
        pair_owner = owner[pairs[:, 0]]
    cell_owner = {}
    if simulation.nonlinear is not None:
        for name, arrays in simulation.nonlinear.arrays.items():
            cell_owner[name] = owner[arrays.cell_nodes.min(axis=1)]
    return Partition(size=size, node_owner=owner, pair_owner=pair_owner, cell_owner=cell_owner)


@dataclasses.dataclass
class Share:
    """One rank's share: the owned-first local numbering and what it computes.

    Attributes:
        nodes: (n_local,) global node of every local node, owned first (ascending), then ghosts (ascending).
        n_owned: owned nodes.
        local_of: (n_nodes,) local number of every global node, -1 when not on this rank.
        cells: per region, [(kind, indices into the region's cells)] with kind "counted" (cells this
            rank owns) or "halo" (cells of other ranks touching an owned node); empty ones left out.
        pairs: indices of this rank's contact pairs (None without contact).
        constraints: indices of this rank's constraints in the serial list (None without).
        dashpots: indices of this rank's dashpot entries in the serial list.
    """

    nodes: np.ndarray
    n_owned: int
    local_of: np.ndarray
    cells: dict
    pairs: np.ndarray | None
    constraints: np.ndarray | None
    dashpots: np.ndarray


def _ranges(starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The concatenated index ranges starts[k] .. ends[k]-1 (CSR rows gathered)."""
    counts = ends - starts
    return np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())


def _block_neighbours(stiffness: sp.bsr_matrix, rows: np.ndarray) -> np.ndarray:
    """Block columns of the given block rows."""
    return np.unique(stiffness.indices[_ranges(stiffness.indptr[rows], stiffness.indptr[rows + 1])])


def share(simulation, parts: Partition, rank: int) -> Share:
    """Rank `rank`'s share of the simulation (`Share`)."""
    n_nodes = len(parts.node_owner)
    is_owned = parts.node_owner == rank
    owned = np.flatnonzero(is_owned)
    needed = [_block_neighbours(simulation.stiffness, owned)]
    cells = {}
    if simulation.nonlinear is not None:
        for name, arrays in simulation.nonlinear.arrays.items():
            touches = is_owned[arrays.cell_nodes].any(axis=1)
            counted = parts.cell_owner[name] == rank
            halo = touches & ~counted
            cells[name] = [(kind, np.flatnonzero(mask)) for kind, mask in (("counted", counted), ("halo", halo))
                           if mask.any()]
            needed.append(arrays.cell_nodes[touches].reshape(-1))
    ghosts = np.setdiff1d(np.concatenate(needed), owned)
    nodes = np.concatenate([owned, ghosts]).astype(np.int64)
    local_of = np.full(n_nodes, -1, dtype=np.int64)
    local_of[nodes] = np.arange(len(nodes))
    pairs = None if parts.pair_owner is None else np.flatnonzero(parts.pair_owner == rank)
    constraints = None
    if simulation.constraints is not None:
        constraints = np.flatnonzero(is_owned[simulation.constraints.nodes])
    dashpots = np.flatnonzero(is_owned[simulation.dashpot_nodes]) if len(simulation.dashpot_nodes) else \
        np.zeros(0, dtype=np.int64)
    return Share(nodes=nodes, n_owned=len(owned), local_of=local_of, cells=cells, pairs=pairs,
                 constraints=constraints, dashpots=dashpots)


def rank_work(simulation, parts: Partition) -> np.ndarray:
    """(size,) each rank's work in a step by the model of `node_work` (matrix rows), counted as the
    ranks do it: its owned rows, every element-loop cell with an owned node (counted and halo: a
    cell on a rank boundary is computed by each rank it touches) and its pairs."""
    work = np.zeros(parts.size)
    for rank in range(parts.size):
        mine = share(simulation, parts, rank)
        work[rank] = mine.n_owned
        if simulation.nonlinear is not None:
            for name in simulation.nonlinear.arrays:
                cells = sum(len(indices) for _, indices in mine.cells.get(name, []))
                work[rank] += POINT_WORK * cells * cell_points(simulation.nonlinear, name)
        if mine.pairs is not None:
            work[rank] += PAIR_WORK * len(mine.pairs)
    return work


def local_matrix(stiffness: sp.bsr_matrix, mine: Share) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(indptr, indices, blocks) of the rank's matrix in local numbering: every block (i, j) of
    local nodes with i or j owned, and the ghosts' diagonal blocks. Symmetric as the serial one."""
    n_rows = stiffness.shape[0] // 3
    rows = np.repeat(np.arange(n_rows), np.diff(stiffness.indptr))
    cols = stiffness.indices
    li, lj = mine.local_of[rows], mine.local_of[cols]
    keep = (li >= 0) & (lj >= 0) & ((li < mine.n_owned) | (lj < mine.n_owned) | (li == lj))
    li, lj, blocks = li[keep], lj[keep], stiffness.data[keep]
    order = np.lexsort((lj, li))
    li, lj, blocks = li[order], lj[order], blocks[order]
    indptr = np.zeros(len(mine.nodes) + 1, dtype=np.int64)
    np.cumsum(np.bincount(li, minlength=len(mine.nodes)), out=indptr[1:])
    return (indptr, np.ascontiguousarray(lj, dtype=np.int32),
            np.ascontiguousarray(blocks, dtype=np.float64))


def _exchange(comm: MPI.Comm, parts: Partition, mine: Share):
    """The kernel's MpiNodeExchange: each rank tells the owners which of their nodes it ghosts."""
    return _ghost_exchanges(comm, parts, mine, [np.ones(len(mine.nodes) - mine.n_owned, dtype=bool)])[0]


def _ghost_exchanges(comm: MPI.Comm, parts: Partition, mine: Share, groups: list) -> list:
    """One kernel MpiNodeExchange per group of the share's ghosts (a boolean mask over
    mine.nodes[n_owned:]): each rank tells the owners which of their nodes it ghosts in each group.
    Every rank makes every group's exchange (a collective: the communicator's copy)."""
    from pyfem import _kernels

    ghosts = mine.nodes[mine.n_owned:]
    owners = parts.node_owner[ghosts]
    requests = [[ghosts[(owners == q) & group] for group in groups] for q in range(comm.size)]  # sorted
    asked = comm.alltoall(requests)
    exchanges = []
    for k in range(len(groups)):
        neighbours = [q for q in range(comm.size) if q != comm.rank and (len(requests[q][k]) or len(asked[q][k]))]
        send = [mine.local_of[asked[q][k]].astype(np.int32) for q in neighbours]
        recv = [mine.local_of[requests[q][k]].astype(np.int32) for q in neighbours]
        exchanges.append(_kernels.MpiNodeExchange(comm.py2f(), neighbours, send, recv, len(mine.nodes)))
    return exchanges


def _owned_input_arrays(arrays: dict, mine: Share) -> dict:
    """`Simulation.input_arrays` of the share's owned input nodes, in local numbering."""
    nodes = arrays["nodes"].astype(np.int64)
    local = mine.local_of[nodes]
    keep = np.flatnonzero((local >= 0) & (local < mine.n_owned))
    starts, ends = arrays["node_ptr"][keep], arrays["node_ptr"][keep + 1]
    entries = _ranges(starts, ends)
    node_ptr = np.zeros(len(keep) + 1, dtype=np.int64)
    np.cumsum(ends - starts, out=node_ptr[1:])
    return dict(arrays, node_ptr=node_ptr, nodes=local[keep].astype(np.int32),
                **{key: np.ascontiguousarray(arrays[key][entries]) for key in ("table", "tau", "P", "Q")})


def _local_contact(arrays: dict, mine: Share, pairs: np.ndarray | None = None):
    """The kernel's ContactPairs of the share's pairs (or of `pairs`, model pair indices it owns), in
    local numbering."""
    from pyfem.solver import make_contact_pairs

    pairs = mine.pairs if pairs is None else pairs
    local = dict(arrays)
    local["pairs"] = np.ascontiguousarray(mine.local_of[arrays["pairs"][pairs]], dtype=np.int32)
    for key in ("area", "normal", "static_force"):
        local[key] = np.ascontiguousarray(np.asarray(arrays[key])[pairs])
    return make_contact_pairs(local)


def _add_dashpots(stepper, simulation, mine: Share) -> None:
    if len(mine.dashpots):
        stepper.set_dashpots(np.ascontiguousarray(mine.local_of[simulation.dashpot_nodes[mine.dashpots]],
                                                  dtype=np.int32),
                             np.ascontiguousarray(simulation.dashpot_matrices[mine.dashpots]))


def _add_constraints(stepper, constraints, mine: Share) -> None:
    """The share's constraints (`mine.constraints`, indices into `constraints`) in local numbering."""
    if constraints is not None:
        stepper.set_constraints(np.ascontiguousarray(mine.local_of[constraints.nodes[mine.constraints]], dtype=np.int32),
                                np.ascontiguousarray(constraints.projection[mine.constraints]))


def _add_components(stepper, nonlinear, regions: list, mine: Share) -> tuple[list, list]:
    """Element-loop components of the share's cells of `regions` (counted and halo), added to the
    stepper in region order. Fresh (no initial stress): the state comes with slice_state.

    Returns:
        (components, objects) as `local_stepper` returns them.
    """
    components, objects = [], []
    for name in regions:
        for kind, cells in mine.cells[name]:
            component = nonlinear.new_component(name, initial_stress=None, rows=cells, node_numbers=mine.local_of)
            stepper.add_internal_force(component, count_energy=kind == "counted")
            components.append((name, kind, cells))
            objects.append(component)
    return components, objects


def local_stepper(simulation, mine: Share, exchange):
    """The kernel's Stepper of one rank's share: `pyfem.solver.make_stepper`'s objects restricted to
    the share (an effect added there must be added here too; tests/test_mpi.py runs each).

    Returns:
        (stepper, components, objects): components (region, "counted" or "halo", indices into the
        region's cells) and the element-loop component object of each, in the stepper's order.
    """
    from pyfem import _kernels
    from pyfem.solver import seismic_input_kernel

    indptr, indices, blocks = local_matrix(simulation.stiffness, mine)
    mass = np.ascontiguousarray(simulation.mass[mine.nodes])
    single = simulation.scene["time"].get("matrix_precision", "double") == "single"
    stepper = _kernels.Stepper(indptr, indices, blocks, mass, simulation.time_step.dt, simulation.alpha,
                               simulation.beta, True, single)
    _add_dashpots(stepper, simulation, mine)
    _add_constraints(stepper, simulation.constraints, mine)
    if simulation.input_arrays is not None:
        stepper.add_seismic_input(seismic_input_kernel(_owned_input_arrays(simulation.input_arrays, mine)))
    contact = None
    if simulation.contact_arrays is not None:
        contact = _local_contact(simulation.contact_arrays, mine)
        stepper.add_contact(contact)
    components, objects = [], []
    if simulation.nonlinear is not None:
        components, objects = _add_components(stepper, simulation.nonlinear, list(simulation.nonlinear.arrays), mine)
    if simulation.static is not None:  # the stage's out-of-balance on the owned nodes (pyfem/static.py)
        from pyfem.static import add_hand_over_force

        add_hand_over_force(stepper, simulation, nodes=mine.nodes[:mine.n_owned], local_of=mine.local_of,
                            n_local=len(mine.nodes))
    stepper.set_partition(mine.n_owned, exchange)
    return stepper, components, objects


# --- The serial stepper's state (save_state blocks) cut into shares and put together again ---

def _dof_rows(nodes: np.ndarray) -> np.ndarray:
    """The dofs 3 i, 3 i + 1, 3 i + 2 of the given nodes, in order."""
    return (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).reshape(-1)


def state_rows(block: bytes, count: int) -> np.ndarray:
    """A block of `count` equal rows as a (count, row bytes) uint8 array."""
    data = np.frombuffer(block, dtype=np.uint8)
    if count == 0:
        return data.reshape(0, 0) if data.size == 0 else data.reshape(0, -1)
    if data.size % count:
        raise ValueError(f"a state block of {data.size} bytes is not {count} equal rows")
    return data.reshape(count, -1)


CONTACT_PAIR_BLOCKS = ("state", "bond_intact", "normal_force", "tangential_force", "contact_force",
                        "deterioration", "slip_rate", "gap_offset", "static_force", "effective_normal")


def pair_blocks(state: dict, prefix: str = "") -> list[str]:
    """The per-pair blocks of CONTACT_PAIR_BLOCKS that a ContactPairs state holds (effective_normal
    only with the normal lag on)."""
    return [name for name in CONTACT_PAIR_BLOCKS if prefix + name in state]


def unique_slots(pair_nodes: np.ndarray, selected: np.ndarray) -> np.ndarray:
    """Rows of the serial pairs' unique nodes that the selected pairs use (ascending)."""
    unique = np.unique(pair_nodes)
    return np.searchsorted(unique, np.unique(pair_nodes[selected]))


def _region_points(nonlinear, name: str) -> int:
    return int(nonlinear.arrays[name].weights.shape[1])


def slice_state(serial: dict, template: dict, simulation, parts: Partition, mine: Share, rank: int,
                components: list) -> dict:
    """The serial stepper's state blocks as rank `rank`'s stepper needs them. `template`: that
    stepper's own save_state() (names, sizes, its parameters). Scalars of the energy account and
    of the components go to rank 0 (and to the first rank counting a region's cells): the
    account is a sum over ranks."""
    out = dict(template)
    out["stepper/energy_started"] = serial["stepper/energy_started"]
    for key in ("stepper/energy", "stepper/provider_work", "stepper/provider_power"):
        out[key] = serial[key] if rank == 0 else np.zeros_like(np.frombuffer(serial[key], dtype=np.float64)).tobytes()
    force = np.frombuffer(serial["stepper/internal_force"], dtype=np.float64).reshape(-1, 3)
    if len(template["stepper/internal_force"]):  # a rank without element-loop cells has none
        out["stepper/internal_force"] = np.ascontiguousarray(force[mine.nodes]).tobytes()
    if mine.constraints is not None:
        out["stepper/reactions"] = np.ascontiguousarray(
            np.frombuffer(serial["stepper/reactions"], dtype=np.float64).reshape(-1, 3)[mine.constraints]).tobytes()
    if mine.pairs is not None:
        pair_nodes = simulation.contact_arrays["pairs"]
        n_pairs = len(pair_nodes)
        for name in pair_blocks(serial, "contact/"):
            out["contact/" + name] = np.ascontiguousarray(state_rows(serial["contact/" + name], n_pairs)[mine.pairs]).tobytes()
        slots = unique_slots(pair_nodes, mine.pairs)
        node_force = np.frombuffer(serial["contact/node_force"], dtype=np.float64).reshape(-1, 3)
        out["contact/node_force"] = np.ascontiguousarray(node_force[slots]).tobytes()
    regions = list(simulation.nonlinear.arrays) if simulation.nonlinear is not None else []
    for j, (name, kind, cells) in enumerate(components):
        k = regions.index(name)
        src, dst = f"component/{k}/", f"component/{j}/"
        n_cells = len(simulation.nonlinear.arrays[name].cells)
        out[dst + "state"] = np.ascontiguousarray(state_rows(serial[src + "state"], n_cells)[cells]).tobytes()
        sigma0 = serial[src + "initial_stress"]
        out[dst + "initial_stress"] = (np.ascontiguousarray(state_rows(sigma0, n_cells)[cells]).tobytes()
                                       if len(sigma0) else b"")
        first = kind == "counted" and rank == int(parts.cell_owner[name].min())
        for scalar in ("stored_energy", "dissipation"):
            out[dst + scalar] = serial[src + scalar] if first else np.zeros(1).tobytes()
    return out


def merge_states(serial_template: dict, states: list, simulation, parts: Partition, shares: list,
                 components: list, points: bool = True) -> dict:
    """The serial stepper's state blocks from every rank's (`states`, `shares`, `components`
    per rank): owned rows from their owner, counted cells from theirs, sums of the scalars.
    points False: `states` are save_state(points=False) (no per-point or per-node blocks), and so
    is what this returns for the serial stepper's load_state(..., points=False)."""
    out = dict(serial_template)
    out["stepper/energy_started"] = states[0]["stepper/energy_started"]
    for key in ("stepper/energy", "stepper/provider_work", "stepper/provider_power"):
        out[key] = np.sum([np.frombuffer(s[key], dtype=np.float64) for s in states], axis=0).tobytes()
    force = np.frombuffer(serial_template["stepper/internal_force"], dtype=np.float64).reshape(-1, 3)
    if force.size and points:
        force = force.copy()
        for s, mine in zip(states, shares):
            rows = mine.nodes[:mine.n_owned]
            if len(s["stepper/internal_force"]):
                force[rows] = np.frombuffer(s["stepper/internal_force"], dtype=np.float64).reshape(-1, 3)[:mine.n_owned]
            else:  # no element-loop cell touches this rank's nodes
                force[rows] = 0.0
        out["stepper/internal_force"] = force.tobytes()
    if shares[0].constraints is not None:
        reactions = np.frombuffer(serial_template["stepper/reactions"], dtype=np.float64).reshape(-1, 3).copy()
        for s, mine in zip(states, shares):
            reactions[mine.constraints] = np.frombuffer(s["stepper/reactions"], dtype=np.float64).reshape(-1, 3)
        out["stepper/reactions"] = reactions.tobytes()
    if shares[0].pairs is not None:
        pair_nodes = simulation.contact_arrays["pairs"]
        n_pairs = len(pair_nodes)
        for name in pair_blocks(serial_template, "contact/"):
            rows = state_rows(serial_template["contact/" + name], n_pairs).copy()
            for s, mine in zip(states, shares):
                if len(mine.pairs):
                    rows[mine.pairs] = state_rows(s["contact/" + name], len(mine.pairs))
            out["contact/" + name] = rows.tobytes()
        node_force = np.frombuffer(serial_template["contact/node_force"], dtype=np.float64).reshape(-1, 3).copy()
        for s, mine in zip(states, shares):
            if not len(mine.pairs):
                continue
            node_force[unique_slots(pair_nodes, mine.pairs)] = np.frombuffer(
                s["contact/node_force"], dtype=np.float64).reshape(-1, 3)
        out["contact/node_force"] = node_force.tobytes()
    regions = list(simulation.nonlinear.arrays) if simulation.nonlinear is not None else []
    for k, name in enumerate(regions):
        counted = [(s, f"component/{j}/", cells) for s, rank_components in zip(states, components)
                   for j, (region, kind, cells) in enumerate(rank_components)
                   if region == name and kind == "counted"]
        out.update(merge_component_rows(serial_template, f"component/{k}/",
                                        len(simulation.nonlinear.arrays[name].cells), counted, points))
    if not points:  # the template's per-point blocks: not read, so not copied into the kernel
        per_point = {"stepper/internal_force"} | {f"component/{k}/{block}" for k in range(len(regions))
                                                  for block in ("points", "state", "initial_stress")}
        out = {key: value for key, value in out.items() if key not in per_point}
    return out


def merge_component_rows(template: dict, src: str, n_cells: int, counted: list, points: bool) -> dict:
    """One nonlinear component of the serial state from the ranks' counted parts of it.

    Args:
        template: the serial state the merge fills (its rows of cells no rank counts stay).
        src: the component's prefix in the serial state ("component/k/" or a level's).
        n_cells: the serial component's cells.
        counted: (a rank's state, its part's prefix, the part's rows in the serial component) for
            every part that counts its cells (halo parts hold copies, not the state).
        points: whether the per-point state (and initial stress) is merged, or the scalars only.

    Returns:
        The component's blocks: per-point state and initial stress rows (with `points`) and the
        stored energy and dissipation summed over the parts.
    """
    out = {}
    if points:
        state = state_rows(template[src + "state"], n_cells).copy()
        sigma0 = template[src + "initial_stress"]
        sigma0_rows = state_rows(sigma0, n_cells).copy() if len(sigma0) else None
    totals = {"stored_energy": 0.0, "dissipation": 0.0}
    for s, prefix, at in counted:
        if points:
            state[at] = state_rows(s[prefix + "state"], len(at))
            if sigma0_rows is not None:
                sigma0_rows[at] = state_rows(s[prefix + "initial_stress"], len(at))
        for scalar in totals:
            totals[scalar] += float(np.frombuffer(s[prefix + scalar], dtype=np.float64)[0])
    if points:
        out[src + "state"] = state.tobytes()
        out[src + "initial_stress"] = sigma0_rows.tobytes() if sigma0_rows is not None else b""
    for scalar, value in totals.items():
        out[src + scalar] = np.array([value]).tobytes()
    return out


# --- Local time stepping on the ranks (the row split, LocalStepper.set_partition) ---

def level_exchanges(comm: MPI.Comm, parts: Partition, mine: Share, levels: np.ndarray) -> list:
    """One kernel MpiNodeExchange per rate level k: the velocity of the share's level-k ghosts from
    their owners, before each of the level's drifts (LocalStepper.set_partition)."""
    ghost_levels = np.asarray(levels)[mine.nodes[mine.n_owned:]]
    return _ghost_exchanges(comm, parts, mine, [ghost_levels == k for k in range(int(np.max(levels)) + 1)])


def level_bytes_per_fine_step(nodes_per_level: list) -> float:
    """Bytes of the velocity exchanges per fine step, averaged over a global step, for the given
    count of shared nodes at each level k (24 bytes each, at each of the level's 2^(L - k) drifts)."""
    top = len(nodes_per_level) - 1
    return 24.0 * sum(count * 2 ** (top - k) for k, count in enumerate(nodes_per_level)) / 2 ** top


@dataclasses.dataclass
class LevelLayout:
    """Where the parts of a LocalStepper's state sit in its save_state archive, for the serial
    stepper (`serial_layout`) or one rank's share (`local_lts_stepper`).

    Attributes:
        max_level: L, the model's largest level.
        level_nodes: per level k, the model nodes of the stepper's level-k rows, in row order.
        components: [(region, kind, region cell rows, level, archive prefix)] of its element-loop
            components (kind "counted" or "halo" on a rank, "whole" in the serial stepper).
        pairs: [(model pair indices, level, archive prefix)] of its ContactPairs.
    """

    max_level: int
    level_nodes: list
    components: list
    pairs: list


def _level_prefix(max_level: int, level: int, what: str, k: int) -> str:
    return f"lts/level/{max_level - int(level)}/{what}/{k}/"


def _region_levels(simulation) -> dict:
    """Region -> the rate level of each of its cells, as the serial stepper splits it (row split)."""
    from pyfem import local_stepping

    model = simulation.model
    cell_nodes = model.V.dofmap.list.array.reshape(model.n_cells, -1)
    cap = local_stepping.row_cell_cap(simulation.node_levels, cell_nodes)
    return {name: local_stepping.region_cell_levels(arrays, simulation.node_levels, cap)
            for name, arrays in simulation.nonlinear.arrays.items()}


def _pair_levels(simulation) -> np.ndarray | None:
    arrays = simulation.contact_arrays
    if arrays is None or not len(arrays["pairs"]):
        return None
    return np.asarray(simulation.node_levels)[np.asarray(arrays["pairs"])[:, 0]]


def serial_layout(simulation) -> LevelLayout:
    """The serial LocalStepper's layout (pyfem.solver._make_local_stepper: per region its cells split
    by level, in region order at each level; one ContactPairs per level)."""
    levels = np.asarray(simulation.node_levels)
    max_level = int(levels.max())
    components, count = [], {}
    if simulation.nonlinear is not None:
        for name, cell_level in _region_levels(simulation).items():
            for level in np.unique(cell_level):
                k = count.get(int(level), 0)
                count[int(level)] = k + 1
                components.append((name, "whole", np.flatnonzero(cell_level == level), int(level),
                                   _level_prefix(max_level, level, "component", k)))
    pairs = []
    pair_level = _pair_levels(simulation)
    if pair_level is not None:
        for level in np.unique(pair_level):
            pairs.append((np.flatnonzero(pair_level == level), int(level), _level_prefix(max_level, level, "contact", 0)))
    return LevelLayout(max_level, [np.flatnonzero(levels == k) for k in range(max_level + 1)], components, pairs)


def local_lts_stepper(simulation, mine: Share, exchanges: list, bare: bool = False):
    """The kernel's LocalStepper of one rank's share (row split, `LocalStepper.set_partition`):
    `pyfem.solver._make_local_stepper`'s objects restricted to the share, each region's counted and
    halo cells split by level as the serial stepper splits the region, the owned pairs by level.
    With `bare`, the map the stability check iterates (`check_stability_on_ranks`): no mass-
    proportional damping, no pairs, no input or hand-over forces (the serial check's bare kernel).

    Returns:
        (LocalSteppingAdapter, LevelLayout, component objects, pair objects), the objects in the
        layout's order.
    """
    from pyfem import _kernels
    from pyfem.local_stepping import LocalSteppingAdapter
    from pyfem.solver import seismic_input_kernel

    levels = np.asarray(simulation.node_levels, dtype=np.int32)
    max_level = int(levels.max())
    local_levels = np.ascontiguousarray(levels[mine.nodes])
    indptr, indices, blocks = local_matrix(simulation.stiffness, mine)
    kernel = _kernels.LocalStepper(indptr, indices, blocks, np.ascontiguousarray(simulation.mass[mine.nodes]),
                                   local_levels, simulation.time_step.dt, 0.0 if bare else simulation.alpha,
                                   max_level)
    kernel.set_row_split(True)
    _add_dashpots(kernel, simulation, mine)
    _add_constraints(kernel, simulation.constraints, mine)
    components, objects, count = [], [], {}
    if simulation.nonlinear is not None:
        for name, cell_level in _region_levels(simulation).items():
            for kind, cells in mine.cells.get(name, []):
                for level in np.unique(cell_level[cells]):
                    rows = cells[cell_level[cells] == level]
                    component = simulation.nonlinear.new_component(name, initial_stress=None, rows=rows,
                                                                   node_numbers=mine.local_of)
                    kernel.add_internal_force(component, int(level), kind == "counted")
                    k = count.get(int(level), 0)
                    count[int(level)] = k + 1
                    components.append((name, kind, rows, int(level), _level_prefix(max_level, level, "component", k)))
                    objects.append(component)
    pairs, pair_objects = [], []
    pair_level = _pair_levels(simulation)
    if pair_level is not None and len(mine.pairs) and not bare:
        for level in np.unique(pair_level[mine.pairs]):
            selected = mine.pairs[pair_level[mine.pairs] == level]
            contact = _local_contact(simulation.contact_arrays, mine, selected)
            kernel.add_contact(contact, int(level))
            pairs.append((selected, int(level), _level_prefix(max_level, level, "contact", 0)))
            pair_objects.append(contact)
    stepper = LocalSteppingAdapter(kernel, 2 ** max_level)
    if simulation.input_arrays is not None and not bare:
        owned_input = _owned_input_arrays(simulation.input_arrays, mine)
        if len(owned_input["nodes"]):  # (the kernel takes no provider without nodes)
            kernel.add_seismic_input(seismic_input_kernel(owned_input))
    hand_over = getattr(simulation.static, "hand_over_force", None)
    if hand_over is not None and not bare:  # the stage's out-of-balance on the owned nodes (pyfem/static.py)
        from pyfem.static import hand_over_force_provider, local_force

        force = local_force(hand_over, mine.nodes[:mine.n_owned], mine.local_of, len(mine.nodes))
        if np.any(force):  # (the kernel takes no provider without nodes)
            kernel.add_provider(hand_over_force_provider(force))
    kernel.set_partition(mine.n_owned, exchanges)
    layout = LevelLayout(max_level, [mine.nodes[np.flatnonzero(local_levels == k)] for k in range(max_level + 1)],
                         components, pairs)
    return stepper, layout, objects, pair_objects


class RankSummed:
    """A share's kernel LocalStepper (run() in global steps, a collective) whose energy() is the whole
    model's: summed over the ranks, each counting its owned rows and counted cells."""

    def __init__(self, kernel, comm: MPI.Comm) -> None:
        self.kernel, self.comm = kernel, comm

    def run(self, u, v, a, n_steps: int, t0: float) -> float:
        return self.kernel.run(u, v, a, n_steps, t0)

    def energy(self) -> dict:
        energy = self.kernel.energy()
        keys = ("kinetic", "strain", "internal_stored")
        total = self.comm.allreduce(np.array([energy[key] for key in keys]))
        return dict(zip(keys, total))


def check_stability_on_ranks(simulation, comm: MPI.Comm, **check) -> dict:
    """local_stepping.check_stability of the model's LTS map stepped by the ranks' shares (row
    split, the partition the run steps in): the same random state on every rank, each stepping its
    owned rows, the energy summed over the ranks; every rank gets the same report, with "ranks".
    Each rank holds and steps its share only, where the serial check stepped the whole model on
    every rank (docs/scaling.md "Local time stepping on the ranks"). Its "seconds" include the
    partition, the share and its exchanges (the slowest rank's)."""
    from mpi4py import MPI

    from pyfem.local_stepping import check_stability

    began = time.perf_counter()
    parts = partition(simulation, comm.size)
    mine = share(simulation, parts, comm.rank)
    exchanges = level_exchanges(comm, parts, mine, simulation.node_levels)

    def make_kernel():
        stepper, *_ = local_lts_stepper(simulation, mine, exchanges, bare=True)
        return RankSummed(stepper.kernel, comm)

    with _alone():  # a kernel error on one rank's share ends every rank (rank 0 may be in its plan)
        report = check_stability(make_kernel, 3 * len(simulation.mass), rows=_dof_rows(mine.nodes), **check)
    seconds = comm.allreduce(time.perf_counter() - began, op=MPI.MAX)
    return dict(comm.bcast(report, root=0), seconds=seconds, ranks=comm.size)  # rank 0's verdict for all


def _started(state: dict) -> bool:
    return bool(np.frombuffer(state["lts/started"], dtype=np.uint8)[0])


def _float_rows(block: bytes) -> np.ndarray:
    return np.frombuffer(block, dtype=np.float64).reshape(-1, 3)


def _component_scalar_rank(parts: Partition, name: str, serial_rows: np.ndarray) -> int:
    """The rank whose counted component of a serial part (region cells `serial_rows`) carries the
    part's stored energy and dissipation when a state is cut into shares: the lowest counting one."""
    return int(parts.cell_owner[name][serial_rows].min())


def slice_lts_state(source: dict, template: dict, serial: LevelLayout, mine_layout: LevelLayout, simulation,
                    parts: Partition, mine: Share, rank: int) -> dict:
    """The serial LocalStepper's state blocks (`source`: its save_state, with its components' and
    pairs' blocks under their prefixes even when it has not started) as rank `rank`'s stepper needs
    them; `template`: that stepper's own save_state (a started one: every name and size). The energy
    account's scalars go to rank 0, a component part's to the lowest rank counting its cells."""
    out = dict(template)
    out["lts/started"] = source["lts/started"]
    if _started(source):
        for key in ("lts/energy", "lts/dissipation_at_start"):
            out[key] = source[key] if rank == 0 else np.zeros_like(np.frombuffer(source[key], dtype=np.float64)).tobytes()
        if mine.constraints is not None:
            out["lts/reactions"] = np.ascontiguousarray(_float_rows(source["lts/reactions"])[mine.constraints]).tobytes()
        for k in range(serial.max_level + 1):
            prefix = f"lts/level/{serial.max_level - k}/"
            rows = np.searchsorted(serial.level_nodes[k], mine_layout.level_nodes[k])
            for block in ("force", "external"):
                out[prefix + block] = np.ascontiguousarray(_float_rows(source[prefix + block])[rows]).tobytes()
    by_part = {(name, level): (rows, prefix) for name, _, rows, level, prefix in serial.components}
    for name, kind, rows, level, prefix in mine_layout.components:
        serial_rows, src = by_part[(name, level)]
        at = np.searchsorted(serial_rows, rows)
        n_cells = len(serial_rows)
        out[prefix + "state"] = np.ascontiguousarray(state_rows(source[src + "state"], n_cells)[at]).tobytes()
        sigma0 = source[src + "initial_stress"]
        out[prefix + "initial_stress"] = (np.ascontiguousarray(state_rows(sigma0, n_cells)[at]).tobytes()
                                          if len(sigma0) else b"")
        first = kind == "counted" and rank == _component_scalar_rank(parts, name, serial_rows)
        for scalar in ("stored_energy", "dissipation"):
            out[prefix + scalar] = source[src + scalar] if first else np.zeros(1).tobytes()
    pair_nodes = None if simulation.contact_arrays is None else np.asarray(simulation.contact_arrays["pairs"])
    by_level = {level: (rows, prefix) for rows, level, prefix in serial.pairs}
    for selected, level, prefix in mine_layout.pairs:
        serial_rows, src = by_level[level]
        at = np.searchsorted(serial_rows, selected)
        for name in pair_blocks(source, src):
            out[prefix + name] = np.ascontiguousarray(state_rows(source[src + name], len(serial_rows))[at]).tobytes()
        slots = unique_slots(pair_nodes[serial_rows], at)
        out[prefix + "node_force"] = np.ascontiguousarray(_float_rows(source[src + "node_force"])[slots]).tobytes()
    return out


def merge_lts_states(template: dict, states: list, serial: LevelLayout, layouts: list, simulation,
                     parts: Partition, shares: list, points: bool = True) -> dict:
    """The serial LocalStepper's state blocks from every rank's (`states`, `layouts`, `shares` per
    rank): owned rows from their owner, counted cells from theirs, sums of the scalars. `template`:
    the serial stepper's started save_state(points). points False: the ranks' save_state(points=False)
    into a state for the serial stepper's load_state(..., points=False)."""
    out = dict(template)
    out["lts/started"] = states[0]["lts/started"]
    if not _started(states[0]):
        return out
    for key in ("lts/energy", "lts/dissipation_at_start"):
        out[key] = np.sum([np.frombuffer(s[key], dtype=np.float64) for s in states], axis=0).tobytes()
    if shares[0].constraints is not None:
        reactions = _float_rows(template["lts/reactions"]).copy()
        for s, mine in zip(states, shares):
            reactions[mine.constraints] = _float_rows(s["lts/reactions"])
        out["lts/reactions"] = reactions.tobytes()
    if points:
        for k in range(serial.max_level + 1):
            prefix = f"lts/level/{serial.max_level - k}/"
            for block in ("force", "external"):
                rows = _float_rows(template[prefix + block]).copy()
                for rank, (s, layout) in enumerate(zip(states, layouts)):
                    nodes = layout.level_nodes[k]
                    owned = parts.node_owner[nodes] == rank
                    rows[np.searchsorted(serial.level_nodes[k], nodes[owned])] = _float_rows(s[prefix + block])[owned]
                out[prefix + block] = rows.tobytes()
    for name, _, serial_rows, level, src in serial.components:
        counted = [(s, prefix, np.searchsorted(serial_rows, rows)) for s, layout in zip(states, layouts)
                   for region, kind, rows, part_level, prefix in layout.components
                   if region == name and part_level == level and kind == "counted"]
        out.update(merge_component_rows(template, src, len(serial_rows), counted, points))
    pair_nodes = None if simulation.contact_arrays is None else np.asarray(simulation.contact_arrays["pairs"])
    for serial_rows, level, src in serial.pairs:
        blocks = {name: state_rows(template[src + name], len(serial_rows)).copy() for name in pair_blocks(template, src)}
        node_force = _float_rows(template[src + "node_force"]).copy()
        for s, layout in zip(states, layouts):
            for selected, part_level, prefix in layout.pairs:
                if part_level != level:
                    continue
                at = np.searchsorted(serial_rows, selected)
                for name, rows in blocks.items():
                    rows[at] = state_rows(s[prefix + name], len(selected))
                node_force[unique_slots(pair_nodes[serial_rows], at)] = _float_rows(s[prefix + "node_force"])
        for name, rows in blocks.items():
            out[src + name] = rows.tobytes()
        out[src + "node_force"] = node_force.tobytes()
    return out


class DistributedStepper:
    """The ranks' steppers behind the Stepper calls of `pyfem.solver.run` (which runs on every
    rank). The u, v, a the run loop holds are the whole model's, read by every rank only where the
    run starts (zeros, or a checkpoint's). After every run() rank 0 holds what a sample reads:
    u, v, a at the sampled nodes (`set_samples`), the energy account, reactions and contact pairs
    in the serial stepper, the monitors' law values (`monitor_point_values`). The whole state (u,
    v, a everywhere, every point's material state) is gathered by `gather_whole`, a collective,
    where fields, the summary or a checkpoint read it; `whole` says whether it is. energy(),
    reactions() and save_state() are the serial stepper's after the merge: meaningful on rank 0,
    which writes."""

    def __init__(self, simulation, serial, comm: MPI.Comm):
        from pyfem.local_stepping import LocalSteppingAdapter

        self.simulation, self.serial, self.comm = simulation, serial, comm
        began = time.perf_counter()
        self.parts = partition(simulation, comm.size)
        self.shares = [share(simulation, self.parts, q) for q in range(comm.size)] if comm.rank == 0 else None
        self.mine = self.shares[0] if comm.rank == 0 else share(simulation, self.parts, comm.rank)
        # Local time stepping (the serial stepper is a LocalStepper): each rank's share steps the row
        # split with one exchange per level and drift (LocalStepper.set_partition).
        self.lts = isinstance(serial, LocalSteppingAdapter)
        if self.lts:
            self.exchange = level_exchanges(comm, self.parts, self.mine, simulation.node_levels)
            self.kernel, self.layout, self.objects, self.pair_objects = local_lts_stepper(simulation, self.mine,
                                                                                          self.exchange)
            self.components = [(name, kind, rows) for name, kind, rows, _, _ in self.layout.components]
            self.layouts = comm.gather(self.layout, root=0)
            self.serial_layout = serial_layout(simulation)
            self._lts_templates()
            self.serial_template_unstarted = serial.save_state()  # the stage's state is in the serial parts
        else:
            self.exchange = _exchange(comm, self.parts, self.mine)
            self.kernel, self.components, self.objects = local_stepper(simulation, self.mine, self.exchange)
            self.template = self.kernel.save_state()
            self.serial_template = serial.save_state()
        self.all_components = comm.gather(self.components, root=0)
        self.setup_seconds = time.perf_counter() - began
        self.merge_seconds = 0.0
        self.whole = True
        self._sent = {False: (0, 0), True: (0, 0)}  # gathers, bytes sent to rank 0 by the last, light / whole
        self.set_samples(np.arange(len(simulation.mass)), None)  # until told what the writer reads
        # The stage's state (components, pairs), cut into shares; under local stepping from the serial
        # stepper as it is (not started: the first run initialises every share from the run's u, v).
        self._load(self.serial_template_unstarted if self.lts else self.serial_template)

    def set_samples(self, nodes: np.ndarray, kernel_points: list | None) -> None:
        """What every sample reads: `nodes` (rank 0's RunWriter.sampled_nodes, the same on every
        rank) and the monitors' kernel points (MonitorStress.kernel_points: per monitor None or
        (region index, flat point index))."""
        nodes = np.unique(np.asarray(nodes, dtype=np.int64))
        owner = self.parts.node_owner[nodes]
        self._sample_rows = _dof_rows(self.mine.local_of[nodes[owner == self.comm.rank]])
        if self.comm.rank == 0:
            self._sample_global = [_dof_rows(nodes[owner == q]) for q in range(self.comm.size)]
        self._kernel_points = [] if kernel_points is None else list(kernel_points)
        self._points = []  # (monitor, local component object, point index in it) of this rank's points
        regions = list(self.simulation.nonlinear.arrays) if self.simulation.nonlinear is not None else []
        for j, found in enumerate(self._kernel_points):
            if found is None:
                continue
            name = regions[found[0]]
            n_points = _region_points(self.simulation.nonlinear, name)
            cell, q = divmod(int(found[1]), n_points)
            for component, (region, kind, cells) in zip(self.objects, self.components):
                k = int(np.searchsorted(cells, cell))
                if region == name and kind == "counted" and k < len(cells) and cells[k] == cell:
                    self._points.append((j, component, k * n_points + q))
        self._values = None

    def monitor_point_values(self, locations: list) -> dict:
        """The monitors' law values at the last sample (as NonlinearRegions.point_values gives them),
        read on the ranks that count their cells; rank 0 only."""
        if len(locations) != len(self._kernel_points) or self._values is None:
            raise RuntimeError("monitor_point_values: not the kernel points given to set_samples")
        return self._values

    def _lts_templates(self) -> None:
        """Started states of the share's and the serial LocalStepper (every block a merge or a slice
        fills: a stepper saves its levels' blocks only once it has run), from one initialisation of
        each at rest; the serial stepper's parts (the stage's state) are put back after it."""
        zeros = np.zeros(3 * len(self.mine.nodes))
        self.kernel.run(zeros, zeros.copy(), zeros.copy(), 0, 0.0)  # initialises, steps nothing
        self.template = self.kernel.save_state()
        self.kernel.load_state(dict(self.template, **{"lts/started": np.zeros(1, dtype=np.uint8).tobytes()}))
        kept = [(part, part.save_state()) for part in self._serial_parts()]
        whole = np.zeros(3 * len(self.simulation.mass))
        self.serial.run(whole, whole.copy(), whole.copy(), 0, 0.0)
        self.serial_template = self.serial.save_state()
        self.serial_light_template = self.serial.save_state(points=False)
        self.serial.load_state(dict(self.serial_template, **{"lts/started": np.zeros(1, dtype=np.uint8).tobytes()}))
        for part, state in kept:
            part.load_state(state)

    def _serial_parts(self) -> list:
        """The serial LocalStepper's component and pair objects in the order of its layout."""
        parts = []
        if self.simulation.nonlinear is not None:
            for region in self.simulation.nonlinear.components:  # LevelComponents, region order
                parts.extend(component for _, component in region.parts)
        if self.simulation.contact_arrays is not None and self.serial_layout.pairs:
            parts.extend(contact for _, contact in self.simulation.contact_pairs.parts)
        return parts

    def _serial_part_blocks(self) -> dict:
        """The serial parts' own states under their archive prefixes (what a started serial
        stepper's save_state holds for them; an unstarted one holds none)."""
        entries = [prefix for *_, prefix in self.serial_layout.components] + \
                  [prefix for *_, prefix in self.serial_layout.pairs]
        blocks = {}
        for prefix, part in zip(entries, self._serial_parts()):
            blocks.update({prefix + name: block for name, block in part.save_state().items()})
        return blocks

    # The run loop's calls -----------------------------------------------------------------------
    def _load(self, serial_state: dict) -> None:
        if self.lts:
            source = dict(serial_state)
            if not _started(serial_state):  # the stage's state is in the serial parts only
                source.update(self._serial_part_blocks())
            local = slice_lts_state(source, self.template, self.serial_layout, self.layout, self.simulation,
                                    self.parts, self.mine, self.comm.rank)
            self.kernel.load_state(local)  # not started: only that (its first run initialises from u, v)
            if not _started(serial_state):  # the parts' state, which an unstarted kernel does not load
                prefixes = [prefix for *_, prefix in self.layout.components] + \
                           [prefix for *_, prefix in self.layout.pairs]
                for prefix, part in zip(prefixes, self.objects + self.pair_objects):
                    own = part.save_state()
                    part.load_state({name: local.get(prefix + name, block) for name, block in own.items()})
        else:
            local = slice_state(serial_state, self.template, self.simulation, self.parts, self.mine,
                                self.comm.rank, self.components)
            self.kernel.load_state(local)
        self._pull = True

    def _local_state(self, u, v, a):
        if self._pull:
            rows = _dof_rows(self.mine.nodes)
            self.u, self.v, self.a = (np.ascontiguousarray(x[rows]) for x in (u, v, a))
            self._pull = False
        return self.u, self.v, self.a

    def _finite(self) -> bool:
        from mpi4py import MPI

        n = 3 * self.mine.n_owned
        local = all(bool(np.isfinite(x[:n]).all()) for x in (self.u, self.v, self.a))
        return self.comm.allreduce(local, op=MPI.LAND)

    def _gather_point_values(self) -> None:
        """The monitors' law values into rank 0: each rank reads the points of the cells it counts,
        one batch per component (`read_point_values`), rank 0 fills `blank_point_values` with them."""
        from pyfem.elements import blank_point_values, read_point_values

        pieces_here = []
        for component in {id(component): component for _, component, _ in self._points}.values():
            mine = [(j, point) for j, owner, point in self._points if owner is component]
            read = read_point_values(component, np.array([point for _, point in mine], dtype=np.int64))
            pieces_here.append((np.array([j for j, _ in mine], dtype=np.int64), read))
        pieces = self.comm.gather(pieces_here, root=0)
        if self.comm.rank != 0 or not self._kernel_points:
            return
        values = blank_point_values(np.array([found is not None for found in self._kernel_points], dtype=bool))
        received = [piece for rank_pieces in pieces for piece in rank_pieces]
        count = sum(len(rows) for rows, _ in received)
        if count != int(values["found"].sum()):  # each found point is counted by one rank
            raise RuntimeError(f"monitor law values: {count} points read by the ranks, "
                               f"{int(values['found'].sum())} monitors in nonlinear cells")
        for rows, read in received:
            for key, column in read.items():
                values[key][rows] = column
        self._values = values

    def _gather(self, u, v, a, whole: bool) -> None:
        """Into rank 0: owned u, v, a (of the sampled nodes, or all with `whole`) into the
        whole-model arrays, the ranks' kernel state into the serial stepper (its per-point blocks
        only with `whole`), the monitors' law values. A non-finite value on any rank makes every
        rank's u non-finite (the run loop's check then stops every rank alike)."""
        began = time.perf_counter()
        finite = self._finite()
        if whole:
            n = 3 * self.mine.n_owned
            owned = np.stack([self.u[:n], self.v[:n], self.a[:n]])
            rows_of = [_dof_rows(mine.nodes[:mine.n_owned]) for mine in self.shares] if self.comm.rank == 0 else None
        else:
            rows = self._sample_rows
            owned = np.stack([self.u[rows], self.v[rows], self.a[rows]])
            rows_of = self._sample_global if self.comm.rank == 0 else None
        state = self.kernel.save_state(points=whole)
        self._sent[whole] = (self._sent[whole][0] + 1, owned.nbytes + sum(len(block) for block in state.values()))
        pieces = self.comm.gather(owned, root=0)
        states = self.comm.gather(state, root=0)
        if self.comm.rank == 0:
            for piece, rows in zip(pieces, rows_of):
                u[rows], v[rows], a[rows] = piece
            if self.lts:
                merged = merge_lts_states(self.serial_template if whole else self.serial_light_template, states,
                                          self.serial_layout, self.layouts, self.simulation, self.parts,
                                          self.shares, points=whole)
            else:
                merged = merge_states(self.serial_template, states, self.simulation, self.parts, self.shares,
                                      self.all_components, points=whole)
            self.serial.load_state(merged, points=whole)
        self._gather_point_values()
        if not finite:
            u[:] = np.nan
        self.whole = whole
        self.merge_seconds += time.perf_counter() - began

    def gather_whole(self, u, v, a) -> None:
        """The whole state on rank 0 (fields, the summary, a checkpoint read it); a collective,
        nothing to do when it is already whole."""
        if not self.whole:
            self._gather(u, v, a, whole=True)

    def reset_energy(self, u, v, a, t0: float) -> None:
        self._pull = True
        lu, lv, la = self._local_state(u, v, a)
        self.kernel.reset_energy(lu, lv, la, t0)
        self._gather(u, v, a, whole=True)

    def run(self, u, v, a, n_steps: int, t0: float) -> float:
        lu, lv, la = self._local_state(u, v, a)
        end = self.kernel.run(lu, lv, la, n_steps, t0)
        self._gather(u, v, a, whole=False)
        return end

    def energy(self):
        return self.serial.energy() if self.comm.rank == 0 else self.kernel.energy()

    def reactions(self):
        return self.serial.reactions() if self.comm.rank == 0 else None

    def save_state(self) -> dict:
        if not self.whole:
            raise RuntimeError("save_state: the state is not whole on rank 0 (gather_whole first)")
        return self.serial.save_state() if self.comm.rank == 0 else {}

    def load_state(self, state: dict) -> None:
        self.serial.load_state(state)
        self._load(state)
        self.whole = True
        if self._kernel_points:  # the monitors' values of the loaded state
            self._gather_point_values()

    def phase_seconds(self) -> dict:
        phases = dict(self.kernel.phase_seconds())
        phases["merge"] = self.merge_seconds
        return phases

    def reset_phase_seconds(self) -> None:
        self.kernel.reset_phase_seconds()
        self.merge_seconds = 0.0

    def bytes_sent_per_step(self) -> int:
        """Bytes this rank sends per step: v and a of its shared nodes; under local time stepping
        per fine step, the average of each level's v once per drift (2^(L - k) per global step)."""
        if not self.lts:
            return int(self.exchange.bytes_sent_per_step)
        return int(round(level_bytes_per_fine_step([exchange.bytes_sent_per_step // 48 for exchange in self.exchange])))

    def describe(self) -> dict:
        """For run.json, per rank: owned and ghost nodes, bytes sent per step (per fine step under
        local time stepping), element-loop cells it
        counts and halo cells it also computes, contact pairs, the merges on rank 0 (light: what a
        sample reads; whole: every node and point) of this sitting and the bytes it sent to the
        last of each; and the set-up time."""
        cells = sum(len(rows) for region in self.mine.cells.values() for kind, rows in region if kind == "counted")
        halo = sum(len(rows) for region in self.mine.cells.values() for kind, rows in region if kind == "halo")
        pairs = 0 if self.mine.pairs is None else len(self.mine.pairs)
        from pyfem.output import peak_memory_mib

        counts = self.comm.gather((self.mine.n_owned, len(self.mine.nodes) - self.mine.n_owned,
                                   self.bytes_sent_per_step(), cells, halo, pairs,
                                   *self._sent[False], *self._sent[True], round(peak_memory_mib(), 1)), root=0)
        if self.comm.rank != 0:
            return {}
        columns = ("owned_nodes", "ghost_nodes", "bytes_sent_per_step", "element_loop_cells", "halo_cells", "pairs",
                   "light_merges", "bytes_per_light_merge", "whole_merges", "bytes_per_whole_merge",
                   "peak_memory_mib")
        return {"ranks": self.comm.size, **{name: [c[k] for c in counts] for k, name in enumerate(columns)},
                "setup_seconds": round(self.setup_seconds, 3)}


# --- The static stage's relaxation on the ranks (pyfem/static.py, pyfem/relaxation.py) ---

@contextlib.contextmanager
def _alone():
    """A failure inside this block is this rank's alone (a kernel error on its share): every rank
    is ended (abort_all) rather than the others left waiting in the next collective."""
    try:
        yield
    except Exception as error:
        abort_all(error)
        raise


@dataclasses.dataclass
class StageModel:
    """What slice_state and merge_states read of a relaxation stage's stepper: its pairs and its
    active element-loop regions, in the serial stage stepper's order (stage 1 leaves the regions
    installed later out)."""

    contact_arrays: dict | None
    nonlinear: "ActiveRegions | None"


class ActiveRegions:
    """A NonlinearRegions restricted to the regions a stage steps (`arrays` in the given order)."""

    def __init__(self, nonlinear, regions: list) -> None:
        self.arrays = {name: nonlinear.arrays[name] for name in regions}


class DistributedStage(RankSums):
    """One relaxation stage's stepper shared among the ranks behind the Stepper calls of
    `pyfem.relaxation.relax`: the serial stage stepper (matrix, scaled mass, held faces, ramped load,
    element-loop components, pairs) cut into the dynamic run's shares (`partition` of the
    simulation: the same owners, ghosts and cells). run() steps each rank's share; relax works on
    each rank's owned dofs with this object as its `space` (pyfem.relaxation.WholeModel's calls:
    norms and Rayleigh quotients summed over the ranks, rank 0's ratio and damping decide for all,
    the whole u and out-of-balance gathered once at the end); `gathered` puts every rank's kernel
    state into the serial stage stepper on every rank at the stage's end (its components, pairs and
    reactions are then the whole model's, as after a serial stage).

    Args:
        simulation: pyfem.solver.Simulation being prepared (model, nonlinear, contact arrays).
        parts: `partition(simulation, comm.size)`.
        serial: the serial stage stepper (pyfem.static._stage_stepper), its state the stage's start.
        stiffness: (3n, 3n) the stage's matrix cells (N/m); every block of an owned row must couple
            nodes of the share (the simulation's matrix rows and the element-loop cells touching
            the owned nodes: so are the stages' and the probe's matrices, checked here).
        mass: (n,) the stage's scaled nodal masses (kg in pseudo time).
        constraints: the stage's held faces (pyfem.solver constraints) or None.
        load: (3n,) the stage's load (N); ramp: pseudo time over which it rises.
        regions: the element-loop regions the serial stepper has, in its order.
        contact_arrays: the stage's pair arrays (no deterioration) or None.
        comm: the MPI communicator.
    """

    def __init__(self, simulation, parts: Partition, serial, stiffness, mass: np.ndarray, constraints,
                 load: np.ndarray, ramp: float, regions: list, contact_arrays: dict | None, comm) -> None:
        from mpi4py import MPI

        self.serial, self.comm, self.parts = serial, comm, parts
        self.model = StageModel(contact_arrays, None if simulation.nonlinear is None
                                else ActiveRegions(simulation.nonlinear, regions))

        def stage_share(rank: int) -> Share:  # the dynamic run's share with the stage's held faces
            held = None if constraints is None else np.flatnonzero(parts.node_owner[constraints.nodes] == rank)
            return dataclasses.replace(share(simulation, parts, rank), constraints=held)

        # Rank 0 merges the ranks' states at the stage's end (`gathered`): it alone needs every share.
        mine = self.mine = stage_share(comm.rank)
        with _alone():  # rank 0's work alone: a failure must not leave the others in the allreduce below
            self.shares = ([mine] + [stage_share(q) for q in range(1, comm.size)]) if comm.rank == 0 else None
        stiffness = stiffness.tobsr(blocksize=(3, 3))
        lacking = bool(np.any(mine.local_of[_block_neighbours(stiffness, mine.nodes[:mine.n_owned])] < 0))
        if comm.allreduce(lacking, op=MPI.LOR):  # every rank raises, none is left waiting
            raise RuntimeError("the static stage's matrix couples an owned node to a node outside its rank's share")
        # Owned nodes ascending, as each share numbers them first: where each rank's owned dofs go.
        self._owned_rows = [_dof_rows(parts.owned(q)) for q in range(comm.size)]
        self.exchange = _exchange(comm, parts, mine)
        with _alone():
            self.kernel, self.components = self._kernel(simulation, stiffness, mass, constraints, load, ramp,
                                                        regions, contact_arrays)
        self.all_components = comm.gather(self.components, root=0)
        self.serial_template = serial.save_state()
        with _alone():
            self.kernel.load_state(slice_state(self.serial_template, self.kernel.save_state(), self.model, parts,
                                               mine, comm.rank, self.components))
        self._local = None

    def _kernel(self, simulation, stiffness, mass, constraints, load, ramp, regions, contact_arrays):
        """This rank's Stepper of the stage and its components (region, kind, cells)."""
        from pyfem import _kernels
        from pyfem.relaxation import PSEUDO_STEP
        from pyfem.static import hand_over_force_provider, local_force

        mine = self.mine
        indptr, indices, blocks = local_matrix(stiffness, mine)
        kernel = _kernels.Stepper(indptr, indices, blocks, np.ascontiguousarray(mass[mine.nodes]), PSEUDO_STEP,
                                  0.0, 0.0)
        _add_constraints(kernel, constraints, mine)
        local_load = local_force(load, mine.nodes[:mine.n_owned], mine.local_of, len(mine.nodes))
        if np.any(local_load):
            kernel.add_provider(hand_over_force_provider(local_load, ramp))
        components = []
        if self.model.nonlinear is not None:
            components, _ = _add_components(kernel, simulation.nonlinear, regions, mine)
        if contact_arrays is not None:
            kernel.add_contact(_local_contact(contact_arrays, mine))
        kernel.set_partition(mine.n_owned, self.exchange)
        return kernel, components

    @property
    def n_dofs(self) -> int:
        return self.serial.n_dofs

    def set_mass_damping(self, alpha: float) -> None:
        self.kernel.set_mass_damping(alpha)

    # relax's arithmetic on the owned dofs (pyfem.relaxation.WholeModel is the serial one) ----------
    def owned_rows(self, n_dofs: int) -> np.ndarray:
        """The rows of the model's dof vectors this rank's relax arrays hold: its owned dofs."""
        return self._owned_rows[self.comm.rank]

    def whole(self, x: np.ndarray) -> np.ndarray:
        """The model's (3n,) vector on every rank from each rank's owned rows of it (an allgather:
        relax calls it once, at the end)."""
        out = np.empty(self.n_dofs)
        for piece, rows in zip(self.comm.allgather(np.asarray(x)), self._owned_rows):
            out[rows] = piece
        return out

    def run(self, u, v, a, n_steps: int, t0: float) -> float:
        """Steps the share n_steps relaxation steps from pseudo time t0 and returns the time reached.

        Args:
            u, v, a: (3 n_owned,) this rank's owned dofs of the displacement (m), velocity and
                acceleration in pseudo time (relax's arrays, `owned_rows`), written in place after
                the steps. relax starts from rest, so the share's ghosts start at zero with their
                owners and then follow them through the ghost exchange of every step.
        """
        if self._local is None:
            if any(np.any(given) for given in (u, v, a)):
                raise ValueError("DistributedStage.run: relax starts from rest")
            self._local = tuple(np.zeros(3 * len(self.mine.nodes)) for _ in range(3))
        lu, lv, la = self._local
        with _alone():
            end = self.kernel.run(lu, lv, la, n_steps, t0)
        n = 3 * self.mine.n_owned
        u[:], v[:], a[:] = lu[:n], lv[:n], la[:n]
        return end

    def gathered(self):
        """The serial stage stepper with every rank's kernel state merged in (a collective; on every
        rank): its components, pairs and reactions are the stage's end, as after a serial stage.
        Rank 0 merges the ranks' states and sends the merged state to every rank."""
        states = self.comm.gather(self.kernel.save_state(), root=0)
        with _alone():  # rank 0's work alone: a failure must not leave the others in the broadcast
            merged = (merge_states(self.serial_template, states, self.model, self.parts, self.shares,
                                   self.all_components) if self.comm.rank == 0 else None)
        self.serial.load_state(self.comm.bcast(merged, root=0))
        return self.serial


def abort_all(error: BaseException) -> None:
    """After a failure that not every rank shares (a write on rank 0, a kernel error on one rank):
    one line on stderr, then MPI_Abort, which ends every rank of the job (the others would wait
    forever in their next exchange). Exit status 1."""
    import sys
    import traceback

    comm = world()
    traceback.print_exception(error, file=sys.__stderr__)
    print(f"error: rank {comm.rank} of {comm.size}: {type(error).__name__}: {error}; ending every rank",
          file=sys.__stderr__, flush=True)
    comm.Abort(1)


class SilentWriter:
    """The writer of ranks other than 0: rank 0 writes every output of a distributed run."""

    writes = False
    show_progress = False
    checkpoint_problem = None

    def __init__(self, out_dir) -> None:
        from pathlib import Path

        self.out_dir = Path(out_dir)
        self.times: list[float] = []

    @property
    def started(self) -> bool:
        return False

    def start(self) -> None:
        pass

    def resume(self, meta: dict, arrays: dict, resumed_at: float) -> None:
        pass

    def sample(self, t: float, *args, **kwargs) -> None:
        self.times.append(t)

    def checkpoint_state(self) -> tuple[dict, dict]:
        return {}, {}

    def fail(self, reason: str, interrupted: bool = False) -> None:
        pass

    def finish(self, **kwargs) -> dict:
        return {}


def threads_per_rank(comm: MPI.Comm) -> int | None:
    """OpenMP threads for each of the ranks sharing this machine's cores (None: serial, the caller
    decides), unless OMP_NUM_THREADS says otherwise."""
    if comm.size == 1 or os.environ.get("OMP_NUM_THREADS", "").isdigit():
        return None
    # Not a collective (rank 0 alone builds the plan's trial stepper): mpirun's environment.
    on_node = int(os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE", os.environ.get("MPI_LOCALNRANKS", comm.size)))
    return max(1, min(len(os.sched_getaffinity(0)), (os.cpu_count() or 1) // on_node))

"""Local time stepping on the distributed model (`[parallel] model = "distributed"` with `[time]
local_stepping`; docs/scaling.md "Local time stepping on the distributed model"): the whole model's
row split (pyfem/local_stepping.py) on the ranks' parts, no rank holding the whole model.

- Levels (`node_levels`): each rank takes the stable step of its owned rows (the Gershgorin bound of
  every cell's matrix with the boundary springs, `RankModel.row_sums`) and the finest over the ranks;
  its owned cells' levels from their nodes'; each node the finest level of its cells on every rank
  (a ghost's sent to its owner, `GhostPlan.reduce`); the truncation faces' dashpot nodes at the
  finest; the two nodes of a pair at the finer of theirs (a pair and its nodes are on one rank).
  These are the whole model's levels, node for node (tests/test_mpi_distributed_lts.py).
- The cap to the output interval, the time step and "auto" read the whole model's nodes per level
  and work sums (`local_stepping.fitted_top`, `local_time_step`, `decision_of`): each rank's owned
  rows, counted cells and pairs summed over the ranks.
- The set-up check (`check_stability_on_ranks`): the whole model's check of the LTS map, stepped by
  the ranks' parts from a random state that is a function of the node coordinates
  (`distributed_parts.start_vector`), the energy summed over the ranks.
- Stepping (`rank_stepper`): the kernel's LocalStepper of the part by the row split, one velocity
  exchange per level (`level_exchanges`: the ghost plan's nodes of that level), each region's counted
  and halo cells split by level (the finest of its nodes), the pairs by their level; after a static
  stage, the stage's components and pairs cut by level (`local_stepping.load_component_parts`,
  `load_pair_parts`).
- Checkpoints (`lts_rank_state`, `load_lts_state`): the stepper's state keyed by position as the
  global stepper's (pyfem/distributed_model.py `DistributedRun.rank_state`), so that a run resumes
  on any rank count.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from pyfem.scene import SceneError


@dataclass
class RankLevels:
    """Local time stepping of a rank's part.

    Attributes:
        levels: int32 rate level per local node (the kernel's numbering; a ghost's its owner's).
        counts: the whole model's nodes per level, finest first.
        global_step: the scene's TimeStep (global stepping's).
        time_step: local_stepping.local_time_step's (dt the finest level's).
        stability: the set-up check's report once it ran (`check_stability_on_ranks`).
    """

    levels: np.ndarray
    counts: np.ndarray
    global_step: object
    time_step: object
    stability: dict | None = None

    @property
    def max_level(self) -> int:
        return len(self.counts) - 1

    @property
    def ratio(self) -> int:
        """Fine steps per global step."""
        return 2 ** self.max_level


def owned_cell_nodes(part) -> np.ndarray:
    """(owned cells, nodes per cell) the rank's owned cells' nodes in the kernel's numbering."""
    model = part.model
    dofmap = model.V.dofmap.list
    cells = dofmap.array.reshape(len(dofmap.offsets) - 1, -1)[:model.n_cells]
    return np.asarray(part.kernel_nodes(cells), dtype=np.int64)


def node_levels(part) -> np.ndarray:
    """int32 per local node: pyfem.local_stepping.node_levels (row split) of the whole model on the
    ranks (module docstring), before the cap to the output interval. A collective."""
    from pyfem.local_stepping import MAX_LEVEL, equalize_pair_levels, node_stable_steps, rate_levels

    comm, n_owned = part.comm, part.n_owned
    dt_node = np.zeros(part.n_local)
    dt_node[:n_owned] = node_stable_steps(part.row_sums, part.mass[:n_owned])
    dt_min = comm.allreduce(float(dt_node[:n_owned].min()) if n_owned else math.inf, op=MPI.MIN)
    dt_node[np.asarray(part.dashpot_nodes, dtype=np.int64)] = dt_min  # (owned face nodes)
    part.plan.update(comm, dt_node)
    cells = owned_cell_nodes(part)
    cell_level = rate_levels(dt_node[cells].min(axis=1), dt_min, MAX_LEVEL)
    levels = np.full(part.n_local, MAX_LEVEL, dtype=np.int32)
    np.minimum.at(levels, cells.ravel(), np.repeat(cell_level, cells.shape[1]))
    part.plan.reduce(comm, levels, np.minimum)
    if part.pairs is not None and len(part.pairs.nodes):  # (both nodes of a pair are owned here)
        levels = equalize_pair_levels(levels, np.asarray(part.pairs.nodes))
    part.plan.update(comm, levels)
    return levels


def level_counts(comm: MPI.Comm, levels: np.ndarray, n_owned: int) -> np.ndarray:
    """The whole model's nodes per level (the ranks' owned nodes'), up to the largest level with nodes."""
    from pyfem.local_stepping import MAX_LEVEL

    counts = comm.allreduce(np.bincount(levels[:n_owned], minlength=MAX_LEVEL + 1).astype(np.int64))
    return np.trim_zeros(counts, "b")


def work_sums_on_ranks(part, loop, levels: np.ndarray) -> np.ndarray:
    """local_stepping.work_sums of the whole model: each rank's owned rows, counted cells and pairs,
    summed over the ranks."""
    from pyfem.local_stepping import row_cell_cap, work_sums

    n_owned = part.n_owned
    points, cell_level = [np.zeros(0)], [np.zeros(0)]
    if loop is not None:
        for arrays in loop.counted.arrays.values():
            points.append(np.full(len(arrays.cells), float(arrays.weights.shape[1])))
            cell_level.append(row_cell_cap(levels, arrays.cell_nodes))  # (the finest of its nodes)
    pair_levels = np.zeros(0)
    if part.pairs is not None and len(part.pairs.nodes):
        pair_levels = levels[np.asarray(part.pairs.nodes)[:, 0]]
    mine = work_sums(levels[:n_owned], np.diff(part.matrix[0][:n_owned + 1]), np.concatenate(points),
                     np.concatenate(cell_level), pair_levels)
    return part.comm.allreduce(mine)


def _supported(part) -> None:
    """SceneError where local stepping cannot step this model (a collective)."""
    from pyfem import local_stepping

    local_stepping.check_supported(part.scene, part.beta)
    held = None
    if part.constraints is not None and part.pairs is not None:
        on_pair = np.intersect1d(np.asarray(part.constraints.nodes), np.asarray(part.pairs.nodes).ravel())
        held = part.coords[on_pair[0]].round(3).tolist() if len(on_pair) else None
    held = next((where for where in part.comm.allgather(held) if where is not None), None)
    if held is not None:
        raise local_stepping.held_pair_error(f"the node at {held}")


def _fitted_levels(part, time_step) -> tuple[np.ndarray, np.ndarray]:
    """(each local node's rate level, fitted to the output interval; the whole model's nodes per level)."""
    from pyfem import local_stepping

    levels = node_levels(part)
    top = local_stepping.fitted_top(level_counts(part.comm, levels, part.n_owned), time_step.steps_per_output)
    levels = np.minimum(levels, top).astype(np.int32)
    return levels, level_counts(part.comm, levels, part.n_owned)


def preview(part, loop, time_step) -> tuple[np.ndarray, np.ndarray] | None:
    """With local stepping off: (the whole model's work sums, nodes per level) of the levels it would
    use (`check`'s prediction, pyfem/plan.py lts_preview_lines), None where it cannot step the model.
    A collective."""
    try:
        _supported(part)
    except SceneError:
        return None
    levels, counts = _fitted_levels(part, time_step)
    return work_sums_on_ranks(part, loop, levels), counts


def choose(part, loop, time_step, duration: float) -> tuple[RankLevels | None, str | None]:
    """Whether the run steps locally (`time.local_stepping`: true, or "auto" where it pays, as the
    whole model decides) and at which levels: (RankLevels or None, "auto"'s reason or None). Refuses
    (SceneError) what local stepping does not do when set to true. A collective."""
    from pyfem import local_stepping

    setting = part.scene["time"].get("local_stepping")
    if not setting:
        return None, None
    try:
        _supported(part)
    except SceneError as error:
        if setting is True:
            raise
        return None, "\"auto\": off: not available " + error.allowed.removeprefix("false ")
    levels, counts = _fitted_levels(part, time_step)
    on, decision = True, None
    if setting == "auto":
        on, decision = local_stepping.decision_of(
            work_sums_on_ranks(part, loop, levels) if len(counts) > 1 else None, counts, time_step, duration)
    if not on:
        return None, decision
    fine_step, _ = local_stepping.local_time_step(time_step, None, "row", counts=counts)
    return RankLevels(levels, counts, time_step, fine_step), decision


class LevelExchanges(list):
    """The kernel's MpiNodeExchange of each level (finest first), with the bytes a rank sends per
    fine step: each level's velocities at each of its drifts, 2^(L - k) per global step
    (pyfem.ranks.level_bytes_per_fine_step; an exchange counts 48 bytes per node, v and a, as
    the global Stepper sends them)."""

    @property
    def bytes_sent_per_step(self) -> float:
        from pyfem.ranks import level_bytes_per_fine_step

        return level_bytes_per_fine_step([exchange.bytes_sent_per_step // 48 for exchange in self])


def level_exchanges(part, levels: np.ndarray, max_level: int) -> LevelExchanges:
    """One kernel MpiNodeExchange per level k: the ghost plan's nodes at level k (a ghost's level is
    its owner's). A collective."""
    return LevelExchanges(part.plan.kernel_exchange(part.comm, part.n_local, levels == k)
                          for k in range(max_level + 1))


@dataclass
class RankLayout:
    """Where a rank's LocalStepper keeps its parts' state (its save_state's prefixes).

    Attributes:
        components: per region of the element loop [(region, kind "counted" or "halo", the
            region's LevelComponents, per part of it its archive prefix)].
        pairs, pair_prefixes: the LevelPairs of the rank's pairs (None: none), per part its prefix.
    """

    components: list
    pairs: object = None
    pair_prefixes: list | None = None


def _prefix(max_level: int, level: int, what: str, k: int) -> str:
    return f"lts/level/{max_level - int(level)}/{what}/{k}/"


def rank_stepper(part, rank_levels: RankLevels, loop, input_arrays: dict | None = None,
                 contact_arrays: dict | None = None, stage=None, bare: bool = False) -> tuple:
    """The kernel's LocalStepper of the rank's part (module docstring) behind the Stepper calls of
    the run loop: (LocalSteppingAdapter, LevelExchanges, RankLayout). The run's element-loop regions
    become LevelComponents (`loop.counted.components`, `loop.halo.components`), continuing the stage's
    components when `stage` ran (they are the regions' components then, pyfem/distributed_stage.py
    hand_over). `bare`: the map the set-up check iterates (no mass-proportional damping, no pairs, no
    input, laws without initial stress: a tiny state keeps them elastic), the regions untouched. A
    collective (the exchanges)."""
    from pyfem import _kernels
    from pyfem import local_stepping
    from pyfem.effects import make_contact_pairs, seismic_input_kernel

    levels, max_level = rank_levels.levels, rank_levels.max_level
    kernel = _kernels.LocalStepper(*part.matrix, part.mass, levels, rank_levels.time_step.dt,
                                   0.0 if bare else part.alpha, max_level)
    kernel.set_row_split(True)
    if len(part.dashpot_nodes):
        kernel.set_dashpots(part.dashpot_nodes, part.dashpot_matrices)
    if part.constraints is not None:
        kernel.set_constraints(np.ascontiguousarray(part.constraints.nodes, dtype=np.int32),
                               np.ascontiguousarray(part.constraints.projection, dtype=np.float64))
    layout = RankLayout(components=[])
    per_level = {}  # level -> components added at it (their archive index)
    for kind in ("counted", "halo"):
        regions = None if loop is None else getattr(loop, kind)
        if regions is None:
            continue
        split = []
        for index, (name, arrays) in enumerate(regions.arrays.items()):
            cell_level = local_stepping.row_cell_cap(levels, arrays.cell_nodes)  # (the finest of its nodes)
            parts, prefixes = [], []
            for level in np.unique(cell_level):
                rows = np.flatnonzero(cell_level == level)
                component = regions.new_component(name, initial_stress=None if bare else "scene", rows=rows)
                kernel.add_internal_force(component, int(level), kind == "counted")
                k = per_level.get(int(level), 0)
                per_level[int(level)] = k + 1
                parts.append((rows, component))
                prefixes.append(_prefix(max_level, level, "component", k))
            region = local_stepping.LevelComponents(len(cell_level), arrays.weights.shape[1], parts)
            if stage is not None and not bare:  # the stage's state, cut by level
                local_stepping.load_component_parts(regions.components[index], parts)
            split.append(region)
            layout.components.append((name, kind, region, prefixes))
        if not bare:
            regions.components = split
    # Rock bolts and cables (pyfem/distributed_support.py): each bolt at the finest level of its host
    # nodes, as a pair at the finer of its two nodes' (the stage's components cut by level).
    for rank_group in part.support:
        if bare:  # (fresh, elastic: the set-up check's tiny state; the run's parts untouched)
            from pyfem.distributed_support import make_component

            parts = [(kind, level, make_component(rank_group, bolts)) for kind in ("counted", "halo")
                     for level, bolts in rank_group.by_level(rank_group.bolts_of(kind), levels)]
        else:
            if rank_group.parts:
                rank_group.split_by_level(levels)
            else:
                rank_group.fresh(levels)
            parts = [(bolts.kind, bolts.level, bolts.component) for bolts in rank_group.parts]
        for index, (kind, level, component) in enumerate(parts):
            kernel.add_internal_force(component, int(level), kind == "counted")
            k = per_level.get(int(level), 0)
            per_level[int(level)] = k + 1
            if not bare:
                rank_group.parts[index].prefix = _prefix(max_level, level, "component", k)
    if not bare and contact_arrays is not None and part.pairs is not None and len(part.pairs.nodes):
        pairs, kernel_parts = local_stepping.level_pairs(contact_arrays, levels, None, None, None, make_contact_pairs,
                                                         rows=True)
        if stage is not None and stage.contact is not None:
            local_stepping.load_pair_parts(stage.contact, pairs.parts, np.asarray(contact_arrays["pairs"]))
        for contact, level in kernel_parts:
            kernel.add_contact(contact, level)
        layout.pairs, layout.pair_prefixes = pairs, [_prefix(max_level, level, "contact", 0)
                                                     for _, level in kernel_parts]
    if not bare and input_arrays is not None and len(input_arrays["nodes"]):
        kernel.add_provider(seismic_input_kernel(input_arrays))
    held_force = None if bare or stage is None else stage.hand_over_force
    if held_force is not None and np.any(held_force):  # a linear stage's hand-over force, held constant
        from pyfem.static import hand_over_force_provider

        kernel.add_provider(hand_over_force_provider(held_force))
    exchanges = level_exchanges(part, levels, max_level)
    kernel.set_partition(part.n_owned, exchanges)
    return local_stepping.LocalSteppingAdapter(kernel, rank_levels.ratio), exchanges, layout


def check_stability_on_ranks(part, rank_levels: RankLevels, loop, **check) -> dict:
    """local_stepping.check_stability of the whole model's LTS map stepped by the ranks' parts, from
    STABILITY_AMPLITUDE times `start_vector` of the node coordinates (the same state for any rank
    count), the energy summed over the ranks; rank 0's report on every rank, with "ranks". `check`:
    check_stability's steps and chunk. A collective."""
    from pyfem.ranks import RankSummed
    from pyfem.distributed_parts import start_vector
    from pyfem.local_stepping import STABILITY_AMPLITUDE, check_stability

    comm = part.comm

    def make_kernel():
        stepper, _, _ = rank_stepper(part, rank_levels, loop, bare=True)
        return RankSummed(stepper.kernel, comm)

    state = STABILITY_AMPLITUDE * start_vector(part.coords).reshape(-1)
    report = check_stability(make_kernel, len(state), state=state, **check)
    seconds = comm.allreduce(report["seconds"], op=MPI.MAX)
    return dict(comm.bcast(report, root=0), seconds=seconds, ranks=comm.size)


# --- checkpoints ----------------------------------------------------------------------------------

def _rows(block: bytes) -> np.ndarray:
    return np.frombuffer(block, dtype=np.float64).reshape(-1, 3)


def _started(state: dict) -> bool:
    return bool(np.frombuffer(state["lts/started"], dtype=np.uint8)[0])


def lts_rank_state(kernel_state: dict, rank_levels: RankLevels, n_owned: int) -> dict:
    """The stepper's own state in a rank's checkpoint file (beyond its parts'): whether it started,
    its energy account (this rank's share of a sum), its constraints' reactions and, per owned node,
    the last force and external force of the node's level (the level's rows are its nodes in local
    order, ghosts included)."""
    out = {"lts/started": np.frombuffer(kernel_state["lts/started"], dtype=np.uint8)}
    if not _started(kernel_state):
        return out
    for name in ("lts/energy", "lts/dissipation_at_start"):
        out[name] = np.frombuffer(kernel_state[name], dtype=np.float64)
    out["lts/reactions"] = np.frombuffer(kernel_state["lts/reactions"], dtype=np.float64)
    levels = rank_levels.levels
    for block in ("force", "external"):
        values = np.zeros((n_owned, 3))
        for k in range(rank_levels.max_level + 1):
            rows = np.flatnonzero(levels == k)
            owned = rows < n_owned
            values[rows[owned]] = _rows(kernel_state[f"lts/level/{rank_levels.max_level - k}/{block}"])[owned]
        out[f"lts/{block}"] = values
    return out


def load_lts_state(template: dict, files: list, rows: np.ndarray, reaction_rows, rank_levels: RankLevels,
                   first: bool) -> dict:
    """The stepper's own blocks of a started `template` (its save_state after a run of no steps) from
    the checkpoint's rank files (`lts_rank_state`'s): the force blocks of this rank's local nodes
    (`rows`: their rows in the files' owned nodes, concatenated), its constraints' reactions
    (`reaction_rows`, or None), the energy account's total on the `first` rank (zero elsewhere)."""
    out = dict(template)
    for name in ("lts/energy", "lts/dissipation_at_start"):
        total = np.sum([f[name] for f in files], axis=0)
        out[name] = (total if first else np.zeros_like(total)).tobytes()
    if reaction_rows is not None:
        out["lts/reactions"] = np.ascontiguousarray(
            np.concatenate([f["lts/reactions"].reshape(-1, 3) for f in files])[reaction_rows]).tobytes()
    levels = rank_levels.levels
    for block in ("force", "external"):
        values = np.concatenate([f[f"lts/{block}"].reshape(-1, 3) for f in files])[rows]
        for k in range(rank_levels.max_level + 1):
            out[f"lts/level/{rank_levels.max_level - k}/{block}"] = np.ascontiguousarray(
                values[np.flatnonzero(levels == k)]).tobytes()
    return out

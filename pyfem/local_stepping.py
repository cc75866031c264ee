"""Local time stepping from a scene (`[time] local_stepping`: true, false or "auto", the default, which
turns it on where it pays, `auto_decision`; docs/local_stepping.md): the rate
level of every node, the time step made a whole number of global steps per output interval, and
an adapter that gives the kernel's LocalStepper the interface the run loop uses.

Levels: per node the Gershgorin bound of M^-1 K (springs of the viscoelastic boundary included)
gives a stable step dt_i; a cell may step at dt_fine 2^k with k = floor(log2(min over its nodes of
dt_i / min_i dt_i)), at most MAX_LEVEL; a node steps at the finest rate of its cells (the one-cell
overlap of Diaz & Grote's scheme); the truncation faces' dashpot nodes step at the finest rate.
dt_fine is the scene's step (safety x the power-iteration critical step of the whole model); a
level-k node's step dt_fine 2^k is then within safety x (power-iteration / Gershgorin ratio, 1.1-1.6
here) of its own Gershgorin bound, which is itself conservative. Stability of the scheme on the
user's mesh is checked at set-up (`check_stability`): the LTS map itself, undamped and unforced
but with the model's boundary dashpots, is iterated from a random state for STABILITY_STEPS global
steps, and its energy must not grow (a growth of 0.2 % per global step or more is caught; the 1D
prototype and the kernel's tests are stable up to the global safety factor, docs/local_stepping.md).

Every model steps by the row split (`row_split`, LocalStepper.set_row_split; docs/local_stepping.md "The
scheme: the row split", "The energy account"): every node at its own level with its
whole stiffness row. The levels are then capped where a deep hierarchy costs more fine steps per
output interval than it saves (`fit_levels_to_output`). Element-loop materials (`plasticity`,
`damage` tables) step at their cells' own rates: each cell at the finest level of its nodes (the
column split, kept in the kernel for comparisons: the coarsest), its region split into one kernel
component per level, read back as one region by `LevelComponents`. Contact pairs step at their own
rates too (LocalStepper.add_contact: an impulse before each drift of their level): the two nodes of
a pair at the finer of their levels (`equalize_pair_levels`; the column split: one level and one
drift level, `equalize_pair_drift`), the pairs split into one kernel ContactPairs per level and read
back as one set by `LevelPairs`. After a relaxation stage both continue the stage's state, cut by level
(`load_component_parts`, `load_pair_parts`). Fixed and roller faces project every kick of their
nodes (LocalStepper.set_constraints; contact pairs on them are refused by key, `pyfem.solver.prepare`). What is not supported yet, refused by
key: stiffness-proportional damping. Checkpoints hold the LocalStepper's own state
(each level's last force, the energy account, every level's components and pairs) and resume bit for
bit (docs/checkpoint.md).
"""
from __future__ import annotations

import dataclasses
import math
import re
import time

import numpy as np

from pyfem.scene import SceneError

MAX_LEVEL = 5
KEY = "time.local_stepping"
STABILITY_STEPS = 240      # global steps of the set-up check
STABILITY_CHUNK = 10       # global steps between energy readings
STABILITY_AMPLITUDE = 1.0e-9  # m, the random state's scale
STABILITY_RATIO = 2.0      # largest energy of the last third / of the first third, above: unstable
AUTO_PAYS = 1.25
"""`time.local_stepping = "auto"` (the default) turns local stepping on where `auto_decision` predicts
at least this speed-up over the whole run, its set-up check included: the prediction runs 7-28 %
above the measured speed-up (`predicted_speed_up`; the work model: 1.58x against 1.33x measured on the
coarse case 3, 1.72x against 1.34x on the paper-scale one), so a model it turns on is faster."""
COST_NS = {"block": 5.0, "point": 172.0, "pair": 350.0, "node": 11.2}
"""The kernel's cost per step (ns, 2 threads) of a 3x3 block of the stiffness product, a point of an
element-loop law, a contact pair and a node's update and input forces: the coarse case 3's global steps
with the rock yielding (2.73 ms for 548 268 blocks, 36.2 ms for 210 560 points, 4.03 ms for 11 520
pairs, 0.66 ms for 58 352 nodes; docs/local_stepping.md "When it is on"). `auto_decision` predicts by
these fixed figures, not by timing this machine, so that a scene makes the same decision on every
machine and when a run resumes."""


def check_supported(scene, beta: float) -> None:
    """Raises SceneError naming time.local_stepping when the scene asks for what the local stepper
    does not do yet."""
    allowed = ("false for scenes with {}: local time stepping covers the stiffness, mass-proportional "
               "damping, viscoelastic, viscous, fixed and roller faces, seismic input, element-loop materials, "
               "contact, rock bolts and a static stage (docs/local_stepping.md)")
    if beta != 0.0:
        raise SceneError(KEY, True, allowed.format("stiffness-proportional Rayleigh damping (beta > 0)"))
    if scene["time"].get("matrix_precision", "double") != "double":
        raise SceneError(KEY, True, allowed.format('time.matrix_precision = "single" (the local stepper '
                                                    "stores double blocks)"))


def held_pair_error(node: str) -> SceneError:
    """The refusal of local stepping on a model whose contact pair `node` (its words) is on a fixed or
    roller face."""
    return SceneError(KEY, True, f"false for scenes with contact pairs on fixed or roller faces ({node} is both): "
                                 "local time stepping does not correct a held pair node (docs/local_stepping.md)")


def unstable_words(report: dict) -> tuple[SceneError, str, str]:
    """What is said when the set-up check (`check_stability`'s `report`) found the LTS map unstable:
    (the refusal when local stepping was asked for, "auto"'s reason for run.json, "auto"'s warning
    as it falls back to global stepping)."""
    growth = f"{report['growth']:.3g}x in {report['global_steps']} global steps"
    refusal = SceneError(KEY, True, "false for this model: its local time stepping map amplified a random state's "
                                    f"energy {growth} (unstable); lower time.safety or turn local stepping off")
    decision = ("\"auto\": off: its set-up check found the local time stepping map unstable on this model (a random "
                f"state's energy grew {growth}); global stepping instead")
    warning = ("time.local_stepping = \"auto\": local stepping was predicted to pay, but its map is unstable on this "
               "model; the run steps globally (run.json \"local_stepping\")")
    return refusal, decision, warning


def node_levels(stiffness, mass: np.ndarray, cell_nodes: np.ndarray, max_level: int = MAX_LEVEL,
                pinned: np.ndarray | None = None, pairs: np.ndarray | None = None,
                loop_cells: np.ndarray | None = None, rows: bool = False) -> np.ndarray:
    """int32 (n_nodes,) rate level per node, 0 the finest (module docstring). `pinned` nodes (the
    truncation faces' dashpot nodes) and the cells they belong to step at the finest rate: a
    boundary dashpot at a coarse node's own step is accurate only to (h C / M)^2, which is of order
    the coarse cells' Courant number squared, and it degraded the free field several times
    (docs/local_stepping.md). `pairs` (n_pairs, 2): the two nodes of every contact pair are made to drift at
    one rate (`equalize_pair_drift`; `loop_cells`: `loop_cell_mask` of the element-loop cells), or, for
    the row split (`rows`), the two nodes of every pair at the finer of their levels and nothing else
    (`equalize_pair_levels`)."""
    csr = stiffness.tocsr()
    row_sums = np.asarray(abs(csr).sum(axis=1)).ravel().reshape(-1, 3).max(axis=1)
    dt_node = node_stable_steps(row_sums, mass)
    dt_min = dt_node.min()
    if pinned is not None and len(pinned):
        dt_node[np.asarray(pinned)] = dt_min
    cell_level = rate_levels(dt_node[cell_nodes].min(axis=1), dt_min, max_level)
    levels = _finest_of_cells(cell_level, cell_nodes, np.full(len(mass), max_level))
    if pairs is not None and len(pairs):
        levels = (equalize_pair_levels(levels, np.asarray(pairs)) if rows
                  else equalize_pair_drift(levels, cell_nodes, np.asarray(pairs), loop_cells))
    return levels


def node_stable_steps(row_sums: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Each node's stable step (s) by the Gershgorin bound of its rows: 2 / sqrt(largest absolute row
    sum of its three rows / its mass)."""
    return 2.0 / np.sqrt(np.asarray(row_sums, dtype=float) / np.asarray(mass, dtype=float))


def rate_levels(dt: np.ndarray, dt_min: float, max_level: int) -> np.ndarray:
    """int32 rate level of each stable step `dt`: floor(log2(dt / dt_min)), at most max_level."""
    return np.minimum(np.floor(np.log2(np.asarray(dt) / dt_min) + 1e-12), max_level).astype(np.int32)


def fit_levels_to_output(levels: np.ndarray, steps_per_output: int) -> np.ndarray:
    """Levels capped at the top level L' <= max(levels) that costs least per output interval
    (`fitted_top` of the nodes per level). Capping only makes nodes step finer, so it is as stable as
    the levels it caps. Returns an int32 array."""
    levels = np.asarray(levels, dtype=np.int32)
    return np.minimum(levels, fitted_top(np.bincount(levels), steps_per_output)).astype(np.int32)


def fitted_top(counts, steps_per_output: int) -> int:
    """The top level L' (<= the largest with nodes, `counts` the nodes per level) that costs least per
    output interval: the run takes whole global steps of dt_fine 2^L' per interval (`local_time_step`
    lowers dt_fine to fit), so a deep hierarchy can cost more fine steps than it saves. The cost of L'
    is the fine steps per interval, ceil(steps_per_output / 2^L') 2^L', times the nodes' work per fine
    step, the sum of 2^-min(level, L') (every node's row once per step of its level). On the coarse
    case 3 (85 steps per 0.01 s, nodes per level 19 756 / 8 710 / 8 880 / 17 869 / 3 039 / 98) it caps
    at 3: 88 fine steps instead of 96, 7.7 % less work (docs/local_stepping.md
    "Speed"). The counts of an MPI rank's owned nodes summed over the ranks give the whole model's."""
    counts = np.trim_zeros(np.asarray(counts, dtype=float), "b")
    best, best_cost = 0, math.inf
    for top in range(len(counts)):
        ratio = 2 ** top
        fine_steps = math.ceil(steps_per_output / ratio) * ratio
        work = sum(count * 2.0 ** -min(level, top) for level, count in enumerate(counts))
        cost = fine_steps * work
        if cost < best_cost * (1.0 - 1e-12):  # the shallower of two equal costs
            best, best_cost = top, cost
    return best


def equalize_pair_levels(levels: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Node levels with the two nodes of every contact pair at one level, the finer of the two (pairs
    that share nodes: the finest of the group); the row split needs nothing more, since a node's level
    fixes no neighbour's drift there. Returns a new int32 array."""
    levels = np.array(levels, dtype=np.int32, copy=True)
    i, j = pairs[:, 0], pairs[:, 1]
    while np.any(levels[i] != levels[j]):
        finer = np.minimum(levels[i], levels[j])
        np.minimum.at(levels, i, finer)
        np.minimum.at(levels, j, finer)
    return levels


def _finest_of_cells(cell_level: np.ndarray, cell_nodes: np.ndarray, start: np.ndarray) -> np.ndarray:
    """int32 per node: the finest of `start` (per node) and the levels of the cells it belongs to."""
    levels = np.array(start, dtype=np.int32, copy=True)
    np.minimum.at(levels, cell_nodes.ravel(), np.repeat(cell_level, cell_nodes.shape[1]).astype(np.int32))
    return levels


UNCAPPED = np.iinfo(np.int32).max


MATRIX_CELL, LOOP_CELL, LOOP_AND_MATRIX_CELL = 0, 1, 2
"""Codes of `loop_cell_mask`: a cell in the stiffness matrix only; in the element loop only; in both
(a one-point cell, integration = "reduced": its hourglass stiffness stays in the matrix)."""


def loop_cell_mask(nonlinear, n_cells: int) -> np.ndarray | None:
    """int8 per model cell, MATRIX_CELL, LOOP_CELL or LOOP_AND_MATRIX_CELL (`nonlinear`:
    NonlinearRegions), or None without element-loop materials. Nonzero = the element loop loads it."""
    if nonlinear is None:
        return None
    mask = np.full(n_cells, MATRIX_CELL, dtype=np.int8)
    for name, arrays in nonlinear.arrays.items():
        mask[arrays.cells] = LOOP_AND_MATRIX_CELL if name in nonlinear.hourglass else LOOP_CELL
    return mask


def drift_levels(levels: np.ndarray, cell_nodes: np.ndarray, cell_cap: np.ndarray | None = None,
                 loop_cells: np.ndarray | None = None) -> np.ndarray:
    """int32 (n_nodes,): the finest level whose kicks move each node (its drift level in the
    LocalStepper): the finest level of the nodes it shares a matrix cell with (its stiffness row's
    columns), itself included, and of the element-loop cells (`loop_cells`, `loop_cell_mask`'s codes)
    that load it, each at its own level: the coarsest of its nodes (`cell_levels`), made finer by
    `cell_cap` (per cell; `pair_cell_cap`). A one-point cell is also a matrix cell (its hourglass
    stiffness), so the matrix's finest level rules it."""
    finest_in_cell = levels[cell_nodes].min(axis=1).astype(np.int64)
    if loop_cells is not None:
        finest_in_cell = np.where(np.asarray(loop_cells) == LOOP_CELL, levels[cell_nodes].max(axis=1),
                                  finest_in_cell)
    if cell_cap is not None:
        finest_in_cell = np.minimum(finest_in_cell, cell_cap)
    return _finest_of_cells(finest_in_cell, cell_nodes, levels)


def interface_rows(levels: np.ndarray, cell_nodes: np.ndarray, cell_cap: np.ndarray | None = None,
                   loop_cells: np.ndarray | None = None) -> np.ndarray:
    """int32 nodes on the fine side of a level boundary: a node that shares a cell with a node of a
    coarser level and drifts at its own level (`drift_levels`). The run steps their stiffness rows at
    that level (LocalStepper.step_rows_at_drift_level): a coarser neighbour's force then reaches them
    at each of their substeps, read from its drifting position, instead of as two kicks at the ends of
    the coarse step, which rang the fine cells' modes (docs/local_stepping.md "The column split")."""
    coarsest_in_cell = levels[cell_nodes].max(axis=1)
    coarser = np.zeros(len(levels), dtype=bool)
    for k in range(cell_nodes.shape[1]):
        coarser[cell_nodes[:, k]] |= coarsest_in_cell > levels[cell_nodes[:, k]]
    drift = drift_levels(levels, cell_nodes, cell_cap, loop_cells)
    return np.flatnonzero(coarser & (drift == levels)).astype(np.int32)


def pair_cell_cap(levels: np.ndarray, cell_nodes: np.ndarray, pairs: np.ndarray,
                  loop_cells: np.ndarray | None) -> np.ndarray:
    """int32 per cell: the level an element-loop cell touching contact pair nodes must step at, the
    finest drift level of those nodes (UNCAPPED for every other cell). Its force then reaches each pair
    node at every substep of the pair's level, not as kicks at the ends of a coarser step (which a
    friction threshold would feel within one substep; the stiffness rows of pair nodes are stepped at
    their drift level for the same reason, LocalStepper.step_rows_at_drift_level). A cell stepped finer
    can make its other nodes drift finer: repeated until nothing changes."""
    cap = np.full(len(cell_nodes), UNCAPPED, dtype=np.int64)
    if loop_cells is None or not np.any(loop_cells):
        return cap
    is_pair = np.zeros(len(levels), dtype=bool)
    is_pair[np.asarray(pairs).ravel()] = True
    touching = np.flatnonzero((np.asarray(loop_cells) != MATRIX_CELL) & is_pair[cell_nodes].any(axis=1))
    around = cell_nodes[touching]
    while True:
        drift = drift_levels(levels, cell_nodes, cap, loop_cells)
        finest = np.where(is_pair[around], drift[around], UNCAPPED).min(axis=1)
        lowered = np.minimum(cap[touching], finest)
        if np.array_equal(lowered, cap[touching]):
            return cap
        cap[touching] = lowered


def equalize_pair_drift(levels: np.ndarray, cell_nodes: np.ndarray, pairs: np.ndarray,
                        loop_cells: np.ndarray | None = None) -> np.ndarray:
    """Node levels with the two nodes of every contact pair stepping and drifting at one level
    (LocalStepper.add_contact): both take the finest of their two levels and their two drift levels
    (a node may step finer than its cells need). Stepping at its drift level makes a pair node a column
    of that level in each neighbour's row, so every neighbour its row reads drifts there too
    (LocalStepper.step_rows_at_drift_level); one level for both makes a bonded pair the unsplit node
    exactly. The element-loop cells (`loop_cells`, per cell) touching pair nodes step as
    `pair_cell_cap` says. Lowering a node can make a neighbour drift finer, so it is repeated until
    every pair agrees (levels only fall, so it ends). Returns a new int32 array."""
    levels = np.array(levels, dtype=np.int32, copy=True)
    i, j = pairs[:, 0], pairs[:, 1]
    while True:
        drift = drift_levels(levels, cell_nodes, pair_cell_cap(levels, cell_nodes, pairs, loop_cells), loop_cells)
        target = np.minimum(np.minimum(levels[i], levels[j]), np.minimum(drift[i], drift[j]))
        differ = (levels[i] != target) | (levels[j] != target) | (drift[i] != target) | (drift[j] != target)
        if not differ.any():
            return levels
        np.minimum.at(levels, i[differ], target[differ])
        np.minimum.at(levels, j[differ], target[differ])


def cell_levels(node_levels: np.ndarray, cell_nodes: np.ndarray) -> np.ndarray:
    """int32 level of each cell (rows of cell_nodes): the coarsest level of its nodes. A cell is never
    coarser than its own stable step allows (node_levels puts every node at the finest level of its
    cells), and no node of it drifts slower than the cell loads it (LocalStepper.add_internal_force)."""
    return node_levels[cell_nodes].max(axis=1).astype(np.int32)


def region_cell_levels(arrays, node_levels: np.ndarray, cell_cap: np.ndarray | None = None) -> np.ndarray:
    """int32 level of each cell of a region (`ElementArrays`): `cell_levels`, made finer where
    `cell_cap` (per model cell) says. The serial stepper's parts (`level_components`) and an MPI rank's
    (pyfem/distributed_lts.py) split a region so."""
    levels = cell_levels(node_levels, arrays.cell_nodes)
    if cell_cap is not None:
        levels = np.minimum(levels, cell_cap[arrays.cells]).astype(np.int32)
    return levels


def row_cell_cap(node_levels: np.ndarray, cell_nodes: np.ndarray) -> np.ndarray:
    """The row split's cap of every model cell (rows of cell_nodes): the finest level of its nodes
    (LocalStepper.set_row_split)."""
    return node_levels[cell_nodes].min(axis=1)


class LevelComponents:
    """One region's element-loop cells split into kernel components by level, read as the region's one
    component (the interface `pyfem.elements.NonlinearRegions` uses for monitors, fields and run.json):
    parts [(rows, component)], rows the region's cell positions of each part."""

    def __init__(self, n_cells: int, n_points: int, parts: list):
        self.parts = parts
        self.n_points = n_points
        self.part_of = np.full(n_cells, -1, dtype=np.int64)
        self.local = np.zeros(n_cells, dtype=np.int64)
        for index, (rows, _) in enumerate(parts):
            self.part_of[rows] = index
            self.local[rows] = np.arange(len(rows))
        self.name = parts[0][1].name if parts else ""

    def _gather(self, method: str, points, shape_tail: tuple, dtype=float):
        if points is None:
            out = np.zeros((len(self.part_of), self.n_points, *shape_tail), dtype=dtype)
            for rows, component in self.parts:
                out[rows] = getattr(component, method)()
            return out
        points = np.asarray(points, dtype=np.int64)
        cells, point = np.divmod(points, self.n_points)
        out = np.zeros((len(points), *shape_tail), dtype=dtype)
        for index, (_, component) in enumerate(self.parts):
            mask = self.part_of[cells] == index
            if mask.any():
                local = self.local[cells[mask]] * self.n_points + point[mask]
                out[mask] = getattr(component, method)(local)
        return out

    def stress(self, points=None):
        return self._gather("stress", points, (6,))

    def damage(self, points=None):
        return self._gather("damage", points, ())

    def damage_type(self, points=None):
        return self._gather("damage_type", points, (), np.int32)

    def plastic_strain(self, points=None):
        return self._gather("plastic_strain", points, ())

    def crack_strain(self, points=None):
        return self._gather("crack_strain", points, ())

    def characteristic_length(self) -> np.ndarray:
        out = np.zeros(len(self.part_of))
        for rows, component in self.parts:
            out[rows] = component.characteristic_length()
        return out

    def dissipation(self) -> float:
        return float(sum(component.dissipation() for _, component in self.parts))

    def stored_energy(self) -> float:
        return float(sum(component.stored_energy() for _, component in self.parts))

    @property
    def owned_bytes(self) -> int:
        return int(sum(component.owned_bytes for _, component in self.parts))


class LevelPairs:
    """The contact pairs split into one kernel ContactPairs per level, read as the model's one set of
    pairs in its order (the interface pyfem/output.py uses): parts [(pairs, contact)], pairs the
    model's pair indices of each part."""

    def __init__(self, n_pairs: int, parts: list):
        self.parts = parts
        self.n_pairs = n_pairs

    def _gather(self, method: str, shape_tail: tuple, dtype=float, *args):
        out = np.zeros((self.n_pairs, *shape_tail), dtype=dtype)
        for rows, contact in self.parts:
            out[rows] = np.asarray(getattr(contact, method)(*args)).reshape(len(rows), *shape_tail)
        return out

    def state_counts(self):
        counts = np.zeros(4, dtype=np.int64)
        for _, contact in self.parts:
            counts += np.asarray(contact.state_counts(), dtype=np.int64)
        return counts

    def relative_displacement(self, u):
        return self._gather("relative_displacement", (3,), float, u)

    def tangential_force(self):
        return self._gather("tangential_force", (3,))

    def contact_force(self):
        return self._gather("contact_force", (3,))

    def normal_force(self):
        return self._gather("normal_force", ())

    def deterioration(self):
        return self._gather("deterioration", ())

    def state(self):
        return self._gather("state", (), np.int8)

    def bond_intact(self):
        return self._gather("bond_intact", (), np.uint8)


def level_pairs(arrays: dict, node_levels: np.ndarray, cell_nodes: np.ndarray, cell_cap: np.ndarray | None,
                loop_cells: np.ndarray | None, make_contact_pairs, rows: bool = False) -> tuple:
    """The pairs of `arrays` (pyfem.effects.contact_arguments) split by the level their nodes drift at
    (`drift_levels` with the cells' `pair_cell_cap`; equal for both nodes after
    `equalize_pair_drift`; in the row split, `rows`, a node drifts at its own level):
    (LevelPairs, [(ContactPairs, level)])."""
    pairs = np.asarray(arrays["pairs"])
    drift = (node_levels if rows else drift_levels(node_levels, cell_nodes, cell_cap, loop_cells))[pairs]
    if np.any(drift[:, 0] != drift[:, 1]):
        first = int(np.flatnonzero(drift[:, 0] != drift[:, 1])[0])
        raise ValueError(f"contact pair {first} joins nodes drifting at levels {drift[first].tolist()}: "
                         "the levels were not equalized (local_stepping.node_levels(..., pairs=))")
    parts, kernel_parts = [], []
    for level in np.unique(drift[:, 0]):
        rows = np.flatnonzero(drift[:, 0] == level)
        sliced = dict(arrays, pairs=np.ascontiguousarray(pairs[rows], dtype=np.int32),
                      **{key: np.ascontiguousarray(np.asarray(arrays[key])[rows])
                         for key in ("area", "normal", "static_force")})
        contact = make_contact_pairs(sliced)
        parts.append((rows, contact))
        kernel_parts.append((contact, int(level)))
    return LevelPairs(len(pairs), parts), kernel_parts


def level_components(nonlinear, node_levels: np.ndarray, cell_cap: np.ndarray | None = None,
                     initial_stress="scene") -> list:
    """Per region of `nonlinear` (NonlinearRegions), fresh components of its cells split by level
    (`cell_levels`, made finer where `cell_cap`, per model cell, says: `pair_cell_cap`), with the
    region's initial stress ("scene") or none (None): [(LevelComponents, [(component, level)])] in
    region order."""
    result = []
    for name, arrays in nonlinear.arrays.items():
        levels = region_cell_levels(arrays, node_levels, cell_cap)
        parts, kernel_parts = [], []
        for level in np.unique(levels):
            rows = np.flatnonzero(levels == level)
            component = nonlinear.new_component(name, initial_stress=initial_stress, rows=rows)
            parts.append((rows, component))
            kernel_parts.append((component, int(level)))
        result.append((LevelComponents(len(levels), arrays.weights.shape[1], parts), kernel_parts))
    return result


def load_component_parts(whole, parts: list) -> None:
    """Loads the state of `whole` (a component of a region's cells: the static stage's, rebased) into
    `parts` [(rows, component)] (`LevelComponents.parts`): each part's cells' per-point state and
    initial stress; the stored energy and dissipation go to the first part (the account is a sum)."""
    from pyfem.ranks import state_rows

    state = whole.save_state()
    n_cells = sum(len(rows) for rows, _ in parts)
    for index, (rows, component) in enumerate(parts):
        out = dict(component.save_state())
        out["state"] = np.ascontiguousarray(state_rows(state["state"], n_cells)[rows]).tobytes()
        sigma0 = state["initial_stress"]
        out["initial_stress"] = (np.ascontiguousarray(state_rows(sigma0, n_cells)[rows]).tobytes()
                                 if len(sigma0) else b"")
        for scalar in ("stored_energy", "dissipation"):
            out[scalar] = state[scalar] if index == 0 else np.zeros(1).tobytes()
        component.load_state(out)


def load_pair_parts(whole, parts: list, pair_nodes: np.ndarray) -> None:
    """Loads the state of `whole` (ContactPairs of all the model's pairs: the static stage's, rebased)
    into `parts` [(pair rows, ContactPairs)] (`LevelPairs.parts`); pair_nodes (n_pairs, 2)."""
    from pyfem.ranks import pair_blocks, state_rows, unique_slots

    state = whole.save_state()
    n_pairs = len(pair_nodes)
    node_force = np.frombuffer(state["node_force"], dtype=np.float64).reshape(-1, 3)
    for rows, contact in parts:
        out = dict(contact.save_state())
        for name in pair_blocks(state):
            out[name] = np.ascontiguousarray(state_rows(state[name], n_pairs)[rows]).tobytes()
        out["node_force"] = np.ascontiguousarray(node_force[unique_slots(pair_nodes, rows)]).tobytes()
        contact.load_state(out)


WORK_SUMS = ("blocks", "weighted_blocks", "points", "weighted_points", "pairs", "weighted_pairs", "nodes")
"""What the work model reads of a model (`work_sums`): sums over rows, cells and pairs, so that an MPI
rank's sums over its owned rows, counted cells and pairs add up to the whole model's."""


def work_sums(levels: np.ndarray, row_blocks: np.ndarray, cell_points: np.ndarray, cell_level: np.ndarray,
              pair_levels: np.ndarray) -> np.ndarray:
    """WORK_SUMS of the given rows (`levels` and `row_blocks`: each row's level and stiffness blocks),
    element-loop cells (their points and levels) and contact pairs (their levels): each count and the
    same weighted by 2^-level, the share of global stepping's steps it takes."""
    levels = np.asarray(levels, dtype=float)
    row_blocks = np.asarray(row_blocks, dtype=float)
    cell_points = np.asarray(cell_points, dtype=float)
    pair_levels = np.asarray(pair_levels, dtype=float)
    return np.array([row_blocks.sum(), np.sum(row_blocks * 2.0 ** -levels), cell_points.sum(),
                     np.sum(cell_points * 2.0 ** -np.asarray(cell_level, dtype=float)), len(pair_levels),
                     np.sum(2.0 ** -pair_levels), len(levels)])


def model_work_sums(levels: np.ndarray, cell_nodes: np.ndarray, nonlinear, stiffness, pairs: np.ndarray | None,
                    rows: bool = True) -> np.ndarray:
    """`work_sums` of the whole model: its matrix's rows, its element-loop cells at their level (the
    row split, `rows`: the finest of its nodes'; the column split: `cell_levels`, made finer around
    contact pairs by `pair_cell_cap`) and its pairs at their first node's level."""
    levels = np.asarray(levels)
    cell_level = np.zeros(len(cell_nodes), dtype=np.int64)
    points = np.zeros(len(cell_nodes))
    loop_cells = loop_cell_mask(nonlinear, len(cell_nodes))
    if loop_cells is not None:
        if rows:
            cell_level = levels[cell_nodes].min(axis=1).astype(np.int64)
        else:
            cap = pair_cell_cap(levels, cell_nodes, pairs, loop_cells) if pairs is not None and len(pairs) else None
            cell_level = cell_levels(levels, cell_nodes).astype(np.int64)
            if cap is not None:
                cell_level = np.minimum(cell_level, cap)
        for arrays in nonlinear.arrays.values():
            points[arrays.cells] = arrays.weights.shape[1]
    pair_levels = levels[np.asarray(pairs)[:, 0]] if pairs is not None and len(pairs) else np.zeros(0)
    return work_sums(levels, np.diff(stiffness.indptr), points, cell_level, pair_levels)


def predicted_speed_up(levels: np.ndarray, cell_nodes: np.ndarray, nonlinear, stiffness, pairs: np.ndarray | None,
                       time_step, phases_ms: dict, rows: bool = True) -> dict:
    """What local stepping would save on a model, from its rate levels and the measured phases of one
    global step (`phases_ms`): `speed_up_of` its `model_work_sums`."""
    levels = np.asarray(levels)
    return speed_up_of(model_work_sums(levels, cell_nodes, nonlinear, stiffness, pairs, rows), np.bincount(levels),
                       time_step, phases_ms, rows)


def speed_up_of(sums: np.ndarray, counts, time_step, phases_ms: dict, rows: bool = True) -> dict:
    """What local stepping would save on a model of these `work_sums` and nodes per level (`counts`),
    from the phases of one global step (`phases_ms`: ms per step of element_loop, stiffness, contact,
    update, input_forces). Each phase's work per simulated second relative to global stepping at
    time_step.dt:
    - element loop: its points weighted by 2^-k of their cell's level, times dt / dt_fine;
    - contact: the pairs weighted by their level;
    - the rest (stiffness kicks, drifts, input): the matrix's blocks weighted by their column's level.
    Returns {"speed_up" (global time / predicted local time per simulated second), "element_loop",
    "matrix", "contact" (the relative work of each), "levels" (nodes per level)}. A model: it leaves out
    the pair and interface rows stepped at their drift level and the kicks' own overhead: it over-predicts the
    measured speed-up by 7 % on the coarse case 1 and 23 % on the coarse case 3 (predicted / measured, the column
    split; docs/local_stepping.md "When it is on"), and by 27 % on the coarse case 3 in the row split (1.69x predicted from
    `check`'s steps at rest, 1.33x measured with the rock yielding; "Speed")."""
    work = dict(zip(WORK_SUMS, np.asarray(sums, dtype=float)))
    counts = np.trim_zeros(np.asarray(counts, dtype=np.int64), "b")
    fine_step, top = local_time_step(time_step, None, "row" if rows else "column", counts=counts)
    scale = time_step.dt / fine_step.dt
    matrix = scale * work["weighted_blocks"] / work["blocks"]
    loop = scale * work["weighted_points"] / work["points"] if work["points"] else 0.0
    contact = scale * work["weighted_pairs"] / work["pairs"] if work["pairs"] else 0.0
    # The kernel's phases only: a trial from rest spends milliseconds of "other" (first calls) that a
    # run does not (run.json: ~0.02 ms per step).
    global_ms = sum(phases_ms.get(name, 0.0) for name in ("element_loop", "stiffness", "contact", "update",
                                                           "input_forces"))
    local_ms = (phases_ms.get("element_loop", 0.0) * loop + phases_ms.get("contact", 0.0) * contact
                + sum(phases_ms.get(name, 0.0) for name in ("stiffness", "update", "input_forces")) * matrix)
    return {"speed_up": global_ms / local_ms if local_ms > 0 else math.inf, "element_loop": loop, "matrix": matrix,
            "contact": contact, "levels": [int(c) for c in counts]}


def estimated_phases_ms(sums: np.ndarray) -> dict:
    """A global step's phases (ms) by the work model COST_NS from a model's `work_sums`: the stiffness
    product by its blocks, the element loop by its points, the contact by its pairs, the update and
    input forces by the nodes; `speed_up_of`'s phases where nothing was timed."""
    work = dict(zip(WORK_SUMS, np.asarray(sums, dtype=float)))
    return {"stiffness": 1e-6 * COST_NS["block"] * work["blocks"],
            "element_loop": 1e-6 * COST_NS["point"] * work["points"],
            "contact": 1e-6 * COST_NS["pair"] * work["pairs"],
            "update": 1e-6 * COST_NS["node"] * work["nodes"]}


def auto_decision(levels: np.ndarray, cell_nodes: np.ndarray, nonlinear, stiffness, pairs: np.ndarray | None,
                  time_step, duration: float, rows: bool = True) -> tuple[bool, str]:
    """`time.local_stepping = "auto"` on the whole model: `decision_of` its `model_work_sums`."""
    levels = np.asarray(levels)
    if not np.any(levels):
        return decision_of(None, np.bincount(levels), time_step, duration, rows)
    return decision_of(model_work_sums(levels, cell_nodes, nonlinear, stiffness, pairs, rows), np.bincount(levels),
                       time_step, duration, rows)


def decision_of(sums: np.ndarray | None, counts, time_step, duration: float, rows: bool = True) -> tuple[bool, str]:
    """`time.local_stepping = "auto"`: whether local stepping pays on a model of these `work_sums` and
    nodes per level (`counts`) over this run, and why. The speed-up per step is `speed_up_of` with the
    phases of the work model (`estimated_phases_ms`); the set-up check (`check_stability`,
    STABILITY_STEPS global steps of the local stepper) is charged to the run, so a short run of a model
    that would pay in the long one stays with global stepping. On when the run's predicted speed-up is at
    least AUTO_PAYS. Returns (on, the reason for run.json and `check`)."""
    counts = np.trim_zeros(np.asarray(counts, dtype=np.int64), "b")
    if len(counts) <= 1:
        return False, ("\"auto\": off: one rate level on this model (every node's stable step within 2x of the "
                       "finest), nothing to gain")
    p = speed_up_of(sums, counts, time_step, estimated_phases_ms(sums), rows)
    fine_step, top = local_time_step(time_step, None, "row" if rows else "column", counts=counts)
    run_steps = max(1.0, duration / time_step.dt)  # global stepping's steps
    check_steps = STABILITY_STEPS * 2 ** top * fine_step.dt / time_step.dt  # the check, in those steps
    over_run = p["speed_up"] * run_steps / (run_steps + check_steps)
    on = over_run >= AUTO_PAYS
    reason = (f"\"auto\": {'on' if on else 'off'}: predicted {over_run:.2f}x the speed of global stepping over "
              f"the run ({p['speed_up']:.2f}x per step by the work model, {top + 1} rate level"
              f"{'s' if top else ''}; the set-up check {100 * check_steps / run_steps:.2g} % of the run's steps); "
              f"on from {AUTO_PAYS}x")
    return on, reason


def row_split(nonlinear, contact: bool) -> bool:
    """Whether the kernel steps this model by the row split (LocalStepper.set_row_split: every node at
    its own level with its whole stiffness row, a coarser neighbour read along its drift) rather than
    the column split: every model, element-loop regions (`nonlinear`) and contact pairs (`contact`)
    included. The row split's stresses where levels meet are global stepping's (the cavity test at
    safety 0.8: 0.53-1.07 % against 0.54-1.06 %; the column split 1.5-8.7 %, docs/local_stepping.md "The
    column split"); on the small case 3 with all physics its displacements are as close to global
    stepping's as global stepping at the same safety, and its energy balance 4.0e-5 of the work (the
    column split's 4.6e-5; docs/local_stepping.md "The energy account"), and its pairs
    step at their own nodes' rates instead of pinning the finest rate along every interface. The
    column split stays in the kernel for comparisons (workflows/lts_small_case3.py patches this)."""
    return True


def local_time_step(time_step, levels: np.ndarray | None, split: str = "column", counts=None):
    """The scene's TimeStep with whole global steps per output interval: dt_fine lowered (never
    raised) so that steps_per_output is a multiple of 2^L; its reason names the levels and the split
    ("row" or "column", `row_split`). `counts`: the nodes per level instead of `levels` (an MPI rank's
    owned nodes' summed over the ranks). Returns (TimeStep, L)."""
    counts = np.trim_zeros(np.asarray(np.bincount(levels) if counts is None else counts, dtype=np.int64), "b")
    top = len(counts) - 1
    ratio = 2 ** top
    interval = time_step.dt * time_step.steps_per_output
    global_steps = math.ceil(time_step.steps_per_output / ratio)
    steps_per_output = global_steps * ratio
    dt = interval / steps_per_output
    reason = re.sub(r"\d+ steps per output interval", f"{steps_per_output} fine steps per output interval",
                    time_step.reason)
    reason = (reason + f"; local time stepping: {top + 1} rate levels (nodes per level, finest first: "
              + ", ".join(str(int(c)) for c in counts) + f"), global step {dt * ratio:.6g} s, the {split} split")
    return dataclasses.replace(time_step, dt=dt, steps_per_output=steps_per_output, reason=reason), top


class LocalSteppingAdapter:
    """The kernel's LocalStepper behind the Stepper calls of `pyfem.solver.run` and `simulation_plan`:
    steps are counted in fine steps (dt_fine), whole global steps at a time."""

    def __init__(self, kernel, ratio: int):
        self.kernel = kernel
        self.ratio = ratio

    def add_provider(self, provider) -> None:
        self.kernel.add_provider(provider)

    def run(self, u, v, a, n_steps: int, t0: float) -> float:
        if n_steps % self.ratio:
            raise ValueError(f"local time stepping advances whole global steps of {self.ratio} fine steps, "
                             f"not {n_steps}")
        return self.kernel.run(u, v, a, n_steps // self.ratio, t0)

    def reset_energy(self, u, v, a, t0) -> None:
        """The kernel starts its account at the first run."""

    def energy(self) -> dict:
        return self.kernel.energy()

    def reactions(self):
        """The supports' reactions (k, 3) of the fixed and roller faces (LocalStepper.reactions)."""
        return self.kernel.reactions()

    def phase_seconds(self) -> dict:
        return self.kernel.phase_seconds()  # steps in fine steps, as the run loop counts them

    def reset_phase_seconds(self) -> None:
        self.kernel.reset_phase_seconds()

    def save_state(self, points: bool = True) -> dict:
        """The kernel's state beyond u, v, a, t (LocalStepper.save_state): name -> bytes."""
        return self.kernel.save_state(points)

    def load_state(self, state: dict, points: bool = True) -> None:
        self.kernel.load_state(state, points)


def check_stability(make_kernel, n_dofs: int, steps: int = STABILITY_STEPS, chunk: int = STABILITY_CHUNK,
                    seed: int = 0, rows: np.ndarray | None = None, state: np.ndarray | None = None) -> dict:
    """Iterates the LTS map on the user's model: `make_kernel()` gives a LocalStepper of the model
    (same matrix, mass, levels, step and boundary dashpots; element-loop cells without initial stress,
    so that a tiny state keeps their laws elastic: the linear map) without forces and without mass-
    proportional damping (damping only helps; the undamped map is the one to check). From a random
    displacement at rest, `steps` global steps in chunks of `chunk`; the energy (kinetic + strain) is
    read after each chunk. A stable map keeps it bounded (the dashpots drain it; the plain energy of
    the scheme oscillates around its conserved modified energy, by a factor up to ~3 near the
    stability limit); a mode the map amplifies by rho per global step grows it by rho^2 per step.
    Returns {"global_steps", "growth" (largest energy of the last third / of the first third),
    "growth_per_step" (its (1 / (2 n)) power, n the steps between the thirds' centres: the amplitude
    factor per global step), "stable", "seconds"}; stable when growth < STABILITY_RATIO, which
    catches amplitude growth of ~0.2 % per global step and more with the defaults. `rows`: the
    kernel steps these dofs of the model's n_dofs only (an MPI rank's share, owned then ghosts,
    pyfem.distributed_lts.check_stability_on_ranks), from the same random state. `state`: the start
    displacement (STABILITY_AMPLITUDE times a pseudo-random vector, the kernel's dofs) instead of the
    seeded one (the distributed model's, a function of the node coordinates:
    pyfem.distributed_lts.check_stability_on_ranks)."""
    start = time.perf_counter()
    kernel = make_kernel()
    rng = np.random.default_rng(seed)
    # A tiny state (1e-9 m): the map is linear in it wherever the element-loop laws stay elastic, and
    # their return mappings (every point yielding at a unit displacement) cost nothing extra.
    if state is not None:
        u = np.array(state, dtype=np.float64)
    else:
        u = STABILITY_AMPLITUDE * rng.standard_normal(n_dofs)
        if rows is not None:
            u = np.ascontiguousarray(u[rows])
    v, a = np.zeros(len(u)), np.zeros(len(u))
    energies = []
    t = 0.0
    for _ in range(max(1, steps // chunk)):
        t = kernel.run(u, v, a, chunk, t)
        energy = kernel.energy()
        energies.append(energy["kinetic"] + energy["strain"] + energy["internal_stored"])
    energies = np.asarray(energies)
    third = max(1, len(energies) // 3)
    first, last = energies[:third].max(), energies[-third:].max()
    growth = float(last / first) if first > 0 else math.inf
    if not math.isfinite(growth):
        growth = math.inf
    span = chunk * (len(energies) - third)  # global steps between the thirds' centres
    per_step = growth ** (1.0 / (2.0 * span)) if math.isfinite(growth) else math.inf
    return {"global_steps": int(chunk * len(energies)), "growth": growth, "growth_per_step": float(per_step),
            "stable": bool(growth < STABILITY_RATIO), "seconds": time.perf_counter() - start}


def lts_stability_line(report: dict) -> str:
    """check's line on the local time stepping map's stability check (pyfem/local_stepping.py)."""
    return (f"{'stable' if report['stable'] else 'UNSTABLE'} on this model: a random state's energy changed "
            f"{report['growth']:.3g}x over "
            f"{report['global_steps']} global steps (amplitude factor {report['growth_per_step']:.6f} per "
            f"step; unstable from 2x), {report['seconds']:.2f} s")

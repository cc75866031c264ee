"""Rock bolts and cables on the distributed model (pyfem/support.py's groups on the ranks' parts;
docs/scaling.md "The distributed model").

Every rank places the whole scene's groups (`pyfem.support.scene_groups`: a bolt node's host cell is
the whole model's preferred cell among every rank's, its host nodes numbered globally; a pattern's
surface gathered from every rank), so the bolts and their nodes are the same on any rank count.

A bolt is stepped whole, never split: its own displacements are condensed at every step from the
rock's axial displacement at all its nodes (a tridiagonal solve along the bolt, pyfem/support.py),
so a split bolt would need an exchange inside that solve. Each rank steps every bolt with a host node
it steps (`touched`), with all that bolt's host nodes among its nodes (extra ghosts beyond the index
map's, exchanged with the other ghosts after each step): the forces on the nodes it steps are then
the whole model's, summed bolt by bolt in the group's order, as the element loop's halo cells give
theirs. A bolt's energy, outputs and checkpoint state are those of one rank (`counted`: the rank
stepping its head's first host node); the others step it as halo (count_energy off). On one rank a
group is one kernel component of all its bolts, the serial model's.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from pyfem import _kernels

KINDS = ("counted", "halo")


@dataclasses.dataclass
class BoltPart:
    """One kernel component of a group's bolts on a rank: counted or halo, at one rate level (local
    time stepping; None: global stepping), the bolts (group numbering) and the archive prefix of its
    state in the stepper's save_state (set with the stepper)."""

    kind: str
    level: int | None
    bolts: np.ndarray
    component: object
    prefix: str = ""


@dataclasses.dataclass
class RankGroup:
    """One support group on a rank.

    Attributes:
        group: pyfem.support.SupportGroup of the whole model (host nodes global; no component).
        index: the group's index in the scene's order.
        touched: the bolts this rank steps (a host node stepped here), ascending.
        counted: of them, those whose energy, outputs and state are this rank's.
        halo: the others.
        host_local: (m, k) the kernel's local numbers of the host nodes of the touched bolts' nodes
            (-1 at other bolts' nodes).
        parts: the kernel's GroutedBolts of those bolts (`BoltPart`: one per kind, or with local time
            stepping one per kind and level).
    """

    group: object
    index: int
    touched: np.ndarray
    counted: np.ndarray
    halo: np.ndarray
    host_local: np.ndarray
    parts: list = dataclasses.field(default_factory=list)

    @property
    def name(self) -> str:
        return self.group.name

    @property
    def stage(self) -> str:
        return self.group.stage

    def bolts_of(self, kind: str) -> np.ndarray:
        return self.counted if kind == "counted" else self.halo

    def fresh(self, levels: np.ndarray | None = None) -> None:
        """New, unloaded kernel components of the counted and halo bolts (with local time stepping's
        `levels` per local node: one per level, each bolt at the finest level of its host nodes)."""
        self.parts = [BoltPart(kind, level, bolts, make_component(self, bolts))
                      for kind in KINDS for level, bolts in self.by_level(self.bolts_of(kind), levels)]

    def by_level(self, bolts: np.ndarray, levels: np.ndarray | None) -> list:
        """[(level, its bolts)] of `bolts` (level None without `levels`; none for no bolts)."""
        if not len(bolts):
            return []
        if levels is None:
            return [(None, bolts)]
        bolt_level = self.bolt_levels(levels)[bolts]
        return [(int(level), bolts[bolt_level == level]) for level in np.unique(bolt_level)]

    def bolt_levels(self, levels: np.ndarray) -> np.ndarray:
        """int per bolt of the group: the finest level (smallest) of its host nodes' (touched bolts only;
        the others -1), as a contact pair steps at the finer of its nodes' levels."""
        offsets = self.group.bolts.bolt_offsets
        found = np.full(len(offsets) - 1, -1, dtype=np.int64)
        for j in self.touched:
            found[j] = int(levels[self.host_local[offsets[j]:offsets[j + 1]]].min())
        return found

    def split_by_level(self, levels: np.ndarray) -> None:
        """The parts (global stepping's: the stage's, rebased) cut into one per level, their state
        carried over bolt by bolt (a group's scalars on the first part of each kind)."""
        old, self.parts = self.parts, []
        offsets = self.group.bolts.bolt_offsets
        for part in old:
            state = part.component.save_state()
            nodes_of = {j: np.arange(offsets[j], offsets[j + 1]) for j in part.bolts}
            node_rows = np.concatenate([np.full(len(nodes_of[j]), j) for j in part.bolts])
            segment_rows = np.concatenate([np.full(len(nodes_of[j]) - 1, j) for j in part.bolts])
            for index, (level, bolts) in enumerate(self.by_level(part.bolts, levels)):
                component = make_component(self, bolts)
                out = dict(component.save_state())
                for names, rows in ((PER_NODE, node_rows), (PER_SEGMENT, segment_rows)):
                    keep = np.isin(rows, bolts)
                    for name in names:
                        out[name] = np.ascontiguousarray(np.frombuffer(state[name], dtype=np.float64)[keep]).tobytes()
                for name in SCALARS:
                    out[name] = state[name] if index == 0 else np.zeros(1).tobytes()
                component.load_state(out)
                self.parts.append(BoltPart(part.kind, level, bolts, component))

    def kernel_components(self) -> list:
        """The parts in the stepper's order: counted, then halo (by level within each)."""
        return list(self.parts)


def serial_group(group, index: int, handed_over: bool) -> RankGroup:
    """A group of the serial model (pyfem.solver: one rank, host nodes local) as a `RankGroup` of all its
    bolts counted, for local time stepping's parts by level: with `handed_over` (a relaxation stage
    ran) and the group installed there, its one part is the stage's component (rebased), else none."""
    bolts = np.arange(len(group.bolts.bolt_offsets) - 1)
    found = RankGroup(group, index, bolts, bolts, np.zeros(0, dtype=np.int64),
                      np.ascontiguousarray(group.bolts.host_nodes, dtype=np.int32))
    if handed_over and group.stage == "static":
        found.parts = [BoltPart("counted", None, bolts, group.component)]
    return found


class LevelBolts:
    """A group's bolts stepped as several kernel components (local time stepping's levels) read as
    the one component pyfem.support and pyfem.support_output read (`WholeBolts`' calls, now)."""

    def __init__(self, rank_group: RankGroup) -> None:
        self.rank_group = rank_group
        offsets = rank_group.group.bolts.bolt_offsets
        self.n_bolts = len(offsets) - 1
        self.n_segments = int(offsets[-1]) - self.n_bolts

    def bolts_per_level(self) -> dict:
        """Local time stepping's level -> the group's bolts stepped there."""
        counts = {}
        for part in self.rank_group.parts:
            counts[int(part.level)] = counts.get(int(part.level), 0) + len(part.bolts)
        return dict(sorted(counts.items()))

    def _now(self) -> WholeBolts:
        return whole_view(self.rank_group, [counted_arrays(self.rank_group)]).bolts.component

    def axial_force(self):
        return self._now().axial_force()

    def peak_axial_force(self):
        return self._now().peak_axial_force()

    def bond_slip(self):
        return self._now().bond_slip()

    def plastic_slip(self):
        return self._now().plastic_slip()

    def plastic_strain(self):
        return self._now().plastic_strain()


def plan_lines(comm, rank_groups_: list) -> dict:
    """`check`'s line of each group on the distributed model (rank 0's; {} elsewhere): its bolts, length,
    segments, when installed and how the ranks share them. A collective."""
    shares = comm.gather([(len(rank_group.counted), len(rank_group.halo)) for rank_group in rank_groups_], root=0)
    if comm.rank != 0:
        return {}
    lines = {}
    for g, rank_group in enumerate(rank_groups_):
        group = rank_group.group
        stage = {"static": "in the static stage with static.install", "start": "at the start of the dynamic run"}[
            group.stage]
        per_rank = ", ".join(f"{counted} / {halo}" for counted, halo in (rank_shares[g] for rank_shares in shares))
        lines[group.name] = (
            f"{len(group.lines)} {group.settings['type']}s installed {stage}, {group.total_length:.4g} m in all, "
            f"segments of {group.segment:.3g} m; each stepped whole by every rank stepping one of its host nodes, "
            f"counted on one (counted / halo bolts per rank: {per_rank}); massless and condensed, they do not set "
            "the time step, whose estimate bounds the stiffness they add to their host nodes")
    return lines


def bolt_nodes(offsets: np.ndarray, bolts: np.ndarray) -> np.ndarray:
    """The bolt nodes of `bolts` (group numbering), bolt by bolt."""
    if not len(bolts):
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([np.arange(offsets[j], offsets[j + 1]) for j in bolts]).astype(np.int64)


def bolt_segments(offsets: np.ndarray, bolts: np.ndarray) -> np.ndarray:
    """The segments of `bolts` (group numbering: segment e = node k - bolt j), bolt by bolt."""
    if not len(bolts):
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([np.arange(offsets[j] - j, offsets[j + 1] - j - 1) for j in bolts]).astype(np.int64)


def touched_bolts(group, stepping_rank: np.ndarray, rank: int) -> np.ndarray:
    """The bolts with a host node that `rank` steps (`stepping_rank`: (m, k) per host node)."""
    offsets = group.bolts.bolt_offsets
    here = (stepping_rank == rank).any(axis=1)
    per_bolt = np.add.reduceat(here.astype(np.int64), offsets[:-1]) if len(here) else np.zeros(0, np.int64)
    return np.flatnonzero(per_bolt > 0)


def needed_nodes(groups: list, ownership, rank: int) -> np.ndarray:
    """The global host nodes of every bolt this rank steps (its part's extra ghosts among them)."""
    needed = [np.zeros(0, dtype=np.int64)]
    for group in groups:
        hosts = group.bolts.host_nodes
        bolts = touched_bolts(group, ownership.owner(hosts.ravel()).reshape(hosts.shape), rank)
        needed.append(hosts[bolt_nodes(group.bolts.bolt_offsets, bolts)].ravel())
    return np.unique(np.concatenate(needed)).astype(np.int64)


def rank_groups(groups: list, ownership, rank: int, local_nodes: np.ndarray) -> list[RankGroup]:
    """The rank's `RankGroup` of each group (components not made yet: `RankGroup.fresh`)."""
    from pyfem.distributed_pairs import positions

    found = []
    for index, group in enumerate(groups):
        bolts = group.bolts
        hosts = bolts.host_nodes
        stepping_rank = ownership.owner(hosts.ravel()).reshape(hosts.shape)
        touched = touched_bolts(group, stepping_rank, rank)
        head_rank = stepping_rank[bolts.bolt_offsets[:-1], 0]
        counted = touched[head_rank[touched] == rank]
        halo = touched[head_rank[touched] != rank]
        host_local = np.full(hosts.shape, -1, dtype=np.int32)
        nodes = bolt_nodes(bolts.bolt_offsets, touched)
        if len(nodes):
            host_local[nodes] = positions(local_nodes, hosts[nodes].ravel(), "bolt host nodes").reshape(-1, hosts.shape[1])
        found.append(RankGroup(group, index, touched, counted, halo, host_local))
    return found


def make_component(rank_group: RankGroup, bolts: np.ndarray):
    """The kernel's GroutedBolts of `bolts` of the group (their host nodes in the kernel's numbering)."""
    whole = rank_group.group.bolts
    nodes = bolt_nodes(whole.bolt_offsets, bolts)
    offsets = np.concatenate([[0], np.cumsum(np.diff(whole.bolt_offsets)[bolts])]).astype(np.int64)
    return _kernels.GroutedBolts(offsets, np.ascontiguousarray(whole.arc_length[nodes]),
                                 np.ascontiguousarray(whole.directions[bolts]),
                                 np.ascontiguousarray(rank_group.host_local[nodes], dtype=np.int32),
                                 np.ascontiguousarray(whole.host_weights[nodes]), **whole.parameters)


def bound_rows(rank_groups_: list, n_owned: int, n_local: int, stage: str | None = None) -> sp.bsr_matrix:
    """(3 n_owned, 3 n_local) the owned rows of pyfem.support.stiffness_bound of the groups (those
    installed at `stage` when given), in the kernel's numbering: the time step's and the relaxation's
    bound of the bolts' condensed stiffness."""
    total = sp.csr_matrix((3 * n_local, 3 * n_local))
    for rank_group in rank_groups_:
        if stage is not None and rank_group.stage != stage:
            continue
        whole = rank_group.group.bolts
        nodes = bolt_nodes(whole.bolt_offsets, rank_group.touched)
        if not len(nodes):
            continue
        k = whole.host_nodes.shape[1]
        bolt_of_node = np.repeat(np.arange(len(whole.bolt_offsets) - 1), np.diff(whole.bolt_offsets))[nodes]
        d = whole.directions[bolt_of_node]
        m = len(nodes)
        rows = np.repeat(np.arange(m), 3 * k)
        columns = (3 * rank_group.host_local[nodes][:, :, None].astype(np.int64) + np.arange(3)).reshape(m, -1).ravel()
        values = (whole.host_weights[nodes][:, :, None] * d[:, None, :]).reshape(m, -1).ravel()
        P = sp.csr_matrix((values, (rows, columns)), shape=(m, 3 * n_local))
        # The bond's k_b L_k (a fresh component's tributary lengths) and a cable's head plate.
        lengths = np.asarray(make_component(rank_group, rank_group.touched).bond_length())
        spring = whole.parameters["bond_stiffness"] * lengths
        head = whole.parameters["head_stiffness"]
        if head > 0.0:
            heads = np.concatenate([[0], np.cumsum(np.diff(whole.bolt_offsets)[rank_group.touched])])[:-1]
            spring[heads] += head
        total = total + (P.T @ sp.diags(spring) @ P).tocsr()
    return total[:3 * n_owned].tobsr(blocksize=(3, 3))


def add_rows(matrix: tuple, n_owned: int, extra: sp.bsr_matrix) -> tuple:
    """The kernel's (indptr, indices, blocks) of `matrix`'s owned rows plus `extra` (owned rows only:
    what the Gershgorin row sums and the power iteration read)."""
    indptr, indices, blocks = matrix
    n_local = len(indptr) - 1
    owned = sp.bsr_matrix((blocks[:indptr[n_owned]], indices[:indptr[n_owned]], indptr[:n_owned + 1]),
                          shape=(3 * n_owned, 3 * n_local))
    summed = (owned + extra).tobsr(blocksize=(3, 3))
    summed.sort_indices()
    tail = np.full(n_local - n_owned, summed.indptr[-1], dtype=np.int64)
    return (np.concatenate([summed.indptr.astype(np.int64), tail]), summed.indices.astype(np.int32),
            np.ascontiguousarray(summed.data))


# --- the whole group's state on one rank (outputs) ---------------------------------------------------

class WholeBolts:
    """What pyfem.support and pyfem.support_output read of a group's kernel component, the whole
    group's, from the arrays of the ranks counting its bolts."""

    def __init__(self, offsets: np.ndarray, arrays: dict) -> None:
        self.n_bolts = len(offsets) - 1
        self.n_segments = int(offsets[-1]) - self.n_bolts
        self._arrays = arrays

    def axial_force(self):
        return self._arrays["axial_force"]

    def peak_axial_force(self):
        return self._arrays["peak_axial_force"]

    def bond_slip(self):
        return self._arrays["bond_slip"]

    def plastic_slip(self):
        return self._arrays["plastic_slip"]

    def plastic_strain(self):
        return self._arrays["plastic_strain"]


NODE_ARRAYS = ("bond_slip", "plastic_slip")
SEGMENT_ARRAYS = ("axial_force", "peak_axial_force", "plastic_strain")


def counted_arrays(rank_group: RankGroup) -> dict:
    """The counted parts' per-node and per-segment arrays and where they go in the group."""
    whole = rank_group.group.bolts
    counted = [part for part in rank_group.parts if part.kind == "counted"]
    bolts = np.concatenate([part.bolts for part in counted] or [np.zeros(0, dtype=np.int64)]).astype(np.int64)
    out = {"nodes": bolt_nodes(whole.bolt_offsets, bolts), "segments": bolt_segments(whole.bolt_offsets, bolts),
           "bolts": bolts, "levels": np.concatenate([np.full(len(part.bolts), -1 if part.level is None else part.level)
                                                      for part in counted] or [np.zeros(0, dtype=np.int64)])}
    for name in NODE_ARRAYS + SEGMENT_ARRAYS:
        out[name] = np.concatenate([np.array(getattr(part.component, name)(), dtype=float) for part in counted]
                                   or [np.zeros(0)])
    return out


def whole_view(rank_group: RankGroup, pieces: list):
    """The whole group (pyfem.support.SupportGroup) with a `WholeBolts` component from every rank's
    `counted_arrays` (`pieces`)."""
    whole = rank_group.group.bolts
    n_nodes = int(whole.bolt_offsets[-1])
    n_segments = n_nodes - (len(whole.bolt_offsets) - 1)
    arrays = {name: np.zeros(n_nodes) for name in NODE_ARRAYS}
    arrays.update({name: np.zeros(n_segments) for name in SEGMENT_ARRAYS})
    for piece in pieces:
        for name in NODE_ARRAYS:
            arrays[name][piece["nodes"]] = piece[name]
        for name in SEGMENT_ARRAYS:
            arrays[name][piece["segments"]] = piece[name]
    bolts = dataclasses.replace(whole, component=WholeBolts(whole.bolt_offsets, arrays))
    view = dataclasses.replace(rank_group.group, bolts=bolts)
    view.bolt_levels = np.full(len(whole.bolt_offsets) - 1, -1, dtype=np.int64)  # local time stepping's (-1: none)
    for piece in pieces:
        view.bolt_levels[piece["bolts"]] = piece["levels"]
    return view


def gather_groups(comm, rank_groups_: list, root: int = 0) -> list | None:
    """On `root` the whole groups (`whole_view`) of the ranks' counted bolts now; None elsewhere. A collective."""
    gathered = comm.gather([counted_arrays(rank_group) for rank_group in rank_groups_], root=root)
    if comm.rank != root:
        return None
    return [whole_view(rank_group, [pieces[g] for pieces in gathered]) for g, rank_group in enumerate(rank_groups_)]


def local_view(rank_groups_: list) -> list:
    """The whole groups with this rank's counted bolts' arrays (zero elsewhere): a bolt monitor's
    row where its bolt is counted."""
    return [whole_view(rank_group, [counted_arrays(rank_group)]) for rank_group in rank_groups_]


def monitor_rows(t: float, monitors: list, rank_groups_: list) -> list:
    """[(monitor index, its row)] of the bolt monitors whose bolt this rank counts."""
    mine = [j for j, monitor in enumerate(monitors) if monitor.bolt in set(rank_groups_[monitor.group].counted.tolist())]
    if not mine:
        return []
    view = local_view(rank_groups_)
    return [(j, monitors[j].row(t, view)) for j in mine]


# --- checkpoints: keyed by the bolt nodes' positions and directions ---------------------------------

PER_NODE = ("w", "plastic_slip", "bond_force", "ubar", "ubar_reference", "bond_force_reference")
PER_SEGMENT = ("plastic_strain", "axial_force", "peak_axial_force")
SCALARS = ("stored_energy", "dissipation", "stored_reference")


def node_keys(rank_group: RankGroup, nodes: np.ndarray) -> np.ndarray:
    """(len(nodes), 7) int64 keys of bolt nodes: the group, the position (1 um), the bolt's axis (1e-6)."""
    from pyfem.ranks import point_keys

    whole = rank_group.group.bolts
    bolt_of_node = np.repeat(np.arange(len(whole.bolt_offsets) - 1), np.diff(whole.bolt_offsets))[nodes]
    return np.column_stack([np.full(len(nodes), rank_group.index, dtype=np.int64), point_keys(whole.positions[nodes]),
                            np.round(whole.directions[bolt_of_node] * 1e6).astype(np.int64)])


def segment_first_nodes(offsets: np.ndarray, bolts: np.ndarray) -> np.ndarray:
    if not len(bolts):
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([np.arange(offsets[j], offsets[j + 1] - 1) for j in bolts]).astype(np.int64)


def rank_state(rank_groups_: list) -> dict:
    """This rank's counted bolts' state for a checkpoint (each counted part's committed state): per
    node and per segment, keyed by position; the group's scalars summed over its counted parts."""
    out = {}
    for rank_group in rank_groups_:
        g = rank_group.index
        counted = [part for part in rank_group.parts if part.kind == "counted"]
        if not counted:
            continue
        offsets = rank_group.group.bolts.bolt_offsets
        bolts = np.concatenate([part.bolts for part in counted]).astype(np.int64)
        out[f"bolts/{g}/node_keys"] = node_keys(rank_group, bolt_nodes(offsets, bolts))
        out[f"bolts/{g}/segment_keys"] = node_keys(rank_group, segment_first_nodes(offsets, bolts))
        states = [part.component.save_state() for part in counted]
        for name in PER_NODE + PER_SEGMENT:
            out[f"bolts/{g}/{name}"] = np.concatenate([np.frombuffer(state[name], dtype=np.float64) for state in states])
        for name in SCALARS:
            out[f"bolts/{g}/{name}"] = np.array([sum(float(np.frombuffer(state[name], dtype=np.float64).sum())
                                                     for state in states)])
    return out


def load_state(rank_groups_: list, state: dict, files: list, comm) -> dict:
    """The checkpoint's bolt state (every rank file of it, `files`) into `state` (the stepper's, at the
    parts' prefixes): each part's nodes and segments by their keys; a group's scalars (stored energy,
    dissipation, the rebased zero: sums over its bolts) on the first counted part of the lowest rank
    counting its bolts, zero elsewhere (the energy account is a sum over the ranks). Returns {prefix:
    component} of the parts (a local stepper not started yet loads them one by one)."""
    from pyfem.ranks import rows_of

    counting = comm.allgather([rank_group.index for rank_group in rank_groups_
                               if any(part.kind == "counted" for part in rank_group.parts)])
    loaded = {}
    for rank_group in rank_groups_:
        g = rank_group.index
        having = [f for f in files if f"bolts/{g}/node_keys" in f]
        if not having or not rank_group.parts:
            continue
        node_data = {name: np.concatenate([f[f"bolts/{g}/{name}"] for f in having]) for name in PER_NODE}
        segment_data = {name: np.concatenate([f[f"bolts/{g}/{name}"] for f in having]) for name in PER_SEGMENT}
        all_nodes = np.concatenate([f[f"bolts/{g}/node_keys"] for f in having])
        all_segments = np.concatenate([f[f"bolts/{g}/segment_keys"] for f in having])
        totals = {name: sum(float(f[f"bolts/{g}/{name}"].sum()) for f in having) for name in SCALARS}
        first = min(q for q, groups in enumerate(counting) if g in groups)
        offsets = rank_group.group.bolts.bolt_offsets
        taken = False
        for part in rank_group.parts:
            rows = rows_of(all_nodes, node_keys(rank_group, bolt_nodes(offsets, part.bolts)), f"bolt nodes of group {g}")
            for name in PER_NODE:
                state[part.prefix + name] = np.ascontiguousarray(node_data[name][rows]).tobytes()
            rows = rows_of(all_segments, node_keys(rank_group, segment_first_nodes(offsets, part.bolts)),
                           f"bolt segments of group {g}")
            for name in PER_SEGMENT:
                state[part.prefix + name] = np.ascontiguousarray(segment_data[name][rows]).tobytes()
            takes = part.kind == "counted" and comm.rank == first and not taken
            taken = taken or takes
            for name in SCALARS:
                state[part.prefix + name] = np.array([totals[name] if takes else 0.0]).tobytes()
            loaded[part.prefix] = part.component
    return loaded

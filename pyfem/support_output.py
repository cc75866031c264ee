"""Pictures and ParaView files of the rock bolts and cables (docs/outputs: support.png, support.xdmf).

At the end of a run with `[support.NAME]` groups (and after a static stage that installed some,
in static/):

    plots/support.png, static/support.png   axial force along the bolts of the monitoring section
                         (`section_bolts`), s from the head, one panel per group, yielded
                         segments marked; the section is the plane y = the first monitor's y
                         (without monitors: the middle of the model's y extent)
    support.xdmf (+ support.h5), static/support.xdmf (+ .h5)   every group's bolts as line cells
                         (one per segment): point data axial_force (N, the mean of the node's
                         segments) and bond_slip (m); cell data segment_axial_force (N),
                         yielded (1/0), group (index in the scene's order), bolt (index in its
                         group), and at the end peak_axial_force (N)

`bolt_state` takes a group's state at one moment (the static stage keeps the one it hands over).

A `[[bolt_monitor]]` (`locate_bolt_monitors`) reports the segment whose middle is nearest its point:
bolts/NAME.csv, one row per sample, t, axial_force (N, tension positive), bond_slip (m, the mean of
the segment's two nodes'), plastic_strain (the segment's); run.json "bolt_monitors" says which
segment and its peak |axial force| over the samples.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

FEW_BOLTS = 12
"""A group of at most this many bolts is plotted whole; a larger one shows its bolts nearest the
monitoring section's plane."""

LABELLED_BOLTS = 8
"""A panel of at most this many bolts names each in its legend; more: a colour bar from first to last."""

SECTION_TOLERANCE = 0.01
"""m: bolts within this of the nearest one's distance from the section plane are in the section."""


@dataclasses.dataclass
class BoltState:
    """One group's bolts at one moment.

    Attributes:
        name: the group's name ([support.NAME]).
        bolt_offsets: (b + 1,) bolt j has the bolt nodes [offsets[j], offsets[j + 1]).
        arc_length: (m,) s from the head (m).
        positions: (m, 3) the bolt nodes (m).
        axial_force: (m - b,) per segment (N, tension positive), segment e = node k - bolt.
        bond_slip: (m,) per node (m).
        yielded: (m - b,) bool: the segment has yielded (plastic strain not zero).
        yield_force: the group's axial capacity (N).
        peak_axial_force: (m - b,) the largest |axial force| so far (N), or None.
    """

    name: str
    bolt_offsets: np.ndarray
    arc_length: np.ndarray
    positions: np.ndarray
    axial_force: np.ndarray
    bond_slip: np.ndarray
    yielded: np.ndarray
    yield_force: float
    peak_axial_force: np.ndarray | None = None

    @property
    def n_bolts(self) -> int:
        return len(self.bolt_offsets) - 1

    def segments(self, bolt: int) -> slice:
        """The bolt's segments in the per-segment arrays."""
        return slice(int(self.bolt_offsets[bolt]) - bolt, int(self.bolt_offsets[bolt + 1]) - bolt - 1)

    def nodes(self, bolt: int) -> slice:
        return slice(int(self.bolt_offsets[bolt]), int(self.bolt_offsets[bolt + 1]))


def bolt_state(group, peak: bool = True) -> BoltState:
    """The state of a pyfem.support.SupportGroup now (copies)."""
    component, bolts = group.component, group.bolts
    return BoltState(group.name, np.array(bolts.bolt_offsets), np.array(bolts.arc_length), np.array(bolts.positions),
                     np.array(component.axial_force(), dtype=float), np.array(component.bond_slip(), dtype=float),
                     np.asarray(component.plastic_strain()) != 0.0, float(group.settings["yield_force"]),
                     np.array(component.peak_axial_force(), dtype=float) if peak else None)


# ---------------------------------------------------------------------------------------------
# The monitoring section
# ---------------------------------------------------------------------------------------------

def section_y(scene: dict, model) -> tuple[float, str]:
    """The monitoring section's plane y = y0 and how it was chosen: the first [[monitor]]'s y, else
    the middle of the model's y extent."""
    monitors = scene.get("monitor") or []
    if monitors:
        return float(monitors[0]["point"][1]), f"monitor {monitors[0]['name']}"
    y = np.asarray(model.node_coords)[:, 1]
    return 0.5 * float(y.min() + y.max()), "the model's middle"


def section_bolts(state: BoltState, y0: float, few: int = FEW_BOLTS,
                  tolerance: float = SECTION_TOLERANCE) -> np.ndarray:
    """Indices of the group's bolts in the monitoring section y = y0: all of a group of at most
    `few` bolts, else those whose distance from the plane (0 for a bolt crossing it, else its nearest
    node's |y - y0|) is within `tolerance` of the smallest (a pattern's row nearest the plane); of two
    rows either side of the plane at that distance, the one on the -y side."""
    if state.n_bolts <= few:
        return np.arange(state.n_bolts)
    distance, side = np.empty(state.n_bolts), np.zeros(state.n_bolts)
    for bolt in range(state.n_bolts):
        y = state.positions[state.nodes(bolt), 1] - y0
        crossing = y.min() <= 0.0 <= y.max()
        distance[bolt] = 0.0 if crossing else float(np.abs(y).min())
        side[bolt] = 0.0 if crossing else np.sign(y[0])
    nearest = distance <= distance.min() + tolerance
    if np.any(nearest & (side < 0.0)) and np.any(nearest & (side > 0.0)):
        nearest &= side <= 0.0
    return np.flatnonzero(nearest)


def plot_section(png_path, states: list[BoltState], y0: float, where: str, title: str = "") -> dict:
    """The axial force along the section's bolts (`section_bolts`), one panel per group with a bolt
    that has a segment; yielded segments marked. Returns {group: {"bolts": [...], "yielded_segments": n}}
    of what it drew ({} and no file when there is nothing to draw)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drawn = [(state, section_bolts(state, y0)) for state in states]
    drawn = [(state, bolts) for state, bolts in drawn if len(bolts)]
    if not drawn:
        return {}
    png_path = Path(png_path)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    figure, axes = plt.subplots(len(drawn), 1, figsize=(8.0, 3.2 * len(drawn) + 0.6), squeeze=False)
    report = {}
    for axis, (state, bolts) in zip(axes[:, 0], drawn):
        colours = plt.cm.viridis(np.linspace(0.0, 0.9, len(bolts)))
        yielded_count = 0
        labelled = len(bolts) <= LABELLED_BOLTS
        for colour, bolt in zip(colours, bolts):
            s = state.arc_length[state.nodes(bolt)]
            force = state.axial_force[state.segments(bolt)] / 1e3
            # The force is constant along a segment: a step line from the head to the tip.
            axis.plot(np.repeat(s, 2)[1:-1], np.repeat(force, 2), color=colour, lw=1.0,
                      label=f"bolt {bolt}" if labelled else None)
            yielded = state.yielded[state.segments(bolt)]
            if np.any(yielded):
                middles = 0.5 * (s[1:] + s[:-1])
                axis.plot(middles[yielded], force[yielded], "x", color="red", ms=6,
                          label="yielded segment" if yielded_count == 0 else None)
                yielded_count += int(np.count_nonzero(yielded))
        largest = max(float(np.max(np.abs(state.axial_force[state.segments(b)]), initial=0.0)) for b in bolts)
        yield_note = ""
        if largest >= 0.3 * state.yield_force:
            for sign in (1.0, -1.0):
                axis.axhline(sign * state.yield_force / 1e3, color="grey", ls="--", lw=0.8,
                             label="yield force" if sign > 0 else None)
        else:  # far below: the lines would flatten the profiles
            yield_note = f"; yield force {state.yield_force / 1e3:.4g} kN"
        if not labelled:
            mappable = plt.cm.ScalarMappable(cmap=plt.cm.viridis, norm=plt.Normalize(0.0, 1.0 / 0.9))
            bar = figure.colorbar(mappable, ax=axis, pad=0.01)
            bar.set_ticks([0.0, 1.0])
            bar.set_ticklabels([f"bolt {bolts[0]}", f"bolt {bolts[-1]}"])
        rows = np.unique(np.round(state.positions[np.concatenate([np.arange(state.bolt_offsets[b], state.bolt_offsets[b + 1])
                                                                   for b in bolts]), 1], 2))
        at = f"y = {rows[0]:.4g} m" if len(rows) == 1 else f"y {rows.min():.4g} to {rows.max():.4g} m"
        axis.set_title(f"{state.name}: {len(bolts)} of {state.n_bolts} bolts ({at}; section y = {y0:.4g} m, {where})"
                       + (f", {yielded_count} segments yielded" if yielded_count else "") + yield_note, fontsize=9)
        axis.set_xlabel("s from the head (m)")
        axis.set_ylabel("axial force (kN)")
        axis.grid(True, alpha=0.3)
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=8, loc="best")
        report[state.name] = {"bolts": [int(b) for b in bolts], "yielded_segments": yielded_count}
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    figure.savefig(png_path, dpi=110)
    plt.close(figure)
    return report


# ---------------------------------------------------------------------------------------------
# ParaView
# ---------------------------------------------------------------------------------------------

def node_axial_force(state: BoltState) -> np.ndarray:
    """(m,) the mean axial force of each bolt node's segments (N): one segment at a bolt's ends."""
    force = np.zeros(len(state.arc_length))
    count = np.zeros(len(state.arc_length))
    for bolt in range(state.n_bolts):
        nodes, segments = state.nodes(bolt), state.axial_force[state.segments(bolt)]
        first = nodes.start
        force[first:nodes.stop - 1] += segments
        force[first + 1:nodes.stop] += segments
        count[first:nodes.stop - 1] += 1
        count[first + 1:nodes.stop] += 1
    return force / count


def write_xdmf(path, states: list[BoltState], time: float) -> None:
    """path (.xdmf) and its .h5 beside it: the groups' bolts as line cells (one per segment), one
    time `time` (s; after the stage: 0, the dynamic run's start)."""
    import h5py
    import meshio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    points, lines, cell_data, point_data = [], [], {}, {"axial_force": [], "bond_slip": []}
    names = ("segment_axial_force", "yielded", "group", "bolt") + (
        ("peak_axial_force",) if all(state.peak_axial_force is not None for state in states) else ())
    columns = {name: [] for name in names}
    offset = 0
    for index, state in enumerate(states):
        points.append(state.positions)
        point_data["axial_force"].append(node_axial_force(state))
        point_data["bond_slip"].append(state.bond_slip)
        for bolt in range(state.n_bolts):
            nodes = np.arange(state.nodes(bolt).start, state.nodes(bolt).stop) + offset
            lines.append(np.column_stack([nodes[:-1], nodes[1:]]))
            columns["bolt"].append(np.full(len(nodes) - 1, bolt, dtype=float))
        columns["segment_axial_force"].append(state.axial_force)
        columns["yielded"].append(state.yielded.astype(float))
        columns["group"].append(np.full(len(state.axial_force), index, dtype=float))
        if "peak_axial_force" in columns:
            columns["peak_axial_force"].append(state.peak_axial_force)
        offset += len(state.positions)
    cell_data = {name: [np.concatenate(values)] for name, values in columns.items()}
    writer = meshio.xdmf.TimeSeriesWriter(str(path))
    # As pyfem/output.py's fields: the .h5 beside the .xdmf, which names it without a folder.
    writer.h5_filename = path.with_suffix(".h5").name
    writer.h5_file = h5py.File(path.with_suffix(".h5"), "w")
    try:
        writer.write_points_cells(np.concatenate(points), [("line", np.concatenate(lines).astype(np.int64))])
        writer.write_data(float(time), point_data={name: np.concatenate(values) for name, values in point_data.items()},
                          cell_data=cell_data)
    finally:
        writer.__exit__(None, None, None)


def write_outputs(folder, states: list[BoltState], scene: dict, model, time: float, png_name: str,
                  title: str = "") -> dict:
    """support.xdmf (+ .h5) and `png_name` in the folder: what `plot_section` drew."""
    folder = Path(folder)
    write_xdmf(folder / "support.xdmf", states, time)
    y0, where = section_y(scene, model)
    return plot_section(folder / png_name, states, y0, where, title)


# ---------------------------------------------------------------------------------------------
# Bolt monitors ([[bolt_monitor]])
# ---------------------------------------------------------------------------------------------

BOLT_MONITOR_COLUMNS = ["t", "axial_force", "bond_slip", "plastic_strain"]


@dataclasses.dataclass
class BoltMonitor:
    """The segment a [[bolt_monitor]] reports.

    Attributes:
        name: the monitor's name (bolts/NAME.csv).
        group: index of its support group in Simulation.support.
        bolt: the bolt in the group; segment: the segment in the group's per-segment arrays;
        node: its first bolt node (the second is node + 1).
        s: the segment middle's distance from the head (m); middle: its position (m).
        distance: from the monitor's point to the middle (m).
    """

    name: str
    group: int
    bolt: int
    segment: int
    node: int
    s: float
    middle: list
    distance: float

    def row(self, t: float, groups: list) -> list:
        """[t, axial force, bond slip, plastic strain] of the segment now."""
        component = groups[self.group].component
        slip = component.bond_slip()
        return [t, float(component.axial_force()[self.segment]), 0.5 * float(slip[self.node] + slip[self.node + 1]),
                float(component.plastic_strain()[self.segment])]

    def where(self, groups: list) -> dict:
        return {"group": groups[self.group].name, "bolt": self.bolt, "s": self.s, "segment_middle": self.middle,
                "distance": self.distance}


def locate_bolt_monitors(scene, groups: list) -> list[BoltMonitor]:
    """The segment of each [[bolt_monitor]]: the one whose middle is nearest its point, among its group's
    (or every group's) segments. Warns (scene.warn) when that is farther than the segment's length."""
    monitors = []
    for monitor in scene.get("bolt_monitor") or []:
        point = np.asarray(monitor["point"], dtype=float)
        best = None
        for index, group in enumerate(groups):
            if monitor["group"] is not None and group.name != monitor["group"]:
                continue
            bolts = group.bolts
            for bolt in range(len(bolts.bolt_offsets) - 1):
                nodes = np.arange(bolts.bolt_offsets[bolt], bolts.bolt_offsets[bolt + 1] - 1)
                middles = 0.5 * (bolts.positions[nodes] + bolts.positions[nodes + 1])
                distance = np.linalg.norm(middles - point, axis=1)
                k = int(np.argmin(distance))
                if best is None or distance[k] < best[0]:
                    length = float(bolts.arc_length[nodes[k] + 1] - bolts.arc_length[nodes[k]])
                    best = (float(distance[k]), index, bolt, int(nodes[k]), middles[k], length,
                            0.5 * float(bolts.arc_length[nodes[k]] + bolts.arc_length[nodes[k] + 1]))
        distance, index, bolt, node, middle, length, s = best
        found = BoltMonitor(monitor["name"], index, bolt, node - bolt, node, s, middle.tolist(), distance)
        if distance > length:
            scene.warn(f"bolt_monitor '{monitor['name']}' at {list(monitor['point'])} is {distance:.3g} m from the "
                       f"nearest bolt segment's middle (bolt {bolt} of group {groups[index].name!r}, at "
                       f"{[round(x, 3) for x in middle.tolist()]}), which it reports")
        monitors.append(found)
    return monitors

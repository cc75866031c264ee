"""Rock bolts and anchor cables placed in a model's mesh (docs/method.md "Rock bolts and cables").

A group of straight bolts given as lines head -> tip is cut into segments of about `segment` m;
each bolt node is located in the rock mesh (the model's point_weights: host cell and the
interpolation weights of its nodes, exact for every field of the space) and the group becomes one
kernel GroutedBolts component. Not yet read from a scene: the scene keys, the static stage's
installation and the outputs come next.
"""
import dataclasses
import math

import numpy as np

from pyfem import _kernels


@dataclasses.dataclass
class BoltGroup:
    """One group of bolts in a model: the kernel component and where its nodes are."""
    component: object          # _kernels.GroutedBolts
    bolt_offsets: np.ndarray   # (b + 1,) int64: bolt j has the bolt nodes [offsets[j], offsets[j + 1])
    arc_length: np.ndarray     # (m,) s from the head (m)
    positions: np.ndarray      # (m, 3) coordinates of the bolt nodes (m)
    directions: np.ndarray     # (b, 3) unit axis head -> tip


def discretise_lines(lines, segment: float, free_length: float = 0.0):
    """Bolt nodes of straight lines [x0, y0, z0, x1, y1, z1] (head to tip, m): each cut into
    ceil(length / segment) equal segments, or, with a free length, the free part and the grouted
    part cut separately so that a node falls on the end of the free length. Returns the offsets,
    the arc lengths, the positions and the unit directions."""
    lines = np.asarray(lines, dtype=np.float64).reshape(-1, 6)
    offsets, arcs, positions, directions = [0], [], [], []
    for head, tip in zip(lines[:, :3], lines[:, 3:]):
        length = float(np.linalg.norm(tip - head))
        if not length > 0.0:
            raise ValueError(f"lines: a bolt from {head.tolist()} to {tip.tolist()} has no length")
        if free_length >= length:
            raise ValueError(f"free_length: {free_length} m is not shorter than a bolt of {length:.6g} m")
        parts = [(0.0, free_length), (free_length, length)] if free_length > 0.0 else [(0.0, length)]
        s = [0.0]
        for lo, hi in parts:
            n = max(1, math.ceil((hi - lo) / segment - 1e-9))
            s.extend(lo + (hi - lo) * np.arange(1, n + 1) / n)
        s = np.array(s)
        s[-1] = length
        direction = (tip - head) / length
        arcs.append(s)
        positions.append(head + s[:, None] * direction)
        directions.append(direction)
        offsets.append(offsets[-1] + s.size)
    return (np.array(offsets, dtype=np.int64), np.concatenate(arcs), np.concatenate(positions),
            np.array(directions))


def bolt_group(model, lines, *, diameter: float, E: float, yield_force: float, bond_stiffness: float,
               bond_strength: float, segment: float, pretension: float = 0.0, free_length: float = 0.0,
               head_stiffness: float = 0.0) -> BoltGroup:
    """The bolts along `lines` in `model` (pyfem.operators.Model; every node inside its mesh) with
    the parameters of a support group (SI units; steel area pi diameter^2 / 4)."""
    offsets, arcs, positions, directions = discretise_lines(lines, segment, free_length)
    host_nodes, host_weights = model.point_weights(positions)
    component = _kernels.GroutedBolts(
        offsets, arcs, directions, host_nodes, host_weights,
        axial_stiffness=E * math.pi * diameter**2 / 4.0, yield_force=yield_force,
        bond_stiffness=bond_stiffness, bond_strength=bond_strength, pretension=pretension,
        free_length=free_length, head_stiffness=head_stiffness)
    return BoltGroup(component, offsets, arcs, positions, directions)


def segment_rows(group: BoltGroup, name: str) -> list[tuple]:
    """One row per segment: (group, bolt, s, x, y, z, axial_force, bond_slip, peak_axial_force),
    s and the position at the segment's middle, the bond slip the mean of its two nodes' (m)."""
    component = group.component
    force, peak = component.axial_force(), component.peak_axial_force()
    slip = component.bond_slip()
    rows = []
    for bolt in range(len(group.bolt_offsets) - 1):
        begin, end = group.bolt_offsets[bolt], group.bolt_offsets[bolt + 1]
        for k in range(begin, end - 1):
            e = k - bolt
            middle = 0.5 * (group.positions[k] + group.positions[k + 1])
            rows.append((name, bolt, 0.5 * (group.arc_length[k] + group.arc_length[k + 1]), *middle.tolist(),
                         float(force[e]), 0.5 * float(slip[k] + slip[k + 1]), float(peak[e])))
    return rows

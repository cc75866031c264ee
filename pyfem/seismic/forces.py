"""Viscoelastic boundary operators and equivalent seismic input forces (paper Eq. 6).

At a boundary node with lumped face integrals (ARCHITECTURE, BoundaryFace) the
viscoelastic boundary (docs/method.md section 5, Liu Jingbo et al. 2005) is
    K_b = (G_int / R) (alpha_N n n^T + alpha_T (I - n n^T)),
    C_b = rho_cp_int n n^T + rho_cs_int (I - n n^T),
with G_int = int phi G ds, rho_cp_int = int phi rho c_p ds, rho_cs_int likewise and
R the distance of the face from the scattering centre.  The input force that makes
the boundary transparent to the free field is f = K_b u_ff + C_b v_ff + A sigma_ff n
with the total free field.  For a free-field slot u = a y(t - tau), sigma = S y'(t - tau):
    f = sum_slots P y(t - tau) + Q y'(t - tau),  P = K_b a,  Q = C_b a + A S n.

Boundary types (per face, `BoundaryFace.kind`, or one type for all faces):
"viscoelastic" (springs and dashpots), "viscous" (dashpots only, K_b = 0), and
"fixed", "roller" (kernel constraints, docs/boundaries.md) and "free" (traction-free):
these three have no springs, no dashpots and no input forces (they are NOT "boundary
held at the free field"). Only viscoelastic and viscous faces carry seismic input.
"""
from __future__ import annotations

import numpy as np

BOUNDARY_TYPES = ("viscoelastic", "viscous", "fixed", "roller", "free")
# Faces of these types carry springs, dashpots and the seismic input.
INPUT_TYPES = ("viscoelastic", "viscous")


def face_kind(face, boundary_type=None):
    """The boundary type of `face`: `boundary_type` when given, else the face's own `kind`."""
    kind = boundary_type if boundary_type is not None else getattr(face, "kind", "viscoelastic")
    _check_boundary_type(kind)
    return kind


def _check_boundary_type(boundary_type):
    if boundary_type not in BOUNDARY_TYPES:
        raise ValueError(f"boundary_type = {boundary_type!r}: allowed are {', '.join(BOUNDARY_TYPES)}")


def _check_alpha(name, value):
    value = float(value)
    if not np.isfinite(value) or value < 0.0:
        raise ValueError(f"{name} = {value!r}: allowed is a finite non-negative factor")
    return value


def face_node_operators(face, boundary_type=None, alpha_N=4.0 / 3.0, alpha_T=2.0 / 3.0):
    """K_b (k,3,3) N/m and C_b (k,3,3) N s/m of each node of one face (zero unless it carries input)."""
    boundary_type = face_kind(face, boundary_type)
    alpha_N = _check_alpha("alpha_N", alpha_N)
    alpha_T = _check_alpha("alpha_T", alpha_T)
    normal = np.asarray(face.normal, dtype=float)
    normal_part = np.einsum("ki,kj->kij", normal, normal)
    tangent_part = np.eye(3) - normal_part
    if boundary_type not in INPUT_TYPES:
        zero = np.zeros((len(face.nodes), 3, 3))
        return zero, zero.copy()
    rho_cp = np.asarray(face.rho_cp, dtype=float)[:, None, None]
    rho_cs = np.asarray(face.rho_cs, dtype=float)[:, None, None]
    damping = rho_cp * normal_part + rho_cs * tangent_part
    if boundary_type == "viscous":
        return np.zeros_like(damping), damping
    distance = np.asarray(face.plane_distance, dtype=float)
    if np.any(~np.isfinite(distance)) or np.any(distance <= 0.0):
        raise ValueError(f"face {face.name!r} plane_distance min {distance.min()!r} m: allowed is R > 0 "
                         "(the scattering centre must lie inside the model)")
    spring_scale = (np.asarray(face.shear_modulus, dtype=float) / distance)[:, None, None]
    return spring_scale * (alpha_N * normal_part + alpha_T * tangent_part), damping


def _sum_per_node(nodes, blocks):
    unique, inverse = np.unique(nodes, return_inverse=True)
    summed = np.zeros((len(unique), 3, 3))
    np.add.at(summed, inverse, blocks)
    return unique.astype(np.int32), summed


def boundary_springs_and_dashpots(faces, n_nodes, boundary_type=None, alpha_N=4.0 / 3.0, alpha_T=2.0 / 3.0):
    """Per-node spring and dashpot blocks of the boundary, summed over the faces.

    Args:
        faces: list of BoundaryFace.
        n_nodes: number of nodes of the model (to check the node ids).
        boundary_type: one of BOUNDARY_TYPES for every face, or None: each face's own kind.
        alpha_N, alpha_T: normal and tangential spring factors.

    Returns:
        (spring_nodes int32 (k,), K_nodes (k,3,3) N/m, dashpot_nodes int32 (l,),
        C_nodes (l,3,3) N s/m) over the viscoelastic (springs and dashpots) and viscous
        (dashpots) faces; fixed, roller and free faces add nothing here.
    """
    empty = (np.zeros(0, dtype=np.int32), np.zeros((0, 3, 3)))
    faces = [f for f in faces if face_kind(f, boundary_type) in INPUT_TYPES]
    if not faces:
        return empty + empty
    nodes = np.concatenate([np.asarray(f.nodes, dtype=np.int64) for f in faces])
    if nodes.size and (nodes.min() < 0 or nodes.max() >= n_nodes):
        raise ValueError(f"faces' nodes from {nodes.min()} to {nodes.max()}: allowed are 0 .. n_nodes-1 = {n_nodes - 1}")
    operators = [face_node_operators(f, boundary_type, alpha_N, alpha_T) for f in faces]
    dashpots = _sum_per_node(nodes, np.concatenate([c for _, c in operators]))
    with_springs = [face_kind(f, boundary_type) == "viscoelastic" for f in faces]
    if not any(with_springs):
        return empty + dashpots
    springs = _sum_per_node(nodes, np.concatenate([k for k, _ in operators]))
    return springs + dashpots


def load_area(face) -> np.ndarray:
    """The weights of the traction term A sigma_ff n: `BoundaryFace.load_area` (row sums, the
    consistent load), or `area` for a face object that has no separate load weights."""
    return getattr(face, "load_area", face.area)


def equivalent_input_forces(faces, node_coords, freefield, boundary_type=None,
                            alpha_N=4.0 / 3.0, alpha_T=2.0 / 3.0) -> dict:
    """Arrays of the kernel's SeismicInput: f_node(t) = sum P y(t - tau) + Q y'(t - tau).

    Entries of all faces meeting at a node are summed per (node, free-field slot) and
    grouped by node: the entries of nodes[i] are node_ptr[i] .. node_ptr[i+1]-1.

    Args:
        faces: list of BoundaryFace (name, nodes, area, normal, rho_cp, rho_cs,
            shear_modulus, plane_distance).
        node_coords: (n_nodes, 3) coordinates, m.
        freefield: FreeField; its `tables` are the kernel's tables.
        boundary_type: one of BOUNDARY_TYPES for every face, or None: each face's own kind
            (fixed, roller and free faces carry no input).
        alpha_N, alpha_T: spring factors.

    Returns:
        dict with table_t0 (s), table_dt (s), g, dg, ddg (n_tables, n_samples),
        node_ptr int64 (n_input_nodes+1,), nodes int32 (n_input_nodes,),
        table int32 (n_entries,), tau (n_entries,) s, P (n_entries,3) N/m,
        Q (n_entries,3) N s/m; all C-contiguous.
    """
    faces = [f for f in faces if face_kind(f, boundary_type) in INPUT_TYPES]
    node_coords = np.asarray(node_coords, dtype=float)
    if faces:  # the free field may make its tables as it meets the nodes' depths: ask first
        all_nodes = np.concatenate([np.asarray(f.nodes, dtype=np.int64) for f in faces])
        unique_nodes, inverse = np.unique(all_nodes, return_inverse=True)
        arrays = freefield.component_arrays(node_coords[unique_nodes])
    tables = freefield.tables
    result = {"table_t0": float(tables.t0), "table_dt": float(tables.dt),
              "g": np.ascontiguousarray(tables.g), "dg": np.ascontiguousarray(tables.dg),
              "ddg": np.ascontiguousarray(tables.ddg)}
    if not faces:
        result.update(node_ptr=np.zeros(1, dtype=np.int64), nodes=np.zeros(0, dtype=np.int32),
                      table=np.zeros(0, dtype=np.int32), tau=np.zeros(0), P=np.zeros((0, 3)), Q=np.zeros((0, 3)))
        return result
    n_slots = arrays["tau"].shape[1]
    P = np.zeros((len(unique_nodes), n_slots, 3))
    Q = np.zeros((len(unique_nodes), n_slots, 3))
    start = 0
    for face in faces:
        rows = inverse[start:start + len(face.nodes)]
        start += len(face.nodes)
        stiffness, damping = face_node_operators(face, boundary_type, alpha_N, alpha_T)
        amplitude = arrays["amplitude"][rows]
        traction = np.einsum("ksij,kj->ksi", arrays["stress"][rows], np.asarray(face.normal, dtype=float))
        np.add.at(P, rows, np.einsum("kij,ksj->ksi", stiffness, amplitude))
        np.add.at(Q, rows, np.einsum("kij,ksj->ksi", damping, amplitude)
                  + np.asarray(load_area(face), dtype=float)[:, None, None] * traction)
    result.update(
        node_ptr=np.arange(0, len(unique_nodes) * n_slots + 1, n_slots, dtype=np.int64),
        nodes=unique_nodes.astype(np.int32),
        table=np.ascontiguousarray(arrays["table"].reshape(-1), dtype=np.int32),
        tau=np.ascontiguousarray(arrays["tau"].reshape(-1)),
        P=np.ascontiguousarray(P.reshape(-1, 3)), Q=np.ascontiguousarray(Q.reshape(-1, 3)))
    return result


def evaluate_input_forces(arrays, tables, t, n_nodes):
    """f(t) (nt, n_nodes, 3), N, from the grouped arrays, by WaveformTables.evaluate (kernel rule)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    counts = np.diff(arrays["node_ptr"])
    entry_nodes = np.repeat(arrays["nodes"], counts)
    y, dy, _ = tables.evaluate(np.broadcast_to(arrays["table"], (len(t), len(arrays["table"]))),
                               t[:, None] - arrays["tau"][None, :])
    per_entry = y[..., None] * arrays["P"] + dy[..., None] * arrays["Q"]
    forces = np.zeros((len(t), n_nodes, 3))
    for step in range(len(t)):
        np.add.at(forces[step], entry_nodes, per_entry[step])
    return forces


def equivalent_input_forces_reference(faces, node_coords, freefield, t, boundary_type=None,
                                      alpha_N=4.0 / 3.0, alpha_T=2.0 / 3.0):
    """f(t) (nt, n_nodes, 3), N, straight from FreeField.displacement/velocity/stress (slow, for tests).

    f = K_b u_ff + C_b v_ff + A sigma_ff n per face node, summed over faces (A: `load_area`).
    """
    node_coords = np.asarray(node_coords, dtype=float)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    forces = np.zeros((len(t), len(node_coords), 3))
    for face in [f for f in faces if face_kind(f, boundary_type) in INPUT_TYPES]:
        points = node_coords[np.asarray(face.nodes)]
        u = freefield.displacement(points, t)
        v = freefield.velocity(points, t)
        sigma = freefield.stress(points, t)
        stiffness, damping = face_node_operators(face, boundary_type, alpha_N, alpha_T)
        f = (np.einsum("kij,tkj->tki", stiffness, u) + np.einsum("kij,tkj->tki", damping, v)
             + np.asarray(load_area(face))[None, :, None] * np.einsum("tkij,kj->tki", sigma, np.asarray(face.normal)))
        for step in range(len(t)):
            np.add.at(forces[step], np.asarray(face.nodes), f[step])
    return forces

"""The stepper's effects built from a scene and a model, shared by every path that builds a kernel
stepper (the serial run, pyfem/solver.py; the static stage, pyfem/static.py; the distributed model,
pyfem/distributed_model.py, pyfem/distributed_stage.py, pyfem/distributed_lts.py): the matrix's BSR
arrays, the boundary's constraints, damping, the seismic input's kernel object, contact pairs, the
monitors' stress operator, and the plan's warnings on them. It imports none of those paths.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pyfem.clock import TimeStep
from pyfem.scene import Scene, SceneError, rayleigh_coefficients


# Held directions of a node closer than this (singular value relative to the largest) to the
# span of the others add no new constraint (e.g. a roller edge between coplanar facets).
_DIRECTION_TOLERANCE = 1.0e-6


@dataclass
class MonitorStress:
    """What the stress at the monitor points needs: sigma = C(x) : eps(u)(x) + sigma0(x).

    Attributes:
        nodes: (m, k) nodes of the cell containing each monitor.
        gradients: (m, k, 3) gradient weights (1/m), see `Model.point_gradient_weights`.
        lame_lambda: (m,) Lame's lambda of the containing cell's material (Pa).
        shear_modulus: (m,) G of that material (Pa).
        regions: region (material) name of each containing cell.
        static: (m, 3, 3) initial stress at the points (Pa, compression negative); zero
            without [initial_stress]. At a kernel point, that point's.
        cells: (m,) local cell containing each monitor.
        kernel_points: None without nonlinear regions; else per monitor (component index, flat
            point index) of the nearest quadrature point of its cell when the cell is in a
            nonlinear region (its stress is the law's there), None in the matrix cells.
    """

    nodes: np.ndarray
    gradients: np.ndarray
    lame_lambda: np.ndarray
    shear_modulus: np.ndarray
    regions: list
    static: np.ndarray
    cells: np.ndarray | None = None
    kernel_points: list | None = None

    def dynamic_stress(self, u: np.ndarray) -> np.ndarray:
        """(m, 3, 3) stress of the displacement increment u (dofs, m) at the monitors (Pa)."""
        nodal = u.reshape(-1, 3)[self.nodes]                                   # (m, k, 3)
        gradient = np.einsum("mki,mkl->mil", nodal, self.gradients)            # du_i/dx_l
        strain = 0.5 * (gradient + gradient.transpose(0, 2, 1))
        trace = np.trace(strain, axis1=1, axis2=2)
        return (self.lame_lambda[:, None, None] * trace[:, None, None] * np.eye(3)
                + 2.0 * self.shear_modulus[:, None, None] * strain)


def monitor_stress_operator(scene: Scene, model, points: np.ndarray, cells: np.ndarray | None = None) -> MonitorStress:
    """Gradient weights, materials and initial stress at the monitor points.

    Args:
        scene: validated scene ([materials], optional [initial_stress]).
        model: pyfem.operators.Model.
        points: (m, 3) monitor points (m).
        cells: the local cell containing each point; None: the first found.
    """
    from pyfem.initial_stress import stress_field_from_scene
    from pyfem.material import Material

    nodes, gradients, cells = model.point_gradient_weights(points, cells)
    regions = model.region_of_cells(cells)
    lame = np.array([Material.from_scene(name, scene["materials"][name]).lame
                     for name in regions], dtype=np.float64).reshape(-1, 2)
    field = stress_field_from_scene(scene)
    static = np.zeros((len(points), 3, 3)) if field is None else np.asarray(field(points), dtype=np.float64)
    return MonitorStress(nodes=nodes, gradients=gradients, lame_lambda=lame[:, 0], shear_modulus=lame[:, 1],
                         regions=regions, static=static, cells=np.asarray(cells))


def flow_warnings(scene: Scene, laws: dict, time_step: TimeStep) -> None:
    """Warns where non-associated Mohr-Coulomb flow can raise a frequency past the step's margin to the
    elastic stable limit (`pyfem.elements.plastic_frequency_factor`); laws as `scene_laws` gives them."""
    from pyfem.elements import plastic_frequency_factor

    for name, parameters in laws.items():
        if parameters["law"] == "mohr_coulomb":
            factor = plastic_frequency_factor(parameters["poisson_ratio"], parameters["friction_angle"],
                                              parameters["dilation_angle"])
            if factor * time_step.dt > time_step.critical:
                margin = time_step.critical / time_step.dt - 1
                scene.warn(f"materials.{name}.plasticity: non-associated flow (dilation_angle < "
                           f"friction_angle) can raise frequencies by up to {100 * (factor - 1):.0f} %, more "
                           f"than the step's margin {100 * margin:.0f} % to the elastic stable limit: lower "
                           "time.safety or time.dt")


def attach_kernel_points(stress: MonitorStress, points: np.ndarray, nonlinear) -> None:
    """Monitors in a nonlinear region take the law's stress at the nearest quadrature point of their
    cell (and that point's initial stress as their static stress)."""
    from pyfem.elements import voigt_tensor

    stress.kernel_points = [nonlinear.nearest_point(int(cell), point)
                            for cell, point in zip(stress.cells, points)]
    for j, found in enumerate(stress.kernel_points):
        sigma0 = None if found is None else nonlinear.initial_stress[nonlinear.regions[found[0]]]
        if sigma0 is not None:
            stress.static[j] = voigt_tensor(sigma0.reshape(-1, 6)[found[1]])


def earthquake_clock(scene: Scene, processed=None) -> tuple[float, float]:
    """(start, t_s) of the deterioration's wear (Eq. 9, docs/method.md section 9): the run time (s)
    at which the record's window starts, which is 0 (record time is run time: the zero-phase
    filter's lead-in runs at negative times, and it is the filter's quiet precursor, not shaking),
    and t_s, the window's length (else time.duration). The record is the one the seismic input is
    driven with: `processed` (pyfem.seismic.setup.scene_record), processed here when None."""
    from pyfem.seismic.setup import scene_record

    processed = scene_record(scene) if processed is None else processed
    if processed is None:
        return 0.0, float(scene["time"]["duration"])
    start, end = processed.window
    return 0.0, float(end - start)  # record time: the window starts at t = 0


def contact_arguments(scene: Scene, model, processed=None) -> dict:
    """The arrays and strengths of the kernel's ContactPairs for the scene's [contact] table.

    Static forces come from [initial_stress] (zero without it): F = A sigma0(x) n. processed: the
    scene's processed record for the wear clock (earthquake_clock).

    Returns:
        dict with pairs, area, normal, static_force, cohesion, tensile_strength,
        friction_static, friction_dynamic, deterioration (R0, lam, duration, m, n, p, start) or None,
        normal_lag (length, velocity) or None and release_time (s) or None.
    """
    from pyfem.initial_stress import pair_static_forces, stress_field_from_scene

    contact = scene["contact"]
    pairs = model.pairs
    arguments = {
        "pairs": np.ascontiguousarray(pairs.nodes, dtype=np.int32),
        "area": np.ascontiguousarray(pairs.area, dtype=np.float64),
        "normal": np.ascontiguousarray(pairs.normal, dtype=np.float64),
        "static_force": pair_static_forces(pairs.coords, pairs.area, pairs.normal, stress_field_from_scene(scene)),
        "cohesion": float(contact["cohesion"]),
        "tensile_strength": float(contact["tensile_strength"]),
        "friction_static": math.tan(math.radians(contact["friction_angle"])),
        "friction_dynamic": math.tan(math.radians(contact["dynamic_friction_angle"])),
        "deterioration": None,
    }
    deterioration = contact.get("deterioration")
    if deterioration is not None:
        start, duration = earthquake_clock(scene, processed)
        arguments["deterioration"] = (deterioration["R0"], deterioration["lambda"], duration,
                                      deterioration["m"], deterioration["n"], deterioration["p"], start)
    lag = contact.get("normal_lag")
    arguments["normal_lag"] = None if lag is None else (float(lag["length"]), float(lag["velocity"]))
    release = contact.get("release_time")
    arguments["release_time"] = None if release is None else float(release)
    return arguments


def damping_coefficients(scene: Scene) -> tuple[float, float]:
    """Rayleigh coefficients (alpha in 1/s, beta in s) of the scene, (0, 0) when damping is off."""
    if "damping" not in scene.effects:
        return 0.0, 0.0
    damping = scene["damping"]
    if damping.get("ratio") is not None:
        f1, f2 = damping["frequencies"]
        return rayleigh_coefficients(damping["ratio"], f1, f2)
    return float(damping.get("alpha") or 0.0), float(damping.get("beta") or 0.0)


def bsr_arrays(matrix: sp.bsr_matrix):
    """(indptr int64, indices int32, blocks (nnzb,3,3)) as the kernel expects them."""
    return (np.ascontiguousarray(matrix.indptr, dtype=np.int64),
            np.ascontiguousarray(matrix.indices, dtype=np.int32),
            np.ascontiguousarray(matrix.data, dtype=np.float64))


@dataclass
class BoundaryConstraints:
    """Kinematic constraints of the fixed and roller faces, as the kernel takes them.

    Attributes:
        nodes: (k,) int32 distinct constrained nodes.
        projection: (k, 3, 3) orthogonal projection onto each node's free directions
            (0: fixed; I - n n^T: roller; I - n1 n1^T - n2 n2^T on the edge of two rollers).
        face_names: names of the fixed and roller faces.
        face_weights: (n_faces, k) share of each node's reaction attributed to each face (its
            lumped area on that face over its area on all constrained faces): the face
            resultant is face_weights @ reactions.
    """

    nodes: np.ndarray
    projection: np.ndarray
    face_names: list
    face_weights: sp.csr_matrix

    def face_resultants(self, reactions: np.ndarray) -> np.ndarray:
        """(n_faces, 3) resultant reaction force of each constrained face (N)."""
        return np.asarray(self.face_weights @ np.asarray(reactions).reshape(-1, 3))


def boundary_constraints(faces) -> BoundaryConstraints | None:
    """The constraints of the fixed (all components) and roller (normal component) faces.

    A node on several constrained faces is held in the span of all their held directions.
    Returns None when no face is fixed or roller.
    """
    held_faces = [face for face in faces if face.kind in ("fixed", "roller")]
    if not held_faces:
        return None
    node_list, direction_list, face_list, area_list = [], [], [], []
    for index, face in enumerate(held_faces):
        if face.kind == "fixed":
            directions = np.repeat(np.eye(3)[None], len(face.nodes), axis=0)      # (k, 3, 3)
        else:
            directions = np.asarray(face.normal, dtype=float)[:, None, :]        # (k, 1, 3)
        node_list.append(np.repeat(face.nodes, directions.shape[1]))
        direction_list.append(directions.reshape(-1, 3))
        face_list.append(np.full(len(face.nodes), index))
        area_list.append(np.asarray(face.area, dtype=float))
    nodes_per_direction = np.concatenate(node_list)
    directions = np.concatenate(direction_list)
    nodes, counts = np.unique(nodes_per_direction, return_counts=True)
    order = np.argsort(nodes_per_direction, kind="stable")
    projection = np.empty((len(nodes), 3, 3))
    single = counts == 1
    n_single = directions[order][np.repeat(single, counts)]
    projection[single] = np.eye(3) - np.einsum("ki,kj->kij", n_single, n_single)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    for k in np.flatnonzero(~single):
        held = directions[order[starts[k]:starts[k] + counts[k]]]
        _, singular_values, basis = np.linalg.svd(held)
        rank = int(np.count_nonzero(singular_values > _DIRECTION_TOLERANCE * singular_values[0]))
        projection[k] = np.eye(3) - basis[:rank].T @ basis[:rank]
    # Reaction shares by lumped area.
    face_of_entry = np.concatenate(face_list)
    node_of_entry = np.searchsorted(nodes, np.concatenate([face.nodes for face in held_faces]))
    area_of_entry = np.concatenate(area_list)
    total_area = np.bincount(node_of_entry, weights=area_of_entry, minlength=len(nodes))
    weights = sp.csr_matrix((area_of_entry / total_area[node_of_entry], (face_of_entry, node_of_entry)),
                            shape=(len(held_faces), len(nodes)))
    return BoundaryConstraints(nodes=nodes.astype(np.int32), projection=projection,
                               face_names=[face.name for face in held_faces], face_weights=weights)


def check_input_faces(scene: Scene, model) -> None:
    """A scene with [wave] needs a truncation face that carries input (viscoelastic or viscous).

    Raises:
        SceneError naming the faces found and their types.
    """
    from pyfem.seismic.forces import INPUT_TYPES

    if "seismic_input" not in scene.effects:
        return
    if any(face.kind in INPUT_TYPES for face in model.faces):
        return
    found = ", ".join(f"{face.name} ({face.kind})" for face in model.faces) or "none"
    key = "boundary.type" if not (scene["boundary"].get("face")) else "boundary.face"
    raise SceneError(key, scene["boundary"]["type"] if key == "boundary.type" else scene["boundary"]["face"],
                     f"with [wave], at least one truncation face must be viscoelastic or viscous to carry "
                     f"the input (faces found: {found}; fixed, roller and free faces carry none)")


def warn_input_medium(scene: Scene, model, comm=None) -> None:
    """Warns when the rock at the input faces is not the rock of the free field: other materials than
    `[wave] medium` (or, with [[wave.layers]], than the layer at the node's depth) receive a field
    that is not their own (docs/method.md section 5, "Limit"). A node's material is read off its
    face's lumped impedance, rho c_s over its area; the warning gives the share of the area and the
    largest impedance ratio. comm: the ranks of a distributed model (pyfem/distributed_model.py),
    whose faces are each rank's part."""
    from pyfem.material import Material
    from pyfem.seismic.forces import INPUT_TYPES

    if "seismic_input" not in scene.effects or scene["wave"]["free_field"]["method"] == "drm":
        return  # (the domain-reduction method's input is the auxiliary model's, whatever the rock)
    wave = scene["wave"]
    medium = wave["medium"]

    def impedance(name):
        table = scene["materials"][name]
        return table["rho"] * Material.from_scene(name, table).s_wave_speed

    layers = wave.get("layers") or []
    bottoms = np.cumsum([layer["thickness"] for layer in layers])
    site = [impedance(layer["medium"]) for layer in layers] + [impedance(medium)]
    faces = [face for face in model.faces if face.kind in INPUT_TYPES]
    total = other = 0.0
    worst = 1.0
    for face in faces:
        lumped = face.rho_cs / face.area
        if layers:
            # A node on a layer interface lumps the rock above and below it: either, or a mix, fits.
            depth = wave["surface"] - model.node_coords[np.asarray(face.nodes), 2]
            tolerance = 1e-6 * max(float(bottoms[-1]), 1.0)
            above = np.asarray(site)[np.searchsorted(bottoms, depth - tolerance)]
            below = np.asarray(site)[np.searchsorted(bottoms, depth + tolerance)]
            low, high = np.minimum(above, below), np.maximum(above, below)
            reference = np.clip(lumped, low, high)
        else:
            reference = site[-1]
        ratio = lumped / reference
        mismatch = np.abs(ratio - 1.0) > 0.01
        total += float(np.sum(face.area))
        other += float(np.sum(face.area[mismatch]))
        if np.any(mismatch):
            worst = max(worst, float(np.max(np.maximum(ratio[mismatch], 1.0 / ratio[mismatch]))))
    if comm is not None:  # a distributed model's faces hold each rank's owned nodes: the whole's sums
        total, other, worst = comm.allreduce(total), comm.allreduce(other), comm.allreduce(worst, op=_mpi_max())
    if total > 0.0 and other > 0.01 * total:
        field = (f"the layered site of [[wave.layers]] over '{medium}'" if layers
                 else f"a homogeneous '{medium}' half-space")
        scene.warn(f"wave.medium = '{medium}': {100 * other / total:.0f} % of the input faces' area lies in other materials "
                   f"than the free field's at its depth (impedance ratio up to {worst:.2f}), and "
                   f"receives the free field of {field}, not its own (the input is approximate there; "
                   "docs/method.md section 5, \"Limit\"; horizontal layers: [[wave.layers]])")


def _mpi_max():
    from mpi4py import MPI

    return MPI.MAX


def warn_far_pair_monitor(scene: Scene, monitor: dict, at: np.ndarray, area: float) -> None:
    """Warns when the pair a pair monitor reports (at `at`, lumped area `area`) is farther than
    about two faces from the monitor's point."""
    distance = float(np.linalg.norm(np.asarray(at, dtype=float) - np.asarray(monitor["point"], dtype=float)))
    if distance > 2.0 * np.sqrt(area):
        scene.warn(f"pair_monitor '{monitor['name']}' at {list(monitor['point'])} is {distance:.3g} m from "
                   f"the nearest contact pair (at {[round(float(x), 3) for x in at]}), which it reports: "
                   "is the point on an interface of contact.interfaces?")


def seismic_input_kernel(arrays: dict):
    """The kernel's SeismicInput from `Simulation.input_arrays` (pyfem/seismic/forces.py), or from
    an MPI rank's part of them (pyfem/distributed_model.py)."""
    from pyfem import _kernels

    return _kernels.SeismicInput(arrays["table_t0"], arrays["table_dt"], arrays["g"], arrays["dg"], arrays["ddg"],
                                 arrays["node_ptr"], arrays["nodes"], arrays["table"], arrays["tau"], arrays["P"],
                                 arrays["Q"])


def make_contact_pairs(arrays: dict):
    """The kernel's ContactPairs from `contact_arguments` (deterioration set when given)."""
    from pyfem import _kernels

    if not hasattr(_kernels, "ContactPairs"):
        raise RuntimeError("this build of pyfem._kernels has no ContactPairs: rebuild the kernel "
                           "(cmake --build build) to run scenes with [contact]")
    contact = _kernels.ContactPairs(arrays["pairs"], arrays["area"], arrays["normal"], arrays["static_force"],
                                    arrays["cohesion"], arrays["tensile_strength"], arrays["friction_static"],
                                    arrays["friction_dynamic"])
    if arrays["deterioration"] is not None:
        contact.set_deterioration(*arrays["deterioration"])
    if arrays.get("normal_lag") is not None:
        contact.set_normal_lag(*arrays["normal_lag"])
    if arrays.get("release_time") is not None:
        contact.set_release_time(arrays["release_time"])
    return contact


def kernel_threads() -> int:
    """Sets the kernel's OpenMP threads to OMP_NUM_THREADS, else the cores this process may use, and
    returns the number. Needed before stepping: gmsh shares libgomp and sets it to its own
    General.NumThreads (1) when it meshes, which left every run after a gmsh call on one thread."""
    import os

    from pyfem import _kernels

    from pyfem.ranks import threads_per_rank, world

    given = os.environ.get("OMP_NUM_THREADS", "")
    threads = int(given) if given.isdigit() and int(given) > 0 else len(os.sched_getaffinity(0))
    shared = threads_per_rank(world())  # ranks on one machine share its cores
    if shared is not None:
        threads = shared
    _kernels.set_num_threads(threads)
    return threads


def free_field_words(scene: Scene) -> str:
    """Which free field the input faces get: the homogeneous half-space of wave.medium, or the layered
    site of [[wave.layers]] over it (the rock of each face against it: warn_input_medium)."""
    wave = scene["wave"]
    if wave["free_field"]["method"] == "drm":
        return (f"domain-reduction method: the auxiliary scene {wave['free_field']['auxiliary']} is run first and its "
                "motion on the layer of cells inside the input faces gives their forces (pyfem.seismic.drm)")
    surface = "no free surface" if wave.get("surface") is None else f"free surface at z = {wave['surface']:g} m"
    layers = wave.get("layers") or []
    if not layers:
        return f"homogeneous '{wave['medium']}' half-space, {surface} (pyfem.seismic.freefield)"
    stack = ", ".join(f"{layer['thickness']:g} m of '{layer['medium']}'" for layer in layers)
    return f"layered site: {stack} (top down) over a '{wave['medium']}' half-space, {surface} (pyfem.seismic.layered)"

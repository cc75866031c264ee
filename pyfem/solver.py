"""Builds the explicit kernel from a scene and runs it in chunks of one output interval.

Data flow (docs/method.md section 1): scene -> model (gmsh -> dolfinx operators) -> boundary
springs/dashpots and seismic input forces -> C++ Stepper (many steps per call) -> outputs.
Python owns orchestration and I/O; nothing in Python runs once per time step.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from pyfem.clock import record_lead_in, run_origin, run_steps, whole_steps  # noqa: F401  (also pyfem.solver.*)
from pyfem.interfaces import wear_words  # noqa: F401  (also pyfem.solver.wear_words)
from pyfem.operators import face_report  # noqa: F401  (also pyfem.solver.face_report)
from pyfem.scene import Scene, SceneError, rayleigh_coefficients

# Memory traffic assumed by the time estimate before a measurement exists (bytes/s).
_ASSUMED_BANDWIDTH = 5.0e9
# Held directions of a node closer than this (singular value relative to the largest) to the
# span of the others add no new constraint (e.g. a roller edge between coplanar facets).
_DIRECTION_TOLERANCE = 1.0e-6


@dataclass
class TimeStep:
    """The time step and how it was chosen.

    Attributes:
        dt: step used (s).
        critical: stability limit of central differences with the damping correction (s).
        omega_max: highest circular frequency used for the limit (rad/s).
        reason: a sentence for the plan and run.json.
        steps_per_output: steps between two monitor samples.
    """

    dt: float
    critical: float
    omega_max: float
    reason: str
    steps_per_output: int


@dataclass
class Simulation:
    """Everything assembled for a run, before the time loop."""

    scene: Scene
    model: object
    stiffness: sp.bsr_matrix  # elastic stiffness plus boundary springs
    mass: np.ndarray
    alpha: float
    beta: float
    time_step: TimeStep
    dashpot_nodes: np.ndarray
    dashpot_matrices: np.ndarray
    constraints: "BoundaryConstraints | None" = None
    freefield: object = None
    input_arrays: dict | None = None
    monitor_names: list = field(default_factory=list)
    monitor_nodes: np.ndarray | None = None
    monitor_weights: np.ndarray | None = None
    monitor_stress: "MonitorStress | None" = None
    n_steps: int = 0
    lead_in: float = 0.0                 # s of a record's filter lead-in before its window (t < 0)
    contact_arrays: dict | None = None   # ContactPairs arguments (see contact_arguments)
    contact_pairs: object = None         # the kernel's ContactPairs, set by make_stepper
    pair_monitor_names: list = field(default_factory=list)
    pair_monitor_pairs: np.ndarray | None = None  # (m,) pair index of each pair monitor
    nonlinear: "NonlinearRegions | None" = None  # element-loop regions (pyfem.elements), None: matrix only
    node_levels: np.ndarray | None = None  # [time] local_stepping: rate level per node (pyfem.local_stepping)
    lts_stability: dict | None = None      # [time] local_stepping: check_stability's report, once per model
    lts_split: str | None = None           # [time] local_stepping: "row" or "column" (local_stepping.row_split)
    lts_preview: np.ndarray | None = None  # local stepping off: the levels it would use (prepare(preview_levels=True))
    lts_decision: str | None = None        # [time] local_stepping = "auto": on or off, and why (auto_decision)
    lts_global_step: TimeStep | None = None  # local stepping on: the scene's global step (fall_back_to_global_stepping)
    lts_check_deferred: bool = False       # `plan`: the LTS map's set-up check is left to the run
    static: object = None                # pyfem.static.StaticState when a [static] stage ran
    support: list = field(default_factory=list)  # pyfem.support.SupportGroup of each [support.NAME]
    bolt_monitors: list = field(default_factory=list)  # pyfem.support_output.BoltMonitor of each [[bolt_monitor]]


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


def nonlinear_regions(scene: Scene, model, time_step: TimeStep):
    """The regions whose material has a [plasticity] or [damage] table, taken out of the stiffness
    matrix into kernel element loops (pyfem.elements), or None when there are none. Their laws start
    from the scene's initial stress at the quadrature points; warnings go to the scene (also a step
    too close to the elastic limit for non-associated flow, `plastic_frequency_factor`)."""
    from pyfem.elements import initial_warnings, nonlinear_component, scene_laws
    from pyfem.initial_stress import stress_field_from_scene

    laws, mean_dilatation = scene_laws(scene)
    if not laws:
        return None
    try:
        nonlinear = nonlinear_component(model, list(laws), laws, mean_dilatation=mean_dilatation,
                                        initial_stress=stress_field_from_scene(scene))
    except ValueError as error:  # the kernel's own range checks, should the scene's have missed one
        raise SceneError("materials", sorted(laws), f"a nonlinear material was refused by the kernel: "
                         f"{error}")
    for message in initial_warnings(nonlinear, scene):
        scene.warn(message)
    flow_warnings(scene, laws, time_step)
    return nonlinear


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


def add_block_diagonal(matrix: sp.bsr_matrix, nodes: np.ndarray, blocks: np.ndarray) -> sp.bsr_matrix:
    """Returns matrix + the 3x3 blocks on the diagonal of the given nodes.

    The diagonal blocks already exist in an assembled stiffness pattern, so the sum keeps
    the pattern of `matrix`.
    """
    if len(nodes) == 0:
        return matrix
    n = matrix.shape[0] // 3
    order = np.argsort(nodes)
    extra = sp.bsr_matrix((blocks[order], nodes[order].astype(np.int32),
                           np.searchsorted(nodes[order], np.arange(n + 1))),
                          shape=matrix.shape, blocksize=(3, 3))
    total = (matrix + extra).tobsr(blocksize=(3, 3))
    total.sort_indices()
    return total


def bsr_arrays(matrix: sp.bsr_matrix):
    """(indptr int64, indices int32, blocks (nnzb,3,3)) as the kernel expects them."""
    return (np.ascontiguousarray(matrix.indptr, dtype=np.int64),
            np.ascontiguousarray(matrix.indices, dtype=np.int32),
            np.ascontiguousarray(matrix.data, dtype=np.float64))


def choose_time_step(scene: Scene, stiffness: sp.bsr_matrix, mass: np.ndarray, beta: float) -> TimeStep:
    """Stable step of central differences for M^-1 K, with stiffness-proportional damping.

    omega_max^2 is bounded above by Gershgorin row sums of M^-1 K (guaranteed); power
    iteration sharpens it (an estimate from below, so it is raised by 5 % before use and
    never exceeds the bound). With damping ratio xi = beta omega/2 at omega_max the limit is
    dt_crit = (2/omega)(sqrt(1 + xi^2) - xi). Mass-proportional damping and dashpots are
    implicit and do not restrict the step.
    """
    from pyfem import _kernels

    indptr, indices, blocks = bsr_arrays(stiffness)
    omega2_bound = _kernels.gershgorin_bound(indptr, indices, blocks, mass)
    omega2_power = None
    if scene["time"].get("power_iteration", True):
        omega2_power = _kernels.power_iteration(indptr, indices, blocks, mass, POWER_ITERATIONS, 1)
    return time_step_from(scene, omega2_bound, omega2_power, beta)


# Power iterations of the stable step's estimate (choose_time_step).
POWER_ITERATIONS = 300


def time_step_from(scene: Scene, omega2_bound: float, omega2_power: float | None, beta: float) -> TimeStep:
    """The step of `choose_time_step` from its two estimates of omega_max^2: the Gershgorin bound
    and the power iteration's (None: not run); also the distributed model's (pyfem/distributed_model.py)."""
    how = "Gershgorin bound"
    omega2 = omega2_bound
    if omega2_power is not None:
        if 1.05 * omega2_power < omega2_bound:
            omega2 = 1.05 * omega2_power
            how = f"power iteration (+5 %), {math.sqrt(omega2_bound / omega2):.2f}x sharper than Gershgorin"
    omega = math.sqrt(omega2)
    xi = 0.5 * beta * omega
    critical = (2.0 / omega) * (math.sqrt(1.0 + xi * xi) - xi)
    interval = scene["output"]["interval"]
    user_dt = scene["time"].get("dt")
    if user_dt is not None:
        if user_dt > critical:
            raise SceneError("time.dt", user_dt,
                             f"a step at most the stable step {critical:.6g} s "
                             f"(omega_max {omega:.6g} rad/s from the {how})")
        dt_wanted = user_dt
        reason = f"user dt; stable limit {critical:.4g} s from the {how}"
    else:
        dt_wanted = scene["time"]["safety"] * critical
        reason = (f"{scene['time']['safety']:g} x critical {critical:.4g} s "
                  f"(omega_max {omega:.4g} rad/s, {how}" + (f", damping ratio {xi:.3g} at omega_max" if xi else "")
                  + ")")
    steps_per_output = max(1, math.ceil(interval / dt_wanted * (1 - 1e-12)))
    dt = interval / steps_per_output
    if user_dt is not None and abs(dt - user_dt) > 1e-12 * user_dt:
        reason += f"; reduced from {user_dt:.6g} s to divide the output interval {interval:g} s"
    else:
        reason += f"; {steps_per_output} steps per output interval {interval:g} s"
    return TimeStep(dt=dt, critical=critical, omega_max=omega, reason=reason, steps_per_output=steps_per_output)


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


def boundary_operators(scene: Scene, model):
    """Boundary springs (added to K) and dashpots (implicit in the kernel) of the viscoelastic
    and viscous truncation faces, and the constraints of the fixed and roller faces.

    Returns:
        (spring_nodes, spring_blocks, dashpot_nodes, dashpot_blocks, constraints or None)
    """
    from pyfem.seismic.forces import boundary_springs_and_dashpots

    boundary = scene["boundary"]
    spring_nodes, springs, dashpot_nodes, dashpots = boundary_springs_and_dashpots(
        model.faces, len(model.mass), None, boundary["alpha_N"], boundary["alpha_T"])
    return spring_nodes, springs, dashpot_nodes, dashpots, boundary_constraints(model.faces)


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

    if "seismic_input" not in scene.effects:
        return
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


def fall_back_to_global_stepping(simulation: Simulation, report: dict) -> None:
    """`time.local_stepping = "auto"` turned local stepping on but its set-up check found the map
    unstable on this model (`report`, local_stepping.check_stability): the run steps globally at the
    scene's step instead, and run.json and a warning say why."""
    simulation.lts_preview, simulation.node_levels, simulation.lts_split = simulation.node_levels, None, None
    simulation.time_step = simulation.lts_global_step
    simulation.n_steps = run_steps(simulation.scene["time"]["duration"], simulation.lead_in, simulation.time_step)
    from pyfem.local_stepping import unstable_words

    simulation.lts_stability = report
    _, simulation.lts_decision, warning = unstable_words(report)
    simulation.scene.warn(warning)


def prepare(scene: Scene, solve_static: bool = True, preview_levels: bool = False) -> Simulation:
    """Builds the model and every operator the kernel needs (no time stepping); with [static], runs
    the static stage and hands its state over (solve_static=False: only checks it, for `plan`).
    preview_levels: with local stepping off, also the rate levels it would use where the scene allows
    it (Simulation.lts_preview, for `plan`'s prediction)."""
    from pyfem.operators import PointOutsideMesh, build_model

    from mpi4py import MPI

    model = build_model(scene, MPI.COMM_SELF)  # (under mpirun: pyfem/distributed_model.py)
    mass = np.array(model.mass, dtype=np.float64)
    check_input_faces(scene, model)
    warn_input_medium(scene, model)
    spring_nodes, springs, dashpot_nodes, dashpots, constraints = boundary_operators(scene, model)
    stiffness = add_block_diagonal(model.stiffness, spring_nodes, springs)
    alpha, beta = damping_coefficients(scene)
    support = []
    if scene.get("support"):  # rock bolts and cables (pyfem/support.py): their stiffness bound in the step
        from pyfem.support import scene_groups, stiffness_bound

        support = scene_groups(scene, model)
        time_step = choose_time_step(scene, (stiffness + stiffness_bound(support, model.n_nodes)).tobsr(
            blocksize=(3, 3)), mass, beta)
    else:
        time_step = choose_time_step(scene, stiffness, mass, beta)
    nonlinear = nonlinear_regions(scene, model, time_step)
    elastic_stiffness = stiffness  # of every cell: the rate levels of local stepping
    if nonlinear is not None:  # its cells leave K; dt stays that of the full elastic stiffness
        stiffness = add_block_diagonal(nonlinear.stiffness, spring_nodes, springs)
    node_levels = preview = lts_split = global_step = None
    setting = scene["time"].get("local_stepping")
    local = setting is True  # "auto" decides below, where the scene allows local stepping
    lts_decision = None
    if setting or preview_levels:
        from pyfem import local_stepping

        try:
            local_stepping.check_supported(scene, beta)
            rows = local_stepping.row_split(nonlinear, "contact" in scene.effects)
            if constraints is not None and "contact" in scene.effects:
                held = np.intersect1d(constraints.nodes, model.pairs.nodes)
                if len(held):
                    raise local_stepping.held_pair_error(
                        f"node {int(held[0])} at {np.round(model.node_coords[held[0]], 3).tolist()}")
        except SceneError as error:
            if local:
                raise
            if setting == "auto":
                lts_decision = "\"auto\": off: not available " + error.allowed.removeprefix("false ")
        else:
            cell_nodes = model.V.dofmap.list.array.reshape(model.n_cells, -1)
            pairs = model.pairs.nodes if "contact" in scene.effects else None
            levels = local_stepping.node_levels(elastic_stiffness, mass, cell_nodes, local_stepping.MAX_LEVEL,
                                                pinned=np.unique(dashpot_nodes), pairs=pairs,
                                                loop_cells=local_stepping.loop_cell_mask(nonlinear, model.n_cells),
                                                rows=rows)
            levels = local_stepping.fit_levels_to_output(levels, time_step.steps_per_output)
            if setting == "auto":
                local, lts_decision = local_stepping.auto_decision(
                    levels, cell_nodes, nonlinear, stiffness, pairs, time_step, scene["time"]["duration"], rows)
            if local:
                node_levels = levels
                lts_split = "row" if rows else "column"
                global_step = time_step
                time_step, _ = local_stepping.local_time_step(time_step, node_levels, lts_split)
            else:
                preview = levels
    from pyfem.seismic.setup import scene_record, seismic_input_from_scene

    # The record is processed once: the input forces and the interfaces' wear clock share it.
    record = scene_record(scene) if {"seismic_input", "contact"} & set(scene.effects) else None
    lead_in = record_lead_in(record) if "seismic_input" in scene.effects else 0.0
    n_steps = run_steps(scene["time"]["duration"], lead_in, time_step)
    simulation = Simulation(lead_in=lead_in, scene=scene, model=model, stiffness=stiffness, mass=mass, alpha=alpha, beta=beta,
                            time_step=time_step, dashpot_nodes=dashpot_nodes, dashpot_matrices=dashpots,
                            constraints=constraints, n_steps=n_steps, nonlinear=nonlinear,
                            node_levels=node_levels, lts_preview=preview, lts_split=lts_split,
                            lts_decision=lts_decision, lts_global_step=global_step, support=support)
    if "seismic_input" in scene.effects:
        simulation.freefield, simulation.input_arrays = seismic_input_from_scene(scene, model, record)
    monitors = scene.get("monitor", [])
    if monitors:
        points = np.array([m["point"] for m in monitors], dtype=np.float64)
        try:
            simulation.monitor_nodes, simulation.monitor_weights = model.point_weights(points)
        except PointOutsideMesh as error:
            key, monitor = f"monitor.{error.index}.point", monitors[error.index]
            raise SceneError(key, monitor["point"], "a point inside a cell of the model",
                             f"scene key '{key}' = {monitor['point']} (monitor {monitor['name']!r}): {error}; "
                             "allowed: a point inside a cell of the model") from None
        simulation.monitor_names = [m["name"] for m in monitors]
        simulation.monitor_stress = monitor_stress_operator(scene, model, points)
        if nonlinear is not None:
            attach_kernel_points(simulation.monitor_stress, points, nonlinear)
    if "contact" in scene.effects:
        simulation.contact_arrays = contact_arguments(scene, model, record)
        pair_monitors = scene.get("pair_monitor", [])
        simulation.pair_monitor_names = [m["name"] for m in pair_monitors]
        simulation.pair_monitor_pairs = np.array([model.pairs.nearest(m["point"]) for m in pair_monitors],
                                                 dtype=np.int64)
        area = np.asarray(simulation.contact_arrays["area"], dtype=float)
        for monitor, pair in zip(pair_monitors, simulation.pair_monitor_pairs):
            warn_far_pair_monitor(scene, monitor, model.pairs.coords[pair], float(area[pair]))
    if scene.get("bolt_monitor"):  # the bolt segments they report (pyfem/support_output.py)
        from pyfem.support_output import locate_bolt_monitors

        simulation.bolt_monitors = locate_bolt_monitors(scene, simulation.support)
    if "static" in scene:  # the stage's stress and pair forces become the initial state (pyfem/static.py)
        from pyfem.static import hand_over

        hand_over(simulation, solve=solve_static)
    return simulation


def warn_far_pair_monitor(scene: Scene, monitor: dict, at: np.ndarray, area: float) -> None:
    """Warns when the pair a pair monitor reports (at `at`, lumped area `area`) is farther than
    about two faces from the monitor's point."""
    distance = float(np.linalg.norm(np.asarray(at, dtype=float) - np.asarray(monitor["point"], dtype=float)))
    if distance > 2.0 * np.sqrt(area):
        scene.warn(f"pair_monitor '{monitor['name']}' at {list(monitor['point'])} is {distance:.3g} m from "
                   f"the nearest contact pair (at {[round(float(x), 3) for x in at]}), which it reports: "
                   "is the point on an interface of contact.interfaces?")


def _make_local_stepper(simulation: Simulation, indptr, indices, blocks):
    """The kernel's LocalStepper behind the Stepper calls of the run loop. After a relaxation stage
    its element-loop components and pairs, split by level, continue the stage's state
    (local_stepping.load_component_parts, load_pair_parts)."""
    from pyfem import _kernels
    from pyfem import local_stepping

    levels = np.ascontiguousarray(simulation.node_levels, dtype=np.int32)
    model = simulation.model
    cell_nodes = model.V.dofmap.list.array.reshape(model.n_cells, -1)
    loop_cells = local_stepping.loop_cell_mask(simulation.nonlinear, model.n_cells)
    row_split = simulation.lts_split == "row"
    cell_cap = None
    if row_split:  # a cell at the finest level of its nodes (LocalStepper.set_row_split)
        cell_cap = local_stepping.row_cell_cap(levels, cell_nodes)
    elif loop_cells is not None and simulation.contact_arrays is not None:
        cell_cap = local_stepping.pair_cell_cap(levels, cell_nodes, simulation.contact_arrays["pairs"], loop_cells)

    built = {}  # the regions' LevelComponents of the last kernel built

    def bare_kernel(alpha, initial_stress="scene"):
        # With element-loop regions: fresh components of their cells, each at its level (the run's
        # become simulation.nonlinear.components, one LevelComponents per region, for the outputs).
        # The stability check's have no initial stress: its tiny state must keep the laws elastic (a
        # fresh law at the stage's stress, without the stage's history, would yield or crack at once).
        kernel = _kernels.LocalStepper(indptr, indices, blocks, simulation.mass, levels, simulation.time_step.dt,
                                       alpha)
        if len(simulation.dashpot_nodes):
            kernel.set_dashpots(np.ascontiguousarray(simulation.dashpot_nodes, dtype=np.int32),
                                np.ascontiguousarray(simulation.dashpot_matrices, dtype=np.float64))
        if simulation.constraints is not None:
            kernel.set_constraints(np.ascontiguousarray(simulation.constraints.nodes, dtype=np.int32),
                                   np.ascontiguousarray(simulation.constraints.projection, dtype=np.float64))
        if simulation.nonlinear is not None:
            regions = local_stepping.level_components(simulation.nonlinear, levels, cell_cap, initial_stress)
            for _, parts in regions:
                for component, level in parts:
                    kernel.add_internal_force(component, level)
            built["regions"] = [region for region, _ in regions]
        if row_split:
            kernel.set_row_split(True)  # every row at its own level: no caps
            return kernel
        # Column split: rows stepped at their drift level: the pair nodes (add_contact), and the fine
        # side of every level boundary, so that a coarser neighbour's force reaches them at each of
        # their substeps instead of as kicks at the ends of the coarse step (docs/local_stepping.md
        # "The column split").
        rows = [local_stepping.interface_rows(levels, cell_nodes, cell_cap, loop_cells)]
        if simulation.contact_arrays is not None:
            rows.append(np.unique(simulation.contact_arrays["pairs"]))
        kernel.step_rows_at_drift_level(np.unique(np.concatenate(rows)).astype(np.int32))
        return kernel

    if simulation.lts_stability is None and not simulation.lts_check_deferred:  # once per model
        simulation.lts_stability = local_stepping.check_stability(lambda: bare_kernel(0.0, None),
                                                                  simulation.stiffness.shape[0])
    report = simulation.lts_stability
    if report is not None and not report["stable"]:
        if simulation.scene["time"].get("local_stepping") == "auto":
            fall_back_to_global_stepping(simulation, report)
            return None
        raise local_stepping.unstable_words(report)[0]
    kernel = bare_kernel(simulation.alpha)
    stage = simulation.static
    if simulation.nonlinear is not None:
        stage_components = getattr(stage, "components", None)
        if stage_components is not None:  # the relaxation stage's state, cut by level
            for region, whole in zip(built["regions"], stage_components):
                if whole is not None:
                    local_stepping.load_component_parts(whole, region.parts)
        simulation.nonlinear.components = built["regions"]
    if simulation.contact_arrays is not None:  # the pairs at their levels, read back as one set
        simulation.contact_pairs, parts = local_stepping.level_pairs(simulation.contact_arrays, levels, cell_nodes,
                                                                     cell_cap, loop_cells, make_contact_pairs,
                                                                     row_split)
        stage_contact = getattr(stage, "contact", None)
        if stage_contact is not None:
            local_stepping.load_pair_parts(stage_contact, simulation.contact_pairs.parts,
                                           simulation.contact_arrays["pairs"])
        for contact, level in parts:
            kernel.add_contact(contact, level)
    stepper = local_stepping.LocalSteppingAdapter(kernel, 2 ** int(levels.max()))
    if simulation.input_arrays is not None:
        kernel.add_provider(seismic_input_kernel(simulation.input_arrays))
    if simulation.static is not None:  # the stage's out-of-balance, held constant (pyfem/static.py)
        from pyfem.static import add_hand_over_force

        add_hand_over_force(stepper, simulation)
    return stepper


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


def make_stepper(simulation: Simulation):
    """The C++ stepper with the force providers the scene calls for, and nothing else (one rank;
    under `mpirun -n N` each rank builds its part's: pyfem/distributed_model.py)."""
    from pyfem import _kernels

    kernel_threads()
    indptr, indices, blocks = bsr_arrays(simulation.stiffness)
    if simulation.node_levels is not None:  # [time] local_stepping (pyfem/local_stepping.py)
        stepper = _make_local_stepper(simulation, indptr, indices, blocks)
        if stepper is not None:
            return stepper  # (None: "auto" fell back to global stepping)
    single = simulation.scene["time"].get("matrix_precision", "double") == "single"
    stepper = _kernels.Stepper(indptr, indices, blocks, simulation.mass, simulation.time_step.dt,
                               simulation.alpha, simulation.beta, True, single)
    if len(simulation.dashpot_nodes):
        stepper.set_dashpots(np.ascontiguousarray(simulation.dashpot_nodes, dtype=np.int32),
                             np.ascontiguousarray(simulation.dashpot_matrices, dtype=np.float64))
    if simulation.constraints is not None:
        stepper.set_constraints(np.ascontiguousarray(simulation.constraints.nodes, dtype=np.int32),
                                np.ascontiguousarray(simulation.constraints.projection, dtype=np.float64))
    if simulation.input_arrays is not None:
        stepper.add_provider(seismic_input_kernel(simulation.input_arrays))
    handed_over = getattr(simulation.static, "components", None) is not None  # a relaxation stage ran
    if simulation.contact_arrays is not None:
        contact = getattr(simulation.static, "contact", None)  # the stage's pairs, rebased, go on
        simulation.contact_pairs = contact if contact is not None else make_contact_pairs(simulation.contact_arrays)
        stepper.add_contact(simulation.contact_pairs)
    if simulation.nonlinear is not None:
        # A component holds the state of one run: fresh ones, or the stage's (rebased) after a
        # relaxation stage, which a prepared simulation hands to one stepper only.
        components = simulation.nonlinear.components if handed_over else simulation.nonlinear.new_components()
        for component in components:
            stepper.add_internal_force(component)
    for group in simulation.support:  # rock bolts and cables: the stage's (rebased) or fresh at t = 0
        stepper.add_internal_force(group.component)
    if simulation.static is not None:  # the stage's out-of-balance, held constant (pyfem/static.py)
        from pyfem.static import add_hand_over_force

        add_hand_over_force(stepper, simulation)
    return stepper


def upper_triangle_blocks(stiffness: sp.bsr_matrix) -> int:
    """Blocks the kernel's symmetric storage keeps: the diagonal and those above it."""
    n_block_rows = stiffness.shape[0] // 3
    rows = np.repeat(np.arange(n_block_rows), np.diff(stiffness.indptr))
    return int(np.count_nonzero(stiffness.indices > rows)) + n_block_rows


def element_name(model, order: int) -> str:
    """Q1/Q2 on hexahedra, P1/P2 on tetrahedra (a gmsh file of the user's)."""
    from dolfinx import mesh as dolfinx_mesh

    tetrahedra = model.mesh.topology.cell_type == dolfinx_mesh.CellType.tetrahedron
    return f"{'P' if tetrahedra else 'Q'}{order}{' tetrahedra' if tetrahedra else ''}"


def memory_estimate(simulation: Simulation) -> int:
    """Bytes held during the run: stiffness (BSR, and the kernel's upper-triangle copy), state and
    scratch vectors, input tables, contact pairs."""
    k = simulation.stiffness
    n_dofs = k.shape[0]
    total = k.data.nbytes + k.indices.nbytes + k.indptr.nbytes + 6 * 8 * n_dofs + simulation.mass.nbytes
    block_bytes = 36 if simulation.scene["time"].get("matrix_precision") == "single" else 72
    total += upper_triangle_blocks(k) * (block_bytes + 4) + 8 * (n_dofs // 3 + 1)
    if simulation.input_arrays is not None:
        total += sum(v.nbytes for v in simulation.input_arrays.values() if isinstance(v, np.ndarray))
    total += simulation.dashpot_matrices.nbytes * 2
    if simulation.contact_arrays is not None:
        n_pairs = len(simulation.contact_arrays["area"])
        total += sum(v.nbytes for v in simulation.contact_arrays.values() if isinstance(v, np.ndarray))
        total += n_pairs * (3 * 3 * 8 + 8)  # kernel state per pair: forces, D, state (estimate)
    if simulation.nonlinear is not None:
        total += simulation.nonlinear.memory_bytes  # element arrays, per-point state, buffers
    return int(total)


def plan(scene: Scene) -> dict:
    """What a run of the scene would do, without running it: effects, sizes, dt, memory and time.

    The time estimate comes from timing a few kernel steps on the real matrices. A static stage is
    described, not solved; with local stepping on, the set-up check of its map is estimated, not run
    (it runs when the run starts: 35 s on the coarse case 3, 400-1 060 s on the paper-scale cases).
    """
    simulation = prepare(scene, solve_static=False, preview_levels=True)
    simulation.lts_check_deferred = True
    return simulation_plan(simulation)


def free_field_words(scene: Scene) -> str:
    """Which free field the input faces get: the homogeneous half-space of wave.medium, or the layered
    site of [[wave.layers]] over it (the rock of each face against it: warn_input_medium)."""
    wave = scene["wave"]
    surface = "no free surface" if wave.get("surface") is None else f"free surface at z = {wave['surface']:g} m"
    layers = wave.get("layers") or []
    if not layers:
        return f"homogeneous '{wave['medium']}' half-space, {surface} (pyfem.seismic.freefield)"
    stack = ", ".join(f"{layer['thickness']:g} m of '{layer['medium']}'" for layer in layers)
    return f"layered site: {stack} (top down) over a '{wave['medium']}' half-space, {surface} (pyfem.seismic.layered)"


def resolution_plan(scene: Scene, model) -> dict:
    """{"mesh resolution": {region: its element sizes against the accuracy study's advice}} of a scene
    with a wave (pyfem.accuracy.resolution_report); a mesh file's too-coarse regions are warned of
    (the box and layered_cavern builders are checked from their scene keys)."""
    from pyfem.accuracy import resolution_report

    if "seismic_input" not in scene.effects:
        return {}
    try:
        lines, warnings = resolution_report(scene, model)
    except Exception as error:  # advice only: it must never stop a run
        return {"mesh resolution": f"no advice ({type(error).__name__}: {error})"}
    if scene["mesh"]["builder"] == "file":
        for warning in warnings:
            if warning not in scene.warnings:
                scene.warn(warning)
    return {"mesh resolution": lines} if lines else {}


def interface_slip_plan(scene: Scene, model) -> dict:
    """{"interface slip": {name: what the slip study says at its resolution}} of a contact scene with
    a wave (pyfem.accuracy.interface_slip_advice), else {}."""
    from pyfem.accuracy import interface_slip_advice

    try:
        advice = interface_slip_advice(scene, model)
    except Exception as error:  # advice only: it must never stop a run
        return {"interface slip": f"no advice ({type(error).__name__}: {error})"}
    return {"interface slip": advice} if advice else {}


def simulation_plan(simulation: Simulation, trial_steps: int = 20) -> dict:
    """The plan of a prepared simulation (`plan`; `run` prints it before the time loop).

    The time per step is measured on a stepper of its own, run `trial_steps` steps from rest and
    then dropped. It is made from a copy of the simulation without the static stage's state
    (static=None: fresh element-loop components and contact pairs), so the state a solved stage
    hands to the run's stepper is never touched.
    """
    import dataclasses

    from pyfem.static import plan_report
    from pyfem.support import support_plan

    scene = simulation.scene
    nonlinear = simulation.nonlinear
    kept = None if nonlinear is None else nonlinear.components  # the trial's fresh ones must not replace them
    trial = dataclasses.replace(simulation, static=None, contact_pairs=None,
                                support=[group.fresh() for group in simulation.support])
    stepper = make_stepper(trial)
    simulation.lts_stability = trial.lts_stability  # checked once per model (local time stepping)
    if trial.node_levels is None and simulation.node_levels is not None:  # "auto" fell back
        fall_back_to_global_stepping(simulation, trial.lts_stability)
    if simulation.node_levels is not None:  # whole global steps of local time stepping
        ratio = 2 ** int(simulation.node_levels.max())
        trial_steps = ratio * max(1, -(-trial_steps // ratio))
    n = simulation.stiffness.shape[0]
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    start = time.perf_counter()
    stepper.run(u, v, a, trial_steps, 0.0)
    per_step = (time.perf_counter() - start) / trial_steps
    phases = phase_split(stepper.phase_seconds(), per_step * trial_steps)
    del stepper
    if nonlinear is not None:
        nonlinear.components = kept
    model = simulation.model
    ts = simulation.time_step
    element_loop = element_loop_plan(simulation.nonlinear, per_step, simulation.time_step,
                                     phases.get("element_loop", {}).get("ms_per_step", 0.0) * 1e-3)
    return {
        "title": scene["title"],
        "effects on": ", ".join(scene.effects) or "none (free vibration)",
        "mesh": f"{scene['mesh']['builder']}, {element_name(model, scene['mesh']['order'])}, {model.n_cells} cells",
        "nodes": len(simulation.mass),
        "dofs": n,
        **({"free field": free_field_words(scene)} if "seismic_input" in scene.effects else {}),
        **({"contact pairs": len(simulation.contact_arrays["area"])} if simulation.contact_arrays else {}),
        **({"interface wear": wear_words(simulation.contact_arrays["deterioration"],
                                         run_origin(simulation.lead_in, ts) + simulation.n_steps * ts.dt)["note"]}
           if simulation.contact_arrays and simulation.contact_arrays["deterioration"] is not None else {}),
        "truncation faces": {face["name"]: f"{face['type']}, {face['nodes']} nodes, {face['area']:.4g} m^2"
                             + (", input" if face["input"] else "") + f" ({face['source']})"
                             for face in face_report(model)},
        "traction-free surfaces": ", ".join(f"{name} ({count} facets)" for name, count in
                                            model.free_surfaces.items()) or "none",
        "dt": f"{ts.dt:.6g} s ({ts.reason})",
        **({"local stepping (auto)": simulation.lts_decision} if simulation.lts_decision else {}),
        **({"local stepping": lts_stability_line(simulation.lts_stability)} if simulation.lts_stability else {}),
        **({"local stepping": deferred_check_line(simulation, per_step)}
           if simulation.lts_stability is None and simulation.node_levels is not None else {}),
        **lts_preview_plan(simulation, {name: entry["ms_per_step"] for name, entry in phases.items()}),
        **element_loop,
        **({"static stage": plan_report(scene, model)} if "static" in scene else {}),
        **({"support": support_plan(simulation)} if simulation.support else {}),
        **interface_slip_plan(scene, model),
        **resolution_plan(scene, model),
        "steps": simulation.n_steps,
        "memory": f"{memory_estimate(simulation) / 2**20:.1f} MiB",
        "time per step": f"{per_step * 1e3:.3f} ms (measured over {trial_steps} steps, from rest): "
                         + ", ".join(f"{name} {entry['ms_per_step']:.3f} ms" for name, entry in phases.items()
                                     if name != "other" or entry["ms_per_step"] > 0.0),
        "time estimate": f"{per_step * simulation.n_steps:.1f} s for {scene['time']['duration']:g} s of motion"
                         + (f" and the record's {simulation.lead_in:.3g} s lead-in before it (t < 0)"
                            if simulation.lead_in > 0.0 else ""),
        **static_stage_estimate(scene, per_step),
    }


def static_stage_estimate(scene: Scene, per_step: float) -> dict:
    """check's line on the static stage's time before the motion: its two relaxation stages of at
    most static.max_steps steps each at the dynamic step's cost from rest (the same kernel on the
    same cells), which a yielding rock raises several times (README "The element loop on the yield
    surface"); not a bound."""
    from pyfem.static import uses_relaxation

    if "static" not in scene or not uses_relaxation(scene):
        return {}
    max_steps = int(scene["static"]["max_steps"])
    return {"static stage estimate": f"2 stages of at most {max_steps} relaxation steps each (and a frequency probe) "
                                     f"before the motion: {2 * max_steps * per_step:.0f} s at this step's cost from "
                                     f"rest, several times that where the rock yields in the stage (a point on the "
                                     f"yield surface costs about 5x one at rest); a stage stops once its "
                                     f"out-of-balance ratio is reached (the coarse case study's after 1 000-2 000 steps)"}


def lts_preview_plan(simulation: Simulation, phases_ms: dict) -> dict:
    """check's line with local stepping off where the scene allows it: the speed-up its rate levels
    and this step's measured phases predict (local_stepping.predicted_speed_up), and how to turn it on."""
    if simulation.lts_preview is None:
        return {}
    from pyfem import local_stepping

    model = simulation.model
    cell_nodes = model.V.dofmap.list.array.reshape(model.n_cells, -1)
    pairs = simulation.contact_arrays["pairs"] if simulation.contact_arrays is not None else None
    rows = local_stepping.row_split(simulation.nonlinear, pairs is not None)
    p = local_stepping.predicted_speed_up(simulation.lts_preview, cell_nodes, simulation.nonlinear,
                                          simulation.stiffness, pairs, simulation.time_step, phases_ms, rows)
    auto_declined = (simulation.scene["time"].get("local_stepping") == "auto"
                     and str(simulation.lts_decision or "").startswith('"auto": off: predicted'))
    if p["speed_up"] < local_stepping.AUTO_PAYS:
        verdict = "not worth it on this model"
    elif auto_declined:  # per step it pays, over this run not (line above): say which
        verdict = ("it would pay per simulated second on a longer run; over this run's duration the set-up check "
                   "costs more than it saves (\"auto\" above)")
    elif rows:
        verdict = ("it would pay (time.local_stepping = true; the row split: stresses where levels meet as global "
                   "stepping's, docs/local_stepping.md \"The scheme: the row split\")")
    else:
        verdict = ("it would pay (time.local_stepping = true), but it would step by the column split, whose stresses "
                   "where a finer level meets a coarser one are less accurate (a cavity test: 8.7 % off the exact "
                   "history at safety 0.8, global stepping 0.5 %; docs/local_stepping.md \"The column split\")")
    return {"local stepping (off)": (
        f"predicted {p['speed_up']:.2f}x the speed of global stepping per simulated second ({len(p['levels'])} "
        f"rate level{'s' if len(p['levels']) != 1 else ''}, nodes per level {p['levels']}; work against global "
        "stepping: "
        + (f"element loop {p['element_loop']:.2f}, " if simulation.nonlinear is not None else "")
        + f"matrix {p['matrix']:.2f}"
        + (f", contact {p['contact']:.2f}" if pairs is not None else "")
        + f"); {verdict}")}


def deferred_check_line(simulation: Simulation, per_step: float) -> str:
    """`check`'s line on the LTS map's set-up check, which it leaves to the run."""
    from pyfem.local_stepping import STABILITY_STEPS

    fine_steps = STABILITY_STEPS * 2 ** int(simulation.node_levels.max())
    return (f"the set-up check of its map runs when the run starts ({STABILITY_STEPS} global steps, "
            f"{fine_steps} fine steps: at most about {fine_steps * per_step:.3g} s at this plan's step time)")


def lts_stability_line(report: dict) -> str:
    """check's line on the local time stepping map's stability check (pyfem/local_stepping.py)."""
    return (f"{'stable' if report['stable'] else 'UNSTABLE'} on this model: a random state's energy changed "
            f"{report['growth']:.3g}x over "
            f"{report['global_steps']} global steps (amplitude factor {report['growth_per_step']:.6f} per "
            f"step; unstable from 2x), {report['seconds']:.2f} s")


PHASES = ("update", "element_loop", "input_forces", "stiffness", "contact")
"""The kernel's phases of a step (Stepper.phase_seconds; cpp_kernels/stepper.hpp PhaseTimes)."""
DISTRIBUTED_PHASES = ("exchange",)
"""Under mpirun: the ghost exchange of every step (pyfem/distributed_model.py)."""


def phase_split(phase_seconds: dict, loop_seconds: float, output_seconds: float | None = None) -> dict:
    """Per phase of a step: ms per step and share of the time loop.

    Args:
        phase_seconds: Stepper.phase_seconds() (s per phase, and "steps").
        loop_seconds: wall time of the whole loop the steps ran in (s).
        output_seconds: of that, the time spent writing samples (s), None if not measured.

    Returns:
        {phase: {"ms_per_step", "share"}} for PHASES, "output" (when given) and "other" (the loop's
        remainder: Python between the kernel's calls, progress lines).
    """
    steps = max(1, int(phase_seconds["steps"]))
    seconds = {name: float(phase_seconds[name]) for name in PHASES}
    for name in DISTRIBUTED_PHASES:  # under mpirun
        if phase_seconds.get(name):
            seconds[name] = float(phase_seconds[name])
    if output_seconds is not None:
        seconds["output"] = float(output_seconds)
    seconds["other"] = max(0.0, loop_seconds - sum(seconds.values()))
    total = max(loop_seconds, 1e-300)
    return {name: {"ms_per_step": 1e3 * value / steps, "share": value / total} for name, value in seconds.items()}


def element_loop_plan(nonlinear, per_step: float, time_step: TimeStep, loop: float) -> dict:
    """The plan's lines on the element loop: its regions, points, state bytes and measured time,
    and why the elastic stable step holds. loop: the element loop's seconds per step in the same
    trial steps as per_step (the kernel's phase times), so that its share and the per-step
    breakdown are one measurement."""
    from pyfem.elements import plastic_frequency_factor

    if nonlinear is None:
        return {"element loop": "none (no [plasticity] or [damage] table: every cell in the stiffness "
                                "matrix)"}
    regions, stiffening = {}, 1.0
    for component, (name, (law, parameters)) in zip(nonlinear.components, nonlinear.laws.items()):
        one_point = nonlinear.integration.get(name) == "reduced"
        regions[name] = (f"{law}, {component.n_cells} cells, {component.n_cells * component.n_points} points"
                         + (", one point per cell (its hourglass stiffness in the matrix)" if one_point else "")
                         + (", mean dilatation" if component.mean_dilatation else "")
                         + f", {component.owned_bytes / 2**20:.1f} MiB of state and buffers")
        u_ref = parameters.get("damage_plastic_displacement", 0.0) if law == "mohr_coulomb" else 0.0
        if u_ref > 0.0 and component.n_cells:  # the rock's crack band: kappa_ref per cell (docs/materials.md)
            h = np.asarray(component.characteristic_length())
            regions[name] += (f", crack band u_ref = {u_ref:g} m: kappa_ref {u_ref / h.max():.3g}-{u_ref / h.min():.3g} "
                              f"in its cells (h {h.min():.3g}-{h.max():.3g} m, the cube root of a cell's volume)")
        if law == "mohr_coulomb":
            stiffening = max(stiffening, plastic_frequency_factor(parameters["poisson_ratio"],
                                                                  parameters["friction_angle"],
                                                                  parameters.get("dilation_angle", 0.0)))
    margin = time_step.critical / time_step.dt
    return {
        "nonlinear regions": regions,
        "element loop": (f"{loop * 1e3:.3f} ms per step ({loop / max(1, nonlinear.n_points) * 1e9:.0f} ns per "
                         f"point, {100 * loop / max(per_step, 1e-300):.0f} % of the step, in the trial steps of "
                         "'time per step'), measured at rest; a yielding "
                         "Mohr-Coulomb point costs about 6x, a damaging concrete point 3x (README)"),
        "element loop dt": ("from the full elastic stiffness: damage and mean dilatation only soften the cells"
                            + ("" if stiffening == 1.0 else
                               "; non-associated plastic flow (psi < phi) can raise a frequency by up to "
                               f"{100 * (stiffening - 1):.0f} %, "
                               f"{'inside' if stiffening < margin else 'BEYOND'} the step's margin "
                               f"{100 * (margin - 1):.0f} % to the stable limit")),
    }


def run(scene: Scene, out_dir, on_plan=None, progress=None, resume: bool = False) -> dict:
    """Runs the scene and writes run.json, monitors/, fields.xdmf and plots/ into out_dir.

    on_plan: called with the plan (`simulation_plan`, a dict) once the model is built, before
    the run directory is touched (the command line prints it). progress: None shows a tqdm bar
    on a terminal (stderr); else an object with start(t0) and __call__(t) (pyfem.progress.
    ProgressLines), told the simulated time reached after every output interval; no bar then.
    resume: continue the interrupted run in out_dir from its checkpoint (pyfem/checkpoint.py)
    instead of starting a new one; its histories then equal an uninterrupted run's.

    The histories are written as the run goes; every `output.checkpoint_interval` seconds of
    wall time the whole state goes to out_dir/checkpoint.npz (removed when the run finishes).
    Ctrl-C or SIGTERM stops the run between two samples: a checkpoint is written, run.json says
    "interrupted" with the time reached, every row so far is kept, and
    `pyfem.interrupts.RunInterrupted` (a KeyboardInterrupt) is raised. Any other error marks
    the run "failed" the same way (its last periodic checkpoint stays) and is raised again.

    Returns:
        The run summary (also written to run.json).
    """
    from pyfem.ranks import world

    if world().size > 1:  # under mpirun each rank builds and steps its part only
        from pyfem import distributed_model

        return distributed_model.run(scene, out_dir, on_plan=on_plan, progress=progress, resume=resume)
    from tqdm import tqdm

    from pyfem import checkpoint as checkpoints
    from pyfem.interrupts import RunInterrupted, StopSignals
    from pyfem.output import RunWriter

    wall_start = time.perf_counter()
    saved = checkpoints.read_checkpoint(out_dir) if resume else None  # refused before any work
    if saved is not None:
        saved.check_scene(scene)  # another scene is refused before the model is built
    with StopSignals() as signals:
        from pyfem import static_output

        # A resumed run takes the stage from static/hand_over.npz instead of solving it again.
        stage = static_output.read_hand_over(out_dir) if saved is not None and "static" in scene else None
        report = saved.meta.get("lts_stability") if saved is not None else None

        def as_first_sitting(simulation):
            # "auto" fell back to global stepping in the first sitting: the same now, before the
            # stage's hand-over (which holds the first sitting's dt) is compared with the model
            if (report and not report["stable"] and simulation.node_levels is not None
                    and scene["time"].get("local_stepping") == "auto"):
                fall_back_to_global_stepping(simulation, report)
            return simulation

        try:
            simulation = as_first_sitting(prepare(scene, solve_static=stage is None))  # scene/mesh errors surface here
        except RunInterrupted as error:  # the set-up keeps nothing: say what was lost
            error.setup_seconds = time.perf_counter() - wall_start
            error.setup_words = "mesh, matrices" + (" and the static stage" if "static" in scene and stage is None
                                                    else "")
            raise
        if saved is not None:
            saved.check_model(simulation)  # before a stage is solved again for a checkpoint it would refuse
            saved.check_end(run_origin(simulation.lead_in, simulation.time_step)
                            + simulation.n_steps * simulation.time_step.dt, scene["time"]["duration"])
        restored = stage is not None and static_output.restore_hand_over(simulation, stage)
        if stage is not None and not restored:
            simulation = as_first_sitting(prepare(scene))  # the file is of another model: the stage is solved again
        if saved is not None:
            if report and simulation.node_levels is not None:
                # The same model and levels (the fingerprint): the LTS map's check is not run again
                # (852 s on the paper-scale case 1); run.json keeps the first sitting's report.
                simulation.lts_stability = saved.meta["lts_stability"]
        if on_plan is not None:
            plan = simulation_plan(simulation)
            if saved is not None:  # the plan's estimates are a whole run's: say what this sitting does
                stage_words = ("" if "static" not in scene else
                               "; the static stage read from static/hand_over.npz, not solved again" if restored
                               else "; the static stage solved again (no hand-over file of this model)")
                plan = {"resuming": f"from the checkpoint at t = {saved.t:.6g} s of {scene['time']['duration']:g} s"
                                    f"{stage_words}", **plan}
            on_plan(plan)
        writer = RunWriter(out_dir, simulation)
        # the set-up counts towards the first checkpoint (a long stage is not solved twice)
        clock = checkpoints.CheckpointClock(scene["output"]["checkpoint_interval"],
                                            elapsed=time.perf_counter() - wall_start)
        write_checkpoint = None  # set once the state (u, v, a, t, kernel, writer) is whole
        stepper = None
        try:
            stepper = make_stepper(simulation)
            n = simulation.stiffness.shape[0]
            ts = simulation.time_step
            n_outputs = simulation.n_steps // ts.steps_per_output
            previous = {"wall_seconds": 0.0, "loop_seconds": 0.0, "output_seconds": 0.0, "phases": {}}
            if saved is None:
                with signals.deferred():
                    writer.start()
                    if simulation.static is not None:  # static/ and the stage's stress in the fields
                        from pyfem.static_output import write_static_outputs

                        write_static_outputs(writer)
                u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
                origin = run_origin(simulation.lead_in, ts)
                t = origin
                done = 0
                stepper.reset_energy(u, v, a, t)
                with signals.deferred():
                    writer.sample(t, u, v, a, stepper.energy())
            else:
                with signals.deferred():
                    writer.resume(saved.meta["writer"], saved.writer, saved.t)
                    if simulation.static is not None:
                        static_output.static_stress_in_fields(writer)
                        if not isinstance(simulation.static, static_output.SavedStage):  # solved again:
                            static_output.write_hand_over(Path(out_dir) / "static", simulation)  # once
                stepper.load_state(saved.kernel)
                u, v, a = saved.u.copy(), saved.v.copy(), saved.a.copy()
                t, done = saved.t, saved.outputs_done
                origin = run_origin(simulation.lead_in, ts)
                previous = saved.meta["timing"]
            stepper.reset_phase_seconds()
            output_seconds = 0.0
            loop_start = time.perf_counter()

            def timing() -> dict:
                """Wall time so far, over every sitting of this run."""
                now = time.perf_counter()
                phases = dict(stepper.phase_seconds())
                return {"wall_seconds": previous["wall_seconds"] + now - wall_start,
                        "loop_seconds": previous["loop_seconds"] + now - loop_start,
                        "output_seconds": previous["output_seconds"] + output_seconds,
                        "phases": {key: previous["phases"].get(key, 0.0) + value for key, value in phases.items()}}

            def checkpoint_now() -> None:
                began = time.perf_counter()
                writer_meta, writer_arrays = writer.checkpoint_state()
                meta = {"fingerprint": checkpoints.model_fingerprint(simulation), "t": t, "outputs_done": done,
                        "timing": timing(), "writer": writer_meta}
                if simulation.lts_stability:
                    meta["lts_stability"] = simulation.lts_stability
                checkpoints.write_checkpoint(out_dir, meta, u, v, a, stepper.save_state(), writer_arrays)
                clock.written(time.perf_counter() - began)

            write_checkpoint = checkpoint_now
            if progress is not None:
                progress.start(t)
            with tqdm(total=n_outputs, initial=done, desc=scene["title"][:30], unit="out", leave=False,
                      disable=progress is not None or not writer.show_progress) as bar:
                while done < n_outputs:
                    # One block: a stop signal waits for the sample, so the state is whole for a checkpoint.
                    with signals.deferred():
                        # The block's start and end times as products, not sums: no drift over a
                        # long record (2.0 is written 2.0, not 1.9999999999999793), the same on resume.
                        stepper.run(u, v, a, ts.steps_per_output, origin + done * ts.steps_per_output * ts.dt)
                        done += 1
                        t = origin + done * ts.steps_per_output * ts.dt
                        reactions = stepper.reactions() if simulation.constraints is not None else None
                        if not np.isfinite(u).all():
                            raise FloatingPointError(f"the solution became non-finite at t = {t:.6g} s")
                        output_start = time.perf_counter()
                        writer.sample(t, u, v, a, stepper.energy(), reactions)
                        output_seconds += time.perf_counter() - output_start
                        if clock.due() and done < n_outputs:
                            write_checkpoint()
                    bar.update()
                    if progress is not None:
                        progress(t)
            total = timing()
            phases = phase_split(total["phases"], total["loop_seconds"], total["output_seconds"])
            summary = writer.finish(wall_seconds=total["wall_seconds"], loop_seconds=total["loop_seconds"],
                                    phases=phases, checkpoints={"written": clock.count, "seconds": clock.seconds,
                                                                "interval": clock.interval})
            (Path(out_dir) / checkpoints.CHECKPOINT_NAME).unlink(missing_ok=True)  # finished: nothing to resume
            return summary
        except KeyboardInterrupt as error:
            interrupted = error if isinstance(error, RunInterrupted) else RunInterrupted()
            if writer.started:
                with signals.deferred(reraise=False):  # a second Ctrl-C must not cut the files short
                    if write_checkpoint is not None:
                        try:
                            write_checkpoint()
                        except Exception as problem:  # the interruption must still be reported
                            writer.checkpoint_problem = f"{type(problem).__name__}: {problem}"
                    writer.fail(f"interrupted by {interrupted.signal_name}", interrupted=True)
                interrupted.time_reached = writer.times[-1] if writer.times else None
                interrupted.out_dir = writer.out_dir
            if interrupted is error:
                raise
            raise interrupted from error
        except BaseException as error:
            if writer.started:
                with signals.deferred(reraise=False):
                    writer.fail(f"{type(error).__name__}: {error}")
                reached = f"t = {writer.times[-1]:.6g} s" if writer.times else "no sample"
                error.add_note(f"run failed; the results up to {reached} are kept in {writer.out_dir}")
            raise

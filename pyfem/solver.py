"""Builds the explicit kernel from a scene and runs it in chunks of one output interval.

Data flow (docs/method.md section 1): scene -> model (gmsh -> dolfinx operators) -> boundary
springs/dashpots and seismic input forces -> C++ Stepper (many steps per call) -> outputs.
Python owns orchestration and I/O; nothing in Python runs once per time step.
"""
from __future__ import annotations

import dataclasses

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from pyfem.clock import POWER_ITERATIONS, TimeStep, phase_split, time_step_from
from pyfem.clock import record_lead_in, run_origin, run_steps, whole_steps  # noqa: F401  (also pyfem.solver.*)
from pyfem.effects import (BoundaryConstraints, MonitorStress, attach_kernel_points, boundary_constraints, bsr_arrays,
                           check_input_faces, contact_arguments, damping_coefficients, flow_warnings,
                           free_field_words, kernel_threads, make_contact_pairs, monitor_stress_operator,
                           seismic_input_kernel, warn_far_pair_monitor, warn_input_medium)
from pyfem.local_stepping import lts_stability_line
from pyfem.interfaces import wear_words  # noqa: F401  (also pyfem.solver.wear_words)
from pyfem.operators import face_report  # noqa: F401  (also pyfem.solver.face_report)
from pyfem.plan import (deferred_check_line, element_loop_plan, element_name, face_lines, interface_slip_plan,
                        lts_preview_lines, model_lines, resolution_plan, time_lines)
from pyfem.scene import Scene, SceneError

# Memory traffic assumed by the time estimate before a measurement exists (bytes/s).
_ASSUMED_BANDWIDTH = 5.0e9


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


def choose_time_step(scene: Scene, stiffness: sp.bsr_matrix, mass: np.ndarray, beta: float,
                     coords: np.ndarray) -> TimeStep:
    """Stable step of central differences for M^-1 K, with stiffness-proportional damping.

    omega_max^2 is bounded above by Gershgorin row sums of M^-1 K (guaranteed); power
    iteration sharpens it (an estimate from below, so it is raised by 5 % before use and
    never exceeds the bound). With damping ratio xi = beta omega/2 at omega_max the limit is
    dt_crit = (2/omega)(sqrt(1 + xi^2) - xi). Mass-proportional damping and dashpots are
    implicit and do not restrict the step. The power iteration starts from a function of the node
    coordinates (`coords`, (n, 3) m; pyfem.distributed_parts.power_iteration), as the distributed
    model's does: the same estimate for any numbering and rank count.
    """
    from pyfem import _kernels
    from pyfem.distributed_parts import power_iteration

    indptr, indices, blocks = bsr_arrays(stiffness)
    omega2_bound = _kernels.gershgorin_bound(indptr, indices, blocks, mass)
    omega2_power = None
    if scene["time"].get("power_iteration", True):
        omega2_power = power_iteration((indptr, indices, blocks), mass, np.asarray(coords, dtype=np.float64),
                                       len(mass), POWER_ITERATIONS)
    return time_step_from(scene, omega2_bound, omega2_power, beta)


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
        bounded = (stiffness + stiffness_bound(support, model.n_nodes)).tobsr(blocksize=(3, 3))
        time_step = choose_time_step(scene, bounded, mass, beta, model.node_coords)
    else:
        bounded = stiffness
        time_step = choose_time_step(scene, stiffness, mass, beta, model.node_coords)
    nonlinear = nonlinear_regions(scene, model, time_step)
    elastic_stiffness = bounded  # of every cell (and the bolts' bound): the rate levels of local stepping
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
    bolt_groups = []  # rock bolts and cables: each group's parts by level (pyfem/distributed_support.py)
    if simulation.support:
        from pyfem.distributed_support import serial_group

        handed_over = getattr(simulation.static, "components", None) is not None  # a relaxation stage ran
        bolt_groups = [serial_group(group, index, handed_over) for index, group in enumerate(simulation.support)]

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
        # Rock bolts and cables: each bolt at the finest level of its host nodes (pyfem/distributed_support.py;
        # the run's parts continue the stage's components, cut by level; the check's are fresh).
        for rank_group in bolt_groups:
            if initial_stress is None:
                from pyfem.distributed_support import make_component

                parts = [(level, make_component(rank_group, bolts)) for level, bolts in
                         rank_group.by_level(rank_group.counted, levels)]
            else:
                if rank_group.parts:
                    rank_group.split_by_level(levels)
                else:
                    rank_group.fresh(levels)
                parts = [(part.level, part.component) for part in rank_group.parts]
            for level, component in parts:
                kernel.add_internal_force(component, int(level))
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
        # From STABILITY_AMPLITUDE times a function of the node coordinates: the distributed model's
        # state (pyfem.distributed_lts.check_stability_on_ranks), the same for any numbering.
        from pyfem.distributed_parts import start_vector

        state = local_stepping.STABILITY_AMPLITUDE * start_vector(simulation.model.node_coords).reshape(-1)
        simulation.lts_stability = local_stepping.check_stability(lambda: bare_kernel(0.0, None),
                                                                  simulation.stiffness.shape[0], state=state)
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
    for group, rank_group in zip(simulation.support, bolt_groups):  # the outputs read the parts as one group
        from pyfem.distributed_support import LevelBolts

        group.bolts = dataclasses.replace(group.bolts, component=LevelBolts(rank_group))
    stepper = local_stepping.LocalSteppingAdapter(kernel, 2 ** int(levels.max()))
    if simulation.input_arrays is not None:
        kernel.add_provider(seismic_input_kernel(simulation.input_arrays))
    if simulation.static is not None:  # the stage's out-of-balance, held constant (pyfem/static.py)
        from pyfem.static import add_hand_over_force

        add_hand_over_force(stepper, simulation)
    return stepper


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
    from pyfem.ranks import distributed

    if distributed():  # the distributed model's plan (rank 0's; {} on the others), the same lines
        from pyfem import distributed_model

        return distributed_model.check(scene)
    simulation = prepare(scene, solve_static=False, preview_levels=True)
    simulation.lts_check_deferred = True
    return simulation_plan(simulation)


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
        **model_lines(scene, element_name(model, scene["mesh"]["order"]), model.n_cells, len(simulation.mass)),
        **({"free field": free_field_words(scene)} if "seismic_input" in scene.effects else {}),
        **({"contact pairs": len(simulation.contact_arrays["area"])} if simulation.contact_arrays else {}),
        **({"interface wear": wear_words(simulation.contact_arrays["deterioration"],
                                         run_origin(simulation.lead_in, ts) + simulation.n_steps * ts.dt)["note"]}
           if simulation.contact_arrays and simulation.contact_arrays["deterioration"] is not None else {}),
        **face_lines(face_report(model), model.free_surfaces),
        "dt": f"{ts.dt:.6g} s ({ts.reason})",
        **({"local stepping (auto)": simulation.lts_decision} if simulation.lts_decision else {}),
        **({"local stepping": lts_stability_line(simulation.lts_stability)} if simulation.lts_stability else {}),
        **({"local stepping": deferred_check_line(int(simulation.node_levels.max()), per_step)}
           if simulation.lts_stability is None and simulation.node_levels is not None else {}),
        **lts_preview_plan(simulation, {name: entry["ms_per_step"] for name, entry in phases.items()}),
        **element_loop,
        **({"static stage": plan_report(scene, model)} if "static" in scene else {}),
        **({"support": support_plan(simulation)} if simulation.support else {}),
        **interface_slip_plan(scene, model),
        **resolution_plan(scene, model),
        "steps": simulation.n_steps,
        "memory": f"{memory_estimate(simulation) / 2**20:.1f} MiB",
        **time_lines(scene, per_step, trial_steps, phases, simulation.n_steps, simulation.lead_in),
    }


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
    return lts_preview_lines(p, simulation.scene, simulation.lts_decision, simulation.nonlinear is not None,
                             pairs is not None, rows)


def run(scene: Scene, out_dir, on_plan=None, progress=None, resume: bool = False) -> dict:
    """Runs the scene and writes run.json, monitors/, fields.xdmf and plots/ into out_dir.

    on_plan: called with the plan (`simulation_plan`, a dict) once the model is built, before
    the run directory is touched (the command line prints it). progress: None shows a tqdm bar
    on a terminal (stderr); else an object with start(t0) and __call__(t) (pyfem.progress.
    ProgressLines), told the simulated time reached after every output interval; no bar then.
    resume: continue the interrupted or finished run in out_dir from its checkpoint (pyfem/checkpoint.py)
    to the scene's time.duration instead of starting a new one; its histories then equal an
    uninterrupted run's.

    The histories are written as the run goes; every `output.checkpoint_interval` seconds of
    wall time the whole state goes to out_dir/checkpoint.npz, and at the end the final state (kept:
    `resume` with a longer time.duration extends a finished run).
    Ctrl-C or SIGTERM stops the run between two samples: a checkpoint is written, run.json says
    "interrupted" with the time reached, every row so far is kept, and
    `pyfem.interrupts.RunInterrupted` (a KeyboardInterrupt) is raised. Any other error marks
    the run "failed" the same way (its last periodic checkpoint stays) and is raised again.

    Returns:
        The run summary (also written to run.json).
    """
    from pyfem.ranks import distributed

    if distributed():  # under mpirun each rank builds and steps its part only
        from pyfem import distributed_model

        return distributed_model.run(scene, out_dir, on_plan=on_plan, progress=progress, resume=resume)
    if (scene.get("wave") or {}).get("free_field", {}).get("method") == "drm":
        raise SceneError("wave.free_field.method", "drm", "\"half_space\" on the serial path: the domain-reduction "
                         "method runs on the distributed model (PYFEM_ONE_MODEL=1 on one rank, or mpirun)")
    from tqdm import tqdm

    from pyfem import checkpoint as checkpoints
    from pyfem.interrupts import RunInterrupted, StopSignals
    from pyfem.output import RunWriter

    wall_start = time.perf_counter()
    saved = checkpoints.read_checkpoint(out_dir, state=False) if resume else None  # refused before any work
    if saved is not None and saved.meta.get("model") == "distributed":
        raise SceneError("--resume", str(out_dir), "the checkpoint of a run of the serial path",
                         f"--resume {saved.path}: written by the distributed model (each rank's state in its own "
                         "file, keyed by position); resume it under mpirun on any number of ranks, or on one rank "
                         "with PYFEM_ONE_MODEL=1")
    if saved is not None:
        saved = checkpoints.read_checkpoint(out_dir)
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
                if restored:  # not solved in this sitting: no estimate of its time (issue 51)
                    plan.pop("static stage estimate", None)
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

            def checkpoint_now(final: bool = False) -> None:
                """The state at the last sample to checkpoint.npz; final: the finished run's (kept, so
                that a longer time.duration extends the run; not counted with the periodic ones)."""
                began = time.perf_counter()
                writer_meta, writer_arrays = writer.checkpoint_state()
                meta = {"fingerprint": checkpoints.model_fingerprint(simulation), "t": t, "outputs_done": done,
                        "timing": timing(), "writer": writer_meta}
                if final:
                    meta["final"] = True
                if simulation.lts_stability:
                    meta["lts_stability"] = simulation.lts_stability
                checkpoints.write_checkpoint(out_dir, meta, u, v, a, stepper.save_state(), writer_arrays)
                if not final:
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
            with signals.deferred():  # the final state, kept: a longer time.duration and --resume extend the run
                write_checkpoint(final=True)
            total = timing()
            phases = phase_split(total["phases"], total["loop_seconds"], total["output_seconds"])
            return writer.finish(wall_seconds=total["wall_seconds"], loop_seconds=total["loop_seconds"],
                                 phases=phases, checkpoints={"written": clock.count, "seconds": clock.seconds,
                                                             "interval": clock.interval})
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

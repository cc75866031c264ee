"""An excavation sequence: the static stage of `[[static.step]]` entries on the distributed model
(docs/static.md "An excavation sequence").

The sequence runs on its own model, built without the first step's regions only (`pyfem.scene.
model_excavation(scene, stage_model=True)`): the later steps' regions are in it until their step.
The dynamic run's model is built without every step's regions, as a one-step stage's; `carry` then
hands the sequence's end over to it by position (the checkpoint's keys, pyfem/ranks.py): the nodal
displacements by node position, the element loop's per-point state by cell centroid.

Step k (in order): its regions R_k leave (their cells out of the matrices and the element loop, the
nodes only they used idle), the share `relaxation` of the load their removal creates is released,
its `install` regions join stress-free, then the rest is released. The load of removing R_k from a
state in equilibrium is the force R_k exerted on the rest:

    F_1 = f_exc(rock_1),   F_k = f_exc(rock_k) - f_exc(rock_{k-1}) + K_{R_k} u   (k > 1)

with f_exc(rock) the one-step stage's excavation load of the cells present (pyfem.static.
stage_loads: the in-situ traction on the truncation faces, the body force, - B^T sigma0) and u the
displacement so far: R_k is linear elastic (the scene refuses a law there), its stress sigma0 + C :
eps(u). Summed over the steps a linear model's loads give K_n u = f_exc(rock_n), the one-step
stage's: the path does not matter (tests/test_static_sequence.py); with plastic rock it does.

Each sub-stage is dynamic relaxation with `relax`'s arithmetic on the ranks (pyfem/distributed_stage.py:
the scaled mass of every cell, the load ramp of the first step's probe, the components rebased and
the out-of-balance carried between sub-stages). A step without `install` is one sub-stage (its whole
load). A step's `support` groups (rock bolts) join unloaded with its installs and are carried to the
run's model by position (pyfem.distributed_support.load_state, the checkpoint's reader). Contact pairs
in a sequence are refused by the scene (not written yet).

The hand-over gathers every rank's node keys and element-loop states on every rank once (as a resume
reads every rank's checkpoint file): the whole model's keys on each rank for a moment, fine at the
sizes tested; an exchange routed by owner would avoid it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

PER_CELL_BLOCKS = ("state", "initial_stress")  # a component's per-cell state blocks (pyfem.ranks.state_rows)


@dataclass
class Sequence:
    """The sequence's end on the stage model's rank part.

    Attributes:
        u_total, u_support: (3 n_local,) the displacement since the start and since the first
            install (m), the kernel's numbering of the stage model.
        counted: region -> the stage model's counted component at the end (rebased).
        report: static.json's content (every rank).
        installed_regions: every step's install regions, in order.
    """

    u_total: np.ndarray
    u_support: np.ndarray
    counted: dict
    report: dict
    installed_regions: list


def _cells(model, names) -> np.ndarray:
    from pyfem.elements import region_cells

    pieces = [region_cells(model, name) for name in names]
    return np.unique(np.concatenate(pieces)).astype(np.int32) if pieces else np.zeros(0, dtype=np.int32)


def _active_nodes(part, matrix: tuple, components: list) -> np.ndarray:
    """(n_owned,) the nodes this rank steps that some present cell uses: a block row of the sub-stage's
    matrix or a node of an active element-loop cell (counted or halo: every cell at a node it steps)."""
    n = part.n_owned
    active = np.diff(matrix[0][:n + 1]) > 0
    for arrays in components:
        nodes = np.asarray(arrays.cell_nodes).ravel()
        active[nodes[nodes < n]] = True
    return active


def solve(part, loop) -> Sequence:
    """Runs the sequence on the stage model's rank part (`part`: pyfem.distributed_model.RankModel of
    the scene built with `stage_model`; `loop`: its RankRegions or None). A collective."""
    from pyfem.distributed_parts import element_loop_cells, region_summary
    from pyfem.distributed_stage import (_largest_displacement, _stage_stepper, check_held_on_ranks, kernel_nodal,
                                         owned_force, owned_rows, relax_on_ranks, scaled_mass, stage_matrix)
    from pyfem.elements import plastic_frequency_factor, scene_laws
    from pyfem.relaxation import probe_frequency, ramp_length
    from pyfem.scene import static_steps
    from pyfem.static import _stage_constraints, stage_boundary, stage_loads, stage_tolerance, unconverged_warning

    start = time.perf_counter()
    scene, comm, model = part.scene, part.comm, part.model
    root = comm.rank == 0
    settings = scene["static"]
    steps = static_steps(settings)
    tolerance, max_steps = stage_tolerance(scene), int(settings["max_steps"])
    boundary = stage_boundary(scene, model)
    _, _, constraints = _stage_constraints(model, boundary)
    owned = slice(0, 3 * part.n_owned)
    regions_all = list(model.regions)
    installs = [list(step["install"]) for step in steps]
    installed_regions = [name for names in installs for name in names]
    check_steps(part)
    dead_after = [[name for step in steps[1:k + 1] for name in step["excavate"]] for k in range(len(steps))]

    def global_norm(x):
        return math.sqrt(comm.allreduce(float(x[owned] @ x[owned])))

    def nodal(vector):
        return owned_force(part, kernel_nodal(part, vector))

    # f_exc of the rock present after each step (the installed regions carry no sigma0).
    installed_cells = _cells(model, installed_regions)
    f_rock = [nodal(stage_loads(scene, model, np.union1d(installed_cells, _cells(model, dead_after[k]))
                                .astype(np.int32)).excavation) for k in range(len(steps))]
    weights = [nodal(stage_loads(scene, model, _cells(model, names)).installed_weight) if names and settings["gravity"]
               else np.zeros(3 * part.n_local) for names in installs]
    traction = nodal(stage_loads(scene, model, installed_cells).in_situ_traction)
    floor = 1.0e-3 * global_norm(traction)

    loop_cells = element_loop_cells(scene, model)
    element_cells = (np.concatenate([cells for cells, _ in loop_cells.values()]) if loop_cells
                     else np.zeros(0, dtype=np.int32))
    laws, _ = scene_laws(scene)
    factor = max([plastic_frequency_factor(p["poisson_ratio"], p["friction_angle"], p["dilation_angle"])
                  for p in laws.values() if p["law"] == "mohr_coulomb"], default=1.0)
    # Rock bolts and cables of the steps' `support` join in their step's support sub-stage; the mass bounds
    # their condensed stiffness too (as the one-step stage's).
    bolts = [rank_group for rank_group in part.support if rank_group.stage == "static"]
    supports = [list(step["support"]) for step in steps]
    everything = stage_matrix(part, np.zeros(0, dtype=np.int32))
    if bolts:
        from pyfem.distributed_support import add_rows, bound_rows

        everything = add_rows(everything, part.n_owned, bound_rows(bolts, part.n_owned, part.n_local))
    mass = scaled_mass(part, everything, factor)
    del everything
    joined_bolts = []  # the rank groups installed so far

    counted_names = [] if loop is None else list(loop.counted.arrays)
    halo_names = [] if loop is None or loop.halo is None else list(loop.halo.arrays)
    counted = {name: None if name in installed_regions else loop.counted.new_component(name)
               for name in counted_names}
    halo = {name: None if name in installed_regions else loop.halo.new_component(name) for name in halo_names}

    # The sub-stages: (step, name, inactive regions, load fraction, the step's installs joining).
    plan = []
    for k, step in enumerate(steps):
        pending = [name for names in installs[k:] for name in names]
        later = [name for names in installs[k + 1:] for name in names]
        if installs[k] or supports[k]:
            plan.append((k, "excavation", dead_after[k] + pending, step["relaxation"], []))
            plan.append((k, "support", dead_after[k] + later, 1.0 - step["relaxation"], installs[k]))
        else:
            plan.append((k, "excavation", dead_after[k] + pending, 1.0, []))

    first_inactive = plan[0][2]
    elastic = stage_matrix(part, _cells(model, first_inactive))
    active0 = np.zeros(part.n_owned, dtype=bool)
    active0[np.repeat(np.arange(part.n_owned), np.diff(elastic[0][:part.n_owned + 1]))] = True
    check_held_on_ranks(part, boundary, constraints, active0)
    ramp, probe_steps = 0.0, 0
    if comm.allreduce(bool(loop is not None or bolts), op=MPI.LOR):  # path dependent: the load rises slowly
        probe_load = f_rock[0].copy()
        probe_load[owned][~active0.repeat(3)] = 0.0
        probe = _stage_stepper(part, elastic, mass, constraints, probe_load, [], [], None, 0.0)
        omega, probe_steps = probe_frequency(probe, mass, probe_load, max_steps, floor=floor, space=probe)
        ramp = ramp_length(omega)
    del elastic

    u_total = np.zeros(3 * part.n_local)
    u_join = None
    carried = np.zeros(3 * part.n_local)
    applied = np.zeros(3 * part.n_local)
    stages, step_reports = [], []
    step_load = None
    for index, (k, kind, inactive, fraction, joining) in enumerate(plan):
        stage_start = time.perf_counter()
        if kind == "excavation":  # the step's load, from the state the previous step left
            step_load = f_rock[0].copy() if k == 0 else f_rock[k] - f_rock[k - 1]
            if k > 0:
                removed = _cells(model, [n for n in regions_all if n not in steps[k]["excavate"]])
                K_removed = stage_matrix(part, removed, hourglass_but=[n for n in regions_all
                                                                      if n not in steps[k]["excavate"]])
                step_load[owned] += owned_rows(part, K_removed) @ u_total
                del K_removed
        else:
            if u_join is None:
                u_join = u_total.copy()
            for names, table, regions_of in ((counted_names, counted, None if loop is None else loop.counted),
                                             (halo_names, halo, None if loop is None else loop.halo)):
                for region in names:
                    if region in joining:
                        table[region] = regions_of.new_component(region, initial_stress=None)
            for rank_group in bolts:  # the step's bolts, unloaded
                if rank_group.name in supports[k]:
                    rank_group.fresh()
                    joined_bolts.append(rank_group)
        inactive_cells = _cells(model, inactive)
        matrix = stage_matrix(part, np.union1d(element_cells, inactive_cells).astype(np.int32), hourglass_but=inactive)
        active_counted = [c for name, c in counted.items() if c is not None and name not in inactive]
        active_halo = [c for name, c in halo.items() if c is not None and name not in inactive]
        arrays = ([loop.counted.arrays[n] for n, c in counted.items() if c is not None and n not in inactive] +
                  [loop.halo.arrays[n] for n, c in halo.items() if c is not None and n not in inactive]
                  if loop is not None else [])
        active = _active_nodes(part, matrix, arrays)
        for rank_group in joined_bolts:  # (after the element loop's components, as the one-step stage)
            active_counted += [b.component for b in rank_group.parts if b.kind == "counted"]
            active_halo += [b.component for b in rank_group.parts if b.kind == "halo"]
        load = fraction * step_load + carried + (weights[k] if kind == "support" else 0.0)
        load[owned][~active.repeat(3)] = 0.0  # (the nodes only removed or pending cells use stay still)
        applied += load - carried
        name = f"step {k + 1} {kind}"
        stepper, u_owned, result = relax_on_ranks(part, matrix, mass, constraints, load, active_counted, active_halo,
                                                  None, ramp, tolerance, max_steps, floor, name)
        u_total = u_total + stepper.u
        carried = np.zeros(3 * part.n_local)
        carried[owned] = result.out_of_balance
        present_u = u_total[owned] * active.repeat(3)  # (the nodes of removed cells are no longer the model's)
        largest, point, _ = _largest_displacement(comm, present_u, part.coords[:part.n_owned])
        stage_regions = (region_summary(comm, loop.counted, [counted[n] if n not in inactive else None
                                                             for n in counted_names]) if loop is not None else {})
        stage_seconds = comm.allreduce(time.perf_counter() - stage_start, op=MPI.MAX)
        if root:
            print(f"static stage '{name}': {'converged' if result.converged else 'NOT converged'} after "
                  f"{result.steps} relaxation steps, out-of-balance {result.residual:.2e} (tolerance {tolerance:g}), "
                  f"{stage_seconds:.0f} s (dynamic relaxation, distributed model, {comm.size} rank"
                  f"{'s' if comm.size > 1 else ''})", flush=True)
        if not result.converged:
            scene.warn(unconverged_warning(name, tolerance, max_steps, result, ramp))
        present = [n for n in regions_all if n not in inactive]
        stages.append({"name": name, "step": k + 1, "active_regions": present, "load_fraction": fraction,
                       "free_dofs": 3 * comm.allreduce(int(np.count_nonzero(active))), "iterations": result.steps,
                       "residual": result.residual, "converged": result.converged, "seconds": stage_seconds,
                       "max_displacement": largest, "max_displacement_point": point,
                       "solver": "dynamic relaxation (distributed model)", "regions": stage_regions})
        if index == len(plan) - 1 or plan[index + 1][0] != k:  # the step's end
            step_reports.append({
                "step": k + 1, "excavated": list(steps[k]["excavate"]), "installed": list(installs[k]),
                "support": list(supports[k]),
                "relaxation": steps[k]["relaxation"], "residual": result.residual,
                "out_of_balance": global_norm(carried) / max(global_norm(applied), floor),
                "max_displacement": largest, "max_displacement_point": point,
                "plastic_volume": (sum(r.get("yielded_volume", 0.0) for r in stage_regions.values())
                                   if root and stage_regions else 0.0),
                "seconds": sum(s["seconds"] for s in stages if s["step"] == k + 1)})
    largest, point, vector = _largest_displacement(comm, present_u, part.coords[:part.n_owned])
    report = {"settings": dict(settings, tolerance=tolerance, load_ramp_steps=ramp, probe_steps=probe_steps,
                               ranks=comm.size, model="distributed"),
              "initial_stress": scene.get("initial_stress"),
              "excavated": [name for step in steps for name in step["excavate"]],
              "installed": installed_regions, "boundary": boundary, "stages": stages, "steps": step_reports,
              "seconds": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
              "max_displacement": {"value": largest, "point": point, "vector": vector},
              "out_of_balance": global_norm(carried) / max(global_norm(applied), floor),
              "hand_over": "the dynamic run starts from u = v = 0 on the model without every step's regions, with "
                           "the sequence's stress (carried over by position); the out-of-balance above is not "
                           "applied",
              "load_ramp_steps": ramp,
              **({"regions": stages[-1]["regions"]} if loop is not None else {})}
    if bolts:  # the bolts as the sequence leaves them (rank 0; run.json and static.json "support")
        from pyfem.distributed_support import gather_groups
        from pyfem.support import group_summary

        groups = gather_groups(comm, bolts)
        if root:
            report["support"] = {group.name: group_summary(group) for group in groups}
    u_support = u_total - u_join if u_join is not None else np.zeros_like(u_total)
    return Sequence(u_total=u_total, u_support=u_support, counted=counted, report=report,
                    installed_regions=installed_regions)


def check_steps(part) -> None:
    """The steps' regions on the sequence's model (`check` and the run): each install names a region of
    the model and shares no node with a region a later step excavates (it would be cast against rock
    not yet removed: an install before its excavation). A collective.

    Raises:
        SceneError naming static.step.K.install.I."""
    from pyfem.scene import SceneError, static_steps

    model, comm = part.model, part.comm
    steps = static_steps(part.scene["static"])
    for k, step in enumerate(steps):
        for index, name in enumerate(step["install"]):
            if name not in model.regions:
                raise SceneError(f"static.step.{k}.install.{index}", name, "must name a region of the model: "
                                 + ", ".join(sorted(model.regions)))
    dofs = model.V.dofmap.list.array.reshape(len(model.V.dofmap.list.offsets) - 1, -1)
    for k, step in enumerate(steps):
        later = [name for s in steps[k + 1:] for name in s["excavate"]]
        if not later or not step["install"]:
            continue
        later_nodes = set(np.unique(dofs[_cells(model, later)]).tolist())
        global_of = model.V.dofmap.index_map.local_to_global
        later_global = set(global_of(np.fromiter(later_nodes, dtype=np.int32)).tolist()) if later_nodes else set()
        later_global = set().union(*comm.allgather(later_global))
        for index, name in enumerate(step["install"]):
            nodes = np.unique(dofs[_cells(model, [name])])
            mine = bool(len(nodes)) and bool(later_global & set(global_of(nodes.astype(np.int32)).tolist()))
            if comm.allreduce(mine, op=MPI.LOR):
                raise SceneError(f"static.step.{k}.install.{index}", name, "an install region touches a region a "
                                 "later step excavates (" + ", ".join(later) + "): install it in that step or after")


def carry(sequence: Sequence, stage_part, stage_loop, part, loop):
    """The sequence's end on the dynamic run's rank part (pyfem.distributed_stage.RankStage): the
    displacements by node position, each element-loop cell's per-point state by its centroid (fresh
    components of `loop` loaded with it), every stage model's node and cell the dynamic model has. A
    collective."""
    from pyfem.distributed_stage import RankStage
    from pyfem.ranks import point_keys, rows_of, state_rows

    comm = part.comm
    n = stage_part.n_owned
    mine = np.column_stack([sequence.u_total[:3 * n].reshape(-1, 3), sequence.u_support[:3 * n].reshape(-1, 3)])
    keys = np.concatenate(comm.allgather(stage_part.node_keys(np.arange(n))))
    values = np.concatenate(comm.allgather(mine))
    rows = rows_of(keys, part.node_keys(np.arange(part.n_local)), "nodes of the sequence's model")
    u_total = np.ascontiguousarray(values[rows, :3].reshape(-1))
    u_support = np.ascontiguousarray(values[rows, 3:].reshape(-1))
    counted, halo = [], []
    if loop is not None:
        found = {}
        names = sorted(set(loop.counted.arrays) | set(loop.halo.arrays if loop.halo is not None else {}))
        for name in names:
            arrays = None if stage_loop is None else stage_loop.counted.arrays.get(name)
            component = None if arrays is None else sequence.counted.get(name)
            piece = {"keys": np.zeros((0, 3), dtype=np.int64)}
            if component is not None:
                state = component.save_state()
                piece = {"keys": point_keys(arrays.points.mean(axis=1))}
                for block in PER_CELL_BLOCKS:
                    piece[block] = state_rows(state[block], len(arrays.weights))
            pieces = [p for p in comm.allgather(piece) if len(p["keys"])]
            found[name] = ({"keys": np.concatenate([p["keys"] for p in pieces]),
                            **{block: np.concatenate([p[block] for p in pieces]) for block in PER_CELL_BLOCKS}}
                           if pieces else None)
        for regions, out in ((loop.counted, counted), (loop.halo, halo)):
            if regions is None:
                continue
            for name, arrays in regions.arrays.items():
                component = regions.new_component(name)
                data = found.get(name)
                if data is not None and len(arrays.weights):
                    where = rows_of(data["keys"], point_keys(arrays.points.mean(axis=1)),
                                    f"cells of {name!r} in the sequence's model")
                    state = dict(component.save_state())
                    for block in PER_CELL_BLOCKS:
                        state[block] = np.ascontiguousarray(data[block][where]).tobytes()
                    component.load_state(state)
                out.append(component)
    averages = {} if loop is None else loop.counted.cell_averages(counted)
    groups = _carry_bolts(stage_part, part)
    with_bolts = comm.allreduce(sum(rank_group.stage == "static" for rank_group in part.support), op=MPI.MAX) > 0
    return RankStage(counted=counted, halo=halo, contact=None, u_total=u_total, u_support=u_support,
                     installed_regions=list(sequence.installed_regions), report=sequence.report,
                     cell_averages=[averages, averages], u_first=u_total.copy(), support_groups=groups,
                     bounds=part.model.bounds if with_bolts else None)  # (bounds: a collective)


def _carry_bolts(stage_part, part):
    """The sequence's bolts (the steps' support groups, rebased) onto the run's part: fresh components of
    its groups loaded by position with the checkpoint's reader (pyfem.distributed_support.load_state);
    returns the whole groups as the sequence leaves them (rank 0; None elsewhere and without bolts). A
    collective."""
    from pyfem.distributed_support import gather_groups, load_state, rank_state

    bolts = [rank_group for rank_group in part.support if rank_group.stage == "static"]
    if not part.comm.allreduce(len(bolts), op=MPI.MAX):
        return None
    files = part.comm.allgather(rank_state([g for g in stage_part.support if g.stage == "static"]))
    state = {}
    for rank_group in bolts:
        rank_group.fresh()
        for i, bolt_part in enumerate(rank_group.parts):
            bolt_part.prefix = f"carry/{rank_group.index}/{i}/"  # (the stepper sets its own later)
    for prefix, component in load_state(bolts, state, files, part.comm).items():
        own = component.save_state()
        component.load_state({name: state.get(prefix + name, block) for name, block in own.items()})
    return gather_groups(part.comm, bolts)


def sequence_lines(scene) -> dict:
    """`check`'s lines on an excavation sequence (instead of the one-step stage's two): per step what it
    removes, releases before its installs and installs; the model the sequence runs on."""
    from pyfem.scene import static_steps

    steps = static_steps(scene["static"])
    lines = {}
    for k, step in enumerate(steps):
        removed = ", ".join(step["excavate"]) + (" removed (absent from the model)" if k == 0 else " removed")
        if step["install"] or step["support"]:
            joining = ", ".join(step["install"] + [f"support group {name}" for name in step["support"]])
            lines[f"step {k + 1}"] = (f"{removed}; {step['relaxation']:g} of its load released, then "
                                      f"{joining} installed stress-free and the remaining "
                                      f"{1.0 - step['relaxation']:g} released")
        else:
            lines[f"step {k + 1}"] = f"{removed}; all of its load released (nothing installed)"
    later = [name for step in steps[1:] for name in step["excavate"]]
    lines["sequence model"] = (f"the sequence runs on a model with {', '.join(later)} in place (built besides the "
                               "run's); its end is carried over to the run's model by position")
    return lines

"""The plan's lines (`pyfem check`, and `pyfem run` before it steps) that the serial path
(pyfem/solver.py `simulation_plan`) and the distributed model (pyfem/distributed_model.py `whole_plan`)
share: the model's size, its faces, the element loop, the static stage, the mesh's resolution, the
time per step with its phase split and the time it predicts. Each builder takes the numbers of the
whole model; where a distributed model's rank holds only its part, the builder takes `comm` and sums
over the ranks (a collective: every rank calls it, rank 0 prints). Imports nothing of the execution
paths (pyfem/solver.py, pyfem/distributed_model.py both import it)."""
from __future__ import annotations

import numpy as np

from pyfem.clock import TimeStep
from pyfem.scene import Scene


def model_lines(scene: Scene, element: str, n_cells: int, n_nodes: int) -> dict:
    """title, effects on, mesh (builder, element, cells), nodes and dofs of the whole model."""
    return {"title": scene["title"],
            "effects on": ", ".join(scene.effects) or "none (free vibration)",
            "mesh": f"{scene['mesh']['builder']}, {element}, {n_cells} cells",
            "nodes": int(n_nodes),
            "dofs": 3 * int(n_nodes)}


def face_lines(faces: list, free_surfaces: dict) -> dict:
    """The truncation faces (pyfem.operators.face_report's rows, the whole model's) and the
    traction-free surfaces (name -> facets)."""
    return {"truncation faces": {face["name"]: f"{face['type']}, {face['nodes']} nodes, {face['area']:.4g} m^2"
                                 + (", input" if face["input"] else "") + f" ({face['source']})"
                                 for face in faces},
            "traction-free surfaces": ", ".join(f"{name} ({count} facets)" for name, count in
                                                free_surfaces.items()) or "none"}


def time_lines(scene: Scene, per_step: float, trial_steps: int, phases: dict, n_steps: int, lead_in: float,
               how: str = "") -> dict:
    """time per step (its phase split: pyfem.clock.phase_split of the trial steps), the time estimate
    of the run's n_steps and the static stage's. how: words after "from rest" (the distributed
    model's: which rank's time)."""
    return {
        "time per step": f"{per_step * 1e3:.3f} ms (measured over {trial_steps} steps, from rest{how}): "
                         + ", ".join(f"{name} {entry['ms_per_step']:.3f} ms" for name, entry in phases.items()
                                     if name not in ("other", "exchange") or entry["ms_per_step"] > 0.0),
        "time estimate": f"{per_step * n_steps:.1f} s for {scene['time']['duration']:g} s of motion"
                         + (f" and the record's {lead_in:.3g} s lead-in before it (t < 0)" if lead_in > 0.0 else ""),
        **static_stage_estimate(scene, per_step),
    }

def element_name(model, order: int) -> str:
    """Q1/Q2 on hexahedra, P1/P2 on tetrahedra (a gmsh file of the user's)."""
    from dolfinx import mesh as dolfinx_mesh

    tetrahedra = model.mesh.topology.cell_type == dolfinx_mesh.CellType.tetrahedron
    return f"{'P' if tetrahedra else 'Q'}{order}{' tetrahedra' if tetrahedra else ''}"


def resolution_plan(scene: Scene, model, comm=None) -> dict:
    """{"mesh resolution": {region: its element sizes against the accuracy study's advice}} of a scene
    with a wave (pyfem.accuracy.resolution_report); a mesh file's too-coarse regions are warned of
    (the box and layered_cavern builders are checked from their scene keys). comm: the distributed
    model's (a collective): the whole model's cells."""
    from pyfem.accuracy import resolution_report

    if "seismic_input" not in scene.effects:
        return {}
    try:
        lines, warnings = resolution_report(scene, model, comm=comm)
    except Exception as error:  # advice only: it must never stop a run
        return {"mesh resolution": f"no advice ({type(error).__name__}: {error})"}
    if scene["mesh"]["builder"] == "file":
        for warning in warnings:
            if warning not in scene.warnings:
                scene.warn(warning)
    return {"mesh resolution": lines} if lines else {}


def interface_slip_plan(scene: Scene, model, comm=None, pairs=None, node_index=None) -> dict:
    """{"interface slip": {name: what the slip study says at its resolution}} of a contact scene with
    a wave (pyfem.accuracy.interface_slip_advice), else {}. comm, pairs, node_index: the distributed
    model's (a collective over the ranks' pairs; pyfem.accuracy.interface_slip_advice)."""
    from pyfem.accuracy import interface_slip_advice

    try:
        advice = interface_slip_advice(scene, model, comm=comm, pairs=pairs, node_index=node_index)
    except Exception as error:  # advice only: it must never stop a run
        return {"interface slip": f"no advice ({type(error).__name__}: {error})"}
    return {"interface slip": advice} if advice else {}


def static_stage_estimate(scene: Scene, per_step: float) -> dict:
    """check's line on the static stage's time before the motion: its two relaxation stages of at
    most static.max_steps steps each at the dynamic step's cost from rest (the same kernel on the
    same cells), which a yielding rock raises several times (README "The element loop on the yield
    surface"); not a bound."""
    from pyfem.static import uses_relaxation

    if "static" not in scene or not uses_relaxation(scene):
        return {}
    from pyfem.excavation_steps import static_steps

    max_steps = int(scene["static"]["max_steps"])
    stages = (sum(2 if step["install"] or step["support"] else 1 for step in static_steps(scene["static"]))
              if scene["static"].get("step") else 2)  # (an excavation sequence's sub-stages)
    return {"static stage estimate": f"{stages} stages of at most {max_steps} relaxation steps each (and a frequency probe) "
                                     f"before the motion: {stages * max_steps * per_step:.0f} s at this step's cost from "
                                     f"rest, several times that where the rock yields in the stage (a point on the "
                                     f"yield surface costs about 5x one at rest); a stage stops once its "
                                     f"out-of-balance ratio is reached (the coarse case study's after 1 000-2 000 steps)"}


def deferred_check_line(finest_level: int, per_step: float) -> str:
    """`check`'s line on the LTS map's set-up check, which it leaves to the run (finest_level: the
    largest node level, 2**level fine steps per global step)."""
    from pyfem.local_stepping import STABILITY_STEPS

    fine_steps = STABILITY_STEPS * 2 ** int(finest_level)
    return (f"the set-up check of its map runs when the run starts ({STABILITY_STEPS} global steps, "
            f"{fine_steps} fine steps: at most about {fine_steps * per_step:.3g} s at this plan's step time)")


def _region_rows(nonlinear) -> dict:
    """{region: its law, parameters, cells, points, state bytes, integration and crack-band cell
    sizes} of an element loop's components (pyfem.elements.NonlinearRegions)."""
    rows = {}
    if nonlinear is None:
        return rows
    for component, (name, (law, parameters)) in zip(nonlinear.components, nonlinear.laws.items()):
        # (local stepping's pyfem.local_stepping.LevelComponents: the region's kernel components by level)
        kernels = [part for _, part in component.parts] if hasattr(component, "parts") else [component]
        n_cells, n_points = nonlinear.arrays[name].weights.shape
        u_ref = parameters.get("damage_plastic_displacement", 0.0) if law == "mohr_coulomb" else 0.0
        h = (np.concatenate([np.asarray(k.characteristic_length()) for k in kernels])
             if u_ref > 0.0 and n_cells and kernels else None)
        rows[name] = {"law": law, "parameters": parameters, "cells": int(n_cells), "points": int(n_cells * n_points),
                      "bytes": int(sum(k.owned_bytes for k in kernels)),
                      "one_point": nonlinear.integration.get(name) == "reduced",
                      "mean_dilatation": bool(kernels and kernels[0].mean_dilatation), "u_ref": u_ref,
                      "h": None if h is None else (float(h.min()), float(h.max()))}
    return rows


def _whole_rows(shares: list) -> dict:
    """The ranks' `_region_rows` merged (cells, points and bytes summed, sizes' extremes), in the
    order the regions first appear on the ranks."""
    rows = {}
    for share in shares:
        for name, row in share.items():
            if name not in rows:
                rows[name] = dict(row)
                continue
            kept = rows[name]
            for key in ("cells", "points", "bytes"):
                kept[key] += row[key]
            if row["h"] is not None:
                kept["h"] = row["h"] if kept["h"] is None else (min(kept["h"][0], row["h"][0]),
                                                                max(kept["h"][1], row["h"][1]))
    return rows


def element_loop_plan(nonlinear, per_step: float, time_step: TimeStep, loop: float, comm=None) -> dict:
    """The plan's lines on the element loop: its regions, points, state bytes and measured time,
    and why the elastic stable step holds. loop: the element loop's seconds per step in the same
    trial steps as per_step (the kernel's phase times), so that its share and the per-step
    breakdown are one measurement. comm: the distributed model's communicator (a collective then):
    `nonlinear` is the rank's counted cells (None: none) and the lines are the whole model's (cells,
    points, bytes and crack-band sizes over the ranks, each cell counted once by its owner)."""
    from pyfem.elements import plastic_frequency_factor

    rows = _region_rows(nonlinear)
    if comm is not None:
        rows = _whole_rows(comm.allgather(rows))
    if not rows:
        return {"element loop": "none (no [plasticity] or [damage] table: every cell in the stiffness "
                                "matrix)"}
    regions, stiffening = {}, 1.0
    for name, row in rows.items():
        law, parameters, u_ref = row["law"], row["parameters"], row["u_ref"]
        regions[name] = (f"{law}, {row['cells']} cells, {row['points']} points"
                         + (", one point per cell (its hourglass stiffness in the matrix)" if row["one_point"] else "")
                         + (", mean dilatation" if row["mean_dilatation"] else "")
                         + f", {row['bytes'] / 2**20:.1f} MiB of state and buffers")
        if row["h"] is not None:  # the rock's crack band: kappa_ref per cell (docs/materials.md)
            h_min, h_max = row["h"]
            regions[name] += (f", crack band u_ref = {u_ref:g} m: kappa_ref {u_ref / h_max:.3g}-{u_ref / h_min:.3g} "
                              f"in its cells (h {h_min:.3g}-{h_max:.3g} m, the cube root of a cell's volume)")
        if law == "mohr_coulomb":
            stiffening = max(stiffening, plastic_frequency_factor(parameters["poisson_ratio"],
                                                                  parameters["friction_angle"],
                                                                  parameters.get("dilation_angle", 0.0)))
    n_points = sum(row["points"] for row in rows.values())
    margin = time_step.critical / time_step.dt
    return {
        "nonlinear regions": regions,
        "element loop": (f"{loop * 1e3:.3f} ms per step ({loop / max(1, n_points) * 1e9:.0f} ns per "
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


def lts_preview_lines(p: dict, scene: Scene, lts_decision: str | None, element_loop: bool, contact: bool,
                      rows: bool) -> dict:
    """check's line with local stepping off where the scene allows it: the speed-up `p`
    (pyfem.local_stepping.speed_up_of of its rate levels and this step's measured phases) and how
    to turn it on. rows: whether it would step by the row split."""
    from pyfem import local_stepping

    auto_declined = (scene["time"].get("local_stepping") == "auto"
                     and str(lts_decision or "").startswith('"auto": off: predicted'))
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
        + (f"element loop {p['element_loop']:.2f}, " if element_loop else "")
        + f"matrix {p['matrix']:.2f}"
        + (f", contact {p['contact']:.2f}" if contact else "")
        + f"); {verdict}")}

"""A scene's [static] stage solved on the one model in this process (one rank, nothing written), seen
as the static-stage tests read it: the whole model's arrays in the function space's numbering.

`solved(scene)` is pyfem.distributed_model.model_in_memory with the stage's cell stress worked out as
static/fields.xdmf writes it (pyfem.distributed_stage.write_fields): sigma0 + C : eps(u1 + u2) in the
rock, C : eps(u2) in the installed cells, the laws' cell means in the element loop's cells.
"""
from types import SimpleNamespace

import numpy as np


def solved(scene, solve_stage: bool = True) -> SimpleNamespace:
    """The one-rank model of `scene` with its stage solved and handed over.

    Attributes of the answer:
        run: the pyfem.distributed_model.DistributedRun (`.part`, `.stage`, `.loop`, `.stepper()`).
        model: the operators.Model of the mesh; scene: the scene.
        report: static/static.json's content; stages: its "stages" (dicts: "converged", "iterations", ...).
        displacement, displacement_first: (3 n,) u1 + u2 and u1 (m), the function space's numbering.
        cell_stress, cell_stress_first: (n_cells, 3, 3) the stage's stress at the end and after stage 1 (Pa).
        cell_state: {"plastic_strain", "damage", "damage_type"}: (n_cells,) the laws' cell means at the end.
        face_support_forces: face name -> (3,) the held faces' support force beyond the in-situ traction (N).
        pair_forces: (p, 3) the pairs' F0 handed to the dynamic run, the kernel's pairs' order
            (`part.pairs`; None: no pairs).
        installed_cells: the cells of the regions the stage installs; excavation_load: non-zero when
            the stage excavates (the readers of pyfem.static_plots find the wall from the mesh, as
            pyfem.distributed_view.stage_pictures: any non-zero load will do).
        support: the whole support groups (pyfem.support.SupportGroup, their component the bolts'
            arrays now: the stage's for those it installs, zero for the others).
        static: the answer itself, for pyfem.analytic's readers of a model and its stage (`.model`,
            `.static.displacement`, `.static.cell_stress`: salencon.compare_to_stage,
            elliptical_opening.wall_errors).
    """
    from pyfem.distributed_model import model_in_memory
    from pyfem.distributed_stage import cell_static_stress
    from pyfem.elements import voigt_tensor
    from pyfem.output import cell_strain_operator

    run = model_in_memory(scene, solve_stage=solve_stage)
    assert run.comm.size == 1, "the tests read the whole model from one rank"
    part = run.part
    state = SimpleNamespace(run=run, part=part, model=part.model, scene=scene, stage=None)
    state.static = state
    from pyfem.distributed_support import gather_groups

    state.support = gather_groups(run.comm, part.support)
    if not solve_stage or "static" not in scene:
        return state
    stage = run.stage
    model = part.model
    strain = cell_strain_operator(scene, model)
    n_cells = model.n_cells
    final = cell_static_stress(stage, part, strain)[:n_cells]
    first = cell_static_stress(stage, part, strain, first=True)[:n_cells]
    cell_state = {"plastic_strain": np.zeros(n_cells), "damage": np.zeros(n_cells),
                  "damage_type": np.zeros(n_cells, dtype=np.int32)}
    for stress, averages in ((first, stage.cell_averages[0] if stage.cell_averages else {}),
                             (final, stage.cell_averages[-1] if stage.cell_averages else {})):
        for region in averages.values():
            stress[region["cells"]] = voigt_tensor(region["stress"])
    for region in (stage.cell_averages[-1] if stage.cell_averages else {}).values():
        for key in cell_state:
            cell_state[key][region["cells"]] = region[key]
    report = stage.report
    from pyfem.elements import region_cells

    installed_cells = np.concatenate([region_cells(model, name) for name in stage.installed_regions]
                                     or [np.zeros(0, dtype=np.int64)]).astype(np.int64)
    pair_forces = (None if run.contact_arrays is None
                   else np.asarray(run.contact_arrays["static_force"], dtype=np.float64))
    state.__dict__.update(
        stage=stage, report=report, stages=report["stages"],
        displacement=part.dolfinx_order(stage.u_total), displacement_first=part.dolfinx_order(stage.u_first),
        cell_stress=final, cell_stress_first=first, cell_state=cell_state,
        face_support_forces={name: np.asarray(value) for name, value in report["support_forces"].items()},
        pair_forces=pair_forces, installed_cells=installed_cells,
        excavation_load=np.ones(1) if scene["static"].get("excavate") else np.zeros(0))
    return state

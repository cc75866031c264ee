"""The static stage's outputs in the run directory (docs/static.md):

    static/static.json   the stages (what each removed, installed and loaded; solver, iterations,
                         residual, time, largest displacement), the boundary during the stage and its
                         support forces, the hand-over's out-of-balance, displacement and stress at
                         the monitors, the contact pairs' static forces in figures
    static/fields.xdmf   (+ .h5) one time per stage (t = 1: after stage 1, t = 2: after stage 2):
                         point data displacement (m, total so far) and stage_displacement (m, the
                         stage's increment); cell data stress (Pa, Tensor6 xx xy xz yy yz zz, at the
                         centroids; an installed region is 0 before it joins) and active (1/0)
    static/section_stress.png, static/interface_stress.png (with contact): pyfem/static_plots.py;
                         static.json "plots" holds their figures (section y, extreme principal
                         stresses, the interfaces' mean normal stress near the walls before/after)
    static/support.png, static/support.xdmf (+ .h5) with static.support: the bolts after the stage
                         (pyfem/support_output.py)
    static/hand_over.npz what `--resume` takes instead of solving the stage again (write_hand_over)

run.json gets the summary under "static" (pyfem.static.StaticState.summary), and the dynamic
fields' stress starts from the stage's (RunWriter.cell_strain).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from pyfem.output import tensor6

# Monitor stress names of monitors/NAME.csv and their tensor components.
VOIGT_NAMES = {"sxx": (0, 0), "syy": (1, 1), "szz": (2, 2), "sxy": (0, 1), "syz": (1, 2), "sxz": (0, 2)}


def static_report(simulation) -> dict:
    """The content of static/static.json (SI units)."""
    state = simulation.static
    scene = simulation.scene
    displacement = state.displacement.reshape(-1, 3)
    magnitude = np.linalg.norm(displacement, axis=1)
    worst = int(np.argmax(magnitude)) if len(magnitude) else 0
    report = {
        "settings": state.settings,
        "initial_stress": scene.get("initial_stress"),
        "excavated": list(state.settings["excavate"]),
        "installed": state.installed_regions,
        "boundary": state.boundary,
        "stages": [vars(stage) for stage in state.stages],
        "seconds": state.seconds,
        "max_displacement": {"value": float(magnitude[worst]) if len(magnitude) else 0.0,
                             "point": simulation.model.node_coords[worst].tolist() if len(magnitude) else [],
                             "vector": displacement[worst].tolist() if len(magnitude) else []},
        "out_of_balance": state.out_of_balance,
        "hand_over": "the dynamic run starts from u = v = 0 with the stage's stress; the in-situ traction, "
                     "body force, support forces and pair forces of the stage are held constant; " + (
                         "the out-of-balance above is applied as a constant external force"
                         if np.any(state.hand_over_force) else
                         "the out-of-balance above (a relaxed stage's error) is not applied"),
        "load_ramp_steps": state.settings.get("load_ramp_steps"),
        "support_forces": state.face_support_forces,
        "in_situ_tractions": state.face_in_situ_tractions,
    }
    if simulation.monitor_nodes is not None:
        monitors = {}
        for j, name in enumerate(simulation.monitor_names):
            nodes, weights = simulation.monitor_nodes[j], simulation.monitor_weights[j]
            first = weights @ state.displacement_first.reshape(-1, 3)[nodes]
            total = weights @ displacement[nodes]
            entry = {"displacement_stage_1": first.tolist(), "displacement": total.tolist()}
            if state.monitor_stress is not None:
                sigma = state.monitor_stress[j]
                entry["stress"] = {name: float(sigma[a, b]) for name, (a, b) in VOIGT_NAMES.items()}
                entry["region"] = simulation.monitor_stress.regions[j]
            monitors[name] = entry
        report["monitors"] = monitors
    if state.pair_forces is not None and simulation.contact_arrays is not None:
        from pyfem.static import normal_and_shear

        area = simulation.contact_arrays["area"]
        N, T = normal_and_shear(state.pair_forces, simulation.contact_arrays["normal"])  # compression positive
        report["pairs"] = {"count": int(len(N)), "normal_stress_min": float(np.min(N / area)),
                           "normal_stress_max": float(np.max(N / area)),
                           "shear_stress_max": float(np.max(T / area)),
                           "in_tension": int(np.count_nonzero(N < 0.0))}
        if state.contact is not None:  # the pair law ran in the stage: its states at the hand-over
            counts = np.bincount(state.contact.state(), minlength=4)
            report["pairs"]["states"] = {name: int(count) for name, count in
                                         zip(("bonded", "stick", "sliding", "separated"), counts)}
            report["pairs"]["largest_open_gap"] = float(np.max(state.contact.gap_offset(), initial=0.0))
    if state.cell_state is not None:
        report["regions"] = state.stages[-1].regions
    return report


def write_static_fields(folder: Path, simulation) -> None:
    """static/fields.xdmf: one time per stage, on the mesh of the run's fields.xdmf
    (pyfem.output.field_mesh: hexahedra or tetrahedra, every node; cell data of each written cell
    from its parent cell)."""
    import h5py
    import meshio

    from pyfem.output import field_mesh

    state = simulation.static
    model = simulation.model
    field_nodes, cell_type, cells, parent = field_mesh(model)
    n_cells = len(model.V.dofmap.list.array) // model.V.dofmap.dof_layout.num_dofs
    active_first = np.ones(n_cells)
    active_first[state.installed_cells] = 0.0
    u1 = state.displacement_first.reshape(-1, 3)
    u = state.displacement.reshape(-1, 3)
    writer = meshio.xdmf.TimeSeriesWriter(str(folder / "fields.xdmf"))
    writer.h5_filename = "fields.h5"
    writer.h5_file = h5py.File(folder / "fields.h5", "w")
    try:
        writer.write_points_cells(model.node_coords[field_nodes], [(cell_type, cells)])
        stages = ((1.0, u1, u1, state.cell_stress_first, active_first),
                  (2.0, u, u - u1, state.cell_stress, np.ones(n_cells)))
        states = (state.cell_state_first, state.cell_state)
        for (t, total, increment, stress, active), cell_state in zip(stages, states):
            cell_data = {"stress": [tensor6(stress)[parent]], "active": [active[parent]]}
            if cell_state is not None:  # relaxation stage: the laws' history, cell means
                for key in ("plastic_strain", "damage", "damage_type"):
                    cell_data[key] = [np.asarray(cell_state[key], dtype=float)[parent]]
            writer.write_data(t, point_data={"displacement": total[field_nodes],
                                             "stage_displacement": increment[field_nodes]},
                              cell_data=cell_data)
    finally:
        writer.__exit__(None, None, None)


# ---------------------------------------------------------------------------------------------
# What a resumed run needs of the stage (static/hand_over.npz)
# ---------------------------------------------------------------------------------------------

HAND_OVER_NAME = "hand_over.npz"

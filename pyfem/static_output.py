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

import json
from pathlib import Path

import numpy as np

from pyfem.output import _write_json, tensor6

# Monitor stress names of monitors/NAME.csv and their tensor components.
VOIGT_NAMES = {"sxx": (0, 0), "syy": (1, 1), "szz": (2, 2), "sxy": (0, 1), "syz": (1, 2), "sxz": (0, 2)}


def write_static_outputs(writer) -> None:
    """Writes static/ into the run directory of a started RunWriter and makes the stage's stress the
    static part of the dynamic fields' stress.

    Args:
        writer: pyfem.output.RunWriter whose simulation has a solved stage (simulation.static).
    """
    simulation = writer.simulation
    folder = Path(writer.out_dir) / "static"
    folder.mkdir(parents=True, exist_ok=True)
    static_stress_in_fields(writer)
    from pyfem.static_plots import write_static_plots

    report = static_report(simulation)
    report["plots"] = write_static_plots(folder, simulation)
    states = getattr(simulation.static, "support_states", None)
    if states:  # static/support.png and static/support.xdmf: the bolts as the stage leaves them
        from pyfem.support_output import write_outputs

        drawn = write_outputs(folder, states, simulation.scene, simulation.model, 0.0, "support.png",
                              "after the static stage")
        if drawn:
            report["plots"]["support"] = drawn
    _write_json(folder / "static.json", report)
    write_static_fields(folder, simulation)
    write_hand_over(folder, simulation)
    rows = getattr(simulation.static, "support_rows", None)
    if rows:  # the bolts and cables of static.support as the stage leaves them
        from pyfem.support import write_csv

        write_csv(folder / "support.csv", rows, peak=False)


def static_stress_in_fields(writer) -> None:
    """Makes the stage's stress the static part of the dynamic fields' stress (a resumed run does
    this without writing static/ again)."""
    if writer.cell_strain is not None:
        writer.cell_strain.static = writer.simulation.static.cell_stress


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
_HAND_OVER_ARRAYS = ("hand_over_force", "cell_stress", "monitor_stress", "pair_forces")


class SavedStage:
    """The stage as a resumed run holds it (read from static/hand_over.npz, nothing solved): what the
    dynamic run takes from it outside the kernel's checkpointed state. The element-loop components
    and contact pairs are built fresh (components = contact = None) and then receive the
    checkpoint's state, which holds their committed points, sigma0 and pair states.

    Attributes:
        hand_over_force: (n_dofs,) the constant out-of-balance force (N).
        cell_stress: (n_cells, 3, 3) the stage's stress, the static part of the fields' (Pa).
        monitor_stress: (m, 3, 3) or None: the monitors' static stress (Pa).
        pair_forces: (n_pairs, 3) or None: the pairs' static forces F0 (N).
        saved_summary: run.json's "static" of the sitting that solved the stage.
    """

    components = None
    contact = None

    def __init__(self, arrays: dict, summary: dict):
        self.hand_over_force = arrays["hand_over_force"]
        self.cell_stress = arrays["cell_stress"]
        self.monitor_stress = arrays.get("monitor_stress")
        self.pair_forces = arrays.get("pair_forces")
        self.saved_summary = summary

    def summary(self) -> dict:
        return self.saved_summary


def write_hand_over(folder: Path, simulation) -> Path:
    """static/hand_over.npz: the stage's hand-over force, cell and monitor stress, pair forces,
    run.json summary and the model's fingerprint, so that `--resume` need not solve the stage again
    (18 min on the paper-scale mesh). Written atomically, like the checkpoint."""
    from pyfem.checkpoint import model_fingerprint, write_atomically

    state = simulation.static
    arrays = {name: np.asarray(getattr(state, name)) for name in _HAND_OVER_ARRAYS if getattr(state, name) is not None}
    meta = {"fingerprint": model_fingerprint(simulation), "summary": state.summary()}
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return write_atomically(Path(folder) / HAND_OVER_NAME, arrays)


def read_hand_over(out_dir) -> tuple[dict, dict] | None:
    """(arrays, meta) of a run directory's static/hand_over.npz, or None when there is none or it
    cannot be read (a run begun before the file existed: the stage is solved again)."""
    path = Path(out_dir) / "static" / HAND_OVER_NAME
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(bytes(data["meta"]).decode())
            return {name: np.array(data[name]) for name in _HAND_OVER_ARRAYS if name in data}, meta
    except (OSError, ValueError, KeyError):
        return None


def restore_hand_over(simulation, saved: tuple[dict, dict]) -> bool:
    """Makes a saved hand-over the stage of `simulation`, prepared with solve_static=False: the
    monitors' static stress and the pairs' static forces as `pyfem.static.hand_over` leaves them.
    Returns False (nothing changed) when the file is of another model than this one."""
    from pyfem.checkpoint import _drop_decided, _first_difference, model_fingerprint

    arrays, meta = saved
    fingerprint = json.loads(json.dumps(meta["fingerprint"]))  # a copy, without the keys written
    _drop_decided(fingerprint.get("scene", {}))                # before the fingerprint left them out
    if _first_difference(fingerprint, model_fingerprint(simulation)) is not None:
        return False
    stage = SavedStage(arrays, meta["summary"])
    if simulation.monitor_stress is not None and stage.monitor_stress is not None:
        simulation.monitor_stress.static = stage.monitor_stress
    if simulation.contact_arrays is not None and stage.pair_forces is not None:
        simulation.contact_arrays["static_force"] = np.ascontiguousarray(stage.pair_forces, dtype=np.float64)
    simulation.static = stage
    return True

"""From a scene's [wave] table to the free field and the kernel's input-force arrays."""
from __future__ import annotations

import math
import warnings

import numpy as np

from pyfem.seismic.forces import equivalent_input_forces
from pyfem.seismic.freefield import FreeField, ReferencePointWarning
from pyfem.seismic.waveforms import WaveformTables, ricker

# Samples per period of the Ricker centre frequency in its table: cubic Hermite with exact
# derivatives then interpolates to ~1e-6 relative (error ~ (omega h)^4 / 384).
_RICKER_SAMPLES_PER_PERIOD = 100
# Table step of a processed record (s): 25 Hz content is interpolated to ~1e-4.
_RECORD_TABLE_DT = 0.002
# Part of the input peak that may be cut off by a user's reference point without a warning:
# a Ricker wavelet starts at ~1e-6 of its peak and a processed record at rest, so anything
# larger was put there by a negative delay.
CUT_WARNING_LEVEL = 1.0e-3


def input_waveform(scene, processed=None):
    """The input motion g(t) of a scene and the grid of its table.

    Args:
        scene: validated Scene with a [wave] table.
        processed: the scene's record as processed_record gave it, to use instead of processing
            it again (the run's set-up processes it once for the input and the wear clock).

    Returns:
        (waveform, table_grid, processed_record): waveform is a function t -> (g, g', g'')
        (m, m/s, m/s^2) for a Ricker wavelet, or WaveformTables for a record; table_grid is
        (t0, dt, n_samples) for a function, else None; processed_record is the
        ProcessedRecord or None.
    """
    motion = scene["wave"]["motion"]
    duration = scene["time"]["duration"]
    if motion.get("ricker") is not None:
        r = motion["ricker"]
        table_dt = 1.0 / (_RICKER_SAMPLES_PER_PERIOD * r["f0"])

        def waveform(t):
            return ricker(t, r["f0"], r["amplitude"], r["t0"])

        n_samples = math.ceil(duration / table_dt) + 4
        return waveform, (0.0, table_dt, n_samples), None
    from pyfem.seismic.records import as_waveform

    if processed is None:
        processed = processed_record(motion["record"])
    t0, dt, g, dg, ddg = as_waveform(processed)
    # Record time is run time: t = 0 is the start of the record's window; the filter's lead-in (the
    # precursor kept before it) lies at negative times, where the run starts (solver.run_origin).
    t0 -= float(processed.record_start)
    return WaveformTables(t0=t0, dt=dt, g=g[None, :], dg=dg[None, :], ddg=ddg[None, :]), None, processed


def processed_record(spec, record=None):
    """The input motion of a scene's [wave.motion.record] table, processed as the run uses it.

    Args:
        spec: the validated wave.motion.record table (file, units, dt, format, window, band,
            pga, scale, lead_in).
        record: the file already read (pyfem.seismic.records.Record), or None to read it.

    Returns:
        pyfem.seismic.records.ProcessedRecord (time from 0, step _RECORD_TABLE_DT s).

    Raises:
        ValueError: a malformed file, or settings the record cannot meet.
    """
    from pyfem.seismic.records import process_record, read_record

    if record is None:
        record = read_record(spec["file"], units=spec["units"], dt=spec.get("dt"), format=spec["format"])
    return process_record(record, window=spec.get("window"), band=tuple(spec["band"]), pga=spec.get("pga"),
                          table_dt=_RECORD_TABLE_DT, pad=spec.get("lead_in"),
                          scale=spec.get("scale", "after_filter"))


def scene_record(scene):
    """The scene's processed record (processed_record), or None without a [wave.motion.record]."""
    spec = (scene.get("wave") or {}).get("motion", {}).get("record")
    return None if spec is None else processed_record(spec)


def seismic_input_from_scene(scene, model, processed=None, boundary_points=None):
    """The exact free field of the scene's waves and the kernel's SeismicInput arrays.

    Args:
        scene: validated Scene with a [wave] table.
        model: pyfem.operators.Model (faces, node coordinates, bounds).
        processed: the scene's processed record (scene_record), None to process it here.
        boundary_points: (m, 3) where the input acts, for the warning that wave.reference_point
            cuts the input's start; None: the model's truncation-face nodes (a distributed model
            passes every rank's, since its faces hold the rank's own nodes only).

    Returns:
        (FreeField, dict of SeismicInput arrays)
    """
    wave = scene["wave"]
    medium = scene["materials"][wave["medium"]]
    waveform, table_grid, _ = input_waveform(scene, processed)
    components = scene.wave_components()
    for component in components:
        # wave.scale multiplies the motion g(t) that all components share.
        component["scale"] = component.get("scale", 1.0) * wave.get("scale", 1.0)
    if wave.get("layers"):
        from pyfem.seismic.layered import layered_freefield_from_scene

        try:
            freefield = layered_freefield_from_scene(scene, components, waveform, table_grid, model.bounds)
        except ValueError as error:
            from pyfem.errors import SceneError

            raise SceneError("wave.layers", [layer["thickness"] for layer in wave["layers"]], str(error)) from None
    else:
        freefield = FreeField(components, medium["E"], medium["nu"], medium["rho"],
                              surface=wave.get("surface"), waveform=waveform, table_grid=table_grid,
                              reference_point=wave.get("reference_point"), model_bounds=model.bounds)
    if wave.get("reference_point") is not None:
        if boundary_points is None:
            boundary_nodes = np.unique(np.concatenate([face.nodes for face in model.faces])) if model.faces else \
                np.arange(len(model.node_coords))
            boundary_points = model.node_coords[boundary_nodes]
        warn_if_start_is_cut(freefield, boundary_points, wave["reference_point"])
    boundary = scene["boundary"]
    # Each truncation face by its own type: only viscoelastic and viscous faces carry input.
    arrays = equivalent_input_forces(model.faces, model.node_coords, freefield, None,
                                     boundary["alpha_N"], boundary["alpha_T"])
    return freefield, arrays


def warn_if_start_is_cut(freefield, points, reference_point, level=CUT_WARNING_LEVEL):
    """Warns (ReferencePointWarning) when a reference point cuts off the start of the input.

    A node with a negative delay tau starts at g(-tau) instead of at rest: the part of the
    motion before -tau never enters the model, and the jump at t = 0 is a spurious pulse.

    Args:
        freefield: FreeField of the scene.
        points: (m, 3) boundary node coordinates, m (where the input forces act).
        reference_point: the user's wave.reference_point (3,), m, named in the message.
        level: cut fraction of the input peak above which to warn.

    Returns:
        The `FreeField.start_cut` dict (delay s, point m, component, fraction).
    """
    cut = freefield.start_cut(points)
    if cut["delay"] < 0.0 and cut["fraction"] > level:
        x = ", ".join(f"{v:.6g}" for v in np.round(cut["point"], 6) + 0.0)  # no "-0" or "1e-15"
        warnings.warn(
            f"wave.reference_point = {list(reference_point)} cuts off the start of the input motion: "
            f"the {cut['component']} wave has a delay of {cut['delay']:.4g} s at the boundary node ({x}), "
            f"so the first {-cut['delay']:.4g} s of g(t) never enter the model there, up to "
            f"{100 * cut['fraction']:.3g} % of the input peak; omit wave.reference_point (default: the point "
            "the wavefront reaches first) or move it to that point", ReferencePointWarning, stacklevel=3)
    return cut

"""From a scene's [wave] table to the free field and the kernel's input-force arrays."""
from __future__ import annotations

import math

from pyfem.seismic.forces import equivalent_input_forces
from pyfem.seismic.freefield import FreeField
from pyfem.seismic.waveforms import WaveformTables, ricker

# Samples per period of the Ricker centre frequency in its table: cubic Hermite with exact
# derivatives then interpolates to ~1e-6 relative (error ~ (omega h)^4 / 384).
_RICKER_SAMPLES_PER_PERIOD = 100
# Table step of a processed record (s): 25 Hz content is interpolated to ~1e-4.
_RECORD_TABLE_DT = 0.002


def input_waveform(scene):
    """The input motion g(t) of a scene and the grid of its table.

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
    from pyfem.seismic.records import as_waveform, process_record, read_record

    spec = motion["record"]
    record = read_record(spec["file"], units=spec["units"], dt=spec.get("dt"), format=spec["format"])
    processed = process_record(record, window=spec.get("window"), band=tuple(spec["band"]), pga=spec.get("pga"),
                               table_dt=_RECORD_TABLE_DT)
    t0, dt, g, dg, ddg = as_waveform(processed)
    return WaveformTables(t0=t0, dt=dt, g=g[None, :], dg=dg[None, :], ddg=ddg[None, :]), None, processed


def seismic_input_from_scene(scene, model):
    """The exact free field of the scene's waves and the kernel's SeismicInput arrays.

    Args:
        scene: validated Scene with a [wave] table.
        model: pyfem.operators.Model (faces, node coordinates, bounds).

    Returns:
        (FreeField, dict of SeismicInput arrays)
    """
    wave = scene["wave"]
    medium = scene["materials"][wave["medium"]]
    waveform, table_grid, _ = input_waveform(scene)
    freefield = FreeField(scene.wave_components(), medium["E"], medium["nu"], medium["rho"],
                          surface=wave.get("surface"), waveform=waveform, table_grid=table_grid,
                          reference_point=wave.get("reference_point"), model_bounds=model.bounds)
    boundary = scene["boundary"]
    arrays = equivalent_input_forces(model.faces, model.node_coords, freefield, boundary["type"],
                                     boundary["alpha_N"], boundary["alpha_T"])
    return freefield, arrays

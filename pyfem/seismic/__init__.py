"""Seismic input: free-surface reflection, analytical free field, waveform tables, boundary forces.

Modules: `reflection` (coefficients at a traction-free surface), `waveforms` (Ricker,
tables with the kernel's interpolation rule, Hilbert transform), `freefield`
(plane-wave free field of a half-space, the exact reference), `forces` (viscoelastic
boundary springs/dashpots and the kernel's SeismicInput arrays, paper Eq. 6).
"""
from pyfem.seismic.forces import (boundary_springs_and_dashpots, equivalent_input_forces,
                                  equivalent_input_forces_reference, evaluate_input_forces)
from pyfem.seismic.freefield import FreeField, IncidentWave, PlaneWaveComponent
from pyfem.seismic.reflection import critical_angle, free_surface_coefficients, reflected_angles
from pyfem.seismic.waveforms import WaveformTables, hilbert_pair, ricker, ricker_analytic_signal


def input_forces(model, freefield, boundary_type=None, alpha_N=4.0 / 3.0, alpha_T=2.0 / 3.0) -> dict:
    """SeismicInput arrays for a Model (its faces and node coordinates); see `equivalent_input_forces`."""
    return equivalent_input_forces(model.faces, model.node_coords, freefield, boundary_type, alpha_N, alpha_T)


__all__ = ["FreeField", "IncidentWave", "PlaneWaveComponent", "WaveformTables", "boundary_springs_and_dashpots",
           "critical_angle", "equivalent_input_forces", "equivalent_input_forces_reference",
           "evaluate_input_forces", "free_surface_coefficients", "hilbert_pair", "input_forces",
           "reflected_angles", "ricker", "ricker_analytic_signal"]

"""Run directory: run.json, monitors/*.csv, energy.csv, fields.xdmf (+ .h5), plots/*.png,
and with contact pairs/*.csv (pair monitors) and the pair-state counts over time.

run.json is written first with "status": "running" and rewritten with "finished" (or
"failed") at the end, so a half-written directory never looks like a finished run.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

MONITOR_COLUMNS = ["t", "ux", "uy", "uz", "vx", "vy", "vz", "ax", "ay", "az"]
FREEFIELD_COLUMNS = ["ux_ff", "uy_ff", "uz_ff", "vx_ff", "vy_ff", "vz_ff"]
# Stress at the monitor (Pa, tension positive): total = initial (geostatic) + dynamic, its
# largest principal value s1, and s1 of the dynamic increment alone.
STRESS_COLUMNS = ["sxx", "syy", "szz", "sxy", "syz", "sxz", "s1", "s1_dynamic"]
_VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
ENERGY_COLUMNS = ["t", "kinetic", "strain", "external_work", "damping_work", "balance"]
CONTACT_ENERGY_COLUMNS = ["contact_work", "friction_dissipation"]
PAIR_COLUMNS = ["t", "dux", "duy", "duz", "slip", "gap", "N", "T", "D", "state"]
PAIR_STATES = ("bonded", "stick", "sliding", "separated")  # kernel state codes 0..3


def _write_json(path: Path, data: dict) -> None:
    """Writes JSON through a temporary file so a reader never sees half a file."""
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=_json_default))
    os.replace(tmp, path)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def max_principal(voigt: np.ndarray) -> np.ndarray:
    """Largest principal value of symmetric tensors given as (n, 6) [xx, yy, zz, xy, yz, xz] (Pa).

    Tension positive (the largest eigenvalue), the paper's "maximum principal stress".
    """
    voigt = np.asarray(voigt, dtype=float).reshape(-1, 6)
    tensor = np.empty((len(voigt), 3, 3))
    for k, (i, j) in enumerate(_VOIGT):
        tensor[:, i, j] = voigt[:, k]
        tensor[:, j, i] = voigt[:, k]
    return np.linalg.eigvalsh(tensor)[:, -1]


class RunWriter:
    """Collects samples during a run and writes the run directory.

    Args:
        out_dir: directory of the run; a previous finished run there is moved to
            `<out_dir>.previous` (one generation is kept) rather than mixed with the new one.
        simulation: the prepared `pyfem.solver.Simulation`.
    """

    def __init__(self, out_dir, simulation):
        self.out_dir = Path(out_dir)
        self.simulation = simulation
        self.scene = simulation.scene
        self.times: list[float] = []
        self.monitor_samples: list[np.ndarray] = []  # each (n_monitors, 9 or 15 with the dynamic stress)
        self.energy_samples: list[list[float]] = []
        self.contact_on = simulation.contact_arrays is not None
        self.energy_columns = ENERGY_COLUMNS + (CONTACT_ENERGY_COLUMNS if self.contact_on else [])
        self.pair_samples: list[np.ndarray] = []        # each (n_pair_monitors, 9)
        self.state_count_samples: list[np.ndarray] = []  # each (4,)
        self.xdmf = None
        self.show_progress = sys.stderr.isatty()
        interval = self.scene["output"]["xdmf_interval"]
        self.xdmf_every = (max(1, round(interval / self.scene["output"]["interval"]))
                           if interval and interval > 0 else 0)
        self._sample_count = 0

    # -- life cycle ---------------------------------------------------------------------
    def start(self) -> None:
        """Creates the directory and marks the run as running."""
        if (self.out_dir / "run.json").exists():
            previous = self.out_dir.with_name(self.out_dir.name + ".previous")
            if previous.exists():
                shutil.rmtree(previous)
            shutil.move(str(self.out_dir), str(previous))
            print(f"note: the earlier run in {self.out_dir} was moved to {previous}", file=sys.stderr)
        (self.out_dir / "monitors").mkdir(parents=True, exist_ok=True)
        if self.contact_on:
            (self.out_dir / "pairs").mkdir(exist_ok=True)
        (self.out_dir / "plots").mkdir(exist_ok=True)
        self._summary = self._base_summary()
        self._summary["status"] = "running"
        _write_json(self.out_dir / "run.json", self._summary)
        if self.xdmf_every:
            self._open_fields()

    def fail(self, t: float, why: str) -> None:
        """Marks the run as failed at time t (s)."""
        self._summary.update(status="failed", failed_at=t, failure=why)
        self._close_fields()
        _write_json(self.out_dir / "run.json", self._summary)

    def sample(self, t: float, u: np.ndarray, v: np.ndarray, a: np.ndarray, energy: dict) -> None:
        """Records monitors and energy at time t; writes fields every xdmf interval."""
        sim = self.simulation
        self.times.append(t)
        if sim.monitor_nodes is not None:
            with_stress = sim.monitor_stress is not None
            values = np.empty((len(sim.monitor_names), 15 if with_stress else 9))
            for k, field in enumerate((u, v, a)):
                nodal = field.reshape(-1, 3)[sim.monitor_nodes]  # (m, k, 3)
                values[:, 3 * k:3 * k + 3] = np.einsum("mk,mkc->mc", sim.monitor_weights, nodal)
            if with_stress:
                stress = sim.monitor_stress.dynamic_stress(u)
                values[:, 9:15] = np.stack([stress[:, i, j] for i, j in _VOIGT], axis=1)
            self.monitor_samples.append(values)
        self.energy_samples.append([t] + [energy[name] for name in self.energy_columns[1:]])
        write_fields = bool(self.xdmf_every) and self._sample_count % self.xdmf_every == 0
        contact = sim.contact_pairs
        pair_values = None  # every pair's values, computed once when monitors or fields need them
        if contact is not None:
            self.state_count_samples.append(np.asarray(contact.state_counts(), dtype=np.int64).copy())
            if len(sim.pair_monitor_names) or write_fields:
                pair_values = self._pair_values(u)
            if len(sim.pair_monitor_names):
                self.pair_samples.append(pair_values[sim.pair_monitor_pairs])
        if write_fields:
            self._write_fields(t, u, v, pair_values)
        self._sample_count += 1

    def _pair_values(self, u: np.ndarray) -> np.ndarray:
        """(n_pairs, 9): dux, duy, duz, slip, gap (m), N, T (N), D (-), state of every pair."""
        contact = self.simulation.contact_pairs
        normal = self.simulation.contact_arrays["normal"]
        delta = np.asarray(contact.relative_displacement(u))
        gap = np.einsum("pc,pc->p", delta, normal)
        slip = np.linalg.norm(delta - gap[:, None] * normal, axis=1)
        tangential = np.linalg.norm(np.asarray(contact.tangential_force()), axis=1)
        return np.column_stack([delta, slip, gap, np.asarray(contact.normal_force()), tangential,
                                np.asarray(contact.deterioration()), np.asarray(contact.state(), dtype=float)])

    def finish(self, wall_seconds: float, loop_seconds: float) -> dict:
        """Writes monitors, energy, plots and the final run.json; returns the summary."""
        self._close_fields()
        times = np.array(self.times)
        energy = np.array(self.energy_samples)
        summary = self._summary
        summary["status"] = "finished"
        summary["wall_seconds"] = wall_seconds
        summary["loop_seconds"] = loop_seconds
        summary["seconds_per_step"] = loop_seconds / max(1, self.simulation.n_steps)
        summary["energy"] = self._energy_summary(energy, self.energy_columns)
        np.savetxt(self.out_dir / "energy.csv", energy, delimiter=",", header=",".join(self.energy_columns),
                   comments="")
        summary["monitors"] = self._write_monitors(times)
        from pyfem import plots

        if self.contact_on:
            summary["pairs"] = self._write_pairs(times)
            counts = np.array(self.state_count_samples).reshape(-1, len(PAIR_STATES))
            summary["pair_states"] = {"t": times.tolist(),
                                      **{name: counts[:, k].tolist() for k, name in enumerate(PAIR_STATES)}}
            summary["pair_states_final"] = {name: int(counts[-1, k]) for k, name in enumerate(PAIR_STATES)}
            summary["n_pairs"] = int(len(self.simulation.contact_arrays["area"]))
            plots.pair_states(self.out_dir / "plots" / "pair_states.png", times, counts, PAIR_STATES)
        plots.energy(self.out_dir / "plots" / "energy.png", energy, self.energy_columns)
        for name in self.simulation.monitor_names:
            plots.monitor(self.out_dir / "plots" / f"monitor_{name}.png", self.out_dir / "monitors" / f"{name}.csv")
        _write_json(self.out_dir / "run.json", summary)
        return summary

    # -- pieces -------------------------------------------------------------------------
    def _base_summary(self) -> dict:
        sim = self.simulation
        ts = sim.time_step
        return {
            "title": self.scene["title"],
            "scene": self.scene.to_json(),
            "effects": list(self.scene.effects),
            "cells": sim.model.n_cells,
            "nodes": len(sim.mass),
            "dofs": 3 * len(sim.mass),
            "dt": ts.dt,
            "dt_critical": ts.critical,
            "dt_reason": ts.reason,
            "omega_max": ts.omega_max,
            "steps": sim.n_steps,
            "rayleigh": {"alpha": sim.alpha, "beta": sim.beta},
            "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }

    @staticmethod
    def _energy_summary(energy: np.ndarray, names: list[str] = ENERGY_COLUMNS) -> dict:
        """Final energies and the balance error relative to the largest energy in play."""
        columns = {name: energy[:, i] for i, name in enumerate(names)}
        scale = max(np.max(np.abs(columns["external_work"])), np.max(columns["kinetic"] + columns["strain"]),
                    np.max(np.abs(columns["damping_work"])), 1e-300)
        if "contact_work" in columns:
            scale = max(scale, np.max(np.abs(columns["contact_work"])),
                        np.max(np.abs(columns["friction_dissipation"])))
        final = {name: float(columns[name][-1]) for name in names[1:]}
        final["balance_error"] = float(np.max(np.abs(columns["balance"])) / scale)
        final["reference_energy"] = float(scale)
        return final

    def _write_monitors(self, times: np.ndarray) -> dict:
        """monitors/NAME.csv (+ exact free field columns when a wave is on); returns peaks per monitor."""
        sim = self.simulation
        peaks = {}
        if sim.monitor_nodes is None:
            return peaks
        samples = np.array(self.monitor_samples)  # (nt, m, 9 or 15)
        stress = sim.monitor_stress
        freefield = None
        if sim.freefield is not None:
            points = np.array([m["point"] for m in self.scene["monitor"]], dtype=float)
            freefield = np.concatenate([sim.freefield.displacement(points, times),
                                        sim.freefield.velocity(points, times)], axis=2)  # (nt, m, 6)
        for j, name in enumerate(sim.monitor_names):
            columns = [times[:, None], samples[:, j, :9]]
            header = list(MONITOR_COLUMNS)
            if freefield is not None:
                columns.append(freefield[:, j, :])
                header += FREEFIELD_COLUMNS
            if stress is not None:
                dynamic = samples[:, j, 9:15]
                total = dynamic + np.array([stress.static[j, a, b] for a, b in _VOIGT])[None, :]
                s1 = max_principal(total)
                s1_dynamic = max_principal(dynamic)
                columns += [total, s1[:, None], s1_dynamic[:, None]]
                header += STRESS_COLUMNS
            np.savetxt(self.out_dir / "monitors" / f"{name}.csv", np.hstack(columns), delimiter=",",
                       header=",".join(header), comments="", fmt="%.10e")
            u, vel, acc = samples[:, j, 0:3], samples[:, j, 3:6], samples[:, j, 6:9]
            peak = {"displacement": float(np.max(np.linalg.norm(u, axis=1))),
                    "velocity": float(np.max(np.linalg.norm(vel, axis=1))),
                    "acceleration": float(np.max(np.linalg.norm(acc, axis=1)))}
            if freefield is not None:
                reference = freefield[:, j, 0:3]
                norm = np.linalg.norm(reference)
                peak["freefield_error"] = float(np.linalg.norm(u - reference) / norm) if norm > 0 else math.nan
            if stress is not None:
                peak["region"] = stress.regions[j]
                peak["s1_max"] = float(np.max(s1))
                peak["s1_max_time"] = float(times[int(np.argmax(s1))])
                peak["s1_initial"] = float(s1[0])
                peak["s1_dynamic_max"] = float(np.max(s1_dynamic))
            peaks[name] = peak
        return peaks

    def _write_pairs(self, times: np.ndarray) -> dict:
        """pairs/NAME.csv per pair monitor; returns the peaks and final values per pair monitor."""
        sim = self.simulation
        peaks = {}
        if not sim.pair_monitor_names:
            return peaks
        samples = np.array(self.pair_samples)  # (nt, m, 9)
        pairs = sim.model.pairs
        for j, name in enumerate(sim.pair_monitor_names):
            np.savetxt(self.out_dir / "pairs" / f"{name}.csv", np.hstack([times[:, None], samples[:, j, :]]),
                       delimiter=",", header=",".join(PAIR_COLUMNS), comments="", fmt="%.10e")
            index = int(sim.pair_monitor_pairs[j])
            values = samples[:, j, :]
            peaks[name] = {
                "pair": index,
                "interface": pairs.names[int(pairs.interface[index])],
                "point": pairs.coords[index].tolist(),
                "max_relative_displacement": float(np.max(np.linalg.norm(values[:, 0:3], axis=1))),
                "max_slip": float(np.max(values[:, 3])),
                "residual_slip": float(values[-1, 3]),
                "max_gap": float(np.max(values[:, 4])),
                "max_N": float(np.max(values[:, 5])),
                "max_T": float(np.max(values[:, 6])),
                "min_D": float(np.min(values[:, 7])),
                "final_state": PAIR_STATES[int(values[-1, 8])],
            }
        from pyfem import plots

        for name in sim.pair_monitor_names:
            plots.pair_monitor(self.out_dir / "plots" / f"pair_{name}.png", self.out_dir / "pairs" / f"{name}.csv")
        return peaks

    def _open_fields(self) -> None:
        """One temporal XDMF collection holding every field per time (ParaView, meshio read it).

        Fields are written at the cell vertices (the Q1 geometry): for Q2 the vertex values
        are the Q2 nodal values there, so nothing is interpolated.
        """
        import meshio

        model = self.simulation.model
        dofs_per_cell = model.V.dofmap.dof_layout.num_dofs
        cell_nodes = model.V.dofmap.list.array.reshape(-1, dofs_per_cell)[:, :8]  # vertices come first
        self._field_nodes, compact = np.unique(cell_nodes, return_inverse=True)
        # dolfinx numbers hexahedron vertices lexicographically; VTK/XDMF goes round each face.
        hexahedra = compact.reshape(-1, 8)[:, [0, 1, 3, 2, 4, 5, 7, 6]]
        import h5py

        self.xdmf = meshio.xdmf.TimeSeriesWriter(str(self.out_dir / "fields.xdmf"))
        # meshio's __enter__ opens the .h5 in the working directory; the XDMF refers to it by
        # name only, so it must sit beside the .xdmf: open it there ourselves.
        self.xdmf.h5_filename = "fields.h5"
        self.xdmf.h5_file = h5py.File(self.out_dir / "fields.h5", "w")
        self.xdmf.write_points_cells(model.node_coords[self._field_nodes], [("hexahedron", hexahedra)])

    def _write_fields(self, t: float, u: np.ndarray, v: np.ndarray, pair_values: np.ndarray | None) -> None:
        """Writes the fields at time t; pair_values is `_pair_values(u)` when contact is on."""
        point_data = {}
        for name, values in (("displacement", u), ("velocity", v)):
            if name in self.scene["output"]["fields"]:
                point_data[name] = values.reshape(-1, 3)[self._field_nodes]
        if pair_values is not None:
            # Interface fields on both nodes of every pair, 0 elsewhere.
            values = pair_values
            nodes = self.simulation.contact_arrays["pairs"]
            n_nodes = len(self.simulation.mass)
            for name, column in (("pair_state", 8), ("pair_slip", 3), ("pair_D", 7)):
                nodal = np.zeros(n_nodes)
                nodal[nodes[:, 0]] = values[:, column]
                nodal[nodes[:, 1]] = values[:, column]
                point_data[name] = nodal[self._field_nodes]
        self.xdmf.write_data(t, point_data=point_data)

    def _close_fields(self) -> None:
        if self.xdmf is not None:
            self.xdmf.__exit__(None, None, None)
            self.xdmf = None

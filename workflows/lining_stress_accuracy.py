"""Accuracy against cost of the lining's stress after the static stage: how many elements through
the lining (docs/lined_tunnel.md).

A circular tunnel (excavation radius b = 5 m, axis y) with a 0.5 m concrete lining (28 GPa, 0.167) in
rock (8 GPa, 0.24), a plane-strain slab 240 x 240 m, far field sigma_zz = -10 MPa, sigma_xx = -5 MPa
(K = 0.5: the lining bends); the stage releases lambda = 0.5 of the excavation load before the lining
is installed, the rest after (meshes/tunnel_in_box.py --lining; docs/static.md). Every run is held to
the closed form of pyfem/analytic/lined_tunnel.py at two places:
- at the lining cells' centroids (where the fields file reports each cell's stress): the largest
  error over the lining, relative to the largest hoop stress in it;
- the peak an engineer reads off the fields (the largest compressive hoop stress over the lining's
  cells) against the true peak, the hoop stress at the lining's inner face: a coarse mesh reports its
  centroids, a quarter of the thickness inside the face with two elements through.
Q1 and Q2 hexahedra with 2, 4 and 8 elements through the lining (h at the wall = t / n).

Usage: /usr/bin/python3 workflows/lining_stress_accuracy.py [--work DIR]
"""
from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem.elements import region_cells  # noqa: E402
from pyfem.analytic.lined_tunnel import LinedTunnel  # noqa: E402
from pyfem.scene import parse_scene  # noqa: E402
from elliptical_opening import stage_on_the_model  # noqa: E402  (this script's folder is on sys.path)
from study_csv import run_study_main  # noqa: E402

RADIUS, SECTION, THICKNESS, LINING_T = 5.0, 240.0, 2.0, 0.5
CENTRE = np.array([SECTION / 2, THICKNESS / 2, SECTION / 2])
ROCK = {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}
LINING = {"E": 28.0e9, "nu": 0.167, "rho": 2500.0}
P, K, RELAXATION = 10.0e6, 0.5, 0.5
FAR_FIELD = (-K * P, -P, 0.0)  # sigma_xx, sigma_zz, sigma_xz (Pa)
THROUGH = [2, 4, 8]            # elements through the lining
RUNS = [(1, 2), (1, 4), (1, 8), (2, 2), (2, 4)]  # (order, elements through)
RESULTS_CSV = ROOT / "workflows" / "results" / "lining_stress.csv"
COLUMNS = ["order", "through", "h_wall", "centroid_error", "peak_read", "peak_exact", "peak_error", "seconds",
           "dofs", "lining_cells"]


def closed_form() -> LinedTunnel:
    return LinedTunnel(RADIUS, LINING_T, LINING["E"], LINING["nu"], ROCK["E"], ROCK["nu"])


def mesh(folder: Path, through: int) -> Path:
    path = folder / f"lined_n{through}.msh"
    if not path.exists():
        subprocess.run([sys.executable, str(ROOT / "meshes" / "tunnel_in_box.py"), str(path), "--radius", str(RADIUS),
                        "--size", str(SECTION), "--lining", str(LINING_T), "--h-wall", str(LINING_T / through)],
                       check=True, timeout=600)
    return path


def scene(mesh_file: Path, order: int):
    return parse_scene({
        "title": f"lined tunnel, static stage, Q{order}",
        "mesh": {"builder": "file", "file": str(mesh_file), "order": order},
        "materials": {"rock": dict(ROCK), "lining": dict(LINING)},
        "time": {"duration": 0.01},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "initial_stress": {"stress": [FAR_FIELD[0], -0.5 * P, FAR_FIELD[1], 0.0, 0.0, 0.0]},
        "static": {"excavate": ["excavation"], "install": ["lining"], "relaxation": RELAXATION},
        "output": {"xdmf_interval": 0.0},
    })


def hoop_at_centroids(simulation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r, theta, sigma_tt) of the lining cells' centroids (m, rad, Pa) from the static stage
    (elliptical_opening.stage_on_the_model)."""
    model = simulation.model
    cells = region_cells(model, "lining")
    n_basis = model.V.element.basix_element.dim
    corners = model.V.dofmap.list.array.reshape(-1, n_basis)[cells, :8]
    x = model.node_coords[corners].mean(axis=1) - CENTRE
    r, theta = np.hypot(x[:, 0], x[:, 2]), np.arctan2(x[:, 2], x[:, 0])
    sigma = simulation.cell_stress[cells]
    c, s = np.cos(theta), np.sin(theta)
    hoop = sigma[:, 0, 0] * s * s + sigma[:, 2, 2] * c * c - 2 * sigma[:, 0, 2] * s * c
    return r, theta, hoop


def run(work: Path) -> list[dict]:
    exact_form = closed_form()
    angles = np.linspace(0.0, 2 * math.pi, 721)
    inner = exact_form.hoop_stress(np.full_like(angles, exact_form.inner_radius), angles, FAR_FIELD, RELAXATION)
    peak_exact = float(np.abs(inner).max())  # compressive peak at the inner face
    rows = []
    for order, through in RUNS:
        started = time.perf_counter()
        simulation = stage_on_the_model(scene(mesh(work, through), order))
        seconds = time.perf_counter() - started
        r, theta, hoop = hoop_at_centroids(simulation)
        exact = exact_form.hoop_stress(r, theta, FAR_FIELD, RELAXATION)
        rows.append({"order": order, "through": through, "h_wall": LINING_T / through,
                     "centroid_error": float(np.abs(hoop - exact).max() / np.abs(exact).max()),
                     "peak_read": float(np.abs(hoop).max()), "peak_exact": peak_exact,
                     "peak_error": float(np.abs(hoop).max() / peak_exact - 1.0), "seconds": seconds,
                     "dofs": int(simulation.model.n_dofs), "lining_cells": len(r)})
        print(rows[-1], flush=True)
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| order | elements through the lining | h at the wall (m) | error at the centroids | peak read off the "
             "cells (MPa) | true peak at the inner face (MPa) | peak error | stage (s) | dofs |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| Q{row['order']} | {row['through']} | {row['h_wall']:g} | {100 * row['centroid_error']:.2f} % | "
                     f"{row['peak_read'] / 1e6:.2f} | {row['peak_exact'] / 1e6:.2f} | {100 * row['peak_error']:+.1f} % | "
                     f"{row['seconds']:.1f} | {row['dofs']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    return run_study_main(__doc__.splitlines()[0], run, table, RESULTS_CSV, COLUMNS, "lining_stress_",
                          argv)


if __name__ == "__main__":
    sys.exit(main())

"""Accuracy against cost of the wall stress of a non-circular opening: the static stage's excavation of an
elliptical opening against the exact answer (docs/elliptical_opening.md).

A tall elliptical opening (half-width 5 m, half-height 10 m: the crown's radius of curvature rho = 2.5 m,
the sidewalls' 20 m) and, for comparison, a circular one (a = 5 m), each in a plane-strain slab 480 x 480
m, 2 m thick (meshes/tunnel_in_box.py --filled [--height 10]; 8 m elements far away), excavated by the
static stage under sigma_xx = -15 MPa, sigma_zz = -10 MPa, sigma_xz = 2.5 MPa (rollers on every face).
Each run is held to the closed form of pyfem/analytic/elliptical_opening.py (`wall_errors`): the hoop stress in
every cell with a face on the wall at its centroid, relative to the exact peak at the wall; the cell where
the exact hoop stress is largest, relative to its own; the wall's displacement. The element size at the
wall h is taken as 0.24, 0.12 and 0.06 times the smallest radius of curvature (rho for the ellipse, a for
the circle), Q1 and Q2: does the advice for a circle of radius a hold for a wall of radius of curvature
rho?

Usage: /usr/bin/python3 workflows/elliptical_opening.py [--work DIR]
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem.analytic.elliptical_opening import EllipticalOpening, wall_errors  # noqa: E402
from pyfem.scene import parse_scene  # noqa: E402
from study_csv import run_study_main  # noqa: E402  (this script's folder is on sys.path)

SECTION = 480.0
ROCK = {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}
P = 10.0e6
FAR_FIELD = (-1.5 * P, -P, 0.25 * P)  # sigma_xx, sigma_zz, sigma_xz (Pa)
SHAPES = {"ellipse": (5.0, 10.0), "circle": (5.0, 5.0)}  # half-width, half-height (m)
H_OVER_RHO = [0.24, 0.12, 0.06]
ORDERS = [1, 2]
RESULTS_CSV = ROOT / "workflows" / "results" / "elliptical_opening.csv"
COLUMNS = ["shape", "order", "rho", "h_wall", "h_over_rho", "worst", "peak_cell", "displacement", "exact_peak",
           "largest_hoop", "cells", "dofs", "seconds"]


def mesh(folder: Path, shape: str, h_wall: float) -> Path:
    half_width, half_height = SHAPES[shape]
    path = folder / f"{shape}_h{h_wall:g}.msh"
    if not path.exists():
        subprocess.run([sys.executable, str(ROOT / "meshes" / "tunnel_in_box.py"), str(path), "--radius",
                        str(half_width), "--height", str(half_height), "--size", str(SECTION), "--filled",
                        "--h-wall", str(h_wall)], check=True, timeout=600)
    return path


def excavate(mesh_file: Path, order: int):
    scene = parse_scene({
        "title": "elliptical opening",
        "mesh": {"builder": "file", "file": str(mesh_file), "order": order},
        "materials": {"rock": dict(ROCK)},
        "time": {"duration": 0.01},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "initial_stress": {"stress": [FAR_FIELD[0], 0.5 * (FAR_FIELD[0] + FAR_FIELD[1]), FAR_FIELD[1], 0.0,
                                      FAR_FIELD[2], 0.0]},
        "static": {"excavate": ["excavation"], "relaxation": 0.0},
        "output": {"xdmf_interval": 0.0},
    })
    return stage_on_the_model(scene)


def stage_on_the_model(scene):
    """The scene's [static] stage solved on the one model in this process (one rank, nothing written:
    pyfem.distributed_model.model_in_memory): `.model` (pyfem.operators.Model), `.cell_stress` (n_cells,
    3, 3) at the centroids (Pa, as static/fields.xdmf writes it: pyfem.distributed_stage.cell_static_stress;
    linear materials) and `.displacement` (3 n,) u1 + u2 (m), in the function space's numbering."""
    from pyfem.distributed_model import model_in_memory
    from pyfem.distributed_stage import cell_static_stress
    from pyfem.output import cell_strain_operator

    solved = model_in_memory(scene)
    part, stage = solved.part, solved.stage
    model = part.model
    return SimpleNamespace(model=model, displacement=part.dolfinx_order(stage.u_total),
                           cell_stress=cell_static_stress(stage, part, cell_strain_operator(scene, model))[:model.n_cells])


def run(work: Path) -> list[dict]:
    rows = []
    for shape, (half_width, half_height) in SHAPES.items():
        opening = EllipticalOpening(half_width, half_height, ROCK["E"], ROCK["nu"], centre=(SECTION / 2, SECTION / 2))
        rho = opening.smallest_radius_of_curvature
        for order in ORDERS:
            for ratio in H_OVER_RHO:
                h_wall = ratio * rho
                path = mesh(work, shape, h_wall)
                started = time.perf_counter()
                simulation = excavate(path, order)
                seconds = time.perf_counter() - started
                errors = wall_errors(simulation, opening, FAR_FIELD)
                rows.append({"shape": shape, "order": order, "rho": rho, "h_wall": h_wall, "h_over_rho": ratio,
                             "worst": errors["worst"], "peak_cell": errors["peak_cell"],
                             "displacement": errors["displacement"], "exact_peak": errors["peak"],
                             "largest_hoop": errors["largest_hoop"], "cells": errors["cells"],
                             "dofs": int(simulation.model.n_dofs), "seconds": seconds})
                print(f"{shape} Q{order} h/rho {ratio:g}: worst {errors['worst']:.2%}, peak cell "
                      f"{errors['peak_cell']:.2%}, wall u {errors['displacement']:.2%}, {seconds:.1f} s", flush=True)
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| opening | order | h / rho | worst wall cell (% of peak) | peak cell (%) | wall displacement (%) | "
             "dofs | prepare + stage (s) |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        lines.append(f"| {row['shape']} (rho {float(row['rho']):g} m) | Q{row['order']} | {float(row['h_over_rho']):g} | "
                     f"{100 * float(row['worst']):.2f} | {100 * float(row['peak_cell']):.2f} | "
                     f"{100 * float(row['displacement']):.2f} | {int(row['dofs']):,} | {float(row['seconds']):.1f} |")
    return "\n".join(lines).replace(",", " ")


def main(argv=None) -> int:
    return run_study_main(__doc__.splitlines()[0], run, table, RESULTS_CSV, COLUMNS, "elliptical_opening_",
                          argv)


if __name__ == "__main__":
    sys.exit(main())

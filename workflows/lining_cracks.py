"""Where and how wide the case study's lining cracks: the crack band's opening over time.

The lining's damage saturates (d = 0.9999 over the whole ring in every case), so the damage map
says only that the ring cracked. The crack opening (docs/materials.md "Crack opening": h d_t
kappa_t, the largest opening each cell reached) keeps growing after the damage saturates, so it
ranks the parts of the ring by how far they opened. For each run directory given (runs whose
fields have `crack_opening`, since 2026-11-28) this reads every field sample of the lining and
prints, at each time, the share of the lining opened beyond 0.1 / 0.3 / 1 mm and the median
opening of the crown, the walls and the floor (as seen from the section's mid-height) and of the
soft-layer bay (|y| < 10 m); it draws the unrolled lining's opening at the end of each run.

    /usr/bin/python3 workflows/lining_cracks.py RUN_DIR [RUN_DIR ...] [--figure PATH] [--json PATH]
"""
import argparse
import json
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from case_study import (BAY_HALF_LENGTH, _pyplot, draw_unrolled, lining_cells, section_angle,  # noqa: E402
                        section_parts)

THRESHOLDS_MM = (0.1, 0.3, 1.0)


def lining_samples(directory: pathlib.Path) -> dict:
    """Every field sample's lining crack opening (mm) with the cells' position around the section
    (deg, case_study.section_angle) and along the cavern (y, m)."""
    from pyfem.fields_file import read_fields

    summary = json.loads((directory / "run.json").read_text())
    fields = read_fields(directory / "fields.xdmf")
    points, cells, samples = fields.points, fields.cells, fields.steps
    # A run resumed across 2026-11-28 has the field from its resumed sitting on: read those samples.
    samples = [sample for sample in samples if "crack_opening" in sample[2]]
    if not samples:
        raise SystemExit(f"{directory}: its fields have no crack_opening (a run from before 2026-11-28)")
    lining, centroids = lining_cells({"points": points, "cells": cells,
                                      "cell_data": {"region": samples[0][2]["region"]}}, summary)
    return {"title": summary["scene"]["title"], "t": np.array([t for t, _, _ in samples]),
            "opening_mm": np.array([1e3 * c["crack_opening"][lining] for _, _, c in samples]),
            "damage": np.array([c["damage"][lining] for _, _, c in samples]),
            "angle": section_angle(centroids, centre_z=0.5 * centroids[:, 2].max()), "y": centroids[:, 1]}


def parts(run: dict) -> dict:
    return {**section_parts(run["angle"]), "bay": np.abs(run["y"]) < BAY_HALF_LENGTH}


def table(run: dict) -> list:
    rows = []
    where = parts(run)
    for k, t in enumerate(run["t"]):
        w = run["opening_mm"][k]
        rows.append({"t": float(t), "damaged_share": float(np.mean(run["damage"][k] > 0.5)),
                     **{f"opened_{mm:g}mm": float(np.mean(w > mm)) for mm in THRESHOLDS_MM},
                     **{f"median_{name}_mm": float(np.median(w[mask])) for name, mask in where.items()},
                     "largest_mm": float(w.max())})
    return rows


def figure(runs: dict, path: pathlib.Path) -> None:
    from matplotlib.colors import LogNorm

    plt = _pyplot()
    fig, axes = plt.subplots(1, len(runs), figsize=(4.6 * len(runs) + 1.6, 5.2), squeeze=False, sharey=True)
    for ax, (name, run) in zip(axes[0], runs.items()):
        image = draw_unrolled(ax, run["angle"], run["y"], np.maximum(run["opening_mm"][-1], 1e-3),
                              f"{name}, t = {run['t'][-1]:.2f} s", cmap="inferno_r", norm=LogNorm(vmin=1e-3, vmax=300.0))
    axes[0][0].set_ylabel("y along the cavern (m)")
    fig.colorbar(image, ax=axes[0].tolist(), shrink=0.8).set_label("largest crack opening (mm)")
    fig.suptitle("lining crack opening at its largest, unrolled (where the damage saturates at 0.9999); "
                 "shaded: the soft-layer bay", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=pathlib.Path)
    parser.add_argument("--figure", type=pathlib.Path)
    parser.add_argument("--json", type=pathlib.Path)
    args = parser.parse_args(argv)
    runs = {directory.name: lining_samples(directory) for directory in args.runs}
    tables = {name: table(run) for name, run in runs.items()}
    for name, rows in tables.items():
        print(f"\n{name} ({runs[name]['title']}): lining share damaged > 0.5 and opened beyond "
              f"{', '.join(f'{mm:g}' for mm in THRESHOLDS_MM)} mm; median opening (mm) of the crown, walls, "
              "floor, soft-layer bay; largest")
        for row in rows:
            print(f"  t = {row['t']:5.2f} s: {100 * row['damaged_share']:5.1f} % | "
                  + " ".join(f"{100 * row[f'opened_{mm:g}mm']:5.1f} %" for mm in THRESHOLDS_MM) + " | "
                  + " ".join(f"{row[f'median_{p}_mm']:7.3f}" for p in ("crown", "walls", "floor", "bay"))
                  + f" | {row['largest_mm']:.2f}")
    if args.figure:
        figure(runs, args.figure)
    if args.json:
        args.json.write_text(json.dumps(tables, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

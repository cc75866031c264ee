"""Accuracy versus cost: what each digit of accuracy costs in wall time.

The problem has an exact answer: a homogeneous box under a free surface, hit by an SV
Ricker pulse (f0 = 5 Hz, content up to 2.5 f0 = 12.5 Hz) incident at 30 degrees. With the
total free field applied on its faces, the box must move as the analytical half-space free
field; the error of a run is the relative L2 error of the displacement at three monitors on
the box's vertical axis, 40 m apart, 130 m and more below the free surface, over the whole
pulse (incident, reflected SV and reflected P). The monitors are at least 60 m and three
elements from every face: the box is 120 x 120 x 200 m for h <= 20 m and grows with h above.

Knobs, one run per combination:
  * element order: Q1 (8-node) and Q2 (27-node, lumped: spectral-element like);
  * elements per shortest shear wavelength (lambda = 1114 m/s / 12.5 Hz = 89 m), four
    levels per order, from sizes that divide the box (the monitors stay on nodes). The
    monitors are >= 60 m (0.7 wavelength) and >= 3 elements from the faces: nearer, the
    faces' exact input pins the solution on coarse meshes (one element from the faces, Q2
    at 2.2 elements per wavelength "measured" 0.3-0.9 %) and the error no longer measures
    propagation;
  * time step as a fraction ("safety") of the critical step: 0.3, 0.6, 0.9;
  * boundary: viscoelastic (springs + dashpots, the paper's), viscous (dashpots only).
    A fixed face cannot carry the free-field input (the input is a force through the
    boundary's springs and dashpots), so a fixed box stays at rest: error 100 %. The
    rows "fixed" of the CSV are the control runs of 2026-11-23 that showed it; since
    then a scene with [wave] and no face able to carry input is an error (exit 2), so
    the sweep no longer runs them.
Cost: the seconds of the time loop per 120 x 120 x 200 m of model (run.json loop_seconds
scaled by the box's volume, since the box grows with h; the model setup, a fixed
cost of a few seconds, is in wall_seconds and in the CSV too), measured in this session
on this machine: compare ratios, not absolute values.

Outputs: workflows/results/accuracy_cost.csv (one row per run; copied to the program's pyfem/data/), docs/accuracy_cost.md
(table, Pareto front, settings for 5 % and 1 % error budgets), docs/accuracy_cost.png
(error against seconds, log-log, Pareto front marked). `pyfem.accuracy.recommend`
reads the CSV.

Sample runs (from the repository root):
    /usr/bin/python3 workflows/accuracy_cost.py            # the full study, ~12 min
    /usr/bin/python3 workflows/accuracy_cost.py --quick    # 2 sizes per order, ~1 min
    /usr/bin/python3 workflows/accuracy_cost.py --quick --out /tmp/study   # elsewhere
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem import solver  # noqa: E402
from pyfem.accuracy import COST_COLUMN, pareto_front  # noqa: E402
from pyfem.scene import parse_scene  # noqa: E402
from study_csv import publish  # noqa: E402  (this script's folder is on sys.path)

# ----------------------------------------------------------------------------- parameters
E, NU, RHO = 8.0e9, 0.24, 2600.0
SHEAR_SPEED = math.sqrt(E / (2 * (1 + NU)) / RHO)        # 1114 m/s
F0 = 5.0                                                  # Ricker peak frequency (Hz)
SHORTEST_WAVELENGTH = SHEAR_SPEED / (2.5 * F0)            # 89 m
# The monitors keep at least MONITOR_CLEARANCE metres and MONITOR_CLEARANCE_ELEMENTS
# elements from every face (faces carry the exact field: nearer monitors are pinned to it,
# and a 120 m box with 40 m elements once "measured" 0.9 % for Q2 at 2.2 elements per
# wavelength). The box grows with h for that; the monitors, 40 m apart on the box's axis,
# and the free surface 130 m above the highest monitor keep the same relative geometry.
MONITOR_CLEARANCE, MONITOR_CLEARANCE_ELEMENTS = 60.0, 3
MONITOR_SPACING, SURFACE_ABOVE_MONITORS = 40.0, 130.0   # m (above the largest box top: 120 m)
WAVE = {"type": "SV", "angle": 30.0, "azimuth": 0.0}
# Monitor sampling: 20 samples per period at f0, 8 at 2.5 f0. The time step divides the
# interval, so the interval must exceed the largest step tried (0.9 x critical is ~5 ms
# for Q1 at h = 20 m): a shorter one would cap every step and hide the safety knob.
DURATION, INTERVAL = 1.2, 0.01                            # s
# Element sizes (m) per order: their nodes fall on the box faces and the monitors.
# Q1: 4.5 to 22 elements per wavelength; Q2 (two node spacings per element): 2.2 to 8.9.
SIZES = {1: [20.0, 10.0, 5.0, 4.0], 2: [40.0, 20.0, 40.0 / 3.0, 10.0]}
SAFETIES = [0.3, 0.6, 0.9]
BOUNDARIES = ["viscoelastic", "viscous"]
QUICK_SIZES = {1: [20.0, 10.0], 2: [40.0, 20.0]}
QUICK_SAFETIES = [0.6, 0.9]
BUDGETS = [0.05, 0.01]

RESULTS_CSV = ROOT / "workflows" / "results" / "accuracy_cost.csv"
REPORT_MD = ROOT / "docs" / "accuracy_cost.md"
REPORT_PNG = ROOT / "docs" / "accuracy_cost.png"
COLUMNS = ["order", "h", "elements_per_wavelength", "safety", "boundary", "dt", "steps", "dofs", "error",
           "wall_seconds", "loop_seconds", "box_volume", COST_COLUMN]
# Cost is compared per this volume (m^3): the box of every level with h <= 20 m.
REFERENCE_VOLUME = 120.0 * 120.0 * 200.0


def add_normalised_cost(row):
    """Adds the box volume and the loop seconds scaled to REFERENCE_VOLUME to a result row."""
    size, _, _ = box_geometry(row["h"])
    row["box_volume"] = size[0] * size[1] * size[2]
    row[COST_COLUMN] = row["loop_seconds"] * REFERENCE_VOLUME / row["box_volume"]
    return row


# ----------------------------------------------------------------------------- step 1: one run
def box_geometry(h):
    """(box size, monitor points, surface z) for element size h (m): clearance whole elements."""
    margin = h * math.ceil(max(MONITOR_CLEARANCE, MONITOR_CLEARANCE_ELEMENTS * h) / h - 1e-9)
    size = (2 * margin, 2 * margin, 2 * margin + 2 * MONITOR_SPACING)
    monitors = [(margin, margin, margin + k * MONITOR_SPACING) for k in range(3)]
    surface = monitors[-1][2] + SURFACE_ABOVE_MONITORS
    return size, monitors, surface


def box_scene(order, h, safety, boundary):
    """The study's scene for one combination of knobs."""
    size, monitors, surface = box_geometry(h)
    return parse_scene({
        "title": f"accuracy-cost Q{order} h={h:g} safety={safety:g} {boundary}",
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": list(size), "h": h, "order": order},
        "materials": {"rock": {"E": E, "nu": NU, "rho": RHO}},
        "time": {"duration": DURATION, "safety": safety},
        "wave": {**WAVE, "surface": surface, "motion": {"ricker": {"f0": F0, "amplitude": 1.0e-3}}},
        "boundary": {"type": boundary},
        "monitor": [{"name": f"m{k}", "point": list(p)} for k, p in enumerate(monitors)],
        "output": {"interval": INTERVAL, "xdmf_interval": 0.0},
    })


def run_one(order, h, safety, boundary, work_dir):
    """Runs one combination; returns its CSV row (error against the exact free field, seconds)."""
    out = Path(work_dir) / f"q{order}_h{h:.4g}_s{safety:g}_{boundary}"
    summary = solver.run(box_scene(order, h, safety, boundary), out)
    computed, exact = [], []
    for k in range(3):
        data = np.genfromtxt(out / "monitors" / f"m{k}.csv", delimiter=",", names=True)
        computed.append(np.column_stack([data["ux"], data["uy"], data["uz"]]))
        exact.append(np.column_stack([data["ux_ff"], data["uy_ff"], data["uz_ff"]]))
    computed, exact = np.array(computed), np.array(exact)
    error = float(np.linalg.norm(computed - exact) / np.linalg.norm(exact))
    return add_normalised_cost({
        "order": order, "h": h, "elements_per_wavelength": SHORTEST_WAVELENGTH / h, "safety": safety,
        "boundary": boundary, "dt": summary["dt"], "steps": summary["steps"], "dofs": summary["dofs"],
        "error": error, "wall_seconds": summary["wall_seconds"], "loop_seconds": summary["loop_seconds"]})


# ----------------------------------------------------------------------------- step 2: the sweep
def sweep(quick, work_dir, log=print):
    """All runs of the study, cheapest meshes first; returns the rows."""
    sizes = QUICK_SIZES if quick else SIZES
    safeties = QUICK_SAFETIES if quick else SAFETIES
    boundaries = BOUNDARIES[:1] if quick else BOUNDARIES
    plan = [(order, h, safety, boundary) for order in (1, 2) for h in sizes[order]
            for boundary in boundaries for safety in safeties]
    rows = []
    start = time.perf_counter()
    for k, knobs in enumerate(plan):
        row = run_one(*knobs, work_dir)
        rows.append(row)
        log(f"[{k + 1}/{len(plan)}] Q{row['order']} {row['elements_per_wavelength']:5.1f} el/wl "
            f"safety {row['safety']:.1f} {row['boundary']:12s} error {row['error']:.2e} "
            f"loop {row['loop_seconds']:6.2f} s wall {row['wall_seconds']:6.2f} s "
            f"(study {time.perf_counter() - start:.0f} s)")
    return rows


def write_csv(rows, path):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS + ["pareto"])
        writer.writeheader()
        front = {id(r) for r in pareto_front(rows)}
        for row in rows:
            writer.writerow({**{key: row[key] for key in COLUMNS}, "pareto": int(id(row) in front)})
    publish(path)  # the program's copy, pyfem/data/accuracy_cost.csv


# ----------------------------------------------------------------------------- step 3: the report
def cheapest_within(rows, budget):
    meeting = [r for r in rows if r["error"] <= budget]
    return min(meeting, key=lambda r: (r[COST_COLUMN], r["error"])) if meeting else None


def describe(row):
    return (f"Q{row['order']}, {row['elements_per_wavelength']:.3g} elements per wavelength "
            f"(h = {row['h']:.4g} m), "
            f"safety {row['safety']:g}, {row['boundary']} boundary: error {100 * row['error']:.2g} % in "
            f"{row[COST_COLUMN]:.2f} s")


def write_plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    front = pareto_front(rows)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    markers = {"viscoelastic": "o", "viscous": "s", "fixed": "x"}
    colours = {1: "tab:blue", 2: "tab:orange"}
    for order in (1, 2):
        for boundary, marker in markers.items():
            chosen = [r for r in rows if r["order"] == order and r["boundary"] == boundary]
            if chosen:
                ax.scatter([r[COST_COLUMN] for r in chosen], [r["error"] for r in chosen], marker=marker,
                           color=colours[order], alpha=0.75, label=f"Q{order} {boundary}")
    ax.plot([r[COST_COLUMN] for r in front], [r["error"] for r in front], "k-", lw=1.2, label="Pareto front")
    for row in front:
        ax.annotate(f"Q{row['order']} {row['elements_per_wavelength']:.3g}/{row['safety']:g}",
                    (row[COST_COLUMN], row["error"]), textcoords="offset points", xytext=(4, 4), fontsize=7)
    for budget in BUDGETS:
        ax.axhline(budget, color="0.6", ls=":", lw=1)
        ax.text(min(r[COST_COLUMN] for r in rows), budget * 1.08,
                f"{100 * budget:g} %", color="0.4", fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time loop (s, this machine)")
    ax.set_ylabel("relative L2 error of the displacement")
    ax.set_title("Accuracy versus cost: SV at 30 deg in a homogeneous box\n"
                 "labels on the front: order, elements per wavelength / time-step safety", fontsize=10)
    ax.legend(fontsize=8, loc="lower left")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_report(rows, path, png_name, quick, study_seconds):
    front = pareto_front(rows)
    lines = [
        "# Accuracy versus cost",
        "",
        f"Generated by `workflows/accuracy_cost.py{' --quick' if quick else ''}`; do not edit by hand.",
        "",
        "Problem: homogeneous box (E 8 GPa, nu 0.24, rho 2600 kg/m^3, c_s 1114 m/s) under a free surface "
        "130 m above the highest monitor; SV Ricker pulse (f0 = 5 Hz) incident at 30 deg. "
        f"Shortest wavelength {SHORTEST_WAVELENGTH:.1f} m (c_s / 2.5 f0). Error: relative L2 error of the "
        "displacement at three monitors (at least 60 m and 3 elements from every face: 120 x 120 x 200 m "
        "for h <= 20 m, 240 x 240 x 320 m for h = 40 m) against the exact free field, over "
        f"{DURATION:g} s. Cost: seconds of the time loop (`loop_seconds`) scaled to a 120 x 120 x 200 m "
        "model (the box grows with h), measured in one session on a "
        f"2-core machine shared with other jobs: compare ratios. Study: {len(rows)} runs, "
        f"{study_seconds / 60:.1f} min of wall time in all.",
        "",
        f"![error against seconds]({png_name})",
        "",
        "## Settings for an error budget",
        "",
    ]
    for budget in BUDGETS:
        best = cheapest_within(rows, budget)
        advice = describe(best) if best else "no run of the study reached it"
        lines.append(f"- **{100 * budget:g} %**: {advice}.")
    header = ("| order | el./wavelength | h (m) | safety | boundary | dofs | steps | dt (s) | error | loop s | "
              "loop s per reference volume | wall s |")
    lines += ["", "## Pareto front (no run is both cheaper and more accurate)", "", header, "|---" * 12 + "|"]
    lines += [table_row(r) for r in front]
    lines += ["", "## All runs", "", header, "|---" * 12 + "|"]
    order = sorted(rows, key=lambda r: (r["boundary"] == "fixed", r["order"], -r["h"], r["boundary"], r["safety"]))
    lines += [table_row(r) for r in order]
    lines += ["", "## Conclusion", ""] + conclusion(rows)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def table_row(r):
    return (f"| Q{r['order']} | {r['elements_per_wavelength']:.3g} | {r['h']:.4g} | {r['safety']:g} | "
            f"{r['boundary']} | {r['dofs']} | {r['steps']} | {r['dt']:.3g} | {r['error']:.2e} | "
            f"{r['loop_seconds']:.2f} | {r[COST_COLUMN]:.3g} | {r['wall_seconds']:.2f} |")


def conclusion(rows):
    """Sentences drawn from the numbers of this study (not written in advance)."""
    text = []
    absorbing = [r for r in rows if r["boundary"] != "fixed"]
    for budget in BUDGETS:
        best = cheapest_within(rows, budget)
        if best is None:
            text.append(f"- No setting of the study reaches {100 * budget:g} %.")
            continue
        q1 = cheapest_within([r for r in absorbing if r["order"] == 1], budget)
        q2 = cheapest_within([r for r in absorbing if r["order"] == 2], budget)
        parts = [f"- For a {100 * budget:g} % budget use {describe(best)}."]
        if q1 and q2:
            other, mine = (q2, q1) if best["order"] == 1 else (q1, q2)
            parts.append(f"The cheapest Q{other['order']} run within it costs "
                         f"{other[COST_COLUMN] / mine[COST_COLUMN]:.2g}x as much ({describe(other)}).")
        text.append(" ".join(parts))
    # Time-step fraction: error change from safety 0.9 to 0.3 on the same mesh, per order.
    for order in (1, 2):
        ratios = []
        for r in absorbing:
            if r["order"] == order and r["safety"] == max(SAFETIES):
                key = (r["order"], r["h"], r["boundary"])
                same = [s for s in absorbing
                        if (s["order"], s["h"], s["boundary"]) == key and s["safety"] == min(SAFETIES)]
                if same:
                    ratios.append((r["error"] / same[0]["error"], same[0][COST_COLUMN] / r[COST_COLUMN]))
        if ratios:
            errors, costs = zip(*ratios)
            verdict = ("the mesh dominates the error: use the largest stable fraction" if max(errors) < 1.5 else
                       "the time step matters on fine meshes, where the space error has become small")
            text.append(f"- Time step, Q{order}: error at 0.9 / error at 0.3 of the critical step is "
                        f"{min(errors):.2g} to {max(errors):.2g} for {np.median(costs):.2g}x the time (median); "
                        f"{verdict}.")
    pairs = []
    for r in absorbing:
        if r["boundary"] == "viscous":
            twin = [s for s in absorbing if s["boundary"] == "viscoelastic"
                    and (s["order"], s["h"], s["safety"]) == (r["order"], r["h"], r["safety"])]
            if twin:
                pairs.append(r["error"] / twin[0]["error"])
    if pairs:
        text.append(f"- Boundary: viscous error / viscoelastic error ranges over {min(pairs):.2g} to "
                    f"{max(pairs):.2g} (median {np.median(pairs):.2g}); with the total free field as input both "
                    "are exact in the continuum, and the choice barely changes the cost (springs add to the "
                    "stiffness's diagonal only).")
    fixed = [r for r in rows if r["boundary"] == "fixed"]
    if fixed:
        text.append(f"- Fixed faces: error {min(r['error'] for r in fixed):.2g} or more; a fixed box cannot "
                    "take the free-field input, which is why the input goes through viscoelastic (or viscous) "
                    "boundaries.")
    front = pareto_front(rows)
    text.append("- Pareto front: " + "; ".join(f"Q{r['order']} {r['elements_per_wavelength']:.3g} el./wl, "
                                              f"safety {r['safety']:g}, {r['boundary']} ({r['error']:.1e}, "
                                              f"{r[COST_COLUMN]:.2g} s)" for r in front) + ".")
    text.append("- Caveat: the monitors are at least 60 m (0.7 shortest wavelength) and 3 elements from the "
                "faces, which carry the exact field; dispersion error grows with the distance a wave travels "
                "inside the mesh, so where the region of interest lies several wavelengths from the faces "
                "expect proportionally larger errors on the coarse levels: take the next finer level of the "
                "table for large models.")
    text.append("- `pyfem.accuracy.element_size_for(scene, budget)` turns these into an element size for "
                "a scene: h = (slowest c_s / highest frequency) / elements per wavelength.")
    return text


# ----------------------------------------------------------------------------- main
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 sizes per order, 2 safeties, viscoelastic only")
    parser.add_argument("--report-only", action="store_true",
                        help="no runs: rebuild the markdown and the plot from the existing CSV")
    parser.add_argument("--out", type=Path, default=None,
                        help="directory for the CSV, markdown and PNG (default: workflows/results and docs)")
    args = parser.parse_args(argv)
    csv_path, md_path, png_path = RESULTS_CSV, REPORT_MD, REPORT_PNG
    if args.out is not None:
        csv_path, md_path, png_path = (args.out / p.name for p in (RESULTS_CSV, REPORT_MD, REPORT_PNG))
    if args.report_only:
        from pyfem.accuracy import read_results

        rows = [add_normalised_cost(r) for r in read_results(csv_path, cost_column="loop_seconds")]
        seconds = sum(r["wall_seconds"] for r in rows)  # the runs' own; the sweep adds file reading
        write_csv(rows, csv_path)
        write_plot(rows, png_path)
        write_report(rows, md_path, png_path.name, args.quick, seconds)
        print(f"rebuilt {md_path} and {png_path} from {csv_path}")
        return 0
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="accuracy_cost_") as work_dir:
        rows = sweep(args.quick, work_dir)
    seconds = time.perf_counter() - start
    write_csv(rows, csv_path)
    write_plot(rows, png_path)
    write_report(rows, md_path, png_path.name, args.quick, seconds)
    print(f"{len(rows)} runs in {seconds:.0f} s; wrote {csv_path}, {md_path}, {png_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

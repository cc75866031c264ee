"""Case 3 (coarse) with and without the powerhouse's internal concrete: D(t) and the racking.

Issue 48, item 4. Both runs use the same mesh (workflows/scenes/case3_internal_concrete_coarse.toml:
mesh.parameters.internal_concrete = true, so the rock, lining and excavation grids are identical);
"with" installs the region "internal_concrete" (machine piers, turbine and generator floor slabs,
wind covers; the lining's concrete and damage law) with the lining in the static stage, "without"
excavates it with the excavation. Over a short record window (time.duration, default 2 s; a run
stopped early is read up to where both runs have got), this writes

    workflows/results/internal_concrete.csv   quantity, without, with, with / without
    workflows/results/internal_concrete.md    the same as a table, with the window and the costs

Quantities (cm for displacements): D(t) at the end of the window and its minimum at the five pair
monitors; the lining's peak |u| at A-D; the racking of A, B, C against the floor D read both ways:
the peak of the difference max_t |u_X - u_D| and the difference of the peaks max |u_X| - max |u_D|,
and the horizontal (x) racking max_t |ux_X - ux_D|.

Sample runs (from the repository root, Debian's Python; each run ~1-2 h on one loaded core):

    PYFEM_ONE_MODEL=1 OMP_NUM_THREADS=1 /usr/bin/python3 workflows/internal_concrete.py --run
    # both runs, one after the other, into runs/internal_concrete/{without,with}
    /usr/bin/python3 workflows/internal_concrete.py --runs /tmp/ic_runs    # report runs made elsewhere
"""
from __future__ import annotations

import argparse
import csv
import json
import pathlib
import subprocess
import sys

import numpy as np

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
SCENE = REPOSITORY / "workflows" / "scenes" / "case3_internal_concrete_coarse.toml"
RUNS = REPOSITORY / "runs" / "internal_concrete"
RESULTS = REPOSITORY / "workflows" / "results"
# Both: no filter lead-in (the run starts at the record window's start; 1 s less to run) and no field files.
COMMON = ["wave.motion.record.lead_in=0.0", "output.xdmf_interval=0.0"]
VARIANTS = {"without": ['static.excavate=["excavation","internal_concrete"]', 'static.install=["lining"]'],
            "with": []}
PAIRS = ("wall_up_8", "wall_down_8", "wall_up_9", "wall_down_9", "crown_9")
LINING = ("A", "B", "C", "D")


def read_csv(path: pathlib.Path) -> dict:
    with open(path) as stream:
        header = stream.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(header)}


def run(variant: str, runs: pathlib.Path, duration: float) -> None:
    sets = [arg for item in [f"time.duration={duration}", *COMMON, *VARIANTS[variant]] for arg in ("--set", item)]
    subprocess.run([sys.executable, "-m", "pyfem", "run", str(SCENE), "--out", str(runs / variant), *sets],
                   cwd=REPOSITORY, check=True)


def numbers(directory: pathlib.Path, t_end: float) -> dict:
    """The quantities of one run over t <= t_end."""
    out = {}
    for name in PAIRS:
        pair = read_csv(directory / "pairs" / f"{name}.csv")
        keep = pair["t"] <= t_end + 1e-9
        out[f"D at the end, {name}"] = float(pair["D"][keep][-1])
        out[f"D min, {name}"] = float(pair["D"][keep].min())
    u = {}
    for name in LINING:
        monitor = read_csv(directory / "monitors" / f"{name}.csv")
        keep = monitor["t"] <= t_end + 1e-9
        u[name] = np.column_stack([monitor["ux"], monitor["uy"], monitor["uz"]])[keep]
    length = min(len(v) for v in u.values())
    u = {name: v[:length] for name, v in u.items()}
    peak = {name: float(np.linalg.norm(v, axis=1).max()) for name, v in u.items()}
    for name in LINING:
        out[f"peak |u| at {name} (cm)"] = 100 * peak[name]
    for name in ("A", "B", "C"):
        out[f"{name} - D: max_t |u_X - u_D| (cm)"] = 100 * float(np.linalg.norm(u[name] - u["D"], axis=1).max())
        out[f"{name} - D: peak |u_X| - peak |u_D| (cm)"] = 100 * (peak[name] - peak["D"])
        out[f"{name} - D: max_t |ux_X - ux_D| (cm)"] = 100 * float(np.abs(u[name][:, 0] - u["D"][:, 0]).max())
    return out


def last_time(directory: pathlib.Path) -> float:
    return float(read_csv(directory / "monitors" / "D.csv")["t"][-1])


def report(runs: pathlib.Path, results: pathlib.Path) -> str:
    t_end = min(last_time(runs / variant) for variant in VARIANTS)
    table = {variant: numbers(runs / variant, t_end) for variant in VARIANTS}
    summaries = {}
    for variant in VARIANTS:
        path = runs / variant / "run.json"
        summaries[variant] = json.loads(path.read_text()) if path.exists() else {}
    results.mkdir(parents=True, exist_ok=True)
    with open(results / "internal_concrete.csv", "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["quantity", "without", "with", "with / without"])
        for key in table["without"]:
            a, b = table["without"][key], table["with"][key]
            writer.writerow([key, f"{a:.4f}", f"{b:.4f}", f"{b / a:.3f}" if a else ""])
    lines = ["# Case 3 (coarse) with and without the internal concrete",
             "",
             "Generated by `workflows/internal_concrete.py` from two runs of "
             "`workflows/scenes/case3_internal_concrete_coarse.toml` on the same mesh (\"without\": the region "
             "`internal_concrete` excavated with the excavation; \"with\": installed with the lining in the "
             f"static stage). Window: record time 0 to {t_end:.2f} s (the time both runs had reached; "
             "no filter lead-in). Rows \"D ...\": the deterioration factor at the pair monitors; the racking "
             "of A, B, C against the floor D in cm.", ""]
    for variant, summary in summaries.items():
        if summary:
            stages = ", ".join(f"{stage['name']} {stage['iterations']} steps"
                               for stage in (summary.get("static") or {}).get("stages", []))
            lines.append(f"- {variant}: {summary.get('cells')} cells, dt {summary.get('dt', 0):.4g} s, static "
                         f"stages {stages}; status {summary.get('status')} at t = "
                         f"{summary.get('time_reached', float('nan')):.2f} s of {summary['scene']['time']['duration']:g} s")
    lines += ["", "| quantity | without | with | with / without |", "|---|---:|---:|---:|"]
    for key in table["without"]:
        a, b = table["without"][key], table["with"][key]
        lines.append(f"| {key} | {a:.3f} | {b:.3f} | {b / a:.3f} |" if a else f"| {key} | {a:.3f} | {b:.3f} | - |")
    text = "\n".join(lines) + "\n"
    (results / "internal_concrete.md").write_text(text)
    return text


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--run", action="store_true", help="run both variants first (hours)")
    parser.add_argument("--runs", type=pathlib.Path, default=RUNS, help="directory holding with/ and without/")
    parser.add_argument("--duration", type=float, default=2.0, help="record time to run to (s)")
    args = parser.parse_args(argv)
    if args.run:
        for variant in VARIANTS:
            run(variant, args.runs, args.duration)
    print(report(args.runs, RESULTS))


if __name__ == "__main__":
    main()

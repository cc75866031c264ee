"""Local stepping on the small case 3 with all physics: the row split against the column split and
global stepping (docs/local_stepping.md "The scheme: the row split").

The small model of tests/test_case_study_stage.py (workflows/scenes/case3_contact_coarse.toml shrunk
to a 90 x 74 x 110 m block around a 24 m cavern, two interfaces with contact pairs): its static
stage, then `--duration` s of oblique El Centro with the rock yielding, the lining cracking and the
pairs sticking and slipping. Runs global stepping at safety 0.2 (the reference) and 0.8, and local
stepping at 0.8 by the column split and by the row split (each forced through
`pyfem.local_stepping.row_split`; the row split is the default since this comparison, docs/local_stepping.md
"The energy account"). Prints per run: the largest difference of u at the lining monitors A-D from the
reference relative to its peak, the largest slip at the pair monitors, the yielded rock, the lining's damaged
volume, the energy balance error and the wall time of the run (nan: a finished run directory read
again, not run).

    /usr/bin/python3 workflows/lts_small_case3.py [--out DIR] [--duration 1.5]   # ~15 min on 2 cores

`--model coarse` runs the coarse case 3 itself (workflows/scenes/case3_contact_coarse.toml as it is,
43 904 cells, 11 520 pairs) for its speed: global stepping and both splits at the scene's safety 0.8
(no finer reference: the u columns are against global stepping at 0.8), and prints per run the time
loop's seconds per simulated second and its speed against global stepping.

    /usr/bin/python3 workflows/lts_small_case3.py --model coarse --duration 1.5   # ~25 min on 2 cores
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "workflows"))

RUNS = {"small": [("global", 0.2, None), ("global", 0.8, None), ("local", 0.8, "column"), ("local", 0.8, "row")],
        "coarse": [("global", 0.8, None), ("local", 0.8, "row"), ("local", 0.8, "column")]}


def main() -> int:
    import case_study
    import test_case_study_stage as small

    from pyfem import local_stepping, solver
    from pyfem.scene import load_scene

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "runs" / "lts_small_case3")
    parser.add_argument("--duration", type=float, default=1.5)
    parser.add_argument("--model", choices=sorted(RUNS), default="small")
    args = parser.parse_args()

    def scene_of(overrides):
        if args.model == "small":
            return small.small_case3(overrides)
        return load_scene(ROOT / "workflows" / "scenes" / "case3_contact_coarse.toml", overrides)

    args.out.mkdir(parents=True, exist_ok=True)
    chosen = local_stepping.row_split
    reference = None
    print("| run | u at A-D vs reference | largest pair monitor slip (cm) | yielded rock (m^3) | damaged lining (m^3) "
          "| energy balance | wall s | loop s per simulated s | speed |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    global_rate = None
    for scheme, safety, split in RUNS[args.model]:
        local_stepping.row_split = (lambda *_: split == "row") if split else chosen
        scene = scene_of([f"time.duration={args.duration}", "output.xdmf_interval=0.0", f"time.safety={safety}",
                          f"time.local_stepping={'true' if scheme == 'local' else 'false'}"])
        out = args.out / f"{scheme}_{safety:g}{'_' + split if split else ''}"
        started = time.perf_counter()
        done = out / "run.json"
        summary = json.loads(done.read_text()) if done.exists() else {}
        if summary.get("status") == "finished":  # read, not run again
            wall = float("nan")
        else:
            summary = solver.run(scene, out)
            wall = time.perf_counter() - started
        if scheme == "local":
            assert summary["dt_reason"].endswith(f"the {split} split"), summary["dt_reason"]
        u = {name: case_study.displacement(case_study.read_csv(out / "monitors" / f"{name}.csv"))
             for name in ("A", "B", "C", "D")}
        if reference is None:
            reference, difference = u, "-"
        else:
            difference = ", ".join(f"{np.abs(u[k] - reference[k]).max() / np.abs(reference[k]).max():.2%}"
                                   for k in u)
        regions = summary["nonlinear_regions"]
        yielded = sum(r["yielded_volume"] for name, r in regions.items() if name != "lining")
        slip = max((p.get("max_slip", 0.0) for p in summary.get("pairs", {}).values()), default=float("nan"))
        rate = summary["loop_seconds"] / summary["time_reached"]  # the time loop, the stage not counted
        if scheme == "global" and safety == 0.8:
            global_rate = rate
        print(f"| {scheme} {safety:g}{' ' + split + ' split' if split else ''} | {difference} | {100 * slip:.3f} | "
              f"{yielded:,.0f} | {regions['lining'].get('damaged_volume', float('nan')):,.0f} | "
              f"{summary['energy']['balance_error']:.1e} | {wall:.0f} | {rate:.1f} | "
              f"{global_rate / rate if global_rate else float('nan'):.2f}x |", flush=True)
    local_stepping.row_split = chosen
    return 0


if __name__ == "__main__":
    sys.exit(main())

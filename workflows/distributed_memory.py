"""Memory and time of the distributed model against the whole model (issue 13, docs/scaling.md
"The distributed model"): one elastic scene, the same command line, `[parallel] model = "whole"`
(every rank builds the whole model) and `"distributed"` (each rank builds its part of dolfinx's
distributed mesh), on 1 and 2 ranks x 1 thread, one after the other in this run.

Per configuration: each rank's peak resident memory (run.json's peak_memory_mib; for the whole
model on one rank the process's), the set-up (wall time before the time loop: mesh, assembly, the
time step, the input forces), the time loop per step, and the largest history difference from the
whole model's one-rank run (relative to each quantity's largest value).

    /usr/bin/python3 workflows/distributed_memory.py [--quick | --large | --contact | --case3 | --case3-lts]

writes workflows/results/distributed_memory.json and prints the README's markdown table. The
default scene is the free-field box refined to h = 2.5 m in a 160 x 80 x 160 m block (139 425
nodes, 418 275 dofs: the paper-scale case 3 has 497 610), 0.05 s; --quick: h = 5 m (20 k dofs);
--large: the distributed model alone on 2 ranks, a 320 x 160 x 320 m block of h = 2.5 m (1 081 665
nodes, 3 244 995 dofs, 0.02 s; the whole model would need about 3.3 KB per dof on each rank, more than
this machine's 24 GiB for 2 ranks), its row added to the results file as "large"; --contact: the
four configurations on the contact scene (tests/scenes/mpi_hard_contact.toml: soft rock, a thin stiff
layer, both interfaces in contact with deterioration, oblique SV) as a 160 x 80 x 160 m block of
h = 2.5 m (4 290 pairs, 437 580 dofs, 0.2 s), added as "contact"; --case3: the coarse case 3 as the
case study runs it (workflows/scenes/case3_contact_coarse.toml: the static stage, Mohr-Coulomb rock,
the lining's damage, 11 520 pairs, 175 056 dofs), 0.3 s of it without local stepping (not built on
the distributed model), the whole and the distributed model on 2 ranks, added as "case3" with each
run's static stage time and the distributed run's time per step by phase; --case3-lts: the same with
local time stepping on (both models step the whole model's levels by the row split), added as
"case3_lts".
Run it on a quiet machine: the ranks share the same 2 cores and memory bus.
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from pyfem.compare import largest_difference  # noqa: E402

PYTHON = "/usr/bin/python3"
RESULTS = REPO / "workflows" / "results" / "distributed_memory.json"
SCENE = "workflows/scenes/box_vertical_sv.toml"
# A block of rock 160 x 80 x 160 m under the vertical SV pulse, monitors inside cells.
SETTINGS = ["mesh.size=[160.0, 80.0, 160.0]", "wave.surface=210.0", "time.duration=0.05", "output.xdmf_interval=0.0",
            "monitor.0.point=[81.25, 41.25, 81.25]", "monitor.1.point=[81.25, 41.25, 158.75]",
            "monitor.2.point=[81.25, 41.25, 21.25]", "output.interval=0.005"]


LARGE = ["mesh.size=[320.0, 160.0, 320.0]", "wave.surface=370.0", "time.duration=0.02",
         "output.xdmf_interval=0.0", "monitor.0.point=[161.25, 81.25, 161.25]",
         "monitor.1.point=[161.25, 81.25, 318.75]", "monitor.2.point=[161.25, 81.25, 21.25]",
         "output.interval=0.005"]


CONTACT_SCENE = "tests/scenes/mpi_hard_contact.toml"
CONTACT = ["mesh.size=[160.0, 80.0, 160.0]",
           "mesh.layers=[{material = \"soft\", thickness = 79.5}, {material = \"stiff\", thickness = 1.0}, "
           "{material = \"soft\", thickness = 79.5}]",
           "wave.surface=165.0", "initial_stress.surface=165.0", "time.duration=0.2", "output.xdmf_interval=0.0",
           "monitor.0.point=[80.0, 40.0, 80.0]", "pair_monitor.0.point=[80.0, 40.0, 80.5]",
           "pair_monitor.1.point=[80.0, 40.0, 79.5]", "output.interval=0.005"]


CASE3_SCENE = "workflows/scenes/case3_contact_coarse.toml"
CASE3 = ["time.duration=0.3", "time.local_stepping=false", "output.xdmf_interval=0.0"]
CASE3_LTS = ["time.duration=0.3", "time.local_stepping=true", "output.xdmf_interval=0.0"]


def run(ranks: int, model: str, h: float | None, out: Path, settings: list = SETTINGS, scene: str = SCENE) -> dict:
    """One run's row; h: mesh.h (None: the scene's builder sets it)."""
    command = [PYTHON, "-m", "pyfem", "run", scene, "--out", str(out), "--set", f"parallel.model={model}"]
    if h is not None:
        command += ["--set", f"mesh.h={h}"]
    for setting in settings:
        command += ["--set", setting]
    if ranks > 1:
        command = ["mpirun", "--allow-run-as-root", "-q", "--bind-to", "none", "-n", str(ranks)] + command
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    began = time.perf_counter()
    result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{result.stderr[-3000:]}")
    wall = time.perf_counter() - began
    summary = json.loads((out / "run.json").read_text())
    mpi = summary.get("mpi") or {}
    peaks = mpi.get("peak_memory_mib") or [summary["peak_memory_mib"]]
    loop = summary["loop_seconds"]
    return {"ranks": ranks, "model": model, "dofs": summary["dofs"], "steps": summary["steps"],
            "peak_memory_mib": [round(p) for p in peaks], "command_seconds": round(wall, 1),
            "setup_seconds": round(summary["wall_seconds"] - loop, 1),
            "ms_per_step": round(1e3 * loop / summary["steps"], 2),
            "owned_nodes": mpi.get("owned_nodes"), "ghost_nodes": mpi.get("ghost_nodes"),
            **({"static_stage_seconds": round(summary["static"]["seconds"], 1)} if "static" in summary else {}),
            **({"ms_per_step_by_phase": {name: round(entry["ms_per_step"], 2)
                                         for name, entry in summary["time_per_step"].items()}}
               if "time_per_step" in summary else {})}


def main(argv: list) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="h = 5 m (20 k dofs)")
    parser.add_argument("--large", action="store_true", help="3.2 M dofs, the distributed model on 2 ranks only")
    parser.add_argument("--contact", action="store_true", help="the contact scene, 4 290 pairs")
    parser.add_argument("--case3", action="store_true", help="the coarse case 3 with its static stage, 2 ranks")
    parser.add_argument("--case3-lts", action="store_true", help="the same with local time stepping")
    args = parser.parse_args(argv)
    if args.case3 or args.case3_lts:
        settings, key = (CASE3_LTS, "case3_lts") if args.case3_lts else (CASE3, "case3")
        rows = []
        with tempfile.TemporaryDirectory() as scratch:
            base = Path(scratch)
            for model in ("whole", "distributed"):
                rows.append(run(2, model, None, base / model, settings, CASE3_SCENE))
                rows[-1]["difference_from_whole_one_rank"] = (  # (here: from the whole model on 2 ranks)
                    0.0 if model == "whole" else largest_difference(base / model, base / "whole"))
                print(json.dumps(rows[-1]), flush=True)
        result = json.loads(RESULTS.read_text())
        result[key] = {"date": time.strftime("%Y-%m-%d"), "scene": CASE3_SCENE, "settings": settings, "rows": rows,
                       "difference": "from the whole model on 2 ranks"}
        RESULTS.write_text(json.dumps(result, indent=1) + "\n")
        print_table(rows)
        return 0
    if args.contact:
        rows = compare_models(2.5, CONTACT, CONTACT_SCENE)
        result = json.loads(RESULTS.read_text())
        result["contact"] = {"date": time.strftime("%Y-%m-%d"), "scene": CONTACT_SCENE,
                             "settings": ["mesh.h=2.5"] + CONTACT, "rows": rows}
        RESULTS.write_text(json.dumps(result, indent=1) + "\n")
        print_table(rows)
        return 0
    if args.large:
        with tempfile.TemporaryDirectory() as scratch:
            row = run(2, "distributed", 2.5, Path(scratch) / "large", LARGE)
        row["wall_seconds_set_up_included"] = row.pop("command_seconds")
        print(json.dumps(row), flush=True)
        result = json.loads(RESULTS.read_text())
        result["large"] = dict(row, date=time.strftime("%Y-%m-%d"), settings=["mesh.h=2.5"] + LARGE)
        RESULTS.write_text(json.dumps(result, indent=1) + "\n")
        return 0
    h = 5.0 if args.quick else 2.5
    rows = compare_models(h, SETTINGS, SCENE)
    result = {"date": time.strftime("%Y-%m-%d"), "machine": f"{platform.node()}, {os.cpu_count()} cores",
              "scene": SCENE, "settings": [f"mesh.h={h}"] + SETTINGS, "rows": rows}
    if not args.quick:
        RESULTS.write_text(json.dumps(result, indent=1) + "\n")
    print_table(rows)
    return 0


def compare_models(h: float, settings: list, scene: str) -> list[dict]:
    """The whole and the distributed model on 1 and 2 ranks, one after the other."""
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        base = Path(scratch)
        for ranks, model in ((1, "whole"), (1, "distributed"), (2, "whole"), (2, "distributed")):
            out = base / f"{model}_{ranks}"
            rows.append(run(ranks, model, h, out, settings, scene))
            rows[-1]["difference_from_whole_one_rank"] = (0.0 if not rows[:-1] else
                                                          largest_difference(out, base / "whole_1"))
            print(json.dumps(rows[-1]), flush=True)
    return rows


def print_table(rows: list[dict]) -> None:
    print("| model | ranks | peak memory per rank (MiB) | set-up (s) | time loop (ms/step) | difference |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        print(f"| {row['model']} | {row['ranks']} | {' / '.join(map(str, row['peak_memory_mib']))} | "
              f"{row['setup_seconds']} | {row['ms_per_step']} | {row['difference_from_whole_one_rank']:.1e} |")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

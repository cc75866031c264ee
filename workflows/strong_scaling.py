"""Strong scaling on this machine (issue 13): one scene, the same command, on 1 rank x 1 thread,
1 rank x 2 threads and 2 ranks x 1 thread (`mpirun -n 2`), one after the other in this run.

Per configuration: the time loop's wall time per step (run.json loop_seconds / steps; the model
build is left out; docs/scaling.md) and its split, with
the ghost exchange and the per-sample merge on rank 0 (`exchange`, `merge`), and the bytes each rank
sends per step; for a scene with a static stage solved by relaxation, the stage's wall time and its
relaxation steps (the ranks share them since 2026-11-28, like the time loop's). The histories of the
2-rank run are compared with the 1-rank run's (largest difference relative to each quantity's
largest value).

    /usr/bin/python3 workflows/strong_scaling.py [--quick]

writes workflows/results/strong_scaling.json and prints the README's markdown table. --quick: the
box only (about a minute); --case TEXT: only the cases whose title contains TEXT, their rows replacing
those of the same cases in the results file (the others kept). Run it on a quiet machine: ranks and
threads share the same 2 cores.
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
RESULTS = REPO / "workflows" / "results" / "strong_scaling.json"

CASES = {
    "free-field box, 47 k dofs (Q1, h = 2 m, 0.6 s)": (
        "workflows/scenes/box_vertical_sv.toml", ["mesh.h=2.0", "output.xdmf_interval=0.0"]),
    "case 3 coarse, all physics (static stage, contact, damage; 0.1 s)": (
        "workflows/scenes/case3_contact_coarse.toml", ["time.duration=0.1", "output.xdmf_interval=0.0"]),
    # The same under local time stepping (on the ranks since 2026-11-28: one velocity exchange per
    # level and drift); "auto" would step a 0.1 s run globally, so it is forced on.
    "case 3 coarse, all physics, local time stepping (0.1 s)": (
        "workflows/scenes/case3_contact_coarse.toml", ["time.duration=0.1", "output.xdmf_interval=0.0",
                                                       "time.local_stepping=true"]),
}
CONFIGURATIONS = ((1, 1), (1, 2), (2, 1))  # (ranks, threads per rank)


def run(scene: str, sets: list, ranks: int, threads: int, out: Path) -> dict:
    command = [PYTHON, "-m", "pyfem", "run", scene, "--out", str(out)]
    for item in sets:
        command += ["--set", item]
    if ranks > 1:
        command = ["mpirun", "--allow-run-as-root", "--bind-to", "none", "-n", str(ranks)] + command
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), PYTHONPATH=str(REPO))
    began = time.perf_counter()
    result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{result.stderr[-2000:]}")
    summary = json.loads((out / "run.json").read_text())
    summary["command_seconds"] = time.perf_counter() - began
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the box only")
    parser.add_argument("--case", help="only the cases whose title contains this text (the file's other rows kept)")
    args = parser.parse_args()
    cases = dict(list(CASES.items())[:1]) if args.quick else CASES
    if args.case:
        cases = {title: case for title, case in CASES.items() if args.case in title}
        if not cases:
            raise SystemExit(f"--case {args.case!r}: no case title contains it; the cases: {', '.join(CASES)}")
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for title, (scene, sets) in cases.items():
            reference = None
            for ranks, threads in CONFIGURATIONS:
                out = Path(scratch) / f"{len(rows)}"
                summary = run(scene, sets, ranks, threads, out)
                phases = summary.get("time_per_step", {})
                row = {"case": title, "ranks": ranks, "threads": threads, "dofs": summary["dofs"],
                       "steps": summary["steps"], "ms_per_step": 1e3 * summary["loop_seconds"] / summary["steps"],
                       "phases_ms": {key: round(value["ms_per_step"], 4) for key, value in phases.items()},
                       "mpi": summary.get("mpi"), "command_seconds": round(summary["command_seconds"], 1),
                       "peak_memory_mib": summary.get("peak_memory_mib")}
                stages = (summary.get("static") or {}).get("stages", [])
                if any(stage["solver"].startswith("dynamic relaxation") for stage in stages):
                    row["stage_seconds"] = round(sum(stage["seconds"] for stage in stages), 1)
                    row["stage_steps"] = sum(stage["iterations"] for stage in stages)
                if reference is None:
                    reference = out
                    base, base_stage = row["ms_per_step"], row.get("stage_seconds")
                else:
                    row["difference_from_one_rank_one_thread"] = largest_difference(out, reference)
                row["speed_up"] = base / row["ms_per_step"]
                if "stage_seconds" in row:
                    row["stage_speed_up"] = base_stage / row["stage_seconds"]
                rows.append(row)
                stage_words = (f"; static stage {row['stage_seconds']} s for {row['stage_steps']} relaxation steps "
                               f"(x{row['stage_speed_up']:.2f})" if "stage_seconds" in row else "")
                print(f"{title}: {ranks} rank(s) x {threads} thread(s): {row['ms_per_step']:.3f} ms/step "
                      f"(x{row['speed_up']:.2f}), phases {row['phases_ms']}{stage_words}", flush=True)
    for row in rows:
        row["date"] = time.strftime("%Y-%m-%d")
    if args.case and RESULTS.exists():  # the other cases' rows as they were measured
        kept = [row for row in json.loads(RESULTS.read_text())["rows"] if row["case"] not in cases]
        rows = [row for row in kept] + rows
        rows.sort(key=lambda row: list(CASES).index(row["case"]) if row["case"] in CASES else len(CASES))
    record = {"date": time.strftime("%Y-%m-%d"), "machine": f"{platform.machine()}, {os.cpu_count()} cores",
              "rows": rows}
    RESULTS.write_text(json.dumps(record, indent=1) + "\n")
    print("\n| case | ranks x threads | ms per step | speed-up | exchange ms | merge ms | bytes/rank/step "
          "| static stage s (speed-up) |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        mpi = row["mpi"] or {}
        stage = f"{row['stage_seconds']} ({row['stage_speed_up']:.2f})" if "stage_seconds" in row else ""
        print(f"| {row['case']} | {row['ranks']} x {row['threads']} | {row['ms_per_step']:.2f} | "
              f"{row['speed_up']:.2f} | {row['phases_ms'].get('exchange', 0.0):.3f} | "
              f"{row['phases_ms'].get('merge', 0.0):.3f} | {max(mpi.get('bytes_sent_per_step', [0])):,} | {stage} |")
    print(f"\nwritten {RESULTS.relative_to(REPO)}")


if __name__ == "__main__":
    main()

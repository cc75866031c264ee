"""What rock bolts add to a step of the coarse case 3 (docs/method.md "Rock bolts and cables", cost).

The coarse case 3 (workflows/scenes/case3_contact_coarse.toml: 43 904 Q1 cells, interlayer contact
pairs, plasticity in a 12.5 m zone, the lining's damage law, oblique P + SV input) with a bolt
pattern on the excavation's rock face (`cavern_surface`): fully grouted 32 mm bolts, 9 m at
1.5 m x 1.5 m, cut into segments of `--segments` m (0: the default, about the cells' node spacing).
The model is built once in this process (pyfem.distributed_model.model_in_memory, one rank; the
static stage is not solved: the cost of a step does not depend on it); the same bolts are cut at
each segment length. The model's steppers without bolts and with each cut (the same model,
operators and time step; fresh components and pairs, from rest, as `pyfem check` measures a step)
run `--steps` steps each, one after the other in every one of `--repeats` rounds, on one kernel
thread (the machine's load changes between minutes: compare within a round). Prints the ms per
step (the fastest round, and the median over the rounds of each cut's ratio to the run without
bolts of its round) and the kernel's phases (the bolts run in the element loop's phase), then the
bolts timed alone: compute(), the gather and spread through the host cells, commit().

    /usr/bin/python3 workflows/support_cost.py [--segments 1.0 0] [--steps 30] [--repeats 6] [--out cost.json]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SCENE = ROOT / "workflows" / "scenes" / "case3_contact_coarse.toml"
PATTERN = {  # [support.walls]: a powerhouse's systematic bolting
    "surface": '"cavern_surface"', "spacing": "[1.5, 1.5]", "length": "9.0", "diameter": "0.032",
    "yield_force": "3.2e5",        # 32 mm, 400 MPa steel: 804 mm^2 x 400 MPa
    "bond_stiffness": "1.0e9", "bond_strength": "4.0e5",
}


def measure(model, groups: list, steps: int) -> tuple[dict, np.ndarray]:
    """ms per step and the kernel's phases of `steps` steps from rest of a fresh stepper of the model
    in memory with the groups (fresh components: the element loop's, the pairs', the bolts'); the
    rock's u at the end."""
    from pyfem.clock import phase_split
    from pyfem.distributed_support import rank_groups

    part = model.part
    part.support = rank_groups([group.fresh() for group in groups], part.ownership, part.comm.rank, part.local_nodes)
    if model.loop is not None:
        model.loop.counted.new_components()
    stepper, _ = model.stepper()  # (its pairs made afresh from the contact arrays: no stage)
    n = 3 * part.n_local
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    start = time.perf_counter()
    stepper.run(u, v, a, steps, 0.0)
    seconds = time.perf_counter() - start
    phases = phase_split(stepper.phase_seconds(), seconds)
    return {"ms_per_step": 1e3 * seconds / steps,
            "phases": {name: round(entry["ms_per_step"], 3) for name, entry in phases.items()}}, u


def alone_ms(group, u: np.ndarray, calls: int) -> dict:
    """The group's bolts alone at the rock's u (ms, the fastest of `calls`): compute() (the gather of
    the rock's axial displacement at the bolt nodes from their host cells' nodes, each bolt's Newton
    solve, the spread of the bond forces back and the energies), the same with one host node per
    bolt node instead of the cell's k (weight 1: the gather and spread take the difference times
    k / (k - 1)), and commit(); the Newton iterations per bolt."""
    from pyfem import _kernels

    component = group.fresh().component
    bolts = group.bolts
    one_host = _kernels.GroutedBolts(bolts.bolt_offsets, bolts.arc_length, bolts.directions,
                                     np.ascontiguousarray(bolts.host_nodes[:, :1]),
                                     np.ones((len(bolts.arc_length), 1)), **bolts.parameters)
    force = np.zeros_like(u)
    best = {"compute": np.inf, "compute_one_host": np.inf, "commit": np.inf}
    for _ in range(calls):
        for name, bars in (("compute", component), ("compute_one_host", one_host)):
            start = time.perf_counter()
            bars.compute(u, force)
            best[name] = min(best[name], time.perf_counter() - start)
        start = time.perf_counter()
        component.commit()
        best["commit"] = min(best["commit"], time.perf_counter() - start)
    k = bolts.host_nodes.shape[1]
    result = {name: 1e3 * value for name, value in best.items()}
    result["gather_and_spread"] = (result["compute"] - result["compute_one_host"]) * k / (k - 1)
    result["newton_iterations_per_bolt"] = component.last_iterations / component.n_bolts
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--segments", type=float, nargs="+", default=[1.0, 0.0],
                        help="element lengths along a bolt (m); 0: the default (about the cells' node spacing)")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=6)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=pathlib.Path, default=None)
    args = parser.parse_args(argv)

    from pyfem import _kernels
    from pyfem.distributed_model import model_in_memory
    from pyfem.scene import load_scene
    from pyfem.support import _default_segment, bolt_group

    _kernels.set_num_threads(args.threads)
    start = time.perf_counter()
    scene = load_scene(SCENE, [f"support.walls.{key}={value}" for key, value in PATTERN.items()]
                       + ["time.local_stepping=false"])  # (global steps, as measured: a step's cost)
    simulation = model_in_memory(scene, solve_stage=False)
    _kernels.set_num_threads(args.threads)
    assert simulation.comm.size == 1, "one rank: the model in memory is the whole model"
    placed = simulation.part.support[0].group
    model = simulation.part.model
    n_dofs = 3 * simulation.part.n_local
    print(f"built in {time.perf_counter() - start:.0f} s: {model.n_cells} cells, {n_dofs} "
          f"dofs, {placed.component.n_bolts} bolts, {placed.total_length:.0f} m; dt = {simulation.time_step.dt:.4g} s",
          flush=True)
    variants = {"without": []}
    for segment in args.segments:
        length = segment or _default_segment(model, placed.lines, scene["mesh"]["order"])
        parameters = placed.bolts.parameters
        bolts = bolt_group(model, placed.lines, diameter=0.032, E=placed.settings["E"],
                           yield_force=parameters["yield_force"], bond_stiffness=parameters["bond_stiffness"],
                           bond_strength=parameters["bond_strength"], segment=length)
        label = f"segment {length:.3g} m" + (" (default)" if not segment else "")
        variants[label] = [dataclasses.replace(placed, segment=length, bolts=bolts)]
        print(f"{label}: {bolts.component.n_segments} segments, {bolts.component.n_bolt_nodes} bolt nodes", flush=True)
    runs = {label: [] for label in variants}
    last_u = None
    for repeat in range(args.repeats):
        for label, groups in variants.items():
            result, last_u = measure(simulation, groups, args.steps)
            runs[label].append(result)
            print(f"round {repeat}: {label:26s} {result['ms_per_step']:8.2f} ms/step {result['phases']}", flush=True)
    base = runs["without"]
    report = {"scene": str(SCENE.relative_to(ROOT)), "pattern": PATTERN, "threads": args.threads,
              "steps": args.steps, "repeats": args.repeats, "bolts": int(placed.component.n_bolts),
              "total_length_m": placed.total_length, "cells": int(model.n_cells),
              "dofs": int(n_dofs), "runs": runs, "variants": {}}
    fastest = min(r["ms_per_step"] for r in base)
    print(f"without bolts: fastest round {fastest:.2f} ms/step, median {np.median([r['ms_per_step'] for r in base]):.2f}")
    for label, groups in variants.items():
        if label == "without":
            continue
        ratios = [w["ms_per_step"] / o["ms_per_step"] for w, o in zip(runs[label], base)]
        alone = alone_ms(groups[0], last_u, 3 * args.steps)
        entry = {"segments": int(groups[0].component.n_segments), "fastest_ms_per_step": min(r["ms_per_step"] for r in runs[label]),
                 "added_median": float(np.median(ratios)) - 1.0, "added_range": [min(ratios) - 1.0, max(ratios) - 1.0],
                 "alone_ms": alone}
        report["variants"][label] = entry
        print(f"{label}: fastest round {entry['fastest_ms_per_step']:.2f} ms/step; added to the round's step without "
              f"bolts: median +{100.0 * entry['added_median']:.1f} % (rounds +{100.0 * min(ratios) - 100.0:.1f} to "
              f"+{100.0 * max(ratios) - 100.0:.1f} %); the bolts alone (fastest of {3 * args.steps}): compute() "
              f"{alone['compute']:.2f} ms ({100.0 * alone['compute'] / fastest:.1f} % of the fastest step without "
              f"bolts), of which the gather and spread through the host cells ~{alone['gather_and_spread']:.2f} ms; "
              f"commit() {alone['commit']:.2f} ms; {alone['newton_iterations_per_bolt']:.2f} Newton iterations per "
              "bolt", flush=True)
    if args.out is not None:
        args.out.write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

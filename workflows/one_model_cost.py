"""The one-model port's cost (issue 47): seconds per step of the serial path's stepper against the
distributed model's on one rank, built from one scene in one process, from rest, in alternating pairs
(so a drift of the machine's speed hits both), and the ratio distributed / serial per pair.

    OMP_NUM_THREADS=1 /usr/bin/python3 workflows/one_model_cost.py workflows/scenes/default.toml --steps 300
    OMP_NUM_THREADS=1 /usr/bin/python3 workflows/one_model_cost.py workflows/scenes/case3_contact_coarse.toml --steps 40

Prints one line per pair and the median ratio; `--out FILE` appends them (workflows/results/one_model_cost.txt).
The static stage is not solved (both steppers start from rest with fresh components: the elastic
element loop, contact, input and local stepping where the scene turns them on)."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def seconds_per_step(stepper, n: int, steps: int, warm: int) -> float:
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    stepper.run(u, v, a, warm, 0.0)
    began = time.perf_counter()
    stepper.run(u, v, a, steps, 0.0)
    return (time.perf_counter() - began) / steps


def main() -> int:
    from mpi4py import MPI

    from pyfem import distributed_model, solver
    from pyfem.effects import kernel_threads
    from pyfem.scene import load_scene

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", type=Path)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--pairs", type=int, default=7)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    scene = load_scene(args.scene)
    kernel_threads()
    simulation = solver.prepare(scene, solve_static=False)
    serial = solver.make_stepper(simulation)
    run = distributed_model.DistributedRun(scene, Path("one_model_cost_unused"), MPI.COMM_WORLD)
    distributed, _ = run.stepper(check_stability=False)
    ratio = 1 if run.lts is None else run.lts.ratio  # whole global steps under local stepping
    steps = ratio * max(1, -(-args.steps // ratio))
    n_serial, n_distributed = simulation.stiffness.shape[0], 3 * run.part.n_local
    lines = [f"{args.scene} ({n_serial} dofs, {steps} steps per timing, local stepping "
             f"{'on' if run.lts is not None else 'off'})"]
    ratios = []
    for _ in range(args.pairs):
        a = seconds_per_step(serial, n_serial, steps, ratio)
        b = seconds_per_step(distributed, n_distributed, steps, ratio)
        ratios.append(b / a)
        lines.append(f"  serial {a * 1e3:.3f} ms  distributed {b * 1e3:.3f} ms  ratio {b / a:.3f}")
    lines.append(f"  median ratio {np.median(ratios):.3f} (min {min(ratios):.3f}, max {max(ratios):.3f})")
    print("\n".join(lines))
    if args.out:
        with open(args.out, "a") as file:
            file.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

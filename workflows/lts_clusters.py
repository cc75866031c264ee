"""What local time stepping would buy on the case study's meshes: the rate clusters of cells and
the work they leave (docs/lts_plan.md). A measurement of the mesh, not of an LTS run. Local time
stepping itself is implemented (`[time] local_stepping`: pyfem/local_stepping.py and the kernel's
LocalStepper); this script is the early cluster estimate, by cells, that preceded it, and its levels
are not the ones the program uses (those are `pyfem.local_stepping`'s, by the row split).

Per node i, the Gershgorin bound of M^-1 K gives a stable step dt_i = 2 / sqrt(max row sum of
|K| / m_i) (K the full elastic stiffness, every cell in it). A cell may step at
dt_min 2^k_c with k_c = floor(log2(min over its nodes of dt_i / dt_min)), capped at --max-level;
a node steps at the finest rate of its cells (so every coarse cell next to a fine one is stepped
at the fine rate: the one-cell overlap of Diaz & Grote's scheme). Work per simulated second of a
part relative to global stepping is the mean of 2^-k over its nodes or cells.

Usage: /usr/bin/python3 workflows/lts_clusters.py [--preset coarse|paper] [--max-level 5]
"""
import argparse
import json
import pathlib
import sys

import numpy as np

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))


def node_stable_steps(stiffness, mass: np.ndarray) -> np.ndarray:
    """dt_i = 2 / sqrt(lambda_i), lambda_i the largest Gershgorin row sum of M^-1 K over node i's dofs."""
    csr = stiffness.tocsr()
    row_sums = np.asarray(abs(csr).sum(axis=1)).ravel().reshape(-1, 3).max(axis=1)
    return 2.0 / np.sqrt(row_sums / mass)


def clusters(cell_nodes: np.ndarray, dt_node: np.ndarray, max_level: int):
    """(cell levels k_c, node levels k_i): k = 0 the finest rate, k the rate dt_min 2^k."""
    dt_min = dt_node.min()
    cell_dt = dt_node[cell_nodes].min(axis=1)
    cell_level = np.minimum(np.floor(np.log2(cell_dt / dt_min) + 1e-12).astype(int), max_level)
    node_level = np.full(len(dt_node), max_level, dtype=int)
    np.minimum.at(node_level, cell_nodes.ravel(), np.repeat(cell_level, cell_nodes.shape[1]))
    return cell_level, node_level


def analyse(preset: str, max_level: int) -> dict:
    from pyfem import solver
    from pyfem.scene import load_scene

    scene = load_scene(REPOSITORY / "workflows" / "scenes" / f"case3_contact_{preset}.toml")
    simulation = solver.prepare(scene, solve_static=False)
    model = simulation.model
    mass = np.asarray(simulation.mass)
    dt_node = node_stable_steps(model.stiffness, mass)
    cell_nodes = model.V.dofmap.list.array.reshape(model.n_cells, -1)
    cell_level, node_level = clusters(cell_nodes, dt_node, max_level)
    rate = lambda levels: float(np.mean(2.0 ** -np.asarray(levels, dtype=float))) if len(levels) else 1.0
    nonlinear_cells = np.concatenate([arrays.cells for arrays in simulation.nonlinear.arrays.values()]) \
        if simulation.nonlinear is not None else np.zeros(0, dtype=int)
    points_per_cell = {name: arrays.weights.shape[1] for name, arrays in simulation.nonlinear.arrays.items()} \
        if simulation.nonlinear is not None else {}
    pair_nodes = np.unique(simulation.contact_arrays["pairs"]) if simulation.contact_arrays else np.zeros(0, int)
    boundary_nodes = np.unique(simulation.dashpot_nodes)
    # Measured time per step by phase (the plan's trial steps, from rest).
    stepper = solver.make_stepper(simulation)
    from pyfem.bench import stepper_seconds_per_step

    n = simulation.stiffness.shape[0]
    stepper_seconds_per_step(stepper, n, 2, amplitude=1.0e-9)
    stepper.reset_phase_seconds()
    import time

    rng = np.random.default_rng(0)
    u, v, a = 1.0e-9 * rng.standard_normal(n), np.zeros(n), np.zeros(n)
    start = time.perf_counter()
    steps = 20
    stepper.run(u, v, a, steps, 0.0)
    seconds = time.perf_counter() - start
    phases = {name: entry["ms_per_step"] for name, entry in
              solver.phase_split(stepper.phase_seconds(), seconds).items()}
    f_nodes = rate(node_level)
    f_nonlinear = rate(cell_level[nonlinear_cells])
    f_pairs = rate(node_level[pair_nodes])
    f_boundary = rate(node_level[boundary_nodes])
    per_node = phases["update"] + phases["stiffness"] + phases.get("other", 0.0)
    global_ms = sum(phases.values())
    elastic_global = per_node + phases["input_forces"] + phases["contact"]
    scenarios = {
        "elastic model (no element loop), pairs at their own rate": (
            elastic_global, per_node * f_nodes + phases["input_forces"] * f_boundary + phases["contact"] * f_pairs),
        "all physics, nonlinear cells and pairs at their own rate": (
            global_ms, per_node * f_nodes + phases["input_forces"] * f_boundary + phases["contact"] * f_pairs
            + phases["element_loop"] * f_nonlinear),
        "all physics, nonlinear cells and pairs in the finest cluster": (
            global_ms, per_node * f_nodes + phases["input_forces"] * f_boundary + phases["contact"]
            + phases["element_loop"]),
    }
    histogram = {int(k): {"cells": int(np.count_nonzero(cell_level == k)),
                          "nodes": int(np.count_nonzero(node_level == k)),
                          "nonlinear cells": int(np.count_nonzero(cell_level[nonlinear_cells] == k))}
                 for k in range(max_level + 1)}
    return {"preset": preset, "dofs": n, "cells": int(model.n_cells), "max_level": max_level,
            "dt_gershgorin_min": float(dt_node.min()), "dt_critical": float(simulation.time_step.critical),
            "histogram": histogram, "rates": {"nodes": f_nodes, "nonlinear cells": f_nonlinear,
                                             "pair nodes": f_pairs, "boundary nodes": f_boundary},
            "phases_ms": phases, "points_per_cell": points_per_cell,
            "scenarios": {name: {"global_ms": g, "lts_ms": l, "fraction": l / g} for name, (g, l) in scenarios.items()}}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=("coarse", "paper"), default="coarse")
    parser.add_argument("--max-level", type=int, default=5)
    parser.add_argument("--out", default=None, help="write the result as JSON here")
    args = parser.parse_args(argv)
    result = analyse(args.preset, args.max_level)
    print(f"case 3 {args.preset}: {result['dofs']} dofs, {result['cells']} cells; Gershgorin dt_min "
          f"{result['dt_gershgorin_min']:.3e} s, the run's critical step {result['dt_critical']:.3e} s")
    print("| level k (step dt_min 2^k) | cells | nodes | nonlinear cells |\n|---:|---:|---:|---:|")
    for k, row in result["histogram"].items():
        print(f"| {k} | {row['cells']} | {row['nodes']} | {row['nonlinear cells']} |")
    print("\nwork per simulated second relative to global stepping:",
          {k: round(v, 3) for k, v in result["rates"].items()})
    print("measured ms per step (global):", {k: round(v, 2) for k, v in result["phases_ms"].items()})
    print("| scenario | global ms/step | LTS ms per global step (model) | fraction |\n|---|---:|---:|---:|")
    for name, row in result["scenarios"].items():
        print(f"| {name} | {row['global_ms']:.2f} | {row['lts_ms']:.2f} | {100 * row['fraction']:.0f} % |")
    if args.out:
        pathlib.Path(args.out).write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

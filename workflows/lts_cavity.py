"""Local time stepping on the cavity test: the hoop stress against the exact answer where rate levels meet.

The plane-strain tunnel of tests/test_cavity.py (a = 5 m, Q1, 3 rate levels under local stepping)
under a 2 Hz SV wavelet, run with global stepping (safety 0.1 and 0.8) and local stepping (safety
0.8, 0.4, 0.2). For each run: the history error of the hoop stress at the four monitors (r = 1.05 a
and 2 a, 45 and 135 deg) against Pao & Mow's exact answer, the largest displacement difference
from global stepping at safety 0.1 relative to its peak, the energy balance and the wall time.
The table of docs/local_stepping.md "The column split" (the "kicks" row is the commit before the interface
rows, 1bfd44c).

    /usr/bin/python3 workflows/lts_cavity.py [--out DIR]     # about 2 minutes on 2 cores

`--rows` runs local stepping with the kernel's row split (LocalStepper.set_row_split: nodal
subcycling, docs/local_stepping.md "The scheme: the row split") instead of its column split.

`--buffer B` moves every level boundary B node layers out (each node sharing a cell with a finer node
takes that level, B times) and runs local stepping at safety 0.8 only: docs/local_stepping.md "The
column split".
"""
from __future__ import annotations

import argparse
import pathlib
import subprocess
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

RUNS = [("global", 0.1), ("global", 0.8), ("local", 0.8), ("local", 0.4), ("local", 0.2)]


def row_split() -> None:
    """Every LocalStepper the run builds steps by the row split."""
    from pyfem import _kernels

    column_split = _kernels.LocalStepper

    def local_stepper(*args, **kwargs):
        kernel = column_split(*args, **kwargs)
        kernel.set_row_split(True)
        return kernel

    _kernels.LocalStepper = local_stepper


def buffered(layers: int) -> None:
    """Wraps pyfem.local_stepping.node_levels: `layers` times, every node takes the finest level of
    the nodes it shares a cell with."""
    from pyfem import local_stepping

    plain = local_stepping.node_levels

    def node_levels(stiffness, mass, cell_nodes, *args, **kwargs):
        levels = plain(stiffness, mass, cell_nodes, *args, **kwargs)
        for _ in range(layers):
            finest = np.repeat(levels[cell_nodes].min(axis=1), cell_nodes.shape[1]).astype(np.int32)
            levels = levels.copy()
            np.minimum.at(levels, cell_nodes.ravel(), finest)
        print(f"buffer {layers}: nodes per level, finest first {np.bincount(levels).tolist()}", flush=True)
        return levels

    local_stepping.node_levels = node_levels


def main() -> int:
    import test_cavity as cavity
    from pyfem import solver

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "runs" / "lts_cavity")
    parser.add_argument("--buffer", type=int, default=0, help="node layers added to the finer side of every "
                        "level boundary (local stepping at safety 0.8 only)")
    parser.add_argument("--rows", action="store_true", help="local stepping by the row split")
    args = parser.parse_args()
    runs = RUNS
    if args.rows:
        row_split()
    if args.buffer:
        buffered(args.buffer)
        runs = [("global", 0.1), ("local", 0.8)]
    args.out.mkdir(parents=True, exist_ok=True)
    mesh = args.out / "tunnel.msh"
    if not mesh.exists():
        subprocess.run([sys.executable, str(ROOT / "meshes" / "tunnel_in_box.py"), str(mesh), "--radius",
                        str(cavity.RADIUS)], check=True)
    reference = None
    print("| run | " + " | ".join(cavity.monitor_points()) + " | u vs global 0.1 | energy balance | wall s |")
    print("|---|" + "---:|" * (len(cavity.monitor_points()) + 3))
    for scheme, safety in runs:
        scene = cavity.tunnel_scene(mesh, 1)
        scene["time"]["safety"] = safety
        scene["time"]["local_stepping"] = scheme == "local"
        tag = (f"_buffer{args.buffer}" if args.buffer else "") + ("_rows" if args.rows else "")
        out = args.out / f"{scheme}_{safety:g}{tag if scheme == 'local' else ''}"
        started = time.perf_counter()
        summary = solver.run(scene, out)
        wall = time.perf_counter() - started
        errors, u = [], []
        for name, (r, theta, _) in cavity.monitor_points().items():
            columns = cavity.read_monitor(out, name)
            stress = np.column_stack([columns[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")])
            _, hoop, _ = cavity.polar_stress(stress, theta)
            exact = cavity.exact_hoop(scene, columns["t"], r, theta)
            errors.append(np.linalg.norm(hoop - exact) / np.linalg.norm(exact))
            u.append(np.column_stack([columns["ux"], columns["uz"]]))
        if reference is None:
            reference = u
            difference = "-"
        else:
            worst = max(np.abs(a - b).max() / np.abs(b).max() for a, b in zip(u, reference))
            difference = f"{worst:.1e}"
        print(f"| {scheme} {safety:g} | " + " | ".join(f"{e:.2%}" for e in errors)
              + f" | {difference} | {summary['energy']['balance_error']:.1e} | {wall:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The load balance of the MPI partitions (pyfem/distributed.py) on the case study's coarse model: each
rank's work in a step by the node-work model (`distributed.node_work`: matrix rows, element-loop
points, contact pairs), partitions by node count against partitions by node work, for 2 to 16 ranks.
A model of the step, not a timing: the slowest rank sets the step, so max / mean is the time the
others wait (docs/scaling.md "Weighted partitions").

Usage: /usr/bin/python3 workflows/partition_balance.py [--scene workflows/scenes/case3_contact_coarse.toml]
"""
import argparse
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem import distributed, solver  # noqa: E402
from pyfem.scene import load_scene  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=str(ROOT / "workflows" / "scenes" / "case3_contact_coarse.toml"))
    parser.add_argument("--ranks", type=int, nargs="+", default=[2, 3, 4, 8, 16])
    args = parser.parse_args(argv)
    simulation = solver.prepare(load_scene(args.scene), solve_static=False)
    work = distributed.node_work(simulation)
    print(f"{args.scene}: {len(work)} nodes, node work {work.sum():.0f} rows "
          f"({100 * (work.sum() - len(work)) / work.sum():.0f} % element loop and pairs)")
    print("| ranks | by node count: max / mean work | by node work: max / mean work |")
    print("|---:|---:|---:|")
    for size in args.ranks:
        ratios = []
        for weighted in (False, True):
            per_rank = distributed.rank_work(simulation, distributed.partition(simulation, size, weighted=weighted))
            ratios.append(per_rank.max() / per_rank.mean())
        print(f"| {size} | {ratios[0]:.3f} | {ratios[1]:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

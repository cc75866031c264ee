"""The set-up check of the local time stepping map (pyfem/local_stepping.py `check_stability`) on a
case-study scene, whole or on the MPI ranks' shares (pyfem/distributed.py `check_stability_on_ranks`):
its wall time, the energy growth it found and each rank's peak memory. The model is built without
its static stage (the check's components start without initial stress either way).

    /usr/bin/python3 workflows/lts_check_ranks.py [SCENE]                        # whole, one process
    mpirun --allow-run-as-root -n 2 /usr/bin/python3 workflows/lts_check_ranks.py [SCENE]  # on 2 ranks

SCENE defaults to workflows/scenes/case3_contact_coarse.toml; OMP_NUM_THREADS sets the threads.
"""
import json
import resource
import sys
import time

from pyfem import local_stepping, solver
from pyfem.distributed import world
from pyfem.scene import load_scene


def main(argv: list) -> int:
    path = argv[0] if argv else "workflows/scenes/case3_contact_coarse.toml"
    scene = load_scene(path, ["time.local_stepping=true"])
    comm = world()
    began = time.perf_counter()
    simulation = solver.prepare(scene, solve_static=False)
    built = time.perf_counter() - began
    stepper = solver.make_stepper(simulation)  # runs the check (once per model), then builds the run's stepper
    report = simulation.lts_stability
    peak = comm.gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, root=0)
    if comm.rank == 0:
        print(json.dumps({"scene": path, "ranks": comm.size,
                          "nodes": len(simulation.mass), "levels": int(simulation.node_levels.max()) + 1,
                          "build_seconds": round(built, 1), "check_seconds": round(report["seconds"], 1),
                          "growth": report["growth"], "stable": report["stable"],
                          "peak_mib_per_rank": [round(p) for p in peak]}))
    del stepper
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

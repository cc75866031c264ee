"""The entry of every run: `run` and `plan` hand a scene to the model (pyfem/distributed_model.py),
which builds and steps it on any number of ranks (one without mpirun).

Data flow (docs/method.md section 1): scene -> model (gmsh -> dolfinx operators on each rank's part)
-> boundary springs/dashpots and seismic input forces -> C++ stepper (many steps per call) -> outputs.
Python owns orchestration and I/O; nothing in Python runs once per time step.
"""
from __future__ import annotations

from pyfem.scene import Scene


def plan(scene: Scene) -> dict:
    """What a run of the scene would do, without running it: effects, sizes, dt, memory and time.

    The time estimate comes from timing a few kernel steps on the real matrices. A static stage is
    described, not solved; with local stepping on, the set-up check of its map is estimated, not run
    (it runs when the run starts: 35 s on the coarse case 3, 400-1 060 s on the paper-scale cases).
    """
    from pyfem import distributed_model  # rank 0's plan ({} on the others)

    return distributed_model.check(scene)


def run(scene: Scene, out_dir, on_plan=None, progress=None, resume: bool = False) -> dict:
    """Runs the scene and writes run.json, monitors/, fields.xdmf and plots/ into out_dir.

    on_plan: called with the plan (`simulation_plan`, a dict) once the model is built, before
    the run directory is touched (the command line prints it). progress: None shows a tqdm bar
    on a terminal (stderr); else an object with start(t0) and __call__(t) (pyfem.progress.
    ProgressLines), told the simulated time reached after every output interval; no bar then.
    resume: continue the interrupted or finished run in out_dir from its checkpoint (pyfem/checkpoint.py)
    to the scene's time.duration instead of starting a new one; its histories then equal an
    uninterrupted run's.

    The histories are written as the run goes; every `output.checkpoint_interval` seconds of
    wall time the whole state goes to out_dir/checkpoint.npz, and at the end the final state (kept:
    `resume` with a longer time.duration extends a finished run).
    Ctrl-C or SIGTERM stops the run between two samples: a checkpoint is written, run.json says
    "interrupted" with the time reached, every row so far is kept, and
    `pyfem.interrupts.RunInterrupted` (a KeyboardInterrupt) is raised. Any other error marks
    the run "failed" the same way (its last periodic checkpoint stays) and is raised again.

    Returns:
        The run summary (also written to run.json).
    """
    from pyfem import distributed_model  # every rank builds and steps its part; one rank: the whole model

    return distributed_model.run(scene, out_dir, on_plan=on_plan, progress=progress, resume=resume)

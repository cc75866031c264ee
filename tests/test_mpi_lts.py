"""Local time stepping on the MPI ranks (issue 13, docs/scaling.md "Local time stepping on the
ranks"): `mpirun -n N python3 -m pyfem run SCENE` with `[time] local_stepping` steps each rank's
share by the row split, the ghosts of each rate level taking their owners' velocity before each of
that level's drifts (cpp_kernels/local_stepper.hpp LocalStepper.set_partition, pyfem/distributed.py).

The user's models, with local stepping forced on (`time.local_stepping=true`):
- the tunnel of a user's gmsh script (tests/scenes/mpi_tunnel_tet.toml: tetrahedra, 0.4 m at the
  wall to 5 m in the far field, three rate levels; roller faces with reactions, viscoelastic
  boundaries, a vertical SV wavelet): 2 and 3 ranks against the serial local stepping, every history
  to test_mpi's tolerances (the cavity's net forces: NET_FORCE_TOLERANCE);
- the real case-3 scene on a small mesh (tests/test_case_study_stage.py SMALL_MODEL): the static
  stage (shared by the ranks), then 0.3 s of the record's strong part at 0.05 g with three rate
  levels, the rock yielding at its levels, pairs sliding at theirs, the lining's concrete law; the
  interfaces' wear off. 2 ranks against the serial run (3 take the tunnel's paths), to the stage test's tolerances
  (test_mpi_stage STAGE_ROUNDOFF: the stage's state is summed in another order by the ranks).
  With the wear on, the same window is not reproducible from one rank count to another, nor from
  one run to a run whose record is scaled by 1 + 2e-12: the wear slips pairs held at their limit
  and the slip cracks the lining, a softening that amplifies any difference about tenfold every
  0.02 s (docs/scaling.md "What a rank count can change"); with either the wear or the lining's
  cracking off, the ranks agree to round-off (tested here without the wear).
- kill -9 of a 2-rank run after its first checkpoint and `--resume` on 2 ranks: the histories of
  the uninterrupted 2-rank run (the checkpoint is the serial stepper's); a serial checkpoint resumed
  on 2 ranks continues to the serial run's histories.
"""
import numpy as np
import pytest

from pyfem.compare import histories, largest_differences, relative_difference, scales
from test_case_study_stage import SMALL_MODEL
from test_mpi import (MPIRUN, NET_FORCE_TOLERANCE, TOLERANCE, assert_equal_to_serial, killed_and_resumed, pyfem_run,
                      summary)
from test_mpi_stage import STAGE_ROUNDOFF

pytestmark = pytest.mark.skipif(MPIRUN is None, reason="mpirun not found: scripts/setup.sh installs openmpi-bin")

LOCAL = ("--set", "time.local_stepping=true")
TUNNEL = "tests/scenes/mpi_tunnel_tet.toml"
CASE3 = "workflows/scenes/case3_contact_coarse.toml"
# The record's strong part (El Centro from 1.8 s) at 0.05 g after a 0.05 s lead-in, the wear off.
CASE3_WINDOW = tuple(arg for setting in [*SMALL_MODEL, "time.duration=0.3", "time.local_stepping=true",
                                         "output.xdmf_interval=0.1", "wave.motion.record.window=[1.8, 4.0]",
                                         "wave.motion.record.lead_in=0.05", "wave.motion.record.pga=0.05",
                                         "contact.deterioration.R0=1.0"]
                     for arg in ("--set", setting))


def levels_of(run: dict) -> int:
    """The rate levels a run stepped (run.json's dt_reason: "... local time stepping: N rate levels")."""
    reason = run["dt_reason"]
    assert "local time stepping:" in reason, reason
    return int(reason.split("local time stepping:")[1].split("rate levels")[0])


def assert_shared(run: dict, serial: dict, ranks: int) -> None:
    mpi = run["mpi"]
    assert mpi["ranks"] == ranks and sum(mpi["owned_nodes"]) == serial["nodes"]
    assert all(n > 0 for n in mpi["ghost_nodes"]) and all(b > 0 for b in mpi["bytes_sent_per_step"])
    # The set-up check of the LTS map ran on the ranks' shares and found the serial check's growth
    # (the same map and random state; the energy summed in another order).
    checked, alone = run["local_stepping_stability"], serial["local_stepping_stability"]
    assert checked["ranks"] == ranks and "ranks" not in alone and checked["stable"]
    assert checked["global_steps"] == alone["global_steps"]
    assert checked["growth"] == pytest.approx(alone["growth"], rel=1e-9)


@pytest.fixture(scope="module")
def tunnel_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("mpi_lts_tunnel")
    runs = {ranks: base / f"tunnel_{ranks}" for ranks in (1, 2, 3)}
    for ranks, out in runs.items():
        pyfem_run(ranks, TUNNEL, out, *LOCAL)
    return runs


@pytest.mark.parametrize("ranks", [2, 3])
def test_local_stepping_on_the_ranks_equals_the_serial_local_stepping(tunnel_runs, ranks):
    serial, run = summary(tunnel_runs[1]), summary(tunnel_runs[ranks])
    assert levels_of(serial) == levels_of(run) >= 3, "the tunnel's mesh stepped at three rates or more"
    crown = serial["monitors"]["crown"]
    assert crown["displacement"] > 2e-4 and crown["s1_dynamic_max"] > 1e3, "the wave reached the wall"
    reactions = np.loadtxt(tunnel_runs[1] / "reactions.csv", delimiter=",", skiprows=1)
    assert np.abs(reactions[:, 1:]).max() > 0.0, "the rollers held"
    assert_shared(run, serial, ranks)
    worst = assert_equal_to_serial(tunnel_runs[ranks], tunnel_runs[1], NET_FORCE_TOLERANCE["cavity"])
    assert run["energy"]["balance_error"] == pytest.approx(serial["energy"]["balance_error"], rel=1e-6)
    print(f"tunnel, local stepping on {ranks} ranks: largest difference from serial {worst:.2e}; "
          f"bytes per fine step {run['mpi']['bytes_sent_per_step']}, loop {run['loop_seconds']:.2f} s "
          f"(serial {serial['loop_seconds']:.2f} s)")


@pytest.fixture(scope="module")
def case3_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("mpi_lts_case3")
    runs = {ranks: base / f"case3_{ranks}" for ranks in (1, 2)}
    for ranks, out in runs.items():
        pyfem_run(ranks, CASE3, out, *CASE3_WINDOW)
    return runs


@pytest.mark.parametrize("ranks", [2])
def test_the_case_study_scene_under_local_stepping_on_the_ranks_equals_the_serial_run(case3_runs, ranks):
    serial, run = summary(case3_runs[1]), summary(case3_runs[ranks])
    assert levels_of(serial) == levels_of(run) >= 3
    assert [stage["converged"] for stage in serial["static"]["stages"]] == [True, True]
    # Things happened in the dynamic run at their own rates: pairs slid, the rock yielded further.
    states = serial["pair_states"]
    assert states["sliding"][0] == 0 and max(states["sliding"]) >= 10
    assert serial["energy"]["internal_dissipation"] > 0.0 and serial["energy"]["friction_dissipation"] > 0.0
    assert run["pair_states"]["sliding"][-1] == states["sliding"][-1]
    assert_shared(run, serial, ranks)
    assert sum(run["mpi"]["element_loop_cells"]) == sum(region["cells"] for region in
                                                        serial["nonlinear_regions"].values())
    differences = largest_differences(case3_runs[ranks], case3_runs[1])
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, TOLERANCE), (kind, difference)
    print(f"case 3 (small), local stepping on {ranks} ranks: " +
          ", ".join(f"{kind} {value:.1e}" for kind, value in sorted(differences.items()) if value))


STABILITY_ON_RANKS = """
import json, sys
from pathlib import Path
sys.path.insert(0, "tests")
import numpy as np
from mpi4py import MPI
from pyfem import _kernels, distributed, local_stepping, solver
from pyfem.local_stepping import check_stability
from test_local_stepping import GRADED_GEO, graded_scene

local_stepping.fit_levels_to_output = lambda levels, steps_per_output: levels  # (conftest's unfitted_levels)

comm = MPI.COMM_WORLD
geo = Path(sys.argv[1])
if comm.rank == 0:
    geo.write_text(GRADED_GEO)
comm.barrier()
simulation = solver.prepare(graded_scene(geo, True))
indptr, indices, blocks = solver.bsr_arrays(simulation.stiffness)
as_set = simulation.node_levels.copy()
found = {}
# (one level coarser the energy overflows within the default 240 global steps: 60 keep it finite)
for name, levels, steps in (("as set", as_set, 240), ("one coarser", as_set + 1, 60)):
    simulation.node_levels = levels

    def alone():
        stepper = _kernels.LocalStepper(indptr, indices, blocks, simulation.mass,
                                        np.ascontiguousarray(levels, dtype=np.int32), simulation.time_step.dt, 0.0)
        stepper.set_dashpots(np.ascontiguousarray(simulation.dashpot_nodes, dtype=np.int32),
                             np.ascontiguousarray(simulation.dashpot_matrices, dtype=np.float64))
        stepper.set_row_split(True)
        return stepper

    ranks = distributed.check_stability_on_ranks(simulation, comm, steps=steps)
    found[name] = {"ranks": ranks, "serial": check_stability(alone, 3 * len(simulation.mass), steps=steps),
                   "levels": int(levels.max()) + 1}
if comm.rank == 0:
    print("REPORT " + json.dumps(found))
"""


@pytest.mark.parametrize("ranks", [2, 3])
def test_the_stability_check_on_the_ranks_is_the_serial_check_of_the_map_they_step(tmp_path, ranks):
    """check_stability_on_ranks (each rank steps its share of the LTS map from the same random
    state, the energy summed over the ranks) against the serial check of the same row-split map,
    on the graded mesh of tests/test_local_stepping.py: with its levels the map is stable and the
    growth is the serial one to round-off; with every node one rate coarser both find the same
    growth, above 1e3 (unstable), and every rank takes the verdict."""
    import json
    import subprocess

    from test_mpi import ENV, PYTHON, REPO

    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), PYTHON, "-c",
                             STABILITY_ON_RANKS, str(tmp_path / "graded.geo")],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    found = json.loads(result.stdout.split("REPORT ", 1)[1])
    good, coarse = found["as set"], found["one coarser"]
    assert good["levels"] >= 3, "the graded mesh stepped at three rates or more"
    assert good["ranks"]["ranks"] == ranks and good["ranks"]["stable"] and good["serial"]["stable"]
    assert good["ranks"]["growth"] == pytest.approx(good["serial"]["growth"], rel=1e-9)
    assert not coarse["ranks"]["stable"] and not coarse["serial"]["stable"] and coarse["ranks"]["growth"] > 1e3
    assert coarse["ranks"]["growth"] == pytest.approx(coarse["serial"]["growth"], rel=1e-6)
    print(f"{ranks} ranks: growth {good['ranks']['growth']:.6g} (serial {good['serial']['growth']:.6g}), one "
          f"level coarser {coarse['ranks']['growth']:.4g} (serial {coarse['serial']['growth']:.4g}); "
          f"{good['ranks']['seconds']:.2f} s on the ranks, {good['serial']['seconds']:.2f} s whole")


def test_kill_9_of_two_ranks_under_local_stepping_then_resume_gives_the_uninterrupted_run(tmp_path):
    out, reference, resumed = killed_and_resumed(tmp_path, ranks=2, resumed_on=2, window=1.0, name="cavity",
                                                 extra=LOCAL)
    assert levels_of(resumed) >= 3
    assert histories(out) == histories(reference)
    scale = scales(reference)
    for name in histories(reference):
        if name.name == "energy.csv":  # the account's partial sums are regrouped on resume
            assert relative_difference(out / name, reference / name, scale) < 1e-13
        else:
            assert (out / name).read_bytes() == (reference / name).read_bytes(), name


def test_a_serial_checkpoint_under_local_stepping_resumes_on_two_ranks(tmp_path):
    out, reference, resumed = killed_and_resumed(tmp_path, ranks=1, resumed_on=2, window=0.5, name="cavity",
                                                 extra=LOCAL)
    assert levels_of(resumed) >= 3
    differences = largest_differences(out, reference)
    # The cavity's net forces (NET_FORCE_TOLERANCE's reasoning) over this run's 3 s instead of the
    # 0.6 s above: measured up to 2.0e-9 (accelerations) and 1.4e-9 (the rollers' reactions).
    tolerances = dict(NET_FORCE_TOLERANCE["cavity"], acceleration=6.0e-9, reaction=6.0e-9)
    for kind, difference in differences.items():
        assert difference < tolerances.get(kind, TOLERANCE), (kind, difference)
    print(f"largest difference from the uninterrupted serial run {max(differences.values()):.2e}")

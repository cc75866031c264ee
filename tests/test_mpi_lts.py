"""Local time stepping on the MPI ranks (docs/scaling.md "Local time stepping on the distributed
model"): `mpirun -n N python3 -m pyfem run SCENE` with `[time] local_stepping` steps each rank's part
of dolfinx's mesh by the row split, the ghosts of each rate level taking their owners' velocity before
each of that level's drifts (cpp_kernels/local_stepper.hpp LocalStepper.set_partition,
pyfem/distributed_lts.py: no rank holds the whole model).

The user's models, with local stepping forced on (`time.local_stepping=true`), against the serial
local stepping:
- the tunnel of a user's gmsh script (tests/scenes/mpi_tunnel_tet.toml: tetrahedra, 0.4 m at the
  wall to 5 m in the far field, three rate levels; roller faces with reactions, viscoelastic
  boundaries, a vertical SV wavelet) on 2 and 3 ranks: the serial levels and step, every history to
  the tunnel's tolerances (its net forces: tests/test_distributed_model.py TOLERANCES);
- the real case-3 scene on a small mesh (tests/test_case_study_stage.py SMALL_MODEL): the static
  stage (on the ranks' parts), then 0.3 s of the record's strong part at 0.05 g with three rate
  levels, the rock yielding at its levels, pairs sliding at theirs, the lining's concrete law; the
  interfaces' wear off. 2 ranks, to the stage test's tolerances (test_mpi_stage STAGE_ROUNDOFF: the
  stage's state is summed in another order by the ranks). With the wear on, the same window is not
  reproducible from one rank count to another, nor from one run to a run whose record is scaled by
  1 + 2e-12: the wear slips pairs held at their limit and the slip cracks the lining, a softening
  that amplifies any difference about tenfold every 0.02 s (docs/scaling.md "What a rank count can
  change"); with either the wear or the lining's cracking off, the ranks agree to round-off;
- its levels node for node and its set-up check's verdicts (the graded mesh, 3 ranks; 2 slow);
- the small case 3 killed (kill -9) on 2 ranks and resumed on 3 (its LocalStepper's state keyed by
  position): the uninterrupted 2-rank run's histories to the stage's round-off (the resume solves the
  stage again on 3 ranks);
- `check` prints its levels, and "auto" decides as the serial run does.
"""
import numpy as np
import pytest

from pyfem.compare import largest_differences
from test_case_study_stage import NO_LEAD_IN, SMALL_MODEL
from test_mpi import MPIRUN, TOLERANCE, pyfem_run, summary
from test_mpi_stage import STAGE_ROUNDOFF
from test_distributed_model import TOLERANCES as DISTRIBUTED_TOLERANCES

# One rule for the MPI tests: a missing launcher fails (conftest.mpi_launcher), never skips.
pytestmark = pytest.mark.usefixtures("mpi_launcher")

LOCAL = ("--set", "time.local_stepping=true")
TUNNEL = "tests/scenes/mpi_tunnel_tet.toml"
CASE3 = "workflows/scenes/case3_contact_coarse.toml"
# The record's strong part (El Centro from 1.8 s) at 0.05 g after a 0.05 s lead-in, the wear off.
CASE3_WINDOW = tuple(arg for setting in [*SMALL_MODEL, NO_LEAD_IN, "time.duration=0.3", "time.local_stepping=true",
                                         "output.xdmf_interval=0.1", "wave.motion.record.window=[1.8, 4.0]",
                                         "wave.motion.record.lead_in=0.05", "wave.motion.record.pga=0.05",
                                         "contact.deterioration.R0=1.0"]
                     for arg in ("--set", setting))


def levels_of(run: dict) -> int:
    """The rate levels a run stepped (run.json's dt_reason: "... local time stepping: N rate levels")."""
    reason = run["dt_reason"]
    assert "local time stepping:" in reason, reason
    return int(reason.split("local time stepping:")[1].split("rate levels")[0])


def assert_shared_parts(run: dict, serial: dict, ranks: int) -> None:
    """The distributed model's parts: every rank owned and ghosted nodes and exchanged them; its set-up
    check ran on the ranks from its own random state (a function of the node coordinates, not the
    serial check's seeded one): the same global steps, stable as the serial check found."""
    mpi = run["mpi"]
    assert mpi["ranks"] == ranks and all(n > 0 for n in mpi["owned_nodes"])
    assert all(n > 0 for n in mpi["ghost_nodes"]) and all(b > 0 for b in mpi["bytes_sent_per_step"])
    checked, alone = run["local_stepping_stability"], serial["local_stepping_stability"]
    assert checked["ranks"] == ranks and checked["stable"] and alone["stable"]
    assert checked["global_steps"] == alone["global_steps"]


@pytest.fixture(scope="module")
def tunnel_runs(tmp_path_factory):
    """{ranks: run directory} of the tunnel (1: serial), each run when first read."""
    from conftest import RunsOnDemand

    base = tmp_path_factory.mktemp("mpi_lts_tunnel")

    def make(ranks):
        out = base / f"tunnel_{ranks}"
        pyfem_run(ranks, TUNNEL, out, *LOCAL)
        return out

    return RunsOnDemand(make)


@pytest.mark.parametrize("ranks", [2, 3])
def test_local_stepping_on_the_distributed_model_equals_the_serial_local_stepping(tunnel_runs, ranks):
    """The tunnel on the ranks (each builds and steps its part): the serial run's levels and step
    (run.json's dt_reason names the nodes per level), every history to the tunnel's tolerances."""
    serial, run = summary(tunnel_runs[1]), summary(tunnel_runs[ranks])
    assert run["model"] == "distributed" and levels_of(run) >= 3
    assert run["dt_reason"] == serial["dt_reason"] and run["steps"] == serial["steps"]
    crown = serial["monitors"]["crown"]
    assert crown["displacement"] > 2e-4 and crown["s1_dynamic_max"] > 1e3, "the wave reached the wall"
    reactions = np.loadtxt(tunnel_runs[1] / "reactions.csv", delimiter=",", skiprows=1)
    assert np.abs(reactions[:, 1:]).max() > 0.0, "the rollers held"
    assert_shared_parts(run, serial, ranks)
    # (the distributed model's tunnel tolerances, its net forces: test_distributed_model.TOLERANCES)
    differences = largest_differences(tunnel_runs[ranks], tunnel_runs[1])
    for kind, difference in differences.items():
        assert difference < DISTRIBUTED_TOLERANCES["tunnel"].get(kind, TOLERANCE), (kind, difference)
    worst = max(differences.values())
    assert run["energy"]["balance_error"] == pytest.approx(serial["energy"]["balance_error"], rel=1e-6)
    print(f"tunnel, local stepping on the distributed model, {ranks} ranks: largest difference from serial "
          f"{worst:.2e}; bytes per fine step {run['mpi']['bytes_sent_per_step']}, loop {run['loop_seconds']:.2f} s "
          f"(serial {serial['loop_seconds']:.2f} s); set-up check growth {run['local_stepping_stability']['growth']:.4g}"
          f" (serial {serial['local_stepping_stability']['growth']:.4g})")


@pytest.fixture(scope="module")
def case3_runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("mpi_lts_case3")
    runs = {ranks: base / f"case3_{ranks}" for ranks in (1, 2)}
    for ranks, out in runs.items():
        pyfem_run(ranks, CASE3, out, *CASE3_WINDOW)
    return runs


def test_the_case_study_scene_under_local_stepping_on_the_ranks_equals_the_serial_run(case3_runs):
    ranks = 2
    serial, run = summary(case3_runs[1]), summary(case3_runs[ranks])
    assert run["model"] == "distributed" and run["dt_reason"] == serial["dt_reason"]
    assert levels_of(serial) == levels_of(run) >= 3
    assert [stage["converged"] for stage in serial["static"]["stages"]] == [True, True]
    # Things happened in the dynamic run at their own rates: pairs slid, the rock yielded further.
    states = serial["pair_states"]
    assert states["sliding"][0] == 0 and max(states["sliding"]) >= 10
    assert serial["energy"]["internal_dissipation"] > 0.0 and serial["energy"]["friction_dissipation"] > 0.0
    assert run["pair_states"]["sliding"][-1] == states["sliding"][-1]
    assert_shared_parts(run, serial, ranks)
    assert run["mpi"]["moved_pair_nodes"] > 0
    assert sum(run["mpi"]["element_loop_cells"]) == sum(region["cells"] for region in
                                                        serial["nonlinear_regions"].values())
    differences = largest_differences(case3_runs[ranks], case3_runs[1])
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, TOLERANCE), (kind, difference)
    print(f"case 3 (small), local stepping on {ranks} ranks: " +
          ", ".join(f"{kind} {value:.1e}" for kind, value in sorted(differences.items()) if value))


GRADED_ON_RANKS = """
import json, sys
from pathlib import Path
sys.path.insert(0, "tests")
import numpy as np
from mpi4py import MPI
from pyfem import distributed_lts, distributed_model, local_stepping
from test_local_stepping import GRADED_GEO, graded_scene

local_stepping.fit_levels_to_output = lambda levels, steps_per_output: levels  # (conftest's unfitted_levels)

comm = MPI.COMM_WORLD
geo = Path(sys.argv[1])
if comm.rank == 0:
    geo.write_text(GRADED_GEO)
comm.barrier()
whole = distributed_model.build(graded_scene(geo, True), MPI.COMM_SELF)  # (the one-rank model, on every rank alone)
"""
"""The graded mesh of tests/test_local_stepping.py under local stepping (its levels not capped), the
one-rank model (a run without mpirun) on every rank: the start of the script the ranks run below."""

DISTRIBUTED_LEVELS = GRADED_ON_RANKS + """
whole_levels, whole_step = distributed_lts.node_levels(whole), distributed_model.choose_time_step(whole)
part = distributed_model.build(graded_scene(geo, True), comm)
levels = distributed_lts.node_levels(part)
expected = {tuple(x): int(k) for x, k in zip(np.round(whole.coords, 6), whole_levels)}
differ = sum(expected[tuple(x)] != int(k) for x, k in zip(np.round(part.coords, 6), levels))
found = {"differ": comm.allreduce(differ), "nodes": comm.allreduce(part.n_local),
         "counts": distributed_lts.level_counts(comm, levels, part.n_owned).tolist(),
         "whole_counts": np.bincount(whole_levels).tolist()}
# (one level coarser the energy overflows within the default 240 global steps: 60 keep it finite)
for name, shift, steps in (("as set", 0, 240), ("one coarser", 1, 60)):
    rank_levels = distributed_lts.RankLevels(levels + shift, np.array([0] * shift + found["counts"]), whole_step,
                                             whole_step)
    found[name] = distributed_lts.check_stability_on_ranks(part, rank_levels, None, steps=steps)
if comm.rank == 0:
    print("REPORT " + json.dumps(found))
"""


@pytest.mark.parametrize("ranks", [pytest.param(2, marks=pytest.mark.slow), 3])
def test_the_distributed_models_levels_and_set_up_check_are_the_serial_runs(tmp_path, ranks):
    """pyfem.distributed_lts.node_levels (each rank its owned rows and cells, a node the finest of its
    cells over the ranks) on the graded mesh of tests/test_local_stepping.py: every local node, owned
    or ghost, at the one-rank model's level (the model built on one rank alone, as a run without
    mpirun builds it); the set-up check on the ranks' parts finds the map stable
    with these levels, and unstable (growth above 1e3) with every node one rate coarser."""
    import json
    import subprocess

    from test_mpi import ENV, PYTHON, REPO

    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), PYTHON, "-c",
                             DISTRIBUTED_LEVELS, str(tmp_path / "graded.geo")],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    found = json.loads(result.stdout.split("REPORT ", 1)[1])
    assert len(found["whole_counts"]) >= 3, "the graded mesh stepped at three rates or more"
    assert found["differ"] == 0 and found["counts"] == found["whole_counts"]
    good, coarse = found["as set"], found["one coarser"]
    assert good["ranks"] == ranks and good["stable"] and good["growth"] < 1.5
    assert not coarse["stable"] and coarse["growth"] > 1e3
    print(f"{ranks} ranks: {found['nodes']} local nodes at the one-rank model's levels {found['counts']}; check growth "
          f"{good['growth']:.4g}, one level coarser {coarse['growth']:.4g}")


def test_the_distributed_case_study_scene_killed_on_two_ranks_resumes_on_three(tmp_path, case3_runs):
    """The small case 3 under local stepping on the distributed model, killed (kill -9) on 2 ranks past
    a checkpoint in the strong motion, resumed on 3 (another partition: each level's last forces by
    node position, the cells' and pairs' states by position): every history within the stage's
    round-off (the resume solves the stage again, on 3 ranks) of the uninterrupted 2-rank run."""
    from test_distributed_model import kill_after_a_checkpoint_past, pyfem

    reference = case3_runs[2]
    settings = (*CASE3_WINDOW, "--set", "output.checkpoint_interval=1.0")
    out = tmp_path / "killed"
    at = kill_after_a_checkpoint_past(2, CASE3, out, 0.1, settings)
    # Resumed with global stepping: refused in one line that names the key (a new user's trial).
    refused = pyfem(2, "run", CASE3, "--out", str(out), *settings, "--set", "time.local_stepping=false", "--resume")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr, refused.stderr[-3000:]
    assert "stepped locally (time.local_stepping)" in refused.stderr
    pyfem_run(3, CASE3, out, *settings, "--resume")
    resumed, expected = summary(out), summary(reference)
    assert resumed["status"] == "finished" and resumed["resumed"][0]["t"] == pytest.approx(at) and at < 0.3
    assert resumed["mpi"]["ranks"] == 3 and levels_of(resumed) >= 3
    assert max(expected["pair_states"]["sliding"]) >= 10, "pairs slid"
    assert resumed["pair_states"]["sliding"] == expected["pair_states"]["sliding"]
    differences = largest_differences(out, reference)
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, TOLERANCE), (kind, difference)
    print(f"killed at {at:.3f} s on 2 ranks, resumed on 3: " +
          ", ".join(f"{kind} {value:.1e}" for kind, value in sorted(differences.items()) if value))


def test_check_of_the_distributed_model_shows_its_levels_and_auto_decides_as_the_serial_run(tmp_path):
    """`check` of the tunnel with local_stepping = "auto": the distributed model on 2 ranks prints the
    serial run's decision (the same work sums and nodes per level, summed over the ranks) and, on,
    its levels; its trial steps whole global steps."""
    import subprocess

    from test_mpi import ENV, PYTHON, REPO

    def check(*launch):
        result = subprocess.run([*launch, PYTHON, "-m", "pyfem", "check", TUNNEL, "--set", 'time.local_stepping="auto"',
                                 "--set", "time.duration=20.0"], cwd=REPO, env=ENV,
                                capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        return {line.split(":")[0].strip(): line.split(":", 1)[1].strip() for line in result.stdout.splitlines()
                if ":" in line}

    whole, ours = check(), check(MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2")
    assert whole["local stepping (auto)"].startswith('"auto": on'), whole["local stepping (auto)"]
    assert ours["local stepping (auto)"] == whole["local stepping (auto)"]
    assert ours["local stepping"].startswith("3 rate levels") and "1693, 1354, 2026" in ours["local stepping"]
    assert "from rest, fine steps" in ours["time per step"]

"""The static stage under `mpirun -n N` equals the serial stage (docs/scaling.md "The static stage
on the distributed model"): its dynamic relaxation stepped on the ranks' parts of dolfinx's mesh
(pyfem/distributed_stage.py; no rank holds the whole model). A linear stage (PETSc's solves across the
ranks): tests/test_mpi_linear_stage.py.

The user's model: workflows/scenes/case3_contact_coarse.toml as it is (excavation with the whole load
released, the lining cast stress-free, Mohr-Coulomb rock around the cavern, concrete lining damage,
interlayer pairs), shrunk by tests/test_case_study_stage.py's SMALL_MODEL overrides, then 0.05 s of
the dynamic run (the record's filter lead-in). Run serially and on 2 and 3 ranks (an odd partition).

Before comparing, the test asserts that the stage did something in every run: both stages
converged, the rock yielded, pairs left their bond, and the ranks did share the stage
(static.json `settings.ranks`). Then the stage's iterations are the same, its out-of-balance agrees
to ROUNDOFF, the state handed to the dynamic run and the stage's fields to EXACT relative to their
largest value, and the dynamic histories to STAGE_ROUNDOFF per dimension (below): the 0.05 s window
is the lead-in's quiet precursor (displacements of 7e-7 m against the stage's 0.14 m), so round-off
of the static state (1e-14 of its forces, summed in another order over the 1 600 relaxation steps)
is a larger share of these small histories than of a wave's.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import EXACT, ROUNDOFF
from pyfem.compare import largest_differences
from test_case_study_stage import NO_LEAD_IN, SMALL_MODEL
from test_distributed_model import last_fields
from test_mpi import CHECKPOINTED_RUN, MPIRUN, kill_after_first_checkpoint, pyfem_run

SCENE = "workflows/scenes/case3_contact_coarse.toml"
SETTINGS = [*SMALL_MODEL, NO_LEAD_IN, "time.duration=0.05", "time.local_stepping=false", "output.xdmf_interval=0.05"]
# Per dimension (pyfem.compare.dimension), about ten times the largest difference measured on 2 and 3
# ranks (docstring).
STAGE_ROUNDOFF = {"acceleration": 2.0e-7, "velocity": 2.0e-9, "length": 1.0e-9, "energy": 3.0e-8}
HANDED_OVER = ("cell_stress", "monitor_stress", "pair_forces")

# One rule for the MPI tests: a missing launcher fails (conftest.mpi_launcher), never skips.
pytestmark = pytest.mark.usefixtures("mpi_launcher")


@pytest.fixture(scope="module")
def stage_runs(tmp_path_factory):
    """{ranks: run directory} of the small case 3 serially (1) and on 2 and 3 ranks, each run when first read."""
    from conftest import RunsOnDemand

    base = tmp_path_factory.mktemp("mpi_stage")
    extra = [word for setting in SETTINGS for word in ("--set", setting)]

    def make(ranks: int) -> Path:
        pyfem_run(ranks, SCENE, base / f"case3_{ranks}", *extra)
        return base / f"case3_{ranks}"

    return RunsOnDemand(make)


def stage_report(run_dir: Path) -> dict:
    return json.loads((run_dir / "static" / "static.json").read_text())


def largest_relative(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@pytest.mark.parametrize("ranks", [2, 3])
def test_the_static_stage_on_the_distributed_model_equals_the_serial_stage(stage_runs, ranks):
    """The small case 3's stage relaxed on the ranks' parts of dolfinx's mesh (each assembles its loads,
    matrices and scaled masses; contact pairs moved to their side-i node's rank) against the
    serial stage. Before comparing: the ranks did share it (the solver's words, static.json's
    ranks and model, element-loop cells on every rank, pair nodes moved), both stages converged, the
    rock yielded and pairs left their bond. Then the same relaxation steps, the same pair states, the
    out-of-balance to ROUNDOFF, the largest displacement, the faces' support forces and the monitors'
    handed-over stress to EXACT (measured on 2 / 3 ranks: 1.6e-14 / 1.3e-14, 1.4e-15 / 1.0e-15,
    1.9e-14 / 4.0e-14), and the dynamic histories to STAGE_ROUNDOFF (measured in two sittings on 2 / 3 ranks:
    acceleration 1.8e-8 / 1.6e-8-2.0e-8, velocity 1.9e-10 / 1.9e-10, length 2.9e-11-3.0e-11 /
    2.9e-11-4.4e-11, energy 1.1e-9-2.3e-9 / 1.6e-9-2.2e-9; on 2 ranks with the scaled mass's CSR row
    sums, 2026-12-08: acceleration 3.0e-9, velocity 3.4e-11, length 3.0e-11, energy 5.0e-10)."""
    serial, shared = stage_report(stage_runs[1]), stage_report(stage_runs[ranks])
    run = json.loads((stage_runs[ranks] / "run.json").read_text())
    assert run["model"] == "distributed" and run["mpi"]["ranks"] == ranks
    assert shared["settings"]["ranks"] == ranks and shared["settings"]["model"] == "distributed"
    assert {stage["solver"] for stage in shared["stages"]} == {
        f"dynamic relaxation on {ranks} MPI ranks (distributed model)"}
    assert min(run["mpi"]["element_loop_cells"]) > 0 and run["mpi"]["moved_pair_nodes"] > 0
    for report in (serial, shared):
        assert [stage["converged"] for stage in report["stages"]] == [True, True]
        assert sum(region["yielded_volume"] for name, region in report["regions"].items() if name != "lining") > 0.0
        states = report["pairs"]["states"]
        assert states["stick"] + states["sliding"] + states["separated"] > 0, "pairs left their bond in the stage"
    assert shared["pairs"]["states"] == serial["pairs"]["states"]
    assert shared["pairs"]["count"] == serial["pairs"]["count"]
    for expected, got in zip(serial["stages"], shared["stages"]):
        assert got["iterations"] == expected["iterations"], got["name"]
        assert got["free_dofs"] == expected["free_dofs"], got["name"]
        assert got["residual"] == pytest.approx(expected["residual"], rel=ROUNDOFF)
        assert got["max_displacement"] == pytest.approx(expected["max_displacement"], rel=EXACT)
    faces = sorted(serial["support_forces"])
    assert sorted(shared["support_forces"]) == faces
    expected = np.array([serial["support_forces"][face] for face in faces])
    assert np.abs(expected).max() > 1e9, "the faces hold the in-situ stress (GN)"
    assert largest_relative([shared["support_forces"][face] for face in faces], expected) < EXACT
    monitors = sorted(serial["monitors"])
    assert sorted(shared["monitors"]) == monitors
    for key, scale in (("stress", 1e5), ("displacement", 1e-3)):
        def values(report):
            entries = [report["monitors"][name][key] for name in monitors]
            return np.array([list(entry.values()) if isinstance(entry, dict) else entry for entry in entries])
        assert np.abs(values(serial)).max() > scale, key
        assert largest_relative(values(shared), values(serial)) < EXACT, key
    assert [shared["monitors"][name]["region"] for name in monitors] == \
        [serial["monitors"][name]["region"] for name in monitors]
    differences = largest_differences(stage_runs[ranks], stage_runs[1])
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, ROUNDOFF), (kind, difference)
    assert run["status"] == "finished" and run["time_reached"] == pytest.approx(0.05)
    # The fields at the end (0.05 s): the cells' stress is the stage's (measured 2.4e-14 of its largest,
    # 21 MPa, on 2 ranks), the plastic strain the stage's, the kinematics the small dynamic increment's.
    expected, got = last_fields(stage_runs[1]), last_fields(stage_runs[ranks])
    assert np.abs(expected["stress"]).max() > 1e7 and np.abs(expected["plastic_strain"]).max() > 1e-3
    for name, tolerance in (("stress", EXACT), ("plastic_strain", EXACT), ("pair_state", EXACT),
                            ("displacement", STAGE_ROUNDOFF["length"]), ("velocity", STAGE_ROUNDOFF["velocity"])):
        assert largest_relative(got[name], expected[name]) < tolerance, name
    # static/fields.xdmf (dolfinx's layout) at the stage's end: the whole model's (measured 3.6e-14 and below).
    expected = last_fields(stage_runs[1] / "static")
    got = last_fields(stage_runs[ranks] / "static")
    assert np.abs(expected["displacement"]).max() > 0.1 and np.abs(expected["plastic_strain"]).max() > 1e-3
    for name in ("displacement", "stage_displacement", "stress", "plastic_strain", "active", "damage_type"):
        assert largest_relative(got[name], expected[name]) < EXACT, name
    print(f"distributed stage on {ranks} ranks: {differences}")


def test_a_distributed_run_with_a_stage_killed_on_two_ranks_resumes_on_three(tmp_path, stage_runs):
    """kill -9 of the small case 3 on the distributed model (2 ranks) once its dynamic run has written a
    checkpoint; resumed on 3 ranks, which read the stage the 2 ranks kept (static/hand_over.npz and
    its rank files, keyed by position: the stage is not solved again) and load the checkpoint's
    state (element loop, pairs, kinematics): the histories equal the uninterrupted 2-rank run's to
    round-off (when the 3 ranks solved the stage again, measured in two sittings: acceleration
    2.1e-9-1.0e-8, length 4.6e-12-8.6e-12 of their largest values)."""
    out = tmp_path / "killed"
    extra = [word for setting in [*SETTINGS, "output.xdmf_interval=0.0"]
             for word in ("--set", setting)]
    kill_after_first_checkpoint(2, SCENE, out, 1.0, tuple(extra))
    assert (out / "static" / "hand_over.rank1.npz").exists()
    resumed = pyfem_run(3, SCENE, out, *CHECKPOINTED_RUN, *extra, "--resume")
    assert "the static stage read from static/hand_over.npz, not solved again" in resumed.stdout, resumed.stdout
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "finished" and run["mpi"]["ranks"] == 3 and run["resumed"][0]["t"] > 0.0
    assert [stage["converged"] for stage in stage_report(out)["stages"]] == [True, True]
    differences = largest_differences(out, stage_runs[2])
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, ROUNDOFF), (kind, difference)
    print(f"killed at t > {run['resumed'][0]['t']:.3f} s, resumed on 3 ranks: {differences}")


LAYERS = "tests/scenes/distributed_stage_layers.toml"


def test_the_distributed_stage_on_ranks_without_element_loop_cells_equals_the_serial_stage(tmp_path):
    """A new user's scene (a gravity stage with a fixed floor and a free top, a weak Mohr-Coulomb layer
    between two interfaces of pairs) on 3 ranks of the distributed model, two of which own no cell of
    the weak layer: the stage's collectives must not depend on what a rank holds (it hung there once:
    a rank without the layer's cells skipped an assembly the others made). Its stage and histories
    equal the serial whole model's (measured 1e-9 of the stage, 5e-14 of the histories on 2 ranks)."""
    serial, shared = tmp_path / "serial", tmp_path / "distributed"
    pyfem_run(1, LAYERS, serial)
    pyfem_run(3, LAYERS, shared)
    run = json.loads((shared / "run.json").read_text())
    assert run["status"] == "finished" and 0 in run["mpi"]["element_loop_cells"], run["mpi"]
    expected, got = stage_report(serial), stage_report(shared)
    assert [stage["converged"] for stage in got["stages"]] == [True, True]
    assert [stage["iterations"] for stage in got["stages"]] == [stage["iterations"] for stage in expected["stages"]]
    assert got["max_displacement"]["value"] == pytest.approx(expected["max_displacement"]["value"], rel=1e-9)
    assert got["max_displacement"]["value"] > 1e-4, "gravity moved the model"
    differences = largest_differences(shared, serial)
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, ROUNDOFF), (kind, difference)


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_stage_boundary_that_lets_a_model_with_pairs_move_is_refused(tmp_path, ranks):
    """Every face free during the stage (static.boundary.type = "free"): the one-line refusal (the faces
    leave the model free to move as a rigid body), serially and on every rank of the distributed model
    alike; exit 2, no run written. With contact pairs it was not refused before 2026-11-29 (the check
    projected a bonded pair's shared columns twice) and the floating stage ran its 200 000 steps."""
    command = [sys.executable, "-m", "pyfem", "run", LAYERS, "--out", str(tmp_path / "run"),
               "--set", 'static.boundary.type="free"', "--set", 'static.boundary.face.zmin.type="free"']
    if ranks > 1:
        command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), *command]
    result = subprocess.run(command, cwd=Path(__file__).parents[1], capture_output=True, text=True, timeout=300,
                            env=dict(os.environ, PYTHONPATH=str(Path(__file__).parents[1]), OMP_NUM_THREADS="1"))
    assert result.returncode == 2, result.stderr[-2000:]
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert errors and all(line == errors[0] for line in errors), result.stderr
    assert "static.boundary" in errors[0] and "rigid body" in errors[0] and "Traceback" not in result.stderr
    assert not (tmp_path / "run" / "run.json").exists()


SPLIT = "tests/scenes/split_after_static.toml"


@pytest.mark.parametrize("ranks", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_pairs_split_after_the_stage_slip_on_the_ranks_as_in_serial(tmp_path, ranks):
    """contact.split = "after_static" (tests/scenes/split_after_static.toml: the stage welded, a pair
    sheared at 0.8 of its strength slips when the wear falls below it) on the ranks:
    the pair slipped in every run, and the histories equal the serial run's."""
    serial, shared = tmp_path / "serial", tmp_path / f"ranks_{ranks}"
    pyfem_run(1, SPLIT, serial)
    pyfem_run(ranks, SPLIT, shared)
    for run in (serial, shared):
        rows = np.genfromtxt(run / "pairs" / "middle.csv", delimiter=",", names=True)
        assert rows["state"][0] == 0 and np.abs(rows["slip"]).max() > 1e-3, "the pair started bonded and slipped"
    differences = largest_differences(shared, serial)
    print(f"{ranks} ranks vs serial: {differences}")
    for kind, difference in differences.items():
        assert difference < STAGE_ROUNDOFF.get(kind, ROUNDOFF), (kind, difference)

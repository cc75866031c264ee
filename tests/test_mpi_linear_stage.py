"""The linear static stage on the model (pyfem/distributed_linear.py: the reduced system T^T K T built
from the ranks' parts and solved by PETSc across the ranks) equals the serial stage it replaced
(recorded in tests/data/linear_stage_serial.json) on one rank, and one rank on 2 and 3.

The scene, tests/scenes/distributed_linear_stage.toml: a layered box (60 x 6 x 40 m, h 3 m) with two
interfaces of contact pairs, a gravity stage with a uniform in-situ stress (rollers, a fixed floor, a
free top), the upper layer installed stress-free in stage 2 (its nodes held in stage 1 but where
bonded to the rock's), static.solver = "direct", then 0.1 s of an SV Ricker pulse, on one rank and
on 2 (and 3) ranks.

Each test first asserts that the stage did something (gravity moved the box by millimetres, the
faces hold the stage, the pairs carry the forces it handed over, the ranks shared it and the pair
nodes moved to their pair's rank), then the agreement: on one rank the same arithmetic (the same
matrices, basis, products and PETSc solve): equal to the bit; on 2 and 3 ranks MUMPS's other
elimination order (measured 2e-16-2e-15 of the stage's numbers, 1.4e-14 of the histories);
the iterative solve (CG + GAMG to static.tolerance = 1e-10) to the solver's tolerance.
"""
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import EXACT
from pyfem.compare import largest_differences
from test_distributed_model import last_fields
from test_mpi import ENV, PYTHON, REPO, pyfem_run

SCENE = "tests/scenes/distributed_linear_stage.toml"
ITERATIVE = ("--set", 'static.solver="iterative"', "--set", "static.tolerance=1e-10")
# The iterative stage on 2 ranks against one rank's: both solved to a relative residual of 1e-10, the
# stiffness's conditioning makes the displacement's error larger (measured on 2 ranks: 4.7e-12 of the
# monitors' displacement, 4e-10 of the installed layer's small stress, 4.2e-11 of the histories).
SOLVER_TOLERANCE = 1.0e-8

pytestmark = pytest.mark.usefixtures("mpi_launcher")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{(ranks, solver): run directory}."""
    from conftest import RunsOnDemand

    base = tmp_path_factory.mktemp("linear_stage")

    def make(key):
        ranks, solver = key
        out = base / f"{solver}_{ranks}"
        extra = ITERATIVE if solver == "iterative" else ()
        pyfem_run(ranks, SCENE, out, *extra)
        return out

    return RunsOnDemand(make)


def report(run_dir: Path) -> dict:
    return json.loads((run_dir / "static" / "static.json").read_text())


def stage_numbers(run_dir: Path) -> dict:
    """The stage's numbers of a run's static.json, as arrays."""
    return stage_numbers_of(report(run_dir))


def stage_numbers_of(stage: dict) -> dict:
    monitors = sorted(stage["monitors"])
    return {"max_displacement": [stage["max_displacement"]["value"]] + stage["max_displacement"]["vector"],
            "stage_max_displacement": [s["max_displacement"] for s in stage["stages"]],
            "support_forces": [stage["support_forces"][face] for face in sorted(stage["support_forces"])],
            "monitor_displacement": [stage["monitors"][name]["displacement"] for name in monitors],
            "monitor_displacement_stage_1": [stage["monitors"][name]["displacement_stage_1"] for name in monitors],
            "monitor_stress": [list(stage["monitors"][name]["stress"].values()) for name in monitors],
            "pairs": [stage["pairs"][key] for key in ("normal_stress_min", "normal_stress_max", "shear_stress_max")]}


def largest_relative(got, expected) -> float:
    got, expected = np.asarray(got, dtype=float), np.asarray(expected, dtype=float)
    assert got.shape == expected.shape
    return float(np.abs(got - expected).max() / max(np.abs(expected).max(), 1e-300))


def assert_the_stage_did_something(run_dir: Path, ranks: int) -> None:
    stage = report(run_dir)
    assert 3e-3 < stage["max_displacement"]["value"] < 5e-3, "gravity moved the box by millimetres (3.66 mm)"
    assert all(s["iterations"] >= 1 and s["free_dofs"] > 1000 for s in stage["stages"]), stage["stages"]
    assert stage["stages"][0]["free_dofs"] < stage["stages"][1]["free_dofs"], "the upper layer joins in stage 2"
    assert stage["installed"] == ["upper"] and stage["stages"][0]["active_regions"] == ["lower", "weak"]
    assert np.abs(stage["support_forces"]["zmin"]).max() > 1e7, "the floor carries the box's weight"
    assert stage["pairs"]["count"] == 126 and stage["pairs"]["normal_stress_max"] > 1e5
    assert "applied as a constant external force" in stage["hand_over"]
    top = stage["monitors"]["top"]  # in the installed layer: stress-free until stage 2, then its weight
    assert np.abs(top["displacement_stage_1"]).max() == 0.0 and abs(top["stress"]["szz"]) > 1e4
    if ranks:
        run = json.loads((run_dir / "run.json").read_text())
        assert run["model"] == "distributed" and stage["settings"]["model"] == "distributed"
        assert stage["settings"]["ranks"] == ranks == run["mpi"]["ranks"]
        if ranks > 1:
            assert run["mpi"]["moved_pair_nodes"] > 0 and min(run["mpi"]["owned_nodes"]) > 0
            assert all(f"on {ranks} MPI ranks (distributed model)" in s["solver"] for s in stage["stages"])


def test_the_linear_stage_on_one_rank_is_the_serial_stages_record(runs):
    """One rank: the same matrices, free basis, products and MUMPS solve as the serial in-memory stage
    it replaced (pyfem.static.solve_static_stage), whose numbers tests/data/linear_stage_serial.json
    recorded before it was deleted: the stage's numbers of static.json equal them to EXACT (measured
    when recorded: 0 in every number)."""
    one = runs[1, "direct"]
    assert_the_stage_did_something(one, 1)
    record = json.loads((REPO / "tests" / "data" / "linear_stage_serial.json").read_text())["numbers"]
    got = stage_numbers(one)
    for key in got:
        assert largest_relative(got[key], record[key]) < EXACT, key
    assert report(one)["out_of_balance"] == pytest.approx(record["out_of_balance"], rel=1e-6)
    assert record["out_of_balance"] > 0.0


@pytest.mark.parametrize("ranks", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_the_linear_stage_on_the_ranks_equals_the_one_rank_stage(runs, ranks):
    """2 and 3 ranks, MUMPS across the ranks: the stage's numbers and fields and the run's histories
    equal the one-rank run's to EXACT (measured on 2 / 3 ranks: the stage 2e-15 / 1.6e-15 (the installed
    layer's small stress 4.2e-14 / 1.7e-14 of itself), the histories 1.4e-14 / 2.7e-15)."""
    serial, shared = runs[1, "direct"], runs[ranks, "direct"]
    assert_the_stage_did_something(shared, ranks)
    expected, got = stage_numbers(serial), stage_numbers(shared)
    for key in expected:
        assert largest_relative(got[key], expected[key]) < (1e-12 if key == "monitor_stress" else EXACT), key
    differences = largest_differences(shared, serial)
    for kind, difference in differences.items():
        assert difference < EXACT, (kind, difference)
    expected_fields, got_fields = last_fields(serial / "static"), last_fields(shared / "static")
    assert np.abs(expected_fields["displacement"]).max() > 3e-3
    for name in ("displacement", "stage_displacement", "stress", "active"):
        assert largest_relative(got_fields[name], expected_fields[name]) < EXACT, name
    print(f"linear stage on {ranks} ranks: {differences}")


def test_the_iterative_linear_stage_on_two_ranks_equals_the_one_rank_one_to_its_tolerance(runs):
    """static.solver = "iterative" (CG + GAMG with the rigid-body modes, tolerance 1e-10) on 2 ranks
    against the one-rank iterative stage: both converged to the tolerance, the stage and the histories
    agree to SOLVER_TOLERANCE."""
    serial, shared = runs[1, "iterative"], runs[2, "iterative"]
    assert_the_stage_did_something(shared, 2)
    for run in (serial, shared):
        stages = report(run)["stages"]
        assert all(s["solver"].startswith("iterative (CG + GAMG)") and s["iterations"] > 1 for s in stages)
        assert all(s["residual"] <= 1e-10 for s in stages)
    expected, got = stage_numbers(serial), stage_numbers(shared)
    for key in expected:
        assert largest_relative(got[key], expected[key]) < SOLVER_TOLERANCE, key
    for kind, difference in largest_differences(shared, serial).items():
        assert difference < SOLVER_TOLERANCE, (kind, difference)


@pytest.mark.slow
def test_a_run_with_a_linear_stage_resumed_on_another_rank_count_goes_on_as_the_uninterrupted_run(runs, tmp_path):
    """0.05 s on 2 ranks, then --resume to 0.1 s on 3 (which solve the stage again and load the
    checkpoint's state, the hand-over force's work summed onto one provider): the histories equal the
    uninterrupted 2-rank run's to EXACT (measured 1.9e-15 of the accelerations)."""
    out = tmp_path / "resumed"
    pyfem_run(2, SCENE, out, "--set", "time.duration=0.05")
    pyfem_run(3, SCENE, out, "--resume")
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "finished" and run["mpi"]["ranks"] == 3
    assert run["resumed"][0]["t"] == pytest.approx(0.05) and run["time_reached"] == pytest.approx(0.1)
    assert_the_stage_did_something(out, 3)
    differences = largest_differences(out, runs[2, "direct"])
    for kind, difference in differences.items():
        assert difference < EXACT, (kind, difference)


def test_a_linear_solver_for_a_nonlinear_material_is_refused_under_mpirun_as_serially(tmp_path):
    """static.solver = "direct" with a [plasticity] table: the serial refusal (pyfem.static.check_linear)
    on every rank alike, before any model is built; exit 2, no run written."""
    lines = {}
    for ranks in (1, 2):
        command = [PYTHON, "-m", "pyfem", "run", "tests/scenes/distributed_stage_layers.toml", "--out",
                   str(tmp_path / f"run_{ranks}"), "--set", 'static.solver="direct"']
        if ranks > 1:
            from test_mpi import MPIRUN

            command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks), *command]
        result = subprocess.run(command, cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
        assert result.returncode == 2, result.stderr[-2000:]
        errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
        assert errors and all(line == errors[0] for line in errors), result.stderr
        assert "Traceback" not in result.stderr and not (tmp_path / f"run_{ranks}" / "run.json").exists()
        lines[ranks] = errors[0]
    assert lines[1] == lines[2]
    assert "static.solver" in lines[2] and "materials.weak.plasticity" in lines[2], lines[2]

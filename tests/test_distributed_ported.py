"""What only the serial path had, on the one model (issue 47): one point per cell (integration =
"reduced"), quadratic tetrahedra and more than 31 contact interfaces, each run on one rank (`pyfem
run`) and on 2 ranks (`mpirun -n 2`). One rank reproduces the serial path's histories (measured 0
before the serial path was deleted; the reference records of tests/test_reference_histories.py keep
that net); here 2 ranks are held to the one-rank run.

The features x ranks matrix (FEATURES):
- reduced: the weak Mohr-Coulomb layer of tests/scenes/mpi_weak_layer.toml with one point per cell,
  its cells' hourglass stiffness in the matrix (pyfem/reduced_integration.py): the layer yields;
- tet_p2: two layers meshed to quadratic tetrahedra (tests/scenes/mpi_p2_tet.toml; HRZ-lumped masses
  and face integrals, the ghosts' diagonals from their owners): the wave arrives;
- interfaces_33: 34 layers, their 33 interfaces in contact (tests/scenes/mpi_many_interfaces.toml; a
  pair node's checkpoint key holds its roles in two int64 words): the pairs break their bonds and slide.
Each test asserts first that the effect happened, then that every monitor, pair and energy history
equals the one-rank run's to TOLERANCE of its dimension's largest value (measured: at most 4e-12 on
2 and 3 ranks). The interfaces' checkpoint, written on 2 ranks, is resumed on 3.
"""
import json
import subprocess
from pathlib import Path

import pytest

from pyfem.compare import largest_differences
from test_distributed_model import ENV, MPIRUN, PYTHON, REPO

TOLERANCE = 1.0e-10
FEATURES = {
    "reduced": ("tests/scenes/mpi_weak_layer.toml", "--set", 'materials.weak.plasticity.integration="reduced"',
                "--set", "output.xdmf_interval=0.0"),
    "tet_p2": ("tests/scenes/mpi_p2_tet.toml", "--set", "output.xdmf_interval=0.0"),
    "interfaces_33": ("tests/scenes/mpi_many_interfaces.toml",),
}
_RUNS: dict = {}


def pyfem(ranks: int, *arguments: str):
    """`pyfem ARGUMENTS` on `ranks` (under mpirun above one)."""
    command = [PYTHON, "-m", "pyfem", *arguments]
    if ranks > 1:
        command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    return subprocess.run(command, cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600)


def run(tmp_path_factory, feature: str, ranks: int) -> Path:
    """The run directory of `feature` on `ranks`, run once."""
    key = feature, ranks
    if key not in _RUNS:
        out = tmp_path_factory.mktemp(f"{feature}_{ranks}") / "run"
        result = pyfem(ranks, "run", *FEATURES[feature][:1], "--out", str(out), *FEATURES[feature][1:])
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        _RUNS[key] = out
    return _RUNS[key]


def summary(out: Path) -> dict:
    return json.loads((out / "run.json").read_text())


@pytest.mark.parametrize("feature", FEATURES)
def test_two_ranks_equal_one(tmp_path_factory, mpi_launcher, feature):
    ranks = 2
    serial_dir = run(tmp_path_factory, feature, 1)  # (the one-rank run: "serial" below)
    ours_dir = run(tmp_path_factory, feature, ranks)
    serial, ours = summary(serial_dir), summary(ours_dir)
    assert serial["model"] == ours["model"] == "distributed" and ours["mpi"]["ranks"] == ranks
    # The effect happened.
    if feature == "reduced":  # one point per cell, and the layer yielded
        region = serial["nonlinear_regions"]["weak"]
        assert region["integration"] == "reduced" and region["points"] == region["cells"] > 0
        assert region["yielded_volume"] > 0.0 and serial["monitors"]["layer"]["plastic_strain_max"] > 0.0
        assert ours["nonlinear_regions"]["weak"] == pytest.approx(region, rel=1e-9)
    elif feature == "tet_p2":  # quadratic tetrahedra (10 nodes a cell), the wave arrived
        assert serial["nodes"] > serial["cells"] and ours["nodes"] == serial["nodes"]  # (P1: about cells / 5)
        assert serial["monitors"]["upper"]["displacement"] > 1e-3
    else:  # 33 interfaces, their pairs broke their bonds and slid, on the top one too
        assert len(serial["pair_states"]["sliding"]) > 0 and max(serial["pair_states"]["sliding"]) > 0.5 * serial["n_pairs"]
        assert serial["pairs"]["high"]["interface"] == "interface_31" and serial["pairs"]["high"]["max_slip"] > 1e-5
        assert ours["pair_states"] == serial["pair_states"] and ours["n_pairs"] == serial["n_pairs"]
    assert sum(ours["mpi"]["owned_nodes"]) == serial["nodes"]
    assert all(o + g < serial["nodes"] for o, g in zip(ours["mpi"]["owned_nodes"], ours["mpi"]["ghost_nodes"]))
    assert ours["dt"] == serial["dt"] and ours["steps"] == serial["steps"]
    differences = largest_differences(ours_dir, serial_dir)
    assert differences, "no history compared"
    for kind, difference in differences.items():
        assert difference < TOLERANCE, (kind, difference)


def test_a_checkpoint_of_33_interfaces_written_on_2_ranks_resumes_on_3(tmp_path_factory, mpi_launcher):
    """The pair nodes' checkpoint keys (positions and roles, two words of bits for 33 interfaces)
    match across partitions: a run stopped at 0.1 s on 2 ranks, resumed to 0.15 s on 3, equals the
    one-rank run of 0.15 s."""
    serial_dir = run(tmp_path_factory, "interfaces_33", 1)
    out = tmp_path_factory.mktemp("interfaces_33_resumed") / "run"
    scene = FEATURES["interfaces_33"][0]
    first = pyfem(2, "run", scene, "--out", str(out), "--set", "time.duration=0.1")
    assert first.returncode == 0, first.stderr[-3000:]
    assert summary(out)["steps"] < summary(serial_dir)["steps"]
    resumed = pyfem(3, "run", scene, "--out", str(out), "--resume")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert summary(out)["steps"] == summary(serial_dir)["steps"] and summary(out)["mpi"]["ranks"] == 3
    for kind, difference in largest_differences(out, serial_dir).items():
        assert difference < TOLERANCE, (kind, difference)

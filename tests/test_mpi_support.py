"""Rock bolts and cables on the model's ranks (pyfem/distributed_support.py) against the one-rank
run of the same scene, tests/scenes/distributed_bolts.toml: grouted bolts installed in the static
stage whose weak bond slips there, pretensioned cables installed at the start of a P wave that yield
in their free length, a bolt monitor on each group.

Before comparing, each test asserts that the bolts did something in both runs: the grouted bolts
carry axial force and their bond slipped, the cables yielded, and the bolts did cross the ranks'
parts (extra ghost nodes). Then:

- 2 and 3 ranks against one rank: the axial forces of static/support.csv and support.csv, the
  grouted bolts' bond slip, the bolt monitors, the energy account and the monitor to ROUNDOFF of
  their largest values (measured against the former serial path: axial forces 6e-14 of the peak on
  1 and 2 ranks, the stage's 7e-13 / 2.5e-12, internal stored energy 8e-12 / 4e-11, kinetic, strain
  and work 4e-15).
- The cables' bond slip in their yielded free length is not compared: there a perfectly plastic bar
  has no bond and its displacement is not unique (the tridiagonal solve's round-off picks one; measured
  3e-8 m of slips of 8e-6 m), while its force, the yield force, is.
- A run of 0.05 s on 2 ranks extended by --resume to 0.1 s on 3 ranks (its checkpoint's bolt state
  keyed by position) equals the uninterrupted 2-rank run.
"""
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import ROUNDOFF, RunsOnDemand

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
SCENE = "tests/scenes/distributed_bolts.toml"

pytestmark = pytest.mark.usefixtures("mpi_launcher")


def run(ranks, out: Path, *extra: str, mpirun: str = "mpirun") -> dict:
    command = [PYTHON, "-m", "pyfem", "run", SCENE, "--out", str(out), *extra]
    if ranks > 1:
        command = [mpirun, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    done = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return json.loads((out / "run.json").read_text())


@pytest.fixture(scope="module")
def runs(tmp_path_factory, mpi_launcher):
    """{1 | 2 | 3: run directory}, each run when first read."""
    base = tmp_path_factory.mktemp("mpi_support")

    def make(key):
        out = base / str(key)
        run(key, out, mpirun=mpi_launcher)
        return out

    return RunsOnDemand(make)


def table(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")


def relative(got, expected) -> float:
    got, expected = np.asarray(got, dtype=float), np.asarray(expected, dtype=float)
    assert got.shape == expected.shape
    return float(np.abs(got - expected).max() / max(np.abs(expected).max(), 1e-300))


def assert_the_bolts_worked(out: Path) -> dict:
    summary = json.loads((out / "run.json").read_text())
    assert summary["status"] == "finished"
    stage, end = summary["static"]["support"]["grouted"], summary["support"]
    assert stage["installed"] == "static" and stage["peak_axial_force"] > 1e3  # loaded in the stage
    assert stage["slipping_nodes"] > 30 and end["grouted"]["slipping_nodes"] > 30  # the weak bond slipped
    assert end["cables"]["installed"] == "start" and end["cables"]["yielded_segments"] > 0  # the cables yielded
    assert end["cables"]["peak_axial_force"] == pytest.approx(2.05e3, rel=1e-9)  # at their yield force
    forces = table(out / "support.csv")["axial_force"]
    assert np.count_nonzero(np.abs(forces) > 100.0) > 40
    for name in ("middle", "cable"):
        assert np.abs(table(out / "bolts" / f"{name}.csv")["axial_force"]).max() > 100.0
    return summary


def compare(out: Path, reference: Path) -> dict:
    """The largest relative differences of the bolts' outputs and histories."""
    found = {}
    for name in ("static/support.csv", "support.csv"):
        got, expected = table(out / name), table(reference / name)
        assert (got["group"] == expected["group"]).all() and (got["bolt"] == expected["bolt"]).all()
        assert relative(np.column_stack([got[c] for c in "xyz"]), np.column_stack([expected[c] for c in "xyz"])) == 0.0
        found[f"{name} axial_force"] = relative(got["axial_force"], expected["axial_force"])
        grouted = expected["group"] != "cables"  # (a yielded free length's displacement is not unique)
        found[f"{name} bolts' bond_slip"] = relative(got["bond_slip"][grouted], expected["bond_slip"][grouted])
    for name in ("bolts/middle.csv", "bolts/cable.csv", "monitors/floor.csv"):
        got, expected = table(out / name), table(reference / name)
        for column in expected.dtype.names[1:]:
            if np.abs(expected[column]).max() > 1e-6 * max(np.abs(expected[c]).max() for c in expected.dtype.names[1:]):
                found[f"{name} {column}"] = relative(got[column], expected[column])
    got, expected = table(out / "energy.csv"), table(reference / "energy.csv")
    for column in ("kinetic", "strain", "external_work", "damping_work", "internal_stored", "internal_dissipation"):
        found[f"energy {column}"] = relative(got[column], expected[column])
    return found


def test_bolts_and_cables_work_on_one_rank(runs):
    summary = assert_the_bolts_worked(runs[1])
    assert summary["model"] == "distributed" and summary["mpi"]["ranks"] == 1


@pytest.mark.slow
@pytest.mark.parametrize("ranks", [2, 3])
def test_bolts_and_cables_on_the_ranks_equal_the_one_rank_run(runs, ranks):
    assert_the_bolts_worked(runs[1])
    summary = assert_the_bolts_worked(runs[ranks])
    assert summary["model"] == "distributed" and summary["mpi"]["ranks"] == ranks
    assert max(summary["mpi"]["extra_ghost_nodes"]) > 0  # the bolts crossed the ranks' parts
    differences = compare(runs[ranks], runs[1])
    worst = max(differences, key=differences.get)
    print(f"{ranks} ranks against one: largest {worst} {differences[worst]:.2e}")
    for name, difference in differences.items():
        assert difference < ROUNDOFF, (name, difference)


# Local time stepping: an 8 x 8 m column on a stiff base (E 120 GPa, 2 m) meshes three rate levels (the
# interior rock above the base at level 2), and a group "short" of three bolts installed at the start,
# two inside the level-2 rock and one reaching down into level-0 nodes.
LTS = ["time.local_stepping=true", "mesh.size=[8.0,8.0,10.0]",
       'mesh.layers=[{material="hard",thickness=2.0},{material="rock",thickness=4.0},{material="top",thickness=4.0}]',
       "materials.hard={E=1.2e11,nu=0.24,rho=2600.0}", "time.dt=2e-5",
       "support.grouted.lines=[[3.0,3.0,5.5,3.0,3.0,1.0],[5.0,5.0,5.5,5.0,5.0,1.0],[4.0,4.0,5.5,4.0,4.0,0.5]]",
       "support.cables.lines=[[3.0,5.0,5.5,3.0,5.0,0.5],[5.0,3.0,5.5,5.0,3.0,0.5]]",
       "monitor.0.point=[4.0,4.0,5.9]", "bolt_monitor.0.point=[4.0,4.0,3.0]", "bolt_monitor.1.point=[3.0,5.0,2.0]",
       "support.short={lines=[[4.0,4.0,5.8,4.0,4.0,4.2],[3.5,4.5,5.8,3.5,4.5,4.2],[4.5,3.5,5.8,4.5,3.5,2.5]],"
       "diameter=0.032,yield_force=3.2e5,bond_stiffness=1.0e9,bond_strength=4.0e5,segment=0.3}"]


@pytest.mark.slow
def test_bolts_under_local_time_stepping_at_their_host_nodes_finest_level_on_one_two_and_three_ranks(
        tmp_path, mpi_launcher):
    """Each bolt steps at the finest level of its host nodes (as a contact pair at the finer of its
    two nodes'); the levels bound the bolts' stiffness too. Before comparing: three levels, the short
    group's bolts at two of them, the bolts loaded and slipping as in global stepping. Then 2 and 3
    ranks against one rank to ROUNDOFF, and one rank against its global stepping
    within local stepping's own error (measured: axial forces 5.7e-4 of their peak)."""
    extra = [word for setting in LTS for word in ("--set", setting)]
    runs = {1: run(1, tmp_path / "1", *extra)}
    for ranks in (2, 3):
        runs[ranks] = run(ranks, tmp_path / str(ranks), *extra, mpirun=mpi_launcher)
    run(1, tmp_path / "global", *extra, "--set", "time.local_stepping=false")
    for ranks, summary in runs.items():
        assert_the_bolts_worked(tmp_path / str(ranks))
        assert "3 rate levels" in summary["dt_reason"], summary["dt_reason"]
        assert summary["support"]["short"]["bolts_per_level"] == {"0": 1, "2": 2}
        assert summary["support"]["short"]["peak_axial_force"] > 1e3
    assert max(runs[3]["mpi"]["extra_ghost_nodes"]) > 0
    for ranks in (2, 3):
        differences = compare(tmp_path / str(ranks), tmp_path / "1")
        worst = max(differences, key=differences.get)
        print(f"local stepping, {ranks} ranks against one: largest {worst} {differences[worst]:.2e}")
        for name, difference in differences.items():
            assert difference < ROUNDOFF, (name, difference)
    # Its checkpoint keyed by position: 0.05 s on 2 ranks extended by --resume on 3 ranks.
    run(2, tmp_path / "extended", *extra, "--set", "time.duration=0.05", mpirun=mpi_launcher)
    extended = run(3, tmp_path / "extended", *extra, "--resume", mpirun=mpi_launcher)
    assert extended["mpi"]["ranks"] == 3 and extended["resumed"][0]["t"] == pytest.approx(0.05)
    differences = compare(tmp_path / "extended", tmp_path / "2")
    worst = max(differences, key=differences.get)
    print(f"local stepping, 2 ranks resumed on 3 against 2 ranks: largest {worst} {differences[worst]:.2e}")
    for name, difference in differences.items():
        assert difference < ROUNDOFF, (name, difference)
    got, expected = table(tmp_path / "1" / "support.csv"), table(tmp_path / "global" / "support.csv")
    error = relative(got["axial_force"], expected["axial_force"])
    print(f"local against global stepping: axial forces {error:.2e} of their peak")
    assert 0.0 < error < 1e-2


@pytest.mark.slow
def test_a_run_on_two_ranks_extended_on_three_equals_the_uninterrupted_run(runs, tmp_path, mpi_launcher):
    out = tmp_path / "extended"
    run(2, out, "--set", "time.duration=0.05", mpirun=mpi_launcher)
    summary = run(3, out, "--resume", mpirun=mpi_launcher)
    assert summary["mpi"]["ranks"] == 3 and summary["resumed"][0]["t"] == pytest.approx(0.05)
    assert_the_bolts_worked(out)
    differences = compare(out, runs[2])
    worst = max(differences, key=differences.get)
    print(f"2 ranks, resumed on 3, against 2 ranks: largest {worst} {differences[worst]:.2e}")
    for name, difference in differences.items():
        assert difference < ROUNDOFF, (name, difference)


PLACE = """
import sys, json
import numpy as np
sys.path.insert(0, {tests!r})
from mpi4py import MPI
from pyfem.scene import parse_scene
from test_support_scene import tet_tunnel
from pathlib import Path
scene = tet_tunnel(Path({tmp!r}), 'Physical Surface("tunnel_wall") = {{ex[6], ex[7], ex[8], ex[9]}};', "tunnel_wall")
if MPI.COMM_WORLD.size == 1 and {serial}:  # the whole mesh in one piece, placed as one surface
    from pyfem.operators import build_model
    from pyfem.support import scene_groups
    groups = scene_groups(scene, build_model(scene, MPI.COMM_SELF))
else:
    from pyfem import distributed_model
    groups = [rank_group.group for rank_group in distributed_model.build(scene, MPI.COMM_WORLD).support]
if MPI.COMM_WORLD.rank == 0:
    np.savez({out!r}, **{{g.name: g.lines for g in groups}},
             **{{g.name + "_positions": g.bolts.positions for g in groups}},
             **{{g.name + "_weights": g.bolts.host_weights for g in groups}})
"""


@pytest.mark.slow
def test_a_pattern_is_placed_alike_on_any_rank_count(tmp_path, mpi_launcher):
    """A closed pattern (a tetrahedral tunnel's wall, 13 bolts a row, where the first bolt of a row
    follows from the order the surface's triangles are read in) placed on the whole mesh in one piece
    (pyfem.support.scene_groups on operators.build_model's model, as the serial model placed it) and by 2
    and 3 ranks (each its part of the surface, gathered and ordered by position): the same bolts in
    the same order, their nodes' host weights the same (the whole model's preferred cell)."""
    found = {}
    for key, ranks in (("serial", 1), (2, 2), (3, 3)):
        out = tmp_path / f"lines_{key}.npz"
        code = PLACE.format(tests=str(REPO / "tests"), tmp=str(tmp_path), serial=key == "serial", out=str(out))
        command = [PYTHON, "-c", code]
        if ranks > 1:
            command = [mpi_launcher, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
        done = subprocess.run(command, cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1"),
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        found[key] = dict(np.load(out))
    assert len(found["serial"]["radial"]) == 52
    for key in (2, 3):
        for name in ("radial",):
            assert np.abs(found[key][name] - found["serial"][name]).max() < 1e-12, (key, name)
            assert np.abs(found[key][name + "_positions"] - found["serial"][name + "_positions"]).max() < 1e-12
            assert np.abs(found[key][name + "_weights"] - found["serial"][name + "_weights"]).max() < 1e-12

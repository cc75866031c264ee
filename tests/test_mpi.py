"""`mpirun -n N python3 -m pyfem run SCENE` equals the serial run (issue 13, docs/scaling.md).

The same command line on 1 and 2 ranks, and on 3 (an odd partition) for the free field, contact,
damage and zone scenes (the issue's three kinds, and the zone that one of 3 ranks does not reach;
the other scenes take the same paths on 3 ranks as on 2, and their 3-rank runs cost 40-70 s of the
default tier), eight scenes:
- the free-field box under a vertical SV pulse (workflows/scenes/box_vertical_sv.toml);
- a contact scene whose pairs break their bonds, slide and open (tests/scenes/mpi_hard_contact.toml),
  and the same with the friction's normal-stress lag;
- a damage scene whose weak layer yields (tests/scenes/mpi_weak_layer.toml), and the same layer
  with one point per cell;
- the same layer in Q2 with Rayleigh damping, float32 matrix blocks and a plasticity zone that one
  of 3 ranks does not reach (tests/scenes/mpi_q2_zone.toml);
- a circular tunnel in the tetrahedral mesh of a user's gmsh script (meshes/tunnel_in_box_tet.geo),
  its wall traction-free (tests/scenes/mpi_tunnel_tet.toml);
- roller faces (kernel constraints) with their reactions under a vertical P wave.
Every monitor, pair and energy history agrees to 1e-10 relative to the size of the quantity
(the largest value of its group of columns: u, v, a, stress, slip and gap, ...), and so do the
fields and run.json's peaks; before that the test asserts that the wave arrived, the pairs slid
and the layer yielded, the rollers were loaded, and that the ranks did share the model (owned
nodes, ghosts, messages, element-loop cells).
The distributed run differs from the serial one only in the order of the sums (its matrix rows
and the energy account are summed per rank): round-off, not an algorithmic difference.
Then kill -9 of a 2-rank run after its first checkpoint, `--resume` on 2 ranks: the histories
equal those of the uninterrupted 2-rank run.
"""
import json
import os
import random
import shutil
import signal
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import kill_9, rank_pids
from pyfem import checkpoint
from pyfem.compare import histories, largest_difference, largest_differences, relative_difference, scales

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
ENV = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
TOLERANCE = 1.0e-10
MPIRUN = shutil.which("mpirun")

SCENES = {
    "free_field": ("workflows/scenes/box_vertical_sv.toml", ()),
    "contact": ("tests/scenes/mpi_hard_contact.toml", ()),
    # The same pairs with the friction's normal-stress lag ([contact.normal_lag]): each pair's N* is
    # sliced to the rank that owns the pair and merged back with the other per-pair blocks.
    "contact_lag": ("tests/scenes/mpi_hard_contact.toml", ("--set", "contact.normal_lag.length=0.01",
                                                           "--set", "contact.normal_lag.velocity=0.1")),
    "damage": ("tests/scenes/mpi_weak_layer.toml", ()),
    # The same layer with one point per cell (integration = "reduced"): the hourglass stiffness is in
    # the matrix rows each rank owns, the one-point cells on their owner.
    "one_point": ("tests/scenes/mpi_weak_layer.toml", ("--set", 'materials.weak.plasticity.integration="reduced"')),
    # Q2 (tensor-form element loop), stiffness-proportional Rayleigh damping (halo cells damp too),
    # float32 matrix blocks, and a plasticity zone at x < 50 m that some ranks do not reach.
    "zone": ("tests/scenes/mpi_q2_zone.toml", ()),
    # A cavity in a mesh of a user's gmsh script (tetrahedra, unnamed traction-free wall, rollers).
    "cavity": ("tests/scenes/mpi_tunnel_tet.toml", ()),
    # Roller y faces (plane strain, kernel constraints with reactions) under a vertical P wave.
    "rollers": ("workflows/scenes/box_vertical_sv.toml", ("--set", "boundary.face.ymin.type=roller", "--set",
                                                          "boundary.face.ymax.type=roller", "--set", "wave.type=P")),
}

# The scenes also run on 3 ranks.
THREE_RANKS = ("free_field", "contact", "damage", "zone")


def pyfem_run(ranks: int, scene: str, out_dir: Path, *extra: str) -> subprocess.CompletedProcess:
    command = [PYTHON, "-m", "pyfem", "run", scene, "--out", str(out_dir), *extra]
    if ranks > 1:
        assert MPIRUN is not None, "mpirun not found: scripts/setup.sh installs openmpi-bin"
        command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    result = subprocess.run(command, cwd=REPO, env=ENV, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{(scene, ranks): run directory} for 1 and 2 ranks, and 3 for THREE_RANKS."""
    base = tmp_path_factory.mktemp("mpi")
    out = {}
    for name, (scene, extra) in SCENES.items():
        for ranks in (1, 2, 3) if name in THREE_RANKS else (1, 2):
            out[name, ranks] = base / f"{name}_{ranks}"
            pyfem_run(ranks, scene, out[name, ranks], *extra)
    return out


# Net forces of a long wave on a fine mesh: a = (f - K u) / m, where K u is (omega_max / omega)^2
# ~ 1e6 times m a for the cavity scene's 2 Hz wavelet and its 0.4 m tetrahedra at the wall, so
# round-off of the sums in another order (1e-16 of K u) is ~1e-10 of the accelerations and of the
# rollers' reactions there (measured 6e-10 and 3e-10 with the serial product's scalar order; 1.25e-9
# for the accelerations since it sums a row's blocks lane by lane (AVX2, cpp_kernels/symmetric_bsr.hpp);
# u 3e-15, v 3e-12, stress 5e-12).
NET_FORCE_TOLERANCE = {"cavity": {"acceleration": 3.0e-9, "reaction": 1.0e-9}}


def assert_equal_to_serial(run_dir: Path, serial: Path, tolerances: dict | None = None) -> float:
    """Every history to TOLERANCE (or `tolerances` per dimension, pyfem.compare.dimension); fields.h5
    datasets to TOLERANCE; returns the largest difference."""
    differences = largest_differences(run_dir, serial)
    for kind, difference in differences.items():
        assert difference < (tolerances or {}).get(kind, TOLERANCE), (kind, difference)
    worst = max(differences.values())
    if (serial / "fields.h5").exists():
        with h5py.File(serial / "fields.h5") as expected, h5py.File(run_dir / "fields.h5") as got:
            names = []
            expected.visit(lambda name: names.append(name) if isinstance(expected[name], h5py.Dataset) else None)
            assert names
            for name in names:
                a, b = np.asarray(expected[name], dtype=float), np.asarray(got[name], dtype=float)
                assert a.shape == b.shape, name
                assert np.abs(a - b).max() <= TOLERANCE * max(np.abs(a).max(), 1e-300), name
    return worst


def summary(run_dir: Path) -> dict:
    return json.loads((run_dir / "run.json").read_text())


@pytest.mark.parametrize("name, ranks", [(name, ranks) for ranks in (2, 3) for name in SCENES
                                         if ranks == 2 or name in THREE_RANKS])
def test_mpirun_equals_the_serial_run(runs, name, ranks):
    serial, parallel = summary(runs[name, 1]), summary(runs[name, ranks])
    # Something happened, the same in both.
    if name == "free_field":
        assert serial["monitors"]["centre"]["displacement"] > 5.0e-4  # the 1 mm pulse arrived
    if name == "contact":
        assert max(serial["pair_states"]["sliding"]) > 0 and max(serial["pair_states"]["separated"]) > 0
    if name == "contact_lag":
        # The pairs slid (with the lag none of them opens in this scene), and the lag
        # acted: the histories differ from the lag-free run's by more than round-off.
        assert max(serial["pair_states"]["sliding"]) > 0
        assert largest_difference(runs[name, 1], runs["contact", 1]) > 1e-4
    if name in ("contact", "contact_lag"):
        assert parallel["pair_states"] == serial["pair_states"]
    if name == "cavity":
        assert "(unnamed)" in serial["traction_free_surfaces"], "the tunnel's wall is free, not an input face"
        crown = serial["monitors"]["crown"]
        assert crown["displacement"] > 2e-4 and crown["s1_dynamic_max"] > 1e3, "the wave reached the wall"
    if name == "rollers":
        reactions = np.loadtxt(runs[name, 1] / "reactions.csv", delimiter=",", skiprows=1)
        assert np.abs(reactions[:, 2]).max() > 1e8  # the rollers hold the P wave's lateral stress
    if name == "zone":
        assert serial["nonlinear_regions"]["weak"]["yielded_volume"] > 0.0
        assert serial["energy"]["damping_work"] > 0.0
        if ranks == 3:
            assert 0 in parallel["mpi"]["element_loop_cells"], "a rank without element-loop cells"
        assert sum(parallel["mpi"]["element_loop_cells"]) == serial["nonlinear_regions"]["weak"]["cells"]
    if name == "one_point":
        assert serial["nonlinear_regions"]["weak"]["points"] == serial["nonlinear_regions"]["weak"]["cells"]
    if name == "damage":
        # Each sample gathers what it reads (the monitors' nodes and law values, the pairs, the
        # energy, the deformed section's nodes); fields (every 20th sample) and the last sample
        # the whole state. Here the section is a fifth of this small model's nodes: 5x fewer bytes.
        mpi = parallel["mpi"]
        assert all(light >= 15 * whole > 0 for light, whole in zip(mpi["light_merges"], mpi["whole_merges"]))
        assert all(3 * light < whole for light, whole in zip(mpi["bytes_per_light_merge"], mpi["bytes_per_whole_merge"]))
    if name in ("damage", "one_point"):
        weak = serial["nonlinear_regions"]["weak"]
        assert weak["yielded_volume"] > 0.0 and weak["peak_damage"] > 0.0
        for key, value in weak.items():
            got = parallel["nonlinear_regions"]["weak"][key]
            assert got == pytest.approx(value, rel=TOLERANCE, abs=TOLERANCE * abs(weak["dissipated_energy"])), key
    # The ranks shared the model.
    mpi = parallel["mpi"]
    assert mpi["ranks"] == ranks and sum(mpi["owned_nodes"]) == serial["nodes"]
    assert all(n > 0 for n in mpi["owned_nodes"]) and all(n > 0 for n in mpi["ghost_nodes"])
    assert all(b > 0 for b in mpi["bytes_sent_per_step"])
    assert "mpi" not in serial
    # Every rank builds the whole model: the other ranks' peak memory is of rank 0's size (rank 0
    # also holds the writer). (The serial run here is in the test's process: its peak is that
    # process's, whatever it ran before.)
    assert all(0.5 * mpi["peak_memory_mib"][0] <= peak <= 1.5 * mpi["peak_memory_mib"][0]
               for peak in mpi["peak_memory_mib"])
    worst = assert_equal_to_serial(runs[name, ranks], runs[name, 1], NET_FORCE_TOLERANCE.get(name))
    for monitor, peaks in serial["monitors"].items():
        for key, value in peaks.items():
            if isinstance(value, float):
                assert parallel["monitors"][monitor][key] == pytest.approx(value, rel=1e-9, abs=1e-12), (monitor, key)
    assert parallel["energy"]["balance_error"] < 1e-12
    print(f"{name} on {ranks} ranks: largest difference from serial {worst:.2e}; owned {mpi['owned_nodes']}, "
          f"ghosts {mpi['ghost_nodes']}, bytes per step {mpi['bytes_sent_per_step']}")


def test_check_under_mpirun_prints_the_plan_once_with_the_ranks_share():
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem",
                             "check", SCENES["contact"][0]], cwd=REPO, env=ENV, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.count("title:") == 1
    line = next(text for text in result.stdout.splitlines() if text.startswith("MPI ranks:"))
    assert "2: owned nodes [" in line and "ghost nodes" in line


# A key refused when the scene is read, and one refused after every rank has built the model (local
# time stepping with float32 matrix blocks, which it does not step).
@pytest.mark.parametrize("settings, key", [(("time.duration=-1",), "time.duration"),
                                           (("time.local_stepping=true", 'time.matrix_precision="single"'),
                                            "time.local_stepping")])
def test_a_bad_key_under_mpirun_is_one_line_and_exit_2(settings, key):
    sets = [arg for setting in settings for arg in ("--set", setting)]
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem",
                             "run", SCENES["free_field"][0], *sets], cwd=REPO, env=ENV,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and key in errors[0], result.stderr
    assert "Traceback" not in result.stderr


def test_a_failure_on_one_rank_ends_every_rank(tmp_path):
    """Rank 0 cannot start its writer after the ranks have shared the model (RunWriter.start raises
    FileExistsError in the ranks' own processes, as a file named monitors/ in the run directory did
    before `--out` refused such a directory up front, below): it says so and MPI_Abort ends the job,
    instead of rank 1 waiting forever in its next exchange."""
    out = tmp_path / "blocked"
    code = ("import sys\nfrom pyfem import cli, output\n"
            "def blocked(self):\n    raise FileExistsError(17, 'File exists', str(self.out_dir / 'monitors'))\n"
            "output.RunWriter.start = blocked\n"
            f"sys.exit(cli.main(['run', {SCENES['free_field'][0]!r}, '--out', {str(out)!r}]))\n")
    began = time.monotonic()
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-c", code],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
    assert result.returncode != 0
    assert "error: rank 0 of 2: FileExistsError" in result.stderr and "ending every rank" in result.stderr
    assert time.monotonic() - began < 120


def test_a_run_failing_between_whole_merges_leaves_no_stale_material_summary(tmp_path):
    """A write that fails on rank 0 at a sample that gathered only what it reads (the damage scene:
    fields every 20th sample, the failure at the 31st): run.json says "failed" and leaves the
    material regions out, saying why, rather than reporting the points as of the last field sample."""
    out = tmp_path / "failed"
    code = ("import sys\nfrom pyfem import cli, output\n"
            "sample = output.RunWriter.sample\n"
            "def failing(self, *args, **kwargs):\n"
            "    if self._sample_count == 30:\n        raise OSError(28, 'No space left on device')\n"
            "    return sample(self, *args, **kwargs)\n"
            "output.RunWriter.sample = failing\n"
            f"sys.exit(cli.main(['run', {SCENES['damage'][0]!r}, '--out', {str(out)!r}]))\n")
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-c", code],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
    assert result.returncode != 0 and "No space left on device" in result.stderr
    failed = summary(out)
    assert failed["status"] == "failed" and failed["time_reached"] == pytest.approx(29 * 0.005)
    assert "nonlinear_regions" not in failed and "whole state" in failed["nonlinear_regions_note"]


def test_a_directory_of_the_users_files_is_refused_under_mpirun_too(tmp_path):
    """A file of the user's in the run directory: one line, exit 2, before anything is shared, and the
    file as it was."""
    out = tmp_path / "blocked"
    out.mkdir()
    (out / "monitors").write_text("in the way\n")
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem",
                             "run", SCENES["free_field"][0], "--out", str(out)], cwd=REPO, env=ENV,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--out" in errors[0] and "not a run of pyfem (monitors)" in errors[0], result.stderr
    assert "Traceback" not in result.stderr
    assert (out / "monitors").read_text() == "in the way\n"  # nothing of the user's overwritten


CHECKPOINTED_RUN = ("--set", "output.checkpoint_interval=0.5", "--set", "time.duration=3.0")


def kill_after_first_checkpoint(ranks: int, scene: str, out: Path, window: float, extra: tuple = ()) -> None:
    """Starts `pyfem run` on `ranks` ranks and kills it (kill -9: mpirun and every rank) at a random
    time within `window` s after its first checkpoint."""
    command = [PYTHON, "-m", "pyfem", "run", scene, "--out", str(out), *CHECKPOINTED_RUN, *extra]
    if ranks > 1:
        command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    deadline = time.monotonic() + 300
    while not (out / checkpoint.CHECKPOINT_NAME).exists():
        assert process.poll() is None, "the run ended before its first checkpoint"
        assert time.monotonic() < deadline, "no checkpoint after 300 s"
        time.sleep(0.05)
    time.sleep(random.uniform(0.0, window))
    kill_9(process)
    assert json.loads((out / "run.json").read_text())["status"] == "running"  # as a killed run leaves it


def killed_and_resumed(tmp_path: Path, ranks: int, resumed_on: int, window: float, name: str = "contact",
                       extra: tuple = ()) -> tuple[Path, Path, dict]:
    """(the killed and resumed run, the uninterrupted run on `ranks`, the resumed run's run.json) of
    the scene SCENES[name] (and `extra` settings), killed on `ranks` ranks after its first
    checkpoint, resumed on `resumed_on`."""
    scene, settings = SCENES[name]
    extra = (*settings, *extra)
    reference, out = tmp_path / "reference", tmp_path / "killed"
    pyfem_run(ranks, scene, reference, *CHECKPOINTED_RUN, *extra)
    kill_after_first_checkpoint(ranks, scene, out, window, extra)
    pyfem_run(resumed_on, scene, out, *CHECKPOINTED_RUN, *extra, "--resume")
    resumed = summary(out)
    assert resumed["status"] == "finished" and resumed.get("mpi", {}).get("ranks", 1) == resumed_on
    print(f"killed on {ranks} rank(s) at t > {resumed['resumed'][0]['t']:.3f} s; resumed on {resumed_on}")
    return out, reference, resumed


def test_kill_9_of_two_ranks_then_resume_on_two_gives_the_uninterrupted_run(tmp_path):
    out, reference, _ = killed_and_resumed(tmp_path, ranks=2, resumed_on=2, window=1.0)
    assert histories(out) == histories(reference)
    scale = scales(reference)
    for name in histories(reference):
        if name.name == "energy.csv":
            # The account's partial sums are regrouped on resume (rank 0 takes the totals).
            assert relative_difference(out / name, reference / name, scale) < 1e-13
        else:  # kinematics, pair and material states: their own values, restored
            assert (out / name).read_bytes() == (reference / name).read_bytes(), name


@pytest.mark.slow  # (68 s; the default tier resumes 2 ranks on 2 and 3, and a serial LTS checkpoint on 2 in the slow tier too)
def test_a_serial_checkpoint_resumes_on_three_ranks(tmp_path):
    """A checkpoint is the serial stepper's state whatever the rank count that wrote it: a serial
    run killed after its first checkpoint continues on 3 ranks to the uninterrupted serial run's
    histories (to round-off: the rest of the run is distributed)."""
    out, reference, _ = killed_and_resumed(tmp_path, ranks=1, resumed_on=3, window=0.5)
    worst = largest_difference(out, reference)
    print(f"largest difference from the uninterrupted serial run {worst:.2e}")
    assert worst < TOLERANCE


def sigterm_to_rank_one(scene: str, out: Path, settings: tuple, rows: int) -> tuple:
    """Starts `pyfem run` of `scene` on 2 ranks, sends SIGTERM to rank 1 only once monitors/layer.csv
    holds more than `rows` lines (written every 2 s), waits for the run's end: (process, stderr)."""
    command = [MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "2", PYTHON, "-m", "pyfem", "run", scene,
               "--out", str(out), *settings]
    process = subprocess.Popen(command, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    layer = out / "monitors" / "layer.csv"
    deadline = time.monotonic() + 300
    while not (layer.exists() and len(layer.read_text().splitlines()) > rows):
        assert process.poll() is None, "the run ended before the signal"
        assert time.monotonic() < deadline, "no samples after 300 s"
        time.sleep(0.05)
    os.kill(rank_pids(process.pid)[1], signal.SIGTERM)
    _, stderr = process.communicate(timeout=300)
    return process, stderr


def test_sigterm_to_one_rank_stops_every_rank_with_a_whole_checkpoint_that_resumes(tmp_path):
    """SIGTERM to rank 1 only, mid-run, of the damage scene (a yielding layer: per-point state):
    every rank stops at the same sample, rank 0 gathers the whole state (the samples in between
    gather only what they read) and writes the checkpoint and an "interrupted" run.json; resumed on
    2 ranks, the histories equal the uninterrupted 2-rank run's byte for byte. (Ctrl-C to mpirun is
    not tested: mpirun kills the ranks a while after passing it on, and whether the checkpoint is
    written first depends on timing: it was in two runs and was not in a third.)"""
    scene, _ = SCENES["damage"]
    # Long enough that the signal (sent once the first rows are on disk, after ~2 s of wall time:
    # the histories are flushed every 2 s) lands well before the ranks finish and restore the
    # default handlers.
    settings = ("--set", "time.duration=6.0", "--set", "output.checkpoint_interval=0")
    reference, out = tmp_path / "reference", tmp_path / "stopped"
    pyfem_run(2, scene, reference, *settings)
    process, stderr = sigterm_to_rank_one(scene, out, settings, rows=20)
    stopped = summary(out)
    assert process.returncode != 0 and stopped["status"] == "interrupted", stderr[-2000:]
    assert (out / checkpoint.CHECKPOINT_NAME).exists() and "Traceback" not in stderr
    assert 0.1 < stopped["time_reached"] < 5.0
    pyfem_run(2, scene, out, *settings, "--resume")
    resumed = summary(out)
    assert resumed["status"] == "finished" and resumed["nonlinear_regions"]["weak"]["yielded_volume"] > 0.0
    assert histories(out) == histories(reference)
    for name in histories(reference):
        if name.name == "energy.csv":  # the account's partial sums are regrouped on resume
            assert relative_difference(out / name, reference / name, scales(reference)) < 1e-13
        else:
            assert (out / name).read_bytes() == (reference / name).read_bytes(), name

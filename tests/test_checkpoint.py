"""Checkpoint and resume (issue 13, docs/checkpoint.md): a run stopped at any time continues from
its last checkpoint to the same histories, fields and run.json peaks, bit for bit.

- kill -9 of a real `python3 -m pyfem run` at a random time after its first checkpoint, then
  `--resume`: every history file equals the uninterrupted run's byte for byte (the default scene:
  a homogeneous box under a vertical SV wave).
- In process, on a scene with every effect that keeps state (static relaxation stage, oblique SV
  through the viscoelastic boundary, contact pairs with deterioration, Mohr-Coulomb plasticity,
  concrete damage): a crash (an exception) some samples after a periodic checkpoint leaves rows
  beyond it, which the resumed run must drop and recompute; Ctrl-C writes its own checkpoint.
  Before comparing, the test asserts that the pairs slid, the rock yielded and the concrete
  damaged after the checkpoint, so the state restored is one that matters.
- A checkpoint of another scene, a finished run resumed without a longer time.duration and a
  directory without one are refused with one line and exit status 2.
- A finished run keeps its final state: `--resume` with a longer time.duration extends it to the
  histories of an uninterrupted run of that duration, byte for byte (issue 51, item 9).
"""
import json
import os
import random
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from pyfem import checkpoint, distributed_model, distributed_stage, solver, static_output
from pyfem.interrupts import RunInterrupted
from pyfem.scene import SceneError, parse_scene

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
ENV = dict(os.environ, PYTHONPATH=str(REPO))
MPa = 1.0e6
CHECKPOINT_T = 0.30  # s: the crash test's checkpoint, after the wave has begun to slide and yield


def history_files(out_dir: Path) -> dict[str, bytes]:
    """Every CSV history of a run directory, by relative path."""
    return {str(path.relative_to(out_dir)): path.read_bytes() for path in sorted(out_dir.rglob("*.csv"))}


def assert_same_run(resumed: Path, reference: Path) -> None:
    """Histories byte for byte, fields and run.json's peaks and energy equal."""
    files, expected = history_files(resumed), history_files(reference)
    assert sorted(files) == sorted(expected)
    for name in expected:
        assert files[name] == expected[name], f"{name} differs from the uninterrupted run's"
    summary, summary_expected = (json.loads((d / "run.json").read_text()) for d in (resumed, reference))
    assert summary["status"] == "finished" and summary["resumed"]
    for key in ("monitors", "energy", "pairs", "pair_states", "nonlinear_regions", "time_reached"):
        assert summary.get(key) == summary_expected.get(key), key
    if "static" in summary_expected:  # the stage as the first sitting solved it
        def solved(stages):  # wall times apart
            return [{key: value for key, value in stage.items() if key != "seconds"} for stage in stages]

        assert solved(summary["static"]["stages"]) == solved(summary_expected["static"]["stages"])
    final = checkpoint.read_checkpoint(resumed, state=False)  # kept: a longer time.duration extends the run
    assert final.final and final.t == pytest.approx(summary["time_reached"]), "a finished run keeps its final state"
    if (reference / "fields.xdmf").exists():
        import meshio

        readers = [meshio.xdmf.TimeSeriesReader(str(d / "fields.xdmf")) for d in (resumed, reference)]
        for reader in readers:
            reader.read_points_cells()
        assert readers[0].num_steps == readers[1].num_steps > 1
        for step in range(readers[1].num_steps):
            (t, points, cells), (t_ref, points_ref, cells_ref) = (reader.read_data(step) for reader in readers)
            assert t == t_ref and sorted(points) == sorted(points_ref) and sorted(cells) == sorted(cells_ref)
            for name in points_ref:
                assert np.array_equal(points[name], points_ref[name]), (t, name)
            for name in cells_ref:
                assert all(np.array_equal(a, b) for a, b in zip(cells[name], cells_ref[name])), (t, name)


# --------------------------------------------------------------------------- kill -9, a real process

SCENE = "workflows/scenes/default.toml"
KILL_RUN = ("--set", "time.duration=1.5", "--set", "output.xdmf_interval=0.1",
            "--set", "output.checkpoint_interval=0.3")


def pyfem_run(out_dir: Path, *extra: str, check: bool = True, env: dict | None = None) -> subprocess.CompletedProcess:
    result = subprocess.run([PYTHON, "-m", "pyfem", "run", SCENE, "--out", str(out_dir), *KILL_RUN, *extra],
                            cwd=REPO, env=env or ENV, capture_output=True, text=True, timeout=600)
    if check:
        assert result.returncode == 0, result.stderr
    return result


def stop_after_first_checkpoint(out: Path, past: float = 0.0) -> None:
    """Starts a 60 s run of SCENE into `out`, stops it with SIGTERM once a checkpoint (at a time after
    `past` s) is on disk, and checks that it stopped as an interrupted run does (exit 128 + SIGTERM)."""
    process = subprocess.Popen([PYTHON, "-m", "pyfem", "run", SCENE, "--out", str(out), *KILL_RUN,
                                "--set", "time.duration=60"], cwd=REPO, env=ENV, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300

    def reached() -> float:
        try:
            return checkpoint.read_checkpoint(out, state=False).t
        except SceneError:  # none yet
            return -1.0

    while not (out / checkpoint.CHECKPOINT_NAME).exists() or reached() <= past:
        assert process.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    process.send_signal(signal.SIGTERM)
    process.wait(timeout=120)
    assert process.returncode == 128 + signal.SIGTERM


def test_kill_9_at_a_random_time_then_resume_gives_the_uninterrupted_histories(tmp_path):
    pyfem_run(tmp_path / "reference")
    out = tmp_path / "killed"
    process = subprocess.Popen([PYTHON, "-m", "pyfem", "run", SCENE, "--out", str(out), *KILL_RUN], cwd=REPO,
                               env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while not (out / checkpoint.CHECKPOINT_NAME).exists():
        assert process.poll() is None, "the run ended before its first checkpoint"
        assert time.monotonic() < deadline, "no checkpoint after 300 s"
        time.sleep(0.05)
    time.sleep(random.uniform(0.0, 1.0))  # anywhere: inside a sample, a checkpoint, the stepping
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=60)
    assert process.returncode == -signal.SIGKILL, "killed before it finished"
    assert json.loads((out / "run.json").read_text())["status"] == "running"  # as a killed run leaves it
    resumed = pyfem_run(out, "--resume")
    assert "run finished" in resumed.stdout
    summary = json.loads((out / "run.json").read_text())
    print(f"killed at t > {summary['resumed'][0]['t']:.3f} s; resumed; {summary['checkpoints']}")
    assert_same_run(out, tmp_path / "reference")


def test_resume_refuses_another_scene_a_finished_run_and_no_checkpoint(tmp_path):
    out = tmp_path / "run"
    stop_after_first_checkpoint(out)
    before = history_files(out)

    other = pyfem_run(out, "--set", "time.duration=60", "--set", "materials.rock.E=1.0e10", "--resume", check=False)
    assert other.returncode == 2, other.stderr
    lines = other.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "materials.rock.E" in lines[0], other.stderr
    assert "materials.rock.E = 10000000000.0 (the checkpoint's: " in lines[0], other.stderr  # both values
    assert history_files(out) == before, "a refused resume touches nothing"

    missing = pyfem_run(tmp_path / "nothing_here", "--resume", check=False)
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1 and "--resume" in missing.stderr

    pyfem_run(tmp_path / "finished", "--set", "time.duration=0.05")
    finished = pyfem_run(tmp_path / "finished", "--set", "time.duration=0.05", "--resume", check=False)
    # Besides the scene's warning that 0.05 s stops before the Ricker wavelet's peak: one error line.
    errors = [line for line in finished.stderr.splitlines() if not line.startswith("warning: ")]
    assert finished.returncode == 2 and len(errors) == 1 and "finished" in errors[0], finished.stderr


def test_a_checkpoint_of_the_former_serial_path_is_refused_in_one_line(tmp_path):
    """One model (issue 47): the serial path and its one-file checkpoint layout are gone. A run
    directory holding such a checkpoint (its state in one file, no "model" in its record), continued
    with --resume, is refused in one line naming --resume and what to do, exit 2, its files untouched."""
    import json as json_module

    import numpy as np

    from pyfem.checkpoint import CHECKPOINT_NAME, FORMAT, write_atomically

    out = tmp_path / "former"
    pyfem_run(out, "--set", "time.duration=0.02")
    meta = {"format": FORMAT, "t": 0.02, "outputs_done": 2, "fingerprint": {}, "kernel_blocks": [],
            "writer_arrays": []}
    write_atomically(out / CHECKPOINT_NAME, {"u": np.zeros(3), "v": np.zeros(3), "a": np.zeros(3),
                                             "meta": np.frombuffer(json_module.dumps(meta).encode(), dtype=np.uint8)})
    before = history_files(out)
    refused = pyfem_run(out, "--set", "time.duration=0.04", "--resume", check=False)
    errors = [line for line in refused.stderr.splitlines() if line.startswith("error: ")]
    assert refused.returncode == 2 and len(errors) == 1, refused.stderr
    assert "--resume" in errors[0] and "serial path of an earlier version" in errors[0], errors[0]
    assert "Traceback" not in refused.stderr and history_files(out) == before


def test_a_refused_resume_names_every_changed_key_with_both_values_or_another_scene():
    """The fingerprint holds defaults and derived values: a changed friction_angle also changes
    the dynamic_friction_angle that defaults to it, so the refusal lists each differing key (up to
    three) with the scene's and the checkpoint's value, not only the first in alphabetical order;
    a checkpoint of another scene (another title) says so instead of naming its first key."""
    from pyfem.checkpoint import _scene_difference_text

    saved = {"title": "mine", "contact": {"friction_angle": 30.0, "dynamic_friction_angle": 30.0},
             "time": {"duration": 2.0}}
    changed = {"title": "mine", "contact": {"friction_angle": 10.0, "dynamic_friction_angle": 10.0},
               "time": {"duration": 2.0}}
    text = _scene_difference_text(saved, changed)
    assert "contact.friction_angle = 10.0 (the checkpoint's: 30.0)" in text
    assert "contact.dynamic_friction_angle = 10.0 (the checkpoint's: 30.0)" in text
    assert "another scene" in _scene_difference_text(saved, dict(changed, title="default"))
    assert _scene_difference_text(saved, saved) is None
    many = {"title": "mine", "time": {f"k{i}": i for i in range(5)}}
    assert _scene_difference_text({"title": "mine", "time": {}}, many).endswith("; and 2 more")


# --------------------------------------------------------------------------- every stateful effect, in process

def stateful_scene(duration=0.45):
    """Soft rock with Mohr-Coulomb plasticity, a thin concrete-like layer with Eq. 21 damage, both
    interfaces in contact with deterioration, a relaxation stage under a geostatic stress, an
    oblique SV wave strong enough to slide the pairs, yield the rock and crack the layer."""
    soft = {"E": 2.0e9, "nu": 0.30, "rho": 2400.0,
            "plasticity": {"cohesion": 1.0 * MPa, "friction_angle": 25.0, "tensile_strength": 0.1 * MPa, "damage_max": 0.9, "damage_plastic_strain": 0.005}}
    stiff = {"E": 28.0e9, "nu": 0.167, "rho": 2500.0,
             "damage": {"cohesion": 1.8 * MPa, "friction_angle": 46.0, "tensile_strength": 1.5 * MPa}}
    return parse_scene({
        "title": "every stateful effect",
        "mesh": {"builder": "box", "size": [40.0, 4.0, 40.0], "h": 4.0, "order": 1,
                 "layers": [{"material": "soft", "thickness": 19.5}, {"material": "stiff", "thickness": 1.0},
                            {"material": "soft", "thickness": 19.5}]},
        "materials": {"soft": soft, "stiff": stiff},
        "time": {"duration": duration, "safety": 0.8},
        "wave": {"type": "SV", "angle": 20.0, "surface": 45.0, "medium": "soft",
                 "motion": {"ricker": {"f0": 4.0, "amplitude": 0.05}}},
        "initial_stress": {"surface": 45.0, "rho": 2400.0, "k": [1.4, 1.2, 1.15]},
        "static": {"solver": "relaxation"},
        "contact": {"interfaces": ["interface_1", "interface_2"], "cohesion": 2.0e4, "friction_angle": 20.0,
                    "tensile_strength": 1.0e4, "deterioration": {"R0": 0.75, "lambda": 5.0}},
        "monitor": [{"name": "layer", "point": [20.0, 2.0, 20.0]}, {"name": "top", "point": [20.0, 2.0, 40.0]}],
        "pair_monitor": [{"name": "upper", "point": [20.0, 2.0, 20.5]}],
        "output": {"interval": 0.01, "xdmf_interval": 0.05, "fields": ["displacement", "velocity", "stress", "damage"],
                   "checkpoint_interval": 1.0e-9},
    }, source="test")


class StopAt:
    """A progress object (solver.run's `progress`) that raises `error` once t reaches `t_stop`."""

    def __init__(self, t_stop: float, error: BaseException):
        self.t_stop, self.error = t_stop, error

    def start(self, t0):
        pass

    def __call__(self, t):
        if t >= self.t_stop - 1e-12:
            raise self.error


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("checkpoint") / "reference"
    summary = solver.run(stateful_scene(), out)
    return out, summary


def test_the_stateful_scene_slides_yields_and_damages(reference_run):
    """What the resume tests restore is live state: by t = 0.30 s (the crash test's checkpoint)
    pairs have slid and the materials have dissipated, and all of it goes on after."""
    out, summary = reference_run
    rows = np.loadtxt(out / "energy.csv", delimiter=",", skiprows=1)
    columns = (out / "energy.csv").read_text().splitlines()[0].split(",")
    at = int(np.argmin(np.abs(rows[:, 0] - CHECKPOINT_T)))
    for name in ("internal_dissipation", "friction_dissipation"):
        history = rows[:, columns.index(name)]
        assert 0.0 < history[at] < 0.5 * history[-1], f"{name} grows before and after the checkpoint"
    sliding = np.array(summary["pair_states"]["sliding"])
    assert sliding[:at + 1].max() > 0 and sliding[at + 1:].max() > 0
    regions = summary["nonlinear_regions"]
    assert regions["soft"]["yielded_volume"] > 0.0 and regions["stiff"]["peak_damage"] > 0.5, regions
    assert summary["energy"]["balance_error"] < 1e-6


def solve_again(*args, **kwargs):
    raise AssertionError("a resumed run solved the static stage again")


def never_solve_the_stage(patched) -> None:
    """A relaxation stage solved from here on fails the test (the model's stage driver)."""
    patched.setattr(distributed_stage, "solve", solve_again)


def crash_after_a_periodic_checkpoint(monkeypatch, scene, out: Path, every: int, crash_at: float):
    """Runs `scene` into `out` writing a checkpoint at every `every`-th sample only, and crashes it (a
    RuntimeError) at the first sample at or after `crash_at`; returns the checkpoint read back."""
    calls = {"n": 0}

    def every_nth(self):
        calls["n"] += 1
        return calls["n"] % every == 0

    with monkeypatch.context() as patched:
        patched.setattr(checkpoint.CheckpointClock, "due", every_nth)
        with pytest.raises(RuntimeError, match="simulated crash"):
            solver.run(scene, out, progress=StopAt(crash_at, RuntimeError("simulated crash")))
    return checkpoint.read_checkpoint(out)


def test_crash_after_a_periodic_checkpoint_then_resume_gives_the_uninterrupted_run(reference_run, tmp_path,
                                                                                      monkeypatch):
    """Checkpoints every 5th sample only; the run crashes 3 samples after the one at t = 0.30 s, so
    its files hold rows past the checkpoint that the resumed run must drop and recompute."""
    out = tmp_path / "crashed"
    saved = crash_after_a_periodic_checkpoint(monkeypatch, stateful_scene(), out, 5, CHECKPOINT_T + 0.03)
    assert saved.t == pytest.approx(CHECKPOINT_T) and saved.outputs_done == 30
    assert json.loads((out / "run.json").read_text())["status"] == "failed"
    assert (out / "energy.csv").read_text().count("\n") == 1 + 34, "rows past the checkpoint are on disk"
    assert (out / "static" / static_output.HAND_OVER_NAME).exists()
    plans = []
    with monkeypatch.context() as patched:
        never_solve_the_stage(patched)
        summary = solver.run(stateful_scene(), out, resume=True, on_plan=plans.append)
    assert summary["resumed"][0]["t"] == pytest.approx(CHECKPOINT_T)
    # The plan printed says what this sitting does, not only the whole run's estimates.
    assert plans[0]["resuming"] == (f"from the checkpoint at t = {CHECKPOINT_T:.6g} s of 0.45 s; the static stage "
                                    "read from static/hand_over.npz, not solved again")
    assert "static stage estimate" not in plans[0], "no estimate of a stage this sitting does not solve"
    assert_same_run(out, reference_run[0])


def test_a_run_without_its_saved_stage_solves_it_again_and_saves_it(reference_run, tmp_path, monkeypatch):
    """A run directory from before static/hand_over.npz (or with it deleted): the resume solves the
    stage again (deterministic: the same run) and writes the file for the next resume."""
    out = tmp_path / "crashed"
    crash_after_a_periodic_checkpoint(monkeypatch, stateful_scene(), out, 5, CHECKPOINT_T + 0.03)
    saved_stage = out / "static" / static_output.HAND_OVER_NAME
    saved_stage.unlink()
    plans = []
    solver.run(stateful_scene(), out, resume=True, on_plan=plans.append)
    assert plans[0]["resuming"].endswith("; the static stage solved again (no hand-over file of this model)")
    assert plans[0]["static stage estimate"].startswith("2 stages of at most")  # solved again: estimated
    assert saved_stage.exists()
    assert_same_run(out, reference_run[0])


def test_a_set_up_longer_than_the_interval_checkpoints_at_the_first_sample(reference_run, tmp_path, monkeypatch):
    """The paper-scale case study's stage and LTS check take half an hour; a run killed minutes
    into its stepping must not solve them again. The set-up counts towards the first interval: a
    stage that takes longer than `checkpoint_interval` gives a checkpoint at the first sample."""
    interval, stage_seconds = 2.0, 2.5

    def slow(solve):
        def slow_stage(*args, **kwargs):
            time.sleep(stage_seconds)  # the stage of a big model
            return solve(*args, **kwargs)
        return slow_stage

    scene = stateful_scene()
    scene["output"]["checkpoint_interval"] = interval
    out = tmp_path / "crashed"
    with monkeypatch.context() as patched:
        patched.setattr(distributed_stage, "solve", slow(distributed_stage.solve))
        with pytest.raises(RuntimeError, match="simulated crash"):  # 2 samples in, well within an interval
            solver.run(scene, out, progress=StopAt(0.02, RuntimeError("simulated crash")))
    saved = checkpoint.read_checkpoint(out)
    assert saved.t == pytest.approx(0.01) and saved.outputs_done == 1  # the first sample after t = 0
    with monkeypatch.context() as patched:
        never_solve_the_stage(patched)
        solver.run(scene, out, resume=True)
    assert_same_run(out, reference_run[0])


def test_the_clock_counts_the_set_up():
    assert checkpoint.CheckpointClock(60.0, elapsed=61.0).due()
    assert not checkpoint.CheckpointClock(60.0, elapsed=10.0).due()
    assert not checkpoint.CheckpointClock(60.0).due()
    assert not checkpoint.CheckpointClock(0.0, elapsed=1e9).due(), "interval 0: never"


def test_ctrl_c_writes_a_checkpoint_and_resume_continues_from_it(reference_run, tmp_path):
    scene = stateful_scene()
    scene["output"]["checkpoint_interval"] = 0.0  # no periodic checkpoint: the interruption's own
    out = tmp_path / "interrupted"
    with pytest.raises(RunInterrupted):
        solver.run(scene, out, progress=StopAt(0.32, RunInterrupted(signal.SIGINT)))
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    assert checkpoint.read_checkpoint(out).t == pytest.approx(0.32)
    head = checkpoint.read_checkpoint(out, state=False)  # what workflows/case_study.py reads before resuming
    assert head.t == pytest.approx(0.32) and head.u is None and not head.kernel
    head.check_scene(scene)
    solver.run(scene, out, resume=True)
    assert_same_run(out, reference_run[0])


def test_checkpoint_of_another_model_is_refused_before_anything_is_touched(reference_run, tmp_path, monkeypatch):
    out = tmp_path / "run"
    scene = stateful_scene()
    with pytest.raises(RunInterrupted):
        solver.run(scene, out, progress=StopAt(0.05, RunInterrupted(signal.SIGINT)))
    before = history_files(out)
    other = stateful_scene()
    other["contact"]["deterioration"]["R0"] = 0.8

    def not_built(*args, **kwargs):
        raise AssertionError("the model was built (and its static stage solved) before the refusal")

    with monkeypatch.context() as patched:
        patched.setattr(distributed_model, "build", not_built)
        with pytest.raises(SceneError, match=r"contact\.deterioration\.R0"):
            solver.run(other, out, resume=True)
    assert history_files(out) == before
    changed_interval = stateful_scene()
    changed_interval["output"]["checkpoint_interval"] = 600.0  # allowed: it changes nothing computed
    solver.run(changed_interval, out, resume=True)
    assert_same_run(out, reference_run[0])



def fingerprint(deterioration=None, steps: int = 10) -> dict:
    """A model's fingerprint as the model writes it (DistributedRun._fingerprint), without its scene."""
    return {"dofs": 6, "dt": 1e-3, "steps": steps, "ranks": 1, "time_origin": 0.0, "levels": None,
            **({"deterioration": list(deterioration)} if deterioration is not None else {})}


def test_a_checkpoint_of_the_old_wear_clock_is_refused():
    """The wear clock's start (the record's lead-in) is not a scene key but changes what the pairs do:
    a checkpoint whose fingerprint lacks it (written before 2026-11-27, the clock from the run's
    start) or holds another start is refused by name; the same deterioration continues."""
    scene = stateful_scene()
    ours = fingerprint((0.75, 5.0, 20.0, 0.883, 0.02, 0.032, 1.0))
    checkpoint.Checkpoint(path=Path("run/checkpoint.npz"), meta={"fingerprint": ours, "t": 0.0}, u=None, v=None,
                          a=None).check_model(ours, scene, 0.01)
    for old in ({key: value for key, value in ours.items() if key != "deterioration"},
                dict(ours, deterioration=[0.75, 5.0, 20.0, 0.883, 0.02, 0.032, 0.0])):
        with pytest.raises(SceneError, match="deterioration differs from the checkpoint's .*lead-in included"):
            checkpoint.Checkpoint(path=Path("run/checkpoint.npz"), meta={"fingerprint": old, "t": 0.0}, u=None, v=None,
                                  a=None).check_model(ours, scene, 0.01)


def test_a_checkpoint_knows_its_files_by_content_not_by_path(tmp_path):
    """A record file copied elsewhere (another clone, a moved project) is the same model; a file with
    other content at the same path is not. A checkpoint written before files were hashed (the path
    in its fingerprint) is compared by the content of the file that path names."""
    import shutil

    record = REPO / "data" / "elcentro_1940_ns.txt"
    moved = tmp_path / "elsewhere" / record.name
    moved.parent.mkdir()
    shutil.copy(record, moved)

    def scene_with(path):
        return parse_scene({
            "title": "record by content", "mesh": {"builder": "box", "size": [20.0, 20.0, 20.0], "h": 10.0},
            "materials": {"rock": {"E": 8.0e9, "nu": 0.25, "rho": 2600.0}}, "time": {"duration": 0.1},
            "wave": {"type": "SV", "motion": {"record": {"file": str(path), "units": "g", "pga": 0.32}}},
        }, source="test")

    here = checkpoint.scene_fingerprint(scene_with(record))
    assert here["wave"]["motion"]["record"]["file"].startswith("sha256:")
    assert checkpoint.scene_fingerprint(scene_with(moved)) == here
    saved = checkpoint.Checkpoint(path=tmp_path / "checkpoint.npz", meta={"fingerprint": {"scene": here}},
                                  u=np.zeros(1), v=np.zeros(1), a=np.zeros(1))
    saved.check_scene(scene_with(moved))
    older = json.loads(json.dumps(here))
    older["wave"]["motion"]["record"]["file"] = str(record)  # as written before FILE_KEYS
    checkpoint.Checkpoint(path=saved.path, meta={"fingerprint": {"scene": older}}, u=saved.u, v=saved.v,
                          a=saved.a).check_scene(scene_with(moved))
    moved.write_text(moved.read_text().replace("0", "1", 1))
    with pytest.raises(SceneError, match=r"wave\.motion\.record\.file"):
        saved.check_scene(scene_with(moved))


def test_the_normal_lag_resumes_bit_for_bit(tmp_path, monkeypatch):
    """Sliding between dissimilar rocks with [contact.normal_lag] (the slip study's scene, h = 2.5 m):
    a crash after a checkpoint taken while the pair slides, resumed, gives the uninterrupted run's
    histories byte for byte (the pairs' N* is in the checkpoint)."""
    import sys
    sys.path.insert(0, str(REPO / "workflows"))
    from interface_slip_accuracy import scene

    reference = tmp_path / "reference"
    solver.run(scene(1, 2.5, 0.8, "bimaterial, lag"), reference)
    pairs = np.genfromtxt(reference / "pairs" / "I1.csv", delimiter=",", names=True)
    at = int(np.argmin(np.abs(pairs["t"] - 0.35)))
    assert pairs["state"][at - 20:at + 1].max() == 2, "the pair slides before the checkpoint"
    out = tmp_path / "crashed"
    saved = crash_after_a_periodic_checkpoint(monkeypatch, scene(1, 2.5, 0.8, "bimaterial, lag"), out, 20, 0.36)
    assert "contact/effective_normal" in saved.kernel or any("effective_normal" in name for name in saved.kernel)
    solver.run(scene(1, 2.5, 0.8, "bimaterial, lag"), out, resume=True)
    assert_same_run(out, reference)


def test_a_checkpoint_from_before_the_integration_key_still_resumes(tmp_path):
    """`integration` was added to [materials.NAME.plasticity] / [damage] after checkpoints were first
    written: at its old behaviour ("full") it stays out of the fingerprint, so such a checkpoint
    continues; a scene asking for "reduced" is another model and is refused, naming the key."""
    def scene_with(integration=None):
        plasticity = {"cohesion": 1.0e6, "friction_angle": 30.0, "tensile_strength": 1.0e6}
        if integration is not None:
            plasticity["integration"] = integration
        return parse_scene({
            "title": "later key", "mesh": {"builder": "box", "size": [20.0, 20.0, 20.0], "h": 10.0},
            "materials": {"rock": {"E": 8.0e9, "nu": 0.25, "rho": 2600.0, "plasticity": plasticity}},
            "time": {"duration": 0.1}}, source="test")

    assert scene_with().to_json()["materials"]["rock"]["plasticity"]["integration"] == "full"  # the default
    older = checkpoint.scene_fingerprint(scene_with())
    assert "integration" not in older["materials"]["rock"]["plasticity"]  # as a checkpoint before the key
    saved = checkpoint.Checkpoint(path=tmp_path / "checkpoint.npz", meta={"fingerprint": {"scene": older}},
                                  u=np.zeros(1), v=np.zeros(1), a=np.zeros(1))
    saved.check_scene(scene_with())
    saved.check_scene(scene_with("full"))
    with pytest.raises(SceneError, match=r"materials\.rock\.plasticity\.integration"):
        saved.check_scene(scene_with("reduced"))


LONG_RUN = ("--set", "time.duration=2.0")


@pytest.fixture(scope="module")
def two_seconds(tmp_path_factory):
    """The default scene run for 2 s from the start: what a run extended to 2 s must equal."""
    out = tmp_path_factory.mktemp("two_seconds") / "reference"
    pyfem_run(out, *LONG_RUN)
    return out


def test_an_interrupted_run_continues_to_a_later_duration(tmp_path, two_seconds):
    """A run stopped (SIGTERM) after its first checkpoint resumes with a longer time.duration and
    ends as a run of that duration from the start would (histories byte for byte); a duration that
    ends before the checkpoint's time is refused in one line. Catches the refusal a user met when
    extending a long record's run, and a continuation that restarts or drops the earlier part."""
    long_run = LONG_RUN
    out = tmp_path / "stopped"
    stop_after_first_checkpoint(out, past=0.1)  # (half of it a whole number of output intervals earlier)
    reached = json.loads((out / "run.json").read_text())["time_reached"]
    assert 0.0 < reached < 2.0, reached  # stopped before the reference's end
    before = history_files(out)
    short = pyfem_run(out, "--set", f"time.duration={reached / 2:.6g}", "--resume", check=False)
    errors = [line for line in short.stderr.splitlines() if line.startswith("error: ")]
    assert short.returncode == 2 and len(errors) == 1 and "ends before the checkpoint's t" in errors[0], short.stderr
    assert history_files(out) == before  # a refused resume touches nothing
    resumed = pyfem_run(out, *long_run, "--resume")
    assert "run finished" in resumed.stdout
    assert_same_run(out, two_seconds)


def test_a_finished_run_extends_to_a_later_duration(tmp_path, two_seconds):
    """A run that finished at 1 s keeps its final state; `--resume` with time.duration = 2 s
    continues it to 2 s, appending to the monitors, energy.csv and the fields: every history byte
    for byte, every field and run.json's peaks as the run of 2 s from the start, and its energy
    balance within 1e-10. The same or a shorter duration is refused in one line (exit 2), the
    directory untouched. Catches a finished run that cannot be extended, and an extension that
    restarts, drops or rewrites the first second."""
    out = tmp_path / "extended"
    finished = pyfem_run(out, "--set", "time.duration=1.0")
    assert "checkpoint.npz extends the run: --resume with a longer time.duration" in finished.stdout
    first = json.loads((out / "run.json").read_text())
    assert first["status"] == "finished" and first["time_reached"] == 1.0
    before = history_files(out)
    for duration, words in ((1.0, "adds nothing to it"), (0.5, "ends before it")):
        refused = pyfem_run(out, "--set", f"time.duration={duration}", "--resume", check=False)
        errors = [line for line in refused.stderr.splitlines() if not line.startswith("warning: ")]
        assert refused.returncode == 2 and len(errors) == 1, refused.stderr
        assert "time.duration" in errors[0] and "finished at t = 1 s" in errors[0] and words in errors[0], errors[0]
        assert history_files(out) == before, "a refused extension touches nothing"
    extended = pyfem_run(out, *LONG_RUN, "--resume")
    assert "from the checkpoint at t = 1 s of 2 s" in extended.stdout and "run finished" in extended.stdout
    files = history_files(out)
    for name, content in before.items():  # the first second kept as written, the rest appended
        assert files[name].startswith(content) and len(files[name]) > len(content), name
    summary = json.loads((out / "run.json").read_text())
    assert summary["resumed"][0]["t"] == 1.0 and summary["time_reached"] == 2.0
    assert summary["scene"]["time"]["duration"] == 2.0 and summary["steps"] == json.loads(
        (two_seconds / "run.json").read_text())["steps"]
    assert 0.0 < summary["energy"]["balance_error"] < 1e-10, summary["energy"]
    assert_same_run(out, two_seconds)


def without_wear(duration: float):
    """stateful_scene without the interfaces' deterioration: with a Ricker wavelet (no record) the
    wear time t_s is time.duration, so that scene at another duration is another model."""
    scene = stateful_scene(duration)
    del scene["contact"]["deterioration"]
    return scene


@pytest.mark.slow  # (three runs of the scene)
def test_a_finished_run_with_every_state_extends_bit_for_bit(tmp_path):
    """In process, the stateful scene (plasticity, damage, sliding pairs, static stage) finished at
    0.30 s and extended to 0.45 s: histories byte for byte as the 0.45 s run from the start, after
    asserting that the pairs slide, the rock yields and the concrete dissipates after 0.30 s."""
    reference = tmp_path / "reference"
    solver.run(without_wear(0.45), reference)
    out = tmp_path / "extended"
    solver.run(without_wear(0.30), out)
    assert checkpoint.read_checkpoint(out, state=False).final
    summary = solver.run(without_wear(0.45), out, resume=True)
    rows = np.loadtxt(reference / "energy.csv", delimiter=",", skiprows=1)
    columns = (reference / "energy.csv").read_text().splitlines()[0].split(",")
    at = int(np.argmin(np.abs(rows[:, 0] - 0.30)))
    for name in ("internal_dissipation", "friction_dissipation"):
        history = rows[:, columns.index(name)]
        assert 0.0 < history[at] < history[-1], f"{name} grows after the extension's start"
    assert summary["resumed"][0]["t"] == pytest.approx(0.30) and summary["energy"]["balance_error"] < 1e-10
    assert_same_run(out, reference)


def test_without_a_record_another_duration_is_another_wear_and_refused():
    """With deterioration and no record t_s = time.duration: an extension would change the wear of the
    part already run, so it is refused in one line naming time.duration."""
    def wear(t_s):
        return fingerprint((0.75, 5.0, t_s, 0.883, 0.02, 0.032, 0.0))

    saved = checkpoint.Checkpoint(path=Path("run/checkpoint.npz"), meta={"fingerprint": wear(0.30), "t": 0.0},
                                  u=None, v=None, a=None)
    saved.check_model(wear(0.30), stateful_scene(), 0.01)
    with pytest.raises(SceneError, match=r"wear time t_s .* is time\.duration"):
        saved.check_model(wear(0.45), stateful_scene(), 0.01)


def test_a_layered_ricker_input_follows_the_duration_and_is_refused():
    """With [[wave.layers]] and a Ricker wavelet the layered free field is an FFT over the run's time:
    a run to 0.3 s extended to 0.6 s differed from the 0.6 s run by up to 0.75 % at its monitors
    (workflows/scenes/layered_site_sv30.toml, measured). Another duration is refused in one line naming
    time.duration; the same duration (an interrupted run resumed) continues; a record through the
    same layers does not depend on the duration."""
    from pyfem.scene import load_scene

    def scene(duration):
        return load_scene(REPO / "workflows/scenes/layered_site_sv30.toml", [f"time.duration={duration}"])

    assert checkpoint.input_follows_duration(scene(0.3))
    saved = checkpoint.Checkpoint(path=Path("run/checkpoint.npz"), meta={"fingerprint": fingerprint(steps=300), "t": 0.0},
                                  u=None, v=None, a=None)
    saved.check_model(fingerprint(steps=300), scene(0.3), 0.3)
    with pytest.raises(SceneError, match=r"wave\.layers.* time\.duration = 0\.6 s is another input") as refused:
        saved.check_model(fingerprint(steps=600), scene(0.6), 0.6)
    assert refused.value.key == "time.duration" and "\n" not in str(refused.value)
    recorded = scene(0.3)
    recorded["wave"]["motion"] = {"record": {"file": "elcentro.txt"}}
    assert not checkpoint.input_follows_duration(recorded)

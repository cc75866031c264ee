"""Runs survive interrupts: a real SIGINT or SIGTERM sent to a real `python3 -m pyfem run`.

The child runs the default scene (homogeneous box, vertical SV) for 60 s of motion, far longer
than the test waits: once run.json says "running" and the monitors hold some rows, the signal is
sent with `Popen.send_signal`. The run must stop between two samples with exit status 128 + the
signal number and one line on stderr (no traceback), run.json must say "interrupted" with the
time reached, and every history must hold every sample from t = 0 to that time. Reruns into the
same --out keep the earlier runs as `<dir>.previous`, `<dir>.previous-2`.
"""
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
ENV = dict(os.environ, PYTHONPATH=str(REPO))
SCENE = "workflows/scenes/default.toml"
INTERVAL = 0.005  # output.interval of the default scene (s)
MONITORS = ("centre", "top", "bottom", "corner")
LONG_RUN = ("--set", "time.duration=60", "--set", "output.xdmf_interval=0.5")
SHORT_RUN = ("--set", "time.duration=0.05", "--set", "output.xdmf_interval=0")
ROWS_BEFORE_SIGNAL = 40


def command(out_dir: Path, *overrides: str) -> list[str]:
    """`python3 -m pyfem run` of the default scene into out_dir."""
    return [PYTHON, "-m", "pyfem", "run", SCENE, "--out", str(out_dir), *overrides]


def start_run(out_dir: Path, *overrides: str) -> subprocess.Popen:
    """The run as a child process (stdout and stderr captured)."""
    return subprocess.Popen(command(out_dir, *overrides), cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def finished_run(out_dir: Path) -> subprocess.CompletedProcess:
    """A short run to its end."""
    result = subprocess.run(command(out_dir, *SHORT_RUN), cwd=REPO, env=ENV, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    return result


def run_status(out_dir: Path) -> str | None:
    try:
        return json.loads((out_dir / "run.json").read_text())["status"]
    except (FileNotFoundError, json.JSONDecodeError, KeyError):
        return None


def wait_until_running_with_rows(process: subprocess.Popen, out_dir: Path, rows: int, timeout: float = 300.0):
    """Waits for run.json "running" and `rows` complete rows in monitors/centre.csv (s of wall time)."""
    history = out_dir / "monitors" / "centre.csv"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            pytest.fail(f"the run ended (status {process.returncode}) before the signal: "
                        f"{process.stderr.read()}")
        if run_status(out_dir) == "running" and history.exists() and history.read_text().count("\n") > rows:
            return
        time.sleep(0.1)
    process.kill()
    pytest.fail(f"no {rows} monitor rows after {timeout} s")


def interrupt(out_dir: Path, signal_number: int) -> tuple[subprocess.Popen, str]:
    """Starts a long run, sends the signal mid-run; returns the ended process and its stderr."""
    process = start_run(out_dir, *LONG_RUN)
    wait_until_running_with_rows(process, out_dir, ROWS_BEFORE_SIGNAL)
    process.send_signal(signal_number)
    try:
        _, stderr = process.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail("the run did not stop within 120 s of the signal")
    return process, stderr


def assert_every_row_up_to(out_dir: Path, time_reached: float) -> int:
    """Every history holds whole rows at t = 0, INTERVAL, ..., time_reached; returns the row count."""
    files = [out_dir / "energy.csv"] + [out_dir / "monitors" / f"{name}.csv" for name in MONITORS]
    counts = []
    for path in files:
        with open(path) as stream:
            header = stream.readline().strip().split(",")
        rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)  # a half-written row fails here
        assert rows.shape[1] == len(header), path
        assert np.all(np.isfinite(rows)), path
        t = rows[:, 0]
        assert np.allclose(t, INTERVAL * np.arange(len(t)), rtol=0, atol=1e-9), path
        assert t[-1] == pytest.approx(time_reached, abs=1e-12), path
        counts.append(len(t))
    assert len(set(counts)) == 1, counts
    return counts[0]


def assert_interrupted(process, stderr: str, out_dir: Path, signal_number: int, reason: str) -> float:
    """Exit status, the one-line message and run.json of an interrupted run; returns the time reached."""
    assert process.returncode == 128 + signal_number, stderr
    assert "Traceback" not in stderr
    last_line = stderr.strip().splitlines()[-1]
    assert last_line.startswith("error: interrupted at t = ") and f"kept in {out_dir} " in last_line
    # The interruption's checkpoint (tests/test_checkpoint.py resumes from one).
    assert (out_dir / "checkpoint.npz").exists() and last_line.endswith("--resume)")
    run_json = json.loads((out_dir / "run.json").read_text())
    assert run_json["status"] == "interrupted"
    assert run_json["reason"] == reason
    time_reached = run_json["time_reached"]
    assert f"t = {time_reached:.6g} s" in last_line
    assert 0.0 < time_reached < 60.0
    rows = assert_every_row_up_to(out_dir, time_reached)
    print(f"{signal.Signals(signal_number).name}: stopped at t = {time_reached:.4g} s, "
          f"{rows} rows per history")
    assert rows > ROWS_BEFORE_SIGNAL
    return time_reached


def test_sigint_mid_run_keeps_every_row_and_reruns_keep_earlier_runs(tmp_path):
    out = tmp_path / "run"
    process, stderr = interrupt(out, signal.SIGINT)
    time_reached = assert_interrupted(process, stderr, out, signal.SIGINT, "interrupted by SIGINT")
    # The fields were closed cleanly: a reader this project did not write opens them.
    import meshio

    with meshio.xdmf.TimeSeriesReader(str(out / "fields.xdmf")) as reader:
        reader.read_points_cells()
        times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
    assert times[0] == 0.0 and times[-1] <= time_reached + 1e-9 and len(times) >= 1

    # A second run into the same directory keeps the interrupted one as .previous ...
    second = finished_run(out)
    previous = tmp_path / "run.previous"
    assert f"note: the earlier run in {out} was moved to {previous}" in second.stderr
    assert run_status(out) == "finished"
    assert run_status(previous) == "interrupted"
    assert assert_every_row_up_to(previous, time_reached) > ROWS_BEFORE_SIGNAL
    # ... and a third keeps the second as .previous-2, the first still as .previous.
    third = finished_run(out)
    assert f"moved to {tmp_path / 'run.previous-2'}" in third.stderr
    assert run_status(tmp_path / "run.previous-2") == "finished"
    assert run_status(previous) == "interrupted"
    assert run_status(out) == "finished"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["run", "run.previous", "run.previous-2"]


def test_sigterm_mid_run_is_an_interrupt_too(tmp_path):
    out = tmp_path / "run"
    process, stderr = interrupt(out, signal.SIGTERM)
    assert_interrupted(process, stderr, out, signal.SIGTERM, "interrupted by SIGTERM")


def test_a_stop_in_the_set_up_says_what_was_lost(tmp_path, monkeypatch, capsys):
    """A stop while the model is built or its static stage solved (minutes on the case scenes) keeps
    nothing: one line says so and that the next run does the set-up again; no directory is made."""
    from pyfem import cli, distributed_model
    from pyfem.interrupts import RunInterrupted

    def stopped(*args, **kwargs):
        raise RunInterrupted(signal.SIGINT)

    monkeypatch.setattr(distributed_model, "build", stopped)  # the model's set-up
    status = cli.main(["run", str(REPO / SCENE), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 130
    assert len(err) == 1 and err[0].startswith("error: interrupted in the set-up (mesh, matrices) after ")
    assert err[0].endswith("nothing written, and the next run does the set-up again")
    assert not (tmp_path / "run").exists()

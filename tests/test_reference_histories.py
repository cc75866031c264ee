"""Today's histories, recorded (workflows/reference_histories.py, records in
workflows/results/reference_histories/): the net under the merge of the serial and the
distributed-model MPI paths into one (issue "One model, one time loop, one writer"); the serial
path is gone, and its records are the net that a one-rank run of the one model still reproduces.

Each scene is rerun with the command line its record was made with and every column of every
monitor, pair monitor and energy history must equal the recorded one within 1e-10 of the column's
largest |value| (a column of round-off: of 1 % of its dimension's largest value); so must the numbers
of run.json's key numbers and of the static stage's static.json. The MPI paths' measured exceptions
and why: the workflow's docstring and `Entry.mpi`.
- default tier: the records are complete and were made with today's scene settings, and the three
  cheap scenes (the free-field box, the contact layers, the yielding layer under cracking concrete)
  rerun on one rank (20 s in all, measured);
- slow tier: the other three on one rank, and every scene on the distributed model on 2 and 3 ranks
  (`mpirun`; a missing launcher fails; the whole-model MPI path these records also covered is gone).
"""
import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "workflows"))
import reference_histories as rh  # noqa: E402


def assert_reproduces(name: str, out: Path, model, ranks: int) -> None:
    differences = rh.compare(name, out, model, ranks)
    for part, values in differences.items():
        key, value = rh.worst(values)
        print(f"{name} {rh.path_label(model, ranks)}: {part} largest {value:.2e} ({key}) of {len(values)}")
    assert len(differences["histories"]) > 20 and len(differences["summary"]) > 20
    above = rh.above(name, model, ranks, differences)
    assert not above, sorted(above.items(), key=lambda item: -item[1][0])[:10]


def test_every_scene_has_a_complete_record_of_todays_command_line():
    for name, entry in rh.SCENES.items():
        record = rh.RECORDS / name
        summary = json.loads((record / "summary.json").read_text())
        line = " ".join(rh.command(name, Path(f"runs/reference_histories/{name}")))
        assert summary["record"]["command"] == line, name
        expected = rh.RERECORDED.get(name, (rh.BASE_COMMIT, ""))[0]
        assert summary["status"] == "finished" and summary["record"]["commit"] == expected, name
        names = rh.history_files(record)
        assert any(str(p).startswith("monitors/") for p in names) and Path("energy.csv") in names, name
        for relative in names:
            header, rows = rh.read_history(record / relative)
            assert len(header) == rows.shape[1] and rows.shape[0] >= 5, relative
            assert abs(rows[:, 1:]).max() > 0.0, (name, relative)  # something moved
        assert (record / "static" / "static.json").exists() == ("case3" in name)
    assert (rh.RECORDS / "README.md").exists()


SERIAL = [pytest.param(name, marks=() if entry.cheap else pytest.mark.slow) for name, entry in rh.SCENES.items()]


@pytest.mark.parametrize("name", SERIAL)
def test_a_run_on_one_rank_reproduces_the_serial_record(name, tmp_path):
    """One model (issue 47): a run without mpirun is the distributed model's one-rank case, and it
    reproduces the records of the serial path it replaced, every summary key included (its
    pictures' numbers, dt_critical, the local stepping check, case3_small's stage and static.json)."""
    out = tmp_path / name
    rh.run(name, out)
    assert json.loads((out / "run.json").read_text())["model"] == "distributed"  # the one model
    assert_reproduces(name, out, None, 1)


MPI = [(name, model, ranks) for model, ranks in rh.PATHS if model is not None for name in rh.SCENES]


@pytest.mark.slow
@pytest.mark.parametrize("name, model, ranks", MPI)
def test_the_mpi_paths_reproduce_the_serial_record(name, model, ranks, tmp_path, mpi_launcher):
    refusal = rh.REFUSED.get(name, {}).get((model, ranks))
    if refusal is not None:  # the path refuses the scene: with its one line, exit 2
        with pytest.raises(RuntimeError, match=r"exit 2") as error:
            rh.run(name, tmp_path / name, ranks, model)
        assert refusal in str(error.value)
        return
    out = tmp_path / name
    rh.run(name, out, ranks, model)
    assert_reproduces(name, out, model, ranks)

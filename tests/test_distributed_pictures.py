"""The model writes the run's pictures and run.json keys on every rank count (issue 47, one model;
pyfem/distributed_view.py): a small layered box (a Mohr-Coulomb layer between rock and cracking
concrete, over geostatic stress, under an oblique SV wavelet) run on one rank and on 2 ranks
(mpirun). Both write the same plot files and the same run.json keys; the numbers of the pictures (the
deformed section's largest displacement, its time and magnification, the end section's cells and
peaks) and the critical step (one power iteration from a function of the node coordinates) agree to
round-off. (That one rank draws the serial path's numbers to the bit is in the reference records'
summaries, tests/test_reference_histories.py.)
"""
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"

SCENE = """
title = "small layers for the pictures"

[mesh]
builder = "box"
size = [40.0, 10.0, 30.0]
h = 5.0
layers = [{material = "lower", thickness = 10.0}, {material = "weak", thickness = 10.0},
          {material = "concrete", thickness = 10.0}]

[materials.lower]
E = 8.0e9
nu = 0.25
rho = 2600.0

[materials.weak]
E = 8.0e9
nu = 0.25
rho = 2600.0
plasticity = {cohesion = 1.0e5, friction_angle = 30.0, tensile_strength = 1.0e6, damage_max = 0.5, damage_plastic_strain = 0.005}

[materials.concrete]
preset = "concrete"

[materials.concrete.damage]

[time]
duration = 0.1

[wave]
type = "SV"
angle = 20.0
surface = 30.0
medium = "lower"
motion = {ricker = {f0 = 10.0, amplitude = 0.008}}

[initial_stress]
surface = 100.0
rho = 500.0
k = [1.0, 1.0, 1.0]

[[monitor]]
name = "layer"
point = [17.5, 2.5, 15.5]

[[monitor]]
name = "rock"
point = [22.5, 2.5, 4.5]

[output]
interval = 0.005
xdmf_interval = 0.0
"""

# What a run writes besides its pictures and numbers: the distributed model keeps its final state as
# per-rank checkpoint files (a longer time.duration and --resume extend the run).
NOT_COMPARED = ("checkpoint",)
# run.json keys only the distributed model writes: its rank count, shares and set-up time.
OWN_KEYS = {"model", "ranks", "mpi", "setup_seconds"}


def run(scene: Path, out: Path, ranks: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
    command = [PYTHON, "-m", "pyfem", "run", str(scene), "--out", str(out)]
    if ranks > 1:
        mpirun = shutil.which("mpirun")
        assert mpirun is not None, "mpirun not found: scripts/setup.sh installs openmpi-bin"
        command = [mpirun, "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return json.loads((out / "run.json").read_text())


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{"one rank" | "two ranks": (run directory, run.json)}."""
    base = tmp_path_factory.mktemp("pictures")
    scene = base / "layers.toml"
    scene.write_text(SCENE)
    return {label: (base / label.replace(" ", "_"), run(scene, base / label.replace(" ", "_"), ranks))
            for label, ranks in (("one rank", 1), ("two ranks", 2))}


def files(out: Path) -> set:
    return {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and not p.name.startswith(NOT_COMPARED)}


def test_two_ranks_write_the_one_rank_runs_files_and_keys(runs):
    one_dir, one = runs["one rank"]
    out, summary = runs["two ranks"]
    assert one["model"] == summary["model"] == "distributed" and summary["mpi"]["ranks"] == 2
    expected = files(one_dir)
    for picture in ("plots/deformed_section.png", "plots/section_end.png", "plots/input.png", "plots/energy.png",
                    "plots/monitor_layer.png"):
        assert picture in expected, picture
    assert files(out) == expected
    for name in expected:
        if name.endswith(".png"):
            assert (out / name).stat().st_size > 10_000, name  # a drawn picture, not an empty file
    assert set(summary) - OWN_KEYS == set(one) - OWN_KEYS


def test_the_pictures_numbers_and_the_critical_step_agree(runs):
    _, one = runs["one rank"]
    _, summary = runs["two ranks"]
    tolerance = 1e-12
    section = one["deformed_section"]
    assert section["largest"] > 1e-6 and 0.0 < section["t"] <= one["time_reached"]  # the wave deformed it
    assert one["section_end"]["cells"] > 0 and one["nonlinear_regions"]["weak"]["peak_plastic_strain"] > 0.0
    for key in ("largest", "magnification", "t", "y"):
        assert summary["deformed_section"][key] == pytest.approx(section[key], rel=tolerance, abs=0.0), key
    assert summary["section_end"]["cells"] == one["section_end"]["cells"]
    for key in ("y", "peak_damage", "peak_plastic_strain"):
        assert summary["section_end"][key] == pytest.approx(one["section_end"][key], rel=1e-10), key
    assert summary["dt_critical"] == pytest.approx(one["dt_critical"], rel=tolerance, abs=0.0)
    assert summary["dt"] == one["dt"] and summary["steps"] == one["steps"]
    assert summary["input_motion"]["pga"] == one["input_motion"]["pga"]


def test_the_section_cut_does_not_depend_on_the_coordinates_round_off():
    """A plane through a layer of nodes cuts one layer of cells whatever the round-off of the nodes'
    y (dolfinx tabulates them per rank): the cells above it, or below it at the model's top."""
    from pyfem.static_plots import section_cells

    y = np.array([[0.0, 5.0], [5.0 + 1e-15, 10.0], [5.0 - 1e-15, 10.0], [10.0, 15.0]])
    assert section_cells(y, 5.0).tolist() == [False, True, True, False]
    assert section_cells(y, 15.0).tolist() == [False, False, False, True]  # the top: the cells below


def test_no_damage_is_drawn_as_no_damage_type():
    """A yielded cell without damage carries the type of its largest plastic strain (shear); the end
    section draws it as type 0 (issue 51)."""
    from pyfem.static_plots import drawn_damage_type

    drawn = drawn_damage_type(np.array([0.0, 0.4, np.nan]), np.array([2, 1, np.nan]))
    assert drawn[:2].tolist() == [0.0, 1.0] and np.isnan(drawn[2])


@pytest.mark.slow  # (the small case 3 built three times, about 1.5 min)
def test_the_wear_line_of_check_is_the_same_on_every_rank_count():
    """Issue 51: under mpirun `check` put the interfaces' wear at the run's end counted from the
    lead-in's start (t = 1.2 s for a 0.2 s run after El Centro's 1 s lead-in; serially 0.2 s). Now the
    end in record time on every rank count."""
    import sys

    sys.path.insert(0, str(REPO / "workflows"))
    import reference_histories as rh

    settings = [arg for setting in (*rh.SMALL_CASE3, "time.duration=0.2") for arg in ("--set", setting)]
    lines = {}
    for label, ranks in (("one rank", 1), ("two ranks", 2)):
        env = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")
        command = [PYTHON, "-m", "pyfem", "check", "workflows/scenes/case3_contact_coarse.toml", *settings]
        if ranks > 1:
            command = [shutil.which("mpirun"), "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
        result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=900)
        assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
        found = [line.split(":", 1)[1].strip() for line in result.stdout.splitlines()
                 if line.startswith("interface wear:")]
        assert len(found) == 1, result.stdout[-3000:]
        lines[label] = found[0]
    assert lines["one rank"].endswith("0.988 at t = 0.2 s")
    assert lines["one rank"] == lines["two ranks"]

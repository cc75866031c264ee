"""Command line: a bad scene is a one-line error with exit status 2 and writes nothing."""
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest

import pyfem
from pyfem import cli

REPO = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"

GOOD_SCENE = """
title = "cli test"
[mesh]
size = [20.0, 10.0, 20.0]
h = 5.0
[materials.rock]
preset = "sandstone"
[time]
duration = 0.1
[[monitor]]
name = "centre"
point = [10.0, 5.0, 10.0]
"""


def run_pyfem(*args, cwd):
    """Run `python3 -m pyfem ARGS` in `cwd` with the repository importable."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([PYTHON, "-m", "pyfem", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def bad_scene(tmp_path):
    """A scene whose only fault is Poisson's ratio 0.5."""
    path = tmp_path / "bad.toml"
    path.write_text(GOOD_SCENE.replace('preset = "sandstone"', 'preset = "sandstone"\nnu = 0.5'))
    return path


def assert_clean_error(result, *words):
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("error: ")
    assert "Traceback" not in result.stderr and "Traceback" not in result.stdout
    for word in words:
        assert word in result.stderr


def test_check_bad_scene_exits_2_naming_the_key(bad_scene, tmp_path):
    result = run_pyfem("check", bad_scene, cwd=tmp_path)
    assert_clean_error(result, "materials.rock.nu", "(-1, 0.5)", str(bad_scene))


def test_check_bad_override_exits_2(tmp_path):
    scene = tmp_path / "good.toml"
    scene.write_text(GOOD_SCENE)
    result = run_pyfem("check", scene, "--set", "mesh.hh=2", cwd=tmp_path)
    assert_clean_error(result, "mesh.hh", "did you mean 'mesh.h'")


def test_check_missing_scene_file_exits_2(tmp_path):
    result = run_pyfem("check", tmp_path / "nowhere.toml", cwd=tmp_path)
    assert_clean_error(result, "nowhere.toml")


def test_check_invalid_toml_exits_2_with_line(tmp_path):
    scene = tmp_path / "broken.toml"
    scene.write_text('title = "x"\n[mesh\n')
    result = run_pyfem("check", scene, cwd=tmp_path)
    assert_clean_error(result, "broken.toml", "line 2")


def test_run_bad_scene_creates_no_out_dir(bad_scene, tmp_path):
    out = tmp_path / "out"
    explicit = run_pyfem("run", bad_scene, "--out", out, cwd=tmp_path)
    assert_clean_error(explicit, "materials.rock.nu")
    assert not out.exists()
    by_default = run_pyfem("run", bad_scene, cwd=tmp_path)  # would be runs/bad
    assert_clean_error(by_default, "materials.rock.nu")
    assert not (tmp_path / "runs").exists()


def test_run_bad_override_creates_no_out_dir(tmp_path):
    scene = tmp_path / "good.toml"
    scene.write_text(GOOD_SCENE)
    out = tmp_path / "out"
    result = run_pyfem("run", scene, "--out", out, "--set", "monitor.0.point=[10, 5, 99]", cwd=tmp_path)
    assert_clean_error(result, "monitor.0.point", "inside the box")
    assert not out.exists()


def test_default_out_dir_is_runs_slash_stem():
    assert cli.default_out_dir(Path("workflows/scenes/default.toml")) == Path("runs/default")


def test_bench_passes_arguments_through(monkeypatch):
    received = []
    fake_bench = types.ModuleType("pyfem.bench")
    fake_bench.main = lambda argv: received.append(argv) or 3
    monkeypatch.setitem(sys.modules, "pyfem.bench", fake_bench)
    monkeypatch.setattr(pyfem, "bench", fake_bench, raising=False)
    assert cli.main(["bench", "--dofs", "1000", "--threads=2"]) == 3
    assert received == [["--dofs", "1000", "--threads=2"]]


def test_format_plan_prints_every_key_readably():
    text = cli.format_plan({
        "effects_on": ["seismic_input", "damping"],
        "dofs": 15129,
        "dt": 0.000812345,
        "dt_reason": "0.8 x critical (power iteration)",
        "memory_bytes": 3 * 1024 ** 2,
        "time_estimate_seconds": 125.0,
        "mesh": {"cells": 4096, "order": 1},
    })
    lines = text.splitlines()
    assert len(lines) == 9  # six plain keys, then "mesh:" and its two entries
    assert "effects on:" in text and "seismic_input, damping" in text
    assert "0.0008123" in text
    assert "3 MiB" in text
    assert "2.08 min" in text
    assert any(line.startswith("  cells:") and line.endswith("4096") for line in lines)


def test_bench_element_loop_rows_measure_what_they_say():
    """The benchmark's element-loop rows (no timing asserted: timings live in the benchmark): the
    scene path and three laws on a small box, each with a time, and a time per point for the laws;
    Mohr-Coulomb also on its yield surface, where points do return."""
    from pyfem.bench import element_loop_rows, markdown_table

    rows = element_loop_rows(1500, 3, threads=1)
    assert [row["case"].split(",")[-1].strip().split(" (")[0] for row in rows][1:] == [
        "linear_elastic", "mohr_coulomb at rest", "mohr_coulomb on its yield surface", "concrete_damage at rest"]
    assert 0.2 < rows[3]["returning_share"] <= 1.0, "the points on the surface return"
    assert rows[0]["ns_per_point"] is None and all(row["ns_per_point"] > 0 for row in rows[1:])
    assert all(row["ms"] > 0 and row["reference_ms"] > 0 for row in rows)
    table = markdown_table({"date": "d", "machine": "m", "cpu_count": 1, "rows": [], "element_loop": rows})
    assert "Effects that are off cost nothing" in table


def test_bench_case_rows_one_point_overrides_make_a_valid_scene():
    """The benchmark's case rows run the case-3 scene as it is and with ONE_POINT_ROCK (a constant
    once lost in an edit, which only a minutes-long `pyfem bench` would have found)."""
    from pyfem.bench import ONE_POINT_ROCK
    from pyfem.scene import load_scene

    scene = load_scene(Path(__file__).resolve().parents[1] / "workflows" / "scenes" / "case3_contact_coarse.toml",
                       ONE_POINT_ROCK)
    assert all(scene["materials"][name]["plasticity"]["integration"] == "reduced"
               for name in ("sandstone", "non_sandstone"))


def test_format_plan_prints_the_scenes_names_as_written():
    """Issue 51: a support group `ph_bolts` was printed "ph bolts"; the program's keys keep their spaces."""
    text = cli.format_plan({"peak_memory_bytes": 1024, "support": {"ph_bolts": "12 bolts", "th_cables": "4 cables"}})
    lines = text.splitlines()
    assert lines[0].startswith("peak memory bytes:") and lines[1] == "support:"
    assert lines[2].startswith("  ph_bolts:") and lines[2].endswith("12 bolts")
    assert lines[3].startswith("  th_cables:") and "ph bolts" not in text

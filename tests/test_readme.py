"""The README's examples run (issue 14): its scene and the fragments it shows, its files and commands.

- The first TOML block is a whole scene: it runs, the wave arrives at the monitor and follows the
  free field.
- Each later block is a fragment of a scene (layers with contact, nonlinear materials, boundary
  faces): merged into the first scene it validates and runs, and does what its text says (pairs
  exist and are monitored, the element loop takes the nonlinear regions, roller faces report
  reactions).
- Every file of the repository the README names exists, and every `python3 -m pyfem` command in
  it names a subcommand the CLI has.
"""
import copy
import pathlib
import re
import tomllib

import numpy as np
import pytest

from pyfem import solver
from pyfem.scene import parse_scene

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
README = (REPOSITORY / "README.md").read_text()


def toml_blocks() -> list[dict]:
    return [tomllib.loads(block) for block in re.findall(r"```toml\n(.*?)```", README, flags=re.S)]


def merged(base: dict, fragment: dict) -> dict:
    out = copy.deepcopy(base)
    for key, value in fragment.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merged(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def short(data: dict, duration: float = 0.3) -> dict:
    data = copy.deepcopy(data)
    data["time"]["duration"] = duration
    data.setdefault("output", {})["xdmf_interval"] = 0.0
    return data


def test_readme_has_the_blocks_this_test_knows():
    blocks = toml_blocks()
    assert len(blocks) == 4
    assert "mesh" in blocks[0] and "wave" in blocks[0]
    assert "contact" in blocks[1] and "plasticity" in blocks[2]["materials"]["sandstone"]
    assert "face" in blocks[3]["boundary"]


def test_readme_scene_runs_and_follows_the_free_field(tmp_path):
    data = toml_blocks()[0]
    summary = solver.run(parse_scene(data, source="README.md"), tmp_path / "run")
    assert summary["status"] == "finished"
    centre = summary["monitors"]["centre"]
    assert centre["displacement"] > 1e-4  # the pulse (amplitude 1 mm) arrived
    assert centre["freefield_error"] < 0.02
    assert summary["energy"]["balance_error"] < 1e-10


def test_readme_contact_fragment_runs_with_pairs(tmp_path):
    base, fragment = toml_blocks()[0], toml_blocks()[1]
    data = merged(base, fragment)
    data["materials"] = {"sandstone": {"preset": "sandstone"}, "non_sandstone": {"preset": "non_sandstone"}}
    data["wave"]["medium"] = "sandstone"
    summary = solver.run(parse_scene(short(data), source="README.md"), tmp_path / "run")
    assert summary["status"] == "finished"
    assert summary["n_pairs"] > 0 and "I1" in summary["pairs"]
    assert {"contact", "deterioration", "initial_stress"} <= set(summary["effects"])
    assert (tmp_path / "run" / "pairs" / "I1.csv").stat().st_size > 0


def test_readme_nonlinear_fragment_puts_its_regions_in_the_element_loop(tmp_path):
    base, fragment = toml_blocks()[0], toml_blocks()[2]
    data = merged(base, fragment)
    del data["materials"]["rock"]
    data["mesh"]["layers"] = [{"material": "sandstone", "thickness": 60.0}, {"material": "lining", "thickness": 40.0}]
    data["wave"]["medium"] = "sandstone"
    summary = solver.run(parse_scene(short(data, 0.1), source="README.md"), tmp_path / "run")
    assert summary["status"] == "finished"
    assert set(summary["nonlinear_regions"]) == {"sandstone", "lining"}
    laws = {name: region["law"] for name, region in summary["nonlinear_regions"].items()}
    assert laws == {"sandstone": "mohr_coulomb", "lining": "concrete_damage"}


def test_readme_boundary_fragment_makes_roller_faces_with_reactions(tmp_path):
    base, fragment = toml_blocks()[0], toml_blocks()[3]
    data = merged(base, fragment)
    summary = solver.run(parse_scene(short(data), source="README.md"), tmp_path / "run")
    faces = {face["name"]: face["type"] for face in summary["boundary_faces"]}
    assert faces["ymin"] == faces["ymax"] == "roller" and faces["xmin"] == "viscoelastic"
    header = (tmp_path / "run" / "reactions.csv").read_text().splitlines()[0]
    assert "ymin_Fy" in header and "ymax_Fy" in header
    reactions = np.loadtxt(tmp_path / "run" / "reactions.csv", delimiter=",", skiprows=1)
    assert np.all(np.isfinite(reactions))


def test_files_and_commands_the_readme_names_exist():
    paths = set(re.findall(r"(?<![\w/.-])((?:workflows|docs|meshes|data|scripts|tests|pyfem|cpp_kernels)/"
                           r"[\w./-]*\w)", README))
    assert len(paths) > 20
    # A module may be named without its suffix (pyfem/_kernels: the built .so).
    missing = sorted(path for path in paths if not (REPOSITORY / path).exists()
                     and not list(REPOSITORY.glob(path + ".*")))
    assert not missing, missing
    from pyfem.cli import _parser

    commands = set(_parser()._subparsers._group_actions[0].choices)
    used = set(re.findall(r"-m pyfem (\w+)", README)) | set(re.findall(r"\bpyfem (\w+) ", README))
    used &= {word for word in used if word.islower()}
    unknown = sorted(used - commands - {"is", "the", "command"})
    assert not unknown, unknown

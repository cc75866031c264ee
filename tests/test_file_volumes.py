"""A user's own cavern complex from a gmsh .geo (issue 51, item 1): a volume that does not cut the rock is
refused in one line naming the volumes, exit 2 (`pyfem.geometry.file.volume_problem`).

The user's kind of model: a powerhouse and a transformer hall 20 m apart in rock split by a bedding plane
dipping 70 degrees through the pillar, tetrahedra, both halls excavated by the static stage. The correct
script fragments the halls and the plane with the rock; each mistake is one a user makes in such a script:

- a hall left out of BooleanFragments: meshed on its own over the rock's cells (the hall does not exist);
- a hall also listed in a rock's physical volume (its cells counted in two regions);
- a hall defined twice, the copy not fragmented (duplicate volumes);
- an excavated hall that touches no rock (a box outside the model).
"""
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

ROCK = "Box(1) = {0, 0, 0, 120, 20, 100};\n"
HALLS = "Box(2) = {35, 0, 40, 20, 20, 25};\nBox(3) = {75, 0, 40, 12, 20, 20};\n"
# The bedding plane: a horizontal rectangle turned to dip 70 degrees, through (62, y, 50); x = 62 + 0.364 (z - 50).
PLANE = "Rectangle(100) = {-8, -5, 50, 140, 30};\nRotate {{0, 1, 0}, {62, 10, 50}, -70*Pi/180} { Surface{100}; }\n"
HALL_BOXES = ("powerhouse() = Volume In BoundingBox{34.9, -0.1, 39.9, 55.1, 20.1, 65.1};\n"
              "transformer() = Volume In BoundingBox{74.9, -0.1, 39.9, 87.1, 20.1, 60.1};\n")
ROCKS = ("left() = Volume In BoundingBox{-0.1, -0.1, -0.1, 80.3, 20.1, 100.1};\n"
         "right() = Volume In BoundingBox{43.7, -0.1, -0.1, 120.1, 20.1, 100.1};\n"
         "left() -= powerhouse();\nleft() -= transformer();\nright() -= powerhouse();\nright() -= transformer();\n")
GROUPS = ('Physical Volume("rock_left") = left();\nPhysical Volume("rock_right") = right();\n'
          'Physical Volume("powerhouse") = powerhouse();\nPhysical Volume("transformer") = transformer();\n')
SIZE = "Mesh.MeshSizeMax = 10;\nMesh.MeshSizeMin = 10;\n"

CORRECT = ('SetFactory("OpenCASCADE");\n' + ROCK + HALLS + PLANE
           + "BooleanFragments{ Volume{1}; Delete; }{ Volume{2, 3}; Surface{100}; Delete; }\n"
           + HALL_BOXES + ROCKS + GROUPS + SIZE)
# The transformer hall left out of the fragment: its volume 3 lies over the right rock's cells.
LEFT_OUT = ('SetFactory("OpenCASCADE");\n' + ROCK + HALLS + PLANE
            + "BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Surface{100}; Delete; }\n"
            + HALL_BOXES.replace("transformer() = Volume In BoundingBox{74.9, -0.1, 39.9, 87.1, 20.1, 60.1}",
                                 "transformer() = {3}")
            + ROCKS + GROUPS + SIZE)
# The right rock's physical volume also lists the transformer hall.
TWICE = CORRECT.replace('Physical Volume("rock_right") = right();',
                        'Physical Volume("rock_right") = {right(), transformer()};')
# A copy of the powerhouse, not fragmented, named as a region of its own.
DUPLICATE = CORRECT.replace(SIZE, 'Box(50) = {35, 0, 40, 20, 20, 25};\nPhysical Volume("powerhouse_copy") = {50};\n'
                            + SIZE)
# An "excavation" box beside the model, sharing nothing with the rock.
APART = CORRECT.replace(SIZE, 'Box(60) = {130, 0, 40, 12, 20, 20};\nPhysical Volume("gallery") = {60};\n' + SIZE)

SCENE = """
title = "a user's cavern complex"
[mesh]
builder = "file"
file = "{geo}"
[materials.rock_left]
preset = "sandstone"
[materials.rock_right]
preset = "non_sandstone"
{extra_materials}
[static]
excavate = [{excavate}]
[initial_stress]
surface = 100.0
rho = 2500.0
k = [1.0, 1.0, 1.0]
[time]
duration = 0.01
[output]
xdmf_interval = 0.0
"""


def check(tmp_path: Path, script: str, excavate=("powerhouse", "transformer"), materials=()):
    (tmp_path / "complex.geo").write_text(script)
    extra = "".join(f'[materials.{name}]\npreset = "sandstone"\n' for name in materials)
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(geo=tmp_path / "complex.geo", extra_materials=extra,
                                  excavate=", ".join(f'"{name}"' for name in excavate)))
    return subprocess.run(["/usr/bin/python3", "-m", "pyfem", "check", str(scene)], capture_output=True, text=True,
                          cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=300)


def test_the_fragmented_complex_is_accepted(tmp_path):
    result = check(tmp_path, CORRECT)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("script, excavate, materials, names, words", [
    (LEFT_OUT, ("powerhouse", "transformer"), (), ('"transformer"', '"rock_right"'), "overlap"),
    (TWICE, ("powerhouse", "transformer"), (), ('"rock_right"', '"transformer"'), "two regions"),
    (DUPLICATE, ("powerhouse", "transformer"), ("powerhouse_copy",), ('"powerhouse"', '"powerhouse_copy"'),
     "overlap"),
    (APART, ("powerhouse", "transformer", "gallery"), (), ('"gallery"', '"rock_left"', '"rock_right"'),
     "shares no cell face"),
], ids=["hall-left-out-of-the-fragment", "cells-in-two-regions", "duplicate-volume", "excavation-touching-no-rock"])
def test_a_volume_that_does_not_cut_the_rock_is_one_line_and_exit_2(tmp_path, script, excavate, materials, names,
                                                                    words):
    result = check(tmp_path, script, excavate, materials)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "mesh.file" in lines[0] and words in lines[0], lines[0]
    for name in names:
        assert name in lines[0], lines[0]


def test_check_of_a_new_mesh_prints_no_gmsh_info_and_a_gmsh_error_in_one_line(tmp_path):
    """gmsh talks ("Info    : Meshing 3D...", a line per step) unless told General.Terminal = 0: the
    control, gmsh meshing the user's script with its defaults, prints such lines; `check` of a scene
    that meshes the same script, and of the box builder's default scene, prints none. A script gmsh
    cannot read is still one line naming mesh.file with gmsh's own words, exit 2."""
    (tmp_path / "complex.geo").write_text(CORRECT)
    control = subprocess.run(["/usr/bin/python3", "-c", "import sys, gmsh; gmsh.initialize(); gmsh.open(sys.argv[1]); "
                              "gmsh.model.mesh.generate(3); gmsh.finalize()", str(tmp_path / "complex.geo")],
                             capture_output=True, text=True, timeout=300)
    assert (control.stdout + control.stderr).count("Info") > 5, "gmsh's defaults print Info lines"
    result = check(tmp_path, CORRECT)
    assert result.returncode == 0, result.stderr
    assert "Info" not in result.stderr and "Info" not in result.stdout, result.stderr
    box = subprocess.run(["/usr/bin/python3", "-m", "pyfem", "check", str(REPO / "workflows/scenes/default.toml")],
                         capture_output=True, text=True, cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(REPO)),
                         timeout=300)
    assert box.returncode == 0 and "Info" not in box.stderr + box.stdout, box.stderr
    broken = check(tmp_path, CORRECT.replace("Box(1) = {0, 0, 0, 120, 20, 100};", "Box(1) = {0, 0, 0, 120, 20, 100;"))
    lines = broken.stderr.strip().splitlines()
    assert broken.returncode == 2 and len(lines) == 1 and "Info" not in broken.stderr, broken.stderr
    assert "mesh.file" in lines[0] and "gmsh could not mesh" in lines[0] and "syntax error" in lines[0], lines[0]

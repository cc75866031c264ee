"""No silent nonsense: every bad input a user can write is one `error:` line and exit 2, and
what a user may mean is one `warning:` line each, also kept in run.json.

The CLI runs in-process (`pyfem.cli.main`) so the table stays fast; four cases run it as a
subprocess to show that nothing else (a traceback, gmsh's own messages) reaches stderr.
"""
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import write_msh_with_quadratic_tetrahedra

from pyfem import cli
from pyfem._gmsh import gmsh
from pyfem.geometry import gmsh_session

REPO = Path(__file__).resolve().parents[1]
RECORD = REPO / "data" / "elcentro_1940_ns.txt"
TWO_LAYER_MSH = REPO / "meshes" / "two_layer_block.msh"  # volumes sandstone, mudstone; interface_1

BOX = """
title = "bad input"
[mesh]
size = [20.0, 10.0, 20.0]
h = 5.0
[materials.rock]
E = 8.0e9
nu = 0.24
rho = 2600.0
[time]
duration = 0.02
[output]
xdmf_interval = 0.0
[[monitor]]
name = "centre"
point = [10.0, 5.0, 10.0]
"""

TWO_LAYER = f"""
[mesh]
builder = "file"
file = "{TWO_LAYER_MSH}"
[materials.sandstone]
preset = "sandstone"
[materials.mudstone]
preset = "non_sandstone"
[time]
duration = 0.01
"""


def write_msh_without_volumes(path):
    """A box whose surfaces only are meshed (quadrilaterals), with a physical surface."""
    with gmsh_session("surfaces"):
        volume = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        surfaces = [tag for _, tag in gmsh.model.getBoundary([(3, volume)], oriented=False)]
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, surfaces), "outside")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))


def write_hexahedral_box_msh(path):
    """A user's 4 x 2 x 3 m box of 1 m hexahedra (z from 0 to 3 m), physical volume "rock"."""
    with gmsh_session("hexahedra"):
        gmsh.model.occ.addBox(0, 0, 0, 4, 2, 3)
        gmsh.model.occ.synchronize()
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [1]), "rock")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 1.0)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 1.0)
        for dim, tag in gmsh.model.getEntities(1):
            lo = gmsh.model.getBoundingBox(dim, tag)
            length = max(abs(lo[3] - lo[0]), abs(lo[4] - lo[1]), abs(lo[5] - lo[2]))
            gmsh.model.mesh.setTransfiniteCurve(tag, int(round(length)) + 1)
        for dim, tag in gmsh.model.getEntities(2):
            gmsh.model.mesh.setTransfiniteSurface(tag)
            gmsh.model.mesh.setRecombine(dim, tag)
        gmsh.model.mesh.setTransfiniteVolume(1)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def file_mesh_with(extra):
    """A file-builder scene on write_hexahedral_box_msh's box (top z = 3 m), `extra` TOML appended."""
    def setup(tmp):
        path = tmp / "box.msh"
        write_hexahedral_box_msh(path)
        return replace(file_scene(path), "duration = 0.01", "duration = 1.0") + extra, []
    return setup


WAVE_ON_SURFACE = ('[wave]\ntype = "SV"\nsurface = {surface}\n[wave.motion.ricker]\nf0 = 5.0\n'
                   'amplitude = 1.0e-3\n[boundary]\ntype = "viscoelastic"\n')


def file_scene(msh):
    return f"""
[mesh]
builder = "file"
file = "{msh}"
[materials.rock]
preset = "sandstone"
[time]
duration = 0.01
"""


def replace(text, old, new):
    assert old in text
    return text.replace(old, new, 1)


ROCK_LAW = "[materials.rock.plasticity]\ncohesion = 1.1e6\nfriction_angle = 42.0\ntensile_strength = 1.9e6\n"


def box(old=None, new=None, extra=""):
    """BOX with one line replaced and `extra` TOML appended: a scene without side files."""
    def setup(tmp):
        return (BOX if old is None else replace(BOX, old, new)) + extra, []
    return setup


def two_layer(old=None, new=None, extra=""):
    def setup(tmp):
        return (TWO_LAYER if old is None else replace(TWO_LAYER, old, new)) + extra, []
    return setup


def mesh_file(write):
    """A file-builder scene whose .msh is made by write(path) in the test's directory."""
    def setup(tmp):
        path = tmp / "bad.msh"
        write(path)
        return file_scene(path), []
    return setup


def with_out(out):
    def setup(tmp):
        return BOX, ["--out", out(tmp)]
    return setup


def malformed_record(tmp):
    path = tmp / "rec.txt"
    path.write_text("0.0 0.01\n0.02 abc\n")
    return BOX + record_wave(path), []


def record_wave(path, more=""):
    return (f'[wave]\ntype = "SV"\nsurface = 20.0\n[wave.motion]\n'
            f'record = {{ file = "{path}", units = "g"{more} }}\n')


def regular_file_as_parent(tmp):
    (tmp / "plain").write_text("x")
    return str(tmp / "plain" / "run")


def directory_of_the_users(tmp):
    """A directory holding a user's own files, named like a run's outputs, without a run.json."""
    (tmp / "mine" / "monitors").mkdir(parents=True)
    (tmp / "mine" / "energy.csv").write_text("the user's own numbers\n")
    (tmp / "mine" / "monitors" / "centre.csv").write_text("the user's own numbers\n")
    return str(tmp / "mine")


LAYERED_BOX_CONTACT = ('[materials.rock2]\npreset = "non_sandstone"\n'
                       '[contact]\ninterfaces = ["interface_1"]\ncohesion = 1.0\nfriction_angle = 30.0\n')
TWO_LAYERS = ('h = 5.0\nlayers = [{material = "rock", thickness = 10.0}, '
              '{material = "rock2", thickness = 10.0}]')
CAVERN_BAD_H_FAR = ('[mesh]\nbuilder = "layered_cavern"\n[mesh.parameters]\nh_far = -1.0\n'
                    '[materials.sandstone]\npreset = "sandstone"\n[time]\nduration = 0.01\n')


def contact_on(interface):
    return f'[contact]\ninterfaces = ["{interface}"]\ncohesion = 0.0\nfriction_angle = 30.0\n'


# (id, setup(tmp_path) -> (scene text, extra CLI arguments), key the message names, words it holds)
BAD_INPUTS = [
    ("E in GPa", box("E = 8.0e9", "E = 8.0"), "materials.rock.E", ["looks like GPa: write 8.0e9"]),
    ("E in MPa", box("E = 8.0e9", "E = 8000.0"), "materials.rock.E", ["looks like MPa: write 8.0e9"]),
    ("E absurdly high", box("E = 8.0e9", "E = 8.0e15"), "materials.rock.E", ["[1.0e7, 3.0e11]"]),
    ("rho in t/m^3", box("rho = 2600.0", "rho = 2.6"), "materials.rock.rho",
     ["looks like t/m^3: write 2600.0"]),
    ("initial_stress rho in t/m^3", box(extra="[initial_stress]\nsurface = 20.0\nrho = 2.6\n"),
     "initial_stress.rho", ["looks like t/m^3: write 2600.0"]),
    ("cohesion at top of materials", box("rho = 2600.0", "rho = 2600.0\ncohesion = 1.1e6"),
     "materials.rock.cohesion", ["not read", "[materials.NAME.plasticity]"]),
    ("friction_angle at top of materials", box("rho = 2600.0", "rho = 2600.0\nfriction_angle = 42.0"),
     "materials.rock.friction_angle", ["not read", "[materials.NAME.damage]"]),
    ("tensile_strength at top of materials", box("rho = 2600.0", "rho = 2600.0\ntensile_strength = 1.9e6"),
     "materials.rock.tensile_strength", ["not read"]),
    ("plasticity table without a friction angle", box(extra="[materials.rock.plasticity]\ncohesion = 1.1e6\n"),
     "materials.rock.plasticity.friction_angle", ["missing", "preset"]),
    ("plasticity cohesion in MPa",
     box(extra="[materials.rock.plasticity]\ncohesion = 1.1\nfriction_angle = 42.0\ntensile_strength = 1.9e6\n"),
     "materials.rock.plasticity.cohesion", ["looks like MPa: write 1.1e6"]),
    ("dilation above friction",
     box(extra="[materials.rock.plasticity]\ncohesion = 1.1e6\nfriction_angle = 30.0\ntensile_strength = 1.9e6\n"
               "dilation_angle = 35.0\n"),
     "materials.rock.plasticity.dilation_angle", ["must not exceed the friction angle 30 deg"]),
    ("rock crack band in mm",
     box(extra=ROCK_LAW + "damage_max = 0.9\ndamage_plastic_displacement = 10.0\n"),
     "materials.rock.plasticity.damage_plastic_displacement", ["looks like mm: write 1.0e-2"]),
    ("rock crack band without damage",
     box(extra=ROCK_LAW + "damage_max = 0.0\ndamage_plastic_displacement = 0.01\n"),
     "materials.rock.plasticity.damage_plastic_displacement", ["damage_max = 0"]),
    ("rock crack band beside a plastic strain scale",
     box(extra=ROCK_LAW + "damage_max = 0.9\ndamage_plastic_strain = 0.002\ndamage_plastic_displacement = 0.01\n"),
     "materials.rock.plasticity.damage_plastic_displacement", ["not both"]),
    ("rock damage without its scale",
     box(extra=ROCK_LAW + "damage_max = 0.9\n"),
     "materials.rock.plasticity.damage_max", ["0.9", "damage_plastic_strain", "damage_plastic_displacement",
                                              "perfectly plastic"]),
    ("rock crack band in the concrete's table",
     box(extra="[materials.rock.damage]\ndamage_plastic_displacement = 0.01\n"),
     "materials.rock.damage.damage_plastic_displacement", ["not read here", "[materials.NAME.plasticity]",
                                                           "fracture_energy"]),
    ("contact cohesion in MPa", box("h = 5.0", TWO_LAYERS, extra=LAYERED_BOX_CONTACT),
     "contact.cohesion", ["looks like MPa: write 1.0e6"]),
    ("contact.split not one of its two moments", box("h = 5.0", TWO_LAYERS,
                                                     extra=LAYERED_BOX_CONTACT + 'split = "welded"\n'),
     "contact.split", ['"before_static", "after_static"']),
    ("damage with A_t < 1 and a crack band",
     box(extra="[materials.rock.damage]\ncohesion = 1.8e6\nfriction_angle = 46.0\ntensile_strength = 1.27e6\n"
               "A_t = 0.8\n"),
     "materials.rock.damage.A_t", ["must be 1 when fracture_energy > 0"]),
    ("damage with B_t below E / f_t and a crack band",  # the peak would rise above f_t (lining_law.md)
     box(extra="[materials.rock.damage]\ncohesion = 1.8e6\nfriction_angle = 46.0\ntensile_strength = 1.27e6\n"
               "B_t = 5.0e3\n"),
     "materials.rock.damage.B_t", ["5000", "at least E / f_t = 6299", "fracture_energy = 0"]),
    ("time.safety with time.dt", box("duration = 0.02", "duration = 0.02\ndt = 1.0e-4\nsafety = 0.5"),
     "time.safety", ["not both"]),
    ("mesh.h with a file mesh", two_layer("[mesh]", "[mesh]\nh = 0.1"), "mesh.h",
     ['not read by builder "file"']),
    ("msh without volumes", mesh_file(write_msh_without_volumes), "mesh.file", ["no physical volume"]),
    ("msh with gmsh's quadratic tetrahedra", mesh_file(write_msh_with_quadratic_tetrahedra), "mesh.file",
     ["Tetrahedron 10", "8-node hexahedra", "4-node tetrahedra"]),
    ("wave surface below a file mesh's top", file_mesh_with(WAVE_ON_SURFACE.format(surface=2.0)),
     "wave.surface", ["2.0", "below the model's top z = 3 m", "mesh.file"]),
    ("initial stress surface below a file mesh's top",
     file_mesh_with("[initial_stress]\nsurface = 2.5\nrho = 2600.0\n"),
     "initial_stress.surface", ["2.5", "below the model's top z = 3 m", "mesh.file"]),
    ("msh garbage", mesh_file(lambda path: path.write_bytes(b"\x00\x01garbage\n")), "mesh.file",
     ["gmsh cannot read"]),
    ("msh empty", mesh_file(lambda path: path.write_bytes(b"")), "mesh.file", ["gmsh cannot read"]),
    ("interface names a missing surface", two_layer(extra=contact_on("interface_9")),
     "contact.interfaces.0", ["interface_1"]),
    ("interface on the outside of the mesh", two_layer(extra=contact_on("zmax")),
     "contact.interfaces", ["not inside the model"]),
    ("materials do not match the volumes", two_layer("[materials.mudstone]", "[materials.granite]"),
     "materials.mudstone", ["granite", "sandstone"]),
    ("layered_cavern bad parameter", lambda tmp: (CAVERN_BAD_H_FAR, []), "mesh.parameters.h_far", ["> 0"]),
    # A typo (h = 0.005 for 5.0): refused at once by its memory, not after minutes of meshing.
    ("box too fine for the machine", box("h = 5.0", "h = 0.005"), "mesh.h",
     ["Q1 cells", "GiB at the peak", "h >= "]),
    ("out under /proc", with_out(lambda tmp: "/proc/pyfem-out"), "--out", ["/proc"]),
    ("out under a regular file", with_out(regular_file_as_parent), "--out", ["is not a directory"]),
    ("out holds the user's files", with_out(directory_of_the_users), "--out",
     ["2 entries that are not a run", "energy.csv, monitors", "nothing there was changed"]),
    ("record file malformed", malformed_record, "wave.motion.record.file", ["line 2", "expected numbers"]),
    ("record window outside the record", box(extra=record_wave(RECORD, ", window = [0.0, 99.0]")),
     "wave.motion.record.window", ["inside the record"]),
    ("record scale not a mode", box(extra=record_wave(RECORD, ', pga = 0.32, scale = "before"')),
     "wave.motion.record.scale", ['"before"', '"after_filter"', '"before_filter"']),
]


def run_cli(capsys, tmp_path, scene_text, extra, command="run"):
    scene = tmp_path / "scene.toml"
    scene.write_text(scene_text)
    out = [] if command == "check" or "--out" in extra else ["--out", str(tmp_path / "out")]
    status = cli.main([command, str(scene), *out, *extra])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


@pytest.mark.parametrize("setup, key, words", [case[1:] for case in BAD_INPUTS],
                         ids=[case[0] for case in BAD_INPUTS])
def test_bad_input_is_one_error_line_with_exit_2_and_writes_nothing(capsys, tmp_path, setup, key, words):
    scene_text, extra = setup(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    status, out, err = run_cli(capsys, tmp_path, scene_text, extra)
    lines = err.splitlines()
    assert status == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert f"'{key}'" in lines[0] or f"{key} " in lines[0], lines[0]
    for word in words:
        assert word in lines[0], lines[0]
    after = sorted(p.name for p in tmp_path.iterdir())
    assert after == sorted(before + ["scene.toml"])  # no run directory, nothing else
    assert not Path("/proc/pyfem-out").exists()
    if (tmp_path / "mine").exists():  # the user's files are as they were
        assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["energy.csv", "monitors"]
        assert (tmp_path / "mine" / "energy.csv").read_text() == "the user's own numbers\n"


@pytest.mark.parametrize("case", ["msh garbage", "msh with gmsh's quadratic tetrahedra", "record file malformed",
                                  "out under /proc"])
def test_bad_input_in_a_child_process_prints_only_the_error_line(tmp_path, case):
    setup = next(c[1] for c in BAD_INPUTS if c[0] == case)
    scene_text, extra = setup(tmp_path)
    scene = tmp_path / "scene.toml"
    scene.write_text(scene_text)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = [] if "--out" in extra else ["--out", str(tmp_path / "out")]
    result = subprocess.run(["/usr/bin/python3", "-m", "pyfem", "run", str(scene), *out, *extra],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith("error: "), result.stderr
    assert not (tmp_path / "out").exists()


def test_surfaces_at_a_file_mesh_top_are_accepted(capsys, tmp_path):
    """The same hexahedral box with both surfaces at its top z = 3 m (and one above it) checks cleanly."""
    extra = WAVE_ON_SURFACE.format(surface=3.0) + "[initial_stress]\nsurface = 3.5\nrho = 2600.0\n"
    scene_text, _ = file_mesh_with(extra)(tmp_path)
    status, out, err = run_cli(capsys, tmp_path, scene_text, [], command="check")
    assert status == 0, err
    assert "hexahedra" in out or "Q1" in out, out


def test_a_directory_as_the_scene_file_is_an_error_line(capsys, tmp_path):
    assert cli.main(["check", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"error: {tmp_path}: cannot read the scene file (Is a directory)\n"


def test_a_value_error_that_names_no_key_is_a_bug_and_keeps_its_traceback(monkeypatch, tmp_path):
    from pyfem import distributed_model

    def broken(scene):
        raise ValueError("operands could not be broadcast together")

    monkeypatch.setattr(distributed_model, "check", broken)
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX)
    with pytest.raises(ValueError, match="broadcast"):
        cli.main(["check", str(scene)])


# A box far coarser than the accuracy advice (20 m elements; a 25 Hz record band in rock with
# c_s ~ 1100 m/s wants ~5 m for Q1), run for 0.02 s of a 2 s window (plus the filter lead-in).
WARNED = f"""
title = "warned"
[mesh]
size = [60.0, 20.0, 60.0]
h = 20.0
[materials.rock]
preset = "sandstone"
[time]
duration = 0.02
[wave]
type = "SV"
surface = 60.0
[wave.motion]
record = {{ file = "{RECORD}", units = "g", window = [0.0, 2.0] }}
[output]
xdmf_interval = 0.0
[[monitor]]
name = "centre"
point = [30.0, 10.0, 30.0]
"""


def assert_the_two_warnings(lines):
    warnings = [line for line in lines if line.startswith("warning: ")]
    duration = [line for line in warnings if "time.duration = 0.02 s" in line]
    coarse = [line for line in warnings if "mesh.h = 20 m" in line]
    assert len(duration) == 1 and "window [0, 2] s" in duration[0] and "lead-in" in duration[0]
    assert len(coarse) == 1 and "accuracy study" in coarse[0]
    return duration[0], coarse[0]


def test_warnings_are_printed_by_run_and_kept_in_run_json(capsys, tmp_path):
    status, out, err = run_cli(capsys, tmp_path, WARNED, [])
    assert status == 0, err
    duration, coarse = assert_the_two_warnings(err.splitlines())
    summary = json.loads((tmp_path / "out" / "run.json").read_text())
    assert summary["warnings"] == [duration.removeprefix("warning: "), coarse.removeprefix("warning: ")]


def test_warnings_are_printed_by_check(capsys, tmp_path):
    status, out, err = run_cli(capsys, tmp_path, WARNED, [], command="check")
    assert status == 0, err
    assert_the_two_warnings(err.splitlines())


@pytest.mark.parametrize("scale", ["after_filter", "before_filter"])
def test_check_prints_the_record_peaks_and_where_pga_is_set(capsys, tmp_path, scale):
    """check's "input record" line: the whole record's raw peak, the window's raw peak (both as read),
    where pga was set, and the processed motion's PGA, PGV, PGD; with "after_filter" the PGA is pga."""
    from pyfem.seismic.records import STANDARD_GRAVITY, read_record

    scene = replace(WARNED, 'window = [0.0, 2.0] }', f'window = [0.0, 2.0], pga = 0.32, scale = "{scale}" }}')
    status, out, err = run_cli(capsys, tmp_path, scene, [], command="check")
    assert status == 0, err
    lines = [line for line in out.splitlines() if line.startswith("input record: ")]
    assert len(lines) == 1, out
    record = read_record(RECORD)
    whole = np.abs(record.acceleration).max() / STANDARD_GRAVITY
    window = np.abs(record.acceleration[record.t <= 2.0 + 1e-9]).max() / STANDARD_GRAVITY
    assert f"raw record peak {whole:.3g} g, window [0, 2] s raw peak {window:.3g} g" in lines[0]
    assert f'scale "{scale}"' in lines[0] and "PGV" in lines[0] and "PGD" in lines[0]
    pga = float(lines[0].split("processed motion PGA ")[1].split(" g")[0])
    if scale == "after_filter":
        assert pga == 0.32
    else:  # the whole record's peak is 0.32 g; the processed window's is lower
        assert pga < 0.32 * window / whole * 1.01


def test_a_heavy_density_is_a_warning_not_an_error(capsys, tmp_path):
    heavy = replace(BOX, "rho = 2600.0", "rho = 9.0e5")
    status, out, err = run_cli(capsys, tmp_path, heavy, [], command="check")
    assert status == 0, err
    assert [line for line in err.splitlines() if line.startswith("warning: ")] == [
        "warning: materials.rock.rho = 9.0e5 kg/m^3 is above 8000 kg/m^3 (steel), heavier than any rock "
        "or concrete; used as given"]


def test_a_fine_enough_scene_has_no_warnings(capsys, tmp_path):
    fine = replace(replace(WARNED, "h = 20.0", "h = 5.0"), "duration = 0.02", "duration = 30.0")
    status, out, err = run_cli(capsys, tmp_path, fine, [],
                               command="check")
    assert status == 0, err
    assert "warning" not in err


def test_a_monitor_in_the_cavity_names_its_key_and_where_it_is(capsys):
    """A monitor point in a user's tunnel (inside the mesh's bounding box, in no cell): one line naming
    monitor.1.point and the monitor, saying it is in no cell rather than outside the bounds."""
    scene = REPO / "tests" / "scenes" / "mpi_tunnel_tet.toml"
    status = cli.main(["check", str(scene), "--set", "monitor.1.point=[60.0, 1.0, 60.0]"])
    lines = capsys.readouterr().err.splitlines()
    errors = [line for line in lines if line.startswith("error: ")]
    assert status == 2 and len(errors) == 1, lines
    assert "'monitor.1.point' = [60.0, 1.0, 60.0] (monitor 'crown')" in errors[0]
    assert "inside the mesh's bounding box but in no cell" in errors[0] and "rank" not in errors[0]


@pytest.mark.parametrize("size, h, order", [([20.0, 10.0, 20.0], 0.005, 1), ([4000.0, 2.0, 4000.0], 0.5, 1),
                                            ([4000.0, 2.0, 4000.0], 0.5, 2), ([1e5, 1.0, 1.0], 1e-5, 1)])
def test_a_box_too_fine_for_the_machine_names_an_h_that_fits(size, h, order):
    """The memory guard's smallest h is itself accepted, also for a box with a thin side (where the
    dofs do not fall as h^-3)."""
    import re

    from pyfem.scene import SceneError, parse_scene

    def scene(h_value):
        return parse_scene({"mesh": {"size": size, "h": h_value, "order": order},
                            "materials": {"rock": {"preset": "sandstone"}}, "time": {"duration": 0.01}})

    with pytest.raises(SceneError) as refused:
        scene(h)
    assert refused.value.key == "mesh.h" and "GiB at the peak" in str(refused.value)
    suggested = float(re.search(r"h >= ([0-9.e+-]+) m", str(refused.value)).group(1))
    assert suggested > h
    scene(suggested)  # accepted

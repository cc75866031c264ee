"""An excavation sequence ([[static.step]], docs/static.md "An excavation sequence") on the
distributed model: a 16 x 2 x 16 m section of 1 m hexahedra (plane strain: rollers on the y faces)
with a 4 x 6 m opening dug in two benches, the top heading (x 6-10 m, z 7-10 m) then the bench
below it (z 4-7 m).

- Linear elastic rock: the two steps end where the one step ends (path independence), while the
  state after the first step is another one.
- Mohr-Coulomb rock: the plastic zone of two steps is not the one step's.
- One and two MPI ranks give the same sequence; bad keys are one line and exit code 2.
"""
from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from pyfem.scene import SceneError, parse_scene

ROOT = pathlib.Path(__file__).resolve().parents[1]
ROCK = {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}
# Weak enough to yield around the opening under the stress below (as a user writes it: strengths only).
WEAK = dict(ROCK, plasticity={"cohesion": 1.5e6, "friction_angle": 30.0, "dilation_angle": 0.0,
                              "tensile_strength": 0.5e6})
HEADING, BENCH = (7.0, 10.0), (4.0, 7.0)  # z ranges (m) of the two benches, x 6-10 m
MONITORS = {"crown": [8.0, 1.0, 10.0], "floor": [8.0, 1.0, 4.0], "wall": [10.0, 1.0, 5.0],
            "shoulder": [10.0, 1.0, 9.0], "far": [13.0, 1.0, 12.0]}


def write_benches_msh(path, shotcrete: bool = False):
    """Sixteen boxes meshed as 1 m hexahedra: "heading" (x 6-10, z 7-10) and "bench" (x 6-10, z 4-7)
    among the blocks of "rock"; with `shotcrete` the heading's top metre (z 9-10) is the region
    "shotcrete", a layer under the roof."""
    from pyfem._gmsh import gmsh
    from pyfem.geometry import gmsh_session

    columns = ((0.0, 6.0), (6.0, 10.0), (10.0, 16.0))
    rows = ((0.0, 4.0), BENCH, HEADING, (10.0, 16.0))
    if shotcrete:
        rows = ((0.0, 4.0), BENCH, (HEADING[0], HEADING[1] - 1.0), (HEADING[1] - 1.0, HEADING[1]), (10.0, 16.0))
    with gmsh_session("benches"):
        blocks = [gmsh.model.occ.addBox(x0, 0.0, z0, x1 - x0, 2.0, z1 - z0) for (x0, x1) in columns
                  for (z0, z1) in rows]
        gmsh.model.occ.fragment([(3, tag) for tag in blocks], [])
        gmsh.model.occ.synchronize()
        for _, tag in gmsh.model.getEntities(1):
            box = gmsh.model.getBoundingBox(1, tag)
            length = max(box[3] - box[0], box[4] - box[1], box[5] - box[2])
            gmsh.model.mesh.setTransfiniteCurve(tag, int(round(length)) + 1)
        for _, tag in gmsh.model.getEntities(2):
            gmsh.model.mesh.setTransfiniteSurface(tag)
            gmsh.model.mesh.setRecombine(2, tag)
        for _, tag in gmsh.model.getEntities(3):
            gmsh.model.mesh.setTransfiniteVolume(tag)
        regions = {"rock": [], "heading": [], "bench": []} | ({"shotcrete": []} if shotcrete else {})
        for _, tag in gmsh.model.getEntities(3):
            box = gmsh.model.getBoundingBox(3, tag)
            x, z = 0.5 * (box[0] + box[3]), 0.5 * (box[2] + box[5])
            name = ("rock" if not 6.0 < x < 10.0 else "shotcrete" if shotcrete and HEADING[1] - 1.0 < z < HEADING[1]
                    else "heading" if HEADING[0] < z < HEADING[1]
                    else "bench" if BENCH[0] < z < BENCH[1] else "rock")
            regions[name].append(tag)
        for name, tags in regions.items():
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, tags), name)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


@pytest.fixture(scope="module")
def benches(tmp_path_factory):
    path = tmp_path_factory.mktemp("benches") / "benches.msh"
    write_benches_msh(path)
    return path


def benches_scene(msh, static: dict, rock=ROCK) -> dict:
    return {
        "title": "two benches",
        "mesh": {"builder": "file", "file": str(msh), "order": 1},
        "materials": {"rock": dict(rock), "heading": dict(ROCK), "bench": dict(ROCK)},
        "time": {"duration": 0.002},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "initial_stress": {"stress": [-6.0e6, -5.0e6, -8.0e6, 0.0, 0.0, 0.0]},
        "static": dict({"solver": "relaxation"}, **static),
        "monitor": [{"name": name, "point": point} for name, point in MONITORS.items()],
        "output": {"xdmf_interval": 0.0},
    }


ONE_STEP = {"excavate": ["heading", "bench"]}
TWO_STEPS = {"step": [{"excavate": ["heading"]}, {"excavate": ["bench"]}]}


def run_stage(data: dict, out: pathlib.Path, ranks: int = 1) -> dict:
    """static/static.json of a run of the scene `data` (a subprocess: the distributed model on
    `ranks` ranks)."""
    out.mkdir(parents=True, exist_ok=True)
    scene_file = out / "scene.json"
    scene_file.write_text(json.dumps(data))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    command = [sys.executable, "-c", "import json, sys; from pyfem.scene import parse_scene; "
               "from pyfem.distributed_model import run; "
               "run(parse_scene(json.load(open(sys.argv[1]))), sys.argv[2])", str(scene_file), str(out / "run")]
    if ranks > 1:
        command = ["mpirun", "--allow-run-as-root", "--oversubscribe", "-n", str(ranks)] + command
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads((out / "run" / "static" / "static.json").read_text())


def displacements(report: dict) -> np.ndarray:
    return np.array([report["monitors"][name]["displacement"] for name in MONITORS])


def test_two_steps_of_a_linear_model_end_where_one_step_ends(benches, tmp_path):
    """Linear elastic rock: excavating the heading then the bench gives the one-step excavation's
    displacements (measured: 5e-14 of the largest at the five monitors, relaxation tolerance 1e-8),
    while the state after the first step is another (the largest displacement then is the heave of
    the bench's top, 3.30 mm, which the second step removes; at the end 3.18 mm at the crown)."""
    extra = {"tolerance": 1.0e-8}
    one = run_stage(benches_scene(benches, dict(ONE_STEP, **extra)), tmp_path / "one")
    two = run_stage(benches_scene(benches, dict(TWO_STEPS, **extra)), tmp_path / "two")
    assert [step["excavated"] for step in two["steps"]] == [["heading"], ["bench"]]
    assert [stage["name"] for stage in two["stages"]] == ["step 1 excavation", "step 2 excavation"]
    assert all(stage["converged"] for stage in two["stages"])
    first, final = two["steps"][0], two["max_displacement"]
    assert first["max_displacement_point"][2] == pytest.approx(BENCH[1]), "after step 1: the bench's top heaves"
    assert final["point"][2] != pytest.approx(BENCH[1]), "the bench's top is gone at the end"
    assert abs(first["max_displacement"] - final["value"]) > 0.02 * final["value"]
    a, b = displacements(one), displacements(two)
    assert np.abs(a).max() > 1.0e-3, "the excavation moved the monitors"
    difference = np.abs(a - b).max() / np.abs(a).max()
    print(f"two steps against one: {difference:.1e} of the largest monitor displacement")
    assert difference < 1.0e-6
    assert two["max_displacement"]["value"] == pytest.approx(one["max_displacement"]["value"], rel=1.0e-6)


def test_the_plastic_zone_of_two_steps_is_not_the_one_steps(benches, tmp_path):
    """Mohr-Coulomb rock (c 1.5 MPa, phi 30 deg): the heading alone yields 17 m^3, the bench after it
    brings the zone to 50 m^3 (peak plastic strain 1.14e-3), where the whole opening at once yields
    52 m^3 (peak 7.3e-4), and the wall's shoulder moves 3.14 mm instead of 2.89 mm."""
    one = run_stage(benches_scene(benches, ONE_STEP, rock=WEAK), tmp_path / "one")
    two = run_stage(benches_scene(benches, TWO_STEPS, rock=WEAK), tmp_path / "two")
    volumes = [step["plastic_volume"] for step in two["steps"]]
    assert 0.0 < volumes[0] < volumes[1], volumes
    rock_one, rock_two = one["regions"]["rock"], two["regions"]["rock"]
    assert rock_one["yielded_volume"] > 0.0 and rock_two["yielded_volume"] > 0.0
    peak_one, peak_two = rock_one["peak_plastic_strain"], rock_two["peak_plastic_strain"]
    shoulder_one = one["monitors"]["shoulder"]["displacement"][0]
    shoulder_two = two["monitors"]["shoulder"]["displacement"][0]
    print(f"yielded volume: one step {rock_one['yielded_volume']:.1f} m^3, two steps {volumes} m^3; peak plastic "
          f"strain {peak_one:.3e} / {peak_two:.3e}; shoulder u_x {shoulder_one * 1e3:.3f} / {shoulder_two * 1e3:.3f} mm")
    assert abs(peak_two - peak_one) > 0.2 * peak_one
    assert abs(shoulder_two - shoulder_one) > 0.05 * abs(shoulder_one)
    # The run after the sequence starts from its plastic state (carried over by cell position).
    run = json.loads((tmp_path / "two" / "run" / "run.json").read_text())
    assert run["nonlinear_regions"]["rock"]["yielded_volume"] == pytest.approx(rock_two["yielded_volume"])
    assert run["nonlinear_regions"]["rock"]["peak_plastic_strain"] == pytest.approx(peak_two)
    assert [step["step"] for step in run["static"]["steps"]] == [1, 2]


@pytest.mark.slow
def test_two_ranks_run_the_sequence_of_one(benches, tmp_path):
    """The Mohr-Coulomb sequence on 2 MPI ranks: the same relaxation steps, plastic volumes and
    monitor displacements as on one (measured 8e-16 of the largest)."""
    one = run_stage(benches_scene(benches, TWO_STEPS, rock=WEAK), tmp_path / "one")
    two = run_stage(benches_scene(benches, TWO_STEPS, rock=WEAK), tmp_path / "two", ranks=2)
    assert two["settings"]["ranks"] == 2
    assert [s["iterations"] for s in two["stages"]] == [s["iterations"] for s in one["stages"]]
    assert [s["plastic_volume"] for s in two["steps"]] == pytest.approx([s["plastic_volume"] for s in one["steps"]])
    a, b = displacements(one), displacements(two)
    assert np.abs(a - b).max() < 1.0e-12 * np.abs(a).max()


@pytest.mark.parametrize("static, key, words", [
    ({"excavate": ["heading"], "step": [{"excavate": ["heading"]}, {"excavate": ["bench"]}]},
     "static.excavate", "not both"),
    ({"relaxation": 0.3, "step": [{"excavate": ["heading"]}, {"excavate": ["bench"]}]},
     "static.relaxation", "not both"),
    ({"step": [{"excavate": ["heading"]}, {"install": ["bench"]}]}, "static.step.1.excavate", "at least one"),
    ({"step": [{"excavate": ["heading"]}, {"excavate": ["heading"]}]}, "static.step.1.excavate.0",
     "static.step.0.excavate names it already"),
    ({"step": [{"excavate": ["heading"], "install": ["bench"]}, {"excavate": ["bench"]}]},
     "static.step.1.excavate.0", "static.step.0.install names it already"),
    ({"step": [{"excavate": ["heading"]}, {"excavate": ["bench"]}], "solver": "direct"}, "static.solver",
     "dynamic relaxation"),
    ({"step": []}, "static.step", "at least one"),
    ({"step": [{"excavate": ["heading"], "support": ["roof"]}, {"excavate": ["bench"]}]}, "static.step.0.support.0",
     "must name a [support.NAME] group"),
])
def test_bad_sequence_keys_are_refused_naming_the_key(benches, static, key, words):
    data = benches_scene(benches, {})
    data["static"] = static
    with pytest.raises(SceneError) as error:
        parse_scene(data)
    assert error.value.key == key and words in str(error.value), str(error.value)


def test_a_region_excavated_later_must_be_elastic(benches):
    data = benches_scene(benches, TWO_STEPS)
    data["materials"]["bench"] = dict(WEAK)
    with pytest.raises(SceneError) as error:
        parse_scene(data)
    assert error.value.key == "static.step.1.excavate.0" and "linear elastic" in str(error.value)


def test_one_step_entry_is_the_one_step_form(benches):
    single = parse_scene(benches_scene(benches, {"step": [{"excavate": ["heading", "bench"], "relaxation": 0.3}]}))
    plain = parse_scene(benches_scene(benches, {"excavate": ["heading", "bench"], "relaxation": 0.3}))
    assert dict(single) == dict(plain)
    assert parse_scene(single.to_json()) == single


SCENE_TOML = """
title = "two benches"
[mesh]
builder = "file"
file = "{msh}"
[materials.rock]
E = 8.0e9
nu = 0.24
rho = 2600.0
[materials.heading]
E = 8.0e9
nu = 0.24
rho = 2600.0
[materials.bench]
E = 8.0e9
nu = 0.24
rho = 2600.0
[time]
duration = 0.002
[boundary.face.ymin]
type = "roller"
[boundary.face.ymax]
type = "roller"
[initial_stress]
stress = [-6.0e6, -5.0e6, -8.0e6, 0.0, 0.0, 0.0]
[output]
xdmf_interval = 0.0
[[static.step]]
excavate = ["heading"]
{install}
[[static.step]]
excavate = ["bench"]
"""


@pytest.mark.parametrize("install, refused", [("", None), ('install = ["rock"]', "static.step.0.install.0")])
def test_check_prints_the_sequence_and_refuses_an_install_before_its_excavation(benches, tmp_path, install, refused):
    """`pyfem check` of a two-step sequence prints each step (what it removes and releases) instead of
    the one-step stage's two stages; a region installed in step 1 that touches the bench step 2
    excavates (cast against rock not yet removed) is refused in one line naming the key, exit 2."""
    path = tmp_path / "scene.toml"
    path.write_text(SCENE_TOML.format(msh=benches, install=install))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    done = subprocess.run([sys.executable, "-m", "pyfem", "check", str(path)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)
    if refused is None:
        assert done.returncode == 0, done.stderr[-3000:]
        assert "heading removed (absent from the model); all of its load released" in done.stdout, done.stdout
        assert "bench removed; all of its load released" in done.stdout
        assert "stage 1 (excavation)" not in done.stdout
        return
    assert done.returncode == 2, done.stdout[-2000:] + done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and refused in errors[0] and "later step excavates" in errors[0], done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_a_run_after_a_sequence_killed_resumes_from_the_sequences_state(benches, tmp_path):
    """kill -9 of a run after a Mohr-Coulomb sequence (2 ranks) once it has written a checkpoint;
    resumed on one rank, it reads the sequence's hand-over (static/hand_over.npz, keyed by position:
    not solved again) and the checkpoint's element-loop state: it finishes with the sequence's plastic
    zone (the yielded volume and peak plastic strain of static.json)."""
    from test_mpi import CHECKPOINTED_RUN, kill_after_first_checkpoint

    path = tmp_path / "scene.toml"
    text = SCENE_TOML.format(msh=benches, install="").replace(
        "[materials.rock]\n", "[materials.rock]\nplasticity = {cohesion = 1.5e6, friction_angle = 30.0, "
        "dilation_angle = 0.0, tensile_strength = 0.5e6}\n", 1)
    path.write_text(text)
    out = tmp_path / "killed"
    env = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    kill_after_first_checkpoint(2, str(path), out, 0.5, ("--set", "time.duration=30.0"), env=env)
    assert (out / "static" / "hand_over.rank1.npz").exists()
    resumed = subprocess.run([sys.executable, "-m", "pyfem", "run", str(path), "--out", str(out), *CHECKPOINTED_RUN,
                              "--set", "time.duration=30.0", "--resume"], cwd=ROOT, env=env, capture_output=True,
                             text=True, timeout=900)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "the static stage read from static/hand_over.npz, not solved again" in resumed.stdout, resumed.stdout
    run = json.loads((out / "run.json").read_text())
    stage = json.loads((out / "static" / "static.json").read_text())
    assert run["status"] == "finished" and run["resumed"][0]["t"] > 0.0
    assert [step["step"] for step in stage["steps"]] == [1, 2] and stage["regions"]["rock"]["yielded_volume"] > 0.0
    for key in ("yielded_volume", "peak_plastic_strain"):
        assert run["nonlinear_regions"]["rock"][key] == pytest.approx(stage["regions"]["rock"][key], rel=1e-12)


SHOTCRETE = {"preset": "concrete", "damage": {}}  # the lining's concrete damage law (C25-like defaults)


@pytest.fixture(scope="module")
def shotcrete_benches(tmp_path_factory):
    path = tmp_path_factory.mktemp("shotcrete") / "benches.msh"
    write_benches_msh(path, shotcrete=True)
    return path


@pytest.mark.slow
def test_shotcrete_of_a_mesh_file_is_installed_like_the_lining(shotcrete_benches, tmp_path):
    """A named region of a `file` mesh ("shotcrete", a 1 m layer under the heading's roof, the lining's
    damage law) installed in step 1 after its relaxation share: absent from step 1's first sub-stage,
    stress-free when it joins, it carries the rest of step 1's load and step 2's. Released before it
    joins: 0.5 or all (relaxation 1) of step 1's load; with all, it carries step 2's only, less."""
    reports = {}
    for relaxation in (0.5, 1.0):
        data = benches_scene(shotcrete_benches, {"step": [
            {"excavate": ["heading"], "relaxation": relaxation, "install": ["shotcrete"]},
            {"excavate": ["bench"]}]})
        data["materials"]["shotcrete"] = dict(SHOTCRETE)
        reports[relaxation] = run_stage(data, tmp_path / str(relaxation))
    stages = reports[0.5]["stages"]
    assert [stage["name"] for stage in stages] == ["step 1 excavation", "step 1 support", "step 2 excavation"]
    assert "shotcrete" not in stages[0]["active_regions"] and "shotcrete" in stages[1]["active_regions"]
    assert stages[0]["regions"].get("shotcrete", {}).get("volume", 0.0) == 0.0  # not there yet
    assert reports[0.5]["steps"][0]["installed"] == ["shotcrete"]
    energy = {lam: report["regions"]["shotcrete"] for lam, report in reports.items()}
    print({lam: (r["volume"], r["damaged_volume"], r["peak_damage"]) for lam, r in energy.items()})
    assert energy[0.5]["volume"] == pytest.approx(4.0 * 2.0 * 1.0)
    crown = {lam: report["monitors"]["crown"]["stress"] for lam, report in reports.items()}
    print("shotcrete crown stress (Pa):", crown)
    # the crown monitor lies on the shotcrete's face: its stress is the shotcrete's, zero when it joined
    assert reports[0.5]["monitors"]["crown"]["region"] == "shotcrete"
    assert abs(crown[0.5]["sxx"]) > abs(crown[1.0]["sxx"]) > 0.0


def test_the_layered_cavern_builder_lays_shotcrete_on_the_rock_face():
    """mesh.parameters.shotcrete = 0.2: a region "shotcrete" one element thick between the lining and the
    rock, 0.2 m at the wall's mid-height; the rock face (cavern_surface) and the lining's inner face
    are where they were, and the lining and the shotcrete fill the lining's former ring (volumes to
    round-off); a layer as thick as the lining's thinnest side is refused naming the key."""
    import gmsh

    from pyfem.geometry import gmsh_session
    from pyfem.geometry.layered_cavern import build_layered_cavern

    small = {"preset": "coarse", "half_width_x": 60.0, "below": 40.0, "above": 40.0, "margin_y": 40.0, "h_far": 15.0}
    faces = {}
    for t in (0.0, 0.2):
        with gmsh_session("shotcrete"):
            summary = build_layered_cavern(dict(small, shotcrete=t))
            tags, coords, _ = gmsh.model.mesh.getNodes()
            x = np.empty((int(tags.max()), 3))
            x[tags.astype(np.int64) - 1] = coords.reshape(-1, 3)
            groups = {gmsh.model.getPhysicalName(d, g): (d, g) for d, g in gmsh.model.getPhysicalGroups()}
            nodes = {}
            for name in ("cavern_surface", "lining_inner", "shotcrete"):
                if name not in groups:
                    continue
                dim, tag = groups[name]
                found = [gmsh.model.mesh.getElements(dim, e)[2] for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)]
                nodes[name] = np.unique(np.concatenate([np.concatenate(f) for f in found]).astype(np.int64) - 1)
        faces[t] = {name: np.unique(np.round(x[n], 9), axis=0) for name, n in nodes.items()}
        faces[t]["summary"] = summary
    plain, shot = faces[0.0]["summary"], faces[0.2]["summary"]
    assert "shotcrete" not in plain["regions"] and "shotcrete" in shot["regions"]
    for name in ("cavern_surface", "lining_inner"):
        np.testing.assert_array_equal(faces[0.0][name], faces[0.2][name])
    lined = plain["region_volumes"]["lining"]
    assert shot["region_volumes"]["lining"] + shot["region_volumes"]["shotcrete"] == pytest.approx(lined, rel=1e-12)
    assert 0.0 < shot["region_volumes"]["shotcrete"] < 0.25 * lined
    shotcrete = faces[0.2]["shotcrete"]
    wall = shotcrete[(np.abs(shotcrete[:, 2] - 30.0) < 4.0) & (shotcrete[:, 0] > 0.0), 0]
    assert np.unique(np.round(wall, 9)).tolist() == pytest.approx([12.45 - 0.2, 12.45])
    assert set(np.round(faces[0.2]["cavern_surface"][:, 0], 9)) >= {12.45}
    with pytest.raises(ValueError, match="mesh.parameters.shotcrete"):
        with gmsh_session("shotcrete"):
            build_layered_cavern(dict(small, shotcrete=1.0))


ROOF = {"type": "bolt", "lines": [[8.0, 1.0, 10.0, 8.0, 1.0, 14.0], [7.0, 1.0, 10.0, 7.0, 1.0, 14.0]],
        "diameter": 0.032, "yield_force": 3.2e5, "bond_stiffness": 1.0e9, "bond_strength": 4.0e5}


def bolted_scene(msh, relaxation: float) -> dict:
    """Two 4 m roof bolts up from the heading's crown, installed in step 1 after `relaxation` of its load."""
    data = benches_scene(msh, {"step": [{"excavate": ["heading"], "relaxation": relaxation, "support": ["roof"]},
                                        {"excavate": ["bench"]}]})
    data["support"] = {"roof": dict(ROOF)}
    return data


@pytest.mark.slow
def test_roof_bolts_installed_in_the_first_step_carry_what_follows(benches, tmp_path):
    """Roof bolts of step 1's `support` join unloaded after its relaxation share: installed after half of
    the heading's load they end at 58.5 kN (tension), after all of it only at 2.6 kN (the bench's load
    alone); the run after the sequence starts with them (run.json's peak force is static.json's) and
    static/support.csv holds them; 2 ranks give the forces of one."""
    reports = {lam: run_stage(bolted_scene(benches, lam), tmp_path / str(lam)) for lam in (0.5, 1.0)}
    assert [s["name"] for s in reports[0.5]["stages"]] == ["step 1 excavation", "step 1 support", "step 2 excavation"]
    assert reports[0.5]["steps"][0]["support"] == ["roof"]
    peak = {lam: report["support"]["roof"]["peak_axial_force"] for lam, report in reports.items()}
    print("roof bolts' peak axial force (N):", peak)
    assert peak[0.5] > 10.0 * peak[1.0] > 0.0
    for lam in peak:
        run = json.loads((tmp_path / str(lam) / "run" / "run.json").read_text())
        assert run["support"]["roof"]["peak_axial_force"] == pytest.approx(peak[lam], rel=1e-12)
        assert (tmp_path / str(lam) / "run" / "static" / "support.csv").exists()
    two = run_stage(bolted_scene(benches, 0.5), tmp_path / "two ranks", ranks=2)
    assert two["support"]["roof"]["peak_axial_force"] == pytest.approx(peak[0.5], rel=1e-10)

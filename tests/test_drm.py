"""The domain-reduction method's free field (pyfem/seismic/drm.py, docs/boundaries.md "Dipping layers").

Slabs one cell thick in y (rollers on the y faces: plane strain in x-z) of 10 m hexahedra, written as
MSH 2.2 files here with the material of each cell from its centroid, so that every model's cells are
the same cells where they overlap (the auxiliary and the reference hold the main model's nodes).
Vertical SV Ricker pulse (f0 = 5 Hz) under the free surface z = 200 m, one time step for all.

- One rock: the DRM input equals the closed-form half-space free field (FreeField) at four monitors.
- Dipping layers (70 deg stripes of soft and stiff rock 30 m wide over the stiff rock below z = 60 m,
  in |x - 50| < 200 m): the DRM input on a 100 x 100 m model (its auxiliary model 900 x 300 m) equals
  the motion of the same model cut out of a 3100 x 300 m one (its sides 1.5 km away: nothing comes
  back from them in the record's time; its bottom, as the auxiliary's, in the stiff rock whose
  closed-form field enters there), while today's half-space input on the same 100 x 100 m model is
  more than 100 % off it. The DRM forces are exact: with the reference itself as the auxiliary model the
  monitors equal the reference's to 1e-10.
"""
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
H = 10.0
DIP = math.radians(70.0)
MONITORS = [(25.0, 5.0, 155.0), (55.0, 5.0, 195.0), (75.0, 5.0, 125.0), (45.0, 5.0, 175.0)]
MATERIALS = {"rock": "E = 20.0e9\nnu = 0.25\nrho = 2600.0\n", "soft": "E = 4.0e9\nnu = 0.3\nrho = 2300.0\n"}
AMPLITUDE = 0.01
# mpirun's environment as it was before this process started MPI (a singleton's variables confuse it).
ENV = dict(os.environ, PYTHONPATH=str(REPO), OMP_NUM_THREADS="1")


def write_slab(path, x0, x1, z0, z1, material_of, names, hole=None):
    """A structured hexahedral slab [x0, x1] x [0, H] x [z0, z1] (MSH 2.2), each cell of the physical
    volume material_of(its centroid's x, z); hole = (x0, x1, z0, z1): no cells there (a cavern)."""
    nx, nz = round((x1 - x0) / H), round((z1 - z0) / H)
    grid = np.arange((nx + 1) * 2 * (nz + 1)).reshape(nz + 1, 2, nx + 1)  # [k, j, i]
    cells, tags = [], []
    for k in range(nz):
        for i in range(nx):
            x, z = x0 + (i + 0.5) * H, z0 + (k + 0.5) * H
            if hole is not None and hole[0] < x < hole[1] and hole[2] < z < hole[3]:
                continue
            cells.append([grid[k, 0, i], grid[k, 0, i + 1], grid[k, 1, i + 1], grid[k, 1, i],
                          grid[k + 1, 0, i], grid[k + 1, 0, i + 1], grid[k + 1, 1, i + 1], grid[k + 1, 1, i]])
            tags.append(names.index(material_of(x, z)) + 1)
    used = np.unique(cells)  # (a node no cell uses is left out: dolfinx wants none)
    number = np.zeros(grid.size, dtype=np.int64)
    number[used] = np.arange(1, len(used) + 1)
    k, j, i = np.unravel_index(used, grid.shape)
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(names))]
    lines += [f'3 {t + 1} "{n}"' for t, n in enumerate(names)]
    lines += ["$EndPhysicalNames", "$Nodes", str(len(used))]
    lines += [f"{n} {x0 + a * H:.10g} {b * H:.10g} {z0 + c * H:.10g}" for n, a, b, c in zip(number[used], i, j, k)]
    lines += ["$EndNodes", "$Elements", str(len(cells))]
    lines += [f"{e + 1} 5 2 {tag} {tag} " + " ".join(map(str, number[cell])) for e, (cell, tag) in enumerate(zip(cells, tags))]
    Path(path).write_text("\n".join(lines + ["$EndElements", ""]))


def dipping(x, z):
    """70 deg stripes of soft and stiff rock in |x - 50| < 200 m above z = 60 m; stiff rock elsewhere."""
    if z < 60.0 or abs(x - 50.0) > 200.0:
        return "rock"
    return "soft" if math.floor((x * math.sin(DIP) + z * math.cos(DIP)) / 30.0) % 2 else "rock"


def write_scene(path, mesh, names, duration, reference_z, auxiliary=None, monitors=MONITORS):
    drm = f'free_field = {{method = "drm", auxiliary = "{auxiliary}"}}\n' if auxiliary else ""
    text = (f'title = "DRM test"\n[mesh]\nbuilder = "file"\nfile = "{mesh}"\n'
            + "".join(f"[materials.{n}]\n{MATERIALS[n]}" for n in names)
            + f"[time]\nduration = {duration}\ndt = 0.0015\n"
            + f'[wave]\ntype = "SV"\nangle = 0.0\nsurface = 200.0\nmedium = "rock"\n'
            + f"reference_point = [0.0, 0.0, {reference_z}]\n"
            + f"motion = {{ricker = {{f0 = 5.0, amplitude = {AMPLITUDE}}}}}\n" + drm
            + '[boundary.face.zmax]\ntype = "free"\n[boundary.face.ymin]\ntype = "roller"\n'
            + '[boundary.face.ymax]\ntype = "roller"\n'
            + "".join(f'[[monitor]]\nname = "m{k}"\npoint = [{p[0]}, {p[1]}, {p[2]}]\n' for k, p in enumerate(monitors))
            + "[output]\ninterval = 0.0015\nxdmf_interval = 0.0\n")
    Path(path).write_text(text)
    return path


def run(scene_path, out):
    """A run on one rank of the distributed model (in this process); the monitors' u (n_monitors, nt, 3)."""
    from pyfem import distributed_model
    from pyfem.scene import load_scene

    summary = distributed_model.run(load_scene(scene_path), out)
    return summary, monitor_displacements(out)


def monitor_displacements(out):
    histories = []
    for k in range(len(MONITORS)):
        data = np.genfromtxt(Path(out) / "monitors" / f"m{k}.csv", delimiter=",", names=True)
        histories.append(np.column_stack([data["ux"], data["uy"], data["uz"]]))
    return data["t"], np.array(histories)


def relative_errors(u, reference):
    return [float(np.linalg.norm(a - b) / np.linalg.norm(b)) for a, b in zip(u, reference)]


def test_drm_with_one_rock_is_the_closed_form_half_space_field(tmp_path):
    from pyfem.scene import load_scene
    from pyfem.seismic.freefield import FreeField
    from pyfem.seismic.setup import input_waveform

    rock = lambda x, z: "rock"  # noqa: E731
    write_slab(tmp_path / "main.msh", 0.0, 100.0, 100.0, 200.0, rock, ["rock"])
    write_slab(tmp_path / "aux.msh", -50.0, 150.0, 50.0, 200.0, rock, ["rock"])
    write_scene(tmp_path / "aux.toml", tmp_path / "aux.msh", ["rock"], 0.6, 50.0, monitors=[])
    main = write_scene(tmp_path / "main.toml", tmp_path / "main.msh", ["rock"], 0.6, 50.0, tmp_path / "aux.toml")
    summary, (t, u) = run(main, tmp_path / "out")
    report = summary["free_field"]
    assert report["method"] == "drm" and report["face_nodes"] == 62 and report["layer_nodes"] == 116
    scene = load_scene(main)
    waveform, grid, _ = input_waveform(scene)
    rock_table = scene["materials"]["rock"]
    closed = FreeField(scene.wave_components(), rock_table["E"], rock_table["nu"], rock_table["rho"], surface=200.0,
                       waveform=waveform, table_grid=grid, reference_point=[0.0, 0.0, 50.0],
                       model_bounds=(np.array([0.0, 0.0, 100.0]), np.array([100.0, 10.0, 200.0])))
    expected = np.transpose(closed.displacement(np.array(MONITORS), t), (1, 0, 2))
    assert np.abs(expected[..., 0]).max() > 0.5 * AMPLITUDE  # the pulse went through (and doubled at the surface)
    assert np.abs(u[..., 0]).max() > 0.5 * AMPLITUDE
    errors = relative_errors(u, expected)
    print("DRM against the closed form", errors, report)
    assert max(errors) < 0.01, errors


def test_drm_refusals(tmp_path):
    from pyfem.scene import SceneError, load_scene

    rock = lambda x, z: "rock"  # noqa: E731
    write_slab(tmp_path / "main.msh", 0.0, 100.0, 100.0, 200.0, rock, ["rock"])
    write_scene(tmp_path / "aux.toml", tmp_path / "main.msh", ["rock"], 0.3, 50.0)
    base = write_scene(tmp_path / "main.toml", tmp_path / "main.msh", ["rock"], 0.3, 50.0, tmp_path / "aux.toml")
    cases = [
        ('free_field = {method = "drm"}', "wave.free_field.auxiliary"),
        (f'free_field = {{method = "half_space", auxiliary = "{tmp_path / "aux.toml"}"}}', "wave.free_field.auxiliary"),
        (f'free_field = {{method = "drm", auxiliary = "{tmp_path / "none.toml"}"}}', "wave.free_field.auxiliary"),
        ('free_field = {method = "dr"}', "wave.free_field.method"),
    ]
    from pyfem.effects import free_field_words

    assert free_field_words(load_scene(base)).startswith("domain-reduction method: the auxiliary scene")  # `check`'s line
    text = Path(base).read_text()
    line = next(x for x in text.splitlines() if x.startswith("free_field"))
    for replacement, key in cases:
        Path(tmp_path / "bad.toml").write_text(text.replace(line, replacement))
        with pytest.raises(SceneError) as error:
            load_scene(tmp_path / "bad.toml")
        assert key in str(error.value) and "\n" not in str(error.value)
    for extra, key in [("[damping]\nalpha = 0.0\nbeta = 0.001\n", "damping.beta"),
                       ('[[wave.layers]]\nmedium = "rock"\nthickness = 10.0\n', "wave.layers")]:
        head, tail = text.split("[boundary.face.zmax]")
        if extra.startswith("[["):
            Path(tmp_path / "bad.toml").write_text(head + extra + "[boundary.face.zmax]" + tail)
        else:
            Path(tmp_path / "bad.toml").write_text(text + extra)
        with pytest.raises(SceneError) as error:
            load_scene(tmp_path / "bad.toml")
        assert key in str(error.value)
    # The CLI: one line, exit code 2.
    Path(tmp_path / "bad.toml").write_text(text.replace(line, cases[0][0]))
    result = subprocess.run([sys.executable, "-m", "pyfem", "check", str(tmp_path / "bad.toml")], cwd=REPO,
                            capture_output=True, text=True, env=ENV, timeout=300)
    assert result.returncode == 2 and "wave.free_field.auxiliary" in result.stderr
    assert "Traceback" not in result.stderr


def test_drm_auxiliary_must_hold_the_layer(tmp_path):
    from pyfem.scene import SceneError

    rock = lambda x, z: "rock"  # noqa: E731
    write_slab(tmp_path / "main.msh", 0.0, 100.0, 100.0, 200.0, rock, ["rock"])
    write_slab(tmp_path / "aux.msh", 0.0, 60.0, 100.0, 200.0, rock, ["rock"])  # too narrow
    write_scene(tmp_path / "aux.toml", tmp_path / "aux.msh", ["rock"], 0.03, 50.0, monitors=[])
    main = write_scene(tmp_path / "main.toml", tmp_path / "main.msh", ["rock"], 0.03, 50.0, tmp_path / "aux.toml")
    with pytest.raises(SceneError) as error:
        run(main, tmp_path / "out")
    assert "wave.free_field.auxiliary" in str(error.value) and "is in no cell" in str(error.value)


# The dipping-layer case: the wave is defined at z = -100 m (the bottom of the auxiliary and the reference).
DIPPING_DURATION = 0.8


@pytest.fixture(scope="module")
def dipping_runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dipping")
    names = ["rock", "soft"]
    write_slab(folder / "main.msh", 0.0, 100.0, 100.0, 200.0, dipping, names)
    write_slab(folder / "aux.msh", -400.0, 500.0, -100.0, 200.0, dipping, names)
    write_slab(folder / "reference.msh", -1500.0, 1600.0, -100.0, 200.0, dipping, names)
    write_scene(folder / "aux.toml", folder / "aux.msh", names, DIPPING_DURATION, -100.0, monitors=[])
    scenes = {"drm": write_scene(folder / "drm.toml", folder / "main.msh", names, DIPPING_DURATION, -100.0,
                                 folder / "aux.toml"),
              "half_space": write_scene(folder / "half_space.toml", folder / "main.msh", names, DIPPING_DURATION,
                                        -100.0),
              "reference": write_scene(folder / "reference.toml", folder / "reference.msh", names,
                                       DIPPING_DURATION, -100.0),
              "exact": write_scene(folder / "exact.toml", folder / "main.msh", names, DIPPING_DURATION, -100.0,
                                   folder / "reference.toml")}
    return {name: run(path, folder / name) for name, path in scenes.items()}


@pytest.mark.slow
def test_drm_dipping_layers_equal_a_larger_model_and_the_half_space_input_does_not(dipping_runs):
    _, (_, reference) = dipping_runs["reference"]
    summary, (_, drm) = dipping_runs["drm"]
    _, (_, half_space) = dipping_runs["half_space"]
    assert np.abs(reference[..., 0]).max(axis=1).min() > 0.3 * AMPLITUDE  # the pulse reached every monitor
    drm_errors, half_space_errors = relative_errors(drm, reference), relative_errors(half_space, reference)
    print("DRM", drm_errors, "half-space", half_space_errors, summary["free_field"])
    assert max(drm_errors) < 0.02, drm_errors  # measured 0.6-1.3 %
    assert min(half_space_errors) > 0.5, half_space_errors  # measured 111-129 %
    # With the reference itself as the auxiliary model: the DRM forces add nothing of their own.
    _, (_, exact) = dipping_runs["exact"]
    assert max(relative_errors(exact, reference)) < 1e-10  # measured 1e-13 (the CSV keeps 11 digits)


@pytest.mark.slow
def test_drm_on_two_ranks_is_the_one_rank_run(tmp_path):
    import shutil

    rock = lambda x, z: "rock"  # noqa: E731
    write_slab(tmp_path / "main.msh", 0.0, 100.0, 100.0, 200.0, rock, ["rock"])
    write_slab(tmp_path / "aux.msh", -50.0, 150.0, 50.0, 200.0, rock, ["rock"])
    write_scene(tmp_path / "aux.toml", tmp_path / "aux.msh", ["rock"], 0.6, 50.0, monitors=[])
    main = write_scene(tmp_path / "main.toml", tmp_path / "main.msh", ["rock"], 0.6, 50.0, tmp_path / "aux.toml")
    _, (_, one) = run(main, tmp_path / "one")
    result = subprocess.run([shutil.which("mpirun"), "--allow-run-as-root", "--oversubscribe", "-n", "2",
                             sys.executable, "-m", "pyfem", "run", str(main), "--out", str(tmp_path / "two")],
                            cwd=REPO, capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-2000:]
    _, two = monitor_displacements(tmp_path / "two")
    assert np.abs(one).max() > 0.5 * AMPLITUDE
    assert np.abs(two - one).max() < 1e-12


def test_drm_refuses_element_loop_rock(tmp_path):
    from pyfem.scene import SceneError

    rock = lambda x, z: "rock"  # noqa: E731
    write_slab(tmp_path / "main.msh", 0.0, 100.0, 100.0, 200.0, rock, ["rock"])
    write_scene(tmp_path / "aux.toml", tmp_path / "main.msh", ["rock"], 0.03, 50.0, monitors=[])
    main = write_scene(tmp_path / "main.toml", tmp_path / "main.msh", ["rock"], 0.03, 50.0, tmp_path / "aux.toml")
    text = Path(main).read_text().replace("rho = 2600.0\n", "rho = 2600.0\nplasticity = {cohesion = 1.0e6, "
                                          "friction_angle = 35.0, tensile_strength = 1.0e6}\n", 1)
    Path(main).write_text(text)
    with pytest.raises(SceneError) as error:
        run(main, tmp_path / "out")
    assert "wave.free_field.method" in str(error.value) and "linear elastic" in str(error.value)


@pytest.mark.slow
def test_drm_with_a_cavern_leaves_the_scattered_field_to_the_faces(tmp_path):
    """The same dipping site with a 20 x 20 m cavern (no cells) in the middle of the 100 x 100 m model:
    the auxiliary model has none, the reference has it. What is left is the faces' absorption of the
    cavern's scattered field, 40 m from it: far below the half-space input's error, and smaller with
    the faces 140 m from it (a 300 x 200 m model, "far")."""
    names, hole = ["rock", "soft"], (40.0, 60.0, 140.0, 160.0)
    write_slab(tmp_path / "main.msh", 0.0, 100.0, 100.0, 200.0, dipping, names, hole)
    write_slab(tmp_path / "aux.msh", -400.0, 500.0, -100.0, 200.0, dipping, names)
    write_slab(tmp_path / "far.msh", -100.0, 200.0, 0.0, 200.0, dipping, names, hole)
    write_slab(tmp_path / "reference.msh", -1500.0, 1600.0, -100.0, 200.0, dipping, names, hole)
    write_scene(tmp_path / "aux.toml", tmp_path / "aux.msh", names, DIPPING_DURATION, -100.0, monitors=[])
    runs = {name: run(write_scene(tmp_path / f"{name}.toml", tmp_path / mesh, names, DIPPING_DURATION, -100.0,
                                  auxiliary), tmp_path / name)[1][1]
            for name, mesh, auxiliary in [("drm", "main.msh", tmp_path / "aux.toml"), ("half_space", "main.msh", None),
                                          ("far", "far.msh", tmp_path / "aux.toml"),
                                          ("reference", "reference.msh", None)]}
    reference = runs["reference"]
    assert np.abs(reference[..., 0]).max(axis=1).min() > 0.3 * AMPLITUDE
    drm_errors, half_space_errors = relative_errors(runs["drm"], reference), relative_errors(runs["half_space"], reference)
    far_errors = relative_errors(runs["far"], reference)
    print("cavern: DRM", drm_errors, "far", far_errors, "half-space", half_space_errors)
    assert max(drm_errors) < 0.35, drm_errors  # measured 7-27 %
    assert max(far_errors) < 0.08 and sum(far_errors) < 0.5 * sum(drm_errors), far_errors  # measured 2.4-6.0 %
    assert min(half_space_errors) > 1.0, half_space_errors  # measured 107-130 %

"""What a run shows a person: the plan and progress lines of `pyfem run`, the region field, every
Q2 node and clean times in fields.xdmf, the processed input's peaks, spectrum and plot."""
import json
import os
import re
import subprocess
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest

from pyfem import solver
from pyfem.fields_file import read_fields
from pyfem.progress import ProgressLines
from pyfem.scene import parse_scene

REPOSITORY = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"
ELCENTRO = REPOSITORY / "data" / "elcentro_1940_ns.txt"

PROGRESS_SCENE = """
title = "progress lines"
[mesh]
size = [20.0, 10.0, 20.0]
h = 5.0
[materials.rock]
preset = "sandstone"
[time]
duration = 0.2
[wave]
type = "SV"
surface = 30.0
[wave.motion]
ricker = { f0 = 10.0, amplitude = 1.0e-3 }
[output]
interval = 0.002
xdmf_interval = 0.0
"""
PROGRESS_LINE = re.compile(r"progress: +(\d+) %  t = (\S+) s of 0.2 s, wall (\S+) (s|min|h), (.*)$")


def test_run_prints_the_plan_then_a_progress_line_every_5_percent_off_a_terminal(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(PROGRESS_SCENE)
    env = dict(os.environ, PYTHONPATH=str(REPOSITORY))
    result = subprocess.run([PYTHON, "-m", "pyfem", "run", str(scene), "--out", str(tmp_path / "run")],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    progress = [k for k, line in enumerate(lines) if line.startswith("progress:")]
    # The plan comes first: dt, steps and the time estimate before the first progress line.
    for label in ("dt:", "steps:", "time estimate:"):
        assert any(line.startswith(label) for line in lines[:progress[0]]), label
    assert "it/s" not in result.stderr and "out/s" not in result.stderr  # no tqdm bar in a pipe
    parsed = [PROGRESS_LINE.match(lines[k]) for k in progress]
    assert all(parsed), [lines[k] for k in progress]
    percent = np.array([int(match[1]) for match in parsed])
    simulated = np.array([float(match[2]) for match in parsed])
    units = {"s": 1.0, "min": 60.0, "h": 3600.0}
    wall = np.array([float(match[3]) * units[match[4]] for match in parsed])
    # 100 samples of 1 %: one line at each 5 %, in order.
    assert percent.tolist() == list(range(5, 101, 5))
    assert np.allclose(simulated, percent / 100 * 0.2, rtol=0, atol=1e-9)
    assert np.all(np.diff(simulated) > 0) and np.all(np.diff(wall) >= 0)
    assert all(match[5].startswith("estimated end in ") for match in parsed[:-1])
    assert parsed[-1][5] == "done"
    assert progress[-1] < next(k for k, line in enumerate(lines) if line.startswith("run finished"))


def test_progress_lines_when_stdout_is_a_terminal_and_stderr_is_not(tmp_path):
    """As under mpirun (Open MPI gives a rank's stdout a terminal, its stderr a pipe): the bar, on
    stderr, does not show there, so the lines do, on stdout."""
    import pty

    scene = tmp_path / "scene.toml"
    scene.write_text(PROGRESS_SCENE)
    env = dict(os.environ, PYTHONPATH=str(REPOSITORY))
    leader, follower = pty.openpty()
    process = subprocess.Popen([PYTHON, "-m", "pyfem", "run", str(scene), "--out", str(tmp_path / "run")],
                               cwd=tmp_path, env=env, stdout=follower, stderr=subprocess.PIPE)
    os.close(follower)
    chunks = []
    while True:
        try:
            chunk = os.read(leader, 65536)
        except OSError:  # the terminal closed with the process
            break
        if not chunk:
            break
        chunks.append(chunk)
    stderr = process.communicate(timeout=300)[1].decode()
    os.close(leader)
    assert process.returncode == 0, stderr
    lines = b"".join(chunks).decode().splitlines()
    assert sum(line.startswith("progress:") for line in lines) == 20
    assert any(line.startswith("run finished") for line in lines)
    assert "it/s" not in stderr and "out/s" not in stderr


def test_progress_lines_with_coarse_samples_and_a_fake_clock():
    """Samples 10 % apart: a line at each; the estimate extrapolates wall time per simulated second."""
    lines = []
    clock = iter(np.arange(0.0, 100.0, 2.0))
    progress = ProgressLines(1.0, stream=type("S", (), {"write": lambda self, text: lines.append(text),
                                                        "flush": lambda self: None})(),
                             clock=lambda: float(next(clock)))
    progress.start(0.0)
    t = 0.0
    for _ in range(10):
        t += 0.1
        progress(t)
    text = "".join(lines).splitlines()
    assert len(text) == 10 == progress.lines
    assert text[0].startswith("progress:  10 %  t = 0.1 s of 1 s, wall 2 s, estimated end in 18 s")
    assert text[4].startswith("progress:  50 %  t = 0.5 s of 1 s, wall 10 s, estimated end in 10 s")
    assert text[-1] == "progress: 100 %  t = 1 s of 1 s, wall 20 s, done"


def test_progress_lines_count_a_records_lead_in():
    """A loop that starts in a record's lead-in (t < 0, record time) reports it (issue 51: the lines
    were silent until t = 0): the percentage runs over the lead-in and the duration."""
    lines = []
    clock = iter(np.arange(0.0, 100.0, 1.0))
    progress = ProgressLines(1.0, stream=type("S", (), {"write": lambda self, text: lines.append(text),
                                                        "flush": lambda self: None})(),
                             step=0.25, clock=lambda: float(next(clock)))
    progress.start(-3.0)
    for t in (-2.5, -2.0, -1.0, 0.0, 0.5, 1.0):
        progress(t)
    text = "".join(lines).splitlines()
    assert len(text) == 4 == progress.lines
    assert text[0].startswith("progress:  25 %  t = -2 s (the record's lead-in) of 1 s")
    assert text[2].startswith("progress:  75 %  t = 0 s of 1 s")
    assert text[-1].startswith("progress: 100 %  t = 1 s of 1 s")


def two_layer_scene(order: int) -> dict:
    """Two regions (a below z = 10, b above) under El Centro at half its 0.32 g PGA (wave.scale)."""
    return parse_scene({
        "title": f"two layers Q{order}",
        "mesh": {"builder": "box", "size": [20.0, 10.0, 20.0], "h": 5.0 * order, "order": order,
                 "layers": [{"material": "a", "thickness": 10.0}, {"material": "b", "thickness": 10.0}]},
        "materials": {"a": {"preset": "sandstone"}, "b": {"preset": "non_sandstone"}},
        "time": {"duration": 0.06},
        "wave": {"type": "SV", "surface": 30.0, "medium": "a", "scale": 0.5,
                 "motion": {"record": {"file": str(ELCENTRO), "units": "g", "pga": 0.32,
                                       "window": [0.0, 20.0], "lead_in": 0.0}}},
        "output": {"interval": 0.01, "xdmf_interval": 0.03, "fields": ["displacement", "stress"]},
    })


@pytest.fixture(scope="module", params=[1, 2], ids=["Q1", "Q2"])
def two_layer_run(request, tmp_path_factory):
    """(run directory, scene) of a short run."""
    out = tmp_path_factory.mktemp(f"q{request.param}") / "run"
    scene = two_layer_scene(request.param)
    solver.run(scene, out)
    return out, scene


def test_region_field_has_each_cells_region_id(two_layer_run):
    out, _ = two_layer_run
    legend = json.loads((out / "run.json").read_text())["regions"]
    assert set(legend) == {"a", "b"} and legend["a"] != legend["b"]
    fields = read_fields(out / "fields.xdmf")
    cells = fields.cells
    centroid_z = fields.points[cells].mean(axis=1)[:, 2]
    expected = np.where(centroid_z < 10.0, legend["a"], legend["b"])
    assert len(fields.steps) == 3
    for _, _, cell_data in fields.steps:
        region = cell_data["region"]
        assert region.dtype.kind == "i" and region.shape == (len(cells),)
        assert np.array_equal(region, expected)
        assert cell_data["stress"].shape == (len(cells), 6)
    assert np.count_nonzero(expected == legend["a"]) == np.count_nonzero(expected == legend["b"])
    assert np.count_nonzero(expected == legend["a"]) == len(cells) // 2


def grid(spacing: float) -> np.ndarray:
    """The points of the 20 x 10 x 20 m box on a grid of `spacing` (m), sorted by z, y, x."""
    axes = [np.arange(0.0, size + 1e-9, spacing) for size in (20.0, 10.0, 20.0)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return points[np.lexsort(points.T)]


def test_fields_hold_every_node_and_clean_times(two_layer_run):
    """Every vertex of the mesh, at its coordinates, each once; cells of positive, equal volumes that
    fill the box. Q1 (h = 5): the 5 x 3 x 5 nodes. Q2 (h = 10): also the 5 x 3 x 5 nodes, every node
    (27-node hexahedra). (The values at the nodes: the monitors' in tests/test_run.py; every node of a
    second-order mesh in tests/test_quadratic_fields.py.)"""
    out, scene = two_layer_run
    order = scene["mesh"]["order"]
    fields = read_fields(out / "fields.xdmf")
    points, cells = fields.points, fields.cells
    rounded = np.round(points, 9) + 0.0  # (the mesh generator's coordinates carry round-off; + 0.0: no -0.0)
    written = rounded[np.lexsort(rounded.T)]
    assert np.array_equal(written, grid(5.0))
    displacement = fields.steps[-1][1]["displacement"]
    assert displacement.shape == (len(points), 3) and 0.0 < np.max(np.abs(displacement)) < 1.0
    # Positive, equal volumes (VTK order) filling the 4000 m^3 box.
    corners = points[cells]
    edges = corners[:, [1, 3, 4]] - corners[:, [0, 0, 0]]
    volumes = np.linalg.det(edges)
    assert np.all(volumes > 0.0) and np.allclose(volumes, volumes[0]) and np.isclose(volumes.sum(), 4000.0)
    # Times as sampled: 0.03 and 0.06 exactly, not 0.060000000000000005 (the double a sum of steps gives).
    times = [float(element.get("Value")) for element in ElementTree.parse(out / "fields.xdmf").iter("Time")]
    assert sorted(set(times)) == [0.0, 0.03, 0.06]


def test_input_motion_peaks_spectrum_and_plot(two_layer_run):
    """run.json's PGA, PGV, PGD are those of the processed record the kernel is driven with, x wave.scale."""
    from pyfem.seismic.records import STANDARD_GRAVITY
    from pyfem.seismic.setup import processed_record

    out, scene = two_layer_run
    motion = json.loads((out / "run.json").read_text())["input_motion"]
    processed = processed_record(scene["wave"]["motion"]["record"])
    assert motion["kind"] == "record" and motion["scale"] == 0.5
    assert motion["pga"] == pytest.approx(0.5 * np.max(np.abs(processed.acceleration)), rel=1e-14)
    assert motion["pga"] == pytest.approx(0.5 * 0.32 * STANDARD_GRAVITY, rel=1e-12)
    assert motion["pga_g"] == pytest.approx(0.16, rel=1e-12)
    assert motion["pgv"] == pytest.approx(0.5 * np.max(np.abs(processed.velocity)), rel=1e-14)
    assert motion["pgd"] == pytest.approx(0.5 * np.max(np.abs(processed.displacement)), rel=1e-14)
    k = int(np.argmax(np.abs(processed.acceleration)))
    assert motion["t_pga"] == pytest.approx(processed.t[k], abs=1e-9)
    assert motion["within_run"]["until"] == pytest.approx(0.06)
    assert motion["within_run"]["pga"] <= motion["pga"]
    spectrum = motion["spectrum"]
    assert spectrum["damping"] == 0.05 and len(spectrum["periods"]) == len(spectrum["psa"]) > 20
    assert max(spectrum["psa"]) > 2 * motion["pga"]   # a 5 % spectrum of El Centro peaks near 3 x PGA
    assert spectrum["psa"][0] == pytest.approx(motion["pga"], rel=0.1)  # T = 0.02 s: close to the PGA
    assert (out / "plots" / "input.png").stat().st_size > 10_000


def test_a_run_shorter_than_the_ricker_reports_the_wavelets_peaks_and_warns(tmp_path):
    """A run that stops before the wavelet's peak (0.1 s of a 5 Hz Ricker centred at 0.3 s): the
    input's peaks are the whole wavelet's (as a record's are the whole record's), "within_run" what
    the run saw, and the scene says the run stops before the peak."""
    def scene(duration):
        return parse_scene({"title": "short", "mesh": {"size": [20.0, 20.0, 40.0], "h": 10.0},
                            "materials": {"rock": {"preset": "sandstone"}}, "time": {"duration": duration},
                            "wave": {"type": "SV", "surface": 40.0, "motion": {"ricker": {"f0": 5.0, "amplitude": 1e-3}}},
                            "output": {"interval": 0.01, "xdmf_interval": 0.0}})
    short, whole = scene(0.1), scene(0.6)
    assert any("stops before the wavelet's peak" in warning for warning in short.warnings), short.warnings
    assert not any("Ricker" in warning for warning in whole.warnings)
    seen = solver.run(short, tmp_path / "short")["input_motion"]
    full = solver.run(whole, tmp_path / "whole")["input_motion"]
    # The Ricker's peak acceleration: amplitude x 6 (pi f0)^2 at t0.
    assert full["pga"] == pytest.approx(1e-3 * 6.0 * (np.pi * 5.0) ** 2, rel=1e-3)
    assert seen["pga"] == pytest.approx(full["pga"], rel=1e-12)
    assert seen["within_run"]["pga"] < 0.05 * seen["pga"]


def test_no_input_motion_without_a_wave(tmp_path):
    scene = parse_scene({"title": "free", "mesh": {"size": [10.0, 10.0, 10.0], "h": 5.0},
                         "materials": {"rock": {"preset": "sandstone"}}, "time": {"duration": 0.01},
                         "output": {"interval": 0.005, "xdmf_interval": 0.0}})
    summary = solver.run(scene, tmp_path / "run")
    assert "input_motion" not in summary and summary["regions"] == {"rock": summary["regions"]["rock"]}
    assert not (tmp_path / "run" / "plots" / "input.png").exists()


def test_deformed_section_keeps_the_most_deformed_sample(two_layer_run):
    """plots/deformed_section.png shows the sample where the section through the monitors is most
    deformed relative to its mean: a rigid translation counts nothing, the larger of two shears wins."""
    from pyfem.deformation import DeformedSection, vertex_nodes
    from pyfem.output import cell_regions

    out, scene = two_layer_run
    summary = json.loads((out / "run.json").read_text())
    kept = summary["deformed_section"]
    assert kept["largest"] > 0.0, "the wave deformed the section"
    assert 0.0 < kept["t"] <= summary["time_reached"] + 1e-12
    assert (out / "plots" / "deformed_section.png").stat().st_size > 20000

    from mpi4py import MPI

    from pyfem.operators import build_model

    model = build_model(scene, MPI.COMM_SELF)
    section = DeformedSection(model.node_coords, vertex_nodes(model), None, cell_regions(model))
    assert set(np.unique(section.regions)) == set(summary["regions"].values())  # both layers cut
    tracker = DeformedSection(model.node_coords, vertex_nodes(model), None, np.zeros(model.n_cells, dtype=np.int32))
    x = model.node_coords
    translation = np.tile([0.3, -0.2, 0.1], len(x))
    shear = np.zeros((len(x), 3))
    shear[:, 0] = 1e-3 * (x[:, 2] - x[:, 2].mean())  # u_x grows with z
    tracker.update(0.1, translation)
    assert tracker.largest == pytest.approx(0.0, abs=1e-12)
    tracker.update(0.2, (2.0 * shear).ravel() + translation)
    tracker.update(0.3, shear.ravel())
    section = x[tracker.nodes]
    expected = 2e-3 * np.abs(section[:, 2] - section[:, 2].mean()).max()
    assert tracker.t == 0.2 and tracker.largest == pytest.approx(expected, rel=1e-9)


def test_monitor_plot_draws_the_stress_history_when_the_file_has_stress(tmp_path):
    """plots/monitor_NAME.png gains a fourth panel, the total stress and s1 (MPa), from the
    monitor's stress columns; a file without them keeps three panels."""
    from matplotlib import image

    from pyfem import plots

    t = np.linspace(0.0, 1.0, 11)
    kinematics = {name: np.sin(t + k) for k, name in enumerate(
        ["ux", "uy", "uz", "vx", "vy", "vz", "ax", "ay", "az"])}
    stress = {name: 1e6 * np.cos(t + k) for k, name in enumerate(["sxx", "syy", "szz", "sxy", "syz", "sxz", "s1"])}
    heights = {}
    for label, columns in (("plain", kinematics), ("stress", {**kinematics, **stress})):
        csv = tmp_path / f"{label}.csv"
        names = ["t", *columns]
        np.savetxt(csv, np.column_stack([t, *columns.values()]), delimiter=",", header=",".join(names), comments="")
        png = tmp_path / f"monitor_{label}.png"
        plots.monitor(png, csv)
        heights[label] = image.imread(png).shape[0]
    assert heights["stress"] > 1.2 * heights["plain"]  # 9 in against 7 in: the stress panel is there

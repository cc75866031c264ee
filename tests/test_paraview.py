"""The run's fields.xdmf opens in ParaView's own Python (slow tier).

A short run of the case-3 scene writes fields.xdmf/.h5; `xvfb-run -a pvbatch` loads it with
ParaView's reader, finds the output time of the largest displacement magnitude, renders the
magnitude there to a PNG and prints what it read. The test checks the PNG is an image with
content (not a blank window) and that ParaView read the same peak magnitude, time and number
of points as h5py reads from the .h5 independently.

Needs Debian's packages paraview, python3-paraview and xvfb (pvbatch aborts without an X
server, hence xvfb-run), which `make test-slow` installs: an optional external tool (README
"Verification"), so a bare `pytest -m slow` without them skips with that reason, the one skip in tests/
(`make test` and `make test-slow` print skip reasons, -rs).
"""
import json
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.slow

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
CASE3 = REPOSITORY / "workflows" / "scenes" / "case3_contact_coarse.toml"

PVBATCH_SCRIPT = r'''
import json
import sys

from paraview.simple import ColorBy, GetActiveViewOrCreate, SaveScreenshot, Show, XDMFReader

xdmf, png = sys.argv[1], sys.argv[2]
# ParaView's XDMF (2) reader: its Xdmf3 readers, OpenDataFile's default pick, show no points
# for meshio's time series. The file also holds the bare "mesh" grid that the time steps
# include by XPointer; read only the time series.
reader = XDMFReader(FileNames=[xdmf])
reader.UpdatePipelineInformation()
reader.GridStatus = [grid for grid in reader.GridStatus if grid != "mesh"]
reader.UpdatePipelineInformation()
times = list(reader.TimestepValues)
peak_time, peak = times[0], -1.0
for t in times:
    reader.UpdatePipeline(t)
    magnitude_range = reader.PointData["displacement"].GetRange(-1)   # -1: vector magnitude
    if magnitude_range[1] > peak:
        peak_time, peak = t, magnitude_range[1]
view = GetActiveViewOrCreate("RenderView")
view.ViewSize = [800, 600]
view.ViewTime = peak_time
reader.UpdatePipeline(peak_time)
display = Show(reader, view)
ColorBy(display, ("POINTS", "displacement", "Magnitude"))
display.RescaleTransferFunctionToDataRange(True, False)
display.SetScalarBarVisibility(view, True)
view.CameraPosition = [400.0, -600.0, 300.0]
view.CameraFocalPoint = [0.0, 0.0, 30.0]
view.CameraViewUp = [0.0, 0.0, 1.0]
view.ResetCamera()
SaveScreenshot(png, view, ImageResolution=[800, 600])
info = reader.GetDataInformation()
print("PVRESULT " + json.dumps({"times": times, "peak_time": peak_time, "peak": peak,
                                "points": info.GetNumberOfPoints()}))
'''


@pytest.fixture(scope="module")
def case3_run(tmp_path_factory):
    """A short run of the case-3 scene (static stage, contact, lining) with fields every 0.02 s."""
    if shutil.which("pvbatch") is None or shutil.which("xvfb-run") is None:
        pytest.skip("pvbatch or xvfb-run not installed: this check needs Debian's paraview, python3-paraview and "
                    "xvfb, which `make test-slow` installs (scripts/setup.sh --with-paraview)")
    from pyfem.scene import load_scene
    from pyfem.solver import run

    scene = load_scene(CASE3, ["time.duration=0.06", "output.xdmf_interval=0.02", "wave.motion.record.lead_in=0.0"])
    out = tmp_path_factory.mktemp("paraview") / "run"
    run(scene, out)
    return out


def test_pyfem_view_renders_regions_and_interfaces_and_writes_a_state(case3_run):
    """`pyfem view RUN` (pyfem/pvbatch_view.py under xvfb-run): the picture shows the cut model
    coloured by region and a second view with the interfaces coloured by slip and the lining; the
    ParaView state names the run's fields file; the printed line says what was shown."""
    result = subprocess.run([sys.executable, "-m", "pyfem", "view", str(case3_run)], capture_output=True,
                            text=True, timeout=600, cwd=REPOSITORY)
    assert result.returncode == 0, result.stderr[-3000:]
    for name in ("lining", "sandstone", "non_sandstone"):
        assert name in result.stdout
    assert "interfaces coloured by slip" in result.stdout
    png, state = case3_run / "plots" / "paraview.png", case3_run / "paraview.pvsm"
    from matplotlib import image

    pixels = image.imread(png)[..., :3]
    assert pixels.shape[:2] == (600, 1600)  # two views side by side
    for half in (pixels[:, :800], pixels[:, 800:]):
        colours = np.unique((half.reshape(-1, 3) * 255).astype(np.uint8), axis=0)
        assert len(colours) > 50 and half.std() > 0.05  # each view rendered something coloured
    text = state.read_text()
    assert "fields.xdmf" in text
    for name in ("interfaces", "lining", "cut at the section", "deformed"):
        assert name in text
    # Bad input: one line, exit 2.
    missing = subprocess.run([sys.executable, "-m", "pyfem", "view", str(case3_run / "nothing")],
                             capture_output=True, text=True, timeout=60, cwd=REPOSITORY)
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1 and "run.json" in missing.stderr
    # Fields without a displacement (output.fields leaves it out): the script's one line, exit 2.
    no_displacement = case3_run.parent / "no_displacement"
    shutil.copytree(case3_run, no_displacement)
    xdmf = no_displacement / "fields.xdmf"
    xdmf.write_text(xdmf.read_text().replace('Name="displacement"', 'Name="not_displacement"'))
    refused = subprocess.run([sys.executable, "-m", "pyfem", "view", str(no_displacement)], capture_output=True,
                             text=True, timeout=600, cwd=REPOSITORY)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and "displacement" in refused.stderr


def test_fields_xdmf_renders_in_pvbatch(case3_run, tmp_path):
    pvbatch, xvfb_run = shutil.which("pvbatch"), shutil.which("xvfb-run")
    out = case3_run
    script = tmp_path / "render.py"
    script.write_text(PVBATCH_SCRIPT)
    png = tmp_path / "displacement.png"
    command = [xvfb_run, "-a", pvbatch, str(script), str((out / "fields.xdmf").resolve()), str(png)]
    # On a shared machine the X server xvfb-run starts is sometimes gone when pvbatch opens its
    # window ("bad X server connection", seen ~1 in 3 here while others run Xvfb too): retry that
    # case only; any other failure fails at once.
    for _ in range(4):
        result = subprocess.run(command, capture_output=True, text=True, timeout=600)
        if result.returncode == 0 or "bad X server connection" not in result.stderr:
            break
    assert result.returncode == 0, result.stderr[-3000:]
    line = next(text for text in result.stdout.splitlines() if text.startswith("PVRESULT "))
    read = json.loads(line.removeprefix("PVRESULT "))

    # The same numbers from the .xdmf/.h5, read with ElementTree and h5py, not ParaView.
    import xml.etree.ElementTree as ElementTree

    import h5py

    tree = ElementTree.parse(out / "fields.xdmf")
    geometry = tree.find(".//Geometry/DataItem").text.strip().split(":")[-1]
    displacement = [item.find("DataItem").text.strip().split(":")[-1]
                    for item in tree.iter("Attribute") if item.get("Name") == "displacement"]
    with h5py.File(out / "fields.h5") as h5:
        n_points = h5[geometry].shape[0]
        peaks = [float(np.linalg.norm(h5[name][()], axis=1).max()) for name in displacement]
    assert len(peaks) == 4
    assert len(read["times"]) == 4                  # t = 0, 0.02, 0.04, 0.06 s
    assert read["points"] == n_points                # the time series only, not the bare "mesh" grid
    assert read["peak"] == pytest.approx(max(peaks), rel=1e-6)
    assert read["peak"] > 0.0

    from matplotlib import image

    pixels = image.imread(png)[..., :3]
    assert pixels.shape[:2] == (600, 800)
    colours = np.unique((pixels.reshape(-1, 3) * 255).astype(np.uint8), axis=0)
    assert len(colours) > 50                         # a rendered, coloured mesh, not a blank window
    assert pixels.std() > 0.05

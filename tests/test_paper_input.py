"""The paper's own seismic input on a homogeneous box (workflows/scenes/paper_input_box.toml).

SV carrying the El Centro 1940 N-S record (PGA 0.32 g, first 20 s) plus P carrying 2/3 of
it, both along (1/2, 0, sqrt(3)/2), reference point at the model origin. A homogeneous box
must reproduce the exact free field (ux_ff.. columns of the monitors), return to it once
the shaking is over (no drift), and close its energy balance.
"""
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from conftest import ENERGY_BALANCE, rel_error
from pyfem import solver
from pyfem.distributed_model import model_in_memory
from pyfem.scene import load_scene
from pyfem.seismic.freefield import ReferencePointWarning

SCENE = Path(__file__).resolve().parents[1] / "workflows" / "scenes" / "paper_input_box.toml"
MONITORS = ("centre", "low", "high")
# Default tier: 4 s of record around the strong motion (PGA at 2.02 s), band 0.5-5 Hz (a short
# filter precursor: the motion starts 2.7 s into the table), 20-m elements (11 per shortest
# shear wavelength at 5 Hz).
SHORT = ["mesh.h=20", "wave.motion.record.window=[0,4]", "wave.motion.record.band=[0.5,5]",
         "time.duration=4.8"]  # record time: the 2.7 s precursor runs before t = 0


def histories(run_dir):
    """(t, u, u_ff, v, v_ff) of the monitors: arrays (m, nt, 3) in m and m/s."""
    columns = {key: [] for key in ("u", "u_ff", "v", "v_ff")}
    for name in MONITORS:
        data = np.genfromtxt(run_dir / "monitors" / f"{name}.csv", delimiter=",", names=True)
        for key in columns:
            prefix, suffix = key[0], key[1:]
            columns[key].append(np.column_stack([data[f"{prefix}{c}{suffix}"] for c in "xyz"]))
    return (data["t"],) + tuple(np.array(columns[key]) for key in ("u", "u_ff", "v", "v_ff"))


def test_paper_scene_is_the_papers_input():
    """The scene says what the paper says: two components along (1/2, 0, sqrt 3/2), P at 2/3, PGA 0.32 g."""
    scene = load_scene(SCENE)
    components = scene.wave_components()
    assert [c["type"] for c in components] == ["SV", "P"]
    assert components[1]["scale"] == pytest.approx(2.0 / 3.0) and components[0]["scale"] == 1.0
    from pyfem.seismic.freefield import IncidentWave

    for c in components:
        direction = IncidentWave(c["type"], c["angle"], c["azimuth"]).direction
        assert direction == pytest.approx([0.5, 0.0, math.sqrt(3.0) / 2.0], abs=1e-15)
    record = scene["wave"]["motion"]["record"]
    assert record["units"] == "g" and record["pga"] == 0.32 and record["window"] == [0.0, 20.0]
    assert scene["wave"]["reference_point"] == [0.0, 0.0, 0.0] == scene["mesh"]["origin"]


def test_reference_point_at_the_model_origin():
    """Origin = min corner: the corner both wavefronts reach first, so no delay is negative.

    In a model centred on the origin the lower corner gets tau = -(100/2 + 100 sqrt(3)/2)/c_s
    = -0.123 s; that cuts only the quiet start of the processed record (the filter precursor:
    6e-4 of the peak displacement here, below the 1e-3 warning level), so no warning either.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("error", ReferencePointWarning)
        simulation = model_in_memory(load_scene(SCENE, SHORT), solve_stage=False)
        assert len(simulation.input_arrays["tau"]) and simulation.input_arrays["tau"].min() == pytest.approx(0.0, abs=1e-12)
        centred = model_in_memory(load_scene(SCENE, SHORT + [
            "mesh.origin=[-100,-100,-100]", "wave.surface=400", "monitor.0.point=[0,0,0]",
            "monitor.1.point=[0,0,-50]", "monitor.2.point=[0,0,50]"]), solve_stage=False)
    cut = centred.freefield.start_cut(centred.part.model.node_coords)
    expected = -(100.0 * 0.5 + 100.0 * math.sqrt(3.0) / 2.0) / centred.freefield.c_s
    print("centred model:", cut)
    assert cut["delay"] == pytest.approx(expected, rel=1e-9)
    assert 0.0 < cut["fraction"] < 1e-3


def test_paper_input_reproduces_free_field_short(tmp_path):
    """4 s of El Centro through SV + 2/3 P on a 20-m box: displacement and velocity match the free field.

    Measured: displacement error 1.3e-3, velocity error 4.1e-3 (relative L2, 3 monitors).
    """
    summary = solver.run(load_scene(SCENE, SHORT), tmp_path / "run")
    t, u, u_ff, v, v_ff = histories(tmp_path / "run")
    error_u, error_v = rel_error(u, u_ff), rel_error(v, v_ff)
    print(f"paper input, short: displacement error {error_u:.2e}, velocity error {error_v:.2e}, "
          f"peak |u_ff| {np.abs(u_ff).max():.4f} m, {summary['steps']} steps, "
          f"loop {summary['loop_seconds']:.2f} s, energy balance {summary['energy']['balance_error']:.2e}")
    assert np.abs(v_ff).max() > 0.1  # the strong motion is inside the window (m/s)
    assert np.abs(u_ff[..., 2]).max() > 0.1 * np.abs(u_ff[..., 0]).max()  # the P (and SV) move z too
    # about twice the measured 1.32e-3 / 4.11e-3: catches a free field off by more than 0.3 % of the peak
    # (not the input traction 1 % off: 2.7e-3 / 7.5e-3 then; the full record's test catches that)
    assert error_u < 3e-3 and error_v < 8e-3
    # global stepping's identity: catches any fraction of a work term missing (El Centro input's work)
    assert summary["energy"]["balance_error"] < ENERGY_BALANCE


@pytest.mark.slow
def test_paper_input_full_record_has_no_drift(tmp_path):
    """The whole scene (20 s of record, 30 s of motion): free field reproduced, back to it at the end.

    Measured: displacement error 4.4e-5, velocity 4.0e-4; after the shaking (last 5 s)
    |u - u_ff| <= 4.5e-6 of the peak, final |u| 1e-11 of the peak; energy balance 7e-15.
    """
    summary = solver.run(load_scene(SCENE), tmp_path / "run")
    t, u, u_ff, v, v_ff = histories(tmp_path / "run")
    peak = np.abs(u_ff).max()
    after = t > t[-1] - 5.0
    print(f"paper input, full: displacement error {rel_error(u, u_ff):.2e}, "
          f"velocity {rel_error(v, v_ff):.2e}, "
          f"after the shaking max |u - u_ff| / peak {np.abs(u - u_ff)[:, after].max() / peak:.2e}, "
          f"final |u| / peak {np.abs(u[:, -1]).max() / peak:.2e}, energy balance "
          f"{summary['energy']['balance_error']:.2e}, loop {summary['loop_seconds']:.1f} s")
    # about twice the measured 4.4e-5 / 4.0e-4: catches the input traction 1 % off (2.6e-4 / 2.3e-3)
    assert rel_error(u, u_ff) < 1e-4 and rel_error(v, v_ff) < 8e-4
    # measured 4.5e-6: catches a drift after the shaking
    assert np.abs(u - u_ff)[:, after].max() < 1e-5 * peak
    # measured 1.0e-11: the record ends at rest, and so does the box
    assert np.abs(u[:, -1]).max() < 3e-11 * peak
    # global stepping's identity: catches any fraction of a work term missing (El Centro input's work)
    assert summary["energy"]["balance_error"] < ENERGY_BALANCE

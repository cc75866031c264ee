"""Where a step's time goes (issue 12): the kernel's per-phase timers (Stepper.phase_seconds,
cpp_kernels/stepper.hpp PhaseTimes), run.json "time_per_step" and the plan's split.

Timings are never compared with thresholds here (benchmarks do that): the tests check that the
phases account for the time loop, and that an effect that is off takes no time (contact, the
element loop)."""
import json

import pytest

from pyfem import solver
from pyfem.clock import DISTRIBUTED_PHASES, PHASES
from test_contact import block_scene
from test_run_outputs import two_layer_scene


def time_per_step(out):
    return json.loads((out / "run.json").read_text())


@pytest.mark.parametrize("scene_name", ["wave, no contact", "contact, no wave"])
def test_phases_account_for_the_time_loop(tmp_path, scene_name):
    scene = two_layer_scene(1) if scene_name == "wave, no contact" else block_scene(30.0, duration=0.2)
    solver.run(scene, tmp_path / "run")
    summary = time_per_step(tmp_path / "run")
    split = summary["time_per_step"]
    assert set(split) == {*PHASES, *DISTRIBUTED_PHASES, "output", "other"}
    steps = summary["steps"]
    loop_ms = 1e3 * summary["loop_seconds"] / steps
    total = sum(entry["ms_per_step"] for entry in split.values())
    assert total == pytest.approx(loop_ms, rel=1e-9)  # "other" is the loop's remainder, >= 0
    assert all(entry["ms_per_step"] >= 0.0 for entry in split.values())
    kernel = sum(split[name]["ms_per_step"] for name in PHASES)
    # The kernel's phases lie inside the loop (what is left, "other", is Python between the
    # kernel's calls: on these tiny models a large share, on the case study's below 1 %).
    assert 0.0 < kernel + split["output"]["ms_per_step"] <= loop_ms * (1 + 1e-9)
    assert split["stiffness"]["ms_per_step"] > 0.0 and split["update"]["ms_per_step"] > 0.0
    assert split["element_loop"]["ms_per_step"] == 0.0, "no nonlinear material: no element loop"
    if scene_name == "wave, no contact":
        assert split["contact"]["ms_per_step"] == 0.0, "no contact: no contact time"
        assert split["input_forces"]["ms_per_step"] > 0.0
    else:
        assert split["contact"]["ms_per_step"] > 0.0


def test_plan_prints_the_phase_split():
    plan = solver.plan(two_layer_scene(1))
    line = plan["time per step"]
    for name in ("update", "stiffness", "input_forces", "contact"):
        assert name in line


def test_local_stepping_reports_its_phases(tmp_path):
    """The local stepper's own timers (LocalStepper.phase_seconds): a yielding layer and a sliding
    interface at their rates, every phase inside the loop, steps counted in fine steps."""
    from test_local_stepping import two_layer_contact_scene

    scene = two_layer_contact_scene(True, True, cohesion=0.0, friction_angle=5.0,
                                    soft_plasticity={"cohesion": 4.0e5, "friction_angle": 30.0, "tensile_strength": 2.0e5, "damage_max": 0.9, "damage_plastic_strain": 0.005})
    solver.run(scene, tmp_path / "run")
    summary = time_per_step(tmp_path / "run")
    split = summary["time_per_step"]
    loop_ms = 1e3 * summary["loop_seconds"] / summary["steps"]
    kernel = sum(split[name]["ms_per_step"] for name in PHASES)
    assert 0.0 < kernel <= loop_ms * (1 + 1e-9)
    for name in PHASES:  # every phase ran: drifts, cells, input, kicks, pair impulses
        assert split[name]["ms_per_step"] > 0.0, name

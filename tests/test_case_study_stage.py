"""The case-3 scene's whole physics end to end on a small layered cavern (default tier).

workflows/scenes/case3_contact_coarse.toml as it is (static excavation with the whole load released
before the lining is installed, Mohr-Coulomb rock in a zone around the cavern, concrete lining
damage, the interlayer pairs with deterioration, oblique P + SV El Centro), with mesh overrides that shrink the
model to a 90 x 74 x 110 m block around a 24 m long cavern (two layer interfaces cross it), so that
the static stage and a short dynamic window take about a minute:

- without the wave, the dynamic run after the stage stays at rest, with global and with local time
  stepping: peak velocity below 1e-6 m/s and displacement below 1e-6 of the stage's largest
  displacement (docs/static.md "Hand-over"),
  after the rock yielded and pairs slid in the stage. The wear factor of the deterioration is held
  at 1 (R0 = 1) there: with R0 < 1 the interfaces lose strength with time whether or not the
  ground shakes, and the pairs the stage left at their strength limit slide (measured: without a
  wave t_s = time.duration = 0.02 s, and the crown moved at 6.6 cm/s within it;
  docs/case_study.md "Deterioration without shaking");
- with the wave: the run finishes, the input arrived, the energy balance closes with plastic,
  damage and friction dissipation, and the stage's pictures and figures are written.
"""
import json
import math
import pathlib
import tomllib

import numpy as np
import pytest

from pyfem import solver
from pyfem.scene import load_scene, parse_scene

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
PRESTRESSED_BALANCE = 3.0e-9  # the small case 3's energy balance after its plastic stage (measured 1.3e-9)
CASE3 = REPOSITORY / "workflows" / "scenes" / "case3_contact_coarse.toml"
# The small case 3 after its stage with no wave, peak monitor velocity over the run: measured 8.1e-14
# to 2.15e-13 m/s (global stepping, 0.02 s; the spread is between runs of the same code, alone and
# under pytest-xdist: the stage's direct solve sums in another order) and 1.8e-13 m/s (local
# stepping, 0.2 s), the round-off of a state handed over in equilibrium; about twice the largest. A
# hand-over out of equilibrium (a pair's or a cell's stage state not rebased) moves the walls by
# orders more.
REST_VELOCITY = {False: 4.5e-13, True: 4.0e-13}  # m/s, by local_stepping
SMALL_MODEL = ["mesh.parameters.half_width_x=45.0", "mesh.parameters.below=25.0", "mesh.parameters.above=25.0",
               "mesh.parameters.margin_y=25.0", "mesh.parameters.length=24.0", "mesh.parameters.h_cavern=6.0",
               "mesh.parameters.h_far=15.0", 'contact.interfaces=["interface_1", "interface_2"]']


# Runs of a few hundredths of a second start at the record's window: without the 1 s filter lead-in,
# which would run first (record time is run time: the lead-in lies at t < 0).
NO_LEAD_IN = "wave.motion.record.lead_in=0.0"


def small_case3(extra=(), wave=True):
    if wave:
        return load_scene(CASE3, [*SMALL_MODEL, NO_LEAD_IN, *extra])
    raw = tomllib.loads(CASE3.read_text())
    del raw["wave"]
    return parse_scene(raw, source=str(CASE3), overrides=[*SMALL_MODEL, *extra], base_dir=CASE3.parent)


def stage_checks(summary) -> None:
    """The stage ran as the scene asks: two stages, converged, the rock yielded."""
    stages = summary["static"]["stages"]
    assert [stage["converged"] for stage in stages] == [True, True]
    yielded = sum(region["yielded_volume"] for name, region in summary["nonlinear_regions"].items()
                  if name != "lining")
    assert yielded > 0.0, "the rock around the cavern yielded in the stage"


@pytest.mark.parametrize("local_stepping, integration", [(False, "full"), (True, "mixed")])
def test_small_case3_without_wave_stays_at_rest(tmp_path, local_stepping, integration, unfitted_levels):
    """Also with local time stepping: the stage's element-loop and pair state, cut by rate level
    (pyfem/local_stepping.py load_component_parts, load_pair_parts), hands over in equilibrium, with
    the sandstone's cells at one point each (integration = "reduced", their hourglass stiffness in the
    matrix) beside the non-sandstone's and the lining's full cells ("mixed": both kinds in one run)."""
    # Local stepping over 0.2 s (60 global steps): long enough for a mode its map amplified to show.
    one_point = ['materials.sandstone.plasticity.integration="reduced"'] if integration == "mixed" else []
    # Relaxation 0.95 (the scenes' value until 2026-11-27): the lining then takes 5 % of the load and
    # the stage leaves pairs sliding at their strength limit, the hardest hand-over; with the
    # scene's 1.0 this small model's pairs end the stage in stick.
    scene = small_case3([f"time.duration={0.2 if local_stepping else 0.02}", "output.xdmf_interval=0.0",
                         "contact.deterioration.R0=1.0", f"time.local_stepping={'true' if local_stepping else 'false'}",
                         "static.relaxation=0.95", *one_point], wave=False)
    summary = solver.run(scene, tmp_path / "rest")
    if local_stepping:
        assert "local time stepping: 5 rate levels" in summary["dt_reason"]
    stage_checks(summary)
    report = json.loads((tmp_path / "rest" / "static" / "static.json").read_text())
    assert report["pairs"]["states"]["sliding"] > 0, "pairs were left at their strength limit by the stage"
    stage_max = report["max_displacement"]["value"]
    assert stage_max > 1e-3, "the excavation moved the walls by millimetres at least"
    checks = 0
    for name in ("A", "B", "C", "D"):
        peaks = summary["monitors"][name]
        print(f"{name}: peak velocity {peaks['velocity']:.2e} m/s, displacement {peaks['displacement']:.2e} m "
              f"(stage {stage_max:.3e} m)")
        assert peaks["velocity"] < REST_VELOCITY[local_stepping]  # catches a hand-over out of equilibrium
        assert peaks["displacement"] < 1e-6 * stage_max
        checks += 1
    assert checks == 4
    for name, pair in summary["pairs"].items():  # no pair moved either
        assert pair["max_slip"] < 1e-6 * stage_max, name


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    scene = small_case3(["time.duration=0.04", "output.xdmf_interval=0.02"])
    out = tmp_path_factory.mktemp("runs") / "case3_coarse"  # the name the workflow's report looks for
    return scene, out, solver.run(scene, out)


def test_the_cavern_split_by_contact_interfaces_is_one_opening(small_run):
    """Catches a cavern wall cut by split interfaces read as several openings (the two nodes of a
    pair share a position, the wall's pieces touch): one opening around the whole section, no
    pillar of zero width."""
    _, _, summary = small_run
    contour = summary["contour"]
    assert len(contour["openings"]) == 1 and contour["pillars"] == []
    assert contour["openings"][0]["nodes"] > 40 and contour["openings"][0]["stage_convergence_max"] > 0.0


def test_small_case3_runs_all_physics_with_energy_balance(small_run):
    scene, out, summary = small_run
    assert summary["status"] == "finished"
    stage_checks(summary)
    assert set(summary["effects"]) >= {"seismic_input", "initial_stress", "contact", "deterioration"}
    assert set(summary["nonlinear_regions"]) == {"sandstone", "non_sandstone", "lining"}
    assert "local time stepping" not in summary["dt_reason"]  # "auto" keeps global stepping for 0.04 s
    print(f"{summary['dt_reason']}; energy balance {summary['energy']['balance_error']:.2e}")
    # Global stepping's identity, measured 1.3e-9 here, not 1e-15: the rock yields from a stage left at
    # its strength under 20 MPa, and its stored energy and plastic dissipation (-182 / +182 J at 0.04 s)
    # are differences of the prestress's energy, whose round-off (2.4e-7 J) is 1.3e-9 of them. Catches
    # a contact, plastic, damage or input work term missing from the account by more than 1e-8.
    assert summary["energy"]["balance_error"] < PRESTRESSED_BALANCE
    moved = [summary["monitors"][name]["displacement"] for name in ("A", "B", "C", "D")]
    assert all(math.isfinite(value) and value > 0.0 for value in moved), "the input arrived at the lining"
    assert summary["deformed_section"]["largest"] > 0.0 and abs(summary["deformed_section"]["y"]) < 1.0
    assert (out / "plots" / "deformed_section.png").stat().st_size > 20000


def test_static_stage_pictures_and_interface_figures(small_run):
    _, out, _ = small_run
    report = json.loads((out / "static" / "static.json").read_text())
    for name in ("section_stress", "interface_stress"):
        assert (out / "static" / f"{name}.png").stat().st_size > 20000
    section = report["plots"]["section_stress"]
    assert section["cells"] > 100 and abs(section["y"]) < 1.0  # the cavern's mid-length section
    interface = report["plots"]["interface_stress"]
    print(interface)
    assert interface["pairs_near_wall"] > 0
    # The excavation changes the interfaces' normal stress at the walls (it is not the in-situ one).
    assert abs(interface["after_mean"] - interface["before_mean"]) > 0.05 * abs(interface["before_mean"])


def test_case_study_report_draws_the_lining_damage_maps(small_run, tmp_path):
    """The workflow's report on the small run: Figs. 11-13 from its damage fields and monitors, and the
    static stage's section (stresses, plastic zone)."""
    import sys

    sys.path.insert(0, str(REPOSITORY / "workflows"))
    import case_study

    _, out, summary = small_run
    numbers = case_study.report(presets=("coarse",), cases=(3,), runs_dir=out.parent, results=tmp_path, doc=False)
    case3 = numbers["coarse"][3]
    for name in ("fig11_lining_damage", "fig12_damage_type", "fig13_deformation", "static_case3"):
        assert (tmp_path / f"{name}.png").stat().st_size > 20000
    damage = case3["lining_damage_map"]
    # The map reads the same damage the run's summary reports for the lining.
    assert damage["peak_damage_bay"] <= summary["nonlinear_regions"]["lining"]["peak_damage"] + 1e-12
    assert 0.0 <= damage["damaged_share"] <= 1.0 and damage["t"] == pytest.approx(0.04)
    assert set(case3["upper_structure_offset"]) == {"A", "B", "C"}


@pytest.mark.slow
def test_coarse_case3_after_its_stage_stays_at_rest_until_the_record_starts(tmp_path):
    """The real coarse case 3 (relaxation 1.0, the paper's wear), its input scaled to nothing
    (PGA 1e-9 g): the stage leaves the rock yielded through the zone and pairs at their strength
    limit, and over the lead-in (0.4 s here; the window starts at 1 s) nothing moves, because the
    interfaces do not wear before the record's window starts (docs/method.md section 9). Measured
    2026-11-27 with the wear clocked from the run's start: the crown at 1.7 mm/s after 0.05 s and the
    lining cracking within 1 s; with this clock 1e-11 m/s. About 10 minutes on 2 cores."""
    scene = load_scene(CASE3, ["wave.motion.record.pga=1e-9", "time.duration=0.01", "output.xdmf_interval=0.0"])
    summary = solver.run(scene, tmp_path / "rest")
    stage_checks(summary)
    states = json.loads((tmp_path / "rest" / "static" / "static.json").read_text())["pairs"]["states"]
    assert summary["deterioration"]["wear_start"] == 0.0 and summary["deterioration"]["eta_at_end"] > 0.9999
    for name in ("A", "B", "C", "D"):
        peaks = summary["monitors"][name]
        print(name, peaks["velocity"], peaks["displacement"], states)
        assert peaks["velocity"] < 1e-9 and peaks["displacement"] < 1e-10
    assert summary["nonlinear_regions"]["lining"]["peak_damage"] == 0.0
    for name, pair in summary["pairs"].items():
        assert pair["max_slip"] < 1e-10, name



def test_the_set_up_processes_the_record_once_for_the_input_and_the_wear_clock(monkeypatch):
    """The model's set-up processes case 3's record once: the input forces are driven with it and the
    interfaces' wear clock starts at its window (before, each read and filtered it anew)."""
    from pyfem.distributed_model import model_in_memory
    from pyfem.seismic import records
    from pyfem.seismic.setup import scene_record

    scene = small_case3(["time.duration=0.01", "wave.motion.record.lead_in=1.0"])  # (its check processes it too)
    calls = []
    process = records.process_record
    monkeypatch.setattr(records, "process_record", lambda *args, **kwargs: calls.append(1) or process(*args, **kwargs))
    simulation = model_in_memory(scene, solve_stage=False)
    assert len(calls) == 1
    processed = scene_record(scene)  # the same processing again, for comparison
    assert np.array_equal(simulation.freefield.tables.ddg[0], processed.acceleration)
    assert processed.record_start == pytest.approx(1.0)  # the lead-in, at t < 0 in record time
    assert simulation.contact_arrays["deterioration"][6] == 0.0  # the wear starts with the window, at t = 0
    assert simulation.freefield.tables.t0 == pytest.approx(-1.0)  # the table's first sample: the lead-in's start
    assert simulation.lead_in == pytest.approx(1.0)

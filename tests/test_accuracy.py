"""pyfem.accuracy: settings for an error budget from the accuracy-versus-cost study's CSV.

A small synthetic CSV with a known answer: which run is the cheapest within each budget,
which runs are on the Pareto front, and the element size a scene then needs
(h = slowest c_s / highest frequency / elements per wavelength, worked by hand).
"""
import csv
import math
import subprocess
import sys
from pathlib import Path

import pytest

from pyfem import accuracy
from pyfem.scene import parse_scene

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["order", "h", "elements_per_wavelength", "safety", "boundary", "dt", "steps", "dofs", "error",
           "wall_seconds", "loop_seconds", accuracy.COST_COLUMN, "pareto"]
# (order, elements per wavelength, safety, boundary, error, loop seconds)
RUNS = [
    (1, 4.5, 0.9, "viscoelastic", 0.070, 0.1),
    (1, 8.9, 0.9, "viscoelastic", 0.015, 0.3),
    (1, 8.9, 0.3, "viscoelastic", 0.014, 0.9),
    (1, 17.8, 0.9, "viscoelastic", 0.004, 2.0),
    (2, 2.2, 0.9, "viscoelastic", 0.030, 0.2),   # cheapest within 5 %
    (2, 4.5, 0.9, "viscous", 0.0009, 1.0),      # cheapest within 1 %
    (2, 4.5, 0.6, "viscoelastic", 0.0008, 1.5),
    (1, 4.5, 0.6, "fixed", 1.0, 0.05),          # cheapest of all, but no accuracy: never chosen
]


def test_the_programs_tables_are_the_studies_results():
    """pyfem.accuracy reads its own copies (pyfem/data/), each equal to the study's results CSV that
    the study wrote with it (workflows/study_csv.py `publish`): a study run again must be published."""
    tables = [accuracy.DEFAULT_RESULTS, accuracy.WALL_RESULTS, accuracy.LINING_RESULTS, accuracy.ELLIPSE_RESULTS,
              accuracy.SLIP_RESULTS]
    assert len({path.name for path in tables}) == 5
    for table in tables:
        assert table.parent == ROOT / "pyfem" / "data" and table.is_file(), table
        assert table.read_bytes() == (ROOT / "workflows" / "results" / table.name).read_bytes(), table.name
    assert len(accuracy.read_results()) > 10  # the copy is read: the study's rows


def test_publish_copies_only_what_the_program_reads_from_the_results_folder(tmp_path, monkeypatch):
    sys.path.insert(0, str(ROOT / "workflows"))
    import study_csv

    program, results = tmp_path / "program", tmp_path / "results"
    program.mkdir()
    (program / "wall_stress.csv").write_text("old\n")
    monkeypatch.setattr(study_csv, "PROGRAM_TABLES", program)
    monkeypatch.setattr(study_csv, "RESULTS", results)
    study_csv.write_rows(tmp_path / "elsewhere" / "wall_stress.csv", [{"a": 1.5}], ["a"])  # a study's --out
    assert (program / "wall_stress.csv").read_text() == "old\n"
    study_csv.write_rows(results / "other.csv", [{"a": 1.5}], ["a"])  # not a table of the program's
    assert not (program / "other.csv").exists()
    study_csv.write_rows(results / "wall_stress.csv", [{"a": 1.5}], ["a"])
    assert (program / "wall_stress.csv").read_text().split() == ["a", "1.5"]
    assert (program / "wall_stress.csv").read_bytes() == (results / "wall_stress.csv").read_bytes()


@pytest.fixture
def results_csv(tmp_path):
    path = tmp_path / "accuracy_cost.csv"
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS)
        writer.writeheader()
        for order, epw, safety, boundary, error, seconds in RUNS:
            writer.writerow({"order": order, "h": 89.1 / epw, "elements_per_wavelength": epw,
                             "safety": safety, "boundary": boundary, "dt": 1e-3, "steps": 100, "dofs": 1000, "error": error,
                             "wall_seconds": seconds + 1.0, "loop_seconds": 2.0 * seconds,
                             accuracy.COST_COLUMN: seconds, "pareto": 0})
    return path


def test_recommend_picks_the_cheapest_run_within_the_budget(results_csv):
    five = accuracy.recommend(0.05, results_csv)
    assert (five["order"], five["elements_per_wavelength"], five["safety"], five["boundary"]) == \
        (2, 2.2, 0.9, "viscoelastic")
    assert five["error"] == 0.030 and five["seconds"] == 0.2 and five["runs"] == 6
    one = accuracy.recommend(0.01, results_csv)
    assert (one["order"], one["elements_per_wavelength"], one["safety"], one["boundary"]) == \
        (2, 4.5, 0.9, "viscous")
    assert one["runs"] == 3
    loose = accuracy.recommend(0.08, results_csv)  # now the cheap Q1 run qualifies; the fixed box never does
    assert (loose["order"], loose["elements_per_wavelength"], loose["boundary"]) == (1, 4.5, "viscoelastic")


def test_recommend_says_what_the_study_cannot_reach(results_csv):
    with pytest.raises(ValueError, match=r"error_budget = 0.0001.*smallest error 0.0008"):
        accuracy.recommend(1e-4, results_csv)
    with pytest.raises(ValueError, match="error_budget"):
        accuracy.recommend(-0.05, results_csv)


def test_pareto_front(results_csv):
    rows = accuracy.read_results(results_csv)
    front = accuracy.pareto_front(rows)
    keys = [(r["order"], r["elements_per_wavelength"], r["safety"]) for r in front]
    # 0.1 s 7 %, 0.2 s 3 %, 0.3 s 1.5 %, 0.9 s 1.4 %, 1.0 s 0.09 %, 1.5 s 0.08 %; Q1 at 17.8
    # (2 s, 0.4 %) is beaten by Q2 at 4.5 (1 s, 0.09 %), the fixed box (error 1) is never on it.
    assert keys == [(1, 4.5, 0.9), (2, 2.2, 0.9), (1, 8.9, 0.9), (1, 8.9, 0.3), (2, 4.5, 0.9), (2, 4.5, 0.6)]
    costs = [r[accuracy.COST_COLUMN] for r in front]
    errors = [r["error"] for r in front]
    assert costs == sorted(costs) and errors == sorted(errors, reverse=True)


def _scene(motion, materials):
    return parse_scene({
        "mesh": {"builder": "box", "size": [100.0, 100.0, 100.0], "h": 10.0},
        "materials": materials,
        "time": {"duration": 1.0},
        "wave": {"type": "SV", "motion": motion},
    })


def test_element_size_for_a_ricker_scene(results_csv):
    """c_s = sqrt(8e9 / (2 x 1.24) / 2600) = 1113.9 m/s; f_max = 2.5 x 4 Hz = 10 Hz; 5 % -> Q2 at 2.2."""
    scene = _scene({"ricker": {"f0": 4.0, "amplitude": 1e-3}},
                   {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}})
    advice = accuracy.element_size_for(scene, 0.05, results_csv)
    c_s = math.sqrt(8.0e9 / 2.48 / 2600.0)
    assert advice["highest_frequency"] == 10.0
    assert advice["shear_speed"] == pytest.approx(c_s, rel=1e-12)
    assert advice["h"] == pytest.approx(c_s / 10.0 / 2.2, rel=1e-12)
    assert advice["order"] == 2 and advice["safety"] == 0.9
    assert f"h = {c_s / 22.0:.3g} m" in advice["text"] and "Q2" in advice["text"]


def test_check_says_when_its_advice_is_the_coarsest_mesh_studied_and_gives_wall_advice_only_for_openings():
    """The study's coarsest Q2 mesh (2.23 elements per shortest wavelength) already met 5 % and 1 %:
    the advice says that this is where the study stopped, not a measured limit. A box without a
    static stage has no opening: no wall-stress advice; a case scene (an opening, a mesh builder
    that sets h) has it."""
    from pyfem.cli import mesh_advice
    from pyfem.scene import load_scene

    box = _scene({"ricker": {"f0": 5.0, "amplitude": 1e-3}}, {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}})
    advice = accuracy.element_size_for(box, 0.01)
    assert advice["order"] == 2 and advice["coarsest_studied"]
    assert "the coarsest mesh the study ran, so not a measured limit" in advice["text"]
    text = mesh_advice(box)
    assert "mesh advice" in text and "scene h = 10.0" in text and "wall stress advice" not in text
    case = load_scene(ROOT / "workflows" / "scenes" / "case3_contact_coarse.toml")
    text = mesh_advice(case)
    assert "wall stress advice" in text and "scene h = set by the mesh builder" in text


def test_element_size_for_a_record_uses_the_band_and_the_slowest_material(results_csv):
    """Two materials: the softer sets c_s = sqrt(2e9 / 2.6 / 2400) = 566 m/s; the record's band[1] = 8 Hz."""
    # The rule reads only the materials and the wave's frequency content: a plain dict will do.
    scene = {"materials": {"hard": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0},
                           "soft": {"E": 2.0e9, "nu": 0.3, "rho": 2400.0}},
             "wave": {"motion": {"record": {"band": [0.1, 8.0]}, "ricker": None}}}
    advice = accuracy.element_size_for(scene, 0.01, results_csv)
    c_s = math.sqrt(2.0e9 / 2.6 / 2400.0)
    assert advice["shear_speed"] == pytest.approx(c_s, rel=1e-12)
    assert advice["highest_frequency"] == 8.0
    assert advice["h"] == pytest.approx(c_s / 8.0 / 4.5, rel=1e-12) and advice["order"] == 2


def test_element_size_for_needs_a_wave(results_csv):
    scene = {"materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}}}
    with pytest.raises(ValueError, match=r"\[wave\]"):
        accuracy.element_size_for(scene, 0.05, results_csv)


def test_the_studys_own_results_give_advice():
    """The study's committed CSV exists and meets the 5 % budget (run workflows/accuracy_cost.py)."""
    advice = accuracy.recommend(0.05)
    assert advice["error"] <= 0.05 and advice["order"] in (1, 2)


@pytest.mark.slow
def test_quick_study_runs_and_writes_its_outputs(tmp_path):
    """The real workflow, --quick, into a temporary directory: CSV, markdown and plot, readable advice."""
    result = subprocess.run([sys.executable, "workflows/accuracy_cost.py", "--quick", "--out", str(tmp_path)],
                            cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    rows = accuracy.read_results(tmp_path / "accuracy_cost.csv")
    assert len(rows) == 10
    absorbing = [r for r in rows if r["boundary"] != "fixed"]
    # Finer meshes are more accurate, for each order and step.
    for order in (1, 2):
        for safety in (0.6, 0.9):
            errors = [r["error"] for r in sorted(absorbing, key=lambda r: r["h"], reverse=True)
                      if r["order"] == order and r["safety"] == safety]
            assert len(errors) == 2 and errors[1] < 0.5 * errors[0], errors
    assert all(r["error"] == pytest.approx(1.0) for r in rows if r["boundary"] == "fixed")
    assert accuracy.recommend(0.05, tmp_path / "accuracy_cost.csv")["error"] <= 0.05
    assert "## Conclusion" in (tmp_path / "accuracy_cost.md").read_text()
    assert (tmp_path / "accuracy_cost.png").stat().st_size > 10000


def test_the_wall_advice_is_the_largest_size_whose_peak_error_and_every_finer_one_meet_the_budget(tmp_path):
    # Q1's error is not monotone in h (0.24 a met the budget by a cancellation, 0.12 a did not):
    # the advice must not take the coarse size; the history error plays no part.
    columns = ["order", "h_wall", "h_over_a", "f0", "reference", "peak_error", "history_error", "loop_seconds"]
    rows = [(1, 0.24, 2.0, 0.004), (1, 0.12, 2.0, 0.018), (1, 0.06, 2.0, 0.005),
            (1, 0.24, 8.0, 0.003), (1, 0.12, 8.0, 0.008), (1, 0.06, 8.0, 0.006),
            (2, 0.24, 2.0, 0.028), (2, 0.12, 2.0, 0.006), (2, 0.24, 8.0, 0.030), (2, 0.12, 8.0, 0.009)]
    path = tmp_path / "wall_stress.csv"
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        writer.writerow({"order": 1, "h_wall": 1.0, "h_over_a": 0.2, "f0": 2.0, "reference": "Kirsch",
                         "peak_error": 0.0, "history_error": 0.0, "loop_seconds": 1.0})  # not the exact answer: ignored
        for order, h_over_a, f0, peak in rows:
            writer.writerow({"order": order, "h_wall": 5 * h_over_a, "h_over_a": h_over_a, "f0": f0,
                             "reference": "Pao-Mow", "peak_error": peak, "history_error": 0.5, "loop_seconds": 1.0})
    one, five = accuracy.wall_size_for(0.01, path), accuracy.wall_size_for(0.05, path)
    assert [(a["order"], a["h_over_a"]) for a in one] == [(1, 0.06), (2, 0.12)]
    assert [(a["order"], a["h_over_a"]) for a in five] == [(1, 0.24), (2, 0.24)]
    assert one[0]["error"] == 0.006 and five[1]["error"] == 0.030
    tight = accuracy.wall_size_for(0.001, path)
    assert [a["h_over_a"] for a in tight] == [None, None] and "not reached" in tight[0]["text"]
    assert "k_s a = 0.56" in one[0]["text"]


def test_the_wall_advice_also_holds_the_racking_to_the_budget(tmp_path):
    """With the racking's peak error in the study (the crown relative to the invert), a size whose
    stress meets the budget but whose racking does not is not advised."""
    columns = ["order", "h_wall", "h_over_a", "f0", "reference", "peak_error", "racking_peak_error", "loop_seconds"]
    rows = [(1, 0.24, 0.004, 0.024), (1, 0.12, 0.005, 0.011), (1, 0.06, 0.004, 0.007)]
    path = tmp_path / "wall_stress.csv"
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        for order, h_over_a, peak, racking in rows:
            writer.writerow({"order": order, "h_wall": 5 * h_over_a, "h_over_a": h_over_a, "f0": 2.0,
                             "reference": "Pao-Mow", "peak_error": peak, "racking_peak_error": racking,
                             "loop_seconds": 1.0})
    one = accuracy.wall_size_for(0.01, path)
    assert [(a["order"], a["h_over_a"]) for a in one] == [(1, 0.06)]  # the stress alone would allow 0.24
    assert one[0]["error"] == 0.007 and "racking" in one[0]["text"]
    assert accuracy.wall_size_for(0.03, path)[0]["h_over_a"] == 0.24


def test_lining_advice_takes_the_fewest_elements_that_read_the_peak_within_the_budget(tmp_path):
    """accuracy.lining_elements_for on a table whose finer meshes all meet the budget above the
    advised count, and on the study's own results (docs/lined_tunnel.md): 4 Q1 elements for 5 %,
    8 not enough for 2 %."""
    columns = ["order", "through", "h_wall", "peak_error"]
    path = tmp_path / "lining_stress.csv"
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        for order, through, error in ((1, 2, -0.063), (1, 4, -0.036), (1, 8, -0.021), (2, 2, -0.062), (2, 4, -0.033)):
            writer.writerow({"order": order, "through": through, "h_wall": 0.5 / through, "peak_error": error})
    five = accuracy.lining_elements_for(0.05, path)["per_order"]
    assert [(a["order"], a["through"]) for a in five] == [(1, 4), (2, 4)]
    two = accuracy.lining_elements_for(0.02, path)["per_order"]
    assert [a["through"] for a in two] == [None, None] and "not reached with 8" in two[0]["text"]
    study = accuracy.lining_elements_for(0.05)
    assert study["per_order"][0]["through"] == 4, study["text"]
    with pytest.raises(ValueError, match="error_budget"):
        accuracy.lining_elements_for(-1.0, path)



def test_curved_wall_advice_takes_the_largest_size_whose_finer_sizes_all_met_the_budget(tmp_path):
    """accuracy.curved_wall_size_for on a table where a coarser size happens to meet a budget a finer
    one misses (that size is not advised), ignoring the circle rows; and on the study's own results
    (docs/elliptical_opening.md): Q1 0.24 / 0.06 and Q2 0.24 / 0.12 of rho for 5 % / 1 %."""
    columns = ["shape", "order", "h_over_rho", "worst"]
    path = tmp_path / "elliptical_opening.csv"
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        for shape, order, ratio, worst in (("ellipse", 1, 0.24, 0.009), ("ellipse", 1, 0.12, 0.012),
                                           ("ellipse", 1, 0.06, 0.008), ("circle", 1, 0.24, 0.001),
                                           ("ellipse", 2, 0.24, 0.03), ("ellipse", 2, 0.12, 0.02)):
            writer.writerow({"shape": shape, "order": order, "h_over_rho": ratio, "worst": worst})
    one = accuracy.curved_wall_size_for(0.01, path)
    assert [(a["order"], a["h_over_rho"]) for a in one] == [(1, 0.06), (2, None)]
    assert one[1]["error"] == 0.02
    study = {budget: [(a["order"], a["h_over_rho"]) for a in accuracy.curved_wall_size_for(budget)]
             for budget in (0.05, 0.01)}
    assert study == {0.05: [(1, 0.24), (2, 0.24)], 0.01: [(1, 0.06), (2, 0.12)]}
    with pytest.raises(ValueError, match="error_budget"):
        accuracy.curved_wall_size_for(0.0, path)


def test_slip_advice_reads_the_interface_resolution_and_the_rocks_on_its_sides(tmp_path):
    """pyfem check's interface line: the two-layer contact scene (sandstone under the softer rock, 5 m
    elements) is 9.06 elements per shortest wavelength, dissimilar, where the slip study measured the
    peak slip 25 % low; the same interface between layers of one rock is called alike. slip_error_at
    interpolates in log(resolution) between the rows of a table and holds its ends."""
    from pyfem.scene import load_scene

    columns = ["contrast", "order", "safety", "per_wavelength", "peak_error", "history_error"]
    path = tmp_path / "interface_slip.csv"
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        for per_wavelength, peak in ((10.0, -0.2), (40.0, -0.05), (160.0, -0.01)):
            writer.writerow({"contrast": "bimaterial", "order": 1, "safety": 0.8, "per_wavelength": per_wavelength,
                             "peak_error": peak, "history_error": 2.0 * abs(peak)})
        writer.writerow({"contrast": "bimaterial", "order": 1, "safety": 0.8, "per_wavelength": 320.0,
                         "peak_error": 0.0, "history_error": 0.0})   # the reference row: not used
    assert accuracy.slip_error_at(20.0, True, path)["peak_error"] == pytest.approx(-0.125)
    assert accuracy.slip_error_at(5.0, True, path)["peak_error"] == pytest.approx(-0.2)
    assert accuracy.slip_error_at(640.0, True, path, order=2) == {
        "peak_error": -0.01, "history_error": 0.02, "per_wavelength": 640.0, "studied": (10.0, 160.0),
        "order": 1, "contrast": "bimaterial"}                      # no Q2 rows: Q1's, and it says so
    with pytest.raises(ValueError, match="homogeneous"):
        accuracy.slip_error_at(20.0, False, path)
    with pytest.raises(ValueError, match="bimaterial, lag"):
        accuracy.slip_error_at(20.0, True, path, lag=True)

    from pyfem.operators import build_model

    scene_path = ROOT / "workflows" / "scenes" / "contact_two_layer_sv.toml"
    scene = load_scene(scene_path)
    advice = accuracy.interface_slip_advice(scene, build_model(scene))
    (names, text), = advice.items()
    print(names, text)
    assert names == "interface_1" and "sandstone | mudstone (dissimilar rocks), h ~ 5 m" in text
    assert "9.06 elements per shortest wavelength" in text and "peak slip -25 %" in text
    scene["materials"]["mudstone"] = dict(scene["materials"]["sandstone"])
    (_, text), = accuracy.interface_slip_advice(scene, build_model(scene)).items()
    assert "(alike rocks)" in text and "converges slowly" not in text and "(homogeneous, Q1)" in text
    scene["materials"]["mudstone"]["E"] = 2.0e9
    scene["contact"]["normal_lag"] = {"length": 0.01, "velocity": 1.0}
    (_, text), = accuracy.interface_slip_advice(scene, build_model(scene)).items()
    assert "(bimaterial, lag, Q1)" in text and "converges slowly" not in text


def test_a_mesh_files_cells_are_measured_against_the_advice(tmp_path):
    """A user's gmsh .geo of 25 m tetrahedra under an 8 Hz Ricker (advice at most 6.25 m for 5 %):
    `check` measures the cells per region and warns; under a 0.5 Hz wavelet it does not. Catches the
    advice that read "scene h = set by the mesh builder" and never looked at a mesh file's cells."""
    from pyfem import solver
    from pyfem.accuracy import region_cell_sizes
    from pyfem.operators import build_model
    from pyfem.scene import parse_scene

    geo = tmp_path / "box.geo"
    geo.write_text('SetFactory("OpenCASCADE");\nBox(1) = {0, 0, 0, 100, 100, 100};\nPhysical Volume("rock") = {1};\n'
                   "Mesh.CharacteristicLengthMin = 25;\nMesh.CharacteristicLengthMax = 25;\n")

    def scene(f0):
        return parse_scene({"title": "user mesh", "mesh": {"builder": "file", "file": str(geo)},
                            "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}}, "time": {"duration": 0.05},
                            "wave": {"type": "SV", "surface": 120.0, "motion": {"ricker": {"f0": f0, "amplitude": 1e-3}}},
                            "monitor": [{"name": "c", "point": [50.0, 50.0, 50.0]}]})

    coarse = scene(8.0)
    plan = solver.plan(coarse)
    line = plan["mesh resolution"]["rock"]
    assert "P1 cells" in line and "h <= 6.25 m" in line
    warned = [w for w in coarse.warnings if w.startswith("mesh: region 'rock' has cells of h up to")]
    assert len(warned) == 1 and "6.25 m" in warned[0]
    fine = scene(0.5)
    solver.plan(fine)
    assert not [w for w in fine.warnings if w.startswith("mesh: region")]
    # The measure: a tetrahedron's longest edge, within gmsh's size field.
    model = build_model(fine)
    count, smallest, largest = region_cell_sizes(model)["rock"]
    assert count == model.n_cells and 10.0 < smallest < 25.0 * 1.1 < largest < 60.0

"""Scene validation: every bad scene is a SceneError naming its key; good scenes are fully defaulted."""
import copy
import math
from pathlib import Path

import numpy as np
import pytest

from pyfem.scene import (EFFECT_ORDER, MATERIAL_PRESETS, SceneError, apply_overrides,
                         load_scene, parse_scene, rayleigh_coefficients)

REPO = Path(__file__).resolve().parents[1]
RECORD = str(REPO / "data" / "elcentro_1940_ns.txt")


def good_scene():
    """A small valid box scene with seismic input and two monitors (raw, as read from TOML)."""
    return {
        "title": "test box",
        "mesh": {"builder": "box", "size": [100.0, 10.0, 100.0], "h": 5.0},
        "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}},
        "time": {"duration": 0.6},
        "wave": {"type": "SV", "surface": 150.0,
                 "motion": {"ricker": {"f0": 5.0, "amplitude": 1.0e-3}}},
        "monitor": [{"name": "centre", "point": [50.0, 5.0, 50.0]},
                    {"name": "top", "point": [50.0, 5.0, 100.0]}],
    }


def with_changes(*changes):
    """good_scene() with (dotted path, value) changes; value DELETE removes the key."""
    scene = good_scene()
    for path, value in changes:
        *parents, last = path.split(".")
        node = scene
        for part in parents:
            node = node[int(part)] if isinstance(node, list) else node.setdefault(part, {})
        if value is DELETE:
            del node[last]
        elif isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value
    return scene


DELETE = object()

BAD_SCENES = [
    # (id, raw scene, key the error must name, words the message must contain)
    ("unknown key with suggestion", with_changes(("mesh.hh", 5.0)), "mesh.hh", "did you mean 'mesh.h'"),
    ("unknown top-level table", with_changes(("bench", {"n": 1})), "bench", "unknown scene key"),
    ("string where number", with_changes(("mesh.h", "five")), "mesh.h", "must be a finite number > 0"),
    ("bool is not a number", with_changes(("time.duration", True)), "time.duration", "must be a finite number"),
    ("infinite duration", with_changes(("time.duration", float("inf"))), "time.duration", "must be a finite number > 0"),
    ("vector of wrong length", with_changes(("mesh.size", [100.0, 10.0])), "mesh.size", "3 numbers"),
    ("missing required", with_changes(("time.duration", DELETE)), "time.duration", "is missing"),
    ("missing box size", with_changes(("mesh.size", DELETE)), "mesh.size", "is missing"),
    ("negative E", with_changes(("materials.rock.E", -1.0)), "materials.rock.E", "> 0"),
    ("nu 0.5", with_changes(("materials.rock.nu", 0.5)), "materials.rock.nu", "(-1, 0.5)"),
    ("nu -1.2", with_changes(("materials.rock.nu", -1.2)), "materials.rock.nu", "(-1, 0.5)"),
    ("missing rho without preset", with_changes(("materials.rock.rho", DELETE)),
     "materials.rock.rho", "preset"),
    ("monitor outside box", with_changes(("monitor.1.point", [50.0, 5.0, 100.1])),
     "monitor.1.point", "inside the box"),
    ("bad builder", with_changes(("mesh.builder", "sphere")), "mesh.builder", '"layered_cavern"'),
    ("order 3", with_changes(("mesh.order", 3)), "mesh.order", "one of 1, 2"),
    ("order as float", with_changes(("mesh.order", 1.0)), "mesh.order", "one of 1, 2"),
    ("ricker and record", with_changes(("wave.motion.record", {"file": RECORD, "units": "g"})),
     "wave.motion", "exactly one"),
    ("no motion kind", with_changes(("wave.motion", {})), "wave.motion", "exactly one"),
    ("wave type Q", with_changes(("wave.type", "Q")), "wave.type", '"P", "SV", "SH"'),
    ("angle 90", with_changes(("wave.angle", 90.0)), "wave.angle", "[0, 90)"),
    ("damping ratio 1.5", with_changes(("damping", {"ratio": 1.5, "frequencies": [1.0, 10.0]})),
     "damping.ratio", "[0, 1)"),
    ("damping frequencies decreasing",
     with_changes(("damping", {"ratio": 0.05, "frequencies": [10.0, 1.0]})),
     "damping.frequencies", "increasing"),
    ("damping ratio and alpha", with_changes(("damping", {"ratio": 0.05, "frequencies": [1.0, 10.0],
                                                          "alpha": 0.1})), "damping", "not both"),
    ("component plus top-level type", with_changes(("wave.component", [{"type": "P"}])),
     "wave.type", "[[wave.component]]"),
    ("no wave type at all", with_changes(("wave.type", DELETE)), "wave.type", "is missing"),
    ("extra material region", with_changes(("materials.granite", {"preset": "sandstone"})),
     "materials.granite", 'single region "rock"'),
    ("missing box region", with_changes(("materials", {"granite": {"preset": "sandstone"}})),
     "materials.granite", 'single region "rock"'),
    ("medium not a material", with_changes(("wave.medium", "granite")), "wave.medium", "rock"),
    ("duplicate monitor names", with_changes(("monitor.1.name", "centre")), "monitor.1.name", "unique"),
    ("monitor name not filename-safe", with_changes(("monitor.0.name", "a/b")), "monitor.0.name", "letters"),
    ("record units", with_changes(("wave.motion", {"record": {"file": RECORD, "units": "ft"}})),
     "wave.motion.record.units", '"m/s2"'),
    ("record file missing", with_changes(("wave.motion", {"record": {"file": "no/such.txt", "units": "g"}})),
     "wave.motion.record.file", "no such file"),
    ("free surface inside box", with_changes(("wave.surface", 50.0)), "wave.surface", "top of the box"),
    ("pair monitor without contact", with_changes(("pair_monitor", [{"name": "I1", "point": [1.0, 1.0, 1.0]}])),
     "pair_monitor", "[contact]"),
    ("contact without interfaces", with_changes(("contact", {"cohesion": 1e6, "friction_angle": 30.0})),
     "contact.interfaces", "is missing"),
    ("unknown preset", with_changes(("materials.rock.preset", "granite")), "materials.rock.preset", "sandstone"),
    ("output field unknown", with_changes(("output.fields", ["pressure"])), "output.fields.0", "displacement"),
    ("dt not below duration", with_changes(("time.dt", 1.0)), "time.dt", "shorter"),
]


@pytest.mark.parametrize("raw, key, words", [case[1:] for case in BAD_SCENES],
                         ids=[case[0] for case in BAD_SCENES])
def test_bad_scene_names_its_key(raw, key, words):
    with pytest.raises(SceneError) as caught:
        parse_scene(raw)
    error = caught.value
    assert error.key == key
    assert f"'{key}'" in str(error)
    assert words in str(error)
    assert error.allowed


def test_error_message_format_shows_key_value_and_allowed():
    with pytest.raises(SceneError) as caught:
        parse_scene(with_changes(("materials.rock.nu", 0.6)))
    assert str(caught.value) == "scene key 'materials.rock.nu' = 0.6: Poisson's ratio must lie in (-1, 0.5)"
    assert caught.value.value == 0.6
    assert caught.value.allowed == "Poisson's ratio must lie in (-1, 0.5)"


def test_unknown_key_in_list_element_suggests_sibling():
    with pytest.raises(SceneError, match=r"unknown scene key 'monitor\.0\.nmae'; did you mean 'monitor\.0\.name'\?"):
        parse_scene(with_changes(("monitor.0.nmae", "x")))


def test_key_in_wrong_table_suggests_where_it_belongs():
    with pytest.raises(SceneError, match=r"'mesh\.duration'; did you mean 'time\.duration'"):
        parse_scene(with_changes(("mesh.duration", 1.0)))


def test_defaults_are_filled():
    scene = parse_scene(good_scene())
    assert scene["mesh"]["origin"] == [0.0, 0.0, 0.0]
    assert scene["mesh"]["order"] == 1
    assert scene["time"] == {"duration": 0.6, "safety": 0.8, "dt": None, "power_iteration": True,
                             "matrix_precision": "double", "local_stepping": "auto"}
    assert scene["wave"]["angle"] == 0.0 and scene["wave"]["azimuth"] == 0.0
    assert scene["wave"]["scale"] == 1.0
    assert scene["wave"]["medium"] == "rock"  # the only material
    assert scene["wave"]["motion"]["ricker"]["t0"] == pytest.approx(1.5 / 5.0)
    assert "record" not in scene["wave"]["motion"]
    assert scene["boundary"] == {"type": "viscoelastic", "faces": None, "face": None, "alpha_N": 4.0 / 3.0,
                                 "alpha_T": 2.0 / 3.0, "centre": [50.0, 5.0, 50.0]}
    assert scene["output"] == {"interval": 0.01, "xdmf_interval": 0.1,
                               "fields": ["displacement", "velocity"], "checkpoint_interval": 300.0}
    assert scene["pair_monitor"] == []
    for effect_table in ("damping", "initial_stress", "contact"):
        assert effect_table not in scene
    assert isinstance(scene["materials"]["rock"]["E"], float)
    assert parse_scene(with_changes(("title", DELETE)))["title"] == "untitled"


def test_preset_fills_material_and_explicit_keys_win():
    scene = parse_scene(with_changes(("materials.rock", {"preset": "non_sandstone", "rho": 2300.0})))
    rock = scene["materials"]["rock"]
    expected = dict(MATERIAL_PRESETS["non_sandstone"], rho=2300.0)
    assert {k: rock[k] for k in expected} == expected


def test_effects_tuple_in_fixed_order():
    assert parse_scene(with_changes(("wave", DELETE))).effects == ()
    assert parse_scene(good_scene()).effects == ("seismic_input",)
    everything = with_changes(
        ("contact", {"interfaces": ["interface_1"], "cohesion": 1.0e6, "friction_angle": 30.0,
                     "deterioration": {}}),
        ("initial_stress", {"surface": 560.0, "rho": 2600.0, "k": [1.4, 1.2, 1.15]}),
        ("damping", {"alpha": 0.5}),
    )
    scene = parse_scene(everything)
    assert scene.effects == EFFECT_ORDER
    assert scene["contact"]["dynamic_friction_angle"] == 30.0
    assert scene["contact"]["tensile_strength"] == 1.0e6
    assert scene["contact"]["deterioration"] == {"R0": 0.75, "lambda": 5.0, "m": 0.883,
                                                 "n": 0.02, "p": 0.032}
    assert scene["damping"]["alpha"] == 0.5 and scene["damping"]["beta"] == 0.0
    no_deterioration = copy.deepcopy(everything)
    del no_deterioration["contact"]["deterioration"]
    assert parse_scene(no_deterioration).effects == EFFECT_ORDER[:-1]


def test_overrides_number_array_string_and_list_index():
    scene = parse_scene(good_scene(), overrides=[
        "mesh.h=2.5",
        "monitor.1.point=[10, 2, 30]",
        "title=quick look",            # bare word: a string
        'wave.type="P"',               # quoted TOML string
        "time.power_iteration=false",
        "wave.motion.ricker={f0 = 2.0, amplitude = 0.01}",
    ])
    assert scene["mesh"]["h"] == 2.5
    assert scene["monitor"][1]["point"] == [10.0, 2.0, 30.0]
    assert scene["title"] == "quick look"
    assert scene["wave"]["type"] == "P"
    assert scene["time"]["power_iteration"] is False
    assert scene["wave"]["motion"]["ricker"]["t0"] == pytest.approx(0.75)


def test_override_can_switch_an_effect_on():
    scene = parse_scene(good_scene(), overrides=["damping.ratio=0.05", "damping.frequencies=[1, 10]"])
    assert scene.effects == ("seismic_input", "damping")


def test_override_of_unknown_key_is_the_same_error_as_in_the_file():
    with pytest.raises(SceneError) as from_override:
        parse_scene(good_scene(), overrides=["mesh.hh=5"])
    with pytest.raises(SceneError) as from_file:
        parse_scene(with_changes(("mesh.hh", 5)))
    assert str(from_override.value) == str(from_file.value)
    assert from_override.value.key == "mesh.hh"


@pytest.mark.parametrize("override, key", [
    ("mesh.h", "mesh.h"),                 # no '='
    ("=3", "=3"),                          # empty key
    ("mesh..h=3", "mesh..h"),              # empty part
    ("monitor.5.point=[1,2,3]", "monitor.5"),  # index out of range
    ("monitor.x.point=[1,2,3]", "monitor.x"),  # not an index
    ("mesh.h.x=3", "mesh.h"),              # through a number
])
def test_bad_override_syntax(override, key):
    with pytest.raises(SceneError) as caught:
        parse_scene(good_scene(), overrides=[override])
    assert caught.value.key == key


def test_overrides_do_not_modify_the_input():
    raw = good_scene()
    apply_overrides(raw, ["mesh.h=1", "monitor.0.name=other"])
    assert raw == good_scene()


def test_record_motion_resolves_file_and_fills_defaults():
    scene = parse_scene(with_changes(("wave.motion", {"record": {"file": "data/elcentro_1940_ns.txt",
                                                                 "units": "g", "dt": 0.02}})),
                        base_dir=REPO)
    record = scene["wave"]["motion"]["record"]
    assert Path(record["file"]) == Path(RECORD)
    assert record["band"] == [0.1, 25.0] and record["format"] == "auto"
    assert record["pga"] is None and record["window"] is None


def test_components_replace_top_level_type():
    raw = with_changes(("wave.type", DELETE),
                       ("wave.component", [{"type": "SV", "angle": 30.0},
                                           {"type": "P", "scale": 2.0 / 3.0, "angle": 30.0}]))
    scene = parse_scene(raw)
    components = scene.wave_components()
    assert [c["type"] for c in components] == ["SV", "P"]
    assert components[0]["scale"] == 1.0 and components[1]["scale"] == pytest.approx(2.0 / 3.0)
    assert components[1]["azimuth"] == 0.0
    assert scene["wave"]["type"] is None
    single = parse_scene(good_scene()).wave_components()
    assert single == [{"type": "SV", "scale": 1.0, "angle": 0.0, "azimuth": 0.0}]


def test_json_round_trip_gives_the_same_scene():
    raw = with_changes(("damping", {"ratio": 0.05, "frequencies": [1.0, 10.0]}))
    scene = parse_scene(raw)
    again = parse_scene(scene.to_json())
    assert again == scene and again.effects == scene.effects


def test_model_bounds_and_tolerance_on_the_faces():
    scene = parse_scene(with_changes(("mesh.origin", [-50.0, 0.0, -100.0]),
                                     ("monitor", [{"name": "corner", "point": [50.0 + 1e-8, 10.0, 0.0]}]),
                                     ("wave.surface", 0.0)))
    lo, hi = scene.model_bounds()
    np.testing.assert_array_equal(lo, [-50.0, 0.0, -100.0])
    np.testing.assert_array_equal(hi, [50.0, 10.0, 0.0])
    with pytest.raises(SceneError, match=r"monitor\.0\.point"):
        parse_scene(with_changes(("monitor", [{"name": "out", "point": [50.0, 5.0, 100.0 + 1e-6]}])))


def test_load_scene_reads_toml_and_applies_overrides(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[mesh]\nsize = [10.0, 10.0, 10.0]\nh = 2.0\n[materials.rock]\npreset = "concrete"\n'
                    "[time]\nduration = 0.1\n")
    scene = load_scene(path, overrides=["mesh.order=2"])
    assert scene.source == str(path)
    assert scene["mesh"]["order"] == 2
    assert scene["materials"]["rock"]["E"] == 28.0e9


def test_invalid_toml_names_file_and_line(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('title = "ok"\n[mesh]\nh = = 3\n')
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    assert str(path) in str(caught.value) and "line 3" in str(caught.value)


def test_example_scenes_are_valid():
    scenes = sorted((REPO / "workflows" / "scenes").glob("*.toml"))
    names = {p.name for p in scenes}
    assert {"default.toml", "box_vertical_sv.toml"} <= names
    for path in scenes:
        scene = load_scene(path)
        assert "seismic_input" in scene.effects, path
        assert len(scene["monitor"]) >= 3, path


def test_rayleigh_coefficients_reproduce_ratio_and_undershoot_between():
    ratio, f1, f2 = 0.05, 1.0, 10.0
    alpha, beta = rayleigh_coefficients(ratio, f1, f2)

    def xi(f):
        return alpha / (4.0 * math.pi * f) + beta * math.pi * f

    assert xi(f1) == pytest.approx(ratio, rel=1e-14)
    assert xi(f2) == pytest.approx(ratio, rel=1e-14)
    between = np.linspace(f1, f2, 50)[1:-1]
    assert all(xi(f) < ratio for f in between)
    scene = parse_scene(with_changes(("damping", {"ratio": ratio, "frequencies": [f1, f2]})))
    assert (scene["damping"]["alpha"], scene["damping"]["beta"]) == (alpha, beta)

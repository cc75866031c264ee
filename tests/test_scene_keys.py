"""The scene-key reference (docs/scene-keys.md) is the schema's, complete, and its wave conventions
are the free field's."""
import difflib
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import ROUNDOFF, rel_error
from pyfem import cli, scene_keys
from pyfem.scene import EFFECT_ORDER, MATERIAL_PRESETS, REQUIRED, Number, Table, Vector, _all_schema_keys
from pyfem.seismic.freefield import FreeField
from pyfem.seismic.waveforms import ricker

REPO = Path(__file__).resolve().parents[1]
DOCUMENT = REPO / scene_keys.DOCUMENT
ROCK = MATERIAL_PRESETS["sandstone"]
BOX = ([0.0, 0.0, 0.0], [160.0, 20.0, 160.0])
TABLE_PATHS = [path for path, _ in scene_keys.tables()]
# A backticked dotted name in hand-written text is a key and must exist ("`time.dt`"), as must
# a backticked top-level table ("`materials`").
BACKTICKED_KEY = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z0-9_]+)*)`")


def test_document_is_current():
    written = DOCUMENT.read_text()
    generated = scene_keys.reference()
    if written != generated:
        diff = "\n".join(list(difflib.unified_diff(written.splitlines(), generated.splitlines(), "written",
                                                   "generated", lineterm="", n=0))[:12])
        pytest.fail(f"{scene_keys.DOCUMENT} is not what the schema gives; regenerate it with "
                    f"`{scene_keys.WRITE_COMMAND}` (from the repository root). First differences:\n{diff}")


def test_every_key_the_schema_accepts_is_in_the_document():
    text = DOCUMENT.read_text()
    keys = _all_schema_keys()  # the scene module's own list, not the generator's walk
    missing = [key for key in keys if f"`{key}`" not in text]
    assert not missing, f"keys missing from the document: {missing}; run `{scene_keys.WRITE_COMMAND}`"
    assert sorted(keys) == sorted(scene_keys.schema_keys())
    assert len(keys) > 100  # the walk found the nested tables, maps and lists


def test_every_number_has_a_unit():
    specs = scene_keys.key_specs()
    numbers = {key: spec for key, spec in specs.items() if isinstance(spec, (Number, Vector))}
    without = [key for key, spec in numbers.items() if scene_keys.unit(key, spec) is None]
    assert not without, (f"numbers without a unit: {without}; write it in the description, e.g. "
                         "\"(Pa)\", or list the key in pyfem/scene_keys.py DIMENSIONLESS")
    dimensionless_with_unit = [key for key in scene_keys.DIMENSIONLESS
                               if key not in numbers or scene_keys._UNIT.search(numbers[key].description)]
    assert not dimensionless_with_unit, f"DIMENSIONLESS lists keys that are no unitless numbers: " \
                                        f"{dimensionless_with_unit}"
    assert scene_keys.unit("materials.NAME.E", specs["materials.NAME.E"]) == "Pa"
    assert scene_keys.unit("wave.angle", specs["wave.angle"]) == "deg"
    assert scene_keys.unit("materials.NAME.plasticity.tensile_strength",
                           specs["materials.NAME.plasticity.tensile_strength"]) == "Pa"


def test_every_unset_key_says_what_that_means():
    specs = scene_keys.key_specs()
    unset = [key for key, spec in specs.items()
             if not isinstance(spec, Table) and getattr(spec, "default", REQUIRED) is None]
    missing = [key for key in unset if key not in scene_keys.UNSET]
    assert not missing, (f"keys whose default is None with no word on what that means: {missing}; "
                         "add them to pyfem/scene_keys.py UNSET")
    stale = [key for key in scene_keys.UNSET if key not in unset]
    assert not stale, f"UNSET names keys that do not exist or have a default: {stale}"


def test_hand_written_entries_name_tables_and_keys_that_exist():
    keys = set(scene_keys.schema_keys())
    checks = 0
    assert set(scene_keys.RULES) <= set(TABLE_PATHS), set(scene_keys.RULES) - set(TABLE_PATHS)
    tables_without_purpose = [path for path in TABLE_PATHS if path and path not in scene_keys.PURPOSE]
    assert not tables_without_purpose, f"add a line to pyfem/scene_keys.py PURPOSE: {tables_without_purpose}"
    assert set(scene_keys.PURPOSE) <= set(TABLE_PATHS)
    assert set(scene_keys.SWITCHES) <= set(scene_keys.optional_tables())
    texts = [rule for rules in scene_keys.RULES.values() for rule in rules] + list(scene_keys.UNSET.values())
    for text in texts:
        for name in BACKTICKED_KEY.findall(text):
            assert name in keys or name in TABLE_PATHS, f"{name!r} in {text!r} is no scene key"
            checks += 1
    assert checks > 40


def test_every_effect_is_switched_on_by_a_table_and_described():
    switched = {path: scene_keys.effects_switched_by(path) for path in scene_keys.optional_tables()}
    for effect in EFFECT_ORDER:
        assert effect in scene_keys.EFFECTS, f"describe effect {effect!r} in pyfem/scene_keys.py EFFECTS"
        assert [path for path, effects in switched.items() if effect in effects] != []
    assert switched["wave"] == ["seismic_input"]
    assert switched["contact.deterioration"] == ["deterioration"]
    nothing = [path for path, effects in switched.items() if not effects and path not in scene_keys.SWITCHES]
    assert not nothing, f"optional tables that switch on nothing: {nothing}; add them to scene_keys.SWITCHES"


def test_cli_prints_the_reference_and_writes_it(tmp_path, capsys):
    assert cli.main(["keys"]) == 0
    assert capsys.readouterr().out == scene_keys.reference()
    target = tmp_path / "keys.md"
    assert cli.main(["keys", "--write", str(target)]) == 0
    assert target.read_text() == scene_keys.reference()


# ---------------------------------------------------------------------------
# The wave conventions of the document against pyfem.seismic.freefield.
# ---------------------------------------------------------------------------

def unit_ricker(t):
    return ricker(t, 5.0, 1.0)


def free_field(wave_type, angle=0.0, azimuth=0.0, surface=None):
    return FreeField([dict(type=wave_type, angle=angle, azimuth=azimuth)], ROCK["E"], ROCK["nu"], ROCK["rho"],
                     surface=surface, waveform=unit_ricker, table_grid=(0.0, 1.0e-3, 2000), model_bounds=BOX)


def incident(field):
    return next(c for c in field.components if c.name.endswith("incident"))


def documented_polarisations():
    """{type: (formula, direction at theta = 0, phi = 0)} from the document's table."""
    row = re.compile(r"^\s*\| (P|SV|SH) \| ([^|]+) \| ([^|]+) \|$", re.MULTILINE)
    rows = row.findall(scene_keys.WAVE_CONVENTIONS)
    return {wave: (formula.strip(), at_zero.strip()) for wave, formula, at_zero in rows}


def test_documented_polarisations_at_vertical_incidence_are_the_free_fields():
    axes = {"+x": [1.0, 0.0, 0.0], "+y": [0.0, 1.0, 0.0], "+z": [0.0, 0.0, 1.0]}
    documented = documented_polarisations()
    assert sorted(documented) == ["P", "SH", "SV"]
    for wave, (_, at_zero) in documented.items():
        np.testing.assert_allclose(incident(free_field(wave)).amplitude, axes[at_zero], atol=ROUNDOFF)


def test_documented_directions_and_polarisations_at_oblique_incidence():
    theta, phi = np.radians(30.0), np.radians(30.0)
    e_h = np.array([np.cos(phi), np.sin(phi), 0.0])
    e_z = np.array([0.0, 0.0, 1.0])
    k = np.sin(theta) * e_h + np.cos(theta) * e_z          # upwards, towards +e_h
    expected = {"P": k, "SV": np.cos(theta) * e_h - np.sin(theta) * e_z, "SH": np.cross(e_z, e_h)}
    formulas = {"P": "k", "SV": "cos θ e_h - sin θ e_z", "SH": "e_t"}
    documented = documented_polarisations()
    for wave in ("P", "SV", "SH"):
        component = incident(free_field(wave, 30.0, 30.0))
        np.testing.assert_allclose(component.amplitude, expected[wave], atol=ROUNDOFF)
        speed = np.linalg.norm(component.slowness) ** -1
        np.testing.assert_allclose(component.slowness * speed, k, atol=ROUNDOFF)
        assert documented[wave][0].startswith(formulas[wave])
    assert "k = sin θ e_h + cos θ e_z" in scene_keys.WAVE_CONVENTIONS
    assert "e_h = (cos φ, sin φ, 0)" in scene_keys.WAVE_CONVENTIONS


@pytest.mark.parametrize("wave, angle, azimuth", [("SV", 30.0, 0.0), ("P", 20.0, 135.0), ("SH", 45.0, -60.0)])
def test_default_reference_point_is_the_corner_reached_first(wave, angle, azimuth):
    component = incident(free_field(wave, angle, azimuth, surface=200.0))
    lo, hi = (np.asarray(b) for b in BOX)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    delays = corners @ component.slowness + component.delay_offset
    first = corners[np.argmin(corners @ component.slowness)]   # smallest k.x
    assert delays.min() == pytest.approx(0.0, abs=1e-12)       # no negative delay anywhere in the box
    assert first @ component.slowness + component.delay_offset == pytest.approx(0.0, abs=1e-12)


def test_the_motion_is_the_incident_displacement_at_the_reference_point():
    t = np.linspace(0.0, 0.8, 801)
    g = unit_ricker(t)[0]
    alone = free_field("SV", 30.0)          # no surface: the incident wave alone
    component = incident(alone)
    corners = np.array([[0.0, 0.0, 0.0]])    # the corner SV at azimuth 0 reaches first
    assert corners[0] @ component.slowness + component.delay_offset == pytest.approx(0.0, abs=1e-12)
    u = alone.displacement(corners, t)[:, 0, :]
    assert rel_error(u, np.outer(g, component.amplitude)) < ROUNDOFF
    # With the free surface the total motion adds the reflection: twice g at the surface (vertical SV).
    reflected = free_field("SV", 0.0, surface=200.0)
    at_surface = reflected.displacement(np.array([[0.0, 0.0, 200.0]]), t)[:, 0, 0]
    delay = 200.0 / reflected.c_s           # from x0 = (0, 0, 0) up to the surface
    assert rel_error(at_surface, 2.0 * unit_ricker(t - delay)[0]) < ROUNDOFF


def test_figure_is_drawn_from_the_free_field(tmp_path):
    out = tmp_path / "conventions.png"
    script = REPO / "workflows" / "wave_conventions.py"
    result = subprocess.run(["/usr/bin/python3", str(script), "--out", str(out)], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (REPO / "docs" / "wave-conventions.png").is_file()
    assert "(wave-conventions.png)" in DOCUMENT.read_text()

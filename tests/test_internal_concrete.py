"""The powerhouse's internal concrete in the layered-cavern builder (mesh.parameters.internal_concrete).

Machine piers, turbine and generator floor slabs and wind covers (pyfem/geometry/layered_cavern.py
INTERNAL_CONCRETE, our assumption of typical dimensions) as region "internal_concrete", cut out of
the excavation's grid: measured from the gmsh model the builder fills and compared with the closed
form of the stated dimensions (written out here, not taken from the builder); the region shares
its nodes with the lining; off by default; a bad value is one line, exit 2.
"""
import json
import math
import os
import pathlib
import subprocess

import gmsh
import numpy as np
import pytest

from pyfem.geometry import gmsh_session
from pyfem.geometry.layered_cavern import (INTERNAL_CONCRETE, build_layered_cavern, hexahedron_volumes,
                                           layered_cavern_parameters)

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
SCENE = REPOSITORY / "workflows" / "scenes" / "case3_internal_concrete_coarse.toml"
# The coarse preset on a smaller box (the cavern's full length: the four units need 122 m of it).
SMALL = {"preset": "coarse", "half_width_x": 40.0, "below": 20.0, "above": 20.0, "margin_y": 20.0,
         "h_cavern": 8.0, "h_far": 20.0, "grading": 1.5, "excavated": False}
SMALL_SCENE = [f"mesh.parameters.{key}={str(value).lower() if isinstance(value, bool) else value}"
               for key, value in SMALL.items() if key != "preset"]
INNER_WIDTH = 24.9 - 2 * 1.0      # the lining's inner width (m)
FLOOR_TOP = 1.0                   # the floor lining's top (m)
DIP = 70.0
Z_REF = 60.15 / 2


def closed_form() -> dict:
    """The parts' volumes from the stated dimensions (m^3): 4 units 30 m apart at y = -30 .. 60,
    piers 2 m thick halfway between them and 15 m beyond the end units (5 piers, unit block
    y = -46 .. 76), turbine floor z = 16 .. 17, generator floor z = 24 .. 25, wind cover a square
    ring of inner side 13 m and wall 1 m from z = 17 to 24; the slabs have each unit's pit (13 x 13 m)
    open and the turbine floor gives way to the piers. Shear along the bedding keeps volumes."""
    block, piers, pit = 122.0, 5 * 2.0, 13.0**2
    return {"machine_piers": piers * INNER_WIDTH * (24.0 - FLOOR_TOP),
            "turbine_floor": ((block - piers) * INNER_WIDTH - 4 * pit) * 1.0,
            "generator_floor": (block * INNER_WIDTH - 4 * pit) * 1.0,
            "wind_cover": 4 * (15.0**2 - pit) * 7.0}


@pytest.fixture(scope="module")
def built():
    """The SMALL model with the internal concrete: its summary, nodes and cells per physical volume."""
    with gmsh_session("internal_concrete"):
        summary = build_layered_cavern({**SMALL, "internal_concrete": True})
        tags, coords, _ = gmsh.model.mesh.getNodes()
        x = np.empty((int(tags.max()), 3))
        x[tags.astype(np.int64) - 1] = coords.reshape(-1, 3)
        volumes = {}
        for dim, tag in gmsh.model.getPhysicalGroups(3):
            name = gmsh.model.getPhysicalName(dim, tag)
            blocks = []
            for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                _, _, nodes = gmsh.model.mesh.getElements(dim, entity)
                blocks += [np.asarray(n, dtype=np.int64).reshape(-1, 8) - 1 for n in nodes]
            volumes[name] = np.vstack(blocks)
    return {"summary": summary, "x": x, "volumes": volumes}


def test_the_stated_dimensions_are_the_builders():
    c = INTERNAL_CONCRETE
    assert c["unit_centres"] == (-30.0, 0.0, 30.0, 60.0) and c["pier_thickness"] == 2.0
    assert c["turbine_floor"] == (16.0, 17.0) and c["generator_floor"] == (24.0, 25.0)
    assert c["wind_cover_inner"] == 13.0 and c["wind_cover_wall"] == 1.0


def test_off_by_default():
    assert layered_cavern_parameters({})["internal_concrete"] is False
    with gmsh_session("off"):
        summary = build_layered_cavern({k: v for k, v in SMALL.items()})
    assert "internal_concrete" not in summary["regions"] and "internal_concrete" not in summary


def test_region_and_parts_have_the_closed_form_volumes(built):
    summary, x, volumes = built["summary"], built["x"], built["volumes"]
    assert "internal_concrete" in volumes and len(volumes["internal_concrete"]) > 0
    expected = closed_form()
    measured_parts = summary["internal_concrete"]["part_volumes"]
    assert set(measured_parts) == set(expected)
    for name, volume in expected.items():
        assert measured_parts[name] == pytest.approx(volume, rel=1e-12), name
    # The region as gmsh holds it: the sum of the parts (disjoint) and nothing else.
    region = hexahedron_volumes(x, volumes["internal_concrete"]).sum()
    assert region == pytest.approx(sum(expected.values()), rel=1e-12)
    assert sum(summary["internal_concrete"]["part_cells"].values()) == len(volumes["internal_concrete"])


def test_the_concrete_lies_where_stated(built):
    """Across the lining's inner width, from the floor lining's top to the generator floor's top;
    along y the unit block between the end piers' outer faces, measured on the bedding-parallel
    stations (y + (z - z_ref) cot(dip) for layers dipping towards +y)."""
    x = built["x"][np.unique(built["volumes"]["internal_concrete"])]
    assert x[:, 0].min() == pytest.approx(-INNER_WIDTH / 2, abs=1e-9)
    assert x[:, 0].max() == pytest.approx(INNER_WIDTH / 2, abs=1e-9)
    assert x[:, 2].min() == pytest.approx(FLOOR_TOP, abs=1e-9) and x[:, 2].max() == pytest.approx(25.0, abs=1e-9)
    y_ref = x[:, 1] + (x[:, 2] - Z_REF) / math.tan(math.radians(DIP))
    assert y_ref.min() == pytest.approx(-46.0, abs=1e-9) and y_ref.max() == pytest.approx(76.0, abs=1e-9)


def test_the_mesh_is_conforming_concrete_nodes_are_the_linings(built):
    """Where the concrete meets the lining's inner face (walls x = +-11.45, floor z = 1) its nodes are
    the lining's nodes, and no two nodes of the model share a position (nothing is left unjoined)."""
    x, volumes = built["x"], built["volumes"]
    concrete = np.unique(volumes["internal_concrete"])
    lining = set(np.unique(volumes["lining"]).tolist())
    on_face = concrete[(np.abs(np.abs(x[concrete, 0]) - INNER_WIDTH / 2) < 1e-9)
                       | (np.abs(x[concrete, 2] - FLOOR_TOP) < 1e-9)]
    assert len(on_face) > 100
    assert set(on_face.tolist()) <= lining
    used = np.unique(np.vstack(list(volumes.values())))
    rounded = np.round(x[used], 6)
    assert len(np.unique(rounded, axis=0)) == len(used)


def test_quality_and_time_step(built):
    """Good hexahedra; the concrete's smallest edge is 0.6 m or more (a pier face 0.6 m from a layer
    interface), so its time step exceeds the lining's (0.5 m cells through the lining)."""
    summary = built["summary"]
    assert summary["min_scaled_jacobian"] > 0.5
    steps = summary["critical_time_step_by_region"]
    assert steps["internal_concrete"] > steps["lining"]


@pytest.mark.parametrize("value", ['"yes"', "1"])
def test_a_bad_value_is_one_line_exit_2(tmp_path, value):
    env = dict(os.environ, PYFEM_ONE_MODEL="1")
    result = subprocess.run(["/usr/bin/python3", "-m", "pyfem", "check", str(SCENE),
                             "--set", f"mesh.parameters.internal_concrete={value}"],
                            cwd=REPOSITORY, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    assert len(result.stderr.splitlines()) == 1, result.stderr
    assert "mesh.parameters.internal_concrete" in result.stderr and "true or false" in result.stderr


def test_a_cavern_too_short_for_the_units_is_refused():
    with pytest.raises(ValueError, match=r"mesh.parameters.internal_concrete = true: the unit block"):
        layered_cavern_parameters({"internal_concrete": True, "length": 100.0})


@pytest.mark.slow
def test_a_small_model_with_the_concrete_checks_and_runs(tmp_path):
    """`pyfem check` and a short run of case 3 with the concrete on a small box: the static stage
    excavates and installs the concrete with the lining (stress-free), the run finishes."""
    env = dict(os.environ, PYFEM_ONE_MODEL="1", OMP_NUM_THREADS="1")
    sets = [arg for item in [*SMALL_SCENE, "time.duration=0.01", "wave.motion.record.lead_in=0.0",
                             "output.xdmf_interval=0.0"] for arg in ("--set", item)]
    check = subprocess.run(["/usr/bin/python3", "-m", "pyfem", "check", str(SCENE), *sets],
                           cwd=REPOSITORY, env=env, capture_output=True, text=True, timeout=1200)
    assert check.returncode == 0, check.stderr
    assert "internal_concrete" in check.stdout
    out = tmp_path / "run"
    run = subprocess.run(["/usr/bin/python3", "-m", "pyfem", "run", str(SCENE), "--out", str(out), *sets],
                         cwd=REPOSITORY, env=env, capture_output=True, text=True, timeout=3600)
    assert run.returncode == 0, run.stderr
    summary = json.loads((out / "run.json").read_text())
    assert summary["status"] == "finished"
    assert "internal_concrete" in summary["regions"]
    assert summary["scene"]["static"]["install"] == ["lining", "internal_concrete"]
    assert [stage["converged"] for stage in summary["static"]["stages"]] == [True, True]


def test_an_excavated_regions_law_is_not_looked_for():
    """The same mesh without the concrete excavates region internal_concrete, whose [materials] table
    (with its [damage]) stays in the scene: no element-loop law is set up for the region the model
    no longer has (before: "region 'internal_concrete': unknown" when the run started)."""
    from pyfem.elements import scene_laws
    from pyfem.scene import load_scene

    installed, _ = scene_laws(load_scene(SCENE))
    assert {"lining", "internal_concrete"} <= set(installed)
    excavated, _ = scene_laws(load_scene(SCENE, ['static.excavate=["excavation","internal_concrete"]',
                                                 'static.install=["lining"]']))
    assert "lining" in excavated and "internal_concrete" not in excavated

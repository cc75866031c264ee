"""The layered-cavern builder: names, dimensions, layer planes, volumes, quality, dolfinx.

Every geometric fact is measured from the gmsh model the builder fills (nodes
and elements of the physical groups) or from the dolfinx mesh made from it,
and compared with the asked parameters or an independent formula.
"""
import importlib.util
import math
import pathlib

import gmsh
import numpy as np
import pytest
import ufl
from dolfinx import fem, geometry
from dolfinx.io import gmshio
from mpi4py import MPI

from conftest import ROUNDOFF
from pyfem.geometry import gmsh_session, load_msh
from pyfem.geometry.layered_cavern import (PARAMETER_KEYS, build_layered_cavern, hexahedron_volumes,
                                           layered_cavern_parameters, scaled_jacobians)

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]

# The coarse preset on a smaller box: the cavern, lining and layers of the paper.
SMALL = {"preset": "coarse", "half_width_x": 60.0, "below": 40.0, "above": 40.0, "margin_y": 40.0,
         "h_far": 15.0}
LAYER_MATERIALS = ("non_sandstone", "sandstone")
WIDTH, HEIGHT, RISE, LENGTH = 24.9, 60.15, 8.0, 175.6
CROWN, WALL, FLOOR = 1.25, 1.0, 1.0
DIP = 70.0
SOFT, HARD = 8.0, 12.0   # layer thicknesses normal to the bedding (m)
Z_REF = HEIGHT / 2       # the soft layer is centred on Y = 0 at the cavern's mid-height


def model_data(summary: dict) -> dict:
    """Nodes, cells per physical volume and nodes/quads per physical surface of the current gmsh model."""
    tags, coords, _ = gmsh.model.mesh.getNodes()
    x = np.empty((int(tags.max()), 3))
    x[tags.astype(np.int64) - 1] = coords.reshape(-1, 3)
    volumes, surface_nodes, surface_quads = {}, {}, {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(dim, tag)
        blocks = []
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            types, _, nodes = gmsh.model.mesh.getElements(dim, entity)
            blocks += [np.asarray(n, dtype=np.int64).reshape(-1, 8 if dim == 3 else 4) - 1 for n in nodes]
        elements = np.vstack(blocks)
        if dim == 3:
            volumes[name] = elements
        else:
            surface_quads[name] = elements
            surface_nodes[name] = np.unique(elements)
    return {"summary": summary, "x": x, "volumes": volumes, "surface_nodes": surface_nodes,
            "surface_quads": surface_quads,
            "tags": {gmsh.model.getPhysicalName(d, t): t for d, t in gmsh.model.getPhysicalGroups()}}


@pytest.fixture(scope="module")
def cavern():
    """The SMALL model: its gmsh data and the dolfinx mesh made from the same gmsh model."""
    with gmsh_session("test_layered_cavern"):
        data = model_data(build_layered_cavern(SMALL))
        mesh, cell_tags, facet_tags = gmshio.model_to_mesh(gmsh.model, MPI.COMM_WORLD, 0, gdim=3)
    data.update(mesh=mesh, cell_tags=cell_tags, facet_tags=facet_tags)
    return data


def cells_at(mesh, points: np.ndarray) -> list[np.ndarray]:
    """Cells of `mesh` containing each point."""
    tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
    candidates = geometry.compute_collisions(tree, points)
    colliding = geometry.compute_colliding_cells(mesh, candidates, points)
    return [colliding.links(i) for i in range(len(points))]


def plane_fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares plane through `points`: (centroid, unit normal with n_y > 0, largest residual)."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid)
    normal = vt[-1] * np.sign(vt[-1][1])
    return centroid, normal, float(np.abs((points - centroid) @ normal).max())


def polygon_area(xz: np.ndarray) -> float:
    """Area of the convex polygon through the points `xz` (sorted by angle about their centroid)."""
    centre = xz.mean(axis=0)
    ordered = xz[np.argsort(np.arctan2(xz[:, 1] - centre[1], xz[:, 0] - centre[0]))]
    following = np.roll(ordered, -1, axis=0)
    return 0.5 * abs(np.sum(ordered[:, 0] * following[:, 1] - following[:, 0] * ordered[:, 1]))


def inside_excavation(points: np.ndarray, margin: float) -> np.ndarray:
    """Whether each point lies inside the excavated section (x-z), by more than `margin` (m)."""
    x, z = points[:, 0], points[:, 2]
    z_spring = HEIGHT - RISE
    radius = (WIDTH**2 / 4 + RISE**2) / (2 * RISE)
    in_walls = (np.abs(x) < WIDTH / 2 - margin) & (z > margin) & (z <= z_spring)
    in_crown = (z > z_spring) & (np.hypot(x, z - (HEIGHT - radius)) < radius - margin)
    return in_walls | in_crown


def unique_xz(points: np.ndarray) -> np.ndarray:
    return np.unique(np.round(points[:, [0, 2]], 9), axis=0)


def test_all_named_groups_are_present(cavern):
    summary = cavern["summary"]
    interfaces = [f"interface_{k}" for k in range(1, len(summary["interfaces"]) + 1)]
    assert len(interfaces) >= 10   # the cavern's 175.6 m cross ~16 layers of 8.5-12.8 m (along y)
    assert sorted(cavern["volumes"]) == sorted([*LAYER_MATERIALS, "lining"])
    expected_surfaces = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "cavern_surface", "lining_inner",
                         "cavern_ends", *interfaces]
    assert sorted(cavern["surface_nodes"]) == sorted(expected_surfaces)
    assert [entry["name"] for entry in summary["interfaces"]] == interfaces
    for name, quads in cavern["surface_quads"].items():
        assert len(quads) > 0, name


def test_cavern_and_lining_dimensions_measured_from_the_mesh(cavern):
    x = cavern["x"]
    outer = x[cavern["surface_nodes"]["cavern_surface"]]
    inner = x[cavern["surface_nodes"]["lining_inner"]]
    tolerance = ROUNDOFF * HEIGHT
    assert outer[:, 0].max() - outer[:, 0].min() == pytest.approx(WIDTH, abs=tolerance)
    assert outer[:, 0].max() == pytest.approx(WIDTH / 2, abs=tolerance)        # centred on x = 0
    assert outer[:, 2].max() - outer[:, 2].min() == pytest.approx(HEIGHT, abs=tolerance)
    assert outer[:, 2].max() - inner[:, 2].max() == pytest.approx(CROWN, abs=tolerance)
    assert inner[:, 0].min() - outer[:, 0].min() == pytest.approx(WALL, abs=tolerance)
    assert outer[:, 0].max() - inner[:, 0].max() == pytest.approx(WALL, abs=tolerance)
    assert inner[:, 2].min() - outer[:, 2].min() == pytest.approx(FLOOR, abs=tolerance)
    # Length along the crown apex line (the ends are sheared alike, so any line gives it).
    apex = outer[(np.abs(outer[:, 0]) < tolerance) & (outer[:, 2] > HEIGHT - tolerance)]
    assert np.ptp(apex[:, 1]) == pytest.approx(LENGTH, abs=tolerance)
    # The crown nodes of both faces lie on their circular arcs (through the wall tops and apex).
    checks = 0
    for points, half, apex_z in ((outer, WIDTH / 2, HEIGHT), (inner, WIDTH / 2 - WALL, HEIGHT - CROWN)):
        rise = apex_z - (HEIGHT - RISE)
        radius = (half**2 + rise**2) / (2 * rise)
        crown = unique_xz(points[points[:, 2] > HEIGHT - RISE + tolerance])
        assert len(crown) >= 3
        distance = np.hypot(crown[:, 0], crown[:, 1] - (apex_z - radius))
        np.testing.assert_allclose(distance, radius, rtol=0, atol=1e-8)
        checks += 1
    assert checks == 2
    assert cavern["summary"]["dimensions"]["lining_crown"] == pytest.approx(CROWN, abs=tolerance)


def test_at_least_lining_elements_through_the_lining(cavern):
    elements = layered_cavern_parameters(SMALL)["lining_elements"]
    assert elements == 2
    x = cavern["x"]
    lining_nodes = x[np.unique(cavern["volumes"]["lining"])]
    tolerance = ROUNDOFF * HEIGHT
    # Crown: the lining nodes on the radial line x = 0 above the inner apex sit on elements + 1 levels.
    on_line = (np.abs(lining_nodes[:, 0]) < tolerance) & (lining_nodes[:, 2] > HEIGHT - CROWN - tolerance)
    levels = np.unique(np.round(lining_nodes[on_line, 2], 9))
    np.testing.assert_allclose(levels, np.linspace(HEIGHT - CROWN, HEIGHT, elements + 1))
    # Walls: a horizontal line across the downstream wall lining at Y = 0 crosses `elements` cells
    # (strike along x: the line stays between two station planes).
    mesh, cell_tags = cavern["mesh"], cavern["cell_tags"]
    line = np.column_stack([np.linspace(WIDTH / 2 - WALL + 1e-6, WIDTH / 2 - 1e-6, 401), np.full(401, 0.1234),
                            np.full(401, HEIGHT / 2 + 0.0567)])
    crossed = np.unique(np.concatenate(cells_at(mesh, line)))
    lining_tag = cavern["tags"]["lining"]
    tag_of = dict(zip(cell_tags.indices, cell_tags.values))
    assert [tag_of[c] for c in crossed] == [lining_tag] * elements


def test_interfaces_are_planes_at_the_dip_striking_along_x(cavern):
    x = cavern["x"]
    summary = cavern["summary"]
    checks = 0
    for entry in summary["interfaces"]:
        points = x[cavern["surface_nodes"][entry["name"]]]
        centroid, normal, residual = plane_fit(points)
        assert residual < 1e-9 * HEIGHT
        assert abs(normal[0]) < 1e-12                                     # strike along x
        assert math.degrees(math.acos(abs(normal[2]))) == pytest.approx(DIP, abs=1e-9)
        # Dipping towards +y (the paper: dip NE, y axis N58E): the plane descends as y grows.
        assert normal[1] > 0 and normal[2] > 0
        # Only the rock part: no interface node strictly inside the excavation (walls + crown arc).
        assert not inside_excavation(points, margin=1e-6).any()
        assert np.sum(np.abs(inside_excavation(points, margin=-1e-6))) > 0   # but it reaches the cavern
        # The pair-monitor points lie on the plane, in the rock next to the walls.
        for key in ("point_upstream", "point_downstream"):
            assert abs((np.array(entry[key]) - centroid) @ normal) < 1e-9 * HEIGHT
            assert abs(entry[key][0]) > WIDTH / 2
        checks += 1
    assert checks == len(summary["interfaces"]) >= 10


def test_dip_direction_minus_y_mirrors_the_layers():
    with gmsh_session("test_layered_cavern_minus_y"):
        data = model_data(build_layered_cavern({**SMALL, "dip_direction": "-y"}))
    checks = 0
    for entry in data["summary"]["interfaces"]:
        _, normal, _ = plane_fit(data["x"][data["surface_nodes"][entry["name"]]])
        assert normal[2] < 0   # (n_y > 0): the plane now rises as y grows, i.e. dips towards -y
        assert math.degrees(math.acos(abs(normal[2]))) == pytest.approx(DIP, abs=1e-9)
        checks += 1
    assert checks == len(data["summary"]["interfaces"]) >= 10


def test_monitoring_section_lies_in_the_middle_of_a_soft_layer(cavern):
    x = cavern["x"]
    # The two interfaces nearest Y = 0 at z_ref bound the soft layer symmetrically.
    crossings = []
    for entry in cavern["summary"]["interfaces"]:
        centroid, normal, _ = plane_fit(x[cavern["surface_nodes"][entry["name"]]])
        # y on the plane at x = 0, z = z_ref
        crossings.append(centroid[1] - (normal[2] * (Z_REF - centroid[2])) / normal[1])
    crossings = np.sort(crossings)
    below, above = crossings[crossings < 0].max(), crossings[crossings > 0].min()
    half_width_y = SOFT / (2 * math.sin(math.radians(DIP)))
    assert below == pytest.approx(-half_width_y, abs=1e-9)
    assert above == pytest.approx(half_width_y, abs=1e-9)
    # The rock at Y = 0 beside both walls, at z_ref, is non_sandstone (dolfinx point location).
    points = np.array([[-WIDTH / 2 - 3.0, 0.0, Z_REF], [WIDTH / 2 + 3.0, 0.0, Z_REF],
                       [-40.0, 0.0, Z_REF - 5.0]])
    tag_of = dict(zip(cavern["cell_tags"].indices, cavern["cell_tags"].values))
    found = [{tag_of[c] for c in cells} for cells in cells_at(cavern["mesh"], points)]
    assert found == [{cavern["tags"]["non_sandstone"]}] * 3
    # The lining monitor points A-D lie on the lining's inner face (x, z) at Y = 0.
    inner_xz = unique_xz(x[cavern["surface_nodes"]["lining_inner"]])
    points = cavern["summary"]["monitor_points"]
    assert np.min(np.linalg.norm(inner_xz - [points["A"][0], points["A"][2]], axis=1)) < 1e-9
    assert np.min(np.linalg.norm(inner_xz - [points["D"][0], points["D"][2]], axis=1)) < 1e-9
    assert points["B"][0] == pytest.approx(-(WIDTH / 2 - WALL))
    assert points["C"][0] == pytest.approx(WIDTH / 2 - WALL)
    assert all(p[1] == 0.0 for p in points.values())


def test_region_volumes_fill_the_box_minus_the_excavation(cavern):
    p = layered_cavern_parameters(SMALL)
    x, mesh, cell_tags = cavern["x"], cavern["mesh"], cavern["cell_tags"]
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=cell_tags)
    one = fem.Constant(mesh, 1.0)
    volumes = {name: fem.assemble_scalar(fem.form(one * dx(cavern["tags"][name])))
               for name in ("lining", *LAYER_MATERIALS)}
    box = 2 * p["half_width_x"] * (p["below"] + HEIGHT + p["above"]) * (LENGTH + 2 * p["margin_y"])
    # The excavation and the lining are prisms of the discretised sections over the cavern length.
    inner_area = polygon_area(unique_xz(x[cavern["surface_nodes"]["lining_inner"]]))
    outer_xz = unique_xz(x[cavern["surface_nodes"]["cavern_surface"]])
    outer_area = polygon_area(outer_xz)
    assert sum(volumes.values()) == pytest.approx(box - inner_area * LENGTH, rel=ROUNDOFF)
    assert volumes["lining"] == pytest.approx((outer_area - inner_area) * LENGTH, rel=ROUNDOFF)
    # The polygons approximate the curved section: rectangle plus circular segment.
    half, z_spring = WIDTH / 2, HEIGHT - RISE
    radius = (half**2 + RISE**2) / (2 * RISE)
    angle = 2 * math.asin(half / radius)
    segment = 0.5 * radius**2 * (angle - math.sin(angle))
    # ... less the n_arc chord segments the polygon cuts off (0.2 % of the area here).
    n_arc = len(outer_xz[outer_xz[:, 1] > z_spring + 1e-9]) + 1
    chords = n_arc * 0.5 * radius**2 * (angle / n_arc - math.sin(angle / n_arc))
    assert outer_area == pytest.approx(WIDTH * z_spring + segment - chords, rel=ROUNDOFF)
    # The builder's own volumes agree with dolfinx's.
    for name, volume in volumes.items():
        assert cavern["summary"]["region_volumes"][name] == pytest.approx(volume, rel=ROUNDOFF)
    # Layer fractions: 60 % sandstone by thickness; the model's 255.6 m along y hold 12.0 periods
    # of 21.3 m, but the cavern's ends fall in soft layers (less soft rock there) and the soft
    # slivers at the y faces join their sandstone neighbours: measured 0.637.
    fraction = volumes["sandstone"] / (volumes["sandstone"] + volumes["non_sandstone"])
    assert fraction == pytest.approx(HARD / (HARD + SOFT), abs=0.05)


def test_a_layer_between_two_interfaces_has_its_exact_volume(cavern):
    """A layer over the cavern: thickness / sin(dip) along y times the rock section."""
    p = layered_cavern_parameters(SMALL)
    x = cavern["x"]
    planes = [plane_fit(x[cavern["surface_nodes"][entry["name"]]])[:2]
              for entry in cavern["summary"]["interfaces"]]
    checks = 0
    for name, thickness in (("non_sandstone", SOFT), ("sandstone", HARD)):
        cells = cavern["volumes"][name]
        centres = x[cells].mean(axis=1)
        for (c0, n0), (c1, n1) in zip(planes[:-1], planes[1:]):
            between = ((centres - c0) @ n0 > 0) & ((centres - c1) @ n1 < 0)
            if between.sum() == 0:
                continue
            # The rock section: the model's rectangle minus the excavation polygon (lining outer face).
            outer_xz = unique_xz(x[cavern["surface_nodes"]["cavern_surface"]])
            section = 2 * p["half_width_x"] * (p["below"] + HEIGHT + p["above"]) - polygon_area(outer_xz)
            expected = thickness / math.sin(math.radians(DIP)) * section
            assert hexahedron_volumes(x, cells[between]).sum() == pytest.approx(expected, rel=ROUNDOFF)
            checks += 1
            break
    assert checks == 2


def test_quality_is_good_and_recomputed_from_gmsh(cavern):
    summary = cavern["summary"]
    all_cells = np.vstack(list(cavern["volumes"].values()))
    recomputed = scaled_jacobians(cavern["x"], all_cells).min()
    assert recomputed == pytest.approx(summary["min_scaled_jacobian"], rel=ROUNDOFF)
    assert summary["min_scaled_jacobian"] > 0.1    # measured 0.54 for this model
    # The smallest edge is the lining's wall cell (lining_wall / lining_elements) or the crown's.
    assert summary["min_edge_length"] == pytest.approx(WALL / 2, rel=ROUNDOFF)
    c_p_concrete = math.sqrt(28.0e9 * (1 - 0.167) / ((1 + 0.167) * (1 - 2 * 0.167) * 2500.0))
    assert summary["critical_time_step"] == pytest.approx(WALL / 2 / c_p_concrete, rel=ROUNDOFF)


def test_scaled_jacobian_of_known_hexahedra():
    cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                     [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float)
    order = np.arange(8)[None]
    assert scaled_jacobians(cube, order)[0] == pytest.approx(1.0, abs=ROUNDOFF)
    sheared = cube.copy()
    sheared[:, 1] += 0.75 * sheared[:, 2]          # y += 0.75 z: the sheared extrusion of this builder
    assert scaled_jacobians(sheared, order)[0] == pytest.approx(1 / math.hypot(1, 0.75), abs=ROUNDOFF)
    mirrored = cube * [1, 1, -1]
    assert scaled_jacobians(mirrored, order)[0] == pytest.approx(-1.0, abs=ROUNDOFF)
    assert hexahedron_volumes(sheared * [2, 3, 5], order)[0] == pytest.approx(30.0, rel=ROUNDOFF)


def test_dolfinx_reads_the_same_cells_and_facets(cavern):
    mesh, cell_tags, facet_tags = cavern["mesh"], cavern["cell_tags"], cavern["facet_tags"]
    n_cells = sum(len(c) for c in cavern["volumes"].values())
    assert n_cells == cavern["summary"]["cells"]
    assert mesh.topology.index_map(3).size_local == n_cells
    for name, cells in cavern["volumes"].items():
        assert np.sum(cell_tags.values == cavern["tags"][name]) == len(cells)
    for name, quads in cavern["surface_quads"].items():
        assert np.sum(facet_tags.values == cavern["tags"][name]) == len(quads), name


def test_excavation_present_when_not_excavated():
    with gmsh_session("test_layered_cavern_full"):
        data = model_data(build_layered_cavern({**SMALL, "excavated": False}))
    p = layered_cavern_parameters(SMALL)
    assert sorted(data["volumes"]) == sorted([*LAYER_MATERIALS, "lining", "excavation"])
    volume = sum(hexahedron_volumes(data["x"], cells).sum() for cells in data["volumes"].values())
    box = 2 * p["half_width_x"] * (p["below"] + HEIGHT + p["above"]) * (LENGTH + 2 * p["margin_y"])
    assert volume == pytest.approx(box, rel=ROUNDOFF)
    inner_area = polygon_area(unique_xz(data["x"][data["surface_nodes"]["lining_inner"]]))
    excavated = hexahedron_volumes(data["x"], data["volumes"]["excavation"]).sum()
    assert excavated == pytest.approx(inner_area * LENGTH, rel=ROUNDOFF)
    assert data["summary"]["min_scaled_jacobian"] > 0.1


def test_presets_and_overrides():
    coarse = layered_cavern_parameters({})
    assert coarse["preset"] == "coarse" and coarse["half_width_x"] == 100.0
    assert coarse["h_near"] == pytest.approx(WALL / 2)         # lining_wall / lining_elements
    assert coarse["layer_reference_z"] == pytest.approx(HEIGHT / 2)
    paper = layered_cavern_parameters({"preset": "paper", "below": 120.0})
    assert paper["half_width_x"] == 150.0 and paper["below"] == 120.0
    assert set(coarse) == set(PARAMETER_KEYS)


@pytest.mark.parametrize("parameters, key", [
    ({"lining_crown": -1.0}, "mesh.parameters.lining_crown"),
    ({"lining_elements": 1}, "mesh.parameters.lining_elements"),
    ({"dip": 0.0}, "mesh.parameters.dip"),
    ({"dip": 30.0}, "mesh.parameters.margin_y"),          # the layers could not turn to the y faces
    ({"arch_rise": 20.0}, "mesh.parameters.arch_rise"),   # more than a semicircle
    ({"layers": [{"material": "lining", "thickness": 5.0}]}, "mesh.parameters.layers.0.material"),
    ({"layers": [{"material": "sandstone", "thickness": 0.0}]}, "mesh.parameters.layers.0.thickness"),
    ({"preset": "fine"}, "mesh.parameters.preset"),
    ({"widht": 20.0}, "mesh.parameters.widht"),
    ({"excavated": "yes"}, "mesh.parameters.excavated"),
    ({"grading": 1.0}, "mesh.parameters.grading"),
])
def test_bad_parameters_name_the_key(parameters, key):
    with pytest.raises(ValueError, match=key.replace(".", r"\.")):
        layered_cavern_parameters(parameters)


def test_script_writes_a_msh_the_file_builder_reads(tmp_path):
    spec = importlib.util.spec_from_file_location("layered_cavern_script",
                                                  REPOSITORY / "meshes" / "layered_cavern.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    path = tmp_path / "cavern.msh"
    summary = script.write_layered_cavern(path, SMALL)
    with gmsh_session("reload"):
        load_msh(path)
        names = sorted(gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups())
        mesh, cell_tags, _ = gmshio.model_to_mesh(gmsh.model, MPI.COMM_WORLD, 0, gdim=3)
    assert mesh.topology.index_map(3).size_local == summary["cells"]
    assert names == sorted(summary["regions"] + summary["boundaries"])


@pytest.mark.slow
def test_paper_preset_has_the_paper_size_and_good_quality():
    with gmsh_session("test_layered_cavern_paper"):
        summary = build_layered_cavern({"preset": "paper"})
    assert 100_000 < summary["cells"] < 200_000     # the paper: 138 972 elements (measured 138 040)
    assert summary["min_scaled_jacobian"] > 0.1      # measured 0.46
    dims = summary["dimensions"]
    for key, value in (("width", WIDTH), ("height", HEIGHT), ("length", LENGTH), ("lining_crown", CROWN),
                       ("lining_wall", WALL), ("lining_floor", FLOOR)):
        assert dims[key] == pytest.approx(value, abs=ROUNDOFF * HEIGHT), key


def test_an_inverted_element_fails_loudly(monkeypatch):
    import pyfem.geometry.layered_cavern as builder

    def one_inverted(x, hexahedra):
        quality = scaled_jacobians(x, hexahedra)
        quality[len(quality) // 2] = -0.5
        return quality

    monkeypatch.setattr(builder, "scaled_jacobians", one_inverted)
    with gmsh_session("test_layered_cavern_inverted"):
        with pytest.raises(ValueError, match="1 inverted hexahedra"):
            builder.build_layered_cavern(SMALL)
        assert gmsh.model.getPhysicalGroups() == []   # nothing half-built is left in the model

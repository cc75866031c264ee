"""plots/contour.png's values (pyfem.contour.Contours) against Kirsch's circular opening (issue 51, item 11).

The filled tunnel of tests/test_static.py (a = 5 m, far field sigma_zz = -p, sigma_xx = -K p, p = 10 MPa,
K = 0.5) excavated by a linear stage: along the contour the hoop stress of the wall cells equals Kirsch's
at their centroids' mean radius (2.5 p of compression at the sides, 0.5 p at the crown, at the wall), the
inward wall displacement equals Kirsch's -u_r(a); with the run's displacement zero, the end equals the
stage. Two openings side by side give a pillar whose width change is the difference of the two walls'
displacements across it.
"""
import math

import numpy as np
import pytest

from stage_state import solved
from pyfem.contour import Contours
from pyfem.output import cell_strain_operator
from test_static import (CENTRE, RADIUS, STRESS_TOLERANCE, DISPLACEMENT_TOLERANCE, centroids, kirsch_radial_displacement,
                         kirsch_stress, meshes, tunnel_scene)  # noqa: F401 (meshes: the fixture)


def test_contour_hoop_stress_and_convergence_follow_kirsch(meshes, tmp_path):
    simulation = solved(tunnel_scene(meshes["filled"]))
    contours = Contours(simulation.model, simulation,
                        lambda cells: cell_strain_operator(simulation.scene, simulation.model, cells))
    assert len(contours.openings) == 1 and not contours.pillars
    opening = contours.openings[0]
    assert np.allclose(opening["xz"].mean(axis=0), CENTRE[[0, 2]], atol=1e-6 * RADIUS)
    assert len(opening["nodes"]) >= 32
    # The sampling radius of each contour node: its wall cells' centroids, averaged as the stress is.
    cell_points = centroids(simulation.model)[opening["cells"]]
    points = opening["member"] @ cell_points
    r = np.hypot(points[:, 0] - CENTRE[0], points[:, 2] - CENTRE[2]) / RADIUS
    theta = np.radians(opening["theta"])
    exact = np.array([kirsch_stress(radius, angle)[1] for radius, angle in zip(r, theta)])
    sides = np.abs(np.cos(theta)) > 0.99
    crown = np.abs(np.sin(theta)) > 0.99
    assert sides.sum() >= 2 and crown.sum() >= 2
    for where in (sides, crown):
        error = np.abs(opening["stage_hoop"][where] - exact[where]) / np.abs(exact[where])
        print("hoop", opening["stage_hoop"][where] / 1e6, exact[where] / 1e6, error)
        assert error.max() < STRESS_TOLERANCE
    # At the wall itself Kirsch's hoop stress is -2.5 p at the sides, -0.5 p at the crown; the cells'
    # centroids (r ~ 1.03 a) see a little less.
    assert np.all(opening["stage_hoop"][sides] < -2.2 * 10e6)
    convergence = -np.array([kirsch_radial_displacement(1.0, angle) for angle in theta])
    error = np.abs(opening["stage_displacement"] - convergence) / np.abs(convergence).max()
    print("convergence", opening["stage_displacement"][sides | crown] * 1e3, convergence[sides | crown] * 1e3)
    assert error.max() < DISPLACEMENT_TOLERANCE
    # No run: the end is the stage; the picture is drawn and its summary holds the same numbers.
    summary = contours.plot(tmp_path / "contour.png", "Kirsch")
    assert (tmp_path / "contour.png").stat().st_size > 10_000
    assert summary["openings"][0]["end_hoop_min"] == pytest.approx(float(opening["stage_hoop"].min()))
    # A run's displacement: a rigid translation changes no convergence and no stress.
    u = np.tile([1e-3, 0.0, -2e-3], len(simulation.model.node_coords))
    contours.update(0.1, u)
    assert np.allclose(opening["end_displacement"], opening["stage_displacement"], atol=1e-12)
    assert np.allclose(opening["end_hoop"], opening["stage_hoop"], rtol=1e-9, atol=1e-3)


TWO_HOLES = """
import gmsh, math, sys
gmsh.initialize(readConfigFiles=False)
gmsh.option.setNumber("General.Terminal", 0)
occ = gmsh.model.occ
box = occ.addRectangle(0, 0, 0, 120, 80)
holes = [occ.addDisk(45, 40, 0, 5, 5), occ.addDisk(75, 40, 0, 5, 5)]
section, _ = occ.fragment([(2, box)], [(2, h) for h in holes])
occ.rotate(section, 0, 0, 0, 1, 0, 0, math.pi / 2)
occ.synchronize()
volumes = occ.extrude(section, 0, 2.0, 0, numElements=[1], recombine=True)
occ.synchronize()
rock, excavation = [], []
for dim, tag in volumes:
    if dim == 3:
        x0, _, z0, x1, _, z1 = gmsh.model.getBoundingBox(3, tag)
        (excavation if x1 - x0 < 11 else rock).append(tag)
gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, rock), "rock")
gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, excavation), "excavation")
gmsh.option.setNumber("Mesh.RecombineAll", 1)
gmsh.option.setNumber("Mesh.MeshSizeMax", 4.0)
gmsh.option.setNumber("Mesh.MeshSizeMin", 1.0)
gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 12)
gmsh.model.mesh.generate(3)
gmsh.write(sys.argv[1])
gmsh.finalize()
"""


def test_the_pillar_between_two_openings_widens_by_the_difference_of_its_walls(tmp_path):
    import subprocess
    import sys

    path = tmp_path / "two_holes.msh"
    subprocess.run([sys.executable, "-c", TWO_HOLES, str(path)], check=True, timeout=300)
    p = 10.0e6
    simulation = solved(tunnel_scene(path, stress=[-p, -p, -p, 0.0, 0.0, 0.0]))
    contours = Contours(simulation.model, simulation,
                        lambda cells: cell_strain_operator(simulation.scene, simulation.model, cells))
    assert len(contours.openings) == 2 and len(contours.pillars) == 1
    pillar = contours.pillars[0]
    assert pillar["width"] == pytest.approx(20.0, rel=1e-6)   # the walls at x = 50 and x = 70, z = 40
    u = simulation.displacement.reshape(-1, 3)
    i, j = pillar["nodes"]
    assert simulation.model.node_coords[i][[0, 2]] == pytest.approx([50.0, 40.0], abs=1e-6)
    by_hand = u[j, 0] - u[i, 0]          # the pillar's width change along x
    assert by_hand > 0                   # under all-round compression each wall moves into its opening
    assert pillar["stage"] == pytest.approx(by_hand, rel=1e-12)
    # A run's displacement adds its own difference across the pillar.
    extra = np.zeros_like(simulation.displacement).reshape(-1, 3)
    extra[j, 0] = 1e-3
    contours.update(0.5, extra.ravel())
    assert pillar["change"][-1] == pytest.approx(by_hand + 1e-3, rel=1e-12)
    summary = contours.plot(tmp_path / "contour.png", "two openings")
    assert summary["pillars"][0]["end_change"] == pytest.approx(by_hand + 1e-3, rel=1e-12)


TWO_CAVERNS_GEO = """// two prismatic openings in a 10 m slab (built-in kernel, tetrahedra): an arched one and a box
lf = 12; lc = 3;
Point(1) = {0, 0, 0, lf}; Point(2) = {100, 0, 0, lf}; Point(3) = {100, 0, 80, lf}; Point(4) = {0, 0, 80, lf};
Point(11) = {30, 0, 30, lc}; Point(12) = {40, 0, 30, lc}; Point(13) = {40, 0, 45, lc};
Point(14) = {35, 0, 50, lc}; Point(15) = {30, 0, 45, lc}; Point(16) = {35, 0, 45, lc};
Point(21) = {60, 0, 32, lc}; Point(22) = {68, 0, 32, lc}; Point(23) = {68, 0, 44, lc}; Point(24) = {60, 0, 44, lc};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Line(11) = {11, 12}; Line(12) = {12, 13}; Circle(13) = {13, 16, 14}; Circle(14) = {14, 16, 15}; Line(15) = {15, 11};
Line(21) = {21, 22}; Line(22) = {22, 23}; Line(23) = {23, 24}; Line(24) = {24, 21};
Curve Loop(1) = {1, 2, 3, 4}; Curve Loop(2) = {11, 12, 13, 14, 15}; Curve Loop(3) = {21, 22, 23, 24};
Plane Surface(1) = {1, 2, 3}; Plane Surface(2) = {2}; Plane Surface(3) = {3};
ex[] = Extrude {0, 10, 0} { Surface{1, 2, 3}; };
Physical Volume("rock") = {ex[1]};
Physical Volume("excavation") = {ex[16], ex[23]};
"""


def test_both_openings_of_a_tetrahedral_mesh_are_found_with_their_pillar(tmp_path):
    """Issue 51: a section plane of an unstructured mesh holds few wall nodes or none; the section's band
    finds both openings, their whole contours and the pillar between them (walls at x = 40 and x = 60)."""
    path = tmp_path / "two_caverns.geo"
    path.write_text(TWO_CAVERNS_GEO)
    simulation = solved(tunnel_scene(path))
    assert simulation.model.mesh.topology.cell_type.name == "tetrahedron"
    coords = simulation.model.node_coords
    contours = Contours(simulation.model, simulation,
                        lambda cells: cell_strain_operator(simulation.scene, simulation.model, cells), y0=4.3)
    assert len(contours.openings) == 2 and len(contours.pillars) == 1
    arched, box = sorted(contours.openings, key=lambda o: o["xz"][:, 0].mean())
    for opening, (x0, x1, z0, z1) in ((arched, (30, 40, 30, 50)), (box, (60, 68, 32, 44))):
        xz = opening["xz"]
        assert len(opening["nodes"]) >= 8
        assert np.all((xz[:, 0] > x0 - 1e-6) & (xz[:, 0] < x1 + 1e-6) & (xz[:, 1] > z0 - 1e-6) & (xz[:, 1] < z1 + 1e-6))
        assert np.all(np.abs(coords[opening["nodes"], 1] - contours.y) < 3.0)
        theta = opening["theta"]
        assert np.all((theta >= 0.0) & (theta < 360.0))
        assert np.diff(np.r_[theta, theta[0] + 360.0]).max() < 90.0   # the whole contour, no gap
    # The box's nodes lie on its four walls.
    xz = box["xz"]
    on_wall = np.isclose(xz[:, 0], 60) | np.isclose(xz[:, 0], 68) | np.isclose(xz[:, 1], 32) | np.isclose(xz[:, 1], 44)
    assert on_wall.all()
    # The arch's crown nodes lie on its circle (centre (35, 45), radius 5).
    crown = arched["xz"][arched["xz"][:, 1] > 45.0 + 1e-6]
    assert len(crown) >= 3 and np.allclose(np.hypot(crown[:, 0] - 35, crown[:, 1] - 45), 5.0, atol=1e-6)
    pillar = contours.pillars[0]
    assert 20.0 - 1e-6 < pillar["width"] < 20.5      # the walls at x = 40 and x = 60
    summary = contours.plot(tmp_path / "contour.png", "two caverns")
    assert (tmp_path / "contour.png").stat().st_size > 10_000
    assert len(summary["openings"]) == 2 and len(summary["pillars"]) == 1

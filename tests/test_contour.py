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

from pyfem import solver
from pyfem.contour import Contours
from pyfem.output import cell_strain_operator
from test_static import (CENTRE, RADIUS, STRESS_TOLERANCE, DISPLACEMENT_TOLERANCE, centroids, kirsch_radial_displacement,
                         kirsch_stress, meshes, tunnel_scene)  # noqa: F401 (meshes: the fixture)


def test_contour_hoop_stress_and_convergence_follow_kirsch(meshes, tmp_path):
    simulation = solver.prepare(tunnel_scene(meshes["filled"]))
    contours = Contours(simulation.model, simulation.static,
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
    u = np.tile([1e-3, 0.0, -2e-3], len(simulation.mass))
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
    simulation = solver.prepare(tunnel_scene(path, stress=[-p, -p, -p, 0.0, 0.0, 0.0]))
    contours = Contours(simulation.model, simulation.static,
                        lambda cells: cell_strain_operator(simulation.scene, simulation.model, cells))
    assert len(contours.openings) == 2 and len(contours.pillars) == 1
    pillar = contours.pillars[0]
    assert pillar["width"] == pytest.approx(20.0, rel=1e-6)   # the walls at x = 50 and x = 70, z = 40
    u = simulation.static.displacement.reshape(-1, 3)
    i, j = pillar["nodes"]
    assert simulation.model.node_coords[i][[0, 2]] == pytest.approx([50.0, 40.0], abs=1e-6)
    by_hand = u[j, 0] - u[i, 0]          # the pillar's width change along x
    assert by_hand > 0                   # under all-round compression each wall moves into its opening
    assert pillar["stage"] == pytest.approx(by_hand, rel=1e-12)
    # A run's displacement adds its own difference across the pillar.
    extra = np.zeros_like(simulation.static.displacement).reshape(-1, 3)
    extra[j, 0] = 1e-3
    contours.update(0.5, extra.ravel())
    assert pillar["change"][-1] == pytest.approx(by_hand + 1e-3, rel=1e-12)
    summary = contours.plot(tmp_path / "contour.png", "two openings")
    assert summary["pillars"][0]["end_change"] == pytest.approx(by_hand + 1e-3, rel=1e-12)

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
from test_static import (CENTRE, RADIUS, STRESS_TOLERANCE, DISPLACEMENT_TOLERANCE, centroids, kirsch_radial_displacement,
                         kirsch_stress, meshes, tunnel_scene)  # noqa: F401 (meshes: the fixture)


def test_contour_hoop_stress_and_convergence_follow_kirsch(meshes, tmp_path):
    simulation = solver.prepare(tunnel_scene(meshes["filled"]))
    contours = Contours(simulation.model, simulation.static, simulation.scene)
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

"""A cavity is traction-free, never an input boundary (issue 8): an unlined circular tunnel in a
plane-strain slab under a long vertical SV wave against Kirsch's quasi-static solution.

The tunnel (radius a, axis y) sits in a 120 x 120 m section, 2 m thick in y, meshed by
meshes/tunnel_in_box.py (gmsh, hexahedra graded from 0.6 m at the wall). The thin y faces are
rollers (plane strain); the x and z faces are viscoelastic and carry the free field of a
vertically incident SV Ricker wavelet (2 Hz: the shortest wavelength, ~185 m, is 37 a). For a
far-field shear tau = sigma_xz, Kirsch's solution (theta from +x towards +z) gives
    sigma_thth = -tau (1 + 3 a^4/r^4) sin 2 theta,
    sigma_rr   =  tau (1 + 3 a^4/r^4 - 4 a^2/r^2) sin 2 theta,
    sigma_rth  =  tau (1 - 3 a^4/r^4 + 2 a^2/r^2) cos 2 theta,
a hoop-stress concentration of 4 at the wall (1 if the cavity were "filled" by the free field,
as when its wall was driven as an input boundary). The hoop stress is also held to the exact
dynamic answer, Pao & Mow's series (pyfem/analytic/scattering.py), of which Kirsch is the long-wave limit.
"""
import json
import math

import numpy as np
import pytest

from conftest import LOCAL_STEPPING_BALANCE
from pyfem import solver
from pyfem.distributed_model import model_in_memory
from pyfem.scene import SceneError, parse_scene

RADIUS = 5.0
SECTION = 120.0
THICKNESS = 2.0
CENTRE = np.array([SECTION / 2, THICKNESS / 2, SECTION / 2])
# Monitors: theta = 45 and 135 deg (largest hoop stress), at r = 1.05 a (first element row) and 2 a.
ANGLES = (45.0, 135.0)
RADII = (1.05, 2.0)
# Against Kirsch (quasi-static), about twice the measured at the four monitors (Q1, global and local
# stepping alike): the hoop stress's peak within 1.62 %, its history within 2.11 %, the radial and shear
# stress within 2.63 % of 4 tau (the wall's largest stress).
KIRSCH_PEAK_TOLERANCE = 0.035
KIRSCH_HISTORY_TOLERANCE = 0.045
KIRSCH_WALL_STRESS_TOLERANCE = 0.055
# History error against the exact answer, per order and monitor: measured (Q1, global / local stepping)
# 0.54 / 0.54, 2.95 / 2.96, 0.54 / 0.54, 1.06 / 1.07 % at 1.05 a 45 / 135 deg and 2 a 45 / 135 deg
# (the first element row's stress is the gradient of a bilinear field), (Q2) 0.82, 0.46, 0.80, 0.47 %,
# the Q2 error mostly the truncation faces' reflections (docs/wall_stress_accuracy.md). About twice
# the measured, the earlier 4 % (Q1) and 1.5 % (Q2) where that is less. Per monitor, since the FE
# error's sign differs between them: a wall stress scaled by 1.02 is caught at 1.05 a and 2 a, 45 deg.
EXACT_TOLERANCE = {1: {"r1.05_t45": 0.011, "r1.05_t135": 0.04, "r2_t45": 0.011, "r2_t135": 0.022},
                   2: {"r1.05_t45": 0.015, "r1.05_t135": 0.01, "r2_t45": 0.015, "r2_t135": 0.01}}
# With local time stepping (3 rate levels: the wall's cells and the truncation faces finest) every
# monitor meets the same tolerances. This linear model steps by the row split (every node at its own
# rate with its whole stiffness row, pyfem/local_stepping.py row_split): at safety 0.8 0.54 / 2.96 %
# at 1.05 a and 0.53 / 1.07 % at 2 a, where the finest level meets a coarser one (global stepping
# 0.54 / 2.95 / 0.54 / 1.06 %). The column split, which models with element-loop cells or contact
# pairs still use, was 8.7 % off at 2 a, 45 deg (docs/local_stepping.md "The scheme: the row split").


@pytest.fixture(scope="module")
def tunnel_meshes(tmp_path_factory):
    """The same tunnel meshed twice by the script, as a user runs it (its own process, so no gmsh
    option set by other tests leaks in): with named faces and wall, and with no surface named."""
    import subprocess
    import sys

    folder = tmp_path_factory.mktemp("tunnel")
    paths = {}
    for named in (True, False):
        path = folder / f"tunnel_{'named' if named else 'unnamed'}.msh"
        subprocess.run([sys.executable, "meshes/tunnel_in_box.py", str(path), "--radius", str(RADIUS)]
                       + ([] if named else ["--unnamed"]), check=True, timeout=300)
        paths[named] = path
    return paths


def monitor_points():
    points = {}
    for r in RADII:
        for theta in ANGLES:
            t = math.radians(theta)
            points[f"r{r:g}_t{theta:g}"] = (r, theta, CENTRE + RADIUS * r * np.array([math.cos(t), 0.0, math.sin(t)]))
    return points


def tunnel_scene(mesh_file, order=1, duration=1.6, extra_boundary=None):
    boundary = {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}}
    boundary.update(extra_boundary or {})
    return parse_scene({
        "title": "tunnel under long SV",
        "mesh": {"builder": "file", "file": str(mesh_file), "order": order},
        "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}},
        "time": {"duration": duration},
        "wave": {"type": "SV", "angle": 0.0, "motion": {"ricker": {"f0": 2.0, "amplitude": 1.0e-3}}},
        "boundary": boundary,
        "monitor": [{"name": name, "point": list(point)} for name, (_, _, point) in monitor_points().items()],
        "output": {"interval": 0.005, "xdmf_interval": 0.0},
    })


def polar_stress(row_stress, theta):
    """(sigma_rr, sigma_thth, sigma_rth) from [sxx, syy, szz, sxy, syz, sxz] in the x-z plane."""
    sxx, szz, sxz = row_stress[..., 0], row_stress[..., 2], row_stress[..., 5]
    c, s = math.cos(math.radians(theta)), math.sin(math.radians(theta))
    rr = sxx * c * c + szz * s * s + 2 * sxz * s * c
    tt = sxx * s * s + szz * c * c - 2 * sxz * s * c
    rt = (szz - sxx) * s * c + sxz * (c * c - s * s)
    return rr, tt, rt


def kirsch(r_over_a, theta):
    """Factors on tau of (sigma_rr, sigma_thth, sigma_rth)."""
    q2, q4 = r_over_a ** -2, r_over_a ** -4
    s2, c2 = math.sin(math.radians(2 * theta)), math.cos(math.radians(2 * theta))
    return (1 + 3 * q4 - 4 * q2) * s2, -(1 + 3 * q4) * s2, (1 - 3 * q4 + 2 * q2) * c2


def run_tunnel(tmp_path, mesh_file, order=1, local=False, safety=None):
    scene = tunnel_scene(mesh_file, order)
    # [time] local_stepping: the wall's 0.6 m cells at the finest rate, the far field coarser; or
    # global stepping (not "auto", which decides by the mesh and the duration)
    scene["time"]["local_stepping"] = bool(local)
    if safety is not None:
        scene["time"]["safety"] = safety
    out = tmp_path / f"run_q{order}{'_local' if local else ''}{'' if safety is None else f'_s{safety:g}'}"
    summary = solver.run(scene, out)
    return scene, out, summary


def read_monitor(out, name):
    with open(out / "monitors" / f"{name}.csv") as handle:
        header = handle.readline().strip().split(",")
    data = np.loadtxt(out / "monitors" / f"{name}.csv", delimiter=",", skiprows=1)
    return {key: data[:, k] for k, key in enumerate(header)}


def free_field_shear(scene, times, point=CENTRE):
    """tau(t) = sigma_xz of the free field at `point` (default the tunnel's centre) (Pa)."""
    from pyfem.operators import build_model
    from pyfem.seismic.setup import seismic_input_from_scene

    freefield, _ = seismic_input_from_scene(scene, build_model(scene))
    return freefield.stress(np.asarray(point)[None, :], times)[:, 0, 0, 2]


def exact_hoop(scene, times, r_over_a, theta):
    """Pao & Mow's sigma_thth(t) (Pa) at (r, theta) for the scene's incident wave (pyfem.analytic.scattering)."""
    from pyfem.operators import build_model
    from pyfem.analytic.scattering import CavitySV
    from pyfem.seismic.setup import seismic_input_from_scene

    freefield, _ = seismic_input_from_scene(scene, build_model(scene))
    return CavitySV(RADIUS, 8.0e9, 0.24, 2600.0).hoop_stress_from_free_field(freefield, CENTRE, times,
                                                                             RADIUS * r_over_a, math.radians(theta))


# Q2 is in the slow tier: its 34 880 steps of 2.9 ms (the 27-node cells' matrix, a step 4.6x smaller
# than Q1's) took 140-170 s of the default tier; the default tier keeps a dynamic cavity with quadratic
# elements in tests/test_tetrahedra.py (P2, the tunnel of meshes/tunnel_in_box_tet.geo).
@pytest.mark.parametrize("order, local, safety", [(1, False, None), pytest.param(2, False, None, marks=pytest.mark.slow),
                                                  (1, True, None)])
def test_cavity_wall_follows_kirsch(tmp_path, tunnel_meshes, order, local, safety):
    """The wall's stress against Kirsch and the exact answer; with local time stepping too (its roller
    faces held at every level, several rate levels active, the row split): everything to the same
    tolerances at the default safety 0.8 (and at 0.4: 0.54 / 2.95 / 0.54 / 1.06 %)."""
    scene, out, summary = run_tunnel(tmp_path, tunnel_meshes[True], order, local, safety)
    if local:
        levels = int(summary["dt_reason"].split("local time stepping: ")[1].split(" rate levels")[0])
        print(summary["dt_reason"])
        assert levels >= 3 and summary["local_stepping_stability"]["stable"]
        assert summary["dt_reason"].endswith("the row split")
        print(f"energy balance (local stepping's plain account) {summary['energy']['balance_error']:.2e}")
        # the plain account's O(dt^2) bound: catches a level's work booked wrong (e.g. the kicks' work)
        assert summary["energy"]["balance_error"] < LOCAL_STEPPING_BALANCE
    faces = {face["name"]: face for face in summary["boundary_faces"]}
    assert sorted(faces) == ["xmax", "xmin", "ymax", "ymin", "zmax", "zmin"], "the wall is no truncation face"
    assert faces["ymin"]["type"] == "roller" and not faces["ymin"]["input"]
    assert faces["xmin"]["input"] and faces["zmin"]["input"]
    assert "tunnel_wall" in summary["traction_free_surfaces"]

    first = read_monitor(out, "r1.05_t45")
    times = first["t"]
    tau = free_field_shear(scene, times)
    tau_peak = np.max(np.abs(tau))
    assert tau_peak > 1e3, "the wave arrived (free-field shear above 1 kPa)"
    checks = 0
    for name, (r, theta, point) in monitor_points().items():
        columns = read_monitor(out, name)
        # The history against the shear arriving at the monitor's own height: a vertical wave
        # reaches a point 7 m above the centre 6 ms later, 10 % of a 2 Hz wavelet's L2 norm.
        tau_here = free_field_shear(scene, times, point)
        stress = np.column_stack([columns[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")])
        rr, tt, rt = polar_stress(stress, theta)
        k_rr, k_tt, k_rt = kirsch(r, theta)
        # The Ricker's shear has two lobes of nearly equal size: compare magnitudes and the history.
        peak_ratio = np.max(np.abs(tt)) / (abs(k_tt) * tau_peak)
        history_error = np.linalg.norm(tt - k_tt * tau_here) / np.linalg.norm(k_tt * tau_here)
        exact = exact_hoop(scene, times, r, theta)
        exact_error = np.linalg.norm(tt - exact) / np.linalg.norm(exact)
        print(f"Q{order} {name}: hoop peak / Kirsch = {peak_ratio:.4f}, history error {history_error:.3%}, "
              f"concentration {np.max(np.abs(tt)) / tau_peak:.3f} (Kirsch {abs(k_tt):.3f}); against the exact "
              f"answer: history error {exact_error:.3%}, peak {np.max(np.abs(tt)) / np.max(np.abs(exact)):.4f}")
        # catches a stress concentration off by 2 % (a wall or monitor stress scaled, a wrong tau)
        assert abs(peak_ratio - 1.0) < KIRSCH_PEAK_TOLERANCE, name
        assert history_error < KIRSCH_HISTORY_TOLERANCE, name  # and its history off by as much
        assert exact_error < EXACT_TOLERANCE[order][name], name  # catches a wall stress off by 2 % (45 deg)
        # The wall is traction-free: radial and shear stress as Kirsch says (near 0 at the wall).
        scale = 4.0 * tau_peak
        print(f"    radial {np.max(np.abs(rr - k_rr * tau)) / scale:.4f}, shear "
              f"{np.max(np.abs(rt - k_rt * tau)) / scale:.4f} of 4 tau off Kirsch's")
        # catches a wall that carries traction (radial or shear stress of a few % of 4 tau)
        assert np.max(np.abs(rr - k_rr * tau)) < KIRSCH_WALL_STRESS_TOLERANCE * scale, name
        assert np.max(np.abs(rt - k_rt * tau)) < KIRSCH_WALL_STRESS_TOLERANCE * scale, name
        checks += 1
    assert checks == len(RADII) * len(ANGLES)


def test_unnamed_wall_and_faces_give_the_same_run(tmp_path, tunnel_meshes):
    """Without any named surface, the bounding-box planes are the truncation faces and the wall
    is free: the same histories as the named mesh, to round-off."""
    _, out_named, _ = run_tunnel(tmp_path / "named", tunnel_meshes[True])
    _, out_unnamed, summary = run_tunnel(tmp_path / "unnamed", tunnel_meshes[False])
    assert {face["source"] for face in summary["boundary_faces"]} == {"bounding-box plane"}
    assert summary["traction_free_surfaces"].get("(unnamed)", 0) > 0, "the wall's facets are free"
    name = "r1.05_t45"
    named, unnamed = read_monitor(out_named, name), read_monitor(out_unnamed, name)
    scale = np.max(np.abs(named["sxz"]))
    assert scale > 0.0
    for column in ("ux", "uz", "sxx", "szz", "sxz"):
        assert np.max(np.abs(named[column] - unnamed[column])) <= 1e-9 * max(np.max(np.abs(named[column])), 1e-300)


def test_wall_named_as_input_face_is_what_the_user_asked(tmp_path, tunnel_meshes):
    """boundary.faces decides: a user who lists the wall gets it, and with it the old behaviour
    (the wall driven by the free field: no stress concentration, the control that shows the test
    above can tell the difference); an unknown name or a table for a face that is not a
    truncation face is an error naming the faces."""
    from pyfem.operators import build_model

    scene = tunnel_scene(tunnel_meshes[True], extra_boundary={"faces": ["xmin", "xmax", "ymin", "ymax", "zmin",
                                                                          "zmax", "tunnel_wall"]})
    summary = solver.run(scene, tmp_path / "driven_wall")
    assert "tunnel_wall" in [face["name"] for face in summary["boundary_faces"]]
    columns = read_monitor(tmp_path / "driven_wall", "r1.05_t45")
    _, tt, _ = polar_stress(np.column_stack([columns[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")]), 45.0)
    tau = free_field_shear(scene, columns["t"])
    concentration = np.max(np.abs(tt)) / np.max(np.abs(tau))
    print(f"wall driven as an input face: hoop concentration {concentration:.3f} (free: Kirsch 3.47)")
    assert concentration < 1.5
    with pytest.raises(SceneError, match="boundary.faces.0"):
        build_model(tunnel_scene(tunnel_meshes[True], extra_boundary={"faces": ["nowhere"]}))
    with pytest.raises(SceneError, match="boundary.face.tunnel_wall"):
        build_model(tunnel_scene(tunnel_meshes[True], extra_boundary={"face": {"tunnel_wall": {"type": "fixed"}}}))


def test_wave_without_an_input_face_is_an_error(tunnel_meshes):
    """Every truncation face fixed, roller or free: nothing can carry the wave in."""
    scene = tunnel_scene(tunnel_meshes[True], extra_boundary={"type": "fixed"})
    with pytest.raises(SceneError, match="viscoelastic or viscous"):
        model_in_memory(scene, solve_stage=False)


def test_the_documented_tunnel_example_runs(tmp_path):
    """docs/boundaries.md's gmsh script and scene, as a user would copy them: the mesh has only a
    volume, the bounding-box planes become the truncation faces, the wall is free."""
    import re
    import subprocess
    import sys

    text = open("docs/boundaries.md").read()
    script = re.search(r"A tunnel in a box.*?```python\n(.*?)```", text, re.S).group(1)
    scene_text = re.search(r"and its scene.*?```toml\n(.*?)```", text, re.S).group(1)
    subprocess.run([sys.executable, "-c", script], cwd=tmp_path, check=True, timeout=300)
    (tmp_path / "tunnel.toml").write_text(scene_text)
    result = subprocess.run([sys.executable, "-m", "pyfem", "check", str(tmp_path / "tunnel.toml")],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    for name in ("xmin", "xmax", "zmin", "zmax"):
        assert any(line.strip().startswith(f"{name}:") and "viscoelastic" in line and "input" in line
                   and "bounding-box plane" in line for line in lines), name
    for name in ("ymin", "ymax"):
        assert any(line.strip().startswith(f"{name}:") and "roller" in line for line in lines), name
    assert any("traction-free surfaces:" in line and "(unnamed)" in line for line in lines)

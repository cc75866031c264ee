"""The lined tunnel's closed form (pyfem/analytic/lined_tunnel.py, docs/lined_tunnel.md), checked against
independent answers before the static stage is held to it (tests/test_static.py):
- each Airy term's displacement satisfies plane-strain Hooke's law with its stress (numerical
  derivatives), so bonding at r = b is imposed on true displacements;
- a lining of negligible stiffness leaves Kirsch's unlined solution in the rock (Brady & Brown);
- a lining installed after the whole release (lambda = 1) carries nothing;
- under a hydrostatic far field it is the thick ring of tests/test_static.py's closed form;
- the inner face is free and the traction is continuous across the bond;
- a shear far field sigma_xz is the biaxial one turned by 45 degrees;
- loaded by a far-field change with the lining in place (`loaded_stresses`), a lining of the rock's
  own constants is Kirsch's hole of the inner radius, and a concrete one is free inside and bonded;
- a dynamic run of the lined tunnel in place under a long SV wave follows that closed form.
"""
import math

import numpy as np
import pytest

from pyfem.analytic.lined_tunnel import LinedTunnel, _deviatoric_terms, _lame
from pyfem.analytic.scattering import LinedCavitySV

P, K = 10.0e6, 0.5
FAR = (-K * P, -P, 0.0)
TUNNEL = LinedTunnel(5.0, 0.5, 28.0e9, 0.167, 8.0e9, 0.24)
# The lined tunnel in place under a 2 Hz wave, two Q1 elements through the lining, against the exact
# dynamic answer (pyfem.analytic.scattering.LinedCavitySV): measured +0.25 / +0.24 % in the peak and 0.38 / 0.41 %
# over the history (lining / rock), where the quasi-static closed form is 1.2 % and 1.6-1.8 % away.
# Tighter than the quasi-static form's distance, so the series is what the test holds it to.
EXACT_PEAK_TOLERANCE, EXACT_HISTORY_TOLERANCE = 0.006, 0.008


def kirsch(r_over_a, theta):
    """(sigma_rr, sigma_tt), tension positive, far field sigma_zz = -P, sigma_xx = -K P."""
    q2, q4, c2 = r_over_a ** -2, r_over_a ** -4, np.cos(2 * theta)
    rr = 0.5 * P * ((1 + K) * (1 - q2) - (1 - K) * (1 - 4 * q2 + 3 * q4) * c2)
    tt = 0.5 * P * ((1 + K) * (1 + q2) + (1 - K) * (1 + 3 * q4) * c2)
    return -rr, -tt


@pytest.mark.parametrize("term", range(4))
def test_each_airy_terms_displacement_obeys_hookes_law(term):
    lam, mu, kappa = _lame(8.0e9, 0.24)
    coefficients = np.zeros(4)
    coefficients[term] = 1.0

    def fields(r, t):
        values = _deviatoric_terms(r, kappa) @ coefficients
        c, s = math.cos(2 * t), math.sin(2 * t)
        return values[0] * c, values[1] * s, values[2] * c, values[3] * c / (2 * mu), values[4] * s / (2 * mu)

    r, t, h = 3.7, 0.61, 1.0e-6
    srr, srt, stt, ur, ut = fields(r, t)
    dr = [(a - b) / (2 * h) for a, b in zip(fields(r + h, t), fields(r - h, t))]
    dt = [(a - b) / (2 * h) for a, b in zip(fields(r, t + h), fields(r, t - h))]
    e_rr, e_tt, g_rt = dr[3], (ur + dt[4]) / r, dt[3] / r + dr[4] - ut / r
    hooke = ((lam + 2 * mu) * e_rr + lam * e_tt, lam * e_rr + (lam + 2 * mu) * e_tt, mu * g_rt)
    scale = max(abs(srr), abs(stt), abs(srt))
    assert scale > 0
    assert max(abs(a - b) for a, b in zip(hooke, (srr, stt, srt))) < 1e-8 * scale


def test_a_lining_of_no_stiffness_leaves_kirsch():
    soft = LinedTunnel(5.0, 0.5, 1.0e-3, 0.2, 8.0e9, 0.24)
    for r_over_a in (1.0, 1.3, 2.0, 5.0):
        for theta in (0.0, 0.4, 1.2, math.pi / 2):
            s = soft.stresses(5.0 * r_over_a, theta, FAR, relaxation=0.3)
            rr, tt = kirsch(r_over_a, theta)
            assert s["rr"] == pytest.approx(rr, abs=1e-6 * P)
            assert s["tt"] == pytest.approx(tt, abs=1e-6 * P)


def test_a_lining_installed_after_the_whole_release_carries_nothing():
    for r in (4.5, 4.8, 4.99):
        s = TUNNEL.stresses(r, 0.3, FAR, relaxation=1.0)
        assert max(abs(s["rr"]), abs(s["tt"]), abs(s["rt"])) < 1e-6
    assert TUNNEL.hoop_stress(5.0, 0.0, FAR, 1.0) == pytest.approx(kirsch(1.0, 0.0)[1], rel=1e-12)
    assert TUNNEL.hoop_stress(4.7, 0.0, FAR, 0.0) < -1.0e6  # installed before: it carries the load


@pytest.mark.parametrize("relaxation", [0.3, 0.7])
def test_hydrostatic_far_field_is_the_thick_ring(relaxation):
    b, a_i = 5.0, 4.5
    G_r = 8.0e9 / (2 * 1.24)
    nu_l = 0.167
    C_l = (1 + nu_l) * ((1 - 2 * nu_l) * b * b + a_i * a_i) / (28.0e9 * (b * b - a_i * a_i))
    support = (1 - relaxation) * P / (1 + 2 * G_r * C_l)
    for r in (4.5, 4.75, 4.99):
        exact = -support * b * b / (b * b - a_i * a_i) * (1 + (a_i / r) ** 2)
        assert TUNNEL.hoop_stress(r, 0.2, (-P, -P, 0.0), relaxation) == pytest.approx(exact, rel=1e-10)


def test_free_inner_face_bonded_outer_face_and_a_bending_lining():
    for relaxation in (0.0, 0.5):
        for theta in (0.0, 0.7, 2.0):
            face = TUNNEL.stresses(4.5, theta, FAR, relaxation)
            assert abs(face["rr"]) < 1e-6 * P and abs(face["rt"]) < 1e-6 * P
            lining = TUNNEL.stresses(5.0 * (1 - 1e-12), theta, FAR, relaxation)
            rock = TUNNEL.stresses(5.0, theta, FAR, relaxation)
            assert lining["rr"] == pytest.approx(rock["rr"], abs=1e-6 * P)
            assert lining["rt"] == pytest.approx(rock["rt"], abs=1e-6 * P)
    # K = 0.5 bends the ring: the inner face's hoop stress varies around it by more than 3x.
    inner = TUNNEL.hoop_stress(np.full(73, 4.5), np.linspace(0, math.pi, 73), FAR, 0.5)
    assert inner.min() < 3 * inner.max() < 0.0


def test_a_shear_far_field_is_the_biaxial_one_turned():
    turned = TUNNEL.stresses(4.6, 0.3 + math.pi / 4, (0.0, 0.0, 1.0e6), 0.4)
    biaxial = TUNNEL.stresses(4.6, 0.3, (1.0e6, -1.0e6, 0.0), 0.4)
    for key in ("rr", "tt", "rt"):
        assert turned[key] == pytest.approx(biaxial[key], rel=1e-12)
    assert abs(biaxial["tt"]) > 1e5


def test_bad_geometry_is_refused():
    with pytest.raises(ValueError, match="thickness"):
        LinedTunnel(5.0, 5.0, 28.0e9, 0.167, 8.0e9, 0.24)
    with pytest.raises(ValueError, match="relaxation"):
        TUNNEL.stresses(4.7, 0.0, FAR, relaxation=1.5)


# ------------------------------------------------------------------ a far field applied to the lined tunnel

def test_a_lining_of_the_rocks_own_stiffness_loaded_is_kirsch_at_the_inner_radius():
    """With the lining's constants equal to the rock's, the lined tunnel loaded by a far-field change is
    an unlined hole of the inner radius: Kirsch at r / a, through the lining and the rock (the bond
    then joins one material, so displacement continuity must carry the far field's own strain)."""
    same = LinedTunnel(5.0, 0.5, 8.0e9, 0.24, 8.0e9, 0.24)
    a = same.inner_radius
    r = np.array([a, 4.7, 4.99, 5.0, 5.5, 8.0, 20.0])
    theta = np.radians([0.0, 30.0, 45.0, 90.0, 120.0, 200.0, 310.0])
    out = same.loaded_stresses(r[:, None], theta[None, :], FAR)
    rr, tt = kirsch(r[:, None] / a, theta[None, :])
    assert np.allclose(out["rr"], rr, rtol=0, atol=1e-9 * P)
    assert np.allclose(out["tt"], tt, rtol=0, atol=1e-9 * P)
    tau = 1.0e6  # a far-field shear sigma_xz: the long SV wave's
    shear = same.loaded_stresses(r[:, None], theta[None, :], (0.0, 0.0, tau))
    assert np.allclose(shear["tt"], -tau * (1.0 + 3.0 * (a / r[:, None]) ** 4) * np.sin(2 * theta[None, :]),
                       rtol=0, atol=1e-9 * tau)


def test_a_loaded_stiff_lining_is_free_inside_bonded_outside_and_attracts_the_load():
    """The concrete lining (28 GPa in 8 GPa rock) under a far-field shear: its inner face is free, the
    traction is continuous at the bond, and the hoop stress at its inner face exceeds the unlined
    hole's 4 tau (Kirsch): a ring stiffer than the rock attracts the load (Wang's no-slip case). The
    rock far away carries the far field."""
    tau = 1.0e6
    far = (0.0, 0.0, tau)
    a, b = TUNNEL.inner_radius, TUNNEL.radius
    theta = np.radians(np.arange(0.0, 360.0, 15.0))
    inner = TUNNEL.loaded_stresses(a, theta, far)
    assert np.abs(inner["rr"]).max() < 1e-9 * tau and np.abs(inner["rt"]).max() < 1e-9 * tau
    lining_b = TUNNEL.loaded_stresses(b * (1 - 1e-12), theta, far)
    rock_b = TUNNEL.loaded_stresses(b, theta, far)
    assert np.allclose(lining_b["rr"], rock_b["rr"], atol=1e-6 * tau)
    assert np.allclose(lining_b["rt"], rock_b["rt"], atol=1e-6 * tau)
    hoop = TUNNEL.loaded_stresses(a, math.radians(45.0), far)["tt"]
    assert -hoop > 4.0 * tau
    far_away = TUNNEL.loaded_stresses(1.0e4, math.radians(45.0), far)
    assert far_away["rt"] == pytest.approx(0.0, abs=1e-6 * tau)  # along 45 deg the shear is principal
    assert far_away["rr"] == pytest.approx(tau, rel=1e-6)


def test_a_long_wave_loads_the_lining_in_place_as_the_closed_form(tmp_path):
    """The dynamic path end to end for a lined opening: the lining in place (no static stage,
    meshes/tunnel_in_box.py --lining 0.5 --hollow), two Q1 elements through it, a 2 Hz vertical SV
    wavelet through the viscoelastic faces. The hoop stress at 45 deg, 1 cm inside the lining's free
    face and 1 cm into the rock behind the bond, follows the closed form loaded by the free field's
    shear tau(t): the peak within 3 % (the quasi-static answer is itself ~1.5 % off the dynamic peak
    at 2 Hz for the unlined opening, docs/wall_stress_accuracy.md; workflows/lined_wall_dynamic.py
    measures 0.7 % at 1 Hz; measured here 1.2 %), and the concrete takes about five times the rock's hoop
    stress. Against the exact dynamic answer (the lined tunnel's series) the peak and the history are
    within 0.25 % and 0.4 %."""
    import subprocess
    import sys
    from pathlib import Path

    from pyfem import solver
    from pyfem.operators import build_model
    from pyfem.scene import parse_scene
    from pyfem.seismic.setup import seismic_input_from_scene

    repo = Path(__file__).resolve().parents[1]
    b, t, section = 5.0, 0.5, 120.0
    mesh = tmp_path / "lined.msh"
    subprocess.run([sys.executable, str(repo / "meshes" / "tunnel_in_box.py"), str(mesh), "--radius", str(b),
                    "--size", str(section), "--lining", str(t), "--hollow", "--h-wall", str(t / 2)],
                   check=True, timeout=300)
    centre = np.array([section / 2, 1.0, section / 2])
    radii = {"lining": b - t + 0.01, "rock": b + 0.01}
    c45 = math.cos(math.radians(45.0))

    def at(radius):
        return (centre + radius * np.array([c45, 0.0, c45])).tolist()

    scene = parse_scene({
        "title": "lined tunnel under a long SV wave",
        "mesh": {"builder": "file", "file": str(mesh), "order": 1},
        "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0},
                      "lining": {"E": 28.0e9, "nu": 0.167, "rho": 2500.0}},
        "time": {"duration": 1.6},
        "wave": {"type": "SV", "angle": 0.0, "medium": "rock", "motion": {"ricker": {"f0": 2.0, "amplitude": 1.0e-3}}},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "monitor": [{"name": name, "point": at(radius)} for name, radius in radii.items()],
        "output": {"interval": 0.0025, "xdmf_interval": 0.0},
    }, source="test")
    out = tmp_path / "run"
    solver.run(scene, out)
    freefield = seismic_input_from_scene(scene, build_model(scene))[0]
    tunnel = LinedTunnel(b, t, 28.0e9, 0.167, 8.0e9, 0.24)
    peaks = {}
    for name, radius in radii.items():
        data = np.genfromtxt(out / "monitors" / f"{name}.csv", delimiter=",", names=True)
        hoop = 0.5 * (data["sxx"] + data["szz"]) - data["sxz"]  # sigma_thth at 45 deg
        tau = freefield.stress(np.array([at(radius)]), data["t"])[:, 0, 0, 2]
        factor = float(tunnel.loaded_stresses(radius, math.radians(45.0), (0.0, 0.0, 1.0))["tt"])
        exact = factor * tau
        assert np.abs(exact).max() > 1.0e4, "the wave arrived"
        peaks[name] = np.abs(hoop).max()
        print(f"{name}: peak {peaks[name] / 1e6:.4f} MPa, closed form {np.abs(exact).max() / 1e6:.4f} MPa, "
              f"history error {np.linalg.norm(hoop - exact) / np.linalg.norm(exact):.4f}")
        assert peaks[name] == pytest.approx(np.abs(exact).max(), rel=0.03), name
        assert np.linalg.norm(hoop - exact) < 0.05 * np.linalg.norm(exact), name  # measured 1.6-1.8 %
        # The exact dynamic answer (the lined tunnel's series): the mesh's error alone.
        series = LinedCavitySV(b, t, 28.0e9, 0.167, 2500.0, 8.0e9, 0.24, 2600.0)
        dynamic = series.hoop_stress_from_free_field(freefield, centre, data["t"], radius, math.radians(45.0))
        peak_error = peaks[name] / np.abs(dynamic).max() - 1.0
        history_error = np.linalg.norm(hoop - dynamic) / np.linalg.norm(dynamic)
        print(f"{name}: exact peak {np.abs(dynamic).max() / 1e6:.4f} MPa ({peak_error:+.2%}), "
              f"history error {history_error:.4f}")
        assert abs(peak_error) < EXACT_PEAK_TOLERANCE and history_error < EXACT_HISTORY_TOLERANCE, name
    assert 4.0 < peaks["lining"] / peaks["rock"] < 6.0

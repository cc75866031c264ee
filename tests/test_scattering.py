"""Pao & Mow's series for SV scattered by a circular cavity (pyfem/analytic/scattering.py): the wall is
free, a long wave gives Kirsch's static concentration everywhere around the opening, and the
time synthesis is causal and quasi-static for a long wavelet. The lined tunnel's series
(LinedCavitySV): a lining of the rock's constants is the unlined cavity of the inner radius, a long
wave gives the quasi-static closed form of pyfem/analytic/lined_tunnel.py, the bond is continuous and the
inner face free at every frequency."""
import math

import numpy as np
import pytest

from pyfem.analytic.lined_tunnel import LinedTunnel
from pyfem.analytic.scattering import CavitySV, LinedCavitySV

A, E, NU, RHO = 5.0, 8.0e9, 0.24, 2600.0
THETAS = np.radians([0.0, 20.0, 45.0, 70.0, 90.0, 135.0, 200.0, 300.0])


def kirsch(r, theta):
    """Kirsch's stresses / tau for a far-field shear tau = sigma_xz (the incident wave's shear
    at the centre), in the series' polar coordinates."""
    q = (A / r) ** 2
    return {"rr": (1.0 - 4.0 * q + 3.0 * q * q) * np.sin(2 * theta),
            "thth": -(1.0 + 3.0 * q * q) * np.sin(2 * theta),
            "rth": (1.0 + 2.0 * q - 3.0 * q * q) * np.cos(2 * theta)}


@pytest.mark.parametrize("f", [0.5, 2.0, 8.0, 20.0, 40.0])
def test_the_cavity_wall_is_free_at_every_frequency(f):
    cavity = CavitySV(A, E, NU, RHO)
    omega = 2 * math.pi * f
    stresses = cavity.stresses(omega, A, THETAS)
    tau = abs(cavity.free_field_shear(omega))
    assert np.abs(stresses["thth"]).max() > 2.0 * tau, "the wall carries the concentrated hoop stress"
    assert np.abs(stresses["rr"]).max() < 1e-9 * tau
    assert np.abs(stresses["rth"]).max() < 1e-9 * tau


@pytest.mark.parametrize("r_over_a", [1.0, 1.02, 1.5, 3.0])
def test_a_long_wave_gives_kirsch_around_the_opening(r_over_a):
    cavity = CavitySV(A, E, NU, RHO)
    omega = 2 * math.pi * 0.02
    ka = omega / cavity.cs * A  # 5.6e-4
    stresses = cavity.stresses(omega, A * r_over_a, THETAS)
    tau = cavity.free_field_shear(omega)
    expected = kirsch(A * r_over_a, THETAS)
    for key in ("rr", "thth", "rth"):
        ratio = stresses[key] / tau
        assert np.allclose(ratio.real, expected[key], atol=1e-4), key
        # The wave reaches the points of the opening at different times: a phase of order k_s r.
        assert np.abs(ratio.imag).max() < 10.0 * ka * r_over_a, key


def test_a_shorter_wave_concentrates_more_than_kirsch_at_45_degrees():
    # k_s a = 0.28: the dynamic concentration at the wall exceeds the static 4 (Pao & Mow's SV
    # curves peak near there); the series carries a phase the static answer has not.
    cavity = CavitySV(A, E, NU, RHO)
    omega = 2 * math.pi * 10.0
    ratio = cavity.stresses(omega, A, math.radians(45.0))["thth"][0] / cavity.free_field_shear(omega)
    assert 4.2 < abs(ratio) < 4.6
    assert abs(ratio.imag) > 0.1 * abs(ratio.real)


def ricker(t, f0, t0):
    x = (math.pi * f0 * (t - t0)) ** 2
    return (1.0 - 2.0 * x) * np.exp(-x)


def test_the_history_is_causal_and_quasi_static_for_a_long_wavelet():
    cavity = CavitySV(A, E, NU, RHO)
    dt, f0, t0 = 0.004, 0.25, 6.0
    t = np.arange(0.0, 14.0, dt)
    u = 1e-3 * ricker(t, f0, t0)
    hoop = cavity.hoop_stress_history(t, u, A, math.radians(45.0))
    # tau(t) of the incident wave at the centre: mu du/dz = -mu / c_s du/dt (u(t - z / c_s)).
    tau = -cavity.mu / cavity.cs * np.gradient(u, dt)
    peak = np.abs(hoop).max()
    assert peak > 3.9 * np.abs(tau).max(), "the wave arrived and concentrated at the wall"
    assert np.abs(hoop - (-4.0) * tau).max() < 0.01 * peak
    # The wavelet is below 1e-7 of its peak before 0.3 s: the wall's stress stays at the
    # synthesis' floor (1e-6 of the peak: the spectrum's cut at 1e-12, the padding's wrap).
    early = t < 0.3
    assert np.abs(u[early]).max() < 1e-7 * np.abs(u).max()
    assert np.abs(hoop[early]).max() < 1e-5 * peak


def kirsch_racking(r):
    """u1(r, 90 deg) - u1(r, 270 deg) / gamma for a far-field shear strain gamma = du1/dx2 with its
    rotation (the incident wave's), from Kirsch's displacement field (plane strain)."""
    kappa = 3.0 - 4.0 * NU
    return 2.0 * r + A * A * (kappa - 1.0) / r + A ** 4 / r ** 3


@pytest.mark.parametrize("r_over_a", [1.0, 1.02, 1.5, 3.0])
def test_a_long_wave_racks_the_opening_as_kirsch_displacements(r_over_a):
    """The crown's motion relative to the invert's: gamma a (kappa + 2) at the wall, twice the free
    field's 2 gamma a for nu = 0.25 (Wang's unlined ratio 4 (1 - nu) is the same field's ovaling)."""
    cavity = CavitySV(A, E, NU, RHO)
    omega = 2 * math.pi * 0.02
    ks = omega / cavity.cs
    gamma = 1j * ks  # du1/dx2 of U exp(i k_s x2) at the centre, U = 1 m
    ratio = cavity.racking(omega, A * r_over_a) / gamma
    assert abs(ratio.real / kirsch_racking(A * r_over_a) - 1.0) < 1e-5
    assert abs(ratio.imag) < 10.0 * ks * A * r_over_a * abs(ratio)
    if r_over_a == 1.0:  # the cavity racks more than the ground it replaces
        assert ratio.real / (2.0 * A) == pytest.approx((5.0 - 4.0 * NU) / 2.0, rel=1e-5)


@pytest.mark.parametrize("f", [2.0, 8.0, 20.0])
def test_the_displacements_strain_to_the_series_stresses(f):
    """The displacement series, differentiated numerically in r and theta and put through plane-strain
    Hooke, gives the stress series (an independent path through the same coefficients)."""
    cavity = CavitySV(A, E, NU, RHO)
    omega = 2 * math.pi * f
    r, thetas, h = 1.5 * A, np.radians([10.0, 45.0, 100.0, 250.0]), 1e-4

    def u(radius, theta):
        fields = cavity.fields(omega, radius, theta)
        return fields["ur"], fields["uth"]

    ur, ut = u(r, thetas)
    ur_r = (u(r + h * A, thetas)[0] - u(r - h * A, thetas)[0]) / (2 * h * A)
    ut_r = (u(r + h * A, thetas)[1] - u(r - h * A, thetas)[1]) / (2 * h * A)
    ur_t = (u(r, thetas + h)[0] - u(r, thetas - h)[0]) / (2 * h)
    ut_t = (u(r, thetas + h)[1] - u(r, thetas - h)[1]) / (2 * h)
    e_rr, e_tt, g_rt = ur_r, (ur + ut_t) / r, ur_t / r + ut_r - ut / r
    trace = cavity.lam * (e_rr + e_tt)
    stresses = cavity.stresses(omega, r, thetas)
    tau = abs(cavity.free_field_shear(omega))
    assert np.abs(stresses["thth"]).max() > tau
    for key, strained in (("rr", trace + 2 * cavity.mu * e_rr), ("thth", trace + 2 * cavity.mu * e_tt),
                          ("rth", cavity.mu * g_rt)):
        assert np.abs(strained - stresses[key]).max() < 1e-6 * tau, key


def test_the_racking_history_is_quasi_static_for_a_long_wavelet():
    cavity = CavitySV(A, E, NU, RHO)
    dt, f0, t0 = 0.004, 0.25, 6.0
    t = np.arange(0.0, 14.0, dt)
    u = 1e-3 * ricker(t, f0, t0)
    racking = cavity.racking_history(t, u, A)
    gamma = -1.0 / cavity.cs * np.gradient(u, dt)  # du/dz of u(t - z / c_s) at the centre
    expected = kirsch_racking(A) * gamma
    peak = np.abs(racking).max()
    assert peak > 0.9 * np.abs(expected).max(), "the wave arrived and racked the opening"
    assert np.abs(racking - expected).max() < 0.01 * peak


LINING_T, LINING_E, LINING_NU, LINING_RHO = 0.5, 28.0e9, 0.167, 2500.0


@pytest.mark.parametrize("f", [0.5, 4.0, 20.0])
def test_a_lining_of_rock_is_the_cavity_of_its_inner_radius(f):
    """The lined series with the lining's constants those of the rock: the unlined series of radius
    b - t, in the lining and in the rock (every term of both solutions, the Neumann terms included)."""
    lined = LinedCavitySV(A, LINING_T, E, NU, RHO, E, NU, RHO)
    cavity = CavitySV(A - LINING_T, E, NU, RHO)
    omega = 2 * math.pi * f
    tau = abs(cavity.free_field_shear(omega))
    u_scale = tau / cavity.mu * A
    for r in (A - LINING_T, A - 0.2, A, 1.2 * A, 2.0 * A):
        got, expected = lined.fields(omega, r, THETAS), cavity.fields(omega, r, THETAS)
        assert np.abs(expected["thth"]).max() > 0.5 * tau
        for key in ("rr", "thth", "rth"):
            assert np.abs(got[key] - expected[key]).max() < 1e-8 * tau, (r, key)
        for key in ("ur", "uth"):
            assert np.abs(got[key] - expected[key]).max() < 1e-8 * u_scale, (r, key)


@pytest.mark.parametrize("r", [A - LINING_T, A - 0.25, A - 1e-9, A, 1.2 * A, 2.0 * A])
def test_a_long_wave_loads_the_lined_tunnel_as_the_quasi_static_closed_form(r):
    """k_s b = 2.8e-4: the series' stresses in the concrete lining and the rock equal the closed form of
    the lined tunnel under a far-field shear tau (LinedTunnel.loaded_stresses) to 1e-5 of the peak,
    the lining carrying 5-9 tau; the phase is of order k_s r."""
    lined = LinedCavitySV(A, LINING_T, LINING_E, LINING_NU, LINING_RHO, E, NU, RHO)
    closed = LinedTunnel(A, LINING_T, LINING_E, LINING_NU, E, NU)
    omega = 2 * math.pi * 0.01
    tau = lined.free_field_shear(omega)
    series = lined.fields(omega, r, THETAS)
    quasi_static = closed.loaded_stresses(np.full(len(THETAS), r), THETAS, (0.0, 0.0, 1.0))
    peak = np.abs(closed.loaded_stresses(np.full(len(THETAS), A - LINING_T), THETAS, (0.0, 0.0, 1.0))["tt"]).max()
    assert peak > 5.0
    for key, closed_key in (("rr", "rr"), ("thth", "tt"), ("rth", "rt")):
        ratio = series[key] / tau
        assert np.abs(ratio.imag).max() < 1e-3 * peak
        assert np.abs(ratio.real - quasi_static[closed_key]).max() < 1e-5 * peak, key


@pytest.mark.parametrize("f", [1.0, 4.0, 16.0])
def test_the_lining_is_bonded_and_its_inner_face_free(f):
    """Traction and displacement continuous across the bond r = b (the lining's side just inside), the
    inner face r = a traction-free; the lining concentrates the shear (its hoop stress above 2 tau)."""
    lined = LinedCavitySV(A, LINING_T, LINING_E, LINING_NU, LINING_RHO, E, NU, RHO)
    omega = 2 * math.pi * f
    tau = abs(lined.free_field_shear(omega))
    u_scale = tau / lined.mu * A
    inside, outside = lined.fields(omega, A * (1 - 1e-13), THETAS), lined.fields(omega, A, THETAS)
    for key in ("rr", "rth"):
        assert np.abs(inside[key] - outside[key]).max() < 1e-8 * tau, key
    for key in ("ur", "uth"):
        assert np.abs(inside[key] - outside[key]).max() < 1e-8 * u_scale, key
    face = lined.fields(omega, A - LINING_T, THETAS)
    assert np.abs(face["thth"]).max() > 2.0 * tau
    assert np.abs(face["rr"]).max() < 1e-8 * tau and np.abs(face["rth"]).max() < 1e-8 * tau

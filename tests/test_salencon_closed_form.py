"""The Salencon (1969) closed form of pyfem/analytic/salencon.py against itself and the issue's reference numbers.

FLAC's verification data: P0 = 30 MPa, G = 2.8 GPa, K = 3.9 GPa, c = 3.45 MPa, phi = 30 deg, a = 1 m,
unsupported wall: R0 = 1.735 a, sigma_theta(a) = 11.95 MPa, sigma_theta(R0) = 47.99 MPa, wall
convergence 12.17 mm (psi = 0) and 28.10 mm (psi = 30 deg). Compression positive, u_r inward.
"""
import numpy as np
import pytest

from pyfem.analytic.salencon import salencon

A = 1.0
P0 = 30.0e6
G = 2.8e9
K = 3.9e9
COHESION = 3.45e6
PHI = 30.0
REFERENCE = 1e-3  # the 0.1 %, on the printed digits


def solution(r, psi=0.0, cohesion=COHESION):
    return salencon(r, A, P0, G, K, cohesion, PHI, psi)


def test_reference_numbers():
    wall = solution([A], psi=0.0)
    R0 = wall["R0"]
    at_R0 = solution([R0])
    dilatant = solution([A], psi=30.0)
    print(f"R0 = {R0 / A:.4f} a, sigma_theta(a) = {wall['sigma_theta'][0] / 1e6:.4f} MPa, "
          f"sigma_theta(R0) = {at_R0['sigma_theta'][0] / 1e6:.4f} MPa, u_r(a) = {wall['u_r'][0] * 1e3:.4f} mm "
          f"(psi 0), {dilatant['u_r'][0] * 1e3:.4f} mm (psi 30); nu = {wall['nu']:.4f}")
    assert R0 / A == pytest.approx(1.735, rel=REFERENCE)
    assert wall["sigma_theta"][0] == pytest.approx(11.95e6, rel=REFERENCE)
    assert at_R0["sigma_theta"][0] == pytest.approx(47.99e6, rel=REFERENCE)
    assert wall["u_r"][0] == pytest.approx(12.17e-3, rel=REFERENCE)
    assert dilatant["u_r"][0] == pytest.approx(28.10e-3, rel=REFERENCE)
    assert wall["sigma_r"][0] == pytest.approx(0.0, abs=1e-9 * P0)
    assert dilatant["R0"] == R0, "the plastic radius does not depend on the dilation"


@pytest.mark.parametrize("psi", [0.0, 15.0, 30.0])
def test_continuity_at_the_plastic_radius(psi):
    R0 = solution([A], psi)["R0"]
    eps = 1e-10
    below, above = solution([R0 * (1 - eps)], psi), solution([R0 * (1 + eps)], psi)
    assert below["in_plastic_zone"][0] and not above["in_plastic_zone"][0]
    for key, scale in (("sigma_r", P0), ("sigma_theta", P0), ("u_r", below["u_r"][0])):
        assert abs(below[key][0] - above[key][0]) < 1e-8 * scale, key
    assert above["sigma_r"][0] == pytest.approx(above["sigma_R0"], rel=1e-8)


def test_yield_condition():
    """sigma_theta = N_phi sigma_r + sigma_c in the plastic zone, below it in the elastic zone."""
    s = solution(np.linspace(A, 5 * A, 401))
    f = s["sigma_theta"] - s["N_phi"] * s["sigma_r"] - s["sigma_c"]
    inside = s["in_plastic_zone"]
    assert inside.sum() > 50 and (~inside).sum() > 50
    assert np.max(np.abs(f[inside])) < 1e-10 * P0
    assert np.all(f[~inside] < 0.0)


@pytest.mark.parametrize("psi", [0.0, 30.0])
def test_equilibrium_and_flow_rule_by_finite_differences(psi):
    """d sigma_r/dr + (sigma_r - sigma_theta)/r = 0 in both zones; the strains of u_r (eps_r = du/dr,
    eps_theta = u/r, compression positive) less the elastic strains of the stress change obey the
    flow rule eps_r^p + N_psi eps_theta^p = 0 in the plastic zone, are zero in the elastic zone, and the
    hoop plastic strain grows towards the wall (a contraction, positive)."""
    R0 = solution([A], psi)["R0"]
    radii = np.concatenate([np.linspace(1.01 * A, 0.99 * R0, 9), np.linspace(1.01 * R0, 4 * R0, 9)])
    h = 1e-6 * radii
    mid, plus, minus = solution(radii, psi), solution(radii + h, psi), solution(radii - h, psi)
    inside = mid["in_plastic_zone"]
    assert inside.sum() == 9 and plus["in_plastic_zone"].sum() == 9 and minus["in_plastic_zone"].sum() == 9

    residual = (plus["sigma_r"] - minus["sigma_r"]) / (2 * h) + (mid["sigma_r"] - mid["sigma_theta"]) / radii
    assert np.max(np.abs(residual * radii)) < 1e-6 * P0

    nu, N_psi = mid["nu"], mid["N_psi"]
    eps_r = (plus["u_r"] - minus["u_r"]) / (2 * h)
    eps_t = mid["u_r"] / radii
    d_r, d_t = mid["sigma_r"] - P0, mid["sigma_theta"] - P0
    plastic_r = eps_r - ((1 - nu) * d_r - nu * d_t) / (2 * G)
    plastic_t = eps_t - ((1 - nu) * d_t - nu * d_r) / (2 * G)
    scale = np.max(np.abs(eps_t))
    assert np.max(np.abs(plastic_r[inside] + N_psi * plastic_t[inside])) < 1e-6 * scale
    assert np.max(np.abs(plastic_r[~inside])) < 1e-6 * scale
    assert np.max(np.abs(plastic_t[~inside])) < 1e-6 * scale
    assert np.all(np.diff(plastic_t[inside]) < 0) and plastic_t[inside][-1] > 0


def test_no_plastic_zone_is_lame():
    """A cohesion so large that nothing yields (2 P0 < sigma_c): Lame's cavity, u_r = P0 a^2/(2 G r)."""
    r = np.linspace(A, 10 * A, 50)
    for psi in (0.0, 30.0):
        s = solution(r, psi, cohesion=20.0e6)
        assert not s["plastic"] and s["R0"] == A and not s["in_plastic_zone"].any()
        assert s["u_r"][0] == pytest.approx(P0 * A / (2 * G), rel=1e-12)
        assert np.allclose(s["u_r"], P0 * A * A / (2 * G * r), rtol=1e-12)
        assert np.allclose(s["sigma_r"], P0 * (1 - (A / r) ** 2), rtol=1e-12, atol=1e-9 * P0)
        assert np.allclose(s["sigma_theta"], P0 * (1 + (A / r) ** 2), rtol=1e-12)

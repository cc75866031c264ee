"""Free-surface reflection coefficients: textbook values, energy flux, critical angle, bad input."""
import numpy as np
import pytest

from conftest import ROUNDOFF
from pyfem.seismic.reflection import critical_angle, free_surface_coefficients, reflected_angles

# Sandstone of the paper: E 8 GPa, nu 0.24, rho 2600 kg/m^3.
MU = 8.0e9 / (2.0 * 1.24)
LAM = 8.0e9 * 0.24 / (1.24 * 0.52)
C_P = np.sqrt((LAM + 2.0 * MU) / 2600.0)
C_S = np.sqrt(MU / 2600.0)
ANGLES = [0.0, 10.0, 20.0, 30.0, 45.0, 60.0, 80.0]


def aki_richards_free_surface(p, c_p, c_s):
    """Aki & Richards (2002) eq. 5.27: P-SV free-surface coefficients, real angles only."""
    cos_i = np.sqrt(1.0 - (p * c_p) ** 2)
    cos_j = np.sqrt(1.0 - (p * c_s) ** 2)
    a = (1.0 / c_s**2 - 2.0 * p**2) ** 2
    b = 4.0 * p**2 * (cos_i / c_p) * (cos_j / c_s)
    denominator = a + b
    return {"PP": (-a + b) / denominator,
            "PS": 4.0 * (c_p / c_s) * p * (cos_i / c_p) * (1.0 / c_s**2 - 2.0 * p**2) / denominator,
            "SP": 4.0 * (c_s / c_p) * p * (cos_j / c_s) * (1.0 / c_s**2 - 2.0 * p**2) / denominator}


@pytest.mark.parametrize("angle", ANGLES)
def test_p_incidence_matches_textbook_and_conserves_energy(angle):
    r = free_surface_coefficients("P", angle, C_P, C_S)
    p = np.sin(np.radians(angle)) / C_P
    reference = aki_richards_free_surface(p, C_P, C_S)
    assert abs(r["PP"] - reference["PP"]) < ROUNDOFF
    # The SV polarisation sign is a convention: compare magnitudes.
    assert abs(abs(r["PS"]) - abs(reference["PS"])) < ROUNDOFF
    cos_p = np.cos(np.radians(angle))
    cos_s = np.sqrt(1.0 - (p * C_S) ** 2)
    # Vertical energy flux 1/2 rho w^2 A^2 c cos(th) per wave; same rho above and below.
    flux = abs(r["PP"]) ** 2 + (C_S * cos_s) / (C_P * cos_p) * abs(r["PS"]) ** 2
    assert abs(flux - 1.0) < ROUNDOFF


@pytest.mark.parametrize("angle", [a for a in ANGLES if a < critical_angle(C_P, C_S)])
def test_sv_pre_critical_matches_textbook_and_conserves_energy(angle):
    r = free_surface_coefficients("SV", angle, C_P, C_S)
    p = np.sin(np.radians(angle)) / C_S
    reference = aki_richards_free_surface(p, C_P, C_S)
    assert abs(r["SS"].imag) == 0.0 and abs(r["SP"].imag) == 0.0
    assert abs(abs(r["SS"]) - abs(reference["PP"])) < ROUNDOFF  # |S'S'| = |P'P'| at equal p
    assert abs(abs(r["SP"]) - abs(reference["SP"])) < ROUNDOFF
    cos_s = np.cos(np.radians(angle))
    cos_p = np.sqrt(1.0 - (p * C_P) ** 2)
    flux = abs(r["SS"]) ** 2 + (C_P * cos_p) / (C_S * cos_s) * abs(r["SP"]) ** 2
    assert abs(flux - 1.0) < ROUNDOFF


@pytest.mark.parametrize("angle", [a for a in ANGLES if a > critical_angle(C_P, C_S)])
def test_sv_post_critical_reflects_all_energy(angle):
    r = free_surface_coefficients("SV", angle, C_P, C_S)
    # The evanescent P carries no energy downward: all of it returns as SV.
    assert abs(abs(r["SS"]) - 1.0) < ROUNDOFF
    assert abs(r["SS"].imag) > 1e-3 or angle in (45.0, 90.0)


def test_vertical_and_sh_coefficients():
    assert free_surface_coefficients("P", 0.0, C_P, C_S) == pytest.approx({"PP": -1.0, "PS": 0.0}, abs=ROUNDOFF)
    # Our SV convention: +x at vertical incidence both up and down, so R_SS = +1 (doubling).
    assert free_surface_coefficients("SV", 0.0, C_P, C_S) == pytest.approx({"SS": 1.0, "SP": 0.0}, abs=ROUNDOFF)
    for angle in ANGLES:
        assert free_surface_coefficients("SH", angle, C_P, C_S) == {"HH": 1.0}


def test_critical_angle_is_finite_and_continuous():
    critical = critical_angle(C_P, C_S)
    assert critical == pytest.approx(np.degrees(np.arcsin(C_S / C_P)), rel=ROUNDOFF)
    at = free_surface_coefficients("SV", critical, C_P, C_S)
    assert all(np.isfinite(v) for v in at.values())
    for offset in (-1e-9, 1e-9):
        near = free_surface_coefficients("SV", critical + offset, C_P, C_S)
        # sqrt(1/c_p^2 - s^2) varies like sqrt(offset): continuity to ~sqrt(1e-9)
        assert abs(near["SS"] - at["SS"]) < 1e-3 and abs(near["SP"] - at["SP"]) < 1e-3
    # With nu = 1/3 (c_p = 2 c_s) the critical values are R_SS = 1, R_SP = sqrt(3) (grazing P).
    exact = free_surface_coefficients("SV", 30.0, 2.0, 1.0)
    assert abs(exact["SS"] - 1.0) < 1e-6 and abs(abs(exact["SP"]) - np.sqrt(3.0)) < 1e-6


def test_reflected_angles_follow_snell():
    angles = reflected_angles("P", 30.0, C_P, C_S)
    assert np.sin(np.radians(angles["S"])) / C_S == pytest.approx(np.sin(np.radians(30.0)) / C_P, rel=ROUNDOFF)
    assert angles["P"] == pytest.approx(30.0, rel=ROUNDOFF)
    assert reflected_angles("SV", 60.0, C_P, C_S)["P"] is None
    assert reflected_angles("SV", 20.0, C_P, C_S)["S"] == pytest.approx(20.0, rel=ROUNDOFF)


@pytest.mark.parametrize("args, name", [
    (("Q", 30.0, C_P, C_S), "wave_type"),
    (("P", 95.0, C_P, C_S), "angle_deg"),
    (("P", -1.0, C_P, C_S), "angle_deg"),
    (("SV", 30.0, -C_P, C_S), "c_p"),
    (("SV", 30.0, C_P, -C_S), "c_s"),
    (("SV", 30.0, C_S, C_P), "c_s"),
])
def test_bad_input_names_the_parameter(args, name):
    with pytest.raises(ValueError, match=name):
        free_surface_coefficients(*args)

"""The lining law driven alone at one kernel point (workflows/lining_law.py), against closed forms:

- Eq. 21 with A_t = 1 and no crack band peaks at E / B_t exp(-(1 - B_t eps_t)) with damage
  1 - exp(-(1 - B_t eps_t)) when B_t eps_t < 1 (graded tension damage reachable under a rising load),
  and at f_t with no damage when B_t eps_t > 1 (the scenes' B_t = 5e4: softening from the threshold,
  d = 0.3 only past the peak);
- under s_3 = -5 MPa a growing s_1 damages in shear where Table 1's Mohr-Coulomb is met,
  s_1 = (2c cos(phi) + s_3 (1 - sin(phi))) / (1 + sin(phi)), before the tension criterion;
- uniaxial compression damages at the Mohr-Coulomb strength, not at the Poisson extension's
  f_t / (nu sqrt 2) of the paper's criterion read literally.
"""
import math
import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "workflows"))
import lining_law  # noqa: E402

E, F_T = lining_law.E, 1.27e6


def test_eq21_tension_grades_only_when_b_t_eps_t_is_below_one():
    eps_t = F_T / E
    soft = lining_law.uniaxial_tension(dict(lining_law.LINING, B_t=5.0e4, fracture_energy=0.0), n=8000)
    assert soft["d"].max() > 0.99  # it damaged, to the cap
    assert soft["peak_mpa"] == pytest.approx(F_T * 1e-6, rel=1e-3) and soft["d_at_peak"] < 5e-3  # one strain step past
    assert not soft["graded_before_peak"] and soft["graded_strain"] == pytest.approx(
        1.0 + math.log(1.0 / 0.7) / (5.0e4 * eps_t), rel=2e-3)  # d_t = 1 - exp(-B_t (kappa - eps_t)) = 0.3
    hard = lining_law.uniaxial_tension(dict(lining_law.LINING, B_t=1.0e4, fracture_energy=0.0), n=8000)
    x = 1.0 - 1.0e4 * eps_t
    assert hard["peak_mpa"] == pytest.approx(E / 1.0e4 * math.exp(-x) * 1e-6, rel=1e-4)
    assert hard["d_at_peak"] == pytest.approx(1.0 - math.exp(-x), abs=2e-3)  # 0.421
    assert hard["graded_before_peak"]


def test_a_compressed_wall_damages_in_shear_where_mohr_coulomb_is_met():
    held = lining_law.held_compression(dict(lining_law.LINING))
    phi = math.radians(46.0)
    expected = (2.0 * 1.8e6 * math.cos(phi) - 5.0e6 * (1.0 - math.sin(phi))) / (1.0 + math.sin(phi)) * 1e-6
    assert held["law_type"] == 2  # shear, before the tension criterion's f_t / (1 + nu)
    assert held["law_onset_mpa"] == pytest.approx(expected, abs=2e-3)  # 0.638 MPa, steps of 8.5e-4 MPa
    assert expected < held["energy_split_mpa"] < held["mazars_onset_mpa"]
    compression = lining_law.uniaxial_compression(dict(lining_law.LINING))
    assert compression["onset_type"] == 2
    assert compression["onset_mpa"] == pytest.approx(2 * 1.8 * math.cos(phi) / (1 - math.sin(phi)), abs=0.02)
    assert compression["onset_mpa"] > 1.5 * F_T * 1e-6 / (lining_law.NU * math.sqrt(2.0))  # not 5.38 MPa

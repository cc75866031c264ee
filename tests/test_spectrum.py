"""Response spectrum and peak values of an input motion (pyfem.seismic.spectrum), against closed forms."""
import math
from pathlib import Path

import numpy as np
import pytest

from pyfem.seismic.spectrum import peak_values, response_spectrum, sdof_response

REPOSITORY = Path(__file__).resolve().parents[1]


def test_step_acceleration_matches_the_closed_form_to_round_off():
    """A constant ground acceleration is piecewise linear, so the recurrence is exact:
    u(t) = -(A / w^2) (1 - exp(-z w t) (cos(wd t) + z / sqrt(1 - z^2) sin(wd t)))."""
    amplitude, period, damping, dt = 2.5, 0.4, 0.05, 0.01
    t = dt * np.arange(2001)
    u, velocity = sdof_response(np.full(len(t), amplitude), dt, period, damping)
    omega = 2 * math.pi / period
    omega_d = omega * math.sqrt(1 - damping ** 2)
    decay = np.exp(-damping * omega * t)
    ratio = damping / math.sqrt(1 - damping ** 2)
    exact = -(amplitude / omega ** 2) * (1 - decay * (np.cos(omega_d * t) + ratio * np.sin(omega_d * t)))
    exact_velocity = -(amplitude / omega_d) * decay * np.sin(omega_d * t)
    scale = amplitude / omega ** 2
    assert np.max(np.abs(u - exact)) < 1e-12 * scale
    assert np.max(np.abs(velocity - exact_velocity)) < 1e-12 * scale * omega
    # A step's peak response is the classic dynamic amplification 1 + exp(-pi z / sqrt(1 - z^2)).
    spectrum = response_spectrum(np.full(len(t), amplitude), dt, [period], damping)
    overshoot = 1 + math.exp(-math.pi * damping / math.sqrt(1 - damping ** 2))
    assert spectrum["sd"][0] == pytest.approx(np.max(np.abs(exact)), rel=1e-12)
    assert spectrum["sd"][0] == pytest.approx(overshoot * scale, rel=1e-4)  # peak between samples


@pytest.mark.parametrize("frequency_ratio", [0.5, 1.0, 2.0])
def test_sine_steady_state_amplitude(frequency_ratio):
    """a = A sin(W t): after the transient has decayed, |u| peaks at
    (A / w^2) / sqrt((1 - r^2)^2 + (2 z r)^2), r = W / w."""
    amplitude, period, damping, dt = 1.0, 0.5, 0.05, 0.001
    omega = 2 * math.pi / period
    forcing = frequency_ratio * omega
    t = dt * np.arange(int(40.0 / dt) + 1)          # transient exp(-z w t): below 1e-9 after 35 s
    u, _ = sdof_response(amplitude * np.sin(forcing * t), dt, period, damping)
    steady = np.max(np.abs(u[t > 35.0]))
    exact = (amplitude / omega ** 2) / math.sqrt((1 - frequency_ratio ** 2) ** 2
                                                 + (2 * damping * frequency_ratio) ** 2)
    # Piecewise-linear sine and sampled peaks: errors ~ (W dt)^2 / 8, here < 1e-4.
    assert steady == pytest.approx(exact, rel=2e-4)


def test_spectrum_equals_the_single_period_response():
    rng = np.random.default_rng(3)
    acceleration = np.cumsum(rng.standard_normal(3000)) * 0.01
    periods = [0.05, 0.3, 1.0, 4.0]
    spectrum = response_spectrum(acceleration, 0.005, periods, 0.02)
    for k, period in enumerate(periods):
        u, _ = sdof_response(acceleration, 0.005, period, 0.02)
        assert spectrum["sd"][k] == pytest.approx(np.max(np.abs(u)), rel=1e-12)
        omega = 2 * math.pi / period
        assert spectrum["psa"][k] == pytest.approx(omega ** 2 * spectrum["sd"][k], rel=1e-14)
        assert spectrum["psv"][k] == pytest.approx(omega * spectrum["sd"][k], rel=1e-14)


def test_very_short_period_pseudo_acceleration_is_the_pga_of_a_processed_record():
    """A very stiff oscillator follows the ground: PSA(T -> 0) = PGA (El Centro as a run processes it)."""
    from pyfem.seismic.records import STANDARD_GRAVITY, process_record, read_record

    record = read_record(REPOSITORY / "data" / "elcentro_1940_ns.txt", units="g")
    processed = process_record(record, window=(0.0, 20.0), band=(0.1, 25.0), pga=0.32, table_dt=0.002)
    pga = np.max(np.abs(processed.acceleration))
    assert pga == pytest.approx(0.32 * STANDARD_GRAVITY, rel=1e-12)
    spectrum = response_spectrum(processed.acceleration, processed.dt, [0.001, 0.5], 0.05)
    assert spectrum["psa"][0] == pytest.approx(pga, rel=0.01)
    assert spectrum["psa"][1] > 1.5 * pga  # El Centro's plateau, for contrast


def test_peak_values_and_their_times():
    t = np.linspace(0.0, 1.0, 11)
    a = np.array([0, 1, -3, 2, 0, 0, 0, 0, 0, 0, 0], dtype=float)
    peaks = peak_values(t, a, -2 * a, np.linspace(0, -5, 11))
    assert peaks["pga"] == 3.0 and peaks["t_pga"] == pytest.approx(0.2)
    assert peaks["pgv"] == 6.0 and peaks["t_pgv"] == pytest.approx(0.2)
    assert peaks["pgd"] == 5.0 and peaks["t_pgd"] == pytest.approx(1.0)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="periods"):
        response_spectrum(np.zeros(10), 0.01, [0.0, 1.0])
    with pytest.raises(ValueError, match="damping"):
        response_spectrum(np.zeros(10), 0.01, [1.0], damping=1.0)

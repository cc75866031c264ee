"""Peak values and the elastic response spectrum of an input motion (numpy only).

The spectrum is that of a linear single-degree-of-freedom oscillator (period T, damping ratio
zeta) on the ground acceleration a(t):

    u'' + 2 zeta omega u' + omega^2 u = -a(t),   omega = 2 pi / T,   u(0) = u'(0) = 0,

solved by the exact recurrence for an acceleration that is piecewise linear between samples
(Nigam & Jennings 1969): over one step h the state x = (u, u') obeys x' = A x + b a(t) with
a(t) linear, so

    x_{k+1} = Phi x_k + Gamma_0 a_k + Gamma_1 (a_{k+1} - a_k) / h,

with Phi = exp(A h), Gamma_0 = int_0^h exp(A (h - s)) b ds, Gamma_1 = int_0^h exp(A (h - s)) b s ds,
all read off one matrix exponential of the augmented system (x, a, a') (Van Loan). There is no
stability or accuracy limit on h / T: the only approximation is the piecewise-linear acceleration
(the same rule pyfem.seismic.records integrates a record by).

Spectral displacement SD = max |u|, pseudo-velocity PSV = omega SD, pseudo-acceleration
PSA = omega^2 SD. As T -> 0 the oscillator follows the ground (u -> -a / omega^2) and PSA -> PGA.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

# Default periods of a spectrum (s): 0.02 to 5 s, log-spaced, the range of engineering spectra.
DEFAULT_PERIODS = np.geomspace(0.02, 5.0, 60)
# Damping ratio of the spectra a run reports (the usual 5 %).
STANDARD_DAMPING = 0.05


def step_matrices(period: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phi (2, 2), Gamma_0 (2,) and Gamma_1 (2,) of the exact piecewise-linear recurrence.

    Args:
        period: natural period T (s), > 0.
        damping: damping ratio zeta, 0 <= zeta < 1.
        dt: step h of the acceleration samples (s), > 0.
    """
    omega = 2.0 * np.pi / period
    augmented = np.zeros((4, 4))
    augmented[0, 1] = 1.0
    augmented[1, 0] = -omega * omega
    augmented[1, 1] = -2.0 * damping * omega
    augmented[1, 2] = -1.0          # b = (0, -1): the ground acceleration a
    augmented[2, 3] = 1.0           # a' = slope, constant over the step
    exponential = scipy.linalg.expm(augmented * dt)
    return exponential[:2, :2], exponential[:2, 2], exponential[:2, 3]


def sdof_response(acceleration, dt: float, period: float,
                  damping: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Relative displacement u (m) and velocity u' (m/s) of the oscillator at the samples, from rest.

    Args:
        acceleration: (n,) ground acceleration a_k at t_k = k dt (m/s^2), linear in between.
        dt: sample step (s).
        period: natural period T (s).
        damping: damping ratio zeta.
    """
    a = np.asarray(acceleration, dtype=float)
    phi, gamma0, gamma1 = step_matrices(period, damping, dt)
    state = np.zeros(2)
    history = np.zeros((len(a), 2))
    slopes = np.diff(a) / dt
    for k in range(len(a) - 1):
        state = phi @ state + gamma0 * a[k] + gamma1 * slopes[k]
        history[k + 1] = state
    return history[:, 0], history[:, 1]


def response_spectrum(acceleration, dt: float, periods=DEFAULT_PERIODS, damping: float = 0.05) -> dict:
    """Elastic response spectrum of a ground acceleration, all periods at once.

    Args:
        acceleration: (n,) ground acceleration at t_k = k dt (m/s^2), piecewise linear.
        dt: sample step (s).
        periods: (m,) natural periods (s), > 0.
        damping: damping ratio zeta (0.05: the usual 5 %).

    Returns:
        dict with periods (m,) s, damping, sd (m,) m, psv (m,) m/s, psa (m,) m/s^2.
    """
    a = np.asarray(acceleration, dtype=float)
    periods = np.atleast_1d(np.asarray(periods, dtype=float))
    if not (np.all(periods > 0.0) and 0.0 <= damping < 1.0 and dt > 0.0):
        raise ValueError(f"periods must be > 0 s (got min {periods.min():g}), 0 <= damping < 1 (got "
                         f"{damping:g}), dt > 0 (got {dt:g})")
    matrices = [step_matrices(period, damping, dt) for period in periods]
    phi = np.array([m[0] for m in matrices])        # (m, 2, 2)
    gamma0 = np.array([m[1] for m in matrices])     # (m, 2)
    gamma1 = np.array([m[2] for m in matrices])
    slopes = np.diff(a) / dt
    state = np.zeros((len(periods), 2))
    peak = np.zeros(len(periods))
    for k in range(len(a) - 1):  # vectorised over the periods; one pass over the samples
        state = np.einsum("mij,mj->mi", phi, state) + gamma0 * a[k] + gamma1 * slopes[k]
        np.maximum(peak, np.abs(state[:, 0]), out=peak)
    omega = 2.0 * np.pi / periods
    return {"periods": periods, "damping": float(damping), "sd": peak, "psv": omega * peak,
            "psa": omega * omega * peak}


def peak_values(t, acceleration, velocity, displacement) -> dict:
    """PGA (m/s^2), PGV (m/s), PGD (m) of a motion and the times (s) they occur at.

    Args:
        t: (n,) times (s); acceleration, velocity, displacement: (n,) the motion's histories.
    """
    peaks = {}
    for name, values in (("pga", acceleration), ("pgv", velocity), ("pgd", displacement)):
        values = np.asarray(values, dtype=float)
        k = int(np.argmax(np.abs(values))) if len(values) else 0
        peaks[name] = float(abs(values[k])) if len(values) else 0.0
        peaks[f"t_{name}"] = float(t[k]) if len(values) else 0.0
    return peaks

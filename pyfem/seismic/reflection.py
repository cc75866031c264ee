"""Free-surface reflection of plane P, SV and SH waves in a homogeneous half-space.

Frame of one incident wave (docs/method.md section 6): e_h is the horizontal unit vector of
the propagation direction (azimuth phi from +x toward +y), e_z points up, and
e_t = e_z x e_h.  In the vertical (e_h, e_z) plane a wave is described by its
polarisation d and slowness vector p (s/m); its displacement is u = R d g(t - p.x).

Sign convention of the polarisations (all with |d| = 1 when the wave is homogeneous):

* P: d along the propagation direction, d = c_p p.
* SV: d perpendicular to p in the vertical plane with a non-negative e_h component:
  incident (upgoing) d = cos(th) e_h - sin(th) e_z, reflected (downgoing)
  d = cos(th_s) e_h + sin(th_s) e_z.  At vertical incidence with phi = 0 both are +x.
* SH: d = e_t = e_z x e_h (= +y at phi = 0) for the incident and the reflected wave.

The coefficients are obtained by solving the traction-free condition at the surface
numerically (sum over waves of R_j T_j = 0, T_j the traction per unit g'), not from
textbook formulas.  Beyond the critical angle of SV incidence (sin th > c_s/c_p) the
reflected P has an imaginary vertical slowness: for the time dependence e^{i w t}
with w > 0 it is eta_p = -i kappa, kappa = sqrt(s^2 - 1/c_p^2), which makes
exp(-i w eta_p depth) = exp(-w kappa depth) decay downward.  The complex coefficients
returned then hold for positive frequencies; negative frequencies take the conjugate.
"""
from __future__ import annotations

import numpy as np

WAVE_TYPES = ("P", "SV", "SH")


def check_wave_type(wave_type) -> str:
    """Returns the wave type if it is one of "P", "SV", "SH"; raises ValueError otherwise."""
    if wave_type not in WAVE_TYPES:
        raise ValueError(f"wave_type = {wave_type!r}: allowed are 'P', 'SV', 'SH'")
    return wave_type


def check_angle(angle_deg) -> float:
    """Returns the incidence angle (degrees from the vertical) if it lies in [0, 90]."""
    angle = float(angle_deg)
    if not np.isfinite(angle) or angle < 0.0 or angle > 90.0:
        raise ValueError(f"angle_deg = {angle_deg!r}: allowed is 0 <= angle <= 90 degrees from the vertical")
    return angle


def check_speeds(c_p, c_s) -> tuple[float, float]:
    """Returns (c_p, c_s) if both are finite, positive and c_s < c_p."""
    c_p = float(c_p)
    c_s = float(c_s)
    if not np.isfinite(c_p) or c_p <= 0.0:
        raise ValueError(f"c_p = {c_p!r} m/s: allowed is a finite positive speed")
    if not np.isfinite(c_s) or c_s <= 0.0:
        raise ValueError(f"c_s = {c_s!r} m/s: allowed is a finite positive speed")
    if c_s >= c_p:
        raise ValueError(f"c_s = {c_s!r} m/s: allowed is c_s < c_p = {c_p!r} m/s")
    return c_p, c_s


def vertical_slowness(s: float, c: float) -> complex:
    """Vertical slowness eta (s/m) of a wave of speed c and horizontal slowness s.

    Real and non-negative when s <= 1/c; otherwise -i*sqrt(s^2 - 1/c^2), the branch
    that decays away from the surface for positive frequencies (module docstring).
    """
    radicand = 1.0 / c**2 - s**2
    if radicand >= 0.0:
        return complex(np.sqrt(radicand), 0.0)
    return complex(0.0, -np.sqrt(-radicand))


def horizontal_slowness(wave_type: str, angle_deg: float, c_p: float, c_s: float) -> float:
    """Horizontal slowness s = sin(th)/c_incident (s/m), shared by all waves (Snell)."""
    c_incident = c_p if wave_type == "P" else c_s
    return float(np.sin(np.radians(angle_deg)) / c_incident)


def in_plane_waves(wave_type: str, angle_deg: float, c_p: float, c_s: float) -> dict:
    """Polarisation d and slowness p, as complex 2-vectors (e_h, e_z), of every wave.

    Returns:
        dict with keys "incident", "reflected_P", "reflected_S", each a pair
        (d (2,) complex, p (2,) complex s/m).  For SH only the in-plane slowness
        matters and d is the out-of-plane unit e_t (returned as zeros here).
    """
    th = np.radians(angle_deg)
    s = horizontal_slowness(wave_type, angle_deg, c_p, c_s)
    eta_p = vertical_slowness(s, c_p)
    eta_s = vertical_slowness(s, c_s)
    if wave_type == "P":
        d_inc = np.array([np.sin(th), np.cos(th)], dtype=complex)
        p_inc = d_inc / c_p
    elif wave_type == "SV":
        d_inc = np.array([np.cos(th), -np.sin(th)], dtype=complex)
        p_inc = np.array([np.sin(th), np.cos(th)], dtype=complex) / c_s
    else:
        d_inc = np.zeros(2, dtype=complex)
        p_inc = np.array([np.sin(th), np.cos(th)], dtype=complex) / c_s
    p_rp = np.array([s, -eta_p], dtype=complex)
    d_rp = c_p * p_rp  # unit for a homogeneous wave; complex (elliptic motion) when evanescent
    p_rs = np.array([s, -eta_s], dtype=complex)
    d_rs = c_s * np.array([eta_s, s], dtype=complex)
    return {"incident": (d_inc, p_inc), "reflected_P": (d_rp, p_rp), "reflected_S": (d_rs, p_rs)}


def surface_traction(d, p, lam: float, mu: float):
    """Traction sigma.e_z per unit g' (up to the factor -1 common to all waves), (e_h, e_z).

    From u = d g(t - p.x): eps = -sym(d (x) p) g', so -sigma.e_z / g' =
    lam (d.p) e_z + mu ((p.e_z) d + (d.e_z) p).  Products are not conjugated: this
    is the same algebra for complex (evanescent) d and p.
    """
    e_z = np.array([0.0, 1.0])
    return lam * (d @ p) * e_z + mu * (p[1] * d + d[1] * p)


def free_surface_coefficients(wave_type, angle_deg, c_p, c_s) -> dict:
    """Displacement reflection coefficients at a traction-free surface.

    Args:
        wave_type: "P", "SV" or "SH" (incident wave).
        angle_deg: incidence angle from the vertical, degrees, 0..90.
        c_p: P-wave speed, m/s.
        c_s: S-wave speed, m/s (0 < c_s < c_p).

    Returns:
        dict of complex amplitudes per unit incident amplitude, in the polarisation
        convention of the module docstring: for "P" {"PP", "PS"}, for "SV" {"SS", "SP"},
        for "SH" {"HH": 1}.  Complex only beyond the critical angle of SV incidence.
    """
    wave_type = check_wave_type(wave_type)
    angle = check_angle(angle_deg)
    c_p, c_s = check_speeds(c_p, c_s)
    if wave_type == "SH":
        # sigma_zh = mu du/dz of e_t waves: up- and downgoing must cancel, R = +1.
        return {"HH": complex(1.0, 0.0)}
    # Only the ratio lam/mu matters (rho = 1 without loss of generality).
    mu = c_s**2
    lam = c_p**2 - 2.0 * c_s**2
    waves = in_plane_waves(wave_type, angle, c_p, c_s)
    matrix = np.column_stack([surface_traction(*waves["reflected_P"], lam, mu),
                              surface_traction(*waves["reflected_S"], lam, mu)])
    rhs = -surface_traction(*waves["incident"], lam, mu)
    r_p, r_s = np.linalg.solve(matrix, rhs)
    if wave_type == "P":
        return {"PP": complex(r_p), "PS": complex(r_s)}
    return {"SS": complex(r_s), "SP": complex(r_p)}


def critical_angle(c_p, c_s) -> float:
    """Critical angle of SV incidence, degrees: sin(th_c) = c_s / c_p."""
    c_p, c_s = check_speeds(c_p, c_s)
    return float(np.degrees(np.arcsin(c_s / c_p)))


def reflected_angles(wave_type, angle_deg, c_p, c_s) -> dict:
    """Angles from the vertical (degrees) of the reflected waves (Snell's law).

    Returns:
        dict {"P": angle or None, "S": angle}.  "P" is None for SH incidence (no
        converted wave) and for SV beyond the critical angle (evanescent P, no angle).
    """
    wave_type = check_wave_type(wave_type)
    angle = check_angle(angle_deg)
    c_p, c_s = check_speeds(c_p, c_s)
    s = horizontal_slowness(wave_type, angle, c_p, c_s)
    angle_s = float(np.degrees(np.arcsin(min(s * c_s, 1.0))))
    if wave_type == "SH" or s * c_p > 1.0:
        return {"P": None, "S": angle_s}
    return {"P": float(np.degrees(np.arcsin(min(s * c_p, 1.0)))), "S": angle_s}

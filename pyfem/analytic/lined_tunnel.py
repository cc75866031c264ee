"""A circular tunnel with a bonded elastic lining in an infinite elastic medium under a uniform in-plane
far-field stress, plane strain, excavated in stages (docs/lined_tunnel.md): the closed form that the
static stage's lining stress is held to.

Geometry and loading: the tunnel axis is y, the section the x-z plane, theta measured from +x towards
+z; the excavation radius b, the lining the ring a <= r <= b (a = b - thickness), bonded to the rock at
r = b (no slip), its inner face r = a free. The far field (sigma_xx, sigma_zz, sigma_xz), tension
positive, is the rock's stress before the excavation. The excavation releases it in two stages, as the
scene's `[static]` stage does (docs/static.md): a fraction `relaxation` (lambda) of the excavation
load with the hole unsupported, then the lining is installed stress-free and the rest (1 - lambda)
is released onto rock and lining together. Everything is linear elastic, so the final state is
  rock:   sigma_far + lambda (K - sigma_far) + Delta,    lining: Delta,
with K Kirsch's unlined solution and Delta the composite's response to the rest of the excavation
load, the traction -(1 - lambda) sigma_far . n applied at r = b, zero at infinity.

Each state is the sum of an axisymmetric part (the mean stress p = (sigma_xx + sigma_zz) / 2: Lame's
u_r = c1 r + c2 / r in each region) and a deviatoric part of amplitude R = |((sigma_xx - sigma_zz)/2,
sigma_xz)| along the direction 2 theta_0 = atan2(sigma_xz, (sigma_xx - sigma_zz) / 2): in each region
the Airy function phi = (A r^2 + B r^4 + C r^-2 + D) cos 2(theta - theta_0) (Barber, Elasticity,
ch. 8; the rock's B = 0, its A set by the far field). Bonding (traction and displacement continuous
at r = b, up to the applied load) and the free inner face give 3 and 6 linear equations.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _lame(E: float, nu: float) -> tuple[float, float, float]:
    """(Lame lambda, shear modulus mu, plane-strain kappa = 3 - 4 nu)."""
    mu = E / (2.0 * (1.0 + nu))
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), mu, 3.0 - 4.0 * nu


# Deviatoric part: the stress and 2 mu times the displacement of each Airy term, per unit
# coefficient, without the angular factor (cos 2t for rr, tt, u_r; sin 2t for rt, u_t), for
# the terms r^2, r^4, r^-2 and r^0 (Barber, Table 8.1, plane strain).
def _deviatoric_terms(r: float, kappa: float) -> np.ndarray:
    """(5, 4): rows sigma_rr, sigma_rt, sigma_tt, 2 mu u_r, 2 mu u_t; columns A, B, C, D."""
    return np.array([
        [-2.0, 0.0, -6.0 * r ** -4, -4.0 * r ** -2],
        [2.0, 6.0 * r ** 2, -6.0 * r ** -4, -2.0 * r ** -2],
        [2.0, 12.0 * r ** 2, 6.0 * r ** -4, 0.0],
        [-2.0 * r, (kappa - 3.0) * r ** 3, 2.0 * r ** -3, (kappa + 1.0) / r],
        [2.0 * r, (kappa + 3.0) * r ** 3, 2.0 * r ** -3, -(kappa - 1.0) / r],
    ])


def _far_parts(far_field) -> tuple[float, float, float]:
    """(mean p, deviatoric amplitude R, direction theta_0) of a far field (sigma_xx, sigma_zz,
    sigma_xz): p = (sigma_xx + sigma_zz) / 2, R = |((sigma_xx - sigma_zz) / 2, sigma_xz)|,
    2 theta_0 = atan2(sigma_xz, (sigma_xx - sigma_zz) / 2)."""
    sxx, szz, sxz = far_field
    amplitude = math.hypot(0.5 * (sxx - szz), sxz)
    direction = 0.5 * math.atan2(sxz, 0.5 * (sxx - szz)) if amplitude > 0.0 else 0.0
    return 0.5 * (sxx + szz), amplitude, direction


@dataclass(frozen=True)
class LinedTunnel:
    """The lined tunnel: excavation radius b (m), lining thickness (m), lining and rock elastic
    constants (Pa, -). Stresses in Pa, tension positive."""

    radius: float
    thickness: float
    lining_E: float
    lining_nu: float
    rock_E: float
    rock_nu: float

    def __post_init__(self):
        if not (0.0 < self.thickness < self.radius):
            raise ValueError(f"thickness {self.thickness!r} must lie in (0, radius {self.radius!r})")
        for name in ("lining_E", "rock_E"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must be > 0")
        for name in ("lining_nu", "rock_nu"):
            if not -1.0 < getattr(self, name) < 0.5:
                raise ValueError(f"{name} = {getattr(self, name)!r} must lie in (-1, 0.5)")

    @property
    def inner_radius(self) -> float:
        return self.radius - self.thickness

    # ------------------------------------------------------------------ the two parts
    def axisymmetric(self, far: float, jump: float) -> tuple[np.ndarray, np.ndarray]:
        """Lame coefficients (c1, c2) of u_r = c1 r + c2 / r for the lining and the rock, for a mean far
        field `far` (rock c1 from it) and a radial traction `jump` = sigma_rr(rock) - sigma_rr(lining) at
        r = b; the lining's inner face free."""
        a, b = self.inner_radius, self.radius
        lam_l, mu_l, _ = _lame(self.lining_E, self.lining_nu)
        lam_r, mu_r, _ = _lame(self.rock_E, self.rock_nu)
        c1_rock = far / (2.0 * (lam_r + mu_r))
        # unknowns: lining c1, c2; rock c2
        matrix = np.array([
            [2.0 * (lam_l + mu_l), -2.0 * mu_l / a ** 2, 0.0],                   # sigma_rr(a) = 0
            [-2.0 * (lam_l + mu_l), 2.0 * mu_l / b ** 2, -2.0 * mu_r / b ** 2],  # traction jump at b
            [-b, -1.0 / b, 1.0 / b],                                            # u_r continuous at b
        ])
        rhs = np.array([0.0, jump - 2.0 * (lam_r + mu_r) * c1_rock, -c1_rock * b])
        c1_l, c2_l, c2_r = np.linalg.solve(matrix, rhs)
        return np.array([c1_l, c2_l]), np.array([c1_rock, c2_r])

    def deviatoric(self, far: float, jump_rr: float, jump_rt: float) -> tuple[np.ndarray, np.ndarray]:
        """Airy coefficients (A, B, C, D) of the lining and the rock (B = 0) for a far field of amplitude
        `far` (sigma_rr -> far cos 2t) and traction jumps sigma(rock) - sigma(lining) at r = b of
        jump_rr cos 2t (radial) and jump_rt sin 2t (shear); the lining's inner face free."""
        a, b = self.inner_radius, self.radius
        _, mu_l, kappa_l = _lame(self.lining_E, self.lining_nu)
        _, mu_r, kappa_r = _lame(self.rock_E, self.rock_nu)
        A_r = -0.5 * far
        inner = _deviatoric_terms(a, kappa_l)
        lining_b = _deviatoric_terms(b, kappa_l)
        rock_b = _deviatoric_terms(b, kappa_r)
        # unknowns: lining A, B, C, D; rock C, D
        matrix = np.zeros((6, 6))
        rhs = np.zeros(6)
        matrix[0, :4] = inner[0]                       # sigma_rr(a) = 0
        matrix[1, :4] = inner[1]                       # sigma_rt(a) = 0
        for row, component, jump in ((2, 0, jump_rr), (3, 1, jump_rt)):
            matrix[row, :4] = -lining_b[component]
            matrix[row, 4:] = rock_b[component, 2:]
            rhs[row] = jump - rock_b[component, 0] * A_r
        for row, component in ((4, 3), (5, 4)):        # u_r, u_t continuous at b
            matrix[row, :4] = -lining_b[component] / (2.0 * mu_l)
            matrix[row, 4:] = rock_b[component, 2:] / (2.0 * mu_r)
            rhs[row] = -rock_b[component, 0] * A_r / (2.0 * mu_r)
        x = np.linalg.solve(matrix, rhs)
        return x[:4], np.array([A_r, 0.0, x[4], x[5]])

    # ------------------------------------------------------------------ the staged state
    def stresses(self, r, theta, far_field, relaxation: float = 0.0) -> dict:
        """sigma_rr, sigma_tt, sigma_rt (Pa, tension positive) at polar points (r, theta) after the
        staged excavation: `far_field` = (sigma_xx, sigma_zz, sigma_xz) (Pa), `relaxation` lambda in
        [0, 1] (0: the lining installed before any release, 1: after all of it, stress-free). Points
        with r < a are in the opening (nan), a <= r < b in the lining, r >= b in the rock."""
        if not 0.0 <= relaxation <= 1.0:
            raise ValueError(f"relaxation {relaxation!r} must lie in [0, 1]")
        mean, amplitude, direction = _far_parts(far_field)
        rest = 1.0 - relaxation
        # Kirsch: the unlined hole (rock only, free at b), and the composite's share Delta.
        kirsch_mean, kirsch_dev = self._unlined(mean, amplitude)
        lining0, rock0 = self.axisymmetric(0.0, -rest * mean)
        lining2, rock2 = self.deviatoric(0.0, -rest * amplitude, rest * amplitude)
        lam_r, mu_r, kappa_r = _lame(self.rock_E, self.rock_nu)

        def rock(radius):
            k_rr, k_tt = self._lame_stress(kirsch_mean, radius, lam_r, mu_r)
            d_rr, d_tt = self._lame_stress(rock0, radius, lam_r, mu_r)
            terms = _deviatoric_terms(radius, kappa_r)[:3]
            far_dev = np.array([amplitude, -amplitude, -amplitude])  # rr, rt, tt of the uniform field
            return ((mean + relaxation * (k_rr - mean) + d_rr, mean + relaxation * (k_tt - mean) + d_tt),
                    far_dev + relaxation * (terms @ kirsch_dev - far_dev) + terms @ rock2)

        return self._field(r, theta, direction, lambda radius: self._part(lining0, lining2, radius, True), rock)

    def loaded_stresses(self, r, theta, far_field) -> dict:
        """sigma_rr, sigma_tt, sigma_rt (Pa, tension positive) at polar points (r, theta) when the far
        field changes by `far_field` = (sigma_xx, sigma_zz, sigma_xz) (Pa) with the lining already in
        place and stress-free: a wave much longer than the tunnel loads it this way (quasi-static
        far-field shear, the no-slip lining of Wang 1993 / Penzien 2000). Unlike the excavation of
        `stresses`, the rock's displacement includes the far field's own, so the lining strains with
        it: the composite's response is the far field in the rock plus what the lined opening
        scatters. Points with r < a are in the opening (nan), a <= r < b in the lining, r >= b in the
        rock."""
        mean, amplitude, direction = _far_parts(far_field)
        lining0, rock0 = self.axisymmetric(mean, 0.0)
        lining2, rock2 = self.deviatoric(amplitude, 0.0, 0.0)
        return self._field(r, theta, direction, lambda radius: self._part(lining0, lining2, radius, True),
                           lambda radius: self._part(rock0, rock2, radius, False))

    def _part(self, lame: np.ndarray, airy: np.ndarray, radius: float, lining: bool) -> tuple:
        """((sigma_rr, sigma_tt) of Lame's part, (rr, rt, tt) amplitudes of the Airy part) at `radius`
        from one region's coefficients (the lining's, or the rock's)."""
        lam, mu, kappa = _lame(*((self.lining_E, self.lining_nu) if lining else (self.rock_E, self.rock_nu)))
        return self._lame_stress(lame, radius, lam, mu), _deviatoric_terms(radius, kappa)[:3] @ airy

    def _field(self, r, theta, direction: float, lining, rock) -> dict:
        """sigma_rr, sigma_tt, sigma_rt at polar points: lining(radius) / rock(radius) give the
        axisymmetric (rr, tt) and the deviatoric amplitudes (rr, rt, tt, of cos / sin 2(theta -
        direction)) where a <= r < b / r >= b; nan in the opening."""
        r, theta = np.broadcast_arrays(np.asarray(r, dtype=float), np.asarray(theta, dtype=float))
        out = {key: np.full(r.shape, np.nan) for key in ("rr", "tt", "rt")}
        c2, s2 = np.cos(2.0 * (theta - direction)), np.sin(2.0 * (theta - direction))
        for index in np.ndindex(r.shape):
            radius = r[index]
            if radius < self.inner_radius * (1.0 - 1e-12):
                continue
            (rr0, tt0), dev = (lining if radius < self.radius else rock)(radius)
            out["rr"][index] = rr0 + dev[0] * c2[index]
            out["tt"][index] = tt0 + dev[2] * c2[index]
            out["rt"][index] = dev[1] * s2[index]
        return out

    def _unlined(self, mean: float, amplitude: float) -> tuple[np.ndarray, np.ndarray]:
        """Kirsch's solution in the same form: rock Lame (c1, c2) and Airy (A, 0, C, D) with the wall
        r = b free."""
        b = self.radius
        lam_r, mu_r, kappa_r = _lame(self.rock_E, self.rock_nu)
        c1 = mean / (2.0 * (lam_r + mu_r))
        c2 = mean * b ** 2 / (2.0 * mu_r)  # sigma_rr(b) = mean - 2 mu c2 / b^2 = 0
        A = -0.5 * amplitude
        terms = _deviatoric_terms(b, kappa_r)
        C, D = np.linalg.solve(terms[:2, 2:], -terms[:2, 0] * A)
        return np.array([c1, c2]), np.array([A, 0.0, C, D])

    @staticmethod
    def _lame_stress(coefficients: np.ndarray, r: float, lam: float, mu: float) -> tuple[float, float]:
        c1, c2 = coefficients
        return 2.0 * (lam + mu) * c1 - 2.0 * mu * c2 / r ** 2, 2.0 * (lam + mu) * c1 + 2.0 * mu * c2 / r ** 2

    def hoop_stress(self, r, theta, far_field, relaxation: float = 0.0) -> np.ndarray:
        """sigma_tt (Pa) at (r, theta), `stresses`'s."""
        return self.stresses(r, theta, far_field, relaxation)["tt"]

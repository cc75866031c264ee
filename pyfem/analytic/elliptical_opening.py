"""An elliptical opening in an infinite elastic medium under a uniform in-plane far-field stress, plane
strain (docs/elliptical_opening.md): the closed form that a non-circular excavation's wall stress is
held to.

Geometry: the opening's axis is y, the section the x-z plane; the ellipse has the half-width a along x
and the half-height b along z about its centre, its wall traction-free. The far field (sigma_xx,
sigma_zz, sigma_xz), tension positive, is the rock's stress before the excavation; the stresses below
are the total stresses after it (those of a plate with the hole under the remote load) and the
displacements those of the excavation alone (the total minus the uniform field's).

Muskhelishvili's complex potentials (Some Basic Problems of the Mathematical Theory of Elasticity,
Sec. 56), with the complex coordinate w = (x - x_c) + i (z - z_c) and the map of the outside of the
unit circle onto the outside of the ellipse
    w = omega(zeta) = R (zeta + m / zeta),   R = (a + b) / 2,   m = (a - b) / (a + b),
    sigma_xx + sigma_zz = 4 Re Phi,   sigma_zz - sigma_xx + 2 i sigma_xz = 2 (conj(w) Phi' + Psi),
    2 G (u_x + i u_z) = kappa phi - w conj(Phi) - conj(psi),   kappa = 3 - 4 nu,
Phi = phi'(w), Psi = psi'(w). With Gamma = (sigma_xx + sigma_zz) / 4 and Gamma' = (sigma_zz -
sigma_xx) / 2 + i sigma_xz (the far field: phi ~ Gamma w, psi ~ Gamma' w), the free wall gives
    phi(zeta) = R (Gamma zeta + c / zeta),   c = -(conj(Gamma') + m Gamma),
    psi(zeta) = -R (Gamma / zeta + conj(c) zeta + f(zeta)),
    f(zeta) = zeta (1 + m zeta^2) (Gamma - c / zeta^2) / (zeta^2 - m)
(derived in docs/elliptical_opening.md). Checked in tests/test_elliptical_opening.py against an
independent answer, the wall's hoop stress of a uniaxial far field S at angle beta from x (Inglis 1913
in the form of Savin, Stress Concentration around Holes, ch. 2),
    sigma_tt = S (1 - m^2 + 2 m cos 2 beta - 2 cos 2 (beta - theta)) / (1 + m^2 - 2 m cos 2 theta)
at the wall point omega(e^{i theta}), which gives 1 + 2 b / a at the crown under a horizontal S;
against Kirsch's solution when a = b; and the displacements, differentiated numerically and put
through Hooke's law, against the stresses.
"""
from __future__ import annotations

import math

import numpy as np


class EllipticalOpening:
    """The elliptical opening (half-width a along x, half-height b along z, centre (x_c, z_c)) in a
    rock of Young's modulus E and Poisson's ratio nu, plane strain."""

    def __init__(self, half_width: float, half_height: float, E: float, nu: float,
                 centre: tuple[float, float] = (0.0, 0.0)):
        if not (half_width > 0.0 and half_height > 0.0):
            raise ValueError(f"EllipticalOpening: half_width = {half_width!r} and half_height = "
                             f"{half_height!r} must be > 0 (m)")
        if not (E > 0.0 and -1.0 < nu < 0.5):
            raise ValueError(f"EllipticalOpening: E = {E!r} must be > 0 (Pa) and nu = {nu!r} in (-1, 0.5)")
        self.a, self.b = float(half_width), float(half_height)
        self.R = 0.5 * (self.a + self.b)
        self.m = (self.a - self.b) / (self.a + self.b)
        self.shear_modulus = E / (2.0 * (1.0 + nu))
        self.kappa = 3.0 - 4.0 * nu
        self.centre = complex(*centre)

    @property
    def smallest_radius_of_curvature(self) -> float:
        """min(a^2 / b, b^2 / a) (m): at the ends of the longer axis."""
        return min(self.a ** 2 / self.b, self.b ** 2 / self.a)

    # -- the map and its inverse ------------------------------------------------------------------
    def zeta(self, x, z) -> np.ndarray:
        """The point of |zeta| >= 1 that the map sends to (x, z) (on or outside the wall)."""
        w = np.asarray(x, dtype=float) - self.centre.real + 1j * (np.asarray(z, dtype=float) - self.centre.imag)
        root = np.sqrt(w * w - 4.0 * self.R * self.R * self.m)
        plus, minus = (w + root) / (2.0 * self.R), (w - root) / (2.0 * self.R)
        zeta = np.where(np.abs(plus) >= np.abs(minus), plus, minus)
        if np.any(np.abs(zeta) < 1.0 - 1e-9):
            raise ValueError("EllipticalOpening: a point lies inside the opening (the closed form holds on "
                             "and outside its wall)")
        return zeta

    def wall_point(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """(x, z) of the wall point omega(e^{i theta}) = (x_c + a cos theta, z_c + b sin theta)."""
        theta = np.asarray(theta, dtype=float)
        return self.centre.real + self.a * np.cos(theta), self.centre.imag + self.b * np.sin(theta)

    def directions(self, x, z) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors (complex, x + i z) normal to the confocal ellipse through (x, z), pointing away
        from the opening, and along it (the 'hoop' direction, counter-clockwise in x-z)."""
        zeta = self.zeta(x, z)
        outward = zeta * self.R * (1.0 - self.m / zeta ** 2)   # d omega / d log|zeta|
        normal = outward / np.abs(outward)
        return normal, 1j * normal

    # -- the potentials -----------------------------------------------------------------------------
    @staticmethod
    def _far(far_field) -> tuple[float, complex]:
        if len(far_field) != 3:
            raise ValueError(f"EllipticalOpening: far_field = {far_field!r} must be (sigma_xx, sigma_zz, sigma_xz) (Pa)")
        sxx, szz, sxz = (float(value) for value in far_field)
        return 0.25 * (sxx + szz), complex(0.5 * (szz - sxx), sxz)

    def _potentials(self, zeta, far_field) -> dict:
        """phi, psi (of w) and Phi = phi', Phi' = phi'', Psi = psi' at the points zeta."""
        R, m = self.R, self.m
        gamma, gamma_prime = self._far(far_field)
        c = -(np.conj(gamma_prime) + m * gamma)
        zeta = np.asarray(zeta, dtype=complex)
        z2 = zeta * zeta
        omega_1 = R * (1.0 - m / z2)            # omega'
        omega_2 = 2.0 * R * m / (z2 * zeta)     # omega''
        phi = R * (gamma * zeta + c / zeta)
        phi_1 = R * (gamma - c / z2)            # d phi / d zeta
        phi_2 = 2.0 * R * c / (z2 * zeta)
        g = gamma * zeta + m * gamma * z2 * zeta - c / zeta - m * c * zeta
        g_1 = gamma + 3.0 * m * gamma * z2 + c / z2 - m * c
        f = g / (z2 - m)
        f_1 = (g_1 * (z2 - m) - 2.0 * zeta * g) / (z2 - m) ** 2
        psi = -R * (gamma / zeta + np.conj(c) * zeta + f)
        psi_1 = -R * (-gamma / z2 + np.conj(c) + f_1)
        big_phi = phi_1 / omega_1
        return {"phi": phi, "psi": psi, "Phi": big_phi,
                "dPhi": (phi_2 * omega_1 - phi_1 * omega_2) / omega_1 ** 3, "Psi": psi_1 / omega_1}

    def stresses(self, x, z, far_field) -> dict:
        """Total stresses sxx, szz, sxz (Pa, tension positive) at points on or outside the wall, and
        their components nn (normal to the confocal ellipse through the point), tt (along it, the
        hoop stress) and nt."""
        x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
        p = self._potentials(self.zeta(x, z), far_field)
        w = x - self.centre.real + 1j * (z - self.centre.imag)
        trace = 4.0 * p["Phi"].real
        deviator = 2.0 * (np.conj(w) * p["dPhi"] + p["Psi"])   # szz - sxx + 2 i sxz
        sxx, szz, sxz = 0.5 * (trace - deviator.real), 0.5 * (trace + deviator.real), 0.5 * deviator.imag
        normal, _ = self.directions(x, z)
        nx, nz = normal.real, normal.imag
        nn = sxx * nx * nx + szz * nz * nz + 2.0 * sxz * nx * nz
        tt = sxx * nz * nz + szz * nx * nx - 2.0 * sxz * nx * nz
        nt = (szz - sxx) * nx * nz + sxz * (nx * nx - nz * nz)
        return {"sxx": sxx, "szz": szz, "sxz": sxz, "nn": nn, "tt": tt, "nt": nt}

    def displacement(self, x, z, far_field) -> tuple[np.ndarray, np.ndarray]:
        """(u_x, u_z) (m) of the excavation: the displacement of the opening under the far field minus
        that of the uniform field, 2 G u_uniform = (kappa - 1) Gamma w - conj(Gamma' w)."""
        x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
        p = self._potentials(self.zeta(x, z), far_field)
        w = x - self.centre.real + 1j * (z - self.centre.imag)
        gamma, gamma_prime = self._far(far_field)
        total = self.kappa * p["phi"] - w * np.conj(p["Phi"]) - np.conj(p["psi"])
        uniform = (self.kappa - 1.0) * gamma * w - np.conj(gamma_prime * w)
        u = (total - uniform) / (2.0 * self.shear_modulus)
        return u.real, u.imag

    def wall_hoop_stress(self, theta, far_field) -> np.ndarray:
        """The hoop stress (Pa) at the wall points omega(e^{i theta}) from Inglis' formula for a
        uniaxial far field, summed over the far field's two principal stresses (independent of the
        potentials above)."""
        gamma, gamma_prime = self._far(far_field)   # checks it
        sxx, szz, sxz = (float(value) for value in far_field)
        mean, radius = 0.5 * (sxx + szz), math.hypot(0.5 * (sxx - szz), sxz)
        beta = 0.5 * math.atan2(sxz, 0.5 * (sxx - szz)) if radius > 0.0 else 0.0
        theta = np.asarray(theta, dtype=float)
        m = self.m
        total = np.zeros_like(theta)
        for S, angle in ((mean + radius, beta), (mean - radius, beta + 0.5 * math.pi)):
            total += S * (1.0 - m * m + 2.0 * m * math.cos(2.0 * angle) - 2.0 * np.cos(2.0 * (angle - theta))) / (
                1.0 + m * m - 2.0 * m * np.cos(2.0 * theta))
        return total


def wall_errors(stage, opening: EllipticalOpening, far_field) -> dict:
    """A static stage's excavation of the opening against the closed form, at its wall.

    The cells with a face on the wall (four vertices on it), their hoop stress at the centroid (the
    static stage's cell stress) against the exact stress there, and the displacement of the nodes on
    the wall against the exact excavation displacement.

    Args:
        stage: a static stage that excavated the opening, its section the x-z plane: `.model` (the
            pyfem.operators.Model), `.cell_stress` (n_cells, 3, 3) at the centroids (Pa) and
            `.displacement` (3 n,) (m), in the function space's numbering (the one model's stage on one
            rank: workflows/elliptical_opening.py `stage_on_the_model`).
        opening: the closed form, centred where the mesh has the opening.
        far_field: (sigma_xx, sigma_zz, sigma_xz) of the scene's initial stress (Pa).

    Returns:
        cells (their number), worst (largest hoop error over the cells / the exact peak hoop stress at
        the wall), peak_cell (error of the cell where the exact hoop stress is largest, relative to
        it), hoop and exact_hoop there (Pa), largest_hoop (the model's largest |hoop| over the cells,
        Pa), peak (the exact peak at the wall, Pa), displacement (largest error of the wall nodes'
        displacement / the largest exact one) and largest_displacement (m).
    """
    model = stage.model
    xyz = model.node_coords
    on_wall = np.abs(np.abs(opening.zeta(xyz[:, 0], xyz[:, 2])) - 1.0) < 1e-6
    n_basis = model.V.element.basix_element.dim
    vertices = model.V.dofmap.list.array.reshape(-1, n_basis)[:, :8]
    cells = np.flatnonzero(on_wall[vertices].sum(axis=1) >= 4)
    if len(cells) == 0:
        raise ValueError("wall_errors: no cell has a face on the opening's wall (is the opening where the mesh has it?)")
    centroids = xyz[vertices[cells]].mean(axis=1)
    stress = stage.cell_stress[cells]
    normal, _ = opening.directions(centroids[:, 0], centroids[:, 2])
    nx, nz = normal.real, normal.imag
    hoop = stress[:, 0, 0] * nz * nz + stress[:, 2, 2] * nx * nx - 2.0 * stress[:, 0, 2] * nx * nz
    exact = opening.stresses(centroids[:, 0], centroids[:, 2], far_field)["tt"]
    peak = float(np.abs(opening.wall_hoop_stress(np.linspace(0.0, 2.0 * math.pi, 3601), far_field)).max())
    top = int(np.argmax(np.abs(exact)))
    nodes = np.flatnonzero(on_wall)
    u = stage.displacement.reshape(-1, 3)[nodes]
    ux, uz = opening.displacement(xyz[nodes, 0], xyz[nodes, 2], far_field)
    largest = float(np.hypot(ux, uz).max())
    return {"cells": len(cells), "worst": float(np.abs(hoop - exact).max() / peak),
            "peak_cell": float(abs(hoop[top] - exact[top]) / abs(exact[top])),
            "hoop": float(hoop[top]), "exact_hoop": float(exact[top]),
            "largest_hoop": float(np.abs(hoop).max()), "peak": peak,
            "displacement": float(np.hypot(u[:, 0] - ux, u[:, 2] - uz).max() / largest),
            "largest_displacement": largest}

"""Plane SV waves scattered by an unlined circular cavity in a full plane: Pao & Mow's series.

The exact dynamic answer for the stress at a cavern wall (plane strain, linear elastic,
homogeneous, no free surface). docs/wall_stress_accuracy.md "The exact dynamic answer" states
the problem and the checks; workflows/wall_stress_accuracy.py compares the mesh's wall stress with
it.

The problem, in the plane (x1, x2) = (x, z) with polar coordinates x1 = r cos(theta),
x2 = r sin(theta) about the cavity's centre, time factor exp(-i omega t):
- the incident wave is SV travelling along +x2 with its motion along x1:
  u1 = U exp(i k_s x2), u2 = 0, so the free field's shear stress at the centre is
  sigma_12 = i mu k_s U;
- u = grad(phi) + curl(psi e3); the incident psi = U / (i k_s) exp(i k_s r sin(theta)) =
  U / (i k_s) sum_n J_n(k_s r) exp(i n theta) (Jacobi-Anger);
- the scattered potentials are outgoing: phi = sum_n A_n H_n(k_p r) exp(i n theta),
  psi = sum_n B_n H_n(k_s r) exp(i n theta), H_n Hankel's function of the first kind;
- the wall r = a is free: sigma_rr = sigma_rtheta = 0, one 2 x 2 system per n.

For one term F(r) exp(i n theta) of phi and G(r) exp(i n theta) of psi (F, G solving Bessel's
equation of order n in k_p r and k_s r):
- u_r = F' + i n G / r, u_theta = i n F / r - G';
- sigma_rr = -lambda k_p^2 F + 2 mu (F'' + i n (G' / r - G / r^2));
- sigma_thth = -lambda k_p^2 F + 2 mu (F' / r - n^2 F / r^2 + i n (G / r^2 - G' / r));
- sigma_rth = mu (2 i n (F' / r - F / r^2) - G'' + G' / r - n^2 G / r^2).

The crown's motion relative to the invert's (`racking`) is the displacement the case study reads
"relative to D"; a long wave gives Kirsch's displacement field for the far-field shear
gamma = du1/dx2 plus the incident wave's rotation gamma / 2:
u1(r, 90) - u1(r, 270) = gamma (2 r + a^2 (kappa - 1) / r + a^4 / r^3), kappa = 3 - 4 nu (plane
strain); at the wall gamma a (kappa + 2), (5 - 4 nu) / 2 times the free field's 2 gamma a.

A time history is the series' transfer function applied to the spectrum of the incident
displacement at the centre (`hoop_stress_history`).

Reference: Y.-H. Pao and C.-C. Mow, Diffraction of Elastic Waves and Dynamic Stress
Concentrations, Crane Russak, 1973, ch. 4 (cylindrical cavity, incident P and SV).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import special

_STRESSES = ("rr", "thth", "rth")
_FIELDS = _STRESSES + ("ur", "uth")


def _radial(kind: str, n: np.ndarray, k: float, r: float):
    """(Z, Z', Z'') of Z_n(k r) in r for kind "J" (Bessel), "Y" (Neumann) or "H" (Hankel, first
    kind)."""
    if kind == "J":
        z, dz = special.jv(n, k * r), k * special.jvp(n, k * r)
    elif kind == "Y":
        z, dz = special.yv(n, k * r), k * special.yvp(n, k * r)
    else:
        z, dz = special.hankel1(n, k * r), k * special.h1vp(n, k * r)
    ddz = -dz / r - (k * k - n * n / (r * r)) * z
    return z, dz, ddz


def _term_fields(n, r, lam, mu, kp, f=None, g=None) -> dict:
    """Stresses and displacements of the terms F exp(i n theta) (phi) and G exp(i n theta) (psi)
    at radius r; f and g are (Z, Z', Z'') triples or None (that potential absent)."""
    zero = (0.0, 0.0, 0.0)
    F, dF, ddF = f if f is not None else zero
    G, dG, ddG = g if g is not None else zero
    return {
        "rr": -lam * kp * kp * F + 2 * mu * (ddF + 1j * n * (dG / r - G / r ** 2)),
        "thth": -lam * kp * kp * F + 2 * mu * (dF / r - n * n * F / r ** 2 + 1j * n * (G / r ** 2 - dG / r)),
        "rth": mu * (2j * n * (dF / r - F / r ** 2) - ddG + dG / r - n * n * G / r ** 2),
        "ur": dF + 1j * n * G / r,
        "uth": 1j * n * F / r - dG,
    }


class CavitySV:
    """Vertically travelling SV scattered by a circular cavity of radius `a` (m) in rock of
    Young's modulus E (Pa), Poisson's ratio nu and density rho (kg/m^3), plane strain."""

    def __init__(self, a: float, E: float, nu: float, rho: float):
        self.a = a
        self.mu = E / (2.0 * (1.0 + nu))
        self.lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
        self.cs = math.sqrt(self.mu / rho)
        self.cp = math.sqrt((self.lam + 2.0 * self.mu) / rho)

    def terms(self, omega: float) -> int:
        """Number of orders kept on each side of n = 0: the series converges once n exceeds
        k_s a by a margin (the terms then fall like (a / r)^n at r > a)."""
        return int(2.0 * omega / self.cs * self.a) + 16

    def fields(self, omega: float, r: float, theta, U: complex = 1.0) -> dict:
        """Total (incident + scattered) sigma_rr, sigma_thth, sigma_rth (Pa, keys rr, thth, rth)
        and u_r, u_theta (m, keys ur, uth) at (r, theta) for the incident amplitude U (m) at the
        centre, angular frequency omega > 0."""
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        kp, ks = omega / self.cp, omega / self.cs
        n = np.arange(-self.terms(omega), self.terms(omega) + 1)
        incident_g = tuple(U / (1j * ks) * z for z in _radial("J", n, ks, self.a))
        inc = _term_fields(n, self.a, self.lam, self.mu, kp, g=incident_g)
        phi = _term_fields(n, self.a, self.lam, self.mu, kp, f=_radial("H", n, kp, self.a))
        psi = _term_fields(n, self.a, self.lam, self.mu, kp, g=_radial("H", n, ks, self.a))
        # The free wall, per n: [phi_rr psi_rr; phi_rth psi_rth] [A; B] = -[inc_rr; inc_rth].
        det = phi["rr"] * psi["rth"] - psi["rr"] * phi["rth"]
        A = (-inc["rr"] * psi["rth"] + psi["rr"] * inc["rth"]) / det
        B = (-phi["rr"] * inc["rth"] + inc["rr"] * phi["rth"]) / det
        incident_g = tuple(U / (1j * ks) * z for z in _radial("J", n, ks, r))
        inc = _term_fields(n, r, self.lam, self.mu, kp, g=incident_g)
        phi = _term_fields(n, r, self.lam, self.mu, kp, f=_radial("H", n, kp, r))
        psi = _term_fields(n, r, self.lam, self.mu, kp, g=_radial("H", n, ks, r))
        modes = np.exp(1j * np.outer(theta, n))
        return {key: modes @ (inc[key] + A * phi[key] + B * psi[key]) for key in _FIELDS}

    def stresses(self, omega: float, r: float, theta, U: complex = 1.0) -> dict:
        """sigma_rr, sigma_thth, sigma_rth (Pa) of `fields`."""
        fields = self.fields(omega, r, theta, U)
        return {key: fields[key] for key in _STRESSES}

    def horizontal_displacement(self, omega: float, r: float, theta, U: complex = 1.0) -> np.ndarray:
        """u_1 = u_r cos(theta) - u_theta sin(theta) (m) at (r, theta): along the incident motion."""
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        fields = self.fields(omega, r, theta, U)
        return fields["ur"] * np.cos(theta) - fields["uth"] * np.sin(theta)

    def racking(self, omega: float, r: float, U: complex = 1.0) -> complex:
        """u_1(r, 90 deg) - u_1(r, 270 deg) (m): the crown's motion relative to the invert's along
        the incident motion, at distance r from the centre (the case study's "relative to D")."""
        top, bottom = self.horizontal_displacement(omega, r, [0.5 * math.pi, 1.5 * math.pi], U)
        return complex(top - bottom)

    def free_field_shear(self, omega: float, U: complex = 1.0) -> complex:
        """sigma_12 of the incident wave at the centre (Pa): i mu k_s U."""
        return 1j * self.mu * omega / self.cs * U

    def history(self, t: np.ndarray, u_centre: np.ndarray, transfer, pad: float = 4.0) -> np.ndarray:
        """The time history of a quantity whose response to the incident amplitude U = 1 at angular
        frequency omega is transfer(omega) (complex, time factor exp(-i omega t)), for the
        incident displacement history u_centre(t) (m, along x1, at the centre, uniformly sampled,
        zero before and after the wave).

        The record is padded with zeros to `pad` times its length so the periodic synthesis does
        not wrap; frequencies where the incident spectrum is below 1e-12 of its peak are left out.
        """
        t = np.asarray(t, dtype=float)
        dt = float(t[1] - t[0])
        n_fft = int(2 ** math.ceil(math.log2(pad * len(t))))
        spectrum = np.fft.rfft(np.asarray(u_centre, dtype=float), n_fft)
        omega = 2.0 * math.pi * np.fft.rfftfreq(n_fft, dt)
        response = np.zeros_like(spectrum)
        keep = np.abs(spectrum) > 1e-12 * np.abs(spectrum).max()
        for j in np.flatnonzero(keep):
            if omega[j] > 0.0:
                # numpy's synthesis runs on exp(+i omega t): the transfer of exp(-i omega t) conjugated.
                response[j] = spectrum[j] * np.conj(transfer(omega[j]))
        return np.fft.irfft(response, n_fft)[:len(t)]

    def hoop_stress_history(self, t: np.ndarray, u_centre: np.ndarray, r: float, theta: float,
                            pad: float = 4.0) -> np.ndarray:
        """sigma_thth(t) at (r, theta) (Pa) for the incident displacement history u_centre(t) (`history`)."""
        return self.history(t, u_centre, lambda omega: self.stresses(omega, r, theta)["thth"][0], pad)

    def racking_history(self, t: np.ndarray, u_centre: np.ndarray, r: float, pad: float = 4.0) -> np.ndarray:
        """u_1(r, 90 deg, t) - u_1(r, 270 deg, t) (m, `racking`) for the incident displacement
        history u_centre(t) (`history`)."""
        return self.history(t, u_centre, lambda omega: self.racking(omega, r), pad)

    def _from_free_field(self, freefield, centre, times: np.ndarray, synthesis) -> np.ndarray:
        long = np.arange(3 * len(times)) * (times[1] - times[0]) + times[0]
        u_centre = freefield.displacement(np.asarray(centre, dtype=float)[None, :], long)[:, 0, 0]
        return synthesis(long, u_centre)[:len(times)]

    def hoop_stress_from_free_field(self, freefield, centre, times: np.ndarray, r: float, theta: float) -> np.ndarray:
        """sigma_thth(t) at (r, theta) (Pa) for a scene's incident wave: its free field's displacement
        along x at the cavity's `centre` (m, 3) over three times the `times` (uniform, the wavelet
        whole) through the series (`hoop_stress_history`), cut to `times`."""
        return self._from_free_field(freefield, centre, times,
                                     lambda long, u: self.hoop_stress_history(long, u, r, theta))

    def racking_from_free_field(self, freefield, centre, times: np.ndarray, r: float) -> np.ndarray:
        """The crown's horizontal displacement relative to the invert's at distance r (m, `racking`)
        for a scene's incident wave, as `hoop_stress_from_free_field`."""
        return self._from_free_field(freefield, centre, times, lambda long, u: self.racking_history(long, u, r))


class LinedCavitySV(CavitySV):
    """Vertically travelling SV scattered by a lined circular tunnel: rock (E, nu, rho) outside the
    excavation radius `b`, an elastic lining (lining_E, lining_nu, lining_rho) in a <= r <= b
    (a = b - thickness) bonded to it (traction and displacement continuous at b), its inner face
    r = a free; plane strain (docs/lined_tunnel.md "The exact dynamic answer").

    Per order n, six unknowns: the rock's outgoing A_n H_n(k_p r), B_n H_n(k_s r) and the lining's
    standing C_n J_n(k_pl r) + D_n Y_n(k_pl r) (phi), E_n J_n(k_sl r) + F_n Y_n(k_sl r) (psi); six
    conditions: sigma_rr, sigma_rtheta, u_r, u_theta continuous at b, sigma_rr = sigma_rtheta = 0 at
    a. The system is solved with its rows and columns scaled to unit size (the Neumann and Hankel
    terms of high order grow like (2 n / k r)^n). The incident wave and the history synthesis are
    CavitySV's (the incident amplitude U at the centre, the rock's wave numbers)."""

    def __init__(self, b: float, thickness: float, lining_E: float, lining_nu: float, lining_rho: float,
                 E: float, nu: float, rho: float):
        if not 0.0 < thickness < b:
            raise ValueError(f"LinedCavitySV: thickness = {thickness!r} must lie in (0, b = {b!r})")
        for name, value, allowed in (("E", E, E > 0.0), ("lining_E", lining_E, lining_E > 0.0),
                                     ("nu", nu, -1.0 < nu < 0.5), ("lining_nu", lining_nu, -1.0 < lining_nu < 0.5),
                                     ("rho", rho, rho > 0.0), ("lining_rho", lining_rho, lining_rho > 0.0)):
            if not allowed:
                raise ValueError(f"LinedCavitySV: {name} = {value!r} is out of range (E, rho > 0; nu in (-1, 0.5))")
        super().__init__(b, E, nu, rho)   # self.a: the excavation radius b, which sets the number of terms
        self.outer = b
        self.inner = b - thickness
        self.lining_mu = lining_E / (2.0 * (1.0 + lining_nu))
        self.lining_lam = lining_E * lining_nu / ((1.0 + lining_nu) * (1.0 - 2.0 * lining_nu))
        self.lining_cs = math.sqrt(self.lining_mu / lining_rho)
        self.lining_cp = math.sqrt((self.lining_lam + 2.0 * self.lining_mu) / lining_rho)

    def _lining_terms(self, n, r, omega) -> list[dict]:
        """The lining's four standing terms (phi J, phi Y, psi J, psi Y) at radius r."""
        kp, ks = omega / self.lining_cp, omega / self.lining_cs
        lam, mu = self.lining_lam, self.lining_mu
        return [_term_fields(n, r, lam, mu, kp, f=_radial("J", n, kp, r)),
                _term_fields(n, r, lam, mu, kp, f=_radial("Y", n, kp, r)),
                _term_fields(n, r, lam, mu, kp, g=_radial("J", n, ks, r)),
                _term_fields(n, r, lam, mu, kp, g=_radial("Y", n, ks, r))]

    def _rock_terms(self, n, r, omega, U) -> tuple[dict, list[dict]]:
        """The incident term and the rock's two outgoing terms at radius r."""
        kp, ks = omega / self.cp, omega / self.cs
        incident = _term_fields(n, r, self.lam, self.mu, kp,
                                g=tuple(U / (1j * ks) * z for z in _radial("J", n, ks, r)))
        return incident, [_term_fields(n, r, self.lam, self.mu, kp, f=_radial("H", n, kp, r)),
                          _term_fields(n, r, self.lam, self.mu, kp, g=_radial("H", n, ks, r))]

    def coefficients(self, omega: float, U: complex = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(orders n, (len(n), 6) coefficients A, B, C, D, E, F) at angular frequency omega > 0."""
        n = np.arange(-self.terms(omega), self.terms(omega) + 1)
        a, b = self.inner, self.outer
        incident, rock = self._rock_terms(n, b, omega, U)
        lining_b = self._lining_terms(n, b, omega)
        lining_a = self._lining_terms(n, a, omega)
        matrix = np.zeros((len(n), 6, 6), dtype=complex)
        rhs = np.zeros((len(n), 6), dtype=complex)
        for row, key in enumerate(("rr", "rth", "ur", "uth")):   # continuity at b: rock - lining = 0
            for column, term in enumerate(rock):
                matrix[:, row, column] = term[key]
            for column, term in enumerate(lining_b):
                matrix[:, row, 2 + column] = -term[key]
            rhs[:, row] = -incident[key]
        for row, key in ((4, "rr"), (5, "rth")):                  # the free inner face
            for column, term in enumerate(lining_a):
                matrix[:, row, 2 + column] = term[key]
        columns = np.abs(matrix).max(axis=1, keepdims=True)
        columns[columns == 0.0] = 1.0
        matrix = matrix / columns
        rows = np.abs(matrix).max(axis=2, keepdims=True)
        rows[rows == 0.0] = 1.0
        solution = np.linalg.solve(matrix / rows, (rhs / rows[..., 0])[..., None])[..., 0]
        return n, solution / columns[:, 0, :]

    def fields(self, omega: float, r: float, theta, U: complex = 1.0) -> dict:
        """Total sigma_rr, sigma_thth, sigma_rth (Pa) and u_r, u_theta (m) at (r, theta): in the rock
        (incident + scattered) for r >= b, in the lining for a <= r < b."""
        if not r >= self.inner:
            raise ValueError(f"LinedCavitySV.fields: r = {r!r} lies in the opening (r < a = {self.inner!r})")
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        n, x = self.coefficients(omega, U)
        modes = np.exp(1j * np.outer(theta, n))
        if r >= self.outer:
            incident, rock = self._rock_terms(n, r, omega, U)
            return {key: modes @ (incident[key] + x[:, 0] * rock[0][key] + x[:, 1] * rock[1][key])
                    for key in _FIELDS}
        lining = self._lining_terms(n, r, omega)
        return {key: modes @ sum(x[:, 2 + k] * lining[k][key] for k in range(4)) for key in _FIELDS}

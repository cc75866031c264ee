"""Analytical free field of a homogeneous half-space under plane P, SV and SH waves.

The field is a sum of plane-wave components (docs/method.md section 6): component j moves
u_j(x, t) = a_j y_j(t - tau_j(x)), with a_j = R_j d_j (m per unit waveform), y_j a
waveform table (the input g, its Hilbert transform, or depth-filtered versions of
them) and tau_j = p_j . x + offset_j a delay linear in x (s).  Its strain is
eps_j = E_j y_j'(t - tau_j) with E_j = -sym(a_j (x) p_j) (s/m): from u = a g(t - p.x),
du_i/dx_k = -a_i p_k g'.

Waves of one incident component (angle th from the vertical, azimuth phi from +x
toward +y; e_h = (cos phi, sin phi, 0), e_t = e_z x e_h; polarisations as in
`reflection`):

* incident, upgoing: tau = k.(x - x0)/c, k = sin th e_h + cos th e_z;
* reflected, downgoing, sharing the horizontal slowness s (Snell):
  tau = s e_h.(x - x0) + eta_inc (z_s - z0) + eta_r (z_s - z).

Complex reflection coefficients (SV beyond the critical angle).  With the time
dependence e^{i w t} and w > 0 a complex amplitude c acts on g as
Re(c) g - Im(c) H[g] (H[cos] = sin, see `waveforms`): each complex wave becomes two
real components, one on g and one on H[g].  The reflected P is then evanescent:
for w > 0 its vertical slowness is -i kappa, so below the surface (depth d) it is
filtered by exp(-|w| kappa d) (a Poisson-kernel convolution in time).  That filter
is applied by FFT on a uniform depth grid spanning the model and the tables are
interpolated linearly in depth; its delay keeps only the horizontal part
s e_h.(x - x0) + eta_inc (z_s - z0).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyfem.material import Material
from pyfem.seismic import reflection
from pyfem.seismic.waveforms import WaveformTables, hilbert_pair, hilbert_response, spectral_filter

E_Z = np.array([0.0, 0.0, 1.0])


class ReferencePointWarning(UserWarning):
    """A user-given reference point makes the start of the input motion miss the model."""


@dataclass(frozen=True)
class IncidentWave:
    """One incident plane wave travelling upward.

    Attributes:
        wave_type: "P", "SV" or "SH".
        angle: angle of the propagation direction from the vertical, degrees, 0..90.
        azimuth: azimuth of the horizontal propagation direction from +x toward +y, degrees.
        scale: factor on the input waveform g (dimensionless), e.g. 2/3 for the P of the paper.
    """

    wave_type: str
    angle: float = 0.0
    azimuth: float = 0.0
    scale: float = 1.0

    def __post_init__(self):
        reflection.check_wave_type(self.wave_type)
        reflection.check_angle(self.angle)
        if not np.isfinite(self.azimuth):
            raise ValueError(f"azimuth = {self.azimuth!r}: allowed is a finite angle in degrees")
        if not np.isfinite(self.scale):
            raise ValueError(f"scale = {self.scale!r}: allowed is a finite number")

    @property
    def horizontal_direction(self) -> np.ndarray:
        """e_h, unit horizontal vector of propagation (3,)."""
        phi = np.radians(self.azimuth)
        return np.array([np.cos(phi), np.sin(phi), 0.0])

    @property
    def direction(self) -> np.ndarray:
        """k, unit propagation direction (3,), upward."""
        th = np.radians(self.angle)
        return np.sin(th) * self.horizontal_direction + np.cos(th) * E_Z


@dataclass
class PlaneWaveComponent:
    """One real plane-wave component u = amplitude y(t - tau(x)).

    Attributes:
        name: what the component is, e.g. "SV incident", "SV->P reflected (quadrature)".
        amplitude: (3,) displacement per unit table value (m/m).
        slowness: (3,) gradient of the delay, s/m.
        delay_offset: tau(x) = slowness . x + delay_offset, s.
        strain: (3,3) strain per unit table derivative y' (s/m).
        table: waveform table id, or -1 when the table depends on depth.
        depth_tables: (n_depths,) table ids on `depths` (evanescent waves), else None.
        depths: (n_depths,) uniform depths below the free surface, m, else None.
    """

    name: str
    amplitude: np.ndarray
    slowness: np.ndarray
    delay_offset: float
    strain: np.ndarray
    table: int = 0
    depth_tables: np.ndarray | None = None
    depths: np.ndarray | None = None


def _sym_outer(a, p):
    return 0.5 * (np.outer(a, p) + np.outer(p, a))


def _box_corners(model_bounds):
    low, high = (np.asarray(b, dtype=float) for b in model_bounds)
    return np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])


class FreeField:
    """Total free field (incident + free-surface reflections) of plane waves in a half-space.

    Args:
        waves: list of IncidentWave (or dicts with keys wave_type/type, angle, azimuth, scale).
        E: Young's modulus of the reference medium, Pa.
        nu: Poisson's ratio.
        rho: density, kg/m^3.
        surface: z of the free surface, m; None: the incident waves only (no reflection).
        waveform: the input displacement g at the reference point: a WaveformTables
            (its table 0 is g) or a function t -> (g m, g' m/s, g'' m/s^2).  A function
            is used exactly by the reference methods and sampled on `table_grid` for
            the kernel's tables.
        table_grid: (t0 s, dt s, n_samples) of the tables when `waveform` is a function.
        reference_point: x0 (3,), m, where the incident wave moves as g.  Default: per
            incident wave, the corner of `model_bounds` that its wavefront reaches first
            (minimum of k.x), so that no delay in the model is negative.
        model_bounds: ((x, y, z) min, (x, y, z) max) of the model, m.  Needed for the
            default reference point and for the depth grid of evanescent waves.
        depth_step: spacing of the depth grid of evanescent waves, m; default
            0.1 / (kappa w_rms), which keeps the linear-interpolation error of
            exp(-w kappa d) near 1e-3 at the rms frequency w_rms of g.
        padding_factor: zero padding of the FFTs (Hilbert transform, depth filter).

    Attributes:
        components: list of PlaneWaveComponent.
        tables: WaveformTables read by the kernel (table 0 is g).
        material: the reference medium (pyfem.material.Material).
        lam, mu, c_p, c_s, rho: its constants (Pa, Pa, m/s, m/s, kg/m^3).
    """

    def __init__(self, waves, E, nu, rho, surface=None, waveform=None, table_grid=None,
                 reference_point=None, model_bounds=None, depth_step=None, padding_factor=4):
        self.material = Material(E=E, nu=nu, rho=rho)
        self.lam, self.mu = self.material.lame
        self.c_p, self.c_s = self.material.p_wave_speed, self.material.s_wave_speed
        self.rho = self.material.rho
        self.waves = [w if isinstance(w, IncidentWave) else IncidentWave(
            wave_type=w.get("wave_type", w.get("type")), angle=w.get("angle", 0.0),
            azimuth=w.get("azimuth", 0.0), scale=w.get("scale", 1.0)) for w in waves]
        if not self.waves:
            raise ValueError("waves = []: allowed is a list of at least one incident wave")
        if surface is not None and not np.isfinite(surface):
            raise ValueError(f"surface = {surface!r} m: allowed is a finite z or None")
        self.surface = None if surface is None else float(surface)
        self.model_bounds = None if model_bounds is None else (np.asarray(model_bounds[0], dtype=float),
                                                                np.asarray(model_bounds[1], dtype=float))
        # A surface at the model's top is allowed: mesh coordinates carry round-off (60.000000000000014).
        if self.model_bounds is not None and self.surface is not None and self.model_bounds[1][2] > \
                self.surface + 1e-9 * max(float(np.max(self.model_bounds[1] - self.model_bounds[0])), 1.0):
            raise ValueError(f"surface = {surface!r} m: allowed is z_s >= the model's top "
                             f"z = {self.model_bounds[1][2]!r} m")
        self.padding_factor = padding_factor
        self._set_waveform(waveform, table_grid)
        self._depth_step = depth_step
        self._hilbert_table = None
        self.components: list[PlaneWaveComponent] = []
        for wave in self.waves:
            self.components.extend(self._wave_components(wave, self._reference_point(wave, reference_point)))

    # ------------------------------------------------------------------ construction
    def _set_waveform(self, waveform, table_grid):
        if isinstance(waveform, WaveformTables):
            self.exact_waveform = None
            self.tables = WaveformTables(t0=waveform.t0, dt=waveform.dt, g=waveform.g[:1].copy(),
                                         dg=waveform.dg[:1].copy(), ddg=waveform.ddg[:1].copy())
        elif callable(waveform):
            if table_grid is None or len(table_grid) != 3:
                raise ValueError(f"table_grid = {table_grid!r}: allowed is (t0 s, dt s, n_samples) "
                                 "when the waveform is a function")
            self.exact_waveform = waveform
            self.tables = WaveformTables.from_function(waveform, *table_grid)
        else:
            raise ValueError(f"waveform = {waveform!r}: allowed is a WaveformTables or a function "
                             "t -> (g, g', g'')")

    def _reference_point(self, wave, reference_point):
        if reference_point is not None:
            x0 = np.asarray(reference_point, dtype=float)
            if x0.shape != (3,) or not np.all(np.isfinite(x0)):
                raise ValueError(f"reference_point = {reference_point!r}: allowed is a finite point (3,)")
            return x0
        if self.model_bounds is None:
            raise ValueError("reference_point = None and model_bounds = None: give one of them")
        corners = _box_corners(self.model_bounds)
        return corners[np.argmin(corners @ wave.direction)]

    def _wave_components(self, wave, x0):
        e_h = wave.horizontal_direction
        e_t = np.cross(E_Z, e_h)
        c_inc = self.c_p if wave.wave_type == "P" else self.c_s
        k = wave.direction
        th = np.radians(wave.angle)
        label = wave.wave_type
        if wave.wave_type == "P":
            d_inc = k
        elif wave.wave_type == "SV":
            d_inc = np.cos(th) * e_h - np.sin(th) * E_Z
        else:
            d_inc = e_t
        p_inc = k / c_inc
        components = [self._real_component(f"{label} incident", wave.scale * d_inc, p_inc, -p_inc @ x0, 0)]
        if self.surface is None:
            return components

        z_s = self.surface
        s = np.sin(th) / c_inc
        eta_inc = np.cos(th) / c_inc
        # Delay of a downgoing wave: tau = s e_h.x - eta_r z + offset.
        base_offset = -s * (e_h @ x0) + eta_inc * (z_s - x0[2])
        coefficients = reflection.free_surface_coefficients(wave.wave_type, wave.angle, self.c_p, self.c_s)
        if wave.wave_type == "SH":
            eta_s = np.sqrt(max(1.0 / self.c_s**2 - s**2, 0.0))
            p_r = s * e_h - eta_s * E_Z
            components.append(self._real_component("SH reflected", wave.scale * e_t, p_r,
                                                   base_offset + eta_s * z_s, 0))
            return components

        def to_3d(v):
            return v[0] * e_h + v[1] * E_Z

        in_plane = reflection.in_plane_waves(wave.wave_type, wave.angle, self.c_p, self.c_s)
        key_s, key_p = ("PS", "PP") if wave.wave_type == "P" else ("SS", "SP")
        for kind, key in (("S", key_s), ("P", key_p)):
            d, p = (to_3d(v) for v in in_plane[f"reflected_{kind}"])
            name = f"{label}->{'SV' if kind == 'S' else 'P'} reflected"
            complex_amplitude = wave.scale * coefficients[key] * d
            eta = -p[2]
            if abs(eta.imag) == 0.0:
                p = p.real
                offset = base_offset + eta.real * z_s
                components.append(self._real_component(name, complex_amplitude.real, p, offset, 0))
                if np.any(complex_amplitude.imag != 0.0):
                    components.append(self._real_component(f"{name} (quadrature)", -complex_amplitude.imag,
                                                           p, offset, self._hilbert()))
            else:
                components.extend(self._evanescent_components(name, complex_amplitude, p, s * e_h,
                                                              base_offset, kappa=-eta.imag))
        return components

    def _real_component(self, name, amplitude, slowness, offset, table):
        amplitude = np.asarray(amplitude, dtype=float)
        return PlaneWaveComponent(name=name, amplitude=amplitude, slowness=np.asarray(slowness, dtype=float),
                                  delay_offset=float(offset), strain=-_sym_outer(amplitude, slowness),
                                  table=int(table))

    def _hilbert(self):
        """Id of the table of H[g] (made on first use)."""
        if self._hilbert_table is None:
            t = self.tables
            self._hilbert_table = t.add(*hilbert_pair(t.g[0], t.dg[0], t.ddg[0], t.dt, self.padding_factor))
        return self._hilbert_table

    def _evanescent_components(self, name, complex_amplitude, complex_slowness, delay_slowness, offset, kappa):
        if self.model_bounds is None:
            raise ValueError("model_bounds = None: allowed only without evanescent waves; a post-critical "
                             "SV needs the model's z range for the depth grid of the reflected P")
        depth_top = self.surface - self.model_bounds[1][2]
        depth_bottom = self.surface - self.model_bounds[0][2]
        step = self._depth_step if self._depth_step is not None else self._default_depth_step(kappa)
        if not np.isfinite(step) or step <= 0.0:
            raise ValueError(f"depth_step = {step!r} m: allowed is a finite positive step")
        n_intervals = max(1, int(np.ceil((depth_bottom - depth_top) / step)))
        depths = np.linspace(depth_top, depth_bottom, n_intervals + 1)
        t = self.tables
        source = np.vstack([t.g[0], t.dg[0], t.ddg[0]])
        real_tables, quadrature_tables = [], []
        for depth in depths:
            def decay(omega, depth=depth):
                return np.exp(-omega * kappa * depth)

            def decay_hilbert(omega, depth=depth):
                return np.exp(-omega * kappa * depth) * hilbert_response(omega)

            real_tables.append(t.add(*spectral_filter(source, t.dt, decay, self.padding_factor)))
            quadrature_tables.append(t.add(*spectral_filter(source, t.dt, decay_hilbert, self.padding_factor)))
        complex_strain = -_sym_outer(complex_amplitude, complex_slowness)
        parts = (("", complex_amplitude.real, complex_strain.real, real_tables),
                 (" (quadrature)", -complex_amplitude.imag, -complex_strain.imag, quadrature_tables))
        return [PlaneWaveComponent(name=f"{name}, evanescent{suffix}", amplitude=amplitude,
                                   slowness=np.asarray(delay_slowness, dtype=float), delay_offset=float(offset),
                                   strain=strain, table=-1, depth_tables=np.array(tables, dtype=np.int64),
                                   depths=depths)
                for suffix, amplitude, strain, tables in parts]

    def _default_depth_step(self, kappa):
        g = self.tables.g[0]
        spectrum = np.abs(np.fft.rfft(g)) ** 2
        omega = 2.0 * np.pi * np.fft.rfftfreq(len(g), self.tables.dt)
        if spectrum.sum() == 0.0:
            return 1.0e30  # zero wave: a single depth interval is exact
        omega_rms = np.sqrt((omega**2 * spectrum).sum() / spectrum.sum())
        return 0.1 / (kappa * omega_rms) if omega_rms > 0.0 else 1.0e30

    # ------------------------------------------------------------------ evaluation
    def component_arrays(self, x) -> dict:
        """Per point, per slot: what the kernel needs to evaluate the free field.

        A plain component is one slot; an evanescent one is two slots (the depth-grid
        neighbours below and above the point, amplitudes scaled by the linear weights).

        Args:
            x: (m, 3) points, m.

        Returns:
            dict of arrays: "tau" (m, S) s, "table" (m, S) int32, "amplitude" (m, S, 3)
            m per unit table value, "strain" (m, S, 3, 3) and "stress" (m, S, 3, 3)
            per unit table derivative (s/m and Pa s/m).  u = sum amplitude y(t - tau),
            sigma = sum stress y'(t - tau).
        """
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"x shape {x.shape}: allowed is (m, 3)")
        taus, tables, amplitudes, strains = [], [], [], []
        m = len(x)
        for comp in self.components:
            tau = x @ comp.slowness + comp.delay_offset
            if comp.depth_tables is None:
                taus.append(tau)
                tables.append(np.full(m, comp.table))
                amplitudes.append(np.broadcast_to(comp.amplitude, (m, 3)))
                strains.append(np.broadcast_to(comp.strain, (m, 3, 3)))
                continue
            depth = self.surface - x[:, 2]
            grid = comp.depths
            # A model of zero height has grid[0] == grid[1]: any positive spacing then works.
            spacing = max(grid[1] - grid[0], np.finfo(float).tiny)
            tolerance = 1e-9 * max(spacing, 1.0)
            if np.any(depth < grid[0] - tolerance) or np.any(depth > grid[-1] + tolerance):
                raise ValueError(f"x: z from {x[:, 2].min()!r} to {x[:, 2].max()!r} m; allowed is the model's "
                                 f"z range {self.surface - grid[-1]!r} .. {self.surface - grid[0]!r} m "
                                 "(the depth grid of the evanescent wave)")
            position = np.clip((depth - grid[0]) / spacing, 0.0, len(grid) - 1)
            lower = np.minimum(np.floor(position).astype(np.int64), len(grid) - 2)
            weight_upper = position - lower
            for index, weight in ((lower, 1.0 - weight_upper), (lower + 1, weight_upper)):
                taus.append(tau)
                tables.append(comp.depth_tables[index])
                amplitudes.append(weight[:, None] * comp.amplitude)
                strains.append(weight[:, None, None] * comp.strain)
        strain = np.stack(strains, axis=1)
        trace = np.trace(strain, axis1=2, axis2=3)
        stress = self.lam * trace[..., None, None] * np.eye(3) + 2.0 * self.mu * strain
        return {"tau": np.stack(taus, axis=1), "table": np.stack(tables, axis=1).astype(np.int32),
                "amplitude": np.stack(amplitudes, axis=1), "strain": strain, "stress": stress}

    def start_cut(self, x) -> dict:
        """How much of the input motion a negative delay cuts off at the points x.

        The kernel starts at t = 0 from rest and evaluates a component at g(t - tau): a
        point with tau < 0 never sees g on [t0, t0 - tau] (t0 the first table time).
        Delays are linear in x, so for a box the corners tell the whole story; for other
        meshes pass the boundary nodes.

        Args:
            x: (m, 3) points, m.

        Returns:
            dict: "delay" the most negative delay over points and components, s (0 if none
            is negative); "point" (3,) where it occurs, m; "component" its name;
            "fraction" max |g| over the cut part of the input divided by max |g|
            (0 when nothing is cut).
        """
        x = np.asarray(x, dtype=float)
        taus = np.column_stack([x @ c.slowness + c.delay_offset for c in self.components])
        row, column = np.unravel_index(np.argmin(taus), taus.shape)
        delay = min(float(taus[row, column]), 0.0)
        result = {"delay": delay, "point": x[row].copy(), "component": self.components[column].name,
                  "fraction": 0.0}
        if delay < 0.0:
            t = self.tables
            g = t.g[0]
            peak = np.abs(g).max()
            times = t.t0 + t.dt * np.arange(len(g))
            cut = times <= t.t0 - delay
            if self.exact_waveform is not None:
                # The exact function: sample the cut interval finely (a short cut may hold no table sample).
                samples = np.linspace(t.t0, t.t0 - delay, 201)
                cut_peak = np.abs(self.exact_waveform(samples)[0]).max()
            else:
                cut_peak = np.abs(g[cut]).max() if np.any(cut) else abs(g[0])
            result["fraction"] = float(cut_peak / peak) if peak > 0.0 else 0.0
        return result

    def _waveform_values(self, table, t):
        """(g, g', g'') of each slot: t (nt, m) delayed times, table (m,) ids."""
        values = self.tables.evaluate(np.broadcast_to(table, t.shape), t)
        if self.exact_waveform is not None:
            exact = table == 0
            if np.any(exact):
                exact_values = self.exact_waveform(t[:, exact])
                for v, e in zip(values, exact_values):
                    v[:, exact] = e
        return values

    def _sum(self, x, t, derivative, tensor):
        arrays = self.component_arrays(x)
        t = np.atleast_1d(np.asarray(t, dtype=float))
        factor = arrays["stress"] if tensor else arrays["amplitude"]
        out = np.zeros((len(t),) + factor.shape[:1] + factor.shape[2:])
        for slot in range(arrays["tau"].shape[1]):
            delayed = t[:, None] - arrays["tau"][None, :, slot]
            y = self._waveform_values(arrays["table"][:, slot], delayed)[derivative]
            out += np.einsum("tm,m...->tm...", y, factor[:, slot])
        return out

    def displacement(self, x, t):
        """Free-field displacement (nt, m, 3), m, at points x (m, 3) m and times t (nt,) s."""
        return self._sum(x, t, 0, tensor=False)

    def velocity(self, x, t):
        """Free-field velocity (nt, m, 3), m/s."""
        return self._sum(x, t, 1, tensor=False)

    def acceleration(self, x, t):
        """Free-field acceleration (nt, m, 3), m/s^2."""
        return self._sum(x, t, 2, tensor=False)

    def stress(self, x, t):
        """Free-field stress (nt, m, 3, 3), Pa (tension positive), of the reference medium."""
        return self._sum(x, t, 1, tensor=True)

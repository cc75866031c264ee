"""Exact free field of horizontal layers over a half-space under oblique plane P, SV and SH waves.

The site (docs/method.md, "Layered free field"): layers of constant properties, top down from the
free surface at z = z_s, over a half-space. The incident wave travels up in the half-space and is
defined there as in `pyfem.seismic.freefield`: its displacement at the reference point x0 is
scale d_inc g(t) (the wave continued analytically to x0 when x0 lies in the layers). All waves
share the horizontal slowness s = sin(th)/c_inc (Snell), so the field is F(z, t - s e_h.(x - x0)):
a function of depth, delayed by the horizontal distance. F is computed per frequency.

Per frequency w > 0 (time dependence e^{i w t}) every medium holds four plane waves (P and SV, up
and down; SH: two), with vertical slownesses eta = sqrt(1/c^2 - s^2), or -i sqrt(s^2 - 1/c^2)
beyond the critical slowness (pyfem.seismic.reflection.vertical_slowness). A downgoing wave is
referenced at its layer's top and an upgoing one at its layer's bottom, so every exponential is
at most 1 in modulus in its own layer, evanescent waves included: the global matrix (Knopoff 1964;
Schmidt and Tango 1986) of the traction-free surface and the continuity of displacement and
traction at each interface is then well conditioned at any frequency and angle. The half-space
holds the known incident wave and the unknown downgoing waves.

The kernel reads the field as waveform tables (`FreeField` contract, `component_arrays`): per
depth, nine tables (u_h, u_z, u_t and the stress's time integrals S_hh, S_tt, S_zz, S_hz, S_tz,
S_ht in the wave's frame e_h, e_t, e_z; sigma = S'), each the inverse FFT of its transfer function
times the spectrum of g (and of g', g''). A point at a depth with its own tables is exact; where
a model has more distinct depths than `max_exact_depths` (a tetrahedral mesh), the points between
depth-grid nodes interpolate linearly (step: a fiftieth of the shortest shear wavelength of g).
At a depth on an interface the stress components that jump there (sigma_hh, sigma_tt, sigma_ht)
are the mean of the two sides, which is what the lumped load of a node with equal facets above
and below it receives.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from pyfem.material import Material
from pyfem.seismic.freefield import E_Z, FreeField, IncidentWave, PlaneWaveComponent, _box_corners
from pyfem.seismic.reflection import vertical_slowness
from pyfem.seismic.waveforms import WaveformTables

# The nine field components of one depth, in the wave's frame (h, t, z): displacement, then the
# time integral of stress.
COMPONENTS = ("u_h", "u_z", "u_t", "S_hh", "S_tt", "S_zz", "S_hz", "S_tz", "S_ht")


@dataclass(frozen=True)
class Layer:
    """One horizontal layer: thickness (m) and its material (E Pa, nu, rho kg/m^3)."""

    thickness: float
    E: float
    nu: float
    rho: float
    name: str = ""


class _Medium:
    def __init__(self, E, nu, rho):
        material = Material(E=E, nu=nu, rho=rho)
        self.lam, self.mu = material.lame
        self.c_p, self.c_s, self.rho = material.p_wave_speed, material.s_wave_speed, material.rho


class LayeredFreeField(FreeField):
    """Free field of horizontal layers over a half-space (module docstring); `FreeField`'s contract.

    Args:
        waves: list of IncidentWave (or dicts with keys type, angle, azimuth, scale), incident in
            the half-space.
        layers: list of Layer, top down from the surface.
        E, nu, rho: the half-space (Pa, -, kg/m^3).
        surface: z of the free surface, m.
        waveform, table_grid, reference_point, model_bounds: as FreeField.
        max_exact_depths: distinct depths that get tables of their own; beyond, a depth grid.
        padding_factor: FFT length / table length (at least; more for the layers' ringing).
    """

    def __init__(self, waves, layers, E, nu, rho, surface, waveform=None, table_grid=None,
                 reference_point=None, model_bounds=None, max_exact_depths=400, padding_factor=4):
        if surface is None or not np.isfinite(surface):
            raise ValueError(f"surface = {surface!r} m: allowed is a finite z (layers hang from the free surface)")
        if not layers:
            raise ValueError("layers = []: allowed is at least one layer (without layers use FreeField)")
        for index, layer in enumerate(layers):
            if not np.isfinite(layer.thickness) or layer.thickness <= 0.0:
                raise ValueError(f"layers[{index}].thickness = {layer.thickness!r} m: allowed is > 0")
        self.material = Material(E=E, nu=nu, rho=rho)
        self.lam, self.mu = self.material.lame
        self.c_p, self.c_s = self.material.p_wave_speed, self.material.s_wave_speed
        self.rho = self.material.rho
        self.surface = float(surface)
        self.layers = list(layers)
        self.media = [_Medium(layer.E, layer.nu, layer.rho) for layer in self.layers] + [_Medium(E, nu, rho)]
        depths = np.concatenate([[0.0], np.cumsum([layer.thickness for layer in self.layers])])
        self.interface_depths = depths  # depth of each layer's top; the last is the half-space's top
        self.model_bounds = None if model_bounds is None else (np.asarray(model_bounds[0], dtype=float),
                                                                np.asarray(model_bounds[1], dtype=float))
        if self.model_bounds is not None and self.model_bounds[1][2] > \
                self.surface + 1e-9 * max(float(np.max(self.model_bounds[1] - self.model_bounds[0])), 1.0):
            raise ValueError(f"surface = {surface!r} m: allowed is z_s >= the model's top "
                             f"z = {self.model_bounds[1][2]!r} m")
        self.waves = [w if isinstance(w, IncidentWave) else IncidentWave(
            wave_type=w.get("wave_type", w.get("type")), angle=w.get("angle", 0.0),
            azimuth=w.get("azimuth", 0.0), scale=w.get("scale", 1.0)) for w in waves]
        if not self.waves:
            raise ValueError("waves = []: allowed is a list of at least one incident wave")
        self.padding_factor = padding_factor
        self.max_exact_depths = int(max_exact_depths)
        self._set_waveform(waveform, table_grid)
        self.exact_waveform = None  # every slot reads a filtered table
        self.components = []
        self._frames = []
        for wave in self.waves:
            x0 = self._reference_point(wave, reference_point)
            e_h = wave.horizontal_direction
            c_inc = self.c_p if wave.wave_type == "P" else self.c_s
            s = np.sin(np.radians(wave.angle)) / c_inc
            # The horizontal delay of every wave; the vertical one is in the tables.
            self.components.append(PlaneWaveComponent(
                name=f"{wave.wave_type} incident, layered site", amplitude=np.zeros(3), slowness=s * e_h,
                delay_offset=float(-s * (e_h @ x0)), strain=np.zeros((3, 3)), table=0))
            self._frames.append((wave, x0, s, e_h, np.cross(E_Z, e_h)))
        self._prepare_spectra()
        self._exact = {}  # (wave index, rounded depth) -> first table id of its nine
        self._grid = {}   # wave index -> (depths, first table ids)

    # ------------------------------------------------------------------ spectra
    def _prepare_spectra(self):
        """Pads g with a lead (the layers may advance a wave past x0) and takes its spectra."""
        t = self.tables
        n = t.n_samples
        lead = 0.0
        ringing = 0.0
        half_space_top = self.surface - self.interface_depths[-1]
        for wave, x0, s, _, _ in self._frames:
            c_inc = self.c_p if wave.wave_type == "P" else self.c_s
            eta_inc = np.sqrt(max(1.0 / c_inc**2 - s**2, 0.0))
            lead = max(lead, eta_inc * (x0[2] - half_space_top))
        for layer, medium in zip(self.layers, self.media):
            ringing += 2.0 * layer.thickness / medium.c_s
        self.n_lead = int(np.ceil(max(lead, 0.0) / t.dt)) + (8 if lead > 0.0 else 0)
        n_total = n + self.n_lead
        # Room for the layers' reverberation to die out before the periodic wrap: 30 two-way times.
        n_fft = max(int(np.ceil(self.padding_factor * n_total)), n_total + int(np.ceil(30.0 * ringing / t.dt)))
        self.n_fft = scipy.fft.next_fast_len(n_fft, real=True)
        pad = np.zeros((3, self.n_lead))
        source = np.hstack([pad, np.vstack([t.g[0], t.dg[0], t.ddg[0]])])
        self.tables = WaveformTables(t0=t.t0 - self.n_lead * t.dt, dt=t.dt, g=source[0:1], dg=source[1:2],
                                     ddg=source[2:3])
        self._spectrum = scipy.fft.rfft(source, n=self.n_fft, axis=1)  # (3, n_freq)
        self.omega = 2.0 * np.pi * scipy.fft.rfftfreq(self.n_fft, t.dt)
        # w = 0: the limit, by a frequency far below the first bin (every transfer is finite there).
        self._omega_solve = self.omega.copy()
        self._omega_solve[0] = 1e-6 * self.omega[1]
        self._amplitudes = [self._solve(wave, x0, s) for wave, x0, s, _, _ in self._frames]

    def _waves_of(self, medium_index, polarisation):
        """Basis waves of a medium: (kind, direction) pairs, in the order of the unknowns."""
        kinds = ("S",) if polarisation == "SH" else ("P", "S")
        return [(kind, direction) for direction in ("down", "up") for kind in kinds
                if not (medium_index == len(self.layers) and direction == "up")]

    def _basis(self, medium_index, kind, direction, s, polarisation, z_depth):
        """Displacement (.., 3: h, z, t) and the stress's time integral (.., 6: hh, tt, zz, hz, tz, ht)
        per unit amplitude of one basis wave, at depths z_depth (k,), for all solve frequencies:
        arrays (n_freq, k, 3) and (n_freq, k, 6)."""
        medium = self.media[medium_index]
        c = medium.c_p if kind == "P" else medium.c_s
        eta = vertical_slowness(s, c)
        sign = 1.0 if direction == "up" else -1.0
        p_h, p_z = s, sign * eta
        last = medium_index == len(self.layers)
        top = self.interface_depths[medium_index]
        bottom = self.interface_depths[medium_index + 1] if not last else top
        reference_depth = bottom if (direction == "up" and not last) else top
        # z - z_ref = -(depth - depth_ref)
        dz = -(np.asarray(z_depth, dtype=float) - reference_depth)
        phase = np.exp(-1j * self._omega_solve[:, None] * p_z * dz[None, :])  # (n_freq, k)
        lam, mu = medium.lam, medium.mu
        if polarisation == "SH":
            u = np.zeros(3, dtype=complex)
            u[2] = 1.0
            stress = np.zeros(6, dtype=complex)
            stress[4] = -mu * p_z  # S_tz: sigma_tz = -i w mu p_z A -> its time integral -mu p_z A
            stress[5] = -mu * p_h
        else:
            if kind == "P":
                d_h, d_z = c * p_h, c * p_z
            else:
                d_h, d_z = c * eta, -sign * c * s
            divergence = d_h * p_h + d_z * p_z
            u = np.array([d_h, d_z, 0.0], dtype=complex)
            stress = -np.array([lam * divergence + 2.0 * mu * d_h * p_h, lam * divergence,
                                lam * divergence + 2.0 * mu * d_z * p_z, mu * (d_h * p_z + d_z * p_h), 0.0, 0.0],
                               dtype=complex)
        return phase[..., None] * u, phase[..., None] * stress

    def _solve(self, wave, x0, s):
        """Amplitudes (n_freq, unknowns) of every basis wave per unit spectrum of g."""
        polarisation = "SH" if wave.wave_type == "SH" else "PSV"
        n_layers = len(self.layers)
        columns = [(m, kind, direction) for m in range(n_layers + 1) for kind, direction in self._waves_of(m, polarisation)]
        n = len(columns)
        n_freq = len(self._omega_solve)
        matrix = np.zeros((n_freq, n, n), dtype=complex)
        rhs = np.zeros((n_freq, n), dtype=complex)
        half_space = self.media[-1]
        traction_scale = 1.0 / (half_space.rho * half_space.c_s)  # rows of O(1): S ~ rho c u
        if polarisation == "SH":
            pick_u, pick_t = [2], [4]
        else:
            pick_u, pick_t = [0, 1], [3, 2]  # u_h, u_z; S_hz, S_zz
        n_eq = len(pick_u)

        def values(m, kind, direction, depth):
            u, stress = self._basis(m, kind, direction, s, polarisation, [depth])
            return np.concatenate([u[:, 0, pick_u], traction_scale * stress[:, 0, pick_t]], axis=1)

        incident_kind = "P" if wave.wave_type == "P" else "S"
        c_inc = self.c_p if wave.wave_type == "P" else self.c_s
        eta_inc = np.sqrt(max(1.0 / c_inc**2 - s**2, 0.0))
        half_space_top = self.surface - self.interface_depths[-1]
        # The incident wave referenced at the half-space's top: scale g continued from x0.
        incident = wave.scale * np.exp(-1j * self._omega_solve * eta_inc * (half_space_top - x0[2]))
        row = 0
        # Traction-free surface (the top of medium 0).
        for j, (m, kind, direction) in enumerate(columns):
            if m == 0:
                matrix[:, row:row + n_eq, j] = values(m, kind, direction, 0.0)[:, n_eq:]
        if n_layers == 0:
            rhs[:, row:row + n_eq] = -incident[:, None] * values(0, incident_kind, "up", 0.0)[:, n_eq:]
        row += n_eq
        for interface in range(n_layers):  # between medium `interface` and `interface + 1`
            depth = self.interface_depths[interface + 1]
            for j, (m, kind, direction) in enumerate(columns):
                if m == interface:
                    matrix[:, row:row + 2 * n_eq, j] = values(m, kind, direction, depth)
                elif m == interface + 1:
                    matrix[:, row:row + 2 * n_eq, j] = -values(m, kind, direction, depth)
            if interface + 1 == n_layers:
                rhs[:, row:row + 2 * n_eq] = incident[:, None] * values(n_layers, incident_kind, "up", depth)
            row += 2 * n_eq
        assert row == n, (row, n)
        amplitudes = np.linalg.solve(matrix, rhs[..., None])[..., 0]
        return {"columns": columns, "amplitudes": amplitudes, "incident": incident,
                "incident_kind": incident_kind, "polarisation": polarisation}

    def transfer(self, wave_index, depths) -> np.ndarray:
        """Transfer functions (n_freq, k, 9) of the COMPONENTS at depths (k,) below the surface, per
        unit spectrum of g (displacement m/m, stress integrals Pa s/m)."""
        wave, x0, s, _, _ = self._frames[wave_index]
        solution = self._amplitudes[wave_index]
        depths = np.asarray(depths, dtype=float)
        out = np.zeros((len(self._omega_solve), len(depths), 9), dtype=complex)
        count = np.zeros(len(depths))
        bounds = self.interface_depths
        tolerance = 1e-9 * max(float(bounds[-1]), 1.0)
        for m in range(len(self.layers) + 1):
            top = bounds[m]
            bottom = bounds[m + 1] if m < len(self.layers) else np.inf
            # A depth on an interface belongs to both media: the sum over both, halved below,
            # averages the stress parts that jump there (the others agree on both sides).
            inside = (depths >= top - tolerance) & (depths <= bottom + tolerance)
            if not np.any(inside):
                continue
            count[inside] += 1.0
            waves = [(j, kind, direction) for j, (mm, kind, direction) in enumerate(solution["columns"]) if mm == m]
            if m == len(self.layers):
                waves.append((None, solution["incident_kind"], "up"))
            for j, kind, direction in waves:
                u, stress = self._basis(m, kind, direction, s, solution["polarisation"], depths[inside])
                amplitude = (solution["incident"] if j is None else solution["amplitudes"][:, j])[:, None, None]
                out[:, inside, :3] += amplitude * u
                out[:, inside, 3:] += amplitude * stress
        if np.any(count == 0.0):
            raise ValueError(f"depths from {depths.min()!r} m: allowed are depths >= 0 below the free surface")
        out /= count[None, :, None]
        # Components' order: u_h, u_z, u_t, S_hh, S_tt, S_zz, S_hz, S_tz, S_ht.
        return out

    def _tables_for(self, wave_index, depths) -> np.ndarray:
        """Adds nine tables per depth to self.tables; returns the first id of each depth's nine."""
        n = self.tables.n_samples
        depths = np.asarray(depths, dtype=float)
        k = len(depths)
        rows = [np.empty((k * 9, n)) for _ in range(3)]
        chunk = max(1, int(2.0e7 // (9 * len(self.omega))))  # a few hundred MB of spectra at most
        for start in range(0, k, chunk):
            stop = min(k, start + chunk)
            response = self.transfer(wave_index, depths[start:stop])  # (n_freq, chunk, 9)
            for derivative in range(3):  # g, g', g'' share the response
                spectra = self._spectrum[derivative][:, None, None] * response
                if self.n_fft % 2 == 0:
                    spectra[-1] = spectra[-1].real
                signals = scipy.fft.irfft(spectra, n=self.n_fft, axis=0)[:n]  # (n, chunk, 9)
                rows[derivative][9 * start:9 * stop] = signals.reshape(n, (stop - start) * 9).T
        first = self.tables.n_tables
        self.tables = WaveformTables(t0=self.tables.t0, dt=self.tables.dt, g=np.vstack([self.tables.g, rows[0]]),
                                     dg=np.vstack([self.tables.dg, rows[1]]), ddg=np.vstack([self.tables.ddg, rows[2]]))
        return first + 9 * np.arange(k)

    def _grid_tables(self, wave_index):
        if wave_index not in self._grid:
            if self.model_bounds is None:
                raise ValueError("model_bounds = None: allowed only with at most max_exact_depths distinct depths")
            top = self.surface - self.model_bounds[1][2]
            bottom = self.surface - self.model_bounds[0][2]
            g = self.tables.g[0]
            power = np.abs(np.fft.rfft(g)) ** 2
            frequency = np.fft.rfftfreq(len(g), self.tables.dt)
            cumulative = np.cumsum(power) / max(power.sum(), 1e-300)
            f_high = max(frequency[min(np.searchsorted(cumulative, 0.999), len(frequency) - 1)], frequency[1])
            step = min(m.c_s for m in self.media) / f_high / 50.0
            grid = np.linspace(top, bottom, max(2, int(np.ceil((bottom - top) / step)) + 1))
            inner = self.interface_depths[(self.interface_depths > top) & (self.interface_depths < bottom)]
            grid = np.unique(np.concatenate([grid, inner]))
            self._grid[wave_index] = (grid, self._tables_for(wave_index, grid))
        return self._grid[wave_index]

    # ------------------------------------------------------------------ evaluation
    def component_arrays(self, x) -> dict:
        """Per point, per slot (FreeField.component_arrays): nine slots per wave (per depth-grid
        neighbour when the point's depth has no tables of its own)."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"x shape {x.shape}: allowed is (m, 3)")
        m = len(x)
        depth = self.surface - x[:, 2]
        rounded = np.round(depth, 6)
        taus, tables, amplitudes, stresses = [], [], [], []
        for index, (wave, x0, s, e_h, e_t) in enumerate(self._frames):
            tau = x @ self.components[index].slowness + self.components[index].delay_offset
            frame = (e_h, E_Z, e_t)
            unit_u = [frame[0], frame[1], frame[2]]
            pairs = ((e_h, e_h), (e_t, e_t), (E_Z, E_Z), (e_h, E_Z), (e_t, E_Z), (e_h, e_t))
            unit_s = [np.outer(a, b) if a is b else np.outer(a, b) + np.outer(b, a) for a, b in pairs]
            unique = np.unique(rounded)
            known = {key[1] for key in self._exact if key[0] == index}
            new = [d for d in unique if d not in known]
            if new and len(known) + len(new) <= self.max_exact_depths:
                for d, first in zip(new, self._tables_for(index, np.array(new))):
                    self._exact[(index, d)] = first
                known = {key[1] for key in self._exact if key[0] == index}
            if all(d in known for d in unique):
                first = np.array([self._exact[(index, d)] for d in rounded])
                neighbours = [(first, np.ones(m))]
            else:
                grid, grid_first = self._grid_tables(index)
                position = np.interp(depth, grid, np.arange(len(grid)))
                lower = np.minimum(np.floor(position).astype(np.int64), len(grid) - 2)
                weight = position - lower
                neighbours = [(grid_first[lower], 1.0 - weight), (grid_first[lower + 1], weight)]
            for first, weight in neighbours:
                for c in range(9):
                    taus.append(tau)
                    tables.append(first + c)
                    if c < 3:
                        amplitudes.append(weight[:, None] * unit_u[c])
                        stresses.append(np.zeros((m, 3, 3)))
                    else:
                        amplitudes.append(np.zeros((m, 3)))
                        stresses.append(weight[:, None, None] * unit_s[c - 3])
        stress = np.stack(stresses, axis=1)
        return {"tau": np.stack(taus, axis=1), "table": np.stack(tables, axis=1).astype(np.int32),
                "amplitude": np.stack(amplitudes, axis=1), "stress": stress}


def layered_freefield_from_scene(scene, components, waveform, table_grid, model_bounds):
    """The LayeredFreeField of a scene's [[wave.layers]] (None when there are none)."""
    wave = scene["wave"]
    layers = wave.get("layers") or []
    if not layers:
        return None
    materials = scene["materials"]
    medium = materials[wave["medium"]]
    return LayeredFreeField(components, [Layer(thickness=layer["thickness"], E=materials[layer["medium"]]["E"],
                                               nu=materials[layer["medium"]]["nu"],
                                               rho=materials[layer["medium"]]["rho"], name=layer["medium"])
                                         for layer in layers],
                            medium["E"], medium["nu"], medium["rho"], surface=wave.get("surface"),
                            waveform=waveform, table_grid=table_grid, reference_point=wave.get("reference_point"),
                            model_bounds=model_bounds)

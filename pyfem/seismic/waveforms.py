"""Input waveforms g(t), their tables for the kernel, and spectral transforms of them.

A table holds g, g' and g'' on a uniform grid t0 + i dt.  `WaveformTables.evaluate`
follows the kernel's rule (ARCHITECTURE, SeismicInput): cubic Hermite interpolation
of (g, g') for g and of (g', g'') for g', zero before t0, held at the last sample
after the end, so that the Python reference and the C++ kernel agree.

Hilbert transform convention: H[cos(w t)] = sin(w t) (as the imaginary part of
scipy.signal.hilbert), i.e. in the spectrum of e^{i w t} the component at w is
multiplied by -i sign(w).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft
import scipy.special


def ricker(t, f0, amplitude=1.0, t0=None):
    """Displacement Ricker wavelet and its analytic first and second derivatives.

    g(t) = amplitude (1 - 2 a tau^2) exp(-a tau^2), a = (pi f0)^2, tau = t - t0.

    Args:
        t: times, s (any shape).
        f0: peak frequency, Hz (> 0).
        amplitude: peak displacement at t = t0, m.
        t0: time of the peak, s; default 1.5/f0 (the wavelet starts at ~1e-6 of its peak).

    Returns:
        (g m, g' m/s, g'' m/s^2), arrays of the shape of t.
    """
    f0 = float(f0)
    if not np.isfinite(f0) or f0 <= 0.0:
        raise ValueError(f"f0 = {f0!r} Hz: allowed is a finite positive frequency")
    if t0 is None:
        t0 = 1.5 / f0
    a = (np.pi * f0) ** 2
    tau = np.asarray(t, dtype=float) - t0
    x = a * tau**2
    envelope = amplitude * np.exp(-x)
    g = (1.0 - 2.0 * x) * envelope
    dg = (-6.0 * a * tau + 4.0 * a * x * tau) * envelope
    ddg = (-6.0 * a + 24.0 * a * x - 8.0 * a * x**2) * envelope
    return g, dg, ddg


def ricker_end(f0: float, t0: float) -> float:
    """When the Ricker wavelet centred at t0 is over: t0 + 1.5/f0, where its envelope
    exp(-(pi f0 (t - t0))^2) is 3e-10 of the peak (the default t0 = 1.5/f0 starts it as far before)."""
    return t0 + 1.5 / f0


def ricker_analytic_signal(z, f0, amplitude=1.0, t0=None):
    """Analytic signal g + i H[g] of the Ricker wavelet, continued to complex time z.

    Uses Ricker = -(amplitude / 2a) d^2/dtau^2 exp(-a tau^2) and the Faddeeva
    function w(x) = exp(-x^2) + 2i/sqrt(pi) Dawson(x), the analytic signal of
    exp(-x^2), analytic in the upper half plane.  At z = t + i b (b >= 0) the real
    part is the wavelet filtered by exp(-|w| b) and the imaginary part its Hilbert
    transform: an exact reference for post-critical (evanescent) fields.

    Args:
        z: complex times, s, with Im z >= 0.
        f0, amplitude, t0: as in `ricker`.

    Returns:
        (G, G', G'') complex arrays: the analytic signal and its first two derivatives.
    """
    if t0 is None:
        t0 = 1.5 / float(f0)
    a = (np.pi * float(f0)) ** 2
    root_a = np.sqrt(a)
    x = root_a * (np.asarray(z, dtype=complex) - t0)
    # Derivatives of w: w' = -2x w + 2i/sqrt(pi), w^(n+1) = -2n w^(n-1) - 2x w^(n).
    w = [scipy.special.wofz(x)]
    w.append(-2.0 * x * w[0] + 2j / np.sqrt(np.pi))
    for n in range(1, 4):
        w.append(-2.0 * n * w[n - 1] - 2.0 * x * w[n])
    scale = -0.5 * amplitude
    return tuple(scale * root_a**k * w[k + 2] for k in range(3))


@dataclass
class WaveformTables:
    """Tables of waveforms on one uniform time grid, as the kernel reads them.

    Attributes:
        t0: time of the first sample, s.
        dt: sample step, s (> 0).
        g: (n_tables, n_samples) values, m (per unit input amplitude).
        dg: (n_tables, n_samples) first time derivatives, m/s.
        ddg: (n_tables, n_samples) second time derivatives, m/s^2.
        n_samples: samples per table; give it (with g = None) to start with no table.
    """

    t0: float
    dt: float
    g: np.ndarray = field(default=None)
    dg: np.ndarray = field(default=None)
    ddg: np.ndarray = field(default=None)
    n_samples: int = 0

    def __post_init__(self):
        if not np.isfinite(self.dt) or self.dt <= 0.0:
            raise ValueError(f"dt = {self.dt!r} s: allowed is a finite positive step")
        if self.g is None:
            if self.n_samples < 2:
                raise ValueError(f"n_samples = {self.n_samples!r}: allowed is >= 2 when no table is given")
            self.g = np.zeros((0, self.n_samples))
            self.dg = np.zeros((0, self.n_samples))
            self.ddg = np.zeros((0, self.n_samples))
        self.g = np.ascontiguousarray(np.atleast_2d(self.g), dtype=np.float64)
        self.dg = np.ascontiguousarray(np.atleast_2d(self.dg), dtype=np.float64)
        self.ddg = np.ascontiguousarray(np.atleast_2d(self.ddg), dtype=np.float64)
        if not (self.g.shape == self.dg.shape == self.ddg.shape) or self.g.shape[1] < 2:
            raise ValueError(f"g, dg, ddg shapes {self.g.shape}, {self.dg.shape}, {self.ddg.shape}: "
                             "allowed are equal shapes (n_tables, n_samples >= 2)")
        self.n_samples = self.g.shape[1]

    @classmethod
    def from_function(cls, waveform, t0: float, dt: float, n_samples: int) -> "WaveformTables":
        """One table sampled from waveform(t) -> (g, g', g'') at t0 + i dt, i < n_samples."""
        if int(n_samples) < 2:
            raise ValueError(f"n_samples = {n_samples!r}: allowed is >= 2")
        times = t0 + dt * np.arange(int(n_samples))
        g, dg, ddg = (np.asarray(v, dtype=float) for v in waveform(times))
        return cls(t0=float(t0), dt=float(dt), g=g[None, :], dg=dg[None, :], ddg=ddg[None, :])

    @property
    def n_tables(self) -> int:
        return self.g.shape[0]

    @property
    def times(self) -> np.ndarray:
        """Sample times t0 + i dt, s."""
        return self.t0 + self.dt * np.arange(self.n_samples)

    def add(self, g, dg, ddg) -> int:
        """Appends one table (three arrays of n_samples values); returns its id."""
        rows = [np.asarray(v, dtype=np.float64).reshape(1, -1) for v in (g, dg, ddg)]
        if any(r.shape[1] != self.n_samples for r in rows):
            raise ValueError(f"table length {[r.shape[1] for r in rows]}: allowed is n_samples = {self.n_samples}")
        self.g = np.ascontiguousarray(np.vstack([self.g, rows[0]]))
        self.dg = np.ascontiguousarray(np.vstack([self.dg, rows[1]]))
        self.ddg = np.ascontiguousarray(np.vstack([self.ddg, rows[2]]))
        return self.n_tables - 1

    def evaluate(self, table_id, t):
        """Interpolated (g, g', g'') of table `table_id` at times t (any shape), kernel rule.

        g is the cubic Hermite interpolant of (g, g'), g' that of (g', g'') (as in the
        kernel); g'' is the derivative of the latter (Python reference only).  Zero
        before t0; after the last sample all three are held at their last values.

        Args:
            table_id: int, or an integer array broadcastable with t.
            t: times, s.
        """
        t = np.asarray(t, dtype=float)
        table_id = np.broadcast_to(np.asarray(table_id, dtype=np.int64), t.shape)
        x = (t - self.t0) / self.dt
        last = self.n_samples - 1
        before = x < 0.0
        after = x >= last
        i = np.clip(np.floor(x), 0, last - 1).astype(np.int64)
        r = np.clip(x - i, 0.0, 1.0)
        h00 = (1.0 + 2.0 * r) * (1.0 - r) ** 2
        h10 = r * (1.0 - r) ** 2
        h01 = r**2 * (3.0 - 2.0 * r)
        h11 = r**2 * (r - 1.0)
        dh00 = 6.0 * r * (r - 1.0)
        dh10 = (1.0 - r) * (1.0 - 3.0 * r)
        dh11 = r * (3.0 * r - 2.0)
        out = []
        for value, slope in ((self.g, self.dg), (self.dg, self.ddg)):
            v0, v1 = value[table_id, i], value[table_id, i + 1]
            s0, s1 = slope[table_id, i] * self.dt, slope[table_id, i + 1] * self.dt
            out.append((h00 * v0 + h10 * s0 + h01 * v1 + h11 * s1,
                        (dh00 * v0 + dh10 * s0 - dh00 * v1 + dh11 * s1) / self.dt))
        g, dg, ddg = out[0][0], out[1][0], out[1][1]
        g = np.where(after, self.g[table_id, last], np.where(before, 0.0, g))
        dg = np.where(after, self.dg[table_id, last], np.where(before, 0.0, dg))
        ddg = np.where(after, self.ddg[table_id, last], np.where(before, 0.0, ddg))
        return g, dg, ddg


def spectral_filter(arrays, dt, response, padding_factor=4):
    """Applies a frequency response to real signals sampled at dt, with zero padding.

    Args:
        arrays: (k, n) real signals (rows), zero-padded to >= padding_factor * n
            samples so that the periodic wrap of slowly decaying responses is small.
        dt: sample step, s.
        response: function of the angular frequencies w >= 0 (rad/s, rfft bins) giving
            the complex multiplier of e^{i w t}; negative frequencies take the conjugate.
        padding_factor: total length / n (>= 1).

    Returns:
        (k, n) filtered real signals.
    """
    arrays = np.atleast_2d(np.asarray(arrays, dtype=float))
    n = arrays.shape[1]
    if padding_factor < 1:
        raise ValueError(f"padding_factor = {padding_factor!r}: allowed is >= 1")
    n_fft = scipy.fft.next_fast_len(int(np.ceil(padding_factor * n)), real=True)
    spectrum = scipy.fft.rfft(arrays, n=n_fft, axis=1)
    omega = 2.0 * np.pi * scipy.fft.rfftfreq(n_fft, dt)
    multiplier = np.asarray(response(omega), dtype=complex)
    if n_fft % 2 == 0:
        # The Nyquist bin is its own conjugate: keep only the real part of the response.
        multiplier = multiplier.copy()
        multiplier[-1] = multiplier[-1].real
    return scipy.fft.irfft(spectrum * multiplier, n=n_fft, axis=1)[:, :n]


def hilbert_response(omega):
    """Multiplier of the Hilbert transform for w >= 0: -i (0 at w = 0), so H[cos] = sin."""
    return np.where(omega > 0.0, -1j, 0.0)


def hilbert_pair(g, dg, ddg, dt, padding_factor=4):
    """Hilbert transforms (H[g], H[g'], H[g'']) of sampled signals, computed spectrally.

    Convention H[cos(w t)] = sin(w t).  Each array is transformed on its own (H
    commutes with d/dt), so accurate derivatives given on input stay accurate.
    The Hilbert transform is not causal: H[g] is non-zero before g starts and decays
    like 1/t^2 for a zero-mean g; give the table a lead time of a few periods.

    Args:
        g, dg, ddg: (n,) samples of g (m), g' (m/s), g'' (m/s^2).
        dt: sample step, s.
        padding_factor: zero padding factor of the FFT.

    Returns:
        (h, dh, ddh) arrays (n,).
    """
    out = spectral_filter(np.vstack([g, dg, ddg]), dt, hilbert_response, padding_factor)
    return out[0], out[1], out[2]

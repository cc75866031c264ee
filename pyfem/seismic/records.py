"""Earthquake accelerograms: reading, processing into a smooth input motion g(t), plotting.

The kernel drives the model with the incident wave's displacement g(t) and its
derivatives g'(t), g''(t), tabulated on a uniform step and interpolated by cubic
Hermite polynomials (docs/ARCHITECTURE.md, "SeismicInput"). This module turns a
recorded accelerogram into those three tables:

1. ``read_record``: a plain text file (one value per line, or time/value columns)
   or a PEER NGA AT2 file, in g, m/s^2 or cm/s^2, to acceleration in m/s^2.
2. ``process_record``: cut a window, taper both ends (Tukey), resample band-limited
   onto the table step, band-pass (zero-phase Butterworth on a zero-padded copy),
   integrate, correct the baseline so the motion starts and ends at rest, scale to
   the target PGA.
3. ``as_waveform``: (t0, dt, g, g', g'') for the kernel tables.
4. ``plot_record``: acceleration, velocity and displacement against time.

Integration rule. Acceleration is taken as piecewise linear between samples and
integrated exactly: velocity by the trapezoid rule, displacement by
d_{k+1} = d_k + dt v_k + dt^2/6 (2 a_k + a_{k+1}). The displacement is then the
piecewise cubic whose nodal values and slopes are (d_k, v_k), which is exactly
what the kernel's cubic Hermite interpolation of (g, g') reconstructs, and whose
second derivative is the piecewise-linear acceleration. The processed triple
satisfies this rule to round-off, after every step (the baseline correction is
applied to the acceleration and the triple re-integrated; PGA scaling is linear).
"""
from __future__ import annotations

import dataclasses
import fractions
import math
import pathlib
import re
import warnings

import numpy as np
import scipy.signal

STANDARD_GRAVITY = 9.80665  # m/s^2, the "g" of accelerogram units

# Accepted spellings of the units of a record, and their factor to m/s^2.
_UNIT_FACTORS = {
    "g": STANDARD_GRAVITY,
    "m/s2": 1.0,
    "m/s^2": 1.0,
    "m/s**2": 1.0,
    "cm/s2": 0.01,
    "cm/s^2": 0.01,
    "cm/s**2": 0.01,
    "gal": 0.01,
}
_CANONICAL_UNITS = {"g": "g", "m/s2": "m/s2", "m/s^2": "m/s2", "m/s**2": "m/s2",
                    "cm/s2": "cm/s2", "cm/s^2": "cm/s2", "cm/s**2": "cm/s2", "gal": "cm/s2"}

_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][-+]?\d+)?"
_DT_IN_HEADER = re.compile(r"\bdt\b\s*[=:]?\s*(" + _NUMBER + r")\s*(ms|msec|s|sec|seconds?)?\b",
                           re.IGNORECASE)
_UNITS_IN_HEADER = re.compile(r"\bunits?\b\s*(?:of|:|=|in)?\s*([A-Za-z][A-Za-z0-9/^*]*)", re.IGNORECASE)

PRECURSOR_LEVEL = 1e-3  # default pad: filter precursor below this fraction of the peak acceleration
UNIFORM_STEP_TOLERANCE = 1e-3  # two-column files: largest time deviation from a uniform grid, in steps


@dataclasses.dataclass
class Record:
    """An accelerogram as read from a file.

    Attributes:
        t: (n,) sample times in s, uniform step.
        acceleration: (n,) ground acceleration in m/s^2.
        dt: time step in s.
        source: the file the record was read from.
        units: units of the values in the file ("g", "m/s2" or "cm/s2").
        header: the file's header / comment lines, for provenance.
    """

    t: np.ndarray
    acceleration: np.ndarray
    dt: float
    source: str
    units: str
    header: tuple = ()


@dataclasses.dataclass
class ProcessedRecord:
    """A processed input motion: acceleration, velocity, displacement on one uniform grid.

    The three series are consistent: velocity is the trapezoid integral of the
    acceleration and displacement the exact integral of the piecewise-linear
    acceleration (see the module docstring), both from rest at t[0].

    Attributes:
        t: (n,) times in s, t[0] = 0.
        acceleration: (n,) m/s^2.
        velocity: (n,) m/s.
        displacement: (n,) m.
        dt: time step in s.
        pga_g: max |acceleration| in g.
        residual_velocity: |final velocity| / max |velocity| (dimensionless).
        residual_displacement: |final displacement| / max |displacement| (dimensionless).
        notes: what each processing step did, in words and numbers.
        scale_factor: the factor that brought the motion to the target PGA (1 without one): applied
            to the whole raw record (scale "before_filter") or to the filtered, corrected window
            (scale "after_filter").
        scale: where the PGA was set, "before_filter" or "after_filter" (SCALE_MODES).
        target_pga_g: the pga asked for (g), None without one.
        raw_pga_g: max |acceleration| of the whole record as read, unscaled (g).
        window_raw_pga_g: max |acceleration| of the window as read, unscaled, before the taper (g).
        record_start: time in `t` (s) at which the window start of the record sits
            (the zero pad before it holds the zero-phase filter's precursor).
        window: (start, end) of the record used, in the record's own time (s).
        band: (low, high) corner frequencies actually applied, Hz.
        source: the file of the record.
    """

    t: np.ndarray
    acceleration: np.ndarray
    velocity: np.ndarray
    displacement: np.ndarray
    dt: float
    pga_g: float
    residual_velocity: float
    residual_displacement: float
    notes: list
    scale_factor: float = 1.0
    scale: str = "after_filter"
    target_pga_g: float | None = None
    raw_pga_g: float = 0.0
    window_raw_pga_g: float = 0.0
    record_start: float = 0.0
    window: tuple = (0.0, 0.0)
    band: tuple = (0.0, 0.0)
    source: str = ""

    @property
    def pgv(self) -> float:
        """max |velocity| of the processed motion (m/s)."""
        return float(np.abs(self.velocity).max())

    @property
    def pgd(self) -> float:
        """max |displacement| of the processed motion (m)."""
        return float(np.abs(self.displacement).max())

    def peaks_line(self) -> str:
        """One line: the raw record's peak, the window's raw peak, how the PGA was set, and the
        processed motion's PGA, PGV and PGD (`pyfem check` prints it)."""
        start, end = self.window
        if self.target_pga_g is None:
            how = "no pga: the record's own amplitude"
        elif self.scale == "before_filter":
            how = (f"scale \"before_filter\": the whole raw record x {self.scale_factor:.4g} (its peak "
                   f"{self.raw_pga_g * self.scale_factor:.3g} g), then windowed, tapered, filtered, corrected")
        else:
            how = f"scale \"after_filter\": the processed window x {self.scale_factor:.4g}"
        return (f"{pathlib.Path(self.source).name}: raw record peak {self.raw_pga_g:.3g} g, window [{start:g}, {end:g}] s "
                f"raw peak {self.window_raw_pga_g:.3g} g; {how}; processed motion PGA {self.pga_g:.3g} g, "
                f"PGV {100 * self.pgv:.3g} cm/s, PGD {100 * self.pgd:.3g} cm")


def units_factor(units: str) -> float:
    """Factor from the given acceleration units to m/s^2.

    Args:
        units: "g" (9.80665 m/s^2), "m/s2" or "cm/s2" (also "m/s^2", "cm/s^2", "gal").

    Returns:
        The factor (m/s^2 per unit).

    Raises:
        ValueError: unknown units.
    """
    key = str(units).strip().lower().replace(" ", "")
    if key not in _UNIT_FACTORS:
        raise ValueError(f"units={units!r} is not known; allowed: 'g', 'm/s2', 'cm/s2' "
                         f"(also 'm/s^2', 'cm/s^2', 'gal')")
    return _UNIT_FACTORS[key]


def _canonical_units(units: str) -> str:
    units_factor(units)  # validates
    return _CANONICAL_UNITS[str(units).strip().lower().replace(" ", "")]


def _parse_float(token: str) -> float:
    # Fortran output sometimes writes the exponent with D.
    return float(token.replace("D", "E").replace("d", "e"))


def _check_header_units(path, line_number: int, text: str, units: str) -> None:
    """A header that declares units other than the ones asked for is an error, not a guess."""
    match = _UNITS_IN_HEADER.search(text)
    if match is None:
        return
    declared = match.group(1).strip().lower()
    if declared not in _CANONICAL_UNITS:
        return
    if _CANONICAL_UNITS[declared] != _canonical_units(units):
        raise ValueError(f"{path}, line {line_number}: the header declares units {match.group(1)!r} "
                         f"but units={units!r} was given; pass units={_CANONICAL_UNITS[declared]!r}")


def _uniform_time(n: int, dt: float, t0: float = 0.0) -> np.ndarray:
    return t0 + dt * np.arange(n, dtype=float)


def _read_plain(path, units: str, dt):
    header = []
    header_dt = None
    values = []
    n_columns = None
    with open(path) as stream:
        for line_number, line in enumerate(stream, start=1):
            stripped = line.strip()
            if not stripped:
                continue
            if stripped.startswith("#"):
                header.append(stripped)
                _check_header_units(path, line_number, stripped, units)
                match = _DT_IN_HEADER.search(stripped)
                if match is not None and header_dt is None:
                    header_dt = _parse_float(match.group(1))
                    if (match.group(2) or "s").lower().startswith("ms"):
                        header_dt *= 1e-3
                continue
            tokens = [token for token in re.split(r"[,;\s]+", stripped) if token]
            try:
                row = [_parse_float(token) for token in tokens]
            except ValueError:
                raise ValueError(f"{path}, line {line_number}: expected numbers (acceleration, or time and "
                                 f"acceleration), got {stripped!r}") from None
            if len(row) not in (1, 2):
                raise ValueError(f"{path}, line {line_number}: expected 1 column (acceleration) or 2 columns "
                                 f"(time, acceleration), got {len(row)}: {stripped!r}")
            if n_columns is None:
                n_columns = len(row)
            elif len(row) != n_columns:
                raise ValueError(f"{path}, line {line_number}: expected {n_columns} column(s) like the first "
                                 f"data line, got {len(row)}: {stripped!r}")
            if not all(math.isfinite(value) for value in row):
                raise ValueError(f"{path}, line {line_number}: expected finite numbers, got {stripped!r}")
            values.append(row)
    if len(values) < 2:
        raise ValueError(f"{path}: expected at least 2 samples, found {len(values)}")
    data = np.array(values, dtype=float)
    if n_columns == 2:
        times = data[:, 0]
        step = (times[-1] - times[0]) / (len(times) - 1)
        if not step > 0.0:
            raise ValueError(f"{path}: the time column must increase, got t[0] = {times[0]} s and "
                             f"t[-1] = {times[-1]} s")
        deviation = np.abs(times - _uniform_time(len(times), step, times[0]))
        worst = int(np.argmax(deviation))
        if deviation[worst] > UNIFORM_STEP_TOLERANCE * step:
            raise ValueError(f"{path}: expected uniformly spaced times (step {step:.6g} s), but sample "
                             f"{worst + 1} is at t = {times[worst]} s, {deviation[worst]:.3g} s off the grid")
        for name, other in (("dt", dt), ("the header's dt", header_dt)):
            if other is not None and abs(other - step) > UNIFORM_STEP_TOLERANCE * step:
                raise ValueError(f"{path}: {name} = {other} s disagrees with the time column's "
                                 f"step {step:.6g} s")
        return _uniform_time(len(times), step, times[0]), data[:, 1], step, header
    if dt is None:
        dt = header_dt
    elif header_dt is not None and abs(dt - header_dt) > 1e-9 * dt:
        raise ValueError(f"{path}: dt = {dt} s given but the header says dt = {header_dt} s")
    if dt is None:
        raise ValueError(f"{path}: missing time step: a one-column file needs dt, either as the dt argument "
                         f"or in a header comment such as '# Time step: dt = 0.02 s'")
    return _uniform_time(len(data), dt, 0.0), data[:, 0], dt, header


def _read_at2(path, units: str, dt):
    with open(path) as stream:
        lines = stream.read().splitlines()
    if len(lines) < 5:
        raise ValueError(f"{path}: expected a PEER AT2 file (4 header lines, then values), "
                         f"found only {len(lines)} lines")
    header = [line.rstrip() for line in lines[:4]]
    _check_header_units(path, 3, lines[2], units)
    # NGA-West2: "NPTS=  5372, DT=   .0100 SEC"; NGA-West1: "5372    .0100    NPTS, DT".
    npts_match = re.search(r"NPTS\s*=\s*(\d+)", lines[3], re.IGNORECASE)
    dt_match = re.search(r"DT\s*=\s*(" + _NUMBER + ")", lines[3], re.IGNORECASE)
    if npts_match and dt_match:
        npts, header_dt = int(npts_match.group(1)), _parse_float(dt_match.group(1))
    else:
        old_style = re.match(r"\s*(\d+)\s+(" + _NUMBER + r")\s+NPTS", lines[3], re.IGNORECASE)
        if old_style is None:
            raise ValueError(f"{path}, line 4: expected 'NPTS= <count>, DT= <step> SEC' (PEER AT2), "
                             f"got {lines[3].strip()!r}")
        npts, header_dt = int(old_style.group(1)), _parse_float(old_style.group(2))
    if not header_dt > 0.0:
        raise ValueError(f"{path}, line 4: expected a positive DT, got {header_dt}")
    if dt is not None and abs(dt - header_dt) > 1e-9 * header_dt:
        raise ValueError(f"{path}: dt = {dt} s given but the AT2 header says DT = {header_dt} s")
    values = []
    for line_number, line in enumerate(lines[4:], start=5):
        for token in line.split():
            try:
                value = _parse_float(token)
            except ValueError:
                raise ValueError(f"{path}, line {line_number}: expected numbers, got {token!r}") from None
            if not math.isfinite(value):
                raise ValueError(f"{path}, line {line_number}: expected finite numbers, got {token!r}")
            values.append(value)
    if len(values) != npts:
        raise ValueError(f"{path}: the header says NPTS = {npts} but the file holds {len(values)} values")
    return _uniform_time(npts, header_dt), np.array(values, dtype=float), header_dt, header


def _detect_format(path) -> str:
    if pathlib.Path(path).suffix.lower() == ".at2":
        return "at2"
    with open(path) as stream:
        first_lines = [stream.readline() for _ in range(4)]
    if "PEER" in first_lines[0].upper() or "NPTS" in first_lines[3].upper():
        return "at2"
    return "plain"


def read_record(path, units: str = "g", dt: float | None = None, format: str = "auto") -> Record:
    """Read an accelerogram.

    Args:
        path: the file.
            "plain": '#' comment lines, then one value per line (needs dt, from the
            argument or a header comment containing "dt", e.g. "# Time step: dt = 0.02 s")
            or two columns time (s), value with a uniform step (checked). Columns may
            be separated by blanks or commas.
            "at2": PEER NGA AT2 (4 header lines, the 4th with NPTS and DT; values
            free-format, several per line).
        units: units of the values in the file: "g", "m/s2" or "cm/s2". A header that
            declares different units is an error.
        dt: time step in s, for one-column plain files; if the file states its own step
            the two must agree.
        format: "plain", "at2" or "auto" (".at2" extension or a PEER header: "at2",
            otherwise "plain").

    Returns:
        The record with acceleration in m/s^2.

    Raises:
        ValueError: unknown units or format, missing or inconsistent dt, a line that
            is not numeric, non-uniform times, wrong sample count; the message names
            the file and line.
    """
    try:
        factor = units_factor(units)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    if dt is not None and not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"{path}: dt={dt!r} must be a positive number of seconds (or None)")
    if format not in ("auto", "plain", "at2"):
        raise ValueError(f"{path}: format={format!r} is not known; allowed: 'auto', 'plain', 'at2'")
    if format == "auto":
        format = _detect_format(path)
    reader = _read_at2 if format == "at2" else _read_plain
    t, values, step, header = reader(path, units, dt)
    return Record(t=t, acceleration=factor * values, dt=float(step), source=str(path),
                  units=_canonical_units(units), header=tuple(header))


def integrate_acceleration(acceleration, dt: float):
    """Velocity and displacement of a piecewise-linear acceleration, from rest.

    Exact for acceleration linear between samples: v_{k+1} = v_k + dt/2 (a_k + a_{k+1})
    (trapezoid), d_{k+1} = d_k + dt v_k + dt^2/6 (2 a_k + a_{k+1}).

    Args:
        acceleration: (n,) m/s^2 (borrowed, not modified).
        dt: time step in s.

    Returns:
        (velocity (n,) in m/s, displacement (n,) in m), both zero at the first sample.
    """
    a = np.asarray(acceleration, dtype=float)
    velocity = np.concatenate(([0.0], np.cumsum(0.5 * dt * (a[:-1] + a[1:]))))
    displacement_steps = dt * velocity[:-1] + dt * dt / 6.0 * (2.0 * a[:-1] + a[1:])
    displacement = np.concatenate(([0.0], np.cumsum(displacement_steps)))
    return velocity, displacement


def _bandpass_sos(band, dt: float, order: int):
    return scipy.signal.butter(order, band, btype="bandpass", fs=1.0 / dt, output="sos")


def filter_pad_duration(low_corner: float, order: int = 4) -> float:
    """Zero padding, in s, to put before and after a record for acausal filtering.

    Boore (2005, BSSA 95(2)): T_pad = 1.5 n / f_c for a zero-phase filter of order n
    and low-cut corner f_c; we use it at each end (it is cheap), so the filter's
    precursor and tail decay inside the padding.

    Args:
        low_corner: high-pass corner, Hz.
        order: Butterworth order (applied twice by the zero-phase filter).
    """
    return 1.5 * order / low_corner


def bandpass_filter(acceleration, dt: float, band=(0.1, 25.0), order: int = 4):
    """Zero-phase Butterworth band-pass of a series, padded with zeros at both ends.

    The series is padded by `filter_pad_duration` at each end, filtered forward and
    backward (scipy.signal.sosfiltfilt, amplitude response |H(f)|^2, no phase shift)
    and cut back to its length.

    Args:
        acceleration: (n,) values (borrowed, not modified), any units.
        dt: time step in s.
        band: (low, high) corner frequencies in Hz, 0 < low < high < Nyquist.
        order: Butterworth order.

    Returns:
        (n,) filtered values (new array).
    """
    low, high = _check_band(band, dt)
    pad = int(math.ceil(filter_pad_duration(low, order) / dt))
    padded = np.concatenate((np.zeros(pad), np.asarray(acceleration, dtype=float), np.zeros(pad)))
    filtered = scipy.signal.sosfiltfilt(_bandpass_sos((low, high), dt, order), padded, padtype=None)
    return filtered[pad:len(padded) - pad]


def _check_band(band, dt: float):
    try:
        low, high = (float(value) for value in band)
    except (TypeError, ValueError):
        raise ValueError(f"band={band!r} must be (low, high) corner frequencies in Hz") from None
    nyquist = 0.5 / dt
    if not (0.0 < low < high < nyquist):
        raise ValueError(f"band={band!r} must satisfy 0 < low < high < Nyquist = {nyquist:.6g} Hz "
                         f"(dt = {dt} s)")
    return low, high


def _resampling_factors(dt_in: float, dt_out: float):
    """up, down with dt_out = dt_in * down / up, for scipy.signal.resample_poly."""
    ratio = fractions.Fraction(dt_in / dt_out).limit_denominator(1000)
    if ratio.numerator == 0 or abs(dt_in * ratio.denominator / ratio.numerator - dt_out) > 1e-9 * dt_out:
        raise ValueError(f"table_dt={dt_out} s must be a simple rational multiple of the record's "
                         f"dt = {dt_in} s (ratio with numerator and denominator up to 1000)")
    return ratio.numerator, ratio.denominator


def _baseline_correction(acceleration, dt: float, degree: int):
    """Smallest-displacement polynomial correction that brings the motion to rest at both ends.

    Finds c(t) = sum_j q_j P_j(2t/T - 1) (Legendre, degree `degree`) minimising
    || d[a - c] ||_2 (the corrected displacement: the usual polynomial fit to the
    drifting displacement) subject to, for the corrected acceleration a - c:
    a(0) = 0, a(T) = 0, v(T) = 0, d(T) = 0 (v(0) = d(0) = 0 by integration from rest).
    The constraints are met in the discrete rule, so only round-off remains.

    Returns:
        (n,) the correction c to subtract from the acceleration, m/s^2.
    """
    n = len(acceleration)
    tau = np.linspace(-1.0, 1.0, n)
    basis = np.polynomial.legendre.legvander(tau, degree)  # (n, degree+1)
    basis_velocity, basis_displacement = np.empty_like(basis), np.empty_like(basis)
    for j in range(degree + 1):
        basis_velocity[:, j], basis_displacement[:, j] = integrate_acceleration(basis[:, j], dt)
    velocity, displacement = integrate_acceleration(acceleration, dt)
    constraints = np.vstack((basis[0], basis[-1], basis_velocity[-1], basis_displacement[-1]))
    targets = np.array((acceleration[0], acceleration[-1], velocity[-1], displacement[-1]))
    # KKT system of: min |D q - d|^2 subject to C q = r; columns scaled for conditioning.
    scale = 1.0 / np.maximum(np.abs(basis_displacement).max(axis=0), np.finfo(float).tiny)
    d_matrix = basis_displacement * scale
    c_matrix = constraints * scale
    m, k = d_matrix.shape[1], c_matrix.shape[0]
    kkt = np.zeros((m + k, m + k))
    kkt[:m, :m] = d_matrix.T @ d_matrix
    kkt[:m, m:] = c_matrix.T
    kkt[m:, :m] = c_matrix
    rhs = np.concatenate((d_matrix.T @ displacement, targets))
    solution = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
    return basis @ (solution[:m] * scale)


SCALE_MODES = ("before_filter", "after_filter")
"""Where `process_record` sets the PGA: on the whole raw record before the window, taper, filter and
baseline correction (the processed peak is then lower), or on the processed window (its peak is the PGA)."""


def process_record(record: Record, window=None, taper: float = 0.05, band=(0.1, 25.0),
                   pga: float | None = None, table_dt: float | None = None, pad: float | None = None,
                   order: int = 4, baseline_degree: int = 5, scale: str = "after_filter") -> ProcessedRecord:
    """Process an accelerogram into a consistent (acceleration, velocity, displacement) input motion.

    Steps, in order:
    1. cut the window [start, end] (record time, s);
    2. cosine (Tukey) taper on the first and last `taper` fraction of the window;
    3. zero-pad by `filter_pad_duration` at both ends and resample band-limited onto
       `table_dt` (scipy.signal.resample_poly, polyphase anti-alias/anti-image FIR);
    4. zero-phase Butterworth band-pass (sosfiltfilt) on the padded series;
    5. keep `pad` s before the window start (they hold the zero-phase filter's
       precursor) and cut at the window end; the output time starts at 0;
    6. integrate from rest (exact for piecewise-linear acceleration) and subtract from
       the acceleration the low-order polynomial that minimises the displacement while
       making a(0) = a(T) = v(T) = d(T) = 0; re-integrate;
    7. scale all three series to max |a| = pga (g) exactly (scale "after_filter").
    With scale "before_filter" the whole raw record is scaled to max |a| = pga first (before step 1)
    and step 7 is skipped: the processed peak is then the window's share of it, lower.

    Args:
        record: the accelerogram (not modified).
        window: (start, end) in s of record time; None: the whole record.
        taper: fraction of the window tapered at each end, 0 <= taper <= 0.5.
        band: (low, high) band-pass corners in Hz. If high is above 0.8 x the Nyquist
            frequency of the output step, it is lowered to 0.8 x Nyquist with a warning
            (the Hermite tables need content well below Nyquist).
        pga: target peak ground acceleration in g; None keeps the record's amplitude.
        table_dt: output step in s, a rational multiple of record.dt (up to 1000/1000);
            None: record.dt.
        pad: seconds kept before the window start, s. They are zeros before filtering
            and hold the zero-phase filter's (acausal) precursor after it; the output
            always starts at rest (a = v = d = 0 at t = 0, imposed by the baseline
            correction). None: from where the precursor first exceeds PRECURSOR_LEVEL x
            the peak acceleration, so nothing of size is cut off (4.71 s for El Centro
            N-S [0, 20] s with band (0.1, 25) Hz; 0 for a record with a quiet start).
        order: Butterworth order (each pass).
        baseline_degree: degree of the polynomial acceleration correction (>= 3 for the
            four end conditions).
        scale: "after_filter" (the processed motion's peak is pga) or "before_filter" (the
            whole raw record's peak is pga); read only with a pga.

    Returns:
        The processed record (time from 0, step table_dt).

    Raises:
        ValueError: bad window, taper, band, pga, table_dt, pad, order, degree or scale.
    """
    dt_in = record.dt
    table_dt = dt_in if table_dt is None else float(table_dt)
    if not (math.isfinite(table_dt) and table_dt > 0.0):
        raise ValueError(f"table_dt={table_dt!r} must be a positive number of seconds")
    if not 0.0 <= taper <= 0.5:
        raise ValueError(f"taper={taper!r} must be a fraction of the window at each end, 0 <= taper <= 0.5")
    if pga is not None and not (math.isfinite(pga) and pga > 0.0):
        raise ValueError(f"pga={pga!r} must be a positive peak acceleration in g (or None)")
    if scale not in SCALE_MODES:
        raise ValueError(f"scale={scale!r} must be one of {', '.join(repr(m) for m in SCALE_MODES)}")
    if pad is not None and not (math.isfinite(pad) and pad >= 0.0):
        raise ValueError(f"pad={pad!r} must be a non-negative number of seconds (or None)")
    if int(order) != order or order < 1:
        raise ValueError(f"order={order!r} must be a positive integer")
    if int(baseline_degree) != baseline_degree or baseline_degree < 3:
        raise ValueError(f"baseline_degree={baseline_degree!r} must be an integer >= 3 (four end conditions)")
    try:
        low, high = (float(value) for value in band)
    except (TypeError, ValueError):
        raise ValueError(f"band={band!r} must be (low, high) corner frequencies in Hz") from None
    if not 0.0 < low < high:
        raise ValueError(f"band={band!r} must satisfy 0 < low < high (Hz)")
    notes = []

    # 1. Window.
    t_first, t_last = float(record.t[0]), float(record.t[-1])
    start, end = (t_first, t_last) if window is None else (float(window[0]), float(window[1]))
    first = int(round((start - t_first) / dt_in))
    last = int(round((end - t_first) / dt_in))
    if not (start < end and 0 <= first and last <= len(record.t) - 1 and last - first >= 2):
        raise ValueError(f"window={window!r} must satisfy start < end inside the record "
                         f"[{t_first:.6g}, {t_last:.6g}] s of {record.source}")
    raw_peak = float(np.abs(record.acceleration).max())
    window_acceleration = np.array(record.acceleration[first:last + 1], dtype=float)
    window_raw_peak = float(np.abs(window_acceleration).max())
    start, end = float(record.t[first]), float(record.t[last])
    scale_factor = 1.0
    if pga is not None and scale == "before_filter":
        if raw_peak == 0.0:
            raise ValueError(f"pga={pga!r}: the record {record.source} is zero everywhere, nothing to scale")
        scale_factor = pga * STANDARD_GRAVITY / raw_peak
        window_acceleration *= scale_factor
        notes.append(f"whole record scaled by {scale_factor:.6g} to PGA {pga:.6g} g before the window "
                     f"(raw peak {raw_peak / STANDARD_GRAVITY:.6g} g)")
    notes.append(f"window [{start:.6g}, {end:.6g}] s of {record.source}: {len(window_acceleration)} samples, "
                 f"dt = {dt_in:.6g} s, raw peak {window_raw_peak / STANDARD_GRAVITY:.6g} g "
                 f"(whole record {raw_peak / STANDARD_GRAVITY:.6g} g)")

    # 2. Taper (scipy's alpha is the tapered fraction of the whole window).
    window_acceleration *= scipy.signal.windows.tukey(len(window_acceleration), alpha=2.0 * taper)
    notes.append(f"cosine taper on {100 * taper:.3g} % of the window at each end")

    # 3. Zero padding (whole input steps, a multiple of `down` so the window start lands on the output grid)
    #    and band-limited resampling.
    up, down = _resampling_factors(dt_in, table_dt)
    requested_pad = 0.0 if pad is None else pad
    pad_duration = max(filter_pad_duration(low, order), requested_pad + 1.0)
    pad_in = down * int(math.ceil(pad_duration / (dt_in * down)))
    padded = np.concatenate((np.zeros(pad_in), window_acceleration, np.zeros(pad_in)))
    if (up, down) != (1, 1):
        padded = scipy.signal.resample_poly(padded, up, down)
        notes.append(f"resampled from dt = {dt_in:.6g} s to {table_dt:.6g} s "
                     f"(resample_poly up {up}, down {down})")
    onset = pad_in * up // down
    window_end = onset + (len(window_acceleration) - 1) * up // down

    # 4. Band-pass at the output rate.
    nyquist = 0.5 / table_dt
    if high > 0.8 * nyquist:
        message = (f"band[1] = {high:.6g} Hz is above 0.8 x Nyquist = {0.8 * nyquist:.6g} Hz of the step "
                   f"{table_dt:.6g} s; low-pass corner lowered to {0.8 * nyquist:.6g} Hz")
        warnings.warn(message, stacklevel=2)
        notes.append(message)
        high = 0.8 * nyquist
    if not low < high:
        raise ValueError(f"band={band!r}: low corner {low} Hz must be below the low-pass corner "
                         f"{high:.6g} Hz (0.8 x Nyquist of table_dt = {table_dt} s at most)")
    filtered = scipy.signal.sosfiltfilt(_bandpass_sos((low, high), table_dt, order), padded, padtype=None)
    notes.append(f"zero-phase Butterworth band-pass {low:.6g}-{high:.6g} Hz, order {order} per pass, "
                 f"{pad_in * dt_in:.6g} s zero padding at each end")

    # 5. Keep the precursor before the onset; the output starts at the first kept sample.
    if pad is None:
        peak = np.abs(filtered).max()
        above = np.flatnonzero(np.abs(filtered[:onset + 1]) > PRECURSOR_LEVEL * peak)
        first_kept = int(above[0]) if len(above) else onset
        notes.append(f"pad chosen where the filter precursor exceeds {PRECURSOR_LEVEL:g} x peak acceleration")
    else:
        first_kept = onset - int(round(pad / table_dt))
    acceleration = filtered[first_kept:window_end + 1].copy()
    record_start = (onset - first_kept) * table_dt
    notes.append(f"{record_start:.6g} s kept before the window start; precursor at the first sample "
                 f"{abs(acceleration[0]) / np.abs(acceleration).max():.2e} x peak")

    # 6. Baseline correction.
    velocity, displacement = integrate_acceleration(acceleration, table_dt)
    drift_velocity = abs(velocity[-1]) / np.abs(velocity).max()
    drift_displacement = abs(displacement[-1]) / np.abs(displacement).max()
    correction = _baseline_correction(acceleration, table_dt, int(baseline_degree))
    peak_before = np.abs(acceleration).max()
    acceleration -= correction
    velocity, displacement = integrate_acceleration(acceleration, table_dt)
    notes.append(f"baseline: final velocity / peak {drift_velocity:.3e} and displacement / peak "
                 f"{drift_displacement:.3e} before correction; degree-{baseline_degree} acceleration "
                 f"correction of max {np.abs(correction).max() / peak_before:.3e} x peak acceleration")

    # 7. Scale (linear: the triple stays consistent).
    if pga is not None and scale == "after_filter":
        scale_factor = pga * STANDARD_GRAVITY / np.abs(acceleration).max()
        acceleration *= scale_factor
        velocity *= scale_factor
        displacement *= scale_factor
        notes.append(f"scaled by {scale_factor:.6g} to PGA {pga:.6g} g")
    residual_velocity = abs(velocity[-1]) / np.abs(velocity).max()
    residual_displacement = abs(displacement[-1]) / np.abs(displacement).max()
    notes.append(f"final velocity / peak {residual_velocity:.3e}, final displacement / peak "
                 f"{residual_displacement:.3e}")
    return ProcessedRecord(
        t=_uniform_time(len(acceleration), table_dt), acceleration=acceleration, velocity=velocity,
        displacement=displacement, dt=table_dt, pga_g=float(np.abs(acceleration).max() / STANDARD_GRAVITY),
        residual_velocity=float(residual_velocity), residual_displacement=float(residual_displacement),
        notes=notes, scale_factor=float(scale_factor), scale=scale,
        target_pga_g=None if pga is None else float(pga), raw_pga_g=raw_peak / STANDARD_GRAVITY,
        window_raw_pga_g=window_raw_peak / STANDARD_GRAVITY, record_start=float(record_start), window=(start, end),
        band=(low, high), source=record.source)


def as_waveform(processed: ProcessedRecord):
    """The processed motion as kernel waveform tables.

    Args:
        processed: output of `process_record`.

    Returns:
        (t0 s, dt s, g (n,) m, dg (n,) m/s, ddg (n,) m/s^2): displacement, velocity and
        acceleration on the grid t0 + k dt, C-contiguous float64 copies. g, dg and ddg
        start at rest (g(t0) = dg(t0) = ddg(t0) = 0) and end at rest to round-off.
    """
    def table(values):
        return np.ascontiguousarray(values, dtype=np.float64).copy()

    return (float(processed.t[0]), float(processed.dt), table(processed.displacement),
            table(processed.velocity), table(processed.acceleration))


def plot_record(processed: ProcessedRecord, path, raw: Record | None = None) -> None:
    """PNG of the processed motion: acceleration (g), velocity (cm/s), displacement (cm) against time.

    Args:
        processed: output of `process_record`.
        path: the PNG file to write.
        raw: the record before processing, drawn in grey behind on the processed time
            axis, multiplied by the same scale factor; its velocity and displacement are
            integrated without filtering or baseline correction (they show the drift
            the processing removes).
    """
    import matplotlib

    matplotlib.use("Agg")  # files only; no display on these machines
    import matplotlib.pyplot as plt

    panels = (("acceleration (g)", 1.0 / STANDARD_GRAVITY), ("velocity (cm/s)", 100.0),
              ("displacement (cm)", 100.0))
    series = (processed.acceleration, processed.velocity, processed.displacement)
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    if raw is not None:
        start, end = processed.window
        inside = (raw.t >= start - 0.5 * raw.dt) & (raw.t <= end + 0.5 * raw.dt)
        raw_time = raw.t[inside] - start + processed.record_start
        raw_acceleration = processed.scale_factor * raw.acceleration[inside]
        raw_series = (raw_acceleration, *integrate_acceleration(raw_acceleration, raw.dt))
        for ax, values, (_, factor) in zip(axes, raw_series, panels):
            ax.plot(raw_time, factor * values, color="0.7", lw=0.8, label="raw record (scaled, uncorrected)")
    for ax, values, (label, factor) in zip(axes, series, panels):
        ax.plot(processed.t, factor * values, "C0", lw=1.0, label="processed")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("t (s)")
    axes[0].set_title(f"{pathlib.Path(processed.source).name}: "
                      f"PGA {processed.pga_g:.3g} g, dt {processed.dt:.3g} s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

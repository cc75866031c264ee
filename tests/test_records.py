"""Accelerogram reading and processing (pyfem/seismic/records.py).

Readers: the same numbers written as plain (one and two columns) and PEER AT2 read
back identically; units are exact factors; the El Centro files have their known
size, step and PGA. Processing: exact PGA, start and end at rest, the triple
(a, v, d) satisfies the integration rule (checked with an independent trapezoid
integration and with the kernel's cubic Hermite reconstruction), the band-pass
keeps in-band and removes out-of-band sinusoids as its response says, and the
processed El Centro stays close to the raw record.
"""
import pathlib
import warnings

import numpy as np
import pytest
import scipy.integrate
import scipy.signal

from conftest import ROUNDOFF, rel_error
from pyfem.seismic import records
from pyfem.seismic.records import (STANDARD_GRAVITY, as_waveform, bandpass_filter, plot_record,
                                   process_record, read_record)

DATA = pathlib.Path(__file__).resolve().parents[1] / "data"
ELCENTRO = DATA / "elcentro_1940_ns.txt"
ELCENTRO_AT2 = DATA / "RSN6_IMPVALL.I_I-ELC180.AT2"


def synthetic_values(n=123, seed=7):
    """Values as they would be printed in a file (7 significant digits), in g."""
    rng = np.random.default_rng(seed)
    return np.array([float(f"{value:.7E}") for value in 0.3 * rng.standard_normal(n)])


def write_at2(path, values, dt):
    lines = ["PEER NGA STRONG MOTION DATABASE RECORD", "Synthetic, test",
             "ACCELERATION TIME SERIES IN UNITS OF G",
             f"NPTS= {len(values):6d}, DT= {dt:9.4f} SEC"]
    for start in range(0, len(values), 5):
        lines.append("".join(f"{value:15.7E}" for value in values[start:start + 5]))
    path.write_text("\n".join(lines) + "\n")


def write_plain(path, values, dt=None, two_columns=False, header="# Units: g\n"):
    text = header
    if dt is not None and not two_columns:
        text += f"# Time step: dt = {dt} s\n"
    for k, value in enumerate(values):
        text += f"{k * dt:.4f}, {value:.7E}\n" if two_columns else f"{value:.7E}\n"
    path.write_text(text)


@pytest.fixture(scope="module")
def elcentro_processed():
    record = read_record(ELCENTRO)
    return record, process_record(record, window=(0.0, 20.0), pga=0.32, table_dt=0.005)


# --- readers --------------------------------------------------------------------------------

def test_plain_one_column_two_columns_and_at2_give_the_same_series(tmp_path):
    values, dt = synthetic_values(), 0.01
    write_at2(tmp_path / "record.AT2", values, dt)
    write_plain(tmp_path / "one.txt", values, dt)
    write_plain(tmp_path / "two.csv", values, dt, two_columns=True)
    at2 = read_record(tmp_path / "record.AT2")
    one_column = read_record(tmp_path / "one.txt")
    two_columns = read_record(tmp_path / "two.csv", format="plain")
    expected = STANDARD_GRAVITY * values
    for record in (at2, one_column, two_columns):
        np.testing.assert_array_equal(record.acceleration, expected)
        assert abs(record.dt - dt) <= 1e-15
        np.testing.assert_allclose(record.t, dt * np.arange(len(values)), rtol=0, atol=1e-12)
        assert record.units == "g"
    # "auto" told the AT2 file by its header as well, whatever its name.
    (tmp_path / "record.dat").write_text((tmp_path / "record.AT2").read_text())
    np.testing.assert_array_equal(read_record(tmp_path / "record.dat").acceleration, expected)


def test_units_conversion_is_exact(tmp_path):
    values, dt = synthetic_values(), 0.02
    write_plain(tmp_path / "record.txt", values, header="")
    factors = {"g": 9.80665, "m/s2": 1.0, "m/s^2": 1.0, "cm/s2": 0.01, "gal": 0.01}
    for units, factor in factors.items():
        record = read_record(tmp_path / "record.txt", units=units, dt=dt)
        np.testing.assert_array_equal(record.acceleration, values * factor)
    assert len(factors) == 5


def test_elcentro_plain_file():
    record = read_record(ELCENTRO)
    assert len(record.acceleration) == 1559
    assert record.dt == 0.02
    assert record.t[-1] == pytest.approx(31.16, abs=1e-12)
    pga_g = np.abs(record.acceleration).max() / STANDARD_GRAVITY
    assert abs(pga_g - 0.319) < 0.001
    assert np.argmax(np.abs(record.acceleration)) * record.dt == pytest.approx(2.02, abs=1e-12)


def test_elcentro_at2_file():
    record = read_record(ELCENTRO_AT2)
    assert len(record.acceleration) == 5372
    assert record.dt == 0.01
    assert record.acceleration[0] == pytest.approx(0.9984852e-3 * STANDARD_GRAVITY, rel=1e-15)
    assert record.acceleration[-1] == pytest.approx(-0.1790158e-3 * STANDARD_GRAVITY, rel=1e-15)


@pytest.mark.parametrize("content, kwargs, expected_words", [
    ("# no step here\n0.1\n0.2\n0.3\n", {}, ["missing time step", "dt"]),
    ("# Time step: dt = 0.02 s\n0.1\n0.2\nabc\n0.3\n", {}, ["line 4", "expected numbers", "abc"]),
    ("# Time step: dt = 0.02 s\n0.1\n0.2 0.3 0.4\n", {}, ["line 3", "2 columns"]),
    ("0.0 0.1\n0.02 0.2\n0.05 0.3\n0.06 0.1\n", {}, ["uniformly spaced", "sample 3"]),
    ("# Time step: dt = 0.02 s\n0.1\n0.2\n", {"units": "furlongs"}, ["units='furlongs'", "allowed"]),
    ("# Units: cm/s^2\n# dt = 0.02 s\n0.1\n0.2\n", {"units": "g"}, ["line 1", "declares units", "cm/s2"]),
    ("# Time step: dt = 0.02 s\n0.1\n0.2\n", {"dt": 0.01}, ["dt = 0.01", "header says dt = 0.02"]),
])
def test_bad_plain_files_raise_value_error_naming_the_problem(tmp_path, content, kwargs, expected_words):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    with pytest.raises(ValueError) as error:
        read_record(path, **kwargs)
    message = str(error.value)
    for word in expected_words:
        assert word in message, message
    assert str(path) in message


def test_bad_at2_files_raise_value_error_naming_the_problem(tmp_path):
    values = synthetic_values(12)
    write_at2(tmp_path / "good.AT2", values, 0.01)
    lines = (tmp_path / "good.AT2").read_text().splitlines()
    cases = {
        "count.AT2": (lines[:3] + [lines[3].replace("12", "13")] + lines[4:], ["NPTS = 13", "12 values"]),
        "header.AT2": (lines[:3] + ["no counts here"] + lines[4:], ["line 4", "NPTS"]),
        "value.AT2": (lines[:5] + ["  0.1  x.y"] + lines[6:], ["line 6", "'x.y'"]),
    }
    for name, (content, expected_words) in cases.items():
        (tmp_path / name).write_text("\n".join(content) + "\n")
        with pytest.raises(ValueError) as error:
            read_record(tmp_path / name)
        for word in [str(tmp_path / name)] + expected_words:
            assert word in str(error.value), str(error.value)
    with pytest.raises(ValueError, match="format='seg2'"):
        read_record(tmp_path / "good.AT2", format="seg2")


# --- processing -----------------------------------------------------------------------------

def test_processed_elcentro_has_the_target_pga_exactly(elcentro_processed):
    _, processed = elcentro_processed
    target = 0.32 * STANDARD_GRAVITY
    assert abs(np.abs(processed.acceleration).max() - target) <= 1e-12 * target
    assert abs(processed.pga_g - 0.32) <= 1e-12
    assert processed.dt == 0.005
    np.testing.assert_allclose(np.diff(processed.t), 0.005, rtol=1e-9)
    # the window [0, 20] s follows the precursor pad
    assert processed.t[-1] == pytest.approx(processed.record_start + 20.0, abs=1e-9)


def test_processed_elcentro_starts_and_ends_at_rest(elcentro_processed):
    _, processed = elcentro_processed
    a, v, d = processed.acceleration, processed.velocity, processed.displacement
    residual_velocity = abs(v[-1]) / np.abs(v).max()
    residual_displacement = abs(d[-1]) / np.abs(d).max()
    # reached: about 1e-15 and 1e-14 (the end conditions are imposed in the discrete rule)
    assert residual_velocity < 1e-10 and residual_displacement < 1e-10
    assert residual_velocity == pytest.approx(processed.residual_velocity, abs=1e-16)
    assert residual_displacement == pytest.approx(processed.residual_displacement, abs=1e-16)
    assert abs(a[-1]) < 1e-12 * np.abs(a).max()
    assert v[0] == 0.0 and d[0] == 0.0 and abs(a[0]) < 1e-12 * np.abs(a).max()
    # plausible amplitudes for El Centro N-S at 0.32 g: peak velocity ~ 0.36 m/s, displacement 0.1-0.2 m
    assert 0.3 < np.abs(v).max() < 0.45
    assert 0.08 < np.abs(d).max() < 0.25


def test_processed_triple_satisfies_the_integration_rule(elcentro_processed):
    _, processed = elcentro_processed
    a, v, d, dt = processed.acceleration, processed.velocity, processed.displacement, processed.dt
    velocity_trapezoid = scipy.integrate.cumulative_trapezoid(a, dx=dt, initial=0.0)
    assert rel_error(v, velocity_trapezoid) < ROUNDOFF
    displacement_trapezoid = scipy.integrate.cumulative_trapezoid(v, dx=dt, initial=0.0)
    # The rule is exact for piecewise-linear a; it differs from the trapezoid rule on v by
    # exactly dt^2/12 (a_0 - a_k) (telescoping sum of the per-step differences).
    assert rel_error(d, displacement_trapezoid + dt * dt / 12.0 * (a[0] - a)) < ROUNDOFF
    assert np.abs(d - displacement_trapezoid).max() <= dt * dt / 12.0 * np.abs(a).max() * (1 + ROUNDOFF)
    assert rel_error(d, displacement_trapezoid) < 1e-4


def test_waveform_tables_are_consistent_with_cubic_hermite_interpolation(elcentro_processed):
    _, processed = elcentro_processed
    t0, dt, g, dg, ddg = as_waveform(processed)
    assert t0 == 0.0 and dt == processed.dt
    assert all(table.flags.c_contiguous and table.dtype == np.float64 for table in (g, dg, ddg))
    np.testing.assert_array_equal(g, processed.displacement)
    # Second derivative of the cubic Hermite interpolant of (g, g') on [t_k, t_k+1] at both ends:
    # it must be the tabulated g'' (the displacement is the exact integral of piecewise-linear g'').
    step = g[1:] - g[:-1]
    left = (6.0 * step - dt * (4.0 * dg[:-1] + 2.0 * dg[1:])) / dt**2
    right = (-6.0 * step + dt * (2.0 * dg[:-1] + 4.0 * dg[1:])) / dt**2
    peak = np.abs(ddg).max()
    assert np.abs(left - ddg[:-1]).max() < 1e-9 * peak  # cancellation in g differences: reached 3e-12
    assert np.abs(right - ddg[1:]).max() < 1e-9 * peak


def test_processed_elcentro_stays_close_to_the_raw_record(elcentro_processed):
    record, processed = elcentro_processed
    onset = int(round(processed.record_start / processed.dt))
    on_record_grid = processed.acceleration[onset::4][:1001]
    raw = processed.scale_factor * record.acceleration[:1001]
    interior = slice(50, 951)  # outside the 1-s tapers
    assert rel_error(on_record_grid[interior], raw[interior]) < 0.05  # reached: 0.019
    assert processed.scale_factor == pytest.approx(0.32 / 0.31882, rel=0.01)


def _amplitudes(t, values, frequencies):
    columns = [np.ones_like(t)]
    for frequency in frequencies:
        columns += [np.sin(2 * np.pi * frequency * t), np.cos(2 * np.pi * frequency * t)]
    coefficients = np.linalg.lstsq(np.column_stack(columns), values, rcond=None)[0]
    return np.hypot(coefficients[1::2], coefficients[2::2])


def test_bandpass_filter_follows_its_response():
    dt, frequencies = 0.005, np.array([0.02, 2.0, 40.0])
    t = dt * np.arange(int(400.0 / dt))
    signal = np.sin(2 * np.pi * frequencies[:, None] * t).sum(axis=0)
    filtered = bandpass_filter(signal, dt, band=(0.1, 25.0))
    interior = (t > 150.0) & (t < 250.0)  # away from the zero-padded ends
    amplitudes = _amplitudes(t[interior], filtered[interior], frequencies)
    sos = scipy.signal.butter(4, (0.1, 25.0), btype="bandpass", fs=1 / dt, output="sos")
    response = np.abs(scipy.signal.sosfreqz(sos, worN=frequencies, fs=1 / dt)[1]) ** 2  # forward and backward
    np.testing.assert_allclose(amplitudes, response, rtol=1e-3, atol=1e-6)
    assert amplitudes[0] < 0.05 and amplitudes[2] < 0.05 and abs(amplitudes[1] - 1.0) < 0.02


def test_process_record_removes_out_of_band_sinusoids():
    dt, frequencies = 0.005, np.array([0.02, 2.0, 40.0])
    t = dt * np.arange(int(400.0 / dt))
    signal = np.sin(2 * np.pi * frequencies[:, None] * t).sum(axis=0)
    record = records.Record(t=t, acceleration=signal, dt=dt, source="synthetic", units="m/s2")
    processed = process_record(record, band=(0.1, 25.0), pad=0.0)
    interior = (processed.t > 100.0) & (processed.t < 300.0)
    amplitudes = _amplitudes(processed.t[interior], processed.acceleration[interior], frequencies)
    assert amplitudes[0] < 0.05 and amplitudes[2] < 0.05  # > 95 % reduction
    assert abs(amplitudes[1] - 1.0) < 0.02  # in band: < 2 % change
    assert processed.residual_velocity < 1e-10 and processed.residual_displacement < 1e-10


def _two_amplitude_record(amplitude=1.0, dt=0.005):
    """A 2 Hz sine of `amplitude` (m/s^2) for 0 <= t < 15 s and of 3 x `amplitude` for 15 <= t <= 30 s:
    the window [0, 14] s holds a third of the whole record's peak."""
    t = dt * np.arange(int(round(30.0 / dt)) + 1)
    acceleration = amplitude * np.where(t < 15.0, 1.0, 3.0) * np.sin(2 * np.pi * 2.0 * t)
    return records.Record(t=t, acceleration=acceleration, dt=dt, source="two_amplitudes", units="m/s2")


@pytest.mark.parametrize("scale", ["after_filter", "before_filter"])
def test_pga_scales_the_processed_window_or_the_whole_raw_record(scale):
    """wave.motion.record scale: "after_filter" makes the processed window's peak the pga; "before_filter"
    scales the whole raw record to the pga, so a window holding a third of the record's peak comes out
    at pga / 3 (a 2 Hz sine passes the 0.1-25 Hz band, the taper and the baseline correction within 2 %,
    as test_process_record_removes_out_of_band_sinusoids shows)."""
    amplitude, pga = 1.0, 0.3
    record = _two_amplitude_record(amplitude)
    processed = process_record(record, window=(0.0, 14.0), pga=pga, scale=scale)
    g = records.STANDARD_GRAVITY
    assert processed.scale == scale and processed.target_pga_g == pga
    assert processed.raw_pga_g == pytest.approx(3.0 * amplitude / g, rel=1e-12)
    assert processed.window_raw_pga_g == pytest.approx(amplitude / g, rel=1e-6)  # sin peaks at 1 - 5e-13
    if scale == "after_filter":
        assert processed.pga_g == pytest.approx(pga, rel=1e-12)
    else:
        assert processed.scale_factor == pytest.approx(pga * g / (3.0 * amplitude), rel=1e-12)
        assert processed.pga_g == pytest.approx(pga / 3.0, rel=0.02)
    line = processed.peaks_line()
    assert f'scale "{scale}"' in line and "raw record peak 0.306 g" in line and "raw peak 0.102 g" in line


def test_scale_is_checked_and_read_only_with_a_pga():
    record = _two_amplitude_record()
    with pytest.raises(ValueError, match="scale='both'"):
        process_record(record, window=(0.0, 14.0), pga=0.3, scale="both")
    own = process_record(record, window=(0.0, 14.0), scale="before_filter")
    assert own.scale_factor == 1.0 and own.target_pga_g is None and "no pga" in own.peaks_line()
    assert own.pga_g == pytest.approx(1.0 / records.STANDARD_GRAVITY, rel=0.02)


def test_resampling_downwards_and_the_nyquist_warning():
    record = read_record(ELCENTRO_AT2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        processed = process_record(record, window=(0.0, 20.0), table_dt=0.02, pga=0.32)
    assert any("0.8 x Nyquist" in str(warning.message) for warning in caught)
    assert processed.band == (0.1, pytest.approx(20.0))
    assert processed.dt == 0.02
    assert processed.t[-1] == pytest.approx(processed.record_start + 20.0, abs=1e-9)
    velocity = scipy.integrate.cumulative_trapezoid(processed.acceleration, dx=0.02, initial=0.0)
    assert rel_error(processed.velocity, velocity) < ROUNDOFF
    assert processed.residual_velocity < 1e-10 and processed.residual_displacement < 1e-10


@pytest.mark.parametrize("kwargs, parameter", [
    ({"pga": -0.3}, "pga=-0.3"),
    ({"window": (0.0, 40.0)}, "window=(0.0, 40.0)"),
    ({"window": (5.0, 2.0)}, "window=(5.0, 2.0)"),
    ({"taper": 0.7}, "taper=0.7"),
    ({"band": (2.0, 1.0)}, "band=(2.0, 1.0)"),
    ({"table_dt": 0.02 / np.pi}, "table_dt="),
    ({"pad": -1.0}, "pad=-1.0"),
])
def test_bad_processing_parameters_raise_value_error(kwargs, parameter):
    record = read_record(ELCENTRO)
    with pytest.raises(ValueError) as error:
        process_record(record, **kwargs)
    assert parameter in str(error.value)


def test_plot_record_writes_a_png(tmp_path, elcentro_processed):
    record, processed = elcentro_processed
    for name, raw in (("processed.png", None), ("with_raw.png", record)):
        path = tmp_path / name
        plot_record(processed, path, raw=raw)
        content = path.read_bytes()
        assert content[:8] == b"\x89PNG\r\n\x1a\n" and len(content) > 10_000


def test_scene_lead_in_sets_the_seconds_kept_before_the_window():
    """wave.motion.record.lead_in reaches the processing: the motion starts lead_in s before the window."""
    from pyfem.scene import parse_scene
    from pyfem.seismic.setup import input_waveform

    checks = 0
    for lead_in in (0.0, 1.0):
        scene = parse_scene({
            "mesh": {"size": [10.0, 10.0, 10.0], "h": 5.0},
            "materials": {"rock": {"E": 8e9, "nu": 0.24, "rho": 2600.0}},
            "time": {"duration": 1.0},
            "wave": {"type": "SV", "surface": 20.0, "motion": {"record": {
                "file": str(DATA / "elcentro_1940_ns.txt"), "units": "g", "pga": 0.32, "window": [0.0, 20.0],
                "band": [0.1, 3.0], "lead_in": lead_in}}}})
        _, _, processed = input_waveform(scene)
        assert processed.record_start == pytest.approx(lead_in, abs=1e-9)
        assert processed.t[-1] == pytest.approx(20.0 + lead_in, abs=0.01)
        assert abs(processed.residual_displacement) < 1e-10
        checks += 1
    assert checks == 2


def test_record_time_is_run_time(tmp_path):
    """A record's window [0, 3] s run for time.duration = 3 s: t = 0 is the window's start in the
    monitors, the filter's lead-in runs at negative times, and the record's PGA (at 2.0 s of its
    window, after the default 5.6 s lead-in) lies inside the run. Catches the old clock, where the
    lead-in counted in time.duration and the run ended before the record's strong motion (0.012 g
    at the centre of a user's model instead of the record's 0.32 g)."""
    from pyfem import solver
    from pyfem.scene import parse_scene
    from pyfem.seismic.setup import processed_record

    scene = parse_scene({
        "title": "record time", "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [40.0, 40.0, 40.0],
                                         "h": 20.0},
        "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}}, "time": {"duration": 3.0},
        "wave": {"type": "SV", "surface": 60.0,
                 "motion": {"record": {"file": str(ELCENTRO), "units": "g", "pga": 0.32, "window": [0.0, 3.0]}}},
        "monitor": [{"name": "c", "point": [20.0, 20.0, 20.0]}],
        "output": {"interval": 0.02, "xdmf_interval": 0.0}})
    summary = solver.run(scene, tmp_path / "run")
    data = np.genfromtxt(tmp_path / "run" / "monitors" / "c.csv", delimiter=",", names=True)
    lead_in = processed_record(scene["wave"]["motion"]["record"]).record_start
    assert lead_in > 5.0  # the default lead-in of a 0.1 Hz filter
    assert data["t"][0] == pytest.approx(-0.02 * np.ceil(lead_in / 0.02 - 1e-9), abs=1e-9)
    assert np.count_nonzero(data["t"] == 0.0) == 1 and data["t"][-1] == pytest.approx(3.0, abs=1e-9)
    before = data["t"] < 0.0
    peak = np.max(np.abs(data["ax_ff"] if "ax_ff" in data.dtype.names else data["ax"]))
    assert peak > 0.25 * STANDARD_GRAVITY  # the record's strong motion is inside the run
    assert 1.5 < data["t"][np.argmax(np.abs(data["ax"]))] < 2.5  # at about 2 s of record time
    assert np.max(np.abs(data["ax"][before])) < 0.1 * peak  # the lead-in: the filter's precursor (6.6 %)
    motion = summary["input_motion"] if "input_motion" in summary else None
    if motion is not None:
        assert motion["within_run"]["until"] == pytest.approx(3.0, abs=1e-9)
        assert 1.5 < motion["t_pga"] < 2.5  # El Centro's PGA, at about 2 s of record time


def test_the_input_processing_study_runs_and_orders_the_peaks():
    """workflows/input_processing.py (the paper's input under both scaling orders and four high-pass
    corners): scaled after the filter the processed PGA is the target; scaled first (the paper's
    order) every peak is lower; a higher high-pass corner lowers the displacement."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "workflows"))
    import input_processing

    table = {(row["scale"], row["high_pass_hz"]): row for row in input_processing.rows()}
    assert len(table) == 8
    for corner in input_processing.CORNERS:
        after, before = table["after_filter", corner], table["before_filter", corner]
        assert after["pga_g"] == pytest.approx(input_processing.PGA, rel=1e-12)
        assert before["pga_g"] < after["pga_g"] and before["pgv_cm_s"] < after["pgv_cm_s"]
        assert before["pgd_cm"] < after["pgd_cm"]
    pgd = [table["before_filter", corner]["pgd_cm"] for corner in input_processing.CORNERS]
    assert pgd == sorted(pgd, reverse=True) and pgd[0] > 3 * pgd[-1]


def test_the_calibrated_corner_gives_the_papers_case1_lining_displacement():
    """workflows/input_calibration.py: the case scenes' input (scaled before filtering, high-pass
    0.52 Hz) gives the free field at the lining's monitors a peak |u| within 3 % of the paper's case-1
    lining displacement, 6.83 cm. Checked against the closed form of vertical incidence under a free
    surface (each wave and its reflection, the surface doubling the displacement: u_x = g(t - z/c_s)
    + g(t - (2 z_s - z)/c_s), u_z the same with c_p and 2/3 of g), from the processed record itself."""
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "workflows"))
    import input_calibration
    from pyfem.scene import load_scene
    from pyfem.seismic.setup import scene_record

    scene = load_scene(input_calibration.SCENE)
    spec = scene["wave"]["motion"]["record"]
    assert spec["scale"] == "before_filter" and list(spec["band"]) == [input_calibration.CHOSEN, 3.0]
    peaks = input_calibration.free_field_peaks(input_calibration.CHOSEN)
    assert abs(max(peaks["peak_cm"].values()) / input_calibration.TARGET_CM - 1.0) < 0.03  # measured 0.6 %
    processed = scene_record(scene)
    rock = scene["materials"]["sandstone"]
    mu = rock["E"] / (2.0 * (1.0 + rock["nu"]))
    lam = rock["E"] * rock["nu"] / ((1.0 + rock["nu"]) * (1.0 - 2.0 * rock["nu"]))
    c_s, c_p = np.sqrt(mu / rock["rho"]), np.sqrt((lam + 2.0 * mu) / rock["rho"])
    z_s, z = scene["wave"]["surface"], input_calibration.MONITORS["A"][2]
    tau = processed.t - processed.record_start  # record time: the reference point (z = 0) moves as g(tau)

    def g(t):
        return np.interp(t, tau, processed.displacement, left=0.0, right=processed.displacement[-1])

    t = np.arange(-1.0, 20.0, input_calibration.TIME_STEP)
    u_x = g(t - z / c_s) + g(t - (2.0 * z_s - z) / c_s)
    u_z = (2.0 / 3.0) * (g(t - z / c_p) + g(t - (2.0 * z_s - z) / c_p))
    closed = 100.0 * np.max(np.hypot(u_x, u_z))
    assert closed > 5.0  # the wave arrived: centimetres, not round-off
    assert abs(peaks["peak_cm"]["A"] / closed - 1.0) < 2e-3  # measured: see the failure message

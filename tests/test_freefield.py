"""Analytical free field, waveform tables and equivalent input forces.

Exact answers used: the traction-free surface, doubling at the surface, the elastic
wave equation (finite differences), the analytic signal of the Ricker wavelet
(Faddeeva function) for post-critical fields, Hermite exactness on cubics, and the
direct evaluation of Eq. 6 for the grouped kernel arrays.
"""
from dataclasses import dataclass

import numpy as np
import pytest
import scipy.special

from conftest import ROUNDOFF, observed_orders, rel_error
from pyfem.seismic import reflection
from pyfem.seismic.forces import (boundary_springs_and_dashpots, equivalent_input_forces,
                                  equivalent_input_forces_reference)
from pyfem.material import Material
from pyfem.seismic.freefield import FreeField, IncidentWave
from pyfem.seismic.waveforms import WaveformTables, hilbert_pair, ricker, ricker_analytic_signal

E, NU, RHO = 8.0e9, 0.24, 2600.0
F0, AMPLITUDE, T_PEAK = 5.0, 1.0e-3, 0.3
SURFACE = 200.0
BOUNDS = ((0.0, 0.0, 0.0), (200.0, 20.0, SURFACE))  # model top at the free surface
TABLE_GRID = (0.0, 5.0e-4, 6000)  # 3 s


def wavelet(t):
    return ricker(t, F0, AMPLITUDE, T_PEAK)


def free_field(wave_type, angle, azimuth=0.0, **kwargs):
    options = dict(surface=SURFACE, waveform=wavelet, table_grid=TABLE_GRID, model_bounds=BOUNDS)
    options.update(kwargs)
    return FreeField([IncidentWave(wave_type, angle, azimuth)], E, NU, RHO, **options)


def surface_points(n=5, seed=1):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, 200, n), rng.uniform(0, 20, n), np.full(n, SURFACE)])


def incident_stress_scale(field, x, t):
    """Largest traction on the surface of the incident wave alone (> 0: the reflections must cancel it)."""
    incident = FreeField([field.waves[0]], E, NU, RHO, surface=None, waveform=wavelet, table_grid=TABLE_GRID,
                         model_bounds=BOUNDS)
    return np.abs(incident.stress(x, t)[..., :, 2]).max()


ANGLES = [0.0, 10.0, 20.0, 30.0, 45.0, 60.0, 80.0]


@pytest.mark.parametrize("wave_type", ["P", "SV", "SH"])
@pytest.mark.parametrize("angle", ANGLES)
def test_surface_is_traction_free(wave_type, angle):
    field = free_field(wave_type, angle, azimuth=30.0)
    post_critical = wave_type == "SV" and angle > reflection.critical_angle(field.c_p, field.c_s)
    if post_critical:
        # g, H[g] and the depth-filtered tables all from tables: the cancellation is then
        # exact to round-off (mixing exact g with interpolated H[g] would test interpolation).
        field = free_field(wave_type, angle, azimuth=30.0, waveform=WaveformTables.from_function(wavelet, *TABLE_GRID))
        assert any("evanescent" in c.name for c in field.components)
    x = surface_points()
    t = np.linspace(0.0, 2.0, 801)
    traction = field.stress(x, t)[..., :, 2]
    scale = incident_stress_scale(field, x, t)
    assert scale > 0.0
    assert np.abs(traction).max() / scale < ROUNDOFF


def test_surface_is_traction_free_at_the_critical_angle():
    field = free_field("SV", 0.0)
    critical = reflection.critical_angle(field.c_p, field.c_s)
    tables = WaveformTables.from_function(wavelet, *TABLE_GRID)
    for angle in (critical, np.nextafter(critical, 90.0), np.nextafter(critical, 0.0)):
        field = free_field("SV", angle, azimuth=-20.0, waveform=tables)
        x = surface_points()
        t = np.linspace(0.0, 2.0, 401)
        sigma = field.stress(x, t)
        assert np.all(np.isfinite(sigma))
        assert np.abs(sigma[..., :, 2]).max() / incident_stress_scale(field, x, t) < ROUNDOFF


def test_sh_and_vertical_sv_double_at_the_surface():
    x = surface_points()
    t = np.linspace(0.0, 2.0, 401)
    checks = 0
    for wave_type, angle, azimuth, polarisation in (("SH", 35.0, 60.0, [-np.sin(np.radians(60)), np.cos(np.radians(60)), 0]),
                                                    ("SV", 0.0, 0.0, [1.0, 0.0, 0.0]),
                                                    ("P", 0.0, 0.0, [0.0, 0.0, 1.0])):
        field = free_field(wave_type, angle, azimuth)
        incident = field.components[0]
        tau = x @ incident.slowness + incident.delay_offset
        expected = 2.0 * wavelet(t[:, None] - tau[None, :])[0][..., None] * np.array(polarisation)
        assert rel_error(field.displacement(x, t), expected) < ROUNDOFF
        checks += 1
    assert checks == 3


def test_default_reference_point_gives_no_negative_delay():
    for wave_type, angle, azimuth in (("P", 30.0, 0.0), ("SV", 20.0, 135.0), ("SH", 60.0, -100.0)):
        field = free_field(wave_type, angle, azimuth)
        low, high = BOUNDS
        corners = np.array([[a, b, c] for a in (low[0], high[0]) for b in (low[1], high[1]) for c in (low[2], high[2])])
        tau = field.component_arrays(corners)["tau"]
        assert tau.min() == pytest.approx(0.0, abs=1e-12)
        assert tau[:, 0].min() == pytest.approx(0.0, abs=1e-12)  # the incident wave reaches x0 at t = 0


def test_wave_equation_holds_for_oblique_sv_with_azimuth_45():
    field = free_field("SV", 20.0, azimuth=45.0)
    x = np.array([[100.0, 10.0, 120.0], [40.0, 5.0, 170.0]])
    t = np.linspace(0.2, 0.9, 36)
    inertia = RHO * field.acceleration(x, t)
    errors = []
    steps = [8.0, 4.0, 2.0, 1.0]
    for h in steps:
        divergence = np.zeros_like(inertia)
        for j in range(3):
            shift = np.zeros(3)
            shift[j] = h
            d_sigma = (field.stress(x + shift, t) - field.stress(x - shift, t)) / (2.0 * h)
            divergence += d_sigma[..., :, j]
        errors.append(rel_error(divergence, inertia))
    orders = observed_orders(steps, errors)
    assert np.all(orders > 1.9), (errors, orders)
    assert errors[-1] < 1e-3


def test_velocity_and_acceleration_are_time_derivatives():
    field = free_field("P", 25.0, azimuth=-30.0)
    x = np.array([[100.0, 10.0, 120.0], [10.0, 15.0, 30.0]])
    t = np.linspace(0.1, 1.2, 23)
    errors_v, errors_a = [], []
    steps = [4e-3, 2e-3, 1e-3]
    for h in steps:
        errors_v.append(rel_error((field.displacement(x, t + h) - field.displacement(x, t - h)) / (2 * h),
                                  field.velocity(x, t)))
        errors_a.append(rel_error((field.velocity(x, t + h) - field.velocity(x, t - h)) / (2 * h),
                                  field.acceleration(x, t)))
    assert np.all(observed_orders(steps, errors_v) > 1.9)
    assert np.all(observed_orders(steps, errors_a) > 1.9)


def test_post_critical_field_matches_the_analytic_signal():
    """SV at 60 deg: reflected SV with H[g], evanescent P ~ Re[c d g_a(t - tau_h + i kappa depth)].

    g_a is the analytic signal of the Ricker wavelet continued to complex time (Faddeeva
    function), independent of the FFT tables; the tables are linear in depth, so the
    error must fall as depth_step^2.
    """
    angle, azimuth = 60.0, 20.0
    rng = np.random.default_rng(3)
    depths = np.concatenate([[0.0], np.linspace(0.37, 60.37, 24)])  # the evanescent P decays over ~60 m
    x = np.column_stack([rng.uniform(0, 200, 25), rng.uniform(0, 20, 25), SURFACE - depths])
    t = np.linspace(0.4, 1.6, 241)
    bounds = ((0.0, 0.0, SURFACE - 70.0), BOUNDS[1])
    field = free_field("SV", angle, azimuth, model_bounds=bounds)
    c_p, c_s = field.c_p, field.c_s
    phi, th = np.radians(azimuth), np.radians(angle)
    e_h = np.array([np.cos(phi), np.sin(phi), 0.0])
    e_z = np.array([0.0, 0.0, 1.0])
    s, eta_s = np.sin(th) / c_s, np.cos(th) / c_s
    kappa = np.sqrt(s**2 - 1.0 / c_p**2)
    r = reflection.free_surface_coefficients("SV", angle, c_p, c_s)
    incident = field.components[0]
    tau_incident = x @ incident.slowness + incident.delay_offset
    tau_surface = tau_incident + eta_s * depths  # the incident wave reaches the surface above x
    d_s = np.cos(th) * e_h + np.sin(th) * e_z
    d_p = c_p * (s * e_h + 1j * kappa * e_z)  # c_p (s, -eta_p), eta_p = -i kappa for w > 0

    def g_a(z):
        return ricker_analytic_signal(z, F0, AMPLITUDE, T_PEAK)[0][..., None]

    expected = (wavelet(t[:, None] - tau_incident)[0][..., None] * (np.cos(th) * e_h - np.sin(th) * e_z)
                + np.real(r["SS"] * g_a(t[:, None] - tau_surface - eta_s * depths) * d_s)
                + np.real(r["SP"] * g_a(t[:, None] - tau_surface + 1j * kappa * depths) * d_p))
    assert rel_error(field.displacement(x, t), expected) < 1e-3  # default depth step
    errors = []
    steps = [4.0, 2.0, 1.0]
    for step in steps:
        field = free_field("SV", angle, azimuth, depth_step=step, model_bounds=bounds)
        errors.append(rel_error(field.displacement(x, t), expected))
    orders = observed_orders(steps, errors)
    assert errors[-1] < 5e-5, errors
    assert np.all(orders > 1.8), (errors, orders)


def test_waveform_tables_follow_the_kernel_rule():
    tables = WaveformTables(t0=1.0, dt=0.1, g=[np.zeros(11)], dg=[np.zeros(11)], ddg=[np.zeros(11)])
    times = tables.times
    table = tables.add((times - 1.2) ** 3, 3 * (times - 1.2) ** 2, 6 * (times - 1.2))
    t = np.linspace(1.0, 2.0, 37)
    g, dg, ddg = tables.evaluate(table, t)
    # Cubic Hermite is exact on cubics (g) and on quadratics (g').
    assert rel_error(g, (t - 1.2) ** 3) < ROUNDOFF
    assert rel_error(dg, 3 * (t - 1.2) ** 2) < ROUNDOFF
    assert rel_error(ddg, 6 * (t - 1.2)) < ROUNDOFF
    before = tables.evaluate(table, np.array([0.5, 0.999]))
    after = tables.evaluate(table, np.array([2.5, 10.0]))
    assert all(np.all(v == 0.0) for v in before)
    assert np.all(after[0] == 0.8**3) and np.all(after[1] == 3 * 0.8**2)


def test_ricker_derivatives_and_hilbert_transform():
    t = np.linspace(0.0, 3.0, 6001)
    g, dg, ddg = ricker(t, F0, AMPLITUDE, T_PEAK)
    h = 1e-5
    assert rel_error((ricker(t + h, F0, AMPLITUDE, T_PEAK)[0] - ricker(t - h, F0, AMPLITUDE, T_PEAK)[0]) / (2 * h), dg) < 1e-6
    assert rel_error((ricker(t + h, F0, AMPLITUDE, T_PEAK)[1] - ricker(t - h, F0, AMPLITUDE, T_PEAK)[1]) / (2 * h), ddg) < 1e-6
    # H[cos] = sin on a periodic grid (no padding needed).
    n, periods = 512, 7
    dt = 1.0 / n
    omega = 2 * np.pi * periods
    tt = dt * np.arange(n)
    hc = hilbert_pair(np.cos(omega * tt), -omega * np.sin(omega * tt), -omega**2 * np.cos(omega * tt), dt, 1)
    assert rel_error(hc[0], np.sin(omega * tt)) < ROUNDOFF
    assert rel_error(hc[1], omega * np.cos(omega * tt)) < ROUNDOFF
    assert rel_error(hc[2], -omega**2 * np.sin(omega * tt)) < ROUNDOFF
    # Ricker: independent closed form through Dawson's function, H[Ricker] = -(A/sqrt(pi)) D''(x).
    x = np.pi * F0 * (t - T_PEAK)
    dawson = scipy.special.dawsn(x)
    exact = -(AMPLITUDE / np.sqrt(np.pi)) * (-2.0 * x + (4.0 * x**2 - 2.0) * dawson)
    hr = hilbert_pair(g, dg, ddg, t[1] - t[0], 8)
    assert rel_error(hr[0], exact) < 1e-6
    assert rel_error(ricker_analytic_signal(t + 0j, F0, AMPLITUDE, T_PEAK)[0].imag, exact) < ROUNDOFF


@dataclass
class Face:
    name: str
    nodes: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    rho_cp: np.ndarray
    rho_cs: np.ndarray
    shear_modulus: np.ndarray
    plane_distance: np.ndarray


def box_faces(n=(5, 3, 5)):
    """Nodes of a structured 200 x 20 x 200 box and its six faces with lumped-like integrals."""
    axes = [np.linspace(BOUNDS[0][i], BOUNDS[1][i], n[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    index = np.arange(len(grid)).reshape(n)
    centre = 0.5 * (np.array(BOUNDS[0]) + np.array(BOUNDS[1]))
    material = Material(E=E, nu=NU, rho=RHO)
    mu, c_p, c_s = material.shear_modulus, material.p_wave_speed, material.s_wave_speed
    rng = np.random.default_rng(7)
    faces = []
    for axis in range(3):
        for side, name in ((0, "min"), (-1, "max")):
            nodes = np.take(index, side, axis=axis).reshape(-1).astype(np.int32)
            normal = np.zeros((len(nodes), 3))
            normal[:, axis] = -1.0 if side == 0 else 1.0
            area = rng.uniform(10.0, 50.0, len(nodes))
            distance = np.abs((grid[nodes] - centre) @ normal[0])
            faces.append(Face("xyz"[axis] + name, nodes, area, normal, area * RHO * c_p,
                              area * RHO * c_s, area * mu, distance))
    return grid, faces


def input_field(scale=1.0):
    tables = WaveformTables.from_function(wavelet, *TABLE_GRID)
    waves = [IncidentWave("SV", 25.0, 30.0, scale), IncidentWave("P", 25.0, 30.0, 2.0 / 3.0 * scale),
             IncidentWave("SV", 60.0, -45.0, 0.5 * scale), IncidentWave("SH", 10.0, 90.0, scale)]
    return FreeField(waves, E, NU, RHO, surface=SURFACE + 20.0, waveform=tables,
                     model_bounds=BOUNDS, depth_step=20.0)


def test_grouped_input_forces_equal_direct_evaluation():
    grid, faces = box_faces()
    field = input_field()
    arrays = equivalent_input_forces(faces, grid, field, "viscoelastic")
    assert arrays["node_ptr"][-1] == len(arrays["table"]) == len(arrays["tau"]) == len(arrays["P"])
    assert len(arrays["nodes"]) == len(np.unique(np.concatenate([f.nodes for f in faces])))
    assert arrays["nodes"].dtype == np.int32 and arrays["node_ptr"].dtype == np.int64
    assert arrays["table"].dtype == np.int32 and arrays["g"].shape == field.tables.g.shape
    t = np.linspace(0.0, 2.5, 26)
    tables = WaveformTables(arrays["table_t0"], arrays["table_dt"], arrays["g"], arrays["dg"], arrays["ddg"])
    grouped = np.zeros((len(t), len(grid), 3))
    for i, node in enumerate(arrays["nodes"]):
        for e in range(arrays["node_ptr"][i], arrays["node_ptr"][i + 1]):
            y, dy, _ = tables.evaluate(arrays["table"][e], t - arrays["tau"][e])
            grouped[:, node] += y[:, None] * arrays["P"][e] + dy[:, None] * arrays["Q"][e]
    reference = equivalent_input_forces_reference(faces, grid, field, t, "viscoelastic")
    assert np.abs(reference).max() > 0.0
    assert rel_error(grouped, reference) < 1e-12


def test_zero_wave_gives_zero_forces():
    grid, faces = box_faces()
    arrays = equivalent_input_forces(faces, grid, input_field(scale=0.0), "viscoelastic")
    assert len(arrays["P"]) > 0
    assert np.all(arrays["P"] == 0.0) and np.all(arrays["Q"] == 0.0)


def test_springs_and_dashpots():
    grid, faces = box_faces()
    springs_nodes, springs, dashpot_nodes, dashpots = boundary_springs_and_dashpots(faces, len(grid), "viscoelastic")
    face = faces[0]  # x min, normal -x
    interior_of_face = [i for i, node in enumerate(face.nodes)
                        if sum(node in f.nodes for f in faces) == 1]
    assert interior_of_face
    i = interior_of_face[0]
    row = np.searchsorted(springs_nodes, face.nodes[i])
    g_over_r = face.shear_modulus[i] / face.plane_distance[i]
    assert np.allclose(springs[row], np.diag([4 / 3, 2 / 3, 2 / 3]) * g_over_r, rtol=ROUNDOFF, atol=0)
    assert np.allclose(dashpots[row], np.diag([face.rho_cp[i], face.rho_cs[i], face.rho_cs[i]]), rtol=ROUNDOFF, atol=0)
    # A corner node sums three faces: each direction gets one normal and two tangential terms.
    corner = 0
    row = np.searchsorted(dashpot_nodes, corner)
    expected = np.zeros((3, 3))
    for f in faces:
        hit = np.nonzero(f.nodes == corner)[0]
        for k in hit:
            n = f.normal[k]
            expected += f.rho_cp[k] * np.outer(n, n) + f.rho_cs[k] * (np.eye(3) - np.outer(n, n))
    assert np.allclose(dashpots[row], expected, rtol=ROUNDOFF, atol=0)
    viscous = boundary_springs_and_dashpots(faces, len(grid), "viscous")
    assert len(viscous[0]) == 0 and np.allclose(viscous[3], dashpots)
    for kind in ("fixed", "free"):
        assert all(len(a) == 0 for a in boundary_springs_and_dashpots(faces, len(grid), kind))
        assert len(equivalent_input_forces(faces, grid, input_field(), kind)["P"]) == 0


@pytest.mark.parametrize("kwargs, name", [
    (dict(waves=[IncidentWave("SV", 30.0)], E=-1.0), "E"),
    (dict(waves=[IncidentWave("SV", 30.0)], nu=0.5), "nu"),
    (dict(waves=[IncidentWave("SV", 30.0)], rho=0.0), "rho"),
    (dict(waves=[{"type": "Q", "angle": 10.0}]), "wave_type"),
    (dict(waves=[{"type": "P", "angle": 95.0}]), "angle"),
    (dict(waves=[IncidentWave("SV", 30.0)], surface=150.0), "surface"),
    (dict(waves=[IncidentWave("SV", 30.0)], table_grid=None), "table_grid"),
])
def test_bad_free_field_input_names_the_parameter(kwargs, name):
    options = dict(E=E, nu=NU, rho=RHO, surface=SURFACE, waveform=wavelet, table_grid=TABLE_GRID, model_bounds=BOUNDS)
    options.update(kwargs)
    waves = options.pop("waves")
    with pytest.raises(ValueError, match=name):
        FreeField(waves, **options)


def test_bad_boundary_type_names_the_parameter():
    grid, faces = box_faces()
    with pytest.raises(ValueError, match="boundary_type"):
        boundary_springs_and_dashpots(faces, len(grid), "absorbing")
    with pytest.raises(ValueError, match="boundary_type"):
        equivalent_input_forces(faces, grid, input_field(), "rigid")


GRAZING_ANGLES = [85.0, 89.0, 89.9, 89.99]


@pytest.mark.parametrize("wave_type", ["P", "SV", "SH"])
@pytest.mark.parametrize("angle", GRAZING_ANGLES)
def test_grazing_incidence_stays_finite_and_traction_free(wave_type, angle):
    """No angle in [0, 90) may crash or give NaN: near-grazing waves keep a finite, traction-free field."""
    waveform = WaveformTables.from_function(wavelet, *TABLE_GRID)
    field = free_field(wave_type, angle, waveform=waveform)
    x = surface_points()
    t = np.linspace(0.0, 2.0, 401)
    displacement = field.displacement(x, t)
    stress = field.stress(x, t)
    assert np.isfinite(displacement).all() and np.isfinite(stress).all()
    assert np.abs(displacement).max() > 0.0
    scale = incident_stress_scale(field, x, t)
    assert np.abs(stress[..., :, 2]).max() <= 1e-8 * scale

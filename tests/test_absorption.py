"""Absorption of one truncation face, measured against the analytic reflection coefficient.

A plane pulse meets ONE face (zmin) of a model and nothing else touches it before the reflection
is recorded: the reflected wave at a monitor above the face is compared with the reflection
coefficient of the boundary (docs/boundaries.md)

    C_b = A (rho c_p n n^T + rho c_s (I - n n^T)),
    K_b = A (alpha_N G/R n n^T + alpha_T G/R (I - n n^T))   (viscoelastic only).

1D columns (one element wide) carry no side dashpots: rollers on the side faces for P (the
uniaxial-strain column), and for S a constraint that leaves only the shear component free at
every node (the side faces of a shear column must hold u_z and free u_x, which no face type
does; the projection goes to the kernel through solver.BoundaryConstraints, as the roller faces'
does). The pulse is put into the column as initial conditions of a downward-travelling Ricker
wave, so the bottom face is its only source of reflection.

Each case has a negative control: the same run with the dashpots scaled by 0.5 and 2 (the
arrays solver.prepare hands to the kernel, scaled before solver.make_stepper) must miss the
analytic answer of the correct boundary by far more than the tolerance; the control also
matches its own analytic coefficient, so the measurement itself is sound.

(tests/test_run.py::test_boundary_absorbs_normally_incident_pulse measures energy left in a
column whose side faces carry dashpots too: every dashpot scale from 0.1 to 2.5 passes it.)
"""
import dataclasses
import math

import numpy as np
import pytest
import scipy.sparse as sp

from conftest import REFLECTION_1D, REFLECTION_HISTORY_1D, REFLECTION_OBLIQUE, ROUNDOFF
from pyfem import solver
from pyfem.scene import parse_scene
from pyfem.seismic.waveforms import ricker

E, NU, RHO = 8.0e9, 0.24, 2600.0
MU = E / (2.0 * (1.0 + NU))
LAM = E * NU / ((1.0 + NU) * (1.0 - 2.0 * NU))
C_P = math.sqrt((LAM + 2.0 * MU) / RHO)  # 1905 m/s
C_S = math.sqrt(MU / RHO)                # 1114 m/s
ALPHA_N, ALPHA_T = 4.0 / 3.0, 2.0 / 3.0
AMPLITUDE = 1.0e-3
CONTROL_SCALES = (0.5, 2.0)

# 1D columns: Ricker of 12 Hz, h = 2 m (18 elements per shortest S wavelength, c_s / 2.5 f0).
F0_1D, H_1D = 12.0, 1.0
# Spring distance of the viscoelastic column: [boundary] centre 10 m above the face, so that
# K = alpha G/R is comparable with 2 omega rho c at f0 and |R(omega)| ~ 0.4 there.
R_SPRING = 10.0



# ---------------------------------------------------------------------------------------------
# Analytic coefficients


def viscoelastic_reflection(omega, stiffness, impedance, dashpot):
    """R(omega) of a 1D wave e^{i omega (t + z/c)} meeting at z = 0 a face whose traction on the
    body is -(stiffness u + dashpot v) per unit area (medium impedance rho c = `impedance`).

    Displacement convention: R = u_reflected / u_incident of the same component at the face.
    From rho c (1 - R) i omega = (stiffness + i omega dashpot)(1 + R):
        R = (i omega (impedance - dashpot) - stiffness) / (i omega (impedance + dashpot) + stiffness);
    the matched viscoelastic face (dashpot = rho c) gives R = -K / (K + 2 i omega rho c).
    Time factor e^{+i omega t}: numpy's ifft(R fft(x)) applies it to a history x(t).
    """
    iw = 1j * np.asarray(omega, dtype=float)
    return (iw * (impedance - dashpot) - stiffness) / (iw * (impedance + dashpot) + stiffness)


def filtered(history, dt, response, pad=8):
    """The history filtered by the frequency response `response(omega)` (zero-padded FFT)."""
    n = pad * len(history)
    omega = 2.0 * np.pi * np.fft.rfftfreq(n, dt)
    return np.fft.irfft(response(omega) * np.fft.rfft(history, n), n)[:len(history)]


def _plane_wave(kind, horizontal_slowness, upward, speed):
    """Slowness (s_x, s_z) and unit polarisation (d_x, d_z) of a P or SV plane wave in x-z.
    P: d along the propagation direction k; SV: d = (k_z, -k_x) (k turned by -90 degrees)."""
    s_z = math.sqrt(1.0 / speed**2 - horizontal_slowness**2) * (1.0 if upward else -1.0)
    slowness = np.array([horizontal_slowness, s_z])
    k = slowness * speed
    return slowness, (k if kind == "P" else np.array([k[1], -k[0]]))


def _residual(slowness, polarisation, dashpot_scale):
    """(x, z) traction residual sigma.e_z - C v / (i omega A) per unit amplitude of one plane wave
    u = d f(t - s.x) at the face z = 0 with outward normal -e_z (traction on the body
    -sigma e_z = -C_b v, i.e. sigma_xz = rho c_s v_x, sigma_zz = rho c_p v_z)."""
    s, d = slowness, polarisation
    sigma_xz = -MU * (d[0] * s[1] + d[1] * s[0])
    sigma_zz = -(LAM * (d @ s) + 2.0 * MU * d[1] * s[1])
    return np.array([sigma_xz - dashpot_scale * RHO * C_S * d[0], sigma_zz - dashpot_scale * RHO * C_P * d[1]])


def lysmer_coefficients(kind, angle, dashpot_scale=1.0):
    """Reflected (P, SV) amplitudes of a plane P or SV wave meeting the viscous face at `angle`
    (degrees from the normal), below the critical angle. Polarisations as in _plane_wave."""
    speed = C_P if kind == "P" else C_S
    p = math.sin(math.radians(angle)) / speed
    incident = _residual(*_plane_wave(kind, p, False, speed), dashpot_scale)
    reflected_p = _residual(*_plane_wave("P", p, True, C_P), dashpot_scale)
    reflected_s = _residual(*_plane_wave("SV", p, True, C_S), dashpot_scale)
    return np.linalg.solve(np.column_stack([reflected_p, reflected_s]), -incident)


def test_analytic_coefficients_have_their_limits():
    """Catches a wrong 2x2 system or R(omega): normal incidence must give 0 (matched) and
    -/+(1 - s)/(1 + s) for dashpots scaled by s; the viscous limit of R(omega) is the same."""
    for kind in ("P", "SV"):
        assert np.allclose(lysmer_coefficients(kind, 0.0), 0.0, atol=ROUNDOFF)
        for s in CONTROL_SCALES:
            # Polarisations flip at normal incidence (P: -e_z down, +e_z up; SV: -e_x, +e_x), so the
            # displacement's (1 - s)/(1 + s) is -(1 - s)/(1 + s) in these coefficients.
            expected = [-(1 - s) / (1 + s), 0.0] if kind == "P" else [0.0, -(1 - s) / (1 + s)]
            assert np.allclose(lysmer_coefficients(kind, 0.0, s), expected, atol=ROUNDOFF)
    for s in (1.0,) + CONTROL_SCALES:
        assert viscoelastic_reflection(7.0, 0.0, RHO * C_S, s * RHO * C_S) == pytest.approx((1 - s) / (1 + s))
    stiffness = ALPHA_T * MU / R_SPRING
    omega = np.array([1e-6, 2 * np.pi * F0_1D, 1e9])
    r = viscoelastic_reflection(omega, stiffness, RHO * C_S, RHO * C_S)
    assert np.allclose(r, -stiffness / (stiffness + 2j * omega * RHO * C_S), rtol=ROUNDOFF)
    assert r[0] == pytest.approx(-1.0, abs=1e-6) and abs(r[2]) < 1e-3  # a spring at rest, a dashpot fast
    # Energy: incident flux = reflected fluxes + the dashpots' dissipation (P at 30 degrees, s = 2).
    p = math.sin(math.radians(30.0)) / C_P
    r_p, r_s = lysmer_coefficients("P", 30.0, 2.0)
    (_, d_i), (sp_, d_p), (ss, d_s) = (_plane_wave("P", p, False, C_P), _plane_wave("P", p, True, C_P),
                                       _plane_wave("SV", p, True, C_S))
    v = d_i + r_p * d_p + r_s * d_s  # face velocity per unit incident velocity
    dissipated = 2.0 * RHO * (C_S * v[0] ** 2 + C_P * v[1] ** 2)  # v.C v per unit area, C x2
    # Vertical energy flux of a plane wave: rho c |v|^2 k_z (k_z = c s_z, the direction cosine).
    absorbed = RHO * C_P * (sp_[1] * C_P) * (1.0 - r_p**2) - RHO * C_S * (ss[1] * C_S) * r_s**2
    assert dissipated == pytest.approx(absorbed, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# 1D column


def column(wave, face_type):
    """(simulation, component, speed, monitor height) of a column one element wide whose bottom face
    zmin is `face_type`, top face free; P: roller side faces; S: only u_x free at every node."""
    speed = C_P if wave == "P" else C_S
    wavelength = speed / F0_1D
    monitor = H_1D * round(wavelength / H_1D)             # incident and reflection apart at the monitor
    height = H_1D * round((monitor + 3.0 * wavelength) / H_1D)  # the initial pulse below the free top
    faces = {name: {"type": "roller"} for name in ("xmin", "xmax", "ymin", "ymax")}
    faces.update(zmin={"type": face_type}, zmax={"type": "free"})
    scene = parse_scene({
        "title": f"absorption {wave} {face_type}",
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [H_1D, H_1D, height], "h": H_1D, "order": 1},
        "materials": {"rock": {"E": E, "nu": NU, "rho": RHO}},
        "time": {"duration": 1.0},
        "boundary": {"type": face_type, "face": faces, "centre": [H_1D / 2, H_1D / 2, R_SPRING]},
        "output": {"interval": 0.01, "xdmf_interval": 0.0},
    })
    simulation = solver.prepare(scene)
    component = 2 if wave == "P" else 0
    if wave == "S":
        n = len(simulation.mass)
        projection = np.zeros((n, 3, 3))
        projection[:, 0, 0] = 1.0
        simulation.constraints = solver.BoundaryConstraints(
            nodes=np.arange(n, dtype=np.int32), projection=projection, face_names=[],
            face_weights=sp.csr_matrix((0, n)))
    return simulation, component, speed, monitor


def column_pulse(wave, face_type, dashpot_scale=1.0):
    """A downward Ricker u = A g(t + (z - monitor)/c) (peak at the monitor at t0 = 1.5/f0) meets zmin.

    Returns dict: t, measured (monitor history of the wave's component), incident (analytic at the
    monitor), delay (monitor -> face -> monitor), energy.
    """
    simulation, component, speed, monitor = column(wave, face_type)
    simulation.dashpot_matrices = simulation.dashpot_matrices * dashpot_scale
    stepper = solver.make_stepper(simulation)
    z = simulation.model.node_coords[:, 2]
    t0 = 1.5 / F0_1D
    g, dg, _ = ricker((z - monitor) / speed, F0_1D, AMPLITUDE, t0)
    u = np.zeros(3 * len(z))
    v = np.zeros_like(u)
    u[component::3] = g
    v[component::3] = dg
    a = -(simulation.stiffness @ u) / np.repeat(simulation.mass, 3)
    held = simulation.constraints
    for state in (u, v, a):
        nodes = state.reshape(-1, 3)
        nodes[held.nodes] = np.einsum("kij,kj->ki", held.projection, nodes[held.nodes])
    stepper.reset_energy(u, v, a, 0.0)
    dt = simulation.time_step.dt
    delay = 2.0 * monitor / speed
    steps = int(math.ceil((2.0 * t0 + delay) / dt))
    at = np.flatnonzero(np.isclose(z, monitor))
    assert len(at) == 4
    history = [u[3 * at + component].mean()]
    t = 0.0
    for _ in range(steps):
        t = stepper.run(u, v, a, 1, t)
        history.append(u[3 * at + component].mean())
    times = dt * np.arange(steps + 1)
    return {"t": times, "dt": dt, "measured": np.array(history), "speed": speed, "delay": delay,
            "incident": ricker(times, F0_1D, AMPLITUDE, t0)[0],
            "energy": stepper.energy()}


def check_energy(run):
    energy = run["energy"]
    assert abs(energy["balance"]) < ROUNDOFF * energy["initial"], energy
    assert energy["damping_work"] > 0.0


def arrived(run):
    """Guard: the incident wave reached the monitor with its analytic amplitude (1 %)."""
    early = run["t"] < 0.5 * run["delay"] + 1.5 / F0_1D
    peak = np.max(np.abs(run["measured"][early]))
    assert peak == pytest.approx(AMPLITUDE, rel=0.01), peak


def reflected_coefficient(run):
    """Least-squares amplitude of the measured reflection (measured - analytic incident) against
    the incident pulse delayed by the trip to the face and back: R = u_reflected / u_incident."""
    reflected = run["measured"] - run["incident"]
    shape = ricker(run["t"] - run["delay"], F0_1D, AMPLITUDE, 1.5 / F0_1D)[0]
    return float(reflected @ shape / (shape @ shape))


@pytest.mark.parametrize("wave", ["P", "S"])
def test_viscous_face_absorbs_normally_incident_wave(wave):
    """Catches a dashpot that is not rho c (x0.5 or x2 reflects 1/3 of the pulse) at normal incidence."""
    run = column_pulse(wave, "viscous")
    arrived(run)
    check_energy(run)
    measured = reflected_coefficient(run)
    print(f"{wave} viscous: R analytic 0, measured {measured:+.5f}")
    assert abs(measured) < REFLECTION_1D
    for scale in CONTROL_SCALES:
        control = column_pulse(wave, "viscous", scale)
        arrived(control)
        check_energy(control)
        wrong = reflected_coefficient(control)
        expected = (1.0 - scale) / (1.0 + scale)
        print(f"{wave} viscous, dashpots x{scale}: R analytic {expected:+.5f}, measured {wrong:+.5f}")
        assert abs(wrong - 0.0) > 20 * REFLECTION_1D      # the test would catch it
        assert abs(wrong - expected) < REFLECTION_1D      # and the measurement is sound


def viscoelastic_error(run, wave, dashpot_scale=1.0):
    """Relative L2 error of the measured reflection against the analytic one of a face with the
    boundary's springs and dashpots scaled by dashpot_scale, over the incident's norm."""
    impedance = RHO * run["speed"]
    stiffness = (ALPHA_N if wave == "P" else ALPHA_T) * MU / R_SPRING
    # The incident at the monitor delayed by the trip to the face and back, filtered by R(omega).
    delayed = ricker(run["t"] - run["delay"], F0_1D, AMPLITUDE, 1.5 / F0_1D)[0]
    expected = filtered(delayed, run["dt"],
                        lambda omega: viscoelastic_reflection(omega, stiffness, impedance, dashpot_scale * impedance))
    reflected = run["measured"] - run["incident"]
    return float(np.linalg.norm(reflected - expected) / np.linalg.norm(run["incident"])), expected, reflected


def spectral_ratio(reflected, run, frequency=F0_1D):
    """Reflected over incident spectrum at `frequency`, both referred to the face (the delay removed)."""
    omega = 2.0 * np.pi * frequency
    delayed = ricker(run["t"] - run["delay"], F0_1D, AMPLITUDE, 1.5 / F0_1D)[0]
    basis = np.exp(-1j * omega * run["t"])
    return complex(reflected @ basis / (delayed @ basis))


@pytest.mark.parametrize("wave", ["P", "S"])
def test_viscoelastic_face_reflects_as_r_of_omega(wave):
    """Catches a spring or dashpot off its formula: the reflection must follow R = -K/(K + 2 i omega rho c)."""
    run = column_pulse(wave, "viscoelastic")
    arrived(run)
    check_energy(run)
    error, expected, reflected = viscoelastic_error(run, wave)
    peak = np.max(np.abs(expected)) / AMPLITUDE
    print(f"{wave} viscoelastic: reflected peak analytic {peak:.4f}, measured "
          f"{np.max(np.abs(reflected)) / AMPLITUDE:.4f}, L2 error {error:.5f}; R(f0) analytic "
          f"{spectral_ratio(expected, run):.4f}, measured {spectral_ratio(reflected, run):.4f}")
    assert peak > 0.2  # the springs matter here
    assert error < REFLECTION_HISTORY_1D
    for scale in CONTROL_SCALES:
        control = column_pulse(wave, "viscoelastic", scale)
        arrived(control)
        check_energy(control)
        wrong, _, reflected = viscoelastic_error(control, wave)
        own, own_expected, _ = viscoelastic_error(control, wave, scale)
        print(f"{wave} viscoelastic, dashpots x{scale}: L2 error against the correct face {wrong:.5f}, "
              f"against its own {own:.5f}; R(f0) its own {spectral_ratio(own_expected, control):.4f}, "
              f"measured {spectral_ratio(reflected, control):.4f}")
        assert wrong > 10 * REFLECTION_HISTORY_1D
        assert own < REFLECTION_HISTORY_1D


# ---------------------------------------------------------------------------------------------
# Oblique incidence: a plane-strain slab whose top face zmax is the face under test


F0_OBLIQUE, H_OBLIQUE = 10.0, 2.5  # 18 elements per shortest S wavelength (c_s / 2.5 f0)
SLAB = (1000.0, 300.0)             # width (x) and height (z) of the slab (m), one element thick in y
MONITOR_X, MONITOR_DEPTH = 750.0, 120.0  # the monitor, below the top face (m)


def lysmer_as_free_surface(wave_type, angle, c_p, c_s):
    """lysmer_coefficients in pyfem.seismic.reflection's conventions (its free_surface_coefficients'
    signature): the reflected polarisations are the same; its incident SV is minus ours."""
    r_p, r_s = lysmer_coefficients(wave_type, angle)
    return {"PP": r_p, "PS": r_s} if wave_type == "P" else {"SS": -r_s, "SP": -r_p}


def slab_scene(wave, angle, surface):
    width, height = SLAB
    return parse_scene({
        "title": f"absorption {wave} {angle:g} deg",
        "mesh": {"builder": "box", "origin": [0.0, 0.0, 0.0], "size": [width, H_OBLIQUE, height], "h": H_OBLIQUE,
                 "order": 1},
        "materials": {"rock": {"E": E, "nu": NU, "rho": RHO}},
        "time": {"duration": 1.0},
        "wave": {"type": wave, "angle": angle, "azimuth": 0.0, "surface": surface,
                 "motion": {"ricker": {"f0": F0_OBLIQUE, "amplitude": AMPLITUDE}}},
        "boundary": {"type": "viscous", "face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "output": {"interval": 0.01, "xdmf_interval": 0.0},
    })


def _in_slab(vector):
    """Our x-z vectors (face at z = 0, medium above) in the slab's (face on top, medium below)."""
    return np.array([vector[0], -vector[1]])


@pytest.fixture(scope="module")
def oblique_sv():
    """Plane SV at 30 degrees (below the critical 35.8) going up to the slab's top face zmax, viscous,
    without input; xmin, xmax, zmin carry the input of the analytic field of the correct face:
    incident plus its Lysmer-Kuhlemeyer reflections (pyfem's FreeField with lysmer_as_free_surface
    as the 'surface' coefficients at z = top). They are then transparent to that field, and no
    edge of theirs diffracts into the monitor (with the incident field alone on them the upstream
    corner's diffraction put R_SP off by 0.01-0.04 at the monitor, 300-700 m from it).

    Returns {dashpot scale of zmax: (R_P, R_SV) measured, energy}, the analytic field, the runs'
    monitor data and the LK residual of the analytic field on the top face.
    """
    from pyfem.seismic import reflection
    from pyfem.seismic.forces import boundary_springs_and_dashpots, equivalent_input_forces
    from pyfem.seismic.setup import seismic_input_from_scene

    width, height = SLAB
    simulation = solver.prepare(slab_scene("SV", 30.0, height + 1.0e5))  # incident only in the window
    model = simulation.model
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(reflection, "free_surface_coefficients", lysmer_as_free_surface)
        analytic, _ = seismic_input_from_scene(slab_scene("SV", 30.0, height), model)
    others = [face for face in model.faces if face.name != "zmax"]
    top = next(face for face in model.faces if face.name == "zmax")
    simulation.input_arrays = equivalent_input_forces(others, model.node_coords, analytic, None, ALPHA_N, ALPHA_T)
    x = model.node_coords
    monitor = np.flatnonzero(np.isclose(x[:, 0], MONITOR_X) & np.isclose(x[:, 2], height - MONITOR_DEPTH))
    assert len(monitor) == 2
    # The analytic field meets the face's condition sigma e_z = -C_b v / A (the 2x2 solve and the
    # conventions above): residual over the traction's scale, at two points of the face.
    points, times = np.array([[MONITOR_X, 0.0, height], [MONITOR_X - 300.0, 0.0, height]]), np.linspace(0, 1, 500)
    traction = analytic.stress(points, times)[..., :, 2]
    velocity = analytic.velocity(points, times)
    residual = traction + RHO * velocity * np.array([C_S, C_S, C_P])
    lk_residual = np.abs(residual).max() / np.abs(traction).max()
    results = {}
    speed = C_S
    theta = math.radians(30.0)
    t_end = (MONITOR_X * math.sin(theta) + (height - MONITOR_DEPTH) * math.cos(theta)) / speed + 3.6 / F0_OBLIQUE
    for scale in (1.0,) + CONTROL_SCALES:
        scaled = dataclasses.replace(top, rho_cp=scale * np.asarray(top.rho_cp), rho_cs=scale * np.asarray(top.rho_cs))
        _, _, simulation.dashpot_nodes, simulation.dashpot_matrices = boundary_springs_and_dashpots(
            others + [scaled], len(simulation.mass), None, ALPHA_N, ALPHA_T)
        stepper = solver.make_stepper(simulation)
        u, v, a = (np.zeros(3 * len(simulation.mass)) for _ in range(3))
        stepper.reset_energy(u, v, a, 0.0)
        dt = simulation.time_step.dt
        steps = int(math.ceil(t_end / dt))
        history = np.zeros((steps + 1, 3))
        t = 0.0
        for k in range(steps):
            t = stepper.run(u, v, a, 1, t)
            history[k + 1] = u.reshape(-1, 3)[monitor].mean(axis=0)
        results[scale] = {"t": dt * np.arange(steps + 1), "measured": history, "energy": stepper.energy()}
    times = results[1.0]["t"]
    incident = simulation.freefield.displacement(x[monitor[:1]], times)[:, 0]
    return {"runs": results, "incident": incident, "lk_residual": lk_residual}


def oblique_coefficients(run, incident, wave="SV", angle=30.0):
    """Least-squares (R_P, R_SV) of the measured reflection (measured - analytic incident) on the two
    reflected plane waves: R d_r y(t - lag_r), y the incident's amplitude along its polarisation at
    the monitor, lag_r = depth (eta_incident + eta_r) the trip to the face and back."""
    speed = C_P if wave == "P" else C_S
    p = math.sin(math.radians(angle)) / speed
    slowness, polarisation = _plane_wave(wave, p, False, speed)
    amplitude = incident[:, [0, 2]] @ _in_slab(polarisation)
    columns = []
    for kind, c in (("P", C_P), ("SV", C_S)):
        reflected_slowness, reflected_polarisation = _plane_wave(kind, p, True, c)
        lag = MONITOR_DEPTH * (abs(slowness[1]) + abs(reflected_slowness[1]))
        shape = np.interp(run["t"] - lag, run["t"], amplitude, left=0.0)
        columns.append(np.concatenate(np.outer(_in_slab(reflected_polarisation), shape)))
    reflected = (run["measured"] - incident)[:, [0, 2]]
    coefficients, *_ = np.linalg.lstsq(np.column_stack(columns), np.concatenate(reflected.T), rcond=None)
    return coefficients, amplitude


def test_viscous_face_reflects_oblique_sv_as_lysmer_kuhlemeyer(oblique_sv):
    """Catches a viscous face that is not Lysmer-Kuhlemeyer's at 30 degrees (R_SP 0.130, R_SS 0.138;
    dashpots x0.5 give -0.20, x2 +0.44)."""
    assert oblique_sv["lk_residual"] < ROUNDOFF
    expected = lysmer_coefficients("SV", 30.0)
    run = oblique_sv["runs"][1.0]
    measured, amplitude = oblique_coefficients(run, oblique_sv["incident"])
    # Guard: the incident arrived with its amplitude (along its polarisation, before any reflection).
    early = run["t"] < run["t"][np.argmax(np.abs(amplitude))] + 0.05
    assert np.max(np.abs(run["measured"][early][:, [0, 2]] @ _in_slab(_plane_wave("SV", 0.5 / C_S, False, C_S)[1]))) \
        == pytest.approx(AMPLITUDE, rel=0.01)
    energy = run["energy"]
    assert abs(energy["balance"]) < ROUNDOFF * energy["external_work"]
    print(f"SV 30 deg viscous: (R_SP, R_SS) analytic {expected.round(4)}, measured {measured.round(4)}")
    assert np.all(np.abs(measured - expected) < REFLECTION_OBLIQUE)
    for scale in CONTROL_SCALES:
        control = oblique_sv["runs"][scale]
        wrong, _ = oblique_coefficients(control, oblique_sv["incident"])
        own = lysmer_coefficients("SV", 30.0, scale)
        print(f"SV 30 deg viscous, top dashpots x{scale}: analytic of its own {own.round(4)}, measured {wrong.round(4)}")
        assert abs(control["energy"]["balance"]) < ROUNDOFF * control["energy"]["external_work"]
        assert np.max(np.abs(wrong - expected)) > 20 * REFLECTION_OBLIQUE  # the test would catch it
        # The monitor sees the face, not the side faces' input (which carries the correct face's field).
        assert np.max(np.abs(wrong - own)) < 0.25 * np.max(np.abs(own - expected))

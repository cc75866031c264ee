"""Interlayer contact end to end: bonded pairs equal the unsplit mesh, a sliding block matches
Newmark's rigid-block displacement, hard cases stay stable, energy closes, outputs are written.

Base shaking of the block tests (sliding, chatter) is applied in the frame of a rigid base: the
lower layer is held (its nodes get 1e20 times their mass: this test's own rigid base; the scene's
"fixed" faces are kernel constraints) and every
node of the upper layer gets the inertial force -M_i a_g(t), delivered by the kernel's
SeismicInput provider from a table of a_g (the provider evaluates P g(t - tau) + Q g'(t - tau)
with P = -M_i e, Q = 0, tau = 0). Gravity is not a body force of the dynamic run: the block's
weight is in the static pair forces A sigma0 n of a geostatic [initial_stress] whose surface is the
top of the block, so the total normal force of the interface is the block's weight m g.
"""
import copy
import json
import math
import pathlib
import tomllib

import numpy as np
import pytest
from scipy.spatial import cKDTree

from conftest import ENERGY_BALANCE, LOCAL_STEPPING_BALANCE, ROUNDOFF, rel_error
from pyfem.initial_stress import STANDARD_GRAVITY
from pyfem.output import PAIR_COLUMNS, PAIR_STATES
from pyfem.scene import SceneError, parse_scene
from pyfem.distributed_model import model_in_memory
from pyfem.solver import run

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
# The normal lag's slip history on h = 5, 2.5, 1.25 m (test_slip_between_dissimilar_rocks_converges_with_the_normal_lag):
# differences between successive meshes measured 2.19 % and 0.512 %, order 2.10; two-sided bounds on the
# order, the finer difference within about twice the measured.
SLIP_LAG_ORDER = (1.75, 2.45)
SLIP_LAG_DIFFERENCE = 0.01
WORKFLOW = REPOSITORY / "workflows" / "scenes" / "contact_two_layer_sv.toml"
HELD_MASS_FACTOR = 1.0e20

SLIDING_BLOCK_TOLERANCE = 1.5e-3  # the block's permanent slip against Newmark's rigid block (measured 6.7e-4)


def workflow_data(path=WORKFLOW) -> dict:
    with open(path, "rb") as stream:
        return tomllib.load(stream)


def scene_from(data: dict, changes=()) -> "Scene":
    data = copy.deepcopy(data)
    for dotted, value in changes:
        *parents, leaf = dotted.split(".")
        node = data
        for part in parents:
            node = node.setdefault(part, {})
        if value is None:
            node.pop(leaf, None)
        else:
            node[leaf] = value
    return parse_scene(data, source="test", base_dir=REPOSITORY)


@pytest.mark.parametrize("order", [1, 2])
def test_bonded_pairs_reproduce_the_unsplit_mesh_to_roundoff(order):
    data = workflow_data()
    # Strengths far above any stress of the pulse: every pair stays bonded. One dt for both
    # runs (below both stable steps) so that the arithmetic can agree.
    dt = 1.0e-3 if order == 1 else 4.0e-4
    common = [("mesh.order", order), ("time.dt", dt), ("time.duration", 0.6)]
    bonded = scene_from(data, common + [("contact.cohesion", 1.0e15), ("contact.tensile_strength", 1.0e15)])
    unsplit = scene_from(data, common + [("contact", None), ("pair_monitor", None)])
    histories = []
    for scene in (bonded, unsplit):
        model = model_in_memory(scene)
        stepper, _ = model.stepper()
        n = 3 * model.part.n_local
        u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        t, samples = 0.0, []
        steps = round(0.05 / model.time_step.dt)
        for _ in range(12):
            t = stepper.run(u, v, a, steps, t)
            samples.append(u.copy())
        histories.append((model, np.array(samples)))
    (split_sim, split_u), (whole_sim, whole_u) = histories
    assert split_sim.time_step.dt == whole_sim.time_step.dt
    assert len(split_sim.part.pairs) > 0 and whole_sim.contact is None
    assert split_sim.contact.state_counts()[0] == len(split_sim.part.pairs)  # all bonded
    # Every node of the split mesh against the unsplit node at its coordinates (both copies of a pair;
    # the kernel's numbering of each model).
    distance, unsplit_node = cKDTree(whole_sim.part.coords).query(split_sim.part.coords)
    assert np.max(distance) < 1e-9
    split_nodal = split_u.reshape(len(split_u), -1, 3)
    whole_nodal = whole_u.reshape(len(whole_u), -1, 3)[:, unsplit_node]
    assert np.max(np.abs(whole_nodal)) > 1e-4  # the wave has passed through the interface
    assert rel_error(split_nodal, whole_nodal) < ROUNDOFF
    # Monitors interpolate the same fields.
    checks = 0
    split_monitors, whole_monitors = split_sim.monitors, whole_sim.monitors
    for j, index in enumerate(split_monitors.index):
        name = split_sim.names[index]
        k = list(whole_monitors.index).index(whole_sim.names.index(name))
        monitor_split = np.einsum("m,tmc->tc", split_monitors.weights[j], split_nodal[:, split_monitors.nodes[j]])
        whole_full = whole_u.reshape(len(whole_u), -1, 3)
        monitor_whole = np.einsum("m,tmc->tc", whole_monitors.weights[k], whole_full[:, whole_monitors.nodes[k]])
        assert rel_error(monitor_split, monitor_whole) < ROUNDOFF
        checks += 1
    assert checks == len(split_sim.names) == 3
    # Bonded pairs constrain the split system to the unsplit one (u_i = u_j), so by the Rayleigh
    # quotient omega_max(split) >= omega_max(unsplit): the split step is safe for bonded pairs.
    # (Equal here up to the power iteration's convergence: the top mode does not open the interface.
    # 300 iterations from the node coordinates' start vector leave the two estimates 3.9e-4 apart at
    # Q2, measured; 1e-4 held for the kernel's former seeded start, by chance of its two vectors.)
    assert split_sim.time_step.critical <= whole_sim.time_step.critical * (1.0 + 1e-3)


# --------------------------------------------------------------------------- block on a rigid base

def block_scene(friction_angle, thickness=1.0, rho_upper=2500.0, E=1.0e10, h=0.5, cohesion=0.0, duration=1.5,
                tensile_strength=0.0, output_interval=0.01):
    """A 2 x 1 m block of `thickness` on a 1 m base layer, interface frictional (no cohesion by default)."""
    size_z = 1.0 + thickness
    return parse_scene({
        "title": "block on a rigid base",
        "mesh": {"builder": "box", "size": [2.0, 1.0, size_z], "h": h, "order": 1,
                 "layers": [{"material": "base", "thickness": 1.0}, {"material": "block", "thickness": thickness}]},
        "materials": {"base": {"E": E, "nu": 0.25, "rho": 2500.0}, "block": {"E": E, "nu": 0.25, "rho": rho_upper}},
        "time": {"duration": duration, "safety": 0.8},
        "boundary": {"type": "free"},
        "initial_stress": {"surface": size_z, "rho": rho_upper, "k": [1.0, 1.0, 1.0]},
        "contact": {"interfaces": ["interface_1"], "cohesion": cohesion, "friction_angle": friction_angle,
                    "tensile_strength": tensile_strength},
        "output": {"interval": output_interval, "xdmf_interval": 0.0},
    })


def shake_block(simulation, acceleration, direction, table_dt=1.0e-4):
    """Holds the base layer and adds the inertial force -M_i a_g(t) direction on every block node.

    Args:
        simulation: the block scene's model in memory (pyfem.distributed_model.model_in_memory, one
            rank; modified before its stepper is built: base masses raised, input arrays set).
        acceleration: a_g(t) (m/s^2), vectorised; its table runs over the scene's duration.
        direction: unit vector of the base acceleration.
    """
    part = simulation.part
    model = part.model
    base = model.cell_tags.indices[model.cell_tags.values == model.regions["base"]]
    base_nodes = part.kernel_nodes(np.unique(model.V.dofmap.list.array.reshape(model.n_cells, -1)[base]))
    block_nodes = np.setdiff1d(np.arange(part.n_local), base_nodes).astype(np.int32)
    part.mass[base_nodes] *= HELD_MASS_FACTOR
    n_samples = math.ceil(simulation.scene["time"]["duration"] / table_dt) + 4
    t = table_dt * np.arange(n_samples)
    g = acceleration(t)
    dg = np.gradient(g, table_dt)
    simulation.input_arrays = {
        "table_t0": 0.0, "table_dt": table_dt, "g": g[None, :].copy(), "dg": dg[None, :].copy(),
        "ddg": np.gradient(dg, table_dt)[None, :].copy(),
        "node_ptr": np.arange(len(block_nodes) + 1, dtype=np.int64), "nodes": block_nodes,
        "table": np.zeros(len(block_nodes), dtype=np.int32), "tau": np.zeros(len(block_nodes)),
        "P": np.ascontiguousarray(-part.mass[block_nodes, None] * np.asarray(direction, float)[None, :]),
        "Q": np.zeros((len(block_nodes), 3)),
    }
    return block_nodes


def newmark_sliding_block(acceleration, yield_acceleration, duration, dt=1.0e-5):
    """Permanent slip of a rigid block on a base with acceleration a_g(t), two-way Coulomb sliding.

    Relative velocity s' of the block: sliding, s'' = -a_g - a_y sign(s'); stuck (s' = 0) while
    |a_g| <= a_y. Symplectic Euler with a stop when s' changes sign (Newmark 1965).

    Returns:
        (times, slip) (s, m).
    """
    times = np.arange(0.0, duration + dt, dt)
    s, velocity, slip = 0.0, 0.0, np.empty(len(times))
    for k, t in enumerate(times):
        a_g = acceleration(t)
        if velocity == 0.0:
            if abs(a_g) > yield_acceleration:
                velocity = dt * (-a_g - yield_acceleration * np.sign(-a_g))
        else:
            new = velocity + dt * (-a_g - yield_acceleration * np.sign(velocity))
            velocity = 0.0 if new * velocity < 0.0 else new
        s += dt * velocity
        slip[k] = s
    return times, slip


def run_block(simulation, n_outputs=None, observe=None):
    """Steps the model in memory over its duration in output chunks; returns (stepper, energy samples, u)."""
    stepper, _ = simulation.stepper()
    n = 3 * simulation.part.n_local
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    t = 0.0
    stepper.reset_energy(u, v, a, t)
    steps = simulation.time_step.steps_per_output
    energies = []
    for _ in range(n_outputs or simulation.n_steps // steps):
        t = stepper.run(u, v, a, steps, t)
        assert np.isfinite(u).all()
        energies.append(stepper.energy())
        if observe is not None:
            observe(t, u)
    return stepper, energies, u


def test_sliding_block_matches_newmark_rigid_block_displacement():
    # A one-sided half-sine pulse of 0.5 g against a yield acceleration of 0.2 g: one long slip
    # (a symmetric input mostly slides back and forth and leaves a small, cancelling residue).
    mu = 0.2
    amplitude, frequency = 0.5 * STANDARD_GRAVITY, 2.0

    def acceleration(t):
        t = np.asarray(t, dtype=float)
        return np.where(t < 0.5 / frequency, amplitude * np.sin(2 * np.pi * frequency * t), 0.0)

    simulation = model_in_memory(block_scene(math.degrees(math.atan(mu))))
    shake_block(simulation, acceleration, [1.0, 0.0, 0.0])
    stepper, energies, u = run_block(simulation)
    pairs = simulation.part.pairs
    slip = simulation.contact.relative_displacement(u)[:, 0].mean()
    # The weight is in the static forces: sum N = m g, so the yield acceleration is mu g.
    _, reference = newmark_sliding_block(lambda t: float(acceleration(t)), mu * STANDARD_GRAVITY,
                                         simulation.scene["time"]["duration"])
    print(f"slip {slip:.7f} m, Newmark rigid block {reference[-1]:.7f} m, "
          f"off by {abs(slip - reference[-1]) / abs(reference[-1]):.2e}")
    assert abs(reference[-1]) > 0.05  # a real permanent displacement
    # measured 6.7e-4 (0.070283 against 0.070236 m): catches the friction coefficient off by 0.2 %
    assert abs(slip - reference[-1]) < SLIDING_BLOCK_TOLERANCE * abs(reference[-1])
    assert np.allclose(np.asarray(simulation.contact.normal_force()).sum(),
                       2500.0 * 2.0 * 1.0 * STANDARD_GRAVITY, rtol=0.05)
    # Energy: balance including contact work closes; friction dissipates.
    final = energies[-1]
    scale = max(max(abs(e["external_work"]) for e in energies), max(e["kinetic"] + e["strain"] for e in energies))
    print(f"largest energy balance {max(abs(e['balance']) for e in energies) / scale:.2e} of the scale")
    # global stepping's identity: catches the contact (friction) work missing or off by any fraction
    assert max(abs(e["balance"]) for e in energies) < ENERGY_BALANCE * scale
    assert min(e["friction_dissipation"] for e in energies) >= 0.0
    assert final["friction_dissipation"] > 0.1 * scale
    assert len(pairs) == 15


def test_contact_chatter_interface_opens_and_closes_thousands_of_times():
    """Vertical base shaking at 1.5 g, 50 Hz lifts the block off (the interface has no tensile
    strength) and lands it again, over and over: every pair opens and closes tens of times."""
    amplitude, frequency, duration = 1.5 * STANDARD_GRAVITY, 50.0, 2.0

    def acceleration(t):
        return amplitude * np.sin(2 * np.pi * frequency * np.asarray(t, dtype=float))

    simulation = model_in_memory(block_scene(30.0, duration=duration, output_interval=0.0005))
    shake_block(simulation, acceleration, [0.0, 0.0, 1.0])
    previous = {"open": None, "transitions": 0}
    peak = {"u": 0.0}

    def observe(t, u):
        is_open = np.asarray(simulation.contact.state()) == 3
        if previous["open"] is not None:
            previous["transitions"] += int(np.count_nonzero(is_open != previous["open"]))
        previous["open"] = is_open
        peak["u"] = max(peak["u"], float(np.max(np.abs(u))))

    stepper, energies, u = run_block(simulation, observe=observe)
    print(f"open/close transitions {previous['transitions']}, peak |u| {peak['u']:.3g} m")
    assert previous["transitions"] > 1500  # 15 pairs
    # Bounded: the block bounces by millimetres (free flight at ~1 g for ~1/50 s), it does not fly away.
    assert peak["u"] < 0.05
    scale = max(max(abs(e["external_work"]) for e in energies), max(e["kinetic"] + e["strain"] for e in energies))
    print(f"largest energy balance {max(abs(e['balance']) for e in energies) / scale:.2e} of the scale")
    # global stepping's identity: catches the opening/closing pairs' work missing or off by any fraction
    assert max(abs(e["balance"]) for e in energies) < ENERGY_BALANCE * scale
    stored = np.array([e["kinetic"] + e["strain"] for e in energies])
    assert np.max(stored[len(stored) // 2:]) < 3.0 * np.max(stored[: len(stored) // 2])  # no growth


# --------------------------------------------------------------------------- hard cases through scenes

def hard_scene(**changes):
    """Three layers: soft, a thin 28 GPa layer, soft; both interfaces in contact; strong oblique SV."""
    data = {
        "title": "hard case",
        "mesh": {"builder": "box", "size": [40.0, 4.0, 40.0], "h": 4.0, "order": 1,
                 "layers": [{"material": "soft", "thickness": 19.5}, {"material": "stiff", "thickness": 1.0},
                            {"material": "soft", "thickness": 19.5}]},
        "materials": {"soft": {"E": 2.0e9, "nu": 0.30, "rho": 2400.0},
                      "stiff": {"E": 28.0e9, "nu": 0.167, "rho": 2500.0}},
        "time": {"duration": 1.0, "safety": 0.8},
        "wave": {"type": "SV", "angle": 20.0, "surface": 45.0, "medium": "soft",
                 "motion": {"ricker": {"f0": 4.0, "amplitude": 0.02}}},
        "initial_stress": {"surface": 45.0, "rho": 2400.0, "k": [1.4, 1.2, 1.15]},
        "contact": {"interfaces": ["interface_1", "interface_2"], "cohesion": 2.0e4, "friction_angle": 20.0,
                    "tensile_strength": 1.0e4},
        "pair_monitor": [{"name": "upper", "point": [20.0, 2.0, 20.5]}],
        "output": {"interval": 0.01, "xdmf_interval": 0.0},
    }
    for dotted, value in changes.items():
        *parents, leaf = dotted.split("__")
        node = data
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return parse_scene(data, source="test")


def assert_stable_run(summary, out_dir):
    assert summary["status"] == "finished"
    energy = summary["energy"]
    assert all(math.isfinite(value) for value in energy.values())
    local = "local time stepping" in summary["dt_reason"]
    print(f"{summary['dt_reason']}; energy balance {energy['balance_error']:.2e}")
    # global stepping's identity (local stepping's O(dt^2) plain account if "auto" turned it on):
    # catches the contact or damping work missing from the account
    assert energy["balance_error"] < (LOCAL_STEPPING_BALANCE if local else ENERGY_BALANCE)
    assert energy["friction_dissipation"] >= 0.0
    rows = np.loadtxt(out_dir / "energy.csv", delimiter=",", skiprows=1)
    assert np.all(np.isfinite(rows))
    with open(out_dir / "energy.csv") as stream:
        header = stream.readline().strip().split(",")
    stored = rows[:, header.index("kinetic")] + rows[:, header.index("strain")]
    # Bounded energy: nothing stored beyond what the input delivered.
    assert np.max(stored) <= 1.01 * np.max(np.abs(rows[:, header.index("external_work")]))
    assert summary["dt"] <= summary["dt_critical"]  # automatic, safe step


def test_hard_case_stiffness_contrast_thin_layer_slides_and_stays_stable(tmp_path):
    summary = run(hard_scene(), tmp_path / "run")
    assert_stable_run(summary, tmp_path / "run")
    states = summary["pair_states"]
    # The case is hard only if the interfaces really slip or open.
    assert max(np.add(states["sliding"], states["separated"])) > 0
    assert summary["n_pairs"] == 2 * (10 + 1) * (1 + 1)


def test_hard_case_mass_ratio_100_across_pairs(tmp_path):
    # Pair masses ~ rho x element height: 1 m elements in the thin layer, 3.9 m in the soft ones.
    scene = hard_scene(materials__stiff={"E": 28.0e9, "nu": 0.167, "rho": 100.0 * 2400.0 * 3.9})
    pairs = model_in_memory(scene, solve_stage=False).part.pairs
    ratio = pairs.mass[:, 1] / pairs.mass[:, 0]
    assert np.isclose(np.max(np.maximum(ratio, 1 / ratio)), 100.0, rtol=1e-9)
    summary = run(scene, tmp_path / "run")
    assert_stable_run(summary, tmp_path / "run")


def test_hard_case_rayleigh_damping_20_percent(tmp_path):
    summary = run(hard_scene(damping={"ratio": 0.2, "frequencies": [2.0, 20.0]}), tmp_path / "run")
    assert_stable_run(summary, tmp_path / "run")
    assert summary["energy"]["damping_work"] > 0.0
    assert summary["rayleigh"]["beta"] > 0.0


def test_user_dt_above_the_stable_step_is_a_scene_error():
    simulation = model_in_memory(hard_scene(), solve_stage=False)
    too_large = 1.5 * simulation.time_step.critical
    with pytest.raises(SceneError) as caught:
        model_in_memory(hard_scene(time={"duration": 1.0, "dt": too_large}), solve_stage=False)
    assert caught.value.key == "time.dt"
    assert f"{simulation.time_step.critical:.6g}" in str(caught.value)


@pytest.mark.slow
def test_hard_case_20_s_of_el_centro(tmp_path):
    scene = hard_scene(time={"duration": 20.0, "safety": 0.8},
                       wave={"type": "SV", "angle": 30.0, "surface": 45.0, "medium": "soft",
                             "motion": {"record": {"file": str(REPOSITORY / "data" / "elcentro_1940_ns.txt"),
                                                   "units": "g", "pga": 0.32, "window": [0.0, 20.0]}}},
                       contact={"interfaces": ["interface_1", "interface_2"], "cohesion": 2.0e4,
                                "friction_angle": 20.0, "tensile_strength": 1.0e4,
                                "deterioration": {"R0": 0.75, "lambda": 5.0}})
    summary = run(scene, tmp_path / "run")
    assert_stable_run(summary, tmp_path / "run")
    assert summary["pairs"]["upper"]["min_D"] < 1.0


# --------------------------------------------------------------------------- outputs

def test_pair_csv_header_and_run_json_state_counts(tmp_path):
    out = tmp_path / "run"
    scene = scene_from(workflow_data(), [("time.duration", 0.1)])
    summary = run(scene, out)
    with open(out / "pairs" / "I1.csv") as stream:
        header = stream.readline().strip()
    assert header == ",".join(PAIR_COLUMNS) == "t,dux,duy,duz,slip,gap,N,T,D,state"
    rows = np.loadtxt(out / "pairs" / "I1.csv", delimiter=",", skiprows=1)
    on_disk = json.loads((out / "run.json").read_text())
    states = on_disk["pair_states"]
    assert set(PAIR_STATES) <= set(states)
    n_pairs = on_disk["n_pairs"]
    assert n_pairs == (12 + 1) * (2 + 1)
    totals = np.sum([states[name] for name in PAIR_STATES], axis=0)
    assert len(states["t"]) == len(rows) and np.all(totals == n_pairs)
    # The monitored pair carries its overburden: N = rho g depth A at t = 0.
    pair = summary["pairs"]["I1"]
    area = 5.0 * 5.0
    assert np.isclose(rows[0, PAIR_COLUMNS.index("N")], 2500.0 * STANDARD_GRAVITY * (100.0 - 30.0) * area, rtol=1e-12)
    assert pair["final_state"] in PAIR_STATES
    with open(out / "energy.csv") as stream:
        energy_header = stream.readline().strip().split(",")
    assert energy_header[-2:] == ["contact_work", "friction_dissipation"]
    assert (out / "plots" / "pair_states.png").stat().st_size > 0
    xdmf = (out / "fields.xdmf").read_text()
    assert all(f'Name="{name}"' in xdmf for name in ("pair_state", "pair_slip", "pair_D", "displacement"))


def test_pair_updates_do_not_depend_on_the_pair_order():
    """The pair loop runs in parallel from 1024 pairs, colour by colour (pairs of one colour share no
    node, so they are independent): pairs in the given order or reversed, the same bits, while pairs
    slide and open. (One thread against two for the correction alone: tests/cpp/test_contact.cpp;
    a whole run differs between thread counts in the last bits of the stiffness product's sums.)"""
    scene = hard_scene(mesh__size=[100.0, 10.0, 20.0], mesh__h=1.0,
                       mesh__layers=[{"material": "soft", "thickness": 8.0}, {"material": "stiff", "thickness": 12.0}],
                       contact__interfaces=["interface_1"], wave__motion={"ricker": {"f0": 10.0, "amplitude": 0.02}},
                       wave__surface=25.0, initial_stress__surface=25.0, pair_monitor=[])
    simulation = model_in_memory(scene)
    arrays = simulation.contact_arrays
    n_pairs = len(arrays["area"])
    assert n_pairs >= 1024  # the threaded path
    reverse = np.arange(n_pairs)[::-1]
    reversed_arrays = {key: (np.ascontiguousarray(value[reverse]) if isinstance(value, np.ndarray)
                             and value.shape[:1] == (n_pairs,) else value) for key, value in arrays.items()}
    results = []
    for contact_arrays, order in ((arrays, np.arange(n_pairs)), (reversed_arrays, reverse)):
        simulation.contact_arrays = contact_arrays  # (the model's stepper makes its pairs from them)
        stepper, _ = simulation.stepper()
        n = 3 * simulation.part.n_local
        u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
        stepper.run(u, v, a, round(0.14 / simulation.time_step.dt), 0.0)
        contact = simulation.contact
        states = np.empty(n_pairs, dtype=np.int8)
        states[order] = np.asarray(contact.state())
        forces = np.empty(n_pairs)
        forces[order] = np.asarray(contact.normal_force())
        results.append((u, v, states, forces, contact.state_counts()))
    print("state counts (bonded, stick, sliding, separated):", results[0][4])
    assert results[0][4][0] < n_pairs  # the pulse broke bonds: pairs stick again, slide or opened
    assert results[0][4][2] > 0 and results[0][4][3] > 0
    for mine, theirs in zip(results[0][:4], results[1][:4]):
        assert np.array_equal(mine, theirs)


# --------------------------------------------------------------------------- slip against mesh size

def slip_run(tmp_path, h, contrast):
    """The interface-slip study's scene (workflows/interface_slip_accuracy.py: the two-layer box made
    plane strain, no cohesion, a 5 cm SV wavelet) at element size h; (t, dux, N) of the centre pair."""
    import sys
    sys.path.insert(0, str(REPOSITORY / "workflows"))
    from interface_slip_accuracy import scene

    out = tmp_path / f"{contrast}_h{h:g}"
    run(scene(1, h, 0.8, contrast), out)
    data = np.genfromtxt(out / "pairs" / "I1.csv", delimiter=",", names=True)
    return data["t"], data["dux"], data["N"], data["state"]


def test_slip_between_layers_of_one_rock_converges_in_h_and_keeps_the_normal_force(tmp_path):
    """An interface between two layers of the same rock slides under the wave (no cohesion, 30 deg):
    the centre pair's peak slip converges at second order or better in h (measured 6.7089, 6.7260,
    6.7306, 6.7313 cm at h = 5, 2.5, 1.25, 0.625 m: orders 2.1, 2.9 against the finest), and, the two
    sides being alike, sliding leaves the normal force unchanged (no slip-opening coupling; between
    sandstone and the softer rock it is not: docs/interface_slip_accuracy.md)."""
    peaks = {}
    for h in (5.0, 2.5, 1.25, 0.625):
        _, slip, normal, state = slip_run(tmp_path, h, "homogeneous")
        assert (state == 2).any(), "the pair slid"
        assert np.abs(normal - normal[0]).max() < 1e-9 * normal[0]
        peaks[h] = np.abs(slip).max()
    assert peaks[0.625] > 0.05   # 6.7 cm
    errors = [abs(peaks[h] - peaks[0.625]) for h in (5.0, 2.5, 1.25)]
    orders = [math.log2(e0 / e1) for e0, e1 in zip(errors, errors[1:])]
    print(f"peak slip {[f'{100 * p:.4f}' for p in peaks.values()]} cm, errors {errors}, orders {orders}")
    assert errors[0] < 0.01 * peaks[0.625] and min(orders) > 1.5


def test_slip_between_dissimilar_rocks_converges_with_the_normal_lag(tmp_path):
    """Sandstone under the softer rock: sliding swings the pair's normal force (to opening and 3.5x
    its static value on fine meshes) and without [contact.normal_lag] the slip converges slowly
    (docs/interface_slip_accuracy.md). With the lag (L = 1 cm, V* = 1 m/s) the centre pair's slip
    history converges at second order in h: the differences between successive meshes (h = 5, 2.5,
    1.25 m: 9, 18 and 36 elements per wavelength), relative L2 of the finer history, SLIP_LAG_DIFFERENCES,
    fall at the order SLIP_LAG_ORDER; the peak slip on the two finer meshes agrees to 0.1 % (measured
    7.7541 / 7.7533 cm; the finest run of the study, 145 per wavelength, 7.7672). Catches slip that
    stops converging (the lag's N* not followed, as without the lag: order 0.67 on the case's mesh)."""
    import sys
    sys.path.insert(0, str(REPOSITORY / "workflows"))
    from interface_slip_accuracy import scene

    peaks, histories = {}, {}
    for h in (5.0, 2.5, 1.25):
        out = tmp_path / f"lag_h{h:g}"
        run(scene(1, h, 0.8, "bimaterial, lag"), out)
        data = np.genfromtxt(out / "pairs" / "I1.csv", delimiter=",", names=True)
        assert (data["state"] == 2).any(), "the pair slid"
        assert np.ptp(data["N"]) > 0.2 * data["N"][0], "sliding changed the normal force (dissimilar rocks)"
        peaks[h] = np.abs(data["dux"]).max()
        histories[h] = (data["t"], data["dux"])
    assert all(np.array_equal(histories[5.0][0], histories[h][0]) for h in histories), "the same output times"
    differences = [np.linalg.norm(histories[h][1] - histories[h / 2][1]) / np.linalg.norm(histories[h / 2][1])
                   for h in (5.0, 2.5)]
    order = math.log2(differences[0] / differences[1])
    print(f"peak slip with the lag: {peaks}; successive history differences {differences}, order {order:.3f}")
    assert peaks[1.25] > 0.07 and abs(peaks[2.5] - peaks[1.25]) < 1e-3 * peaks[1.25]
    assert SLIP_LAG_ORDER[0] < order < SLIP_LAG_ORDER[1]
    assert differences[1] < SLIP_LAG_DIFFERENCE


def test_a_pair_monitor_far_from_every_interface_is_warned_about():
    """A pair monitor reports the pair nearest its point; a point 14.6 m from the interface (a typo
    in z, say) is accepted, but with a warning naming the monitor, the distance and the pair. And a
    layer of another material than wave.medium on the input faces is warned about."""
    data = tomllib.loads((REPOSITORY / "tests" / "scenes" / "mpi_hard_contact.toml").read_text())
    data["time"]["duration"] = 0.001
    near = model_in_memory(parse_scene(data, source="test"), solve_stage=False)
    assert not any("pair_monitor" in warning for warning in near.scene.warnings)
    # The 1 m stiff layer reaches the side faces: 1 / 40 of their height, 2 % of the input area,
    # which receives the soft medium's free field (a homogeneous box warns nothing: test_bad_input).
    assert any(warning.startswith("wave.medium = 'soft': 2 % of the input faces' area lies in other materials")
               for warning in near.scene.warnings), near.scene.warnings
    data["pair_monitor"][0]["point"] = [20.0, 2.0, 35.0]
    far = parse_scene(data, source="test")
    model_in_memory(far, solve_stage=False)
    warning = next(warning for warning in far.warnings if "pair_monitor 'upper'" in warning)
    assert "14.6 m from the nearest contact pair" in warning


def test_release_time_reaches_the_dynamic_runs_pairs_only_and_a_bad_one_is_a_scene_error():
    from pyfem.static import stage_pair_arrays

    data = workflow_data()
    data["contact"]["release_time"] = 0.02
    simulation = model_in_memory(parse_scene(data, source="test"), solve_stage=False)
    assert simulation.contact_arrays["release_time"] == 0.02
    assert stage_pair_arrays(simulation.scene, simulation.contact_arrays)["release_time"] is None
    simulation.stepper()  # the kernel takes it
    assert simulation.contact is not None  # (the pairs were made, with it)
    for bad in (0.0, -1.0):
        data["contact"]["release_time"] = bad
        with pytest.raises(SceneError, match="contact.release_time"):
            parse_scene(data, source="test")

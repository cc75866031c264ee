"""Interlayer dynamic contact in the kernel (pyfem._kernels.ContactPairs), paper Secs. 2-3.

Tiny synthetic systems built here, each with an exact or independent answer:
- (a) bonded pairs reproduce the unsplit (merged-node) system to round-off, with and without
  mass-proportional damping and with a 3x3 dashpot on one pair node;
- (b) shear: slip starts when |T| reaches c D A + mu_s N D, then |T| = mu_d N D; the bond is not
  regained (a second loading cycle slips at mu_s N D);
- (c) tension: separation at -N = t_s D A, nothing carried while open, compression again when
  the gap closes, interpenetration at round-off level;
- (d) D(t) equals the closed form of Eqs. 9-11 for prescribed slip-velocity histories, and the
  slip force is mu_d N D(t);
- (e) the energy balance with contact_work is zero to round-off and friction dissipation >= 0;
- (f) a 100:1 mass ratio and a chattering pair stay finite with bounded energy;
- (g) bad arguments raise ValueError naming the parameter;
- (h) the normal-stress lag (set_normal_lag): the friction follows the lagged N*, which obeys its
  exact exponential while the pair sticks, and a lag too short to matter changes nothing;
- (i) the gradual release of a broken bond (set_release_time): the force falls from the strength
  linearly over the release time (tension and shear), node 0 rings less, the account closes.
External forces enter through SeismicInput with tau = 0, P = force direction, Q = 0.
"""
import numpy as np
import pytest
import scipy.sparse as sp

from conftest import ROUNDOFF, rel_error

from pyfem import _kernels

EX, EY, EZ = np.eye(3)


@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """These systems have a few nodes: OpenMP fork/join per step would dominate the run time."""
    threads = _kernels.max_threads()
    _kernels.set_num_threads(1)
    yield
    _kernels.set_num_threads(threads)


# ---------------------------------------------------------------------------------------------
# Building blocks


def bsr_arrays(matrix):
    matrix = sp.csr_matrix(matrix).tobsr(blocksize=(3, 3))
    matrix.sort_indices()
    return (np.ascontiguousarray(matrix.indptr, dtype=np.int64),
            np.ascontiguousarray(matrix.indices, dtype=np.int32),
            np.ascontiguousarray(matrix.data, dtype=np.float64).reshape(-1, 3, 3))


def force_input(times, g, dg, ddg, entries):
    """SeismicInput of forces P_e g(t) on nodes; entries: list of (node, P (3,)). One table."""
    nodes = np.array([node for node, _ in entries], dtype=np.int32)
    return _kernels.SeismicInput(
        float(times[0]), float(times[1] - times[0]),
        np.ascontiguousarray(g[None, :]), np.ascontiguousarray(dg[None, :]),
        np.ascontiguousarray(ddg[None, :]),
        np.arange(len(entries) + 1, dtype=np.int64), nodes,
        np.zeros(len(entries), dtype=np.int32), np.zeros(len(entries)),
        np.array([P for _, P in entries], dtype=float).reshape(-1, 3), np.zeros((len(entries), 3)))


def sin2_history(duration, period, table_dt=1e-3):
    """g = sin^2(pi t / period) with exact derivatives: rises to 1 and back once per period."""
    t = np.arange(0.0, duration + 2 * table_dt, table_dt)
    w = np.pi / period
    return t, np.sin(w * t) ** 2, w * np.sin(2 * w * t), 2 * w ** 2 * np.cos(2 * w * t)


def sine_history(duration, period, table_dt=1e-3):
    t = np.arange(0.0, duration + 2 * table_dt, table_dt)
    w = 2 * np.pi / period
    return t, np.sin(w * t), w * np.cos(w * t), -w ** 2 * np.sin(w * t)


def constant_history():
    """g = 1 for all t >= -1 (held after the last sample)."""
    t = np.array([-1.0, 0.0])
    return t, np.ones(2), np.zeros(2), np.zeros(2)


def anchored_pair_system(mass_i, mass_j, k_anchor, dt, alpha=0.0):
    """Node 0 (side i) tied to the ground by an isotropic spring k_anchor; node 1 (side j) free."""
    K = sp.lil_matrix((6, 6))
    K[0:3, 0:3] = k_anchor * np.eye(3)
    stepper = _kernels.Stepper(*bsr_arrays(K), np.array([mass_i, mass_j]), dt, alpha)
    return stepper


def one_pair(normal, static_force, area=1.0, cohesion=0.0, tensile=0.0, mu_s=0.5, mu_d=0.4):
    return _kernels.ContactPairs(np.array([[0, 1]], dtype=np.int32), np.array([area]),
                                 np.array([normal], dtype=float), np.array([static_force], dtype=float),
                                 cohesion, tensile, mu_s, mu_d)


def step_history(stepper, contact, n_steps, n_dofs, u=None, v=None, a=None, t0=0.0, every=1):
    """Runs n_steps in chunks of `every`; records t, u, v, state, N, T, D, forces after each chunk."""
    u = np.zeros(n_dofs) if u is None else u
    v = np.zeros(n_dofs) if v is None else v
    a = np.zeros(n_dofs) if a is None else a
    record = {key: [] for key in ("t", "u", "v", "state", "N", "T", "D", "R", "energy")}
    t = t0
    for _ in range(n_steps // every):
        t = stepper.run(u, v, a, every, t)
        record["t"].append(t)
        record["u"].append(u.copy())
        record["v"].append(v.copy())
        record["state"].append(contact.state()[0])
        record["N"].append(contact.normal_force()[0])
        record["T"].append(contact.tangential_force()[0])
        record["D"].append(contact.deterioration()[0])
        record["R"].append(contact.contact_force()[0])
        record["energy"].append(stepper.energy())
    return {key: np.array(value) if key != "energy" else value for key, value in record.items()}


def energy_scale(report):
    return max(abs(report["total"]), abs(report["initial"]), abs(report["external_work"]),
               abs(report["damping_work"]), abs(report["contact_work"]))


# ---------------------------------------------------------------------------------------------
# (a) bonded pairs = unsplit mesh


def split_system(n_nodes, split_nodes, seed):
    """A random SPD system built from links and groundings, merged and with each node in
    split_nodes duplicated (copy index n_nodes + k); every link and grounding touching a split
    node goes to the original or to the copy at random, its mass is divided at random.
    Returns (K_merged, mass_merged, K_split, mass_split, copy_of)."""
    rng = np.random.default_rng(seed)
    n_split = n_nodes + len(split_nodes)
    copy_of = {node: n_nodes + k for k, node in enumerate(split_nodes)}
    K_merged = np.zeros((3 * n_nodes, 3 * n_nodes))
    K_split = np.zeros((3 * n_split, 3 * n_split))

    def place(K, i, j, S):
        K[3 * i:3 * i + 3, 3 * i:3 * i + 3] += S
        K[3 * j:3 * j + 3, 3 * j:3 * j + 3] += S
        K[3 * i:3 * i + 3, 3 * j:3 * j + 3] -= S
        K[3 * j:3 * j + 3, 3 * i:3 * i + 3] -= S

    def side(node):
        return copy_of[node] if node in copy_of and rng.random() < 0.5 else node

    for i in range(n_nodes):
        B = rng.uniform(-1, 1, (3, 3))
        S = B @ B.T
        K_merged[3 * i:3 * i + 3, 3 * i:3 * i + 3] += S
        if i in copy_of:  # the grounding of a split node is shared by both sides
            K_split[3 * i:3 * i + 3, 3 * i:3 * i + 3] += 0.3 * S
            c = copy_of[i]
            K_split[3 * c:3 * c + 3, 3 * c:3 * c + 3] += 0.7 * S
        else:
            K_split[3 * i:3 * i + 3, 3 * i:3 * i + 3] += S
        for j in rng.integers(0, n_nodes, 3):
            if j == i:
                continue
            B = rng.uniform(-1, 1, (3, 3))
            S = B @ B.T
            place(K_merged, i, j, S)
            place(K_split, side(i), side(j), S)
    mass_merged = rng.uniform(1.0, 2.0, n_nodes)
    mass_split = np.concatenate([mass_merged, np.zeros(len(split_nodes))])
    for node, c in copy_of.items():
        share = rng.uniform(0.2, 0.8)
        mass_split[c] = (1 - share) * mass_merged[node]
        mass_split[node] = share * mass_merged[node]
    return K_merged, mass_merged, K_split, mass_split, copy_of


@pytest.mark.parametrize("alpha, dashpot", [(0.0, False), (0.3, False), (0.3, True)])
def test_bonded_pairs_reproduce_the_unsplit_system_to_roundoff(alpha, dashpot):
    n_nodes, split_nodes = 12, [2, 5, 9]
    K_m, mass_m, K_s, mass_s, copy_of = split_system(n_nodes, split_nodes, seed=4)
    dt = 0.5 * 2 / np.sqrt(np.linalg.eigvalsh(K_m / np.sqrt(np.outer(np.repeat(mass_m, 3),
                                                                       np.repeat(mass_m, 3))))[-1])
    merged = _kernels.Stepper(*bsr_arrays(K_m), mass_m, dt, alpha)
    split = _kernels.Stepper(*bsr_arrays(K_s), mass_s, dt, alpha)
    rng = np.random.default_rng(7)
    if dashpot:  # a full 3x3 dashpot on the copy of node 5 = on merged node 5
        D = rng.uniform(-1, 1, (3, 3))
        C = np.ascontiguousarray((D @ D.T)[None])
        merged.set_dashpots(np.array([5], dtype=np.int32), C)
        split.set_dashpots(np.array([copy_of[5]], dtype=np.int32), C)

    # A force history on a split node (shared between its sides) and on a plain node.
    times, g, dg, ddg = sin2_history(1000 * dt, 60 * dt, table_dt=dt)
    P2, P7 = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    merged.add_provider(force_input(times, g, dg, ddg, [(2, P2), (7, P7)]))
    split.add_provider(force_input(times, g, dg, ddg, [(2, 0.4 * P2), (copy_of[2], 0.6 * P2),
                                                            (7, P7)]))

    # Pairs with random normals and static forces; strengths too high to ever fail.
    normals = rng.standard_normal((3, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    pairs = np.array([[node, copy_of[node]] for node in split_nodes], dtype=np.int32)
    contact = _kernels.ContactPairs(pairs, np.array([1.0, 2.0, 0.5]), normals,
                                    -50.0 * normals + rng.uniform(-1, 1, (3, 3)), 1e9, 1e9, 0.6, 0.5)
    split.add_contact(contact)

    u_m = 0.1 * rng.standard_normal(3 * n_nodes)
    v_m = rng.standard_normal(3 * n_nodes)
    a_m = np.zeros(3 * n_nodes)
    expand = np.concatenate([np.arange(n_nodes), split_nodes])  # split node -> merged node
    dofs = (3 * expand[:, None] + np.arange(3)).ravel()
    u_s, v_s, a_s = u_m[dofs].copy(), v_m[dofs].copy(), a_m[dofs].copy()

    merged.run(u_m, v_m, a_m, 200, 0.0)
    split.run(u_s, v_s, a_s, 200, 0.0)
    assert np.abs(u_m).max() > 0.1  # something moved
    checks = 0
    for name, x_s, x_m in (("u", u_s, u_m), ("v", v_s, v_m), ("a", a_s, a_m)):
        assert rel_error(x_s, x_m[dofs]) < ROUNDOFF, name
        checks += 1
    assert np.all(contact.state() == 0) and contact.bond_intact().all()
    assert np.abs(contact.relative_displacement(u_s)).max() < ROUNDOFF * np.abs(u_m).max()
    report = split.energy()
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    # The contact forces are real (they hold the sides together) but do no work on a bonded pair.
    assert np.abs(contact.contact_force()).max() > 1e-3
    assert abs(report["contact_work"]) < ROUNDOFF * energy_scale(report)
    assert checks == 3


# ---------------------------------------------------------------------------------------------
# (b) shear test


def test_shear_slips_at_peak_strength_then_slides_at_dynamic_friction_without_cohesion():
    N0, area, cohesion, mu_s, mu_d = 100.0, 2.0, 10.0, 0.5, 0.4
    peak = cohesion * area + mu_s * N0      # 70 N: first cycle
    residual = mu_s * N0                    # 50 N: second cycle, bond lost
    dt, period = 1e-3, 2.0
    # Node 0 on a stiff damped anchor, node 1 with a light drag so that each slip ends soon
    # after the load falls (drag while stuck: c v = 50 * F'/k < 0.1 % of the load).
    stepper = anchored_pair_system(1.0, 1.0, 1e5, dt)
    stepper.set_dashpots(np.array([0, 1], dtype=np.int32),
                         np.array([300.0 * np.eye(3), 50.0 * np.eye(3)]))
    times, g, dg, ddg = sin2_history(2 * period, period)
    F_max = 75.0
    stepper.add_provider(force_input(times, g, dg, ddg, [(1, F_max * EX)]))
    contact = one_pair(EZ, -N0 * EZ, area, cohesion, cohesion, mu_s, mu_d)
    stepper.add_contact(contact)
    h = step_history(stepper, contact, int(2 * period / dt), 6)
    external = F_max * np.sin(np.pi * h["t"] / period) ** 2

    sliding = h["state"] == 2
    T = np.linalg.norm(h["T"], axis=1)
    checks = 0
    for cycle, strength in ((0, peak), (1, residual)):
        in_cycle = (h["t"] > cycle * period) & (h["t"] <= (cycle + 1) * period)
        first_slip = np.flatnonzero(in_cycle & sliding)[0]
        assert h["state"][first_slip - 1] == (0 if cycle == 0 else 1)
        # The last stuck step carried |T| just below the strength; the load at the slip is it.
        assert strength * 0.99 < T[first_slip - 1] <= strength
        assert abs(external[first_slip] - strength) < 0.01 * strength
        checks += 1
    assert np.all(np.abs(T[sliding] - mu_d * N0) < ROUNDOFF * N0)
    assert np.all(np.abs(h["N"] - N0) < ROUNDOFF * N0)  # no normal motion
    assert np.all(h["state"][h["t"] > period / 2 + 0.1] != 0)
    assert not contact.bond_intact()[0]
    # Slip happened in both cycles: node 1 ended displaced relative to node 0 along x.
    slip = contact.relative_displacement(h["u"][-1])[0]
    assert slip[0] > 0.1 and abs(slip[2]) < ROUNDOFF
    report = h["energy"][-1]
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    dissipation = np.array([e["friction_dissipation"] for e in h["energy"]])
    assert np.all(np.diff(dissipation) >= 0) and dissipation[-1] > 0
    # The slip work mu_d N0 * slip is what friction dissipated (to the discretisation).
    assert abs(dissipation[-1] - mu_d * N0 * slip[0]) < 1e-3 * dissipation[-1]
    assert checks == 2


# ---------------------------------------------------------------------------------------------
# (c) tension test


def test_tension_separates_at_tensile_strength_and_recontacts_without_interpenetration():
    N0, area, tensile = 100.0, 1.5, 20.0
    strength = tensile * area  # 30 N of net tension
    dt, period = 1e-3, 4.0
    stepper = anchored_pair_system(1.0, 1.0, 1e4, dt)
    stepper.set_dashpots(np.array([0], dtype=np.int32), np.array([100.0 * np.eye(3)]))
    times, g, dg, ddg = sine_history(period, period)
    F_max = 200.0
    stepper.add_provider(force_input(times, g, dg, ddg, [(1, F_max * EZ)]))
    contact = one_pair(EZ, -N0 * EZ, area, 1e3, tensile, 0.5, 0.4)
    stepper.add_contact(contact)
    h = step_history(stepper, contact, int(period / dt), 6)
    external = F_max * np.sin(2 * np.pi * h["t"] / period)
    gap = np.array([contact.relative_displacement(u)[0] @ EZ for u in h["u"]])

    state = h["state"]
    open_ = state == 3
    first_open = np.flatnonzero(open_)[0]
    assert np.all(state[:first_open] == 0)
    assert strength * 0.99 < -h["N"][first_open - 1] <= strength
    assert abs(external[first_open] - (N0 + strength)) < 0.01 * (N0 + strength)
    # Open: nothing carried (total force zero); the gap opens from the step after the decision
    # (the force at t_{n+1} acts on u_{n+2}).
    assert np.all(h["N"][open_] == 0.0) and np.all(h["T"][open_] == 0.0)
    still_open = open_[1:] & open_[:-1]
    assert gap[1:][still_open].min() > 0 and gap.max() > 0.1
    # Closed again later, in compression, bond lost, and no interpenetration beyond round-off.
    reclosed = np.flatnonzero(~open_ & (np.arange(len(state)) > first_open))
    assert len(reclosed) > 100
    assert np.all(np.isin(state[reclosed], [1, 2])) and np.all(h["N"][reclosed] >= 0)
    assert h["N"][reclosed].max() > N0
    assert gap.min() > -ROUNDOFF * gap.max()
    assert not contact.bond_intact()[0]
    report = h["energy"][-1]
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    assert report["friction_dissipation"] >= 0
    assert abs(report["contact_work"]) > 1.0  # the impact and the release did work


# ---------------------------------------------------------------------------------------------
# (d) deterioration


R0, LAM, DURATION, M_, N_, P_ = 0.75, 5.0, 2.0, 0.883, 0.02, 0.032


def closed_form_D(t, slip_rate):
    return (R0 + (1 - R0) * np.exp(-LAM * t / DURATION)) * M_ * (np.abs(slip_rate) + N_) ** -P_


def test_deterioration_equals_eqs_9_to_11_for_a_prescribed_slip_velocity():
    # Two free masses, no normal force, no cohesion: the pair slides carrying nothing, and node 1
    # under a constant force has v_x(t_n) = V0 + (F/M) t_n exactly (velocity reverses).
    dt, V0, F, mass = 1e-3, 0.3, -0.5, 1.0
    K = sp.csr_matrix((6, 6))
    stepper = _kernels.Stepper(*bsr_arrays(K), np.array([2.0, mass]), dt)
    stepper.add_provider(force_input(*constant_history(), [(1, F * EX)]))
    contact = one_pair(EZ, np.zeros(3), 1.0, 0.0, 0.0, 0.5, 0.4)
    contact.set_deterioration(R0, LAM, DURATION, M_, N_, P_)
    assert np.all(contact.deterioration() == 1.0)  # before any step
    stepper.add_contact(contact)
    v = np.zeros(6)
    v[3] = V0
    a = np.zeros(6)
    a[3] = F / mass
    n_steps = 1500
    h = step_history(stepper, contact, n_steps, 6, v=v, a=a)
    t_n = h["t"] - dt  # D at step n+1 uses the slip rate at t_n
    expected = closed_form_D(h["t"], V0 + F / mass * t_n)
    assert np.all(h["state"] == 2)
    assert np.all(h["R"] == 0.0)
    assert rel_error(h["D"], expected) < 1e-13
    assert h["D"].min() < 0.78 and h["D"].max() > 0.9  # eta decayed, gamma varied


def test_a_pair_at_its_limit_stays_bonded_until_the_earthquake_starts_then_slides_as_it_wears():
    """The wear clock starts at the record window's start (`start`), not at the run's t = 0 (the
    filter's lead-in before it is not shaking): a pair whose static shear is 99 % of its strength at
    rest (D = gamma(0) = 1.001) stays bonded and still through the lead-in, and slides once eta has
    fallen by 1 %, 0.0163 s after the start (eta = 0.99 at lam (t - start) / t_s = -ln(0.96))."""
    dt, N0, mu, start = 1e-4, 100.0, 0.5, 0.1
    gamma_rest = M_ * N_ ** -P_
    T0 = 0.99 * mu * N0 * gamma_rest
    stepper = anchored_pair_system(1.0, 1.0, 1e4, dt)
    contact = one_pair(EZ, -N0 * EZ + T0 * EX, 1.0, 0.0, 0.0, mu, mu)
    contact.set_deterioration(R0, LAM, DURATION, M_, N_, P_, start)
    stepper.add_contact(contact)
    h = step_history(stepper, contact, 2000, 6)
    before = h["t"] <= start + 1e-12
    assert before.sum() >= 999
    assert np.all(h["state"][before] == 0) and np.all(h["v"][before] == 0.0)  # still: bonded, at rest
    assert rel_error(h["D"][before], np.full(before.sum(), gamma_rest)) < 1e-14
    sliding = np.flatnonzero(h["state"] == 2)
    assert len(sliding) > 0, "the pair slid once the wear set in"
    first = h["t"][sliding[0]]
    expected = start - DURATION / LAM * np.log(1.0 - 0.01 / (1.0 - R0))
    assert abs(first - expected) < 3 * dt, (first, expected)
    assert np.abs(h["v"][-1]).max() > 0.0


def test_sliding_force_is_mu_d_N_D_with_the_measured_slip_rate():
    dt, N0, mu_d = 1e-3, 100.0, 0.4
    K = sp.csr_matrix((6, 6))
    stepper = _kernels.Stepper(*bsr_arrays(K), np.array([1.0, 3.0]), dt)
    stepper.add_provider(force_input(*constant_history(), [(1, 400.0 * EY)]))
    contact = one_pair(EZ, -N0 * EZ, 1.0, 5.0, 5.0, 0.5, mu_d)
    contact.set_deterioration(R0, LAM, DURATION, M_, N_, P_)
    stepper.add_contact(contact)
    u, v, a = np.zeros(6), np.zeros(6), np.zeros(6)
    h = step_history(stepper, contact, 1000, 6, u, v, a)
    slip_rate = np.abs(h["v"][:, 4] - h["v"][:, 1])  # y components, after each step
    D_expected = closed_form_D(h["t"][1:], slip_rate[:-1])
    assert rel_error(h["D"][1:], D_expected) < 1e-13
    sliding = h["state"] == 2
    assert sliding.all()
    T = np.linalg.norm(h["T"], axis=1)
    assert rel_error(T[sliding], mu_d * N0 * h["D"][sliding]) < ROUNDOFF
    assert slip_rate[-1] > 10  # the slip rate grew, so gamma fell below eta
    report = h["energy"][-1]
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    assert abs(report["damping_work"]) < ROUNDOFF * energy_scale(report)  # there is no damping
    # Restarting the account mid-slide: the contact force inside M a_0 + K u_0 must not be
    # taken for damping.
    stepper.reset_energy(u, v, a, h["t"][-1])
    stepper.run(u, v, a, 300, h["t"][-1])
    report = stepper.energy()
    assert report["contact_work"] < 0 and report["friction_dissipation"] > 0
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    assert abs(report["damping_work"]) < ROUNDOFF * energy_scale(report)


# ---------------------------------------------------------------------------------------------
# (e) energy with many pairs, damping and input


def test_energy_balance_with_sliding_and_separating_pairs_and_all_damping():
    n_nodes, split_nodes = 30, [1, 4, 8, 13, 21]
    K_m, mass_m, K_s, mass_s, copy_of = split_system(n_nodes, split_nodes, seed=11)
    omega = np.sqrt(np.linalg.eigvalsh(K_s / np.sqrt(np.outer(np.repeat(mass_s, 3),
                                                              np.repeat(mass_s, 3))))[-1])
    alpha, beta = 0.2, 0.01 / omega
    dt = 0.4 * 2 / omega
    stepper = _kernels.Stepper(*bsr_arrays(K_s), mass_s, dt, alpha, beta)
    rng = np.random.default_rng(3)
    D = rng.uniform(-1, 1, (2, 3, 3))
    # A full dashpot on a pair node (coupled normal/tangential) and on a plain node.
    stepper.set_dashpots(np.array([copy_of[4], 10], dtype=np.int32),
                         np.ascontiguousarray(D @ D.transpose(0, 2, 1)))
    times, g, dg, ddg = sine_history(3000 * dt, 150 * dt, table_dt=dt)
    stepper.add_provider(force_input(times, g, dg, ddg,
                                          [(node, 10.0 * rng.uniform(-1, 1, 3)) for node in range(0, 30, 3)]))
    normals = rng.standard_normal((5, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    pairs = np.array([[node, copy_of[node]] for node in split_nodes], dtype=np.int32)
    contact = _kernels.ContactPairs(pairs, np.ones(5), normals, -0.5 * normals, 0.2, 0.1, 0.4, 0.3)
    contact.set_deterioration(R0, LAM, 3000 * dt, M_, N_, P_)
    stepper.add_contact(contact)
    u, v, a = np.zeros(3 * len(mass_s)), np.zeros(3 * len(mass_s)), np.zeros(3 * len(mass_s))
    seen = np.zeros(4, dtype=bool)
    t, dissipation = 0.0, [0.0]
    for chunk in range(300):
        t = stepper.run(u, v, a, 10, t)
        seen[contact.state()] = True
        report = stepper.energy()
        assert abs(report["balance"]) < ROUNDOFF * energy_scale(report), chunk
        dissipation.append(report["friction_dissipation"])
    assert seen[[2, 3]].all()  # sliding and separated pairs both occurred
    assert np.all(np.isfinite(u))
    assert dissipation[-1] > 0 and min(np.diff(dissipation)) >= -ROUNDOFF * dissipation[-1]
    assert report["damping_work"] > 0 and report["contact_work"] != 0


# ---------------------------------------------------------------------------------------------
# (f) hard cases


def chatter_run(mass_i, mass_j, n_cycles, steps_per_cycle=100):
    """Pair 0-1 (normal +z, static compression 10 N, c = t_s = 1 Pa on 1 m^2), node 0 on an
    anchor spring; the lighter node is pulled away from the other by 30 sin(w t) N along the
    normal (opens every cycle) and pushed by 8 sin(w t) N along x."""
    dt = 1e-3
    stepper = anchored_pair_system(mass_i, mass_j, 1e4 * mass_i, dt)
    times, g, dg, ddg = sine_history(n_cycles * steps_per_cycle * dt, steps_per_cycle * dt)
    pulled, away = (1, 1.0) if mass_j <= mass_i else (0, -1.0)
    stepper.add_provider(force_input(times, g, dg, ddg, [(pulled, away * 30.0 * EZ + 8.0 * EX)]))
    contact = one_pair(EZ, -10.0 * EZ, 1.0, 1.0, 1.0, 0.5, 0.4)
    stepper.add_contact(contact)
    u, v, a = np.zeros(6), np.zeros(6), np.zeros(6)
    t, previous_open, openings, totals = 0.0, False, 0, []
    for _ in range(n_cycles * 10):
        t = stepper.run(u, v, a, steps_per_cycle // 10, t)
        is_open = contact.state()[0] == 3
        openings += is_open and not previous_open
        previous_open = is_open
        report = stepper.energy()
        totals.append(report["kinetic"] + report["strain"])
    return u, v, a, contact, report, openings, np.array(totals)


@pytest.mark.parametrize("mass_i, mass_j", [(100.0, 1.0), (1.0, 100.0)])
def test_chattering_pair_with_100_to_1_masses_stays_finite_with_bounded_energy(mass_i, mass_j):
    n_cycles = 3000
    u, v, a, contact, report, openings, totals = chatter_run(mass_i, mass_j, n_cycles)
    assert np.all(np.isfinite(np.concatenate([u, v, a])))
    assert openings > 2000  # opened and closed thousands of times (sampled every 10 steps)
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    # Periodic forcing, dissipative impacts: the energy of the last cycles is no larger than
    # that of the early ones (no pumping by the contact algorithm).
    early = totals[: len(totals) // 10].max()
    late = totals[-len(totals) // 10:].max()
    assert late < 1.5 * early
    gaps = contact.relative_displacement(u)
    assert np.all(np.isfinite(gaps))
    assert report["friction_dissipation"] >= 0


# ---------------------------------------------------------------------------------------------
# (g) argument checks


def test_bad_contact_arguments_raise_value_error_naming_the_parameter():
    pairs = np.array([[0, 1]], dtype=np.int32)
    area, normal, F0 = np.ones(1), np.array([EZ]), np.zeros((1, 3))
    good = dict(pairs=pairs, area=area, normal=normal, static_force=F0, cohesion=1.0,
                tensile_strength=1.0, friction_static=0.5, friction_dynamic=0.4)
    cases = [
        ({"pairs": pairs.astype(np.int64)}, r"^pairs: expected int32 array of shape \(any, 2\)"),
        ({"area": np.ones(2)}, r"^area: expected float64 array of shape \(1,\)"),
        ({"normal": np.ones((1, 2))}, r"^normal: expected float64 array of shape \(1, 3\)"),
        ({"static_force": np.zeros((1, 6))[:, ::2]}, r"^static_force: .*not C-contiguous"),
        ({"area": np.zeros(1)}, r"^area\[0\] = 0\.0+ must be finite and > 0"),
        ({"normal": np.array([[0.0, 0.0, 2.0]])}, r"^normal\[0\] has length 2\.0+; it must be a unit"),
        ({"cohesion": -1.0}, r"^cohesion = -1\.0+ must be finite and >= 0"),
        ({"friction_dynamic": np.nan}, r"^friction_dynamic = nan"),
        ({"static_force": np.array([[np.inf, 0, 0]])}, r"^static_force has a non-finite value"),
    ]
    checks = 0
    for change, message in cases:
        with pytest.raises(ValueError, match=message):
            _kernels.ContactPairs(**{**good, **change})
        checks += 1
    contact = _kernels.ContactPairs(**good)
    with pytest.raises(ValueError, match=r"^R0 = 0\.0+ must be in \(0, 1\]"):
        contact.set_deterioration(0.0, 5.0, 20.0, 0.883, 0.02, 0.032)
    with pytest.raises(ValueError, match=r"^duration = -1\.0+ must be finite and > 0"):
        contact.set_deterioration(0.75, 5.0, -1.0, 0.883, 0.02, 0.032)
    with pytest.raises(ValueError, match=r"^u: expected float64 array of shape \(3 n_nodes,\)"):
        contact.relative_displacement(np.zeros(3))

    stepper = anchored_pair_system(1.0, 1.0, 1.0, 1e-3)
    far = _kernels.ContactPairs(**{**good, "pairs": np.array([[0, 2]], dtype=np.int32)})
    with pytest.raises(ValueError, match=r"^pairs\[0, 1\] = 2 is not a node of the Stepper in \[0, 2\)"):
        stepper.add_contact(far)
    itself = _kernels.ContactPairs(**{**good, "pairs": np.array([[1, 1]], dtype=np.int32)})
    with pytest.raises(ValueError, match=r"^pairs\[0\] joins node 1 to itself"):
        stepper.add_contact(itself)
    stepper.add_contact(contact)
    with pytest.raises(ValueError, match=r"^contact: this Stepper already has a ContactPairs"):
        stepper.add_contact(contact)
    assert checks == len(cases) == 9


def test_queries_before_any_step_report_the_static_state():
    F0 = np.array([[0.0, 3.0, -40.0], [1.0, 0.0, 0.0]])
    contact = _kernels.ContactPairs(np.array([[0, 1], [2, 3]], dtype=np.int32), np.ones(2),
                                    np.array([EZ, EX]), F0, 1.0, 1.0, 0.5, 0.4)
    assert contact.n_pairs == 2
    assert contact.state().dtype == np.int8 and np.all(contact.state() == 0)
    assert contact.bond_intact().dtype == bool and contact.bond_intact().all()
    assert np.array_equal(contact.normal_force(), [40.0, -1.0])
    assert np.array_equal(contact.tangential_force(), [[0.0, 3.0, 0.0], [0.0, 0.0, 0.0]])
    assert np.array_equal(contact.state_counts(), [2, 0, 0, 0])
    u = np.arange(12.0)
    assert np.array_equal(contact.relative_displacement(u), [[3.0, 3.0, 3.0], [3.0, 3.0, 3.0]])


# ---------------------------------------------------------------------------------------------
# (h) the normal-stress lag of the friction (Prakash-Clifton; set_normal_lag)


def pressed_and_sheared(lag=None, n_steps=None) -> tuple:
    """The shear test's anchored pair (N0 = 100 N static) pressed by 100 N more along -z from t = 0
    and sheared by a slow sin^2 load up to 150 N along x; mu_s 0.5, mu_d 0.4, no cohesion. Returns the
    history and the pairs (`lag` = (length, velocity) or None)."""
    dt, period = 1e-3, 2.0
    stepper = anchored_pair_system(1.0, 1.0, 1e5, dt)
    stepper.set_dashpots(np.array([0, 1], dtype=np.int32), np.array([300.0 * np.eye(3), 50.0 * np.eye(3)]))
    stepper.add_provider(force_input(*constant_history(), [(1, -100.0 * EZ)]))
    stepper.add_provider(force_input(*sin2_history(period, period), [(1, 150.0 * EX)]))
    contact = one_pair(EZ, -100.0 * EZ, 1.0, 0.0, 0.0, 0.5, 0.4)
    if lag is not None:
        contact.set_normal_lag(*lag)
    stepper.add_contact(contact)
    return step_history(stepper, contact, n_steps or int(0.5 * period / dt), 6), contact


def first_slip_load(history):
    sliding = np.flatnonzero(history["state"] == 2)
    assert len(sliding), "the pair slid"
    return 150.0 * np.sin(np.pi * history["t"][sliding[0]] / 2.0) ** 2


def test_normal_lag_sets_the_friction_by_the_lagged_normal_force():
    """Pressed to N = 200 N, the pair slips at mu_s N = 100 N of shear without the lag; with a lag too
    long to follow (L = 1e9 m, V* = 0) the friction still sees the static 100 N and it slips at 50 N;
    with a lag too short to matter (L = 1e-12 m) the run is the lag-free run bit for bit."""
    plain, _ = pressed_and_sheared()
    assert np.abs(plain["N"][-200:] - 200.0).max() < 0.5        # the extra load arrived
    assert first_slip_load(plain) == pytest.approx(100.0, rel=0.01)
    held, contact = pressed_and_sheared(lag=(1.0e9, 0.0))
    assert first_slip_load(held) == pytest.approx(50.0, rel=0.01)
    assert contact.effective_normal()[0] == pytest.approx(100.0, rel=1e-6)
    instant, contact = pressed_and_sheared(lag=(1.0e-12, 1.0))
    for key in ("u", "v", "state", "N", "T", "R"):
        assert np.array_equal(instant[key], plain[key]), key
    assert contact.effective_normal()[0] == contact.normal_force()[0]
    assert len(one_pair(EZ, -EZ).effective_normal()) == 0          # off: no state


def test_normal_lag_follows_the_normal_force_as_its_exact_exponential():
    """While the pair sticks (slip rate 0) N* obeys dN*/dt = -V*/L (N* - N): over each step with N
    held, N*_{k+1} = N_{k+1} + (N*_k - N_{k+1}) exp(-V* dt / L), from N*_0 = 100 N; the recorded
    normal forces give it to round-off."""
    length, velocity, dt = 0.01, 0.2, 1e-3   # time constant 0.05 s: 50 steps
    stepper = anchored_pair_system(1.0, 1.0, 1e5, dt)
    stepper.set_dashpots(np.array([0, 1], dtype=np.int32), np.array([300.0 * np.eye(3), 50.0 * np.eye(3)]))
    stepper.add_provider(force_input(*constant_history(), [(1, -100.0 * EZ)]))
    contact = one_pair(EZ, -100.0 * EZ, 1.0, 0.0, 0.0, 0.5, 0.4)
    contact.set_normal_lag(length, velocity)
    stepper.add_contact(contact)
    u, v, a = np.zeros(6), np.zeros(6), np.zeros(6)
    expected, got, t = 100.0, [], 0.0
    decay = np.exp(-velocity * dt / length)
    for _ in range(300):
        t = stepper.run(u, v, a, 1, t)
        N = contact.normal_force()[0]
        expected = N + (expected - N) * decay
        got.append((contact.effective_normal()[0], expected))
    got = np.array(got)
    assert np.all(contact.state() == 0)
    assert got[-1, 0] > 190.0 and got[10, 0] < 150.0            # it rose to 200 N over ~0.05 s
    assert np.abs(got[:, 0] - got[:, 1]).max() < 1e-12 * 200.0


def test_normal_lag_is_saved_and_refused_when_bad():
    contact = one_pair(EZ, -100.0 * EZ)
    contact.set_normal_lag(0.01, 0.1)
    state = contact.save_state()
    assert "effective_normal" in state
    other = one_pair(EZ, -100.0 * EZ)
    other.set_normal_lag(0.01, 0.1)
    other.load_state(state)
    assert other.effective_normal()[0] == 100.0
    for length, velocity, match in ((0.0, 0.1, "length"), (float("nan"), 0.1, "length"), (0.01, -1.0, "velocity")):
        with pytest.raises(ValueError, match=match):
            one_pair(EZ, -EZ).set_normal_lag(length, velocity)


# ---------------------------------------------------------------------------------------------
# (i) the gradual release of a broken bond (set_release_time, time-weakening)


def tension_break(release_time=None, n_steps=1500):
    """The pair of the tension test pulled apart by a ramp; node 0 on its anchor spring (period 63 ms)
    rings when the bond lets go. Returns (history, contact)."""
    N0, area, tensile, dt = 100.0, 1.5, 20.0, 1e-3
    stepper = anchored_pair_system(1.0, 1.0, 1e4, dt)
    times = np.arange(0.0, 3.0, 1e-3)
    F_max = 400.0
    g, dg, ddg = np.minimum(times / 1.0, 1.0), np.where(times < 1.0, 1.0, 0.0), np.zeros_like(times)
    stepper.add_provider(force_input(times, g, dg, ddg, [(1, F_max * EZ)]))
    contact = one_pair(EZ, -N0 * EZ, area, 1e3, tensile, 0.5, 0.4)
    if release_time is not None:
        contact.set_release_time(release_time)
    stepper.add_contact(contact)
    return step_history(stepper, contact, n_steps, 6), contact, tensile * area


def test_a_broken_bond_released_over_a_time_carries_its_strength_times_the_share_left_and_rings_less():
    tau = 0.2
    at_once, _, strength = tension_break()
    released, contact, _ = tension_break(tau)
    state, N, t = released["state"], released["N"], released["t"]
    first_open = np.flatnonzero(state == 3)[0]
    # The bond broke where it does at once (the same tension), then the force fell linearly.
    assert first_open == np.flatnonzero(at_once["state"] == 3)[0]
    t_break = t[first_open]  # the correction at t_{n+1} = the chunk's end time
    releasing = (state == 3) & (t < t_break + tau)
    assert releasing.sum() > 150
    share = 1.0 - (t[releasing] - t_break) / tau
    assert np.max(np.abs(-N[releasing] - strength * share)) < ROUNDOFF * strength
    after = (t > t_break + tau + 1e-9) & (state == 3)
    assert after.sum() > 100 and np.all(N[after] == 0.0)
    assert not contact.bond_intact()[0]
    # Node 0 on its undamped anchor (period 63 ms) swings about u_z = N0/k once the pair carries
    # nothing (R = -F0): the step release by the strength's 30 N leaves it swinging by ~30 N/k, the
    # ramp over tau (3.2 periods) by about a quarter of that.
    window = (t > t_break + tau + 1e-9) & (t < t_break + tau + 0.2)
    ring_at_once = np.max(np.abs(at_once["u"][window, 2] - 100.0 / 1e4))
    ring_released = np.max(np.abs(released["u"][window, 2] - 100.0 / 1e4))
    assert ring_at_once > 0.5 * strength / 1e4
    assert ring_released < 0.5 * ring_at_once, (ring_released, ring_at_once)  # measured 0.27
    # The energy account closes with the release's work, which is dissipated.
    report = released["energy"][-1]
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report)
    assert report["friction_dissipation"] > 0.0 and at_once["energy"][-1]["friction_dissipation"] == 0.0


def test_a_bond_broken_in_shear_slides_with_the_cohesion_left_then_with_friction_only():
    N0, area, cohesion, mu_s, mu_d, tau = 100.0, 2.0, 10.0, 0.5, 0.4, 0.3
    dt, period = 1e-3, 2.0
    stepper = anchored_pair_system(1.0, 1.0, 1e5, dt)
    stepper.set_dashpots(np.array([0, 1], dtype=np.int32), np.array([300.0 * np.eye(3), 50.0 * np.eye(3)]))
    times, g, dg, ddg = sin2_history(period, period)
    stepper.add_provider(force_input(times, g, dg, ddg, [(1, 75.0 * EX)]))
    contact = one_pair(EZ, -N0 * EZ, area, cohesion, cohesion, mu_s, mu_d)
    contact.set_release_time(tau)
    stepper.add_contact(contact)
    h = step_history(stepper, contact, int(period / dt), 6)
    sliding = np.flatnonzero(h["state"] == 2)
    assert len(sliding) > 50
    t_break = h["t"][sliding[0]]
    T = np.linalg.norm(h["T"], axis=1)
    share = np.maximum(0.0, 1.0 - (h["t"][sliding] - t_break) / tau)
    assert np.max(np.abs(T[sliding] - (mu_d * N0 + cohesion * area * share))) < ROUNDOFF * N0
    assert share.min() < 1.0 and share.max() == 1.0
    report = h["energy"][-1]
    assert abs(report["balance"]) < ROUNDOFF * energy_scale(report) and report["friction_dissipation"] > 0


def test_release_time_is_refused_when_not_positive_or_finite():
    contact = one_pair(EZ, -100.0 * EZ)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="release time"):
            contact.set_release_time(bad)

"""The C++ kernel (pyfem._kernels) against independent numpy answers.

- exactness: the stepper equals a numpy/scipy implementation of the same scheme to round-off;
- convergence: central differences converge at order 2 in dt to the modal solution;
- energy: H_n - H_0 - W_ext + W_damp is zero to round-off with input, dashpots and Rayleigh;
- the critical-step estimates bracket the exact largest eigenvalue;
- the seismic input forces converge at order 4 in the table step to a closed-form waveform;
- every array argument is checked (ValueError naming the parameter).

Run as a script for the timing of a ~200k-dof 27-point block stencil:
    OMP_NUM_THREADS=1 /usr/bin/python3 tests/test_kernel.py
"""
import os
import subprocess
import sys

if __name__ == "__main__":  # as a script: make the repository root importable
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.linalg
import scipy.sparse as sp

from conftest import ROUNDOFF, observed_orders, rel_error

from pyfem import _kernels  # no skip: a missing module must fail the tests
from pyfem.bench import stepper_seconds_per_step


# ---------------------------------------------------------------------------------------------
# Systems and an independent reference implementation


def bsr_arrays(matrix):
    """(indptr int64, indices int32, blocks (nnzb,3,3)) of a scipy BSR matrix, as the kernel takes them."""
    matrix = matrix.tobsr(blocksize=(3, 3))
    matrix.sort_indices()
    return (np.ascontiguousarray(matrix.indptr, dtype=np.int64),
            np.ascontiguousarray(matrix.indices, dtype=np.int32),
            np.ascontiguousarray(matrix.data, dtype=np.float64))


def random_spd_system(n_nodes, links_per_node, seed):
    """Random SPD block-sparse K (sum of [[S,-S],[-S,S]] over random node pairs with S = B B^T,
    plus a grounding B B^T at every node), lumped masses in [1, 2]."""
    rng = np.random.default_rng(seed)
    rows, cols, values = [], [], []

    def add(i, j, S):
        r, c = np.meshgrid(3 * i + np.arange(3), 3 * j + np.arange(3), indexing="ij")
        rows.append(r.ravel())
        cols.append(c.ravel())
        values.append(S.ravel())

    for i in range(n_nodes):
        B = rng.uniform(-1, 1, (3, 3))
        add(i, i, B @ B.T)
        for j in rng.integers(0, n_nodes, links_per_node):
            if j == i:
                continue
            B = rng.uniform(-1, 1, (3, 3))
            S = B @ B.T
            add(i, i, S)
            add(j, j, S)
            add(i, j, -S)
            add(j, i, -S)
    n = 3 * n_nodes
    K = sp.coo_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(n, n)).tocsr().tobsr(blocksize=(3, 3))
    K.sort_indices()
    mass = rng.uniform(1.0, 2.0, n_nodes)
    return K, mass


def spring_chain(n_nodes, mass, stiffness_per_component):
    """1D chain of n_nodes with both ends tied to walls, three independent components with
    spring constants stiffness_per_component, embedded as 3x3 diagonal blocks."""
    laplacian = sp.diags([-np.ones(n_nodes - 1), 2 * np.ones(n_nodes), -np.ones(n_nodes - 1)], [-1, 0, 1])
    K = sp.kron(laplacian, sp.diags(stiffness_per_component)).tobsr(blocksize=(3, 3))
    K.sort_indices()
    return K, np.full(n_nodes, mass)


def hermite(values, slopes, table_t0, table_dt, t):
    """Cubic Hermite interpolation of tables (values, slopes) (..., n_samples) at times t
    (broadcast against the leading axes): 0 before the table, the last value after it."""
    n_samples = values.shape[-1]
    s = (np.asarray(t, dtype=float) - table_t0) / table_dt
    k = np.clip(np.floor(s).astype(int), 0, n_samples - 2)
    theta = s - k
    h00 = (1 + 2 * theta) * (1 - theta) ** 2
    h10 = theta * (1 - theta) ** 2
    h01 = theta ** 2 * (3 - 2 * theta)
    h11 = theta ** 2 * (theta - 1)

    def at(table, index):
        return np.take_along_axis(table, np.broadcast_to(index, table.shape[:-1])[..., None], -1)[..., 0]

    inside = (h00 * at(values, k) + h10 * table_dt * at(slopes, k)
              + h01 * at(values, k + 1) + h11 * table_dt * at(slopes, k + 1))
    return np.where(s < 0, 0.0, np.where(s >= n_samples - 1, values[..., -1], inside))


class InputSpec:
    """SeismicInput arguments plus a numpy evaluation of its forces on the full dof vector."""

    def __init__(self, table_t0, table_dt, g, dg, ddg, node_ptr, nodes, table, tau, P, Q):
        self.args = (table_t0, table_dt, g, dg, ddg, node_ptr, nodes, table, tau, P, Q)
        self.table_t0, self.table_dt = table_t0, table_dt
        self.g, self.dg, self.ddg = g, dg, ddg
        self.node_of_entry = np.repeat(nodes, np.diff(node_ptr))
        self.table, self.tau, self.P, self.Q = table, tau, P, Q

    def make(self):
        return _kernels.SeismicInput(*self.args)

    def nodal_forces(self, t, n_nodes):
        f = np.zeros((n_nodes, 3))
        shifted = t - self.tau
        g = hermite(self.g[self.table], self.dg[self.table], self.table_t0, self.table_dt, shifted)
        dg = hermite(self.dg[self.table], self.ddg[self.table], self.table_t0, self.table_dt, shifted)
        np.add.at(f, self.node_of_entry, self.P * g[:, None] + self.Q * dg[:, None])
        return f.ravel()


def smooth_input(n_nodes, n_input_nodes, rng, table_dt=0.02, n_samples=300):
    """Two sin^2 pulse tables (exact derivatives) on random nodes, 1-3 entries each, random delays."""
    times = np.arange(n_samples) * table_dt
    omegas = np.array([[2.0], [3.5]])
    g = np.sin(omegas * times) ** 2
    dg = omegas * np.sin(2 * omegas * times)
    ddg = 2 * omegas ** 2 * np.cos(2 * omegas * times)
    nodes = rng.choice(n_nodes, n_input_nodes, replace=False).astype(np.int32)
    counts = rng.integers(1, 4, n_input_nodes)
    node_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n_entries = int(node_ptr[-1])
    return InputSpec(0.0, table_dt, g, dg, ddg, node_ptr, nodes,
                     rng.integers(0, 2, n_entries).astype(np.int32),
                     rng.uniform(0.0, 0.5, n_entries),
                     rng.uniform(-1, 1, (n_entries, 3)), rng.uniform(-1, 1, (n_entries, 3)))


def random_dashpots(n_nodes, count, rng):
    """count symmetric PSD 3x3 dashpots C = D D^T at random nodes (one node listed twice)."""
    nodes = rng.choice(n_nodes, count, replace=False).astype(np.int32)
    nodes[-1] = nodes[0]  # a node on two faces gets the sum
    D = rng.uniform(-1, 1, (count, 3, 3))
    return nodes, np.ascontiguousarray(D @ D.transpose(0, 2, 1))


def reference_run(K, mass, dt, alpha, beta, dashpots, input_spec, u, v, a, n_steps, t0):
    """The scheme of docs/ARCHITECTURE.md in numpy/scipy, with the trapezoid work integrals.

    Returns (u, v, a, external_work, damping_work); the work integrals start from the given
    state assuming a consistent a (the first half-trapezoid uses f_ext(t0) and the damping
    force (f_ext(t0) - (M a + K u)) there, as the kernel does)."""
    n_nodes = len(mass)
    M = np.repeat(mass, 3)
    C = np.zeros((n_nodes, 3, 3))
    if dashpots is not None:
        np.add.at(C, dashpots[0], dashpots[1])
    has_dashpot = np.abs(C).sum(axis=(1, 2)) > 0
    A = mass[:, None, None] * (1 + dt / 2 * alpha) * np.eye(3) + dt / 2 * C
    u, v, a = u.copy(), v.copy(), a.copy()

    def external(t):
        return input_spec.nodal_forces(t, n_nodes) if input_spec is not None else np.zeros(3 * n_nodes)

    f = external(t0)
    external_power = f @ v
    damping_power = (f - (M * a + K @ u)) @ v
    external_work = damping_work = 0.0
    for step in range(n_steps):
        t = t0 + (step + 1) * dt
        v_half = v + dt / 2 * a
        u = u + dt * v_half
        f = external(t)
        Kv = K @ v_half
        r = f - K @ u - beta * Kv
        rhs = M * v_half + dt / 2 * r
        v = rhs / (M * (1 + dt / 2 * alpha))
        v3 = v.reshape(-1, 3)
        v3[has_dashpot] = np.linalg.solve(A[has_dashpot], rhs.reshape(-1, 3)[has_dashpot][..., None])[..., 0]
        implicit_damping = alpha * M * v + np.einsum("nij,nj->ni", C, v3).ravel()
        a = (r - implicit_damping) / M
        damping = implicit_damping + beta * Kv
        external_work += dt / 2 * (external_power + f @ v)
        damping_work += dt / 2 * (damping_power + damping @ v)
        external_power, damping_power = f @ v, damping @ v
    return u, v, a, external_work, damping_work


def discrete_energy(K, mass, dt, u, v, a, non_stiffness_force):
    """H = 1/2 v.Mv + 1/2 u.Ku - dt^2/8 a.Ma + dt^2/4 F.a."""
    M = np.repeat(mass, 3)
    return (0.5 * v @ (M * v) + 0.5 * u @ (K @ u) - dt ** 2 / 8 * a @ (M * a)
            + dt ** 2 / 4 * non_stiffness_force @ a)


def largest_eigenvalue(K, mass):
    """omega_max^2 of M^-1 K: dense symmetric eigensolver for small systems, Lanczos above."""
    scale = 1 / np.sqrt(np.repeat(mass, 3))
    if K.shape[0] <= 3000:
        return scipy.linalg.eigvalsh(scale[:, None] * K.toarray() * scale[None, :])[-1]
    from scipy import sparse
    from scipy.sparse.linalg import eigsh

    symmetric = sparse.diags(scale) @ K @ sparse.diags(scale)
    return eigsh(symmetric, k=1, which="LA", tol=1e-10)[0][0]


# ---------------------------------------------------------------------------------------------
# Exactness


def damped_forced_case(seed=3, n_nodes=300):
    rng = np.random.default_rng(seed)
    K, mass = random_spd_system(n_nodes, 3, seed)
    omega_max = np.sqrt(largest_eigenvalue(K, mass))
    alpha, beta = 0.05, 0.02 / omega_max
    dt = 0.8 * (2 / omega_max) * (np.sqrt(1 + (beta * omega_max / 2) ** 2) - beta * omega_max / 2)
    dashpots = random_dashpots(n_nodes, 25, rng)
    input_spec = smooth_input(n_nodes, 40, rng, table_dt=dt)  # the input lasts ~300 steps
    u0 = 1e-2 * rng.standard_normal(3 * n_nodes)
    v0 = 1e-1 * rng.standard_normal(3 * n_nodes)
    a0 = np.zeros(3 * n_nodes)
    return K, mass, dt, alpha, beta, dashpots, input_spec, u0, v0, a0


def make_stepper(K, mass, dt, alpha, beta, dashpots, input_spec, symmetric_storage=True):
    stepper = _kernels.Stepper(*bsr_arrays(K), mass, dt, alpha, beta, symmetric_storage)
    if dashpots is not None:
        stepper.set_dashpots(*dashpots)
    if input_spec is not None:
        stepper.add_provider(input_spec.make())
    return stepper


@pytest.mark.parametrize("symmetric_storage", [True, False], ids=["upper-triangle", "full-fused"])
@pytest.mark.parametrize("n_nodes", [300, 6000], ids=["one-thread", "threaded"])
def test_stepper_equals_numpy_reference_to_roundoff(symmetric_storage, n_nodes):
    """Both storage formats, below and above the size at which the loops go parallel."""
    K, mass, dt, alpha, beta, dashpots, input_spec, u0, v0, a0 = damped_forced_case(n_nodes=n_nodes)
    stepper = make_stepper(K, mass, dt, alpha, beta, dashpots, input_spec, symmetric_storage)
    u, v, a = u0.copy(), v0.copy(), a0.copy()
    t_end = stepper.run(u, v, a, 100, 0.0)
    u_ref, v_ref, a_ref, _, _ = reference_run(K, mass, dt, alpha, beta, dashpots, input_spec,
                                              u0, v0, a0, 100, 0.0)
    assert t_end == pytest.approx(100 * dt, rel=1e-15)
    for name, got, expected in (("u", u, u_ref), ("v", v, v_ref), ("a", a, a_ref)):
        assert rel_error(got, expected) < 1e-12, name
    # The comparison means something only if the state moved and the input pushed.
    assert rel_error(u, u0) > 0.1
    assert np.abs(input_spec.nodal_forces(100 * dt, len(mass))).max() > 0.1


# ---------------------------------------------------------------------------------------------
# Convergence


def test_central_difference_converges_at_order_two():
    n_nodes, mass, stiffness = 12, 2.0, np.array([50.0, 80.0, 30.0])
    K, masses = spring_chain(n_nodes, mass, stiffness)
    dense = K.toarray()
    omega2, modes = scipy.linalg.eigh(dense, np.diag(np.repeat(masses, 3)))  # M-orthonormal modes
    omega = np.sqrt(omega2)
    rng = np.random.default_rng(0)
    # A mix of the lowest modes of every component: all of them in the asymptotic range.
    low = np.argsort(omega)[:9]
    u0 = modes[:, low] @ rng.uniform(0.5, 1.0, 9)
    v0 = modes[:, low] @ rng.uniform(-1.0, 1.0, 9)
    a0 = -(dense @ u0) / np.repeat(masses, 3)
    duration = 2.0
    modal_u, modal_v = modes.T @ (np.repeat(masses, 3) * u0), modes.T @ (np.repeat(masses, 3) * v0)
    exact_u = modes @ (modal_u * np.cos(omega * duration) + modal_v / omega * np.sin(omega * duration))
    exact_v = modes @ (-modal_u * omega * np.sin(omega * duration) + modal_v * np.cos(omega * duration))

    steps = [100 * 2 ** k for k in range(5)]
    dts, errors_u, errors_v = [], [], []
    for n_steps in steps:
        dt = duration / n_steps
        stepper = _kernels.Stepper(*bsr_arrays(K), masses, dt)
        u, v, a = u0.copy(), v0.copy(), a0.copy()
        stepper.run(u, v, a, n_steps, 0.0)
        dts.append(dt)
        errors_u.append(rel_error(u, exact_u))
        errors_v.append(rel_error(v, exact_v))
    assert dts[0] * omega[low].max() < 0.3
    assert errors_u[-1] > 1e3 * ROUNDOFF  # still far above round-off at the finest step
    orders = np.concatenate([observed_orders(dts, errors_u), observed_orders(dts, errors_v)])
    assert len(orders) == 8
    assert np.all((orders > 1.9) & (orders < 2.1)), orders


# ---------------------------------------------------------------------------------------------
# Energy


@pytest.mark.parametrize("symmetric_storage", [True, False], ids=["upper-triangle", "full-fused"])
def test_energy_balance_is_zero_to_roundoff_with_input_and_damping(symmetric_storage):
    K, mass, dt, alpha, beta, dashpots, input_spec, u0, v0, a0 = damped_forced_case(seed=11, n_nodes=120)
    stepper = make_stepper(K, mass, dt, alpha, beta, dashpots, input_spec, symmetric_storage)
    u, v, a = u0.copy(), v0.copy(), a0.copy()
    stepper.reset_energy(u, v, a, 0.0)
    H0 = discrete_energy(K, mass, dt, u0, v0, a0, np.repeat(mass, 3) * a0 + K @ u0)
    assert stepper.energy()["total"] == pytest.approx(H0, rel=1e-13)

    t, checks = 0.0, 0
    for _ in range(8):  # several run calls: the account carries over between them
        t = stepper.run(u, v, a, 25, t)
        energy = stepper.energy()
        scale = max(abs(energy["total"]), energy["external_work"], energy["damping_work"])
        assert abs(energy["balance"]) < 1e-12 * scale, energy
        checks += 1
    assert checks == 8

    # Each term is what it claims: recompute them from the state and the reference scheme.
    u_ref, v_ref, a_ref, external_work, damping_work = reference_run(
        K, mass, dt, alpha, beta, dashpots, input_spec, u0, v0, a0, 200, 0.0)
    M = np.repeat(mass, 3)
    assert energy["kinetic"] == pytest.approx(0.5 * v @ (M * v), rel=1e-12)
    assert energy["strain"] == pytest.approx(0.5 * u @ (K @ u), rel=1e-12)
    assert energy["total"] == pytest.approx(discrete_energy(K, mass, dt, u, v, a, M * a + K @ u), rel=1e-10)
    assert energy["external_work"] == pytest.approx(external_work, rel=1e-10)
    assert energy["damping_work"] == pytest.approx(damping_work, rel=1e-10)
    assert sum(energy["provider_work"].values()) == pytest.approx(energy["external_work"], rel=1e-12)
    # Damping dissipated a sizeable part, the input did sizeable work, the state still moves.
    assert energy["damping_work"] > 0.1 * H0
    assert abs(energy["external_work"]) > 0.1 * H0
    assert energy["kinetic"] > 0.1 * H0
    assert abs(dt ** 2 / 4 * (M * a + K @ u) @ a) > 1e-3 * H0  # the F.a term is in play


def test_undamped_free_vibration_conserves_the_discrete_energy():
    K, mass = random_spd_system(50, 3, 5)
    dt = 0.9 * 2 / np.sqrt(largest_eigenvalue(K, mass))
    stepper = _kernels.Stepper(*bsr_arrays(K), mass, dt)
    rng = np.random.default_rng(1)
    u, v = rng.standard_normal(150), rng.standard_normal(150)
    a = -(K @ u) / np.repeat(mass, 3)
    stepper.reset_energy(u, v, a, 0.0)
    H0 = stepper.energy()["total"]
    stepper.run(u, v, a, 5000, 0.0)
    energy = stepper.energy()
    assert energy["external_work"] == 0.0
    assert abs(energy["damping_work"]) < 1e-12 * H0  # round-off of (f_ext - (M a + K u)).v at t0
    assert abs(energy["total"] - H0) < 1e-12 * H0
    # The plain mechanical energy oscillates at this dt; H is the conserved quantity.
    assert abs(energy["kinetic"] + energy["strain"] - H0) > 1e-6 * H0


# ---------------------------------------------------------------------------------------------
# Critical step


def test_gershgorin_bounds_power_iteration_bounds_exact_eigenvalue():
    n_nodes, mass, stiffness = 10, 3.0, np.array([40.0, 90.0, 10.0])
    K, masses = spring_chain(n_nodes, mass, stiffness)
    # Fixed-fixed chain: omega_j^2 = (4 k/m) sin^2(j pi / (2 (n + 1))), largest for the stiffest k.
    exact = 4 * stiffness.max() / mass * np.sin(n_nodes * np.pi / (2 * (n_nodes + 1))) ** 2
    assert exact == pytest.approx(largest_eigenvalue(K, masses), rel=1e-12)
    bound = _kernels.gershgorin_bound(*bsr_arrays(K), masses)
    estimate = _kernels.power_iteration(*bsr_arrays(K), masses, 50, 1)
    assert bound == pytest.approx(4 * stiffness.max() / mass, rel=1e-14)  # interior row sum
    assert bound >= estimate >= 0.99 * exact
    assert estimate <= exact * (1 + 1e-12)  # a Rayleigh quotient never exceeds omega_max^2

    K, masses = random_spd_system(80, 3, 8)
    exact = largest_eigenvalue(K, masses)
    bound = _kernels.gershgorin_bound(*bsr_arrays(K), masses)
    estimate = _kernels.power_iteration(*bsr_arrays(K), masses, iterations=3000, seed=4)
    assert bound >= exact >= estimate >= 0.99 * exact


# ---------------------------------------------------------------------------------------------
# Seismic input


def ricker(t, f0, t_peak):
    """Ricker wavelet g = (1 - 2 x) exp(-x), x = (pi f0 (t - t_peak))^2, and its two derivatives."""
    c = (np.pi * f0) ** 2
    s = t - t_peak
    x = c * s ** 2
    g = (1 - 2 * x) * np.exp(-x)
    dg = c * s * (4 * x - 6) * np.exp(-x)
    ddg = c * (-8 * x ** 2 + 24 * x - 6) * np.exp(-x)
    return g, dg, ddg


def test_seismic_input_forces_converge_at_order_four_to_the_closed_form():
    f0, t_peak, table_t0, table_end = 5.0, 0.4, 0.1, 1.0
    node_ptr = np.array([0, 2, 3, 5], dtype=np.int64)
    nodes = np.array([7, 2, 9], dtype=np.int32)
    table = np.array([0, 1, 0, 1, 0], dtype=np.int32)
    tau = np.array([0.0, 0.05, 0.2, 0.13, 0.31])
    rng = np.random.default_rng(2)
    P, Q = rng.uniform(-1, 1, (5, 3)), rng.uniform(-0.1, 0.1, (5, 3))
    amplitudes = np.array([1.0, -0.5])

    def closed_form(t):
        forces = np.zeros((3, 3))
        for e in range(5):
            s = np.clip(t - tau[e], None, table_end)  # held at the last sample after the end
            g, dg, _ = ricker(s, f0, t_peak)
            if t - tau[e] < table_t0:
                g = dg = 0.0  # zero before the table start
            i = np.searchsorted(node_ptr, e, side="right") - 1
            forces[i] += amplitudes[table[e]] * (P[e] * g + Q[e] * dg)
        return forces

    times = np.linspace(0.0, 1.5, 397)  # before the start, through the pulse, after the end
    expected = np.array([closed_form(t) for t in times])
    errors, spacings = [], []
    for n_intervals in (90, 180, 360):
        table_dt = (table_end - table_t0) / n_intervals
        sample_times = table_t0 + table_dt * np.arange(n_intervals + 1)
        g, dg, ddg = (amplitudes[:, None] * w for w in ricker(sample_times, f0, t_peak))
        g, dg, ddg = (np.ascontiguousarray(w) for w in (g, dg, ddg))
        seismic_input = _kernels.SeismicInput(table_t0, table_dt, g, dg, ddg, node_ptr, nodes,
                                              table, tau, P, Q)
        got = np.array([seismic_input.forces(t) for t in times])
        errors.append(rel_error(got, expected))
        spacings.append(table_dt)
    assert errors[-1] < 1e-6
    orders = observed_orders(spacings, errors)
    assert np.all((orders > 3.5) & (orders < 4.5)), (orders, errors)
    # Before every delayed start the force is exactly zero.
    early = _kernels.SeismicInput(table_t0, spacings[-1], g, dg, ddg, node_ptr, nodes, table, tau, P, Q)
    assert np.all(early.forces(table_t0 - 1e-9) == 0.0)


def test_seismic_input_forces_match_the_numpy_hermite_reference():
    rng = np.random.default_rng(4)
    spec = smooth_input(20, 6, rng)
    seismic_input = spec.make()
    checks = 0
    for t in (-0.1, 0.0, 0.37, 1.234, 5.9, 7.0):
        full = spec.nodal_forces(t, 20).reshape(-1, 3)
        expected = np.zeros((len(spec.args[6]), 3))
        for i, node in enumerate(spec.args[6]):
            expected[i] = full[node]
        assert rel_error(seismic_input.forces(t), expected) < ROUNDOFF
        checks += 1
    assert checks == 6


# ---------------------------------------------------------------------------------------------
# Argument checks


@pytest.fixture
def small_stepper():
    K, mass = random_spd_system(5, 2, 1)
    return _kernels.Stepper(*bsr_arrays(K), mass, 0.01), K, mass


def test_run_rejects_bad_state_arrays(small_stepper):
    stepper, _, _ = small_stepper
    n = stepper.n_dofs
    good = lambda: np.zeros(n)  # noqa: E731
    bad_cases = {
        "u": np.zeros(n, dtype=np.float32),          # dtype: a silent copy would lose the update
        "v": np.zeros(n + 3),                        # shape
        "a": np.zeros(2 * n)[::2],                   # not contiguous
    }
    checks = 0
    for name, bad in bad_cases.items():
        arrays = {"u": good(), "v": good(), "a": good()}
        arrays[name] = bad
        with pytest.raises(ValueError, match=rf"^{name}: expected float64 array of shape \({n},\)"):
            stepper.run(arrays["u"], arrays["v"], arrays["a"], 1, 0.0)
        checks += 1
    read_only = good()
    read_only.flags.writeable = False
    with pytest.raises(ValueError, match=r"^u: .*read-only"):
        stepper.run(read_only, good(), good(), 1, 0.0)
    with pytest.raises(ValueError, match=r"^u: expected a numpy"):
        stepper.run([0.0] * n, good(), good(), 1, 0.0)
    assert checks == 3
    assert (stepper.n_nodes, stepper.n_dofs, stepper.dt) == (5, 15, 0.01)


def test_constructors_reject_bad_matrix_and_input_arrays(small_stepper):
    _, K, mass = small_stepper
    indptr, indices, blocks = bsr_arrays(K)
    with pytest.raises(ValueError, match=r"^indices: expected int32"):
        _kernels.Stepper(indptr, indices.astype(np.int64), blocks, mass, 0.01)
    with pytest.raises(ValueError, match=r"^indptr: expected int64 array of shape \(6,\)"):
        _kernels.Stepper(indptr[:-1], indices, blocks, mass, 0.01)
    with pytest.raises(ValueError, match=r"^blocks: expected float64 array of shape"):
        _kernels.Stepper(indptr, indices, blocks.reshape(-1, 9), mass, 0.01)
    with pytest.raises(ValueError, match=r"^mass: expected float64"):
        _kernels.Stepper(indptr, indices, blocks, mass.astype(np.float32), 0.01)
    with pytest.raises(ValueError, match=r"mass\[2\]"):
        _kernels.Stepper(indptr, indices, blocks, np.where(np.arange(5) == 2, 0.0, mass), 0.01)
    with pytest.raises(ValueError, match=r"^dt must be"):
        _kernels.Stepper(indptr, indices, blocks, mass, -1.0)
    with pytest.raises(ValueError, match=r"^blocks: .*not C-contiguous"):
        _kernels.gershgorin_bound(indptr, indices, blocks.transpose(0, 2, 1), mass)

    stepper = _kernels.Stepper(indptr, indices, blocks, mass, 0.01)
    with pytest.raises(ValueError, match=r"^C: expected float64 array of shape \(2, 3, 3\)"):
        stepper.set_dashpots(np.array([0, 1], dtype=np.int32), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"node 1 .*not symmetric"):
        stepper.set_dashpots(np.array([1], dtype=np.int32), np.array([[[1.0, 2, 0], [0, 1, 0], [0, 0, 1]]]))
    with pytest.raises(ValueError, match=r"dashpot nodes\[0\] = 5"):
        stepper.set_dashpots(np.array([5], dtype=np.int32), np.zeros((1, 3, 3)))

    rng = np.random.default_rng(0)
    spec = smooth_input(20, 4, rng)
    args = list(spec.args)
    with pytest.raises(ValueError, match=r"^P: expected float64 array of shape"):
        _kernels.SeismicInput(*args[:9], args[9][:, :2].copy(), args[10])
    bad_table = args[7].copy()
    bad_table[0] = 2
    with pytest.raises(ValueError, match=r"table\[0\] = 2"):
        _kernels.SeismicInput(*args[:7], bad_table, *args[8:])
    with pytest.raises(ValueError, match=r"is not a node of the Stepper"):
        stepper.add_provider(spec.make())  # input nodes up to 19, the stepper has 5


def test_borrowed_arrays_stay_alive():
    K, mass = random_spd_system(6, 2, 2)
    stepper = _kernels.Stepper(*bsr_arrays(K), mass.copy(), 1e-3)  # temporaries only
    spec = smooth_input(6, 3, np.random.default_rng(1))
    stepper.add_provider(_kernels.SeismicInput(*[np.copy(x) if isinstance(x, np.ndarray) else x
                                                      for x in spec.args]))
    import gc
    gc.collect()
    _ = [np.full(10_000, 7.0) for _ in range(100)]  # reuse of freed memory would corrupt K
    u, v, a = np.zeros(18), np.zeros(18), np.zeros(18)
    stepper.run(u, v, a, 400, 0.0)
    u_ref, *_ = reference_run(K, mass, 1e-3, 0.0, 0.0, None, spec, np.zeros(18), np.zeros(18),
                              np.zeros(18), 400, 0.0)
    assert np.abs(u_ref).max() > 0
    assert rel_error(u, u_ref) < 1e-12


# ---------------------------------------------------------------------------------------------
# Timing (printed, not asserted)


def stencil_27_point(n_per_side):
    """A Q1-like 27-point block stencil on an n^3 node grid: K = sum over neighbour pairs of
    [[S,-S],[-S,S]] with S = I + 0.1 J / |offset|^2, plus grounding; SPD, built directly as BSR."""
    n = n_per_side
    index = np.arange(n ** 3).reshape(n, n, n)  # [z, y, x]
    offsets = [(dz, dy, dx) for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    neighbours = np.full((n ** 3, 27), -1, dtype=np.int64)
    padded = np.pad(index, 1, constant_values=-1)
    for k, (dz, dy, dx) in enumerate(offsets):
        neighbours[:, k] = padded[1 + dz:1 + dz + n, 1 + dy:1 + dy + n, 1 + dx:1 + dx + n].ravel()
    present = neighbours >= 0
    couplings = np.array([np.eye(3) + 0.1 * np.ones((3, 3)) / max(1, sum(map(abs, o))) for o in offsets])
    blocks = np.broadcast_to(-couplings, (n ** 3, 27, 3, 3)).copy()
    centre = offsets.index((0, 0, 0))
    blocks[:, centre] = np.eye(3) + np.einsum("nk,kij->nij", present[:, np.arange(27) != centre],
                                              couplings[np.arange(27) != centre])
    indptr = np.concatenate([[0], np.cumsum(present.sum(axis=1))]).astype(np.int64)
    indices = neighbours[present].astype(np.int32)
    blocks = np.ascontiguousarray(blocks[present])
    return indptr, indices, blocks, np.ones(n ** 3)


def time_per_step(n_per_side=41, steps=50):
    """Seconds per step on a ~200k-dof 27-point stencil, without and with beta damping."""
    indptr, indices, blocks, mass = stencil_27_point(n_per_side)
    dt = 1.8 / np.sqrt(_kernels.gershgorin_bound(indptr, indices, blocks, mass))
    results = {}
    for beta in (0.0, 0.01 * dt):
        stepper = _kernels.Stepper(indptr, indices, blocks, mass, dt, 0.0, beta)
        results["beta" if beta else "no beta"] = stepper_seconds_per_step(stepper, 3 * len(mass), steps,
                                                                          amplitude=1e-3)
    return 3 * len(mass), len(indices), results


@pytest.mark.slow
def test_print_time_per_step_on_one_and_two_threads():
    for threads in (1, 2):
        output = subprocess.run([sys.executable, __file__], capture_output=True, text=True, check=True,
                                env={**os.environ, "OMP_NUM_THREADS": str(threads)},
                                cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        print(output.stdout)
        assert "ms/step" in output.stdout


if __name__ == "__main__":
    n_dofs, n_blocks, results = time_per_step()
    print(f"threads={_kernels.max_threads()} dofs={n_dofs} blocks={n_blocks} "
          + " ".join(f"{key}: {1e3 * seconds:.2f} ms/step" for key, seconds in results.items()))


@pytest.mark.parametrize("kind", ["global", "local"])
def test_nodal_effects_are_validated_alike_and_a_bad_call_changes_nothing(kind):
    """Global and local stepping share one NodalEffects (cpp_kernels/nodal_effects.hpp): the same
    words for the same mistake, and a refused set_dashpots or set_constraints leaves the stepper as
    it was (catches LocalStepper's old half-built dashpot table after a bad C)."""
    K, mass = random_spd_system(6, 2, 3)
    indptr, indices, blocks = bsr_arrays(K)
    good = np.array([[[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 3.0]]])

    def make():
        if kind == "global":
            stepper = _kernels.Stepper(indptr, indices, blocks, mass, 1e-3)
        else:
            stepper = _kernels.LocalStepper(indptr, indices, blocks, mass, np.zeros(6, dtype=np.int32), 1e-3, 0.0)
        stepper.set_dashpots(np.array([1], dtype=np.int32), good.copy())
        return stepper

    rng = np.random.default_rng(1)
    u0, v0 = rng.standard_normal(18), rng.standard_normal(18)

    def steps(stepper):
        u, v, a = u0.copy(), v0.copy(), np.zeros(18)
        if kind == "global":
            stepper.reset_energy(u, v, a, 0.0)
        stepper.run(u, v, a, 8, 0.0)
        return u

    before = steps(make())
    stepper = make()
    checks = 0
    for nodes, C, words in ((np.array([1], dtype=np.int32), np.array([[[1.0, 2, 0], [0, 1, 0], [0, 0, 1]]]),
                             r"^dashpot C at node 1 is not symmetric"),
                            (np.array([7], dtype=np.int32), good.copy(), r"^dashpot nodes\[0\] = 7 is not a node in \[0, 6\)"),
                            (np.array([2], dtype=np.int32), -1e9 * np.eye(3)[None], r"^dashpot C at node 2 is not positive semi-definite")):
        with pytest.raises(ValueError, match=words):
            stepper.set_dashpots(nodes, np.ascontiguousarray(C))
        checks += 1
    P = np.eye(3)[None].copy()
    with pytest.raises(ValueError, match=r"^constraint nodes\[1\] = 3 is listed twice"):
        stepper.set_constraints(np.array([3, 3], dtype=np.int32), np.ascontiguousarray(np.repeat(P, 2, axis=0)))
    checks += 1
    assert checks == 4
    assert np.array_equal(steps(stepper), before)  # the refused calls changed nothing
    assert np.abs(before - u0).max() > 0.0  # (and the steps moved something)


@pytest.mark.parametrize("kind", ["global", "local"])
def test_a_held_force_steps_as_the_constant_seismic_input_it_replaced_and_ramps_by_the_smoothstep(kind):
    """HeldForce (cpp_kernels/held_force.hpp), the stage's loads and hand-over force: held, bit for
    bit the run of the one-table SeismicInput that was 1 from long before the run (what the stage
    used before); ramped, s(t) = 3x^2 - 2x^3 with zero slope at both ends; its work in the energy
    account (global stepping's balance to round-off). Catches a force applied twice, at the wrong
    nodes, or ramped another way."""
    K, mass = random_spd_system(40, 3, 5)
    indptr, indices, blocks = bsr_arrays(K)
    rng = np.random.default_rng(2)
    nodes = np.array([3, 7, 8, 30], dtype=np.int32)
    forces = rng.standard_normal((4, 3))
    dt = 0.5 / np.sqrt(largest_eigenvalue(K, mass))

    def constant_table():
        n = len(nodes)
        return _kernels.SeismicInput(-1.0e6, 1.0, np.ones((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)),
                                     np.arange(n + 1, dtype=np.int64), nodes, np.zeros(n, dtype=np.int32),
                                     np.zeros(n), np.ascontiguousarray(forces), np.zeros((n, 3)))

    def run(provider):
        if kind == "global":
            stepper = _kernels.Stepper(indptr, indices, blocks, mass, dt)
        else:
            stepper = _kernels.LocalStepper(indptr, indices, blocks, mass, np.zeros(40, dtype=np.int32), dt, 0.0)
        stepper.add_provider(provider)
        u, v, a = np.zeros(120), np.zeros(120), np.zeros(120)
        if kind == "global":
            stepper.reset_energy(u, v, a, 0.0)
        stepper.run(u, v, a, 50, 0.0)
        return u, stepper.energy()

    held, energy = run(_kernels.HeldForce(nodes, forces))
    table, _ = run(constant_table())
    assert np.abs(held).max() > 0.0  # the force moved the model
    assert np.array_equal(held, table)
    if kind == "global":
        assert energy["external_work"] > 0.0 and abs(energy["balance"]) <= 1e-12 * energy["external_work"]
    ramped = _kernels.HeldForce(nodes, forces, 0.2)
    x = np.array([0.0, 0.05, 0.1, 0.15])
    assert [ramped.factor(t) for t in (-1.0, 0.2, 5.0)] == [0.0, 1.0, 1.0]
    assert np.allclose([ramped.factor(t) for t in x], 3 * (x / 0.2) ** 2 - 2 * (x / 0.2) ** 3,
                       rtol=0, atol=1e-15)
    for arguments, words in (((nodes, forces, -1.0), r"^ramp = -1\.0+ must be finite and >= 0"),
                             ((np.array([3, 3], dtype=np.int32), forces[:2]), r"^node 3 is listed twice"),
                             ((nodes, np.full((4, 3), np.nan)), r"^forces\[0\] is not finite")):
        with pytest.raises(ValueError, match=words):
            _kernels.HeldForce(*arguments)

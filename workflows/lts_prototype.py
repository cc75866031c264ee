"""A numpy prototype of the multi-level local time stepping scheme of docs/lts_plan.md, on a
graded 1D bar (stiff, finely meshed cells in the middle; soft, coarse cells outside): evidence for
the design before the kernel implements it. Checks:

1. one level: the scheme is the kernel's velocity-Verlet step (same numbers to round-off);
2. second order in dt against a converged reference (global leapfrog with a tiny step);
3. stability: the spectral radius of the one-step map (u, v) -> (u, v) over the safety factor,
   against global stepping with the smallest cell's step;
4. a long undamped run keeps its energy bounded.

Usage: /usr/bin/python3 workflows/lts_prototype.py
"""
import numpy as np


def graded_bar(n_coarse=40, n_fine=64, fine_fraction=0.2, stiff_ratio=16.0, length=1.0):
    """Nodes, lumped masses and stiffness of a 1D bar: coarse soft cells, fine stiff cells in the
    middle (wave speed ratio sqrt(stiff_ratio), cell size ratio as given)."""
    coarse_length = (1.0 - fine_fraction) * length / 2
    left = np.linspace(0.0, coarse_length, n_coarse // 2 + 1)
    middle = np.linspace(coarse_length, coarse_length + fine_fraction * length, n_fine + 1)[1:]
    right = np.linspace(coarse_length + fine_fraction * length, length, n_coarse // 2 + 1)[1:]
    x = np.concatenate([left, middle, right])
    n = len(x)
    h = np.diff(x)
    centre = 0.5 * (x[1:] + x[:-1])
    stiff = (centre > coarse_length) & (centre < coarse_length + fine_fraction * length)
    E = np.where(stiff, stiff_ratio, 1.0)
    rho = np.ones_like(h)
    K = np.zeros((n, n))
    M = np.zeros(n)
    for e in range(len(h)):
        k = E[e] / h[e]
        K[e:e + 2, e:e + 2] += k * np.array([[1.0, -1.0], [-1.0, 1.0]])
        M[e:e + 2] += 0.5 * rho[e] * h[e]
    cells = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    return x, M, K, cells


def levels(M, K, cells, max_level=5):
    """Fine index k per node (0 finest, step dt_min 2^k), as workflows/lts_clusters.py: Gershgorin
    per node, per cell the finest of its nodes, per node the finest of its cells."""
    dt_node = 2.0 / np.sqrt(np.abs(K).sum(axis=1) / M)
    dt_min = dt_node.min()
    cell_level = np.minimum(np.floor(np.log2(dt_node[cells].min(axis=1) / dt_min) + 1e-12).astype(int), max_level)
    node_level = np.full(len(M), max_level)
    np.minimum.at(node_level, cells.ravel(), np.repeat(cell_level, 2))
    return node_level, dt_min


def lts_step(u, v, M, K, node_level, dt):
    """One global step dt = dt_min 2^L of the recursion S(k, h) (docs/lts_plan.md), k the coarse index."""
    L = int(node_level.max())
    masks = [(L - node_level) == k for k in range(L + 1)]   # coarse index 0 = coarsest

    def force(k, u):
        return -K @ np.where(masks[k], u, 0.0)

    def S(k, h, u, v):
        v = v + 0.5 * h * force(k, u) / M
        if k == L:
            u = u + h * v
        else:
            u, v = S(k + 1, 0.5 * h, u, v)
            u, v = S(k + 1, 0.5 * h, u, v)
        v = v + 0.5 * h * force(k, u) / M
        return u, v

    return S(0, dt, u, v)


def verlet_step(u, v, M, K, dt):
    v = v - 0.5 * dt * (K @ u) / M
    u = u + dt * v
    v = v - 0.5 * dt * (K @ u) / M
    return u, v


def spectral_radius(step, n):
    """Largest |eigenvalue| of the linear one-step map (u, v) -> step(u, v)."""
    columns = []
    for j in range(2 * n):
        e = np.zeros(2 * n)
        e[j] = 1.0
        u, v = step(e[:n], e[n:])
        columns.append(np.concatenate([u, v]))
    return float(np.max(np.abs(np.linalg.eigvals(np.array(columns).T))))


def main() -> int:
    x, M, K, cells = graded_bar()
    node_level, dt_min = levels(M, K, cells)
    L = int(node_level.max())
    omega_max = np.sqrt(np.max(np.linalg.eigvals(K / M[:, None]).real))
    print(f"bar: {len(x)} nodes, levels (0 finest): {np.bincount(node_level).tolist()}; "
          f"Gershgorin dt_min {dt_min:.4e}, exact global critical step {2 / omega_max:.4e}")

    # 1. One level = velocity Verlet.
    rng = np.random.default_rng(1)
    u0, v0 = rng.standard_normal(len(x)), rng.standard_normal(len(x))
    one = lts_step(u0, v0, M, K, np.zeros(len(x), dtype=int), 0.5 * dt_min)
    ref = verlet_step(u0, v0, M, K, 0.5 * dt_min)
    print(f"1. one level against velocity Verlet: {max(np.abs(one[0] - ref[0]).max(), np.abs(one[1] - ref[1]).max()):.1e}")

    # 2. Order in dt: a smooth pulse, T fixed, the global step halved.
    u_init = np.exp(-((x - 0.25) / 0.05) ** 2)
    T = 0.4
    fine_dt = dt_min / 64
    ur, vr = u_init.copy(), np.zeros_like(u_init)
    for _ in range(int(round(T / fine_dt))):
        ur, vr = verlet_step(ur, vr, M, K, fine_dt)
    errors = []
    for safety in (0.8, 0.4, 0.2):
        dt = safety * dt_min * 2 ** L
        steps = int(round(T / dt))
        dt = T / steps
        u, v = u_init.copy(), np.zeros_like(u_init)
        for _ in range(steps):
            u, v = lts_step(u, v, M, K, node_level, dt)
        errors.append(np.linalg.norm(u - ur) / np.linalg.norm(ur))
    orders = [np.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]
    print("2. error at T against a converged reference, safety 0.8, 0.4, 0.2:",
          ", ".join(f"{e:.2e}" for e in errors), "; observed orders", ", ".join(f"{o:.2f}" for o in orders))

    # 3. Stability: spectral radius of the one-step map against the safety factor.
    n = len(x)
    print("3. spectral radius of one global LTS step (1 = stable, undamped):")
    for safety in (0.5, 0.8, 0.9, 0.95, 1.0, 1.05):
        dt = safety * dt_min * 2 ** L
        radius = spectral_radius(lambda u, v: lts_step(u, v, M, K, node_level, dt), n)
        global_radius = spectral_radius(lambda u, v: verlet_step(u, v, M, K, safety * dt_min), n)
        print(f"   safety {safety:.2f}: LTS {radius:.6f}, global stepping at dt_min {global_radius:.6f}")

    # 4. Long run: energy bounded (the undamped scheme conserves a modified energy).
    dt = 0.8 * dt_min * 2 ** L
    u, v = u_init.copy(), np.zeros_like(u_init)
    energies = []
    for step in range(20000):
        u, v = lts_step(u, v, M, K, node_level, dt)
        if step % 100 == 0:
            energies.append(0.5 * v @ (M * v) + 0.5 * u @ K @ u)
    energies = np.array(energies)
    print(f"4. 20 000 global steps at safety 0.8: energy min/max over the run {energies.min() / energies[0]:.4f} / "
          f"{energies.max() / energies[0]:.4f} of the initial")
    work = np.mean(2.0 ** -node_level)
    print(f"work per simulated second against global stepping: {work:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

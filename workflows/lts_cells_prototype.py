"""Local time stepping with nonlinear cells at their own rates: a numpy prototype on the graded 1D
bar of workflows/lts_prototype.py, evidence for the design step the speed issue needs
(docs/lts_plan.md "Nonlinear cells at their own rates").

The kernel's LocalStepper splits the linear stiffness force by columns (Diaz & Grote: the force
of level k is -K P_k u, P_k the level-k nodes). An element-loop cell has no columns to split: its
force f_e(u_e) and its history (plastic strain, damage) are one cell's. The natural split for
those cells is by cells: F_k(u) = sum of the forces of the cells of level k, each cell evaluated
(and its history committed) once per substep of its own level, at the end kick, and every node
drifting at the rate of the finest cell that touches it. This prototype runs that recursion
S(k, h) with *all* forces split by cells and checks, against the column split and global
stepping:

1. one level: the velocity-Verlet step (round-off);
2. stability of the linear map: spectral radius of one global step over the safety factor,
   cell split against column split and global stepping at dt_min;
3. elastoplastic cells (perfectly plastic, return mapping) stepping at their coarse rates: the
   error at T against a converged global reference, observed order, against global stepping at
   the same dt_min;
4. energy: kinetic + stored + plastic dissipation of a long run stays bounded (the plastic cells'
   dissipation enters at their own rate).

Usage: /usr/bin/python3 workflows/lts_cells_prototype.py
"""
import numpy as np

from lts_prototype import graded_bar, levels, lts_step, spectral_radius, verlet_step


def cell_levels(M, K, cells, max_level=5):
    """(node_level, cell_level, dt_min) as lts_prototype.levels: per cell the finest rate of its nodes'
    Gershgorin steps, per node the finest of its cells."""
    node_level, dt_min = levels(M, K, cells, max_level)
    dt_node = 2.0 / np.sqrt(np.abs(K).sum(axis=1) / M)
    cell_level = np.minimum(np.floor(np.log2(dt_node[cells].min(axis=1) / dt_min) + 1e-12).astype(int),
                            max_level)
    return node_level, cell_level, dt_min


class Bar:
    """The bar's cells: stiffness E/h, length h, and for the plastic ones a yield stress and the
    committed plastic strain. force(cells_mask, u, commit) returns the nodal force of those cells
    at u (and commits their plastic strain)."""

    def __init__(self, x, cells, E, yield_stress):
        self.x, self.cells = x, cells
        self.h = np.diff(x)
        self.E = E
        self.yield_stress = yield_stress  # inf: elastic
        self.plastic = np.zeros(len(self.h))
        self.dissipation = 0.0

    def copy(self):
        other = Bar(self.x, self.cells, self.E, self.yield_stress)
        other.plastic, other.dissipation = self.plastic.copy(), self.dissipation
        return other

    def force(self, mask, u, commit=True):
        a, b = self.cells[mask, 0], self.cells[mask, 1]
        strain = (u[b] - u[a]) / self.h[mask]
        trial = self.E[mask] * (strain - self.plastic[mask])
        stress = np.clip(trial, -self.yield_stress[mask], self.yield_stress[mask])  # the return
        if commit:
            increment = (trial - stress) / self.E[mask]
            self.plastic[mask] += increment
            self.dissipation += float(np.sum(stress * increment * self.h[mask]))
        f = np.zeros(len(u))
        np.add.at(f, a, stress)
        np.add.at(f, b, -stress)
        return f

    def stored(self, u):
        strain = (u[self.cells[:, 1]] - u[self.cells[:, 0]]) / self.h
        return float(np.sum(0.5 * self.E * (strain - self.plastic) ** 2 * self.h))


def cell_split_step(u, v, M, bar, node_level, cell_level, dt, state):
    """One global step of the recursion with the forces split by cells (coarse index c = L - k):
      S(c, h): v += h/2 M^-1 F_c (FSAL: the last end kick's force of level c)
               u += h v on the nodes whose finest cell is of level c
               if c < L: S(c+1, h/2) twice
               F_c = level-c cells' force at the new u (their history committed); v += h/2 M^-1 F_c
    state: {c: F_c} carried between steps (initialised at the first call)."""
    L = int(node_level.max())
    cell_masks = [(L - cell_level) == c for c in range(L + 1)]
    drift = [(L - node_level) == c for c in range(L + 1)]
    if not state:
        for c in range(L + 1):
            state[c] = bar.force(cell_masks[c], u, commit=False)

    def S(c, h, u, v):
        v = v + 0.5 * h * state[c] / M
        u = np.where(drift[c], u + h * v, u)
        if c < L:
            u, v = S(c + 1, 0.5 * h, u, v)
            u, v = S(c + 1, 0.5 * h, u, v)
        state[c] = bar.force(cell_masks[c], u)
        v = v + 0.5 * h * state[c] / M
        return u, v

    return S(0, dt, u, v)


def global_step(u, v, M, bar, dt, state):
    """Velocity Verlet with every cell at dt (the cells' force, history committed once per step)."""
    every = np.ones(len(bar.h), dtype=bool)
    if "f" not in state:
        state["f"] = bar.force(every, u, commit=False)
    v = v + 0.5 * dt * state["f"] / M
    u = u + dt * v
    state["f"] = bar.force(every, u)
    v = v + 0.5 * dt * state["f"] / M
    return u, v


def main() -> int:
    x, M, K, cells = graded_bar()
    node_level, cell_level, dt_min = cell_levels(M, K, cells)
    L = int(node_level.max())
    h = np.diff(x)
    E = np.diag(K, 1) * -h  # the bar's moduli from its stiffness (k = E / h)
    n = len(x)
    print(f"bar: {n} nodes; node levels (0 finest) {np.bincount(node_level).tolist()}, "
          f"cell levels {np.bincount(cell_level).tolist()}")

    # 1. One level: velocity Verlet.
    rng = np.random.default_rng(1)
    u0, v0 = rng.standard_normal(n), rng.standard_normal(n)
    elastic = Bar(x, cells, E, np.full(len(h), np.inf))
    one = cell_split_step(u0, v0, M, elastic.copy(), np.zeros(n, dtype=int), np.zeros(len(h), dtype=int),
                          0.5 * dt_min, {})
    ref = verlet_step(u0, v0, M, K, 0.5 * dt_min)
    print(f"1. one level against velocity Verlet: {max(np.abs(one[0] - ref[0]).max(), np.abs(one[1] - ref[1]).max()):.1e}")

    # 2. Linear stability: the one-step map's spectral radius. The cell split's map is linear for
    # elastic cells; FSAL state makes it a map of (u, v) only when the start force is that of u, so
    # each column starts from a fresh state.
    print("2. spectral radius of one global step (1 = stable, undamped):")
    for safety in (0.5, 0.8, 0.9, 0.95, 0.99, 1.0, 1.05):
        dt = safety * dt_min * 2 ** L
        cell = spectral_radius(lambda u, v: cell_split_step(u, v, M, elastic, node_level, cell_level, dt, {}), n)
        column = spectral_radius(lambda u, v: lts_step(u, v, M, K, node_level, dt), n)
        glob = spectral_radius(lambda u, v: verlet_step(u, v, M, K, safety * dt_min), n)
        print(f"   safety {safety:.2f}: cell split {cell:.6f}, column split {column:.6f}, global at dt_min {glob:.6f}")

    # 3. Plastic soft cells (coarse levels): a velocity pulse from rest (an admissible start) splits
    # into two waves of stress E v / (2 c) = v / 2 in the soft part (E = rho = 1); the soft cells
    # yield at 0.6 of that.
    pulse = np.exp(-((x - 0.25) / 0.05) ** 2)
    soft = E < E.max()
    yield_stress = np.where(soft, 0.6 * 0.5 * pulse.max(), np.inf)
    T = 0.4
    reference_bar = Bar(x, cells, E, yield_stress)
    fine_dt = dt_min / 64
    ur, vr, state = np.zeros(n), pulse.copy(), {}
    for _ in range(int(round(T / fine_dt))):
        ur, vr = global_step(ur, vr, M, reference_bar, fine_dt, state)
    print(f"3. plastic soft cells (levels {sorted(set(cell_level[soft].tolist()))}): reference dissipates "
          f"{reference_bar.dissipation / (0.5 * vr @ (M * vr) + reference_bar.stored(ur) + reference_bar.dissipation):.1%} "
          f"of the energy by T; {int(np.sum(np.abs(reference_bar.plastic) > 0))} of {int(soft.sum())} soft cells yielded")
    rows = []
    for safety in (0.8, 0.4, 0.2, 0.1):
        dt = safety * dt_min * 2 ** L
        steps = int(round(T / dt))
        dt = T / steps
        bar, state = Bar(x, cells, E, yield_stress), {}
        u, v = np.zeros(n), pulse.copy()
        for _ in range(steps):
            u, v = cell_split_step(u, v, M, bar, node_level, cell_level, dt, state)
        lts_error = np.linalg.norm(u - ur) / np.linalg.norm(ur)
        gdt = dt / 2 ** L
        bar_g, state = Bar(x, cells, E, yield_stress), {}
        ug, vg = np.zeros(n), pulse.copy()
        for _ in range(steps * 2 ** L):
            ug, vg = global_step(ug, vg, M, bar_g, gdt, state)
        global_error = np.linalg.norm(ug - ur) / np.linalg.norm(ur)
        rows.append((safety, lts_error, global_error,
                     abs(bar.dissipation - reference_bar.dissipation) / reference_bar.dissipation))
    for i, (safety, lts_error, global_error, dissipation_error) in enumerate(rows):
        order = "" if i == 0 else f", order {np.log2(rows[i - 1][1] / lts_error):.2f} (global {np.log2(rows[i - 1][2] / global_error):.2f})"
        print(f"   safety {safety:.2f}: displacement error LTS {lts_error:.2e}, global at dt_min {global_error:.2e}"
              f"{order}; dissipation error LTS {dissipation_error:.1e}")

    # 4. Long run with plasticity: kinetic + stored + dissipated stays bounded.
    dt = 0.8 * dt_min * 2 ** L
    bar, state = Bar(x, cells, E, yield_stress), {}
    u, v = np.zeros(n), pulse.copy()
    initial = 0.5 * v @ (M * v)
    totals = []
    for step in range(20000):
        u, v = cell_split_step(u, v, M, bar, node_level, cell_level, dt, state)
        if step % 100 == 0:
            totals.append((0.5 * v @ (M * v) + bar.stored(u) + bar.dissipation) / initial)
    totals = np.array(totals)
    print(f"4. 20 000 global steps at safety 0.8 with plastic cells: (kinetic + stored + dissipated) / initial "
          f"min {totals.min():.4f}, max {totals.max():.4f}; dissipated {bar.dissipation / initial:.1%}")
    work = np.mean(2.0 ** -cell_level)
    print(f"cell evaluations per simulated second against global stepping: {work:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

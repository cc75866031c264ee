"""The row split of local time stepping (nodal subcycling) against the column split the kernel runs,
on a graded 1D bar: the strain where rate levels meet (docs/lts_plan.md "The row split, prototyped").

The kernel's LocalStepper splits the stiffness by columns: a coarser node's force reaches a finer
node as kicks at the ends of the coarse step (impulse multiple time stepping), and a coarse node
next to finer ones drifts with them while its own force arrives every coarse step. On the cavity
test that put a 9-61 % error into the hoop stress of the cells where levels meet
(docs/lts_plan.md "A buffer does not remove it"). The row split (Belytschko, Yen & Mullen 1979)
steps every node at its own level with its whole row force; a node reads a coarser neighbour along
that neighbour's drift, u0 + (t - t0) v, which is exact because no kick changes its velocity within
its drift, and finer neighbours are in step with it at its kick times.

Prints, on a bar whose cells grow 3 % per cell from its middle outwards (5 rate levels):
1. the strain history error of every cell against a converged reference, column split, row split
   and global stepping at the finest step, at safety 0.8, 0.4, 0.2; at the level boundaries and
   elsewhere;
2. the spectral radius of one global step of each scheme over the safety factor;
3. momentum and energy over 20 000 global steps of the free bar (the row split conserves neither
   exactly; the column split conserves momentum).

    /usr/bin/python3 workflows/lts_row_split.py      # about a minute
"""
from __future__ import annotations

import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from lts_prototype import levels, lts_step, spectral_radius, verlet_step  # noqa: E402


def graded_bar(n_cells: int = 200, h_min: float = 0.01, growth: float = 1.03):
    """x, cell sizes, lumped masses and stiffness of a unit-modulus, unit-density bar whose cells grow
    by `growth` per cell from the middle outwards (the grading of a mesh around an opening)."""
    h = h_min * growth ** np.abs(np.arange(n_cells) - n_cells // 2)
    x = np.concatenate([[0.0], np.cumsum(h)])
    K = np.zeros((len(x), len(x)))
    M = np.zeros(len(x))
    for e, size in enumerate(h):
        K[e:e + 2, e:e + 2] += np.array([[1.0, -1.0], [-1.0, 1.0]]) / size
        M[e:e + 2] += 0.5 * size
    cells = np.column_stack([np.arange(n_cells), np.arange(1, n_cells + 1)])
    return x, h, M, K, cells


class RowSplit:
    """One global step dt of nodal subcycling in velocity-Verlet form. Node i steps at
    dt_fine 2^level[i]: at the start of each of its steps a half kick with its last acceleration, then
    a drift at constant velocity; at the end its whole row's force at the positions of that time (a
    coarser neighbour along its drift, u0 + (t - t0) v; finer and equal neighbours at their own ends,
    which coincide) and the second half kick. With one level it is velocity Verlet."""

    def __init__(self, M, K, level, dt):
        self.M, self.K, self.level = M, K, np.asarray(level)
        self.fine = dt / 2 ** int(self.level.max())
        self.a = None

    def step(self, u, v):
        M, K, level = self.M, self.K, self.level
        if self.a is None:
            self.a = -(K @ u) / M
        start_u, velocity, start_t = u.copy(), v.copy(), np.zeros(len(u))
        own_step = self.fine * 2.0 ** level
        a = self.a.copy()
        for m in range(2 ** int(level.max())):
            starting = m % 2 ** level == 0
            velocity[starting] += 0.5 * own_step[starting] * a[starting]
            t_end = (m + 1) * self.fine
            ending = (m + 1) % 2 ** level == 0
            at_end = start_u + (t_end - start_t) * velocity
            a[ending] = -(K @ at_end)[ending] / M[ending]
            velocity[ending] += 0.5 * own_step[ending] * a[ending]
            start_u[ending], start_t[ending] = at_end[ending], t_end
        self.a = a
        return start_u, velocity


def strain_errors(x, h, M, K, cells, level, dt_min):
    """Per scheme and safety: the strain history error of every cell (against the reference's largest
    cell norm) over a pulse crossing the bar's levels."""
    top = int(level.max())
    u_start = np.exp(-((x - (x[len(x) // 2] - 0.6)) / 0.15) ** 2)
    dt0 = 0.8 * dt_min * 2 ** top
    steps = int(np.ceil(1.2 / dt0))

    def strain(u):
        return np.diff(u) / h

    reference, u, v = [], u_start.copy(), np.zeros_like(u_start)
    for _ in range(steps):
        for _ in range(2 ** top * 64):
            u, v = verlet_step(u, v, M, K, dt0 / (2 ** top * 64))
        reference.append(strain(u))
    reference = np.array(reference)
    scale = np.linalg.norm(reference, axis=0).max()
    errors = {}
    for halvings, safety in enumerate((0.8, 0.4, 0.2)):
        per = 2 ** halvings
        dt = dt0 / per
        for scheme in ("global", "column", "row"):
            u, v, history = u_start.copy(), np.zeros_like(u_start), []
            rows = RowSplit(M, K, level, dt)
            for s in range(steps * per):
                if scheme == "global":
                    for _ in range(2 ** top):
                        u, v = verlet_step(u, v, M, K, dt / 2 ** top)
                elif scheme == "column":
                    u, v = lts_step(u, v, M, K, level, dt)
                else:
                    u, v = rows.step(u, v)
                if (s + 1) % per == 0:
                    history.append(strain(u))
            errors[scheme, safety] = np.linalg.norm(np.array(history) - reference, axis=0) / scale
    return errors


def main() -> int:
    x, h, M, K, cells = graded_bar()
    level, dt_min = levels(M, K, cells)
    boundary = np.flatnonzero(level[cells[:, 0]] != level[cells[:, 1]])
    print(f"bar: {len(h)} cells of {h.min():.3f}-{h.max():.3f}, nodes per level (finest first) "
          f"{np.bincount(level).tolist()}; cells where levels meet: {boundary.tolist()}")
    errors = strain_errors(x, h, M, K, cells, level, dt_min)
    # The cells next to a boundary cell too: the column split's largest errors sit there.
    near = np.unique(np.clip(np.concatenate([boundary - 1, boundary, boundary + 1]), 0, len(h) - 1))
    print("1. strain history error (of the largest cell's norm): at and next to the level boundaries / elsewhere")
    for (scheme, safety), error in errors.items():
        print(f"   safety {safety}, {scheme:6s}: {error[near].max():.2e} / {np.delete(error, near).max():.2e}")
    for scheme in ("column", "row"):
        worst = [errors[scheme, s][near].max() for s in (0.8, 0.4, 0.2)]
        print(f"   {scheme} split, observed order at the boundaries: "
              + ", ".join(f"{np.log2(worst[k] / worst[k + 1]):.2f}" for k in range(2)))

    small = graded_bar(n_cells=120)
    small_level, small_dt = levels(small[2], small[3], small[4])
    n = len(small[0])
    print(f"2. spectral radius - 1 of one global step (a 120-cell bar, nodes per level "
          f"{np.bincount(small_level).tolist()}):")
    for safety in (0.5, 0.8, 0.95, 1.0, 1.05):
        dt = safety * small_dt * 2 ** int(small_level.max())
        row = spectral_radius(lambda u, v: RowSplit(small[2], small[3], small_level, dt).step(u, v), n)
        column = spectral_radius(lambda u, v: lts_step(u, v, small[2], small[3], small_level, dt), n)
        print(f"   safety {safety:.2f}: row split {row - 1:+.1e}, column split {column - 1:+.1e}")

    x, h, M, K, cells = small
    dt = 0.8 * small_dt * 2 ** int(small_level.max())
    u = np.exp(-((x - x[n // 2] + 0.3) / 0.1) ** 2)
    v = np.zeros(n)
    u_column, v_column = u.copy(), v.copy()
    rows = RowSplit(M, K, small_level, dt)
    initial = 0.5 * u @ K @ u
    momentum = {"row": 0.0, "column": 0.0}
    energy = []
    for _ in range(20000):
        u, v = rows.step(u, v)
        u_column, v_column = lts_step(u_column, v_column, M, K, small_level, dt)
        momentum["row"] = max(momentum["row"], abs(M @ v) / (M @ np.abs(v)))
        momentum["column"] = max(momentum["column"], abs(M @ v_column) / (M @ np.abs(v_column)))
        energy.append((0.5 * v @ (M * v) + 0.5 * u @ K @ u) / initial)
    print(f"3. 20 000 global steps at safety 0.8: |sum M v| / sum M |v| at most {momentum['row']:.1e} (row split), "
          f"{momentum['column']:.1e} (column split); the row split's energy within {min(energy):.4f}-{max(energy):.4f} "
          "of the initial")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

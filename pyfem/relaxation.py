"""Dynamic relaxation: the static stage's solver for nonlinear materials and contact pairs
(docs/static.md "The nonlinear stage").

The static equilibrium f_int(u) = f is the rest state of the damped motion
    M_s a + alpha M_s v + f_int(u) = f,
which the explicit kernel integrates with the very laws, contact pairs and constraints of the
dynamic run. Two things change, both allowed only here because the path to the rest state does
not matter:

- **mass scaling** (Underwood 1983): each node gets the mass M_s,i = (dt^2 / 4) s^-2 max_r sum_c |K_rc|
  over its three rows r of the elastic stiffness (all cells, initial moduli, the plastic factor of
  non-associated flow), so that Gershgorin's bound puts every node's frequency at or below
  2 s / dt: the stable step is the same everywhere (dt = 1 in pseudo time, s the safety factor);
- **a slow load** for path-dependent stages (laws, contact pairs): the load rises smoothly over
  RAMP_PERIODS periods of the lowest frequency omega_1 of the elastic stage, measured first by a
  short elastic relaxation (`probe_frequency`), so that the damped motion follows the load
  quasi-statically instead of overshooting into plastic flow or slip that a static path would
  not see (Salencon's cavity with the load applied at once: 78 % too much wall convergence);
- **critical damping, adapted** (Underwood's adaptive dynamic relaxation): alpha = 2 omega with
  omega^2 = du.df_int / du.M_s du, the Rayleigh quotient of the displacement increment of the last
  `chunk` steps, which tends to the lowest frequency of the deformation still moving, but not
  below half the total displacement's (a softening mechanism would otherwise leave the stiffer
  modes ringing); f_int = f(t) - r, r = M_s (a + alpha v) the out-of-balance force the kernel's
  last step leaves.

Convergence: ||r|| / ||f|| <= tolerance (r on the free directions: the kernel projects the held
ones out) at two successive checks. Python checks between chunks of steps; no Python runs per
step.
"""
from __future__ import annotations

import dataclasses
import math
import os
import time

import numpy as np

# Pseudo time step of the relaxation (the scaled mass makes it the stable step of every node).
PSEUDO_STEP = 1.0
# Safety factor s of the scaled mass: frequencies at most 2 s / dt.
SAFETY = 0.8
# Steps between two convergence checks (and damping updates).
CHUNK = 50
# The load of a nonlinear stage rises over RAMP_PERIODS periods of the lowest frequency the probe
# finds (Salencon's cavity: 2 and 6 periods give the same wall displacement to 1e-5).
RAMP_PERIODS = 3.0
MINIMUM_RAMP = 200.0
# Developer aids, not scene settings: PYFEM_RELAX_DIAGNOSE=1 adds alpha, the largest velocity and the
# worst node's out-of-balance to each progress report; PYFEM_RELAX_REPORT sets its interval (s).
DIAGNOSE = bool(os.environ.get("PYFEM_RELAX_DIAGNOSE"))
# Wall time between two progress reports of a long relaxation (s).
REPORT_SECONDS = float(os.environ.get('PYFEM_RELAX_REPORT', 30.0))
# Out-of-balance ratio of the elastic probe (enough for its Rayleigh quotient).
PROBE_TOLERANCE = 1.0e-3


@dataclasses.dataclass
class RelaxationResult:
    """How a relaxation went.

    Attributes:
        converged: the out-of-balance ratio reached the tolerance.
        steps: pseudo-time steps taken.
        residual: final ||r|| / ||f||.
        history: (step, ratio, alpha) at every check.
        out_of_balance: (n_dofs,) r = f - f_int at the end (N), free directions only.
        seconds: wall time.
    """

    converged: bool
    steps: int
    residual: float
    history: list
    out_of_balance: np.ndarray
    seconds: float


def scaled_mass(stiffness, frequency_factor: float = 1.0, safety: float = SAFETY,
                dt: float = PSEUDO_STEP) -> np.ndarray:
    """(n_nodes,) the relaxation's nodal masses: (dt^2/4) (factor/safety)^2 max over the node's rows
    of sum |K_rc| (Gershgorin), so that omega_max dt <= 2 safety for every node.

    Args:
        stiffness: (3n, 3n) elastic stiffness of every cell that can act during the stage (N/m).
        frequency_factor: how much a law can raise frequencies over the elastic ones (>= 1).
    """
    import scipy.sparse as sp

    absolute = abs(sp.csr_matrix(stiffness))
    row_sums = np.asarray(absolute.sum(axis=1)).ravel().reshape(-1, 3).max(axis=1)
    return mass_of_row_sums(row_sums, frequency_factor, safety, dt)


def mass_of_row_sums(row_sums: np.ndarray, frequency_factor: float = 1.0, safety: float = SAFETY,
                     dt: float = PSEUDO_STEP, comm=None) -> np.ndarray:
    """`scaled_mass` of each node's largest scalar row sum of |K_rc|; `comm`: the nodes are an MPI
    rank's owned ones (pyfem/distributed_stage.py), the largest mass taken over the ranks."""
    mass = 0.25 * dt * dt * (frequency_factor / safety) ** 2 * np.asarray(row_sums, dtype=np.float64)
    # A node no cell of the model touches cannot move either way: any positive mass.
    positive = mass > 0.0
    largest = float(mass[positive].max(initial=1.0))
    if comm is not None:
        from mpi4py import MPI

        largest = comm.allreduce(largest, op=MPI.MAX)
    mass[~positive] = largest
    return mass


class WholeModel:
    """relax's arithmetic on one process: its arrays hold every dof (the serial stage). Under mpirun
    pyfem.distributed_stage.RankSpace offers the same calls on each rank's owned dofs, with sums
    over the ranks (allreduce) and rank 0's decisions (broadcast)."""

    def owned_rows(self, n_dofs: int):
        """The rows of the model's dof vectors that relax's arrays hold: all of them."""
        return slice(0, n_dofs)

    def dot(self, x: np.ndarray, y: np.ndarray) -> float:
        return float(x @ y)

    def norm(self, x: np.ndarray) -> float:
        return float(np.linalg.norm(x))

    def all_finite(self, *arrays: np.ndarray) -> bool:
        return all(bool(np.isfinite(x).all()) for x in arrays)

    def agreed(self, value):
        return value

    def whole(self, x: np.ndarray) -> np.ndarray:
        """The model's vector from relax's array of it: itself."""
        return x


class RankSums:
    """relax's arithmetic when each MPI rank holds its owned dofs (`comm`: the ranks): dot products
    and norms summed over the ranks, rank 0's decisions for every rank. The subclass
    pyfem.distributed_stage.RankSpace says which rows a rank
    holds (`owned_rows`) and what relax returns (`whole`)."""

    comm = None

    def dot(self, x: np.ndarray, y: np.ndarray) -> float:
        """x . y over the whole model: each rank's owned part, summed over the ranks."""
        from mpi4py import MPI

        return float(self.comm.allreduce(float(x @ y), op=MPI.SUM))

    def norm(self, x: np.ndarray) -> float:
        return float(np.sqrt(self.dot(x, x)))

    def all_finite(self, *arrays: np.ndarray) -> bool:
        from mpi4py import MPI

        return bool(self.comm.allreduce(all(bool(np.isfinite(x).all()) for x in arrays), op=MPI.LAND))

    def agreed(self, value):
        """Rank 0's `value` on every rank (a collective): relax's decisions (out-of-balance ratio,
        damping) are taken from rank 0's arithmetic, so that no rank can decide otherwise by the
        last bit of a sum on another processor."""
        return self.comm.bcast(value, root=0)


def _default_space(stepper):
    """relax's `space` when none is given: a stepper with owned rows is its own, a Stepper the whole model."""
    return stepper if hasattr(stepper, "owned_rows") else WholeModel()


def _rayleigh(x: np.ndarray, force: np.ndarray, m: np.ndarray, space=None) -> float:
    """sqrt(x.force / x.M x), or 0 when either is not positive (sums over `space`'s ranks)."""
    space = space or WholeModel()
    stiffness_term, mass_term = space.dot(x, force), space.dot(x, m * x)
    return math.sqrt(stiffness_term / mass_term) if stiffness_term > 0.0 and mass_term > 0.0 else 0.0


def load_factor(t: float, ramp: float) -> float:
    """The share of the load applied at pseudo time t: the smoothstep 3 s^2 - 2 s^3 of s = t / ramp
    (pyfem.static.hand_over_force_provider's smoothstep), 1 after the ramp."""
    if ramp <= 0.0 or t >= ramp:
        return 1.0
    s = max(t, 0.0) / ramp
    return s * s * (3.0 - 2.0 * s)


def probe_frequency(stepper, mass: np.ndarray, load: np.ndarray, max_steps: int,
                    tolerance: float = PROBE_TOLERANCE, floor: float = 0.0, space=None) -> tuple[float, int]:
    """The lowest frequency (1/pseudo time) that relaxing `load` excites: an elastic relaxation
    (a stepper with the stage's elastic cells and no laws) run to a loose tolerance; omega from
    the Rayleigh quotient of its displacement. Sets how slowly a nonlinear stage must load.
    `space`: as for `relax`.

    Returns:
        (omega, steps taken).
    """
    space = space or _default_space(stepper)
    u, result = relax(stepper, mass, load, tolerance, max_steps, floor=floor, space=space)
    rows = space.owned_rows(len(load))  # the whole model (one rank) or the owned dofs
    internal = np.asarray(load)[rows] - result.out_of_balance[rows]
    omega = space.agreed(_rayleigh(u[rows], internal, np.repeat(mass, 3)[rows], space))
    return (omega if omega > 0.0 else 2.0 * SAFETY / PSEUDO_STEP), result.steps


def ramp_length(omega: float) -> float:
    """Pseudo time over which a nonlinear stage's load rises: RAMP_PERIODS periods of the lowest
    frequency omega, at least MINIMUM_RAMP steps, so that the damped motion follows the load
    quasi-statically (no dynamic overshoot: plasticity and pair slip are path dependent)."""
    return max(MINIMUM_RAMP, RAMP_PERIODS * 2.0 * math.pi / omega) * PSEUDO_STEP


def relax(stepper, mass: np.ndarray, load: np.ndarray, tolerance: float, max_steps: int,
          chunk: int = CHUNK, ramp: float = 0.0, floor: float = 0.0, report=None,
          space=None) -> tuple[np.ndarray, RelaxationResult]:
    """Runs the damped pseudo-dynamics of a stepper built for the stage from rest to equilibrium.

    Args:
        stepper: pyfem._kernels.Stepper with dt = PSEUDO_STEP and mass `mass`, its constraints,
            the constant load as a force provider, components and contact pairs attached (or, under
            mpirun, a rank's part of one: pyfem/distributed_stage.py).
        mass: (n_nodes,) the stepper's masses.
        load: (n_dofs,) the load the provider applies (N), for the ratio ||r|| / ||f||.
        tolerance: out-of-balance ratio to reach.
        max_steps: give up after this many steps (converged = False).
        chunk: steps between checks.
        ramp: the provider's load rises over this pseudo time; convergence is checked after it.
        floor: smallest force norm the ratio is taken against (N): a stage whose load nearly
            cancels (nothing excavated) is measured against the stress state's force scale.
        report: None, or called as report(steps, ratio, seconds) every REPORT_SECONDS of wall time.
        space: where relax's arrays live: the whole model in this process (`WholeModel`, the
            default for a Stepper); or a rank's RankSpace (pyfem/distributed_stage.py):
            each rank steps and checks its owned dofs, the norms and Rayleigh quotients are sums
            over the ranks, the ratio and the damping rank 0's.

    Returns:
        (u, RelaxationResult): the displacement at the end (n_dofs,) and how it went, whole on every rank.
    """
    start = time.perf_counter()
    space = space or _default_space(stepper)
    rows = space.owned_rows(len(load))
    load = np.asarray(load)[rows]
    m = np.repeat(mass, 3)[rows]
    n = len(m)
    u, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    load_norm = max(space.norm(load), floor)
    history = []
    t, steps, alpha, below = 0.0, 0, 0.0, 0
    last_report = start
    previous_u, previous_internal = np.zeros(n), np.zeros(n)
    ratio = 0.0 if load_norm == 0.0 else 1.0
    residual = np.zeros(n)
    if load_norm == 0.0:
        return space.whole(u), RelaxationResult(True, 0, 0.0, [], space.whole(residual), time.perf_counter() - start)
    while steps < max_steps:
        count = min(chunk, max_steps - steps)
        t = stepper.run(u, v, a, count, t)
        steps += count
        if not space.all_finite(u):
            raise FloatingPointError(f"the static stage's relaxation became non-finite after {steps} steps")
        residual = m * (a + alpha * v)
        ratio = space.agreed(space.norm(residual) / load_norm)
        history.append((steps, ratio, alpha))
        below = below + 1 if ratio <= tolerance and t >= ramp else 0
        if report is not None and time.perf_counter() - last_report > REPORT_SECONDS:
            last_report = time.perf_counter()
            report(steps, ratio, last_report - start)
            if DIAGNOSE and isinstance(space, WholeModel):
                worst = int(np.argmax(np.abs(residual))) // 3
                print(f"   alpha {alpha:.3g}, |v|max {np.abs(v).max():.3g}, worst node {worst} "
                      f"|r| {np.abs(residual[3 * worst:3 * worst + 3]).max():.3g}", flush=True)
        if below >= 2:
            break
        # Rayleigh quotient of the chunk's displacement increment (Underwood): du.df_int / du.M du,
        # f_int = f(t) - r; the mode still moving sets the damping. The total u's quotient when the
        # increment's is not positive (softening) or on the first chunk.
        internal = load_factor(t, ramp) * load - residual
        increment, force_increment = u - previous_u, internal - previous_internal
        omega_increment = _rayleigh(increment, force_increment, m, space)
        omega_total = _rayleigh(u, internal, m, space)
        # Not below half the total displacement's: a softening mechanism (cracking, slip) gives the
        # increment a tiny quotient, and so little damping would leave the stiffer modes ringing.
        omega = space.agreed(max(omega_increment, 0.5 * omega_total))
        if omega > 0.0:
            alpha = min(2.0 * omega, 2.0 / PSEUDO_STEP)
            stepper.set_mass_damping(alpha)
        previous_u, previous_internal = u.copy(), internal
    return space.whole(u), RelaxationResult(converged=below >= 2, steps=steps, residual=ratio, history=history,
                                            out_of_balance=space.whole(residual),
                                            seconds=time.perf_counter() - start)

"""The static stage on the distributed model (`[parallel] model = "distributed"` with [static];
docs/static.md, docs/scaling.md "The static stage on the distributed model").

The stage is the whole model's dynamic relaxation (pyfem/static.py `solve_relaxation_stage`,
pyfem/relaxation.py `relax`), built from each rank's part of dolfinx's mesh as the dynamic run is
(pyfem/distributed_model.py): no rank holds the whole model at any time.

Each rank:
1. assembles the stage's loads with the whole model's dolfinx forms (`static.stage_loads`: f_exc
   = traction of the in-situ stress on the truncation faces + body force - B^T sigma0 over the
   rock's cells; the installed regions' weight with gravity) on its cells, summed onto dolfinx's
   owners and taken into the kernel's numbering (a moved pair node's from its dolfinx owner);
2. assembles three elastic matrices on the same rows as the dynamic run's (no boundary springs):
   every cell (its Gershgorin row sums give the relaxation's scaled mass, as `scaled_mass`), every
   cell but the installed ones (the frequency probe's), and the stages' matrices: all but the
   element-loop cells (stage 2) and, with an install, all but the element-loop and the installed
   cells (stage 1);
3. holds the stage's faces (`static.boundary`: rollers by default) on the nodes it steps, keeps
   its pairs with their static forces F0 = A sigma0 n and no deterioration, and steps its counted
   and halo element-loop cells, the rock's from the in-situ stress, the installed regions' from
   zero in stage 2;
4. relaxes with `relax`'s arithmetic on its owned dofs (`RankSpace`: norms and Rayleigh quotients
   summed over the ranks, rank 0's ratio and damping for every rank), so the ranks take the same
   steps and stop together.

The end state is handed to the dynamic run as the whole model's `hand_over` hands it: the element-
loop components and the pairs go on (rebased: the stage's stress is their initial stress, the
pairs' total force their F0, with the deterioration now on); the monitors in matrix cells and the
fields' matrix cells get sigma0 + C : eps(u1 + u2) in the rock, C : eps(u2) in the installed
regions. A relaxed stage's out-of-balance is its error and is not applied (as in the whole model).

A linear stage (static.solver "direct" or "iterative", or "auto" without a nonlinear material) is
solved by PETSc across the ranks instead (pyfem/distributed_linear.py) and handed over here. A
resumed run solves the stage again (the same arithmetic on the same rank count; on another, the
same to round-off) and then loads the checkpoint's state over it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from pyfem.relaxation import RankSums
from pyfem.scene import SceneError

KEY = "static.solver"


def check_supported(scene) -> None:
    """Raises SceneError when the scene's stage is one no model solves (pyfem.static.check_linear:
    a linear solver asked for a nonlinear material), as the serial run does."""
    from pyfem.static import check_linear

    if "static" in scene:
        check_linear(scene)


# --- the rank's arrays in the kernel's numbering ----------------------------------------------------

def kernel_nodal(part, values) -> np.ndarray:
    """(n_local, k) per-node values of the function space's local nodes (owned and ghosts, dolfinx's
    numbering, ghosts valid) in the kernel's numbering (pyfem.distributed_parts.to_kernel_numbering).
    A collective."""
    from pyfem.distributed_parts import to_kernel_numbering

    held = np.arange(len(part.model.node_coords)) if part.kernel_of_dolfinx is None else part.kernel_of_dolfinx
    return to_kernel_numbering(part.comm, part.model.V.dofmap.index_map, held, part.local_nodes, values)


def owned_force(part, nodal: np.ndarray) -> np.ndarray:
    """(3 n_local,) a nodal force in the kernel's numbering on the nodes this rank steps, zero on its
    ghosts (each force acts once, where its node is stepped)."""
    force = np.array(nodal, dtype=np.float64).reshape(part.n_local, 3)
    force[part.n_owned:] = 0.0
    return force.reshape(-1)


def stage_matrix(part, removed_cells: np.ndarray, hourglass_but=None) -> tuple:
    """The kernel's (indptr, indices, blocks) of the elastic stiffness of every cell but the local
    `removed_cells`, on the dynamic run's rows and numbering (no boundary springs; all-zero blocks
    dropped, as pyfem.elements.linear_stiffness drops them); with `hourglass_but` (region names, not
    None) plus the hourglass stiffness of the one-point regions but those (pyfem/reduced_integration.py)."""
    from pyfem.assembly import elastic_stiffness_matrix
    from pyfem.distributed_parts import (_without_cells, add_hourglass, drop_zero_blocks, element_loop_cells,
                                         local_stiffness, localize, one_point_regions, owned_rows_global)
    from pyfem.distributed_pairs import move_rows

    model = part.model
    V, materials = model.V, model._materials
    quadrature = {"quadrature_degree": 2 * model.order}
    first, last = V.dofmap.index_map.local_range
    # (dolfinx's Functions and forms are collectives: every rank makes them, with or without removed cells)
    matrix = elastic_stiffness_matrix(V, *_without_cells(materials, removed_cells), quadrature)
    if hourglass_but is not None and one_point_regions(part.scene):
        add_hourglass(matrix, part.scene, model, element_loop_cells(part.scene, model), hourglass_but)
    _, global_rows = move_rows(part.comm, part.ownership, first, owned_rows_global(matrix, last - first,
                                                                                    release=True))
    rows = localize(global_rows, part.local_nodes)
    return drop_zero_blocks(local_stiffness(part.comm, part.ownership, rows, part.n_local, part.local_nodes))


def owned_rows(part, matrix: tuple):
    """(3 n_owned, 3 n_local) scipy CSR of a kernel matrix's (indptr, indices, blocks) owned rows,
    each row's entries in the order of the whole model's CSR on one rank (block columns ascending)."""
    import scipy.sparse as sp

    indptr, indices, blocks = matrix
    n = part.n_owned
    end = int(indptr[n])
    csr = sp.bsr_matrix((blocks[:end], indices[:end], indptr[:n + 1]), shape=(3 * n, 3 * part.n_local)).tocsr()
    csr.sort_indices()
    return csr


def row_sums(part, matrix: tuple) -> np.ndarray:
    """(n_owned,) the largest of each owned node's three scalar rows' sums of |K_rc| (Gershgorin),
    summed as pyfem.relaxation.scaled_mass sums the whole model's rows (scipy's CSR row sums, the
    entries in column order): on one rank the serial stage's masses to the bit."""
    absolute = abs(owned_rows(part, matrix))
    return np.asarray(absolute.sum(axis=1)).ravel().reshape(-1, 3).max(axis=1)


def scaled_mass(part, matrix: tuple, frequency_factor: float) -> np.ndarray:
    """(n_local,) pyfem.relaxation.scaled_mass of the ranks' owned rows, the ghosts' from the ranks
    stepping them (the ghost exchange)."""
    from pyfem.relaxation import mass_of_row_sums

    column = np.zeros((part.n_local, 1))
    column[:part.n_owned, 0] = mass_of_row_sums(row_sums(part, matrix), frequency_factor, comm=part.comm)
    part.plan.update(part.comm, column)
    return np.ascontiguousarray(column[:, 0])


# --- relax's stepper and arithmetic on a rank ---------------------------------------------------

class RankSpace(RankSums):
    """One stage's kernel Stepper of this rank's part behind the Stepper calls `relax` makes, and
    relax's `space` (pyfem.relaxation.WholeModel's calls): relax's arrays are the owned dofs, the
    kernel's (owned and ghost) are kept here; sums over the ranks, rank 0's decisions."""

    def __init__(self, comm: MPI.Comm, kernel, exchange, n_owned: int, n_local: int) -> None:
        self.comm, self.kernel, self.exchange = comm, kernel, exchange
        self.n_owned, self.n_local = n_owned, n_local
        self.local = tuple(np.zeros(3 * n_local) for _ in range(3))

    def owned_rows(self, n_dofs: int) -> slice:
        return slice(0, 3 * self.n_owned)

    def whole(self, x: np.ndarray) -> np.ndarray:
        """relax's result: this rank's owned dofs (the distributed model never gathers a whole vector)."""
        return x

    def set_mass_damping(self, alpha: float) -> None:
        self.kernel.set_mass_damping(alpha)

    def run(self, u, v, a, n_steps: int, t0: float) -> float:
        """Steps n_steps from pseudo time t0; u, v, a: (3 n_owned,) relax's, written after the steps."""
        lu, lv, la = self.local
        end = self.kernel.run(lu, lv, la, n_steps, t0)
        n = 3 * self.n_owned
        u[:], v[:], a[:] = lu[:n], lv[:n], la[:n]
        return end

    def reactions(self) -> np.ndarray:
        return self.kernel.reactions()

    @property
    def u(self) -> np.ndarray:
        """(3 n_local,) the kernel's displacement, ghosts included (valid after every step)."""
        return self.local[0]


# --- the stage --------------------------------------------------------------------------------------

@dataclass
class RankStage:
    """The stage's end on this rank and what run.json's "static" says of it (rank 0's summary).

    Attributes:
        counted, halo: the element-loop components (the rank's counted and halo cells, in the
            region order of pyfem.distributed_model.RankRegions), rebased: the dynamic run's.
        contact: the kernel's ContactPairs of the rank's pairs, rebased (None: none here).
        u_total, u_support, u_first: (3 n_local,) u1 + u2, u2 and u1 in the kernel's numbering (m).
        installed_regions: the regions cast in stage 2.
        report: static/static.json's content (every rank; its "monitors" added by the run).
        cell_averages: per stage, the counted cells' NonlinearRegions.cell_averages at its end.
        hand_over_force: (3 n_local,) a linear stage's out-of-balance on the nodes this rank steps,
            the dynamic run's constant force (None: a relaxed stage's is not applied).
        pair_forces: (p, 3) a linear stage's F0 of the rank's pairs (None: the relaxed stage's pairs).
    """

    counted: list
    halo: list
    contact: object
    u_total: np.ndarray
    u_support: np.ndarray
    installed_regions: list
    report: dict = field(default_factory=dict)
    cell_averages: list = field(default_factory=list)
    hand_over_force: np.ndarray | None = None
    pair_forces: np.ndarray | None = None
    u_first: np.ndarray | None = None
    support_groups: list | None = None   # rank 0: the whole groups installed in the stage, as it leaves them
    bounds: tuple | None = None          # the whole mesh's box (the support plot's section)


def _stage_stepper(part, matrix: tuple, mass: np.ndarray, constraints, load: np.ndarray, counted: list,
                   halo: list, contact, ramp: float) -> RankSpace:
    """A relaxation stage's kernel Stepper of this rank's part (pyfem.static.stage_kernel: the stage's
    matrix, the scaled mass, dt = 1 and no damping yet, the held faces, the ramped load on the nodes
    it steps, the counted and halo cells, the pairs), partitioned."""
    from pyfem.static import stage_kernel

    kernel = stage_kernel(matrix, mass, constraints, load, counted, contact, ramp, halo)
    exchange = part.plan.kernel_exchange(part.comm, part.n_local)
    kernel.set_partition(part.n_owned, exchange)
    return RankSpace(part.comm, kernel, exchange, part.n_owned, part.n_local)


def check_held_on_ranks(part, boundary: dict, constraints, active: np.ndarray) -> None:
    """pyfem.static.check_held on the ranks (the whole model's refusal of a stage boundary that lets
    the body move as a rigid body): each rank's free basis of the nodes it steps (held faces, its
    bonded pairs, nodes of no stage-1 cell held), the Gram matrix summed over the ranks, the modes
    about the whole model's centroid."""
    from pyfem.static import check_held, free_basis

    comm, n = part.comm, part.n_owned
    held_nodes = np.zeros(0, dtype=np.int64) if constraints is None else np.asarray(constraints.nodes, np.int64)
    projection = np.zeros((0, 3, 3)) if constraints is None else constraints.projection
    pairs = None if part.pairs is None or not len(part.pairs.nodes) else np.asarray(part.pairs.nodes, np.int64)
    inactive = np.flatnonzero(~active)
    coords = part.coords[:n]
    centre = comm.allreduce(coords.sum(axis=0)) / comm.allreduce(n)
    check_held(free_basis(n, held_nodes, projection, pairs, inactive), coords, inactive, boundary, comm, centre)


def relax_on_ranks(part, matrix: tuple, mass: np.ndarray, constraints, load: np.ndarray, counted: list, halo: list,
                   contact, ramp: float, tolerance: float, max_steps: int, floor: float, name: str) -> tuple:
    """One sub-stage of dynamic relaxation on the ranks: this rank's stage stepper (`_stage_stepper`)
    relaxed from rest under `load` with `relax`'s arithmetic (rank 0 prints its progress line as
    stage `name`), then its element-loop components and pairs rebased to the end state. A collective.
    Returns (stepper, u of the owned dofs, relax's result)."""
    from pyfem.relaxation import relax

    root = part.comm.rank == 0
    stepper = _stage_stepper(part, matrix, mass, constraints, load, counted, halo, contact, ramp)

    def report(steps, ratio, seconds):
        if root:
            print(f"static stage '{name}': {steps} relaxation steps (load ramp {ramp:.0f}), out-of-balance "
                  f"{ratio:.2e} (tolerance {tolerance:g}), {seconds:.0f} s", flush=True)

    u_owned, result = relax(stepper, mass, load, tolerance, max_steps, ramp=ramp, floor=floor, report=report,
                            space=stepper)
    for component in counted + halo:
        component.rebase()
    if contact is not None:
        contact.rebase(stepper.u)
    return stepper, u_owned, result


def _largest_displacement(comm: MPI.Comm, u_owned: np.ndarray, coords: np.ndarray) -> tuple:
    """(the largest nodal displacement over the ranks (m), its node's position, its vector)."""
    nodal = u_owned.reshape(-1, 3)
    magnitude = np.linalg.norm(nodal, axis=1)
    worst = int(np.argmax(magnitude)) if len(magnitude) else -1
    offer = ((float(magnitude[worst]), coords[worst].tolist(), nodal[worst].tolist()) if worst >= 0
             else (-1.0, [], []))
    return max(comm.allgather(offer), key=lambda item: item[0])


def solve(part, loop, contact_arrays: dict | None) -> RankStage:
    """Runs the two stages of docs/static.md by dynamic relaxation on the ranks (module docstring).

    Args:
        part: pyfem.distributed_model.RankModel of the scene.
        loop: the rank's element loop (pyfem.distributed_model.RankRegions) or None.
        contact_arrays: `pyfem.effects.contact_arguments` of the rank's pairs or None.
    """
    from pyfem.elements import plastic_frequency_factor, scene_laws
    from pyfem.relaxation import probe_frequency, ramp_length
    from pyfem.effects import make_contact_pairs
    from pyfem.static import (_install_cells, _pair_force_vector, _stage_constraints, face_support_resultants,
                              stage_boundary, stage_loads, stage_pair_arrays, stage_tolerance, unconverged_warning)
    start = time.perf_counter()
    scene, comm, model = part.scene, part.comm, part.model
    root = comm.rank == 0
    settings = scene["static"]
    tolerance, max_steps = stage_tolerance(scene), int(settings["max_steps"])
    boundary = stage_boundary(scene, model)
    installed_regions, installed_cells = _install_cells(scene, model)
    loads = stage_loads(scene, model, installed_cells)
    f_exc = owned_force(part, kernel_nodal(part, loads.excavation))
    weight = owned_force(part, kernel_nodal(part, loads.installed_weight))
    traction = owned_force(part, kernel_nodal(part, loads.in_situ_traction))
    _, _, constraints = _stage_constraints(model, boundary)

    # The matrices: every cell (the scaled mass), all but the installed ones (the probe's), the stages'.
    from pyfem.distributed_parts import element_loop_cells

    loop_cells = element_loop_cells(scene, model)
    element_cells = (np.concatenate([cells for cells, _ in loop_cells.values()]) if loop_cells
                     else np.zeros(0, dtype=np.int32))
    laws, _ = scene_laws(scene)
    factor = max([plastic_frequency_factor(p["poisson_ratio"], p["friction_angle"], p["dilation_angle"])
                  for p in laws.values() if p["law"] == "mohr_coulomb"], default=1.0)
    everything = stage_matrix(part, np.zeros(0, dtype=np.int32))
    # Rock bolts and cables of static.support join in the support stage (pyfem/distributed_support.py);
    # the mass bounds their condensed stiffness too (as the whole model's stage).
    bolts = [rank_group for rank_group in part.support if rank_group.stage == "static"]
    if bolts:
        from pyfem.distributed_support import add_rows, bound_rows

        mass = scaled_mass(part, add_rows(everything, part.n_owned, bound_rows(bolts, part.n_owned, part.n_local)),
                           factor)
    else:
        mass = scaled_mass(part, everything, factor)
    installs = comm.allreduce(len(installed_cells)) > 0  # (a rank may hold none of the installed cells)
    elastic = stage_matrix(part, installed_cells) if installs else everything
    del everything
    K_support = stage_matrix(part, element_cells, hourglass_but=())
    K_excavation = (stage_matrix(part, np.union1d(element_cells, installed_cells), hourglass_but=installed_regions)
                    if installs else K_support)
    # A node of no active cell in stage 1 (only the installed regions use it) does not count as free.
    active = np.zeros(part.n_owned, dtype=bool)
    indptr = elastic[0]
    active[np.repeat(np.arange(part.n_owned), np.diff(indptr[:part.n_owned + 1]))] = True
    check_held_on_ranks(part, boundary, constraints, active)

    # Components: the rock's from the in-situ stress now, the installed regions' stress-free in stage 2.
    counted_names = [] if loop is None else list(loop.counted.arrays)
    halo_names = [] if loop is None or loop.halo is None else list(loop.halo.arrays)
    counted = {name: None for name in counted_names}
    halo = {name: None for name in halo_names}
    for names, table, regions in ((counted_names, counted, None if loop is None else loop.counted),
                                  (halo_names, halo, None if loop is None else loop.halo)):
        for name in names:
            if name not in installed_regions:
                table[name] = regions.new_component(name)
    has_pairs = contact_arrays is not None and len(contact_arrays["pairs"])
    stage_pairs = stage_pair_arrays(scene, contact_arrays)  # no deterioration; welded with split "after_static"
    contact = make_contact_pairs(stage_pairs) if has_pairs else None
    if has_pairs:  # F0 on node i and -F0 on j in the load (as the whole model's stage)
        f_exc = f_exc + _pair_force_vector(part.n_local, contact_arrays)
    owned = slice(0, 3 * part.n_owned)

    def global_norm(x):
        return math.sqrt(comm.allreduce(float(x[owned] @ x[owned])))

    floor = 1.0e-3 * global_norm(traction)
    ramp, probe_steps = 0.0, 0
    path_dependent = comm.allreduce(bool(loop is not None or has_pairs or bolts), op=MPI.LOR)
    probe_load = f_exc + weight
    if path_dependent and comm.allreduce(bool(np.any(probe_load)), op=MPI.LOR):
        probe_contact = make_contact_pairs(stage_pairs) if has_pairs else None
        probe = _stage_stepper(part, elastic, mass, constraints, probe_load, [], [], probe_contact, 0.0)
        omega, probe_steps = probe_frequency(probe, mass, probe_load, max_steps, floor=floor, space=probe)
        ramp = ramp_length(omega)
    del elastic
    relaxation = settings["relaxation"]
    weight_words = " + weight of the installed regions" if comm.allreduce(bool(np.any(weight)), op=MPI.LOR) else ""
    stages, reactions, increments, averages = [], [], [], []
    carried = np.zeros(3 * part.n_local)
    regions_summary_first = None
    all_regions = list(model.regions)  # (the scene's order, as the serial stage lists them)
    rock_regions = [name for name in all_regions if name not in installed_regions]
    from pyfem.distributed_parts import region_summary

    for index, (name, matrix, regions, fraction, words) in enumerate((
            ("excavation", K_excavation, rock_regions, relaxation,
             f"{relaxation:g} f_exc (released before {', '.join(installed_regions) or 'any support'})"),
            ("support", K_support, all_regions, 1.0 - relaxation, f"{1.0 - relaxation:g} f_exc{weight_words}"))):
        stage_start = time.perf_counter()
        if index == 1:
            for names, table, regions_of in ((counted_names, counted, None if loop is None else loop.counted),
                                             (halo_names, halo, None if loop is None else loop.halo)):
                for region in names:
                    if table[region] is None:
                        table[region] = regions_of.new_component(region, initial_stress=None)
        load = fraction * f_exc + carried + (weight if index == 1 else 0.0)
        active_counted = [c for c in counted.values() if c is not None]
        active_halo = [c for c in halo.values() if c is not None]
        if index == 1:  # the bolts installed in the stage, after the element loop's components
            for rank_group in bolts:
                rank_group.fresh()
                active_counted += [bolts.component for bolts in rank_group.parts if bolts.kind == "counted"]
                active_halo += [bolts.component for bolts in rank_group.parts if bolts.kind == "halo"]
        # (the bolts' components rebased too: the run's zero of their energy)
        stepper, u_owned, result = relax_on_ranks(part, matrix, mass, constraints, load, active_counted, active_halo,
                                                  contact, ramp, tolerance, max_steps, floor, name)
        carried = np.zeros(3 * part.n_local)
        carried[owned] = result.out_of_balance
        support = np.zeros((part.n_local, 3))
        if constraints is not None:
            support[constraints.nodes] = stepper.reactions()
        reactions.append(support)
        increments.append(stepper.u.copy())
        averages.append({} if loop is None else
                        loop.counted.cell_averages([counted[region] for region in counted_names]))
        largest, point, _ = _largest_displacement(comm, u_owned, part.coords[:part.n_owned])
        if loop is not None:  # the counted cells' summary (region_summary: rank 0's)
            stage_regions = region_summary(comm, loop.counted, [counted[name] for name in counted_names])
        else:
            stage_regions = {}
        solver_words = "dynamic relaxation" + (f" on {comm.size} MPI ranks (distributed model)" if comm.size > 1
                                               else " (distributed model)")
        stage_seconds = comm.allreduce(time.perf_counter() - stage_start, op=MPI.MAX)
        if root:
            print(f"static stage '{name}': {'converged' if result.converged else 'NOT converged'} after "
                  f"{result.steps} relaxation steps, out-of-balance {result.residual:.2e} (tolerance {tolerance:g}), "
                  f"{stage_seconds:.0f} s ({solver_words})", flush=True)
        free = 3 * comm.allreduce(int(np.count_nonzero(active)) if index == 0 else part.n_owned)
        stages.append({"name": name, "active_regions": regions, "load": words, "load_fraction": fraction,
                       "free_dofs": free, "solver": solver_words if comm.allreduce(bool(np.any(load)), op=MPI.LOR)
                       else "none: no load", "iterations": result.steps, "residual": result.residual,
                       "converged": result.converged, "seconds": stage_seconds, "max_displacement": largest,
                       "max_displacement_point": point,
                       "residual_history": [[step, ratio] for step, ratio, _ in result.history],
                       "regions": stage_regions})
        if index == 0:
            regions_summary_first = stage_regions
        if not result.converged:
            scene.warn(unconverged_warning(name, tolerance, max_steps, result, ramp))
    u1, u2 = increments
    applied = f_exc + weight
    load_norm = max(global_norm(applied), floor)
    out_of_balance = global_norm(carried) / load_norm if load_norm > 0.0 else 0.0
    support = reactions[0] + reactions[1]
    mine = face_support_resultants(model.faces, boundary, support)  # (a rank without held face nodes: {})
    face_support = {face.name: comm.allreduce(np.asarray(mine.get(face.name, np.zeros(3)))).tolist()
                    for face in model.faces if boundary[face.name] in ("roller", "fixed")}
    largest, point, vector = _largest_displacement(comm, (u1 + u2)[owned], part.coords[:part.n_owned])
    report = {"settings": dict(settings, tolerance=tolerance, load_ramp_steps=ramp, probe_steps=probe_steps,
                               ranks=comm.size, model="distributed"),
              "initial_stress": scene.get("initial_stress"), "excavated": list(settings["excavate"]),
              "installed": list(installed_regions), "boundary": boundary, "stages": stages,
              "seconds": comm.allreduce(time.perf_counter() - start, op=MPI.MAX),
              "max_displacement": {"value": largest, "point": point, "vector": vector}, "out_of_balance": out_of_balance,
              "hand_over": "the dynamic run starts from u = v = 0 with the stage's stress; the in-situ traction, "
                           "body force, support forces and pair forces of the stage are held constant; the "
                           "out-of-balance above (a relaxed stage's error) is not applied",
              "load_ramp_steps": ramp, "support_forces": face_support,
              "in_situ_tractions": {face.name: comm.allreduce(traction.reshape(-1, 3)[face.nodes].sum(axis=0)).tolist()
                                    for face in model.faces},
              **({"regions": stages[-1]["regions"], "regions_first_stage": regions_summary_first}
                 if loop_cells else {})}
    if contact_arrays is not None:
        report["pairs"] = pair_report(comm, contact, contact_arrays)
    support_groups = None
    if bolts:  # the bolts as the stage leaves them, on rank 0 (static/support.csv, run.json "static")
        from pyfem.distributed_support import gather_groups
        from pyfem.support import group_summary

        support_groups = gather_groups(comm, bolts)
        if root:
            report["support"] = {group.name: group_summary(group) for group in support_groups}
    return RankStage(support_groups=support_groups, bounds=model.bounds if bolts else None,
                     counted=[counted[name] for name in counted_names], halo=[halo[name] for name in halo_names],
                     contact=contact, u_total=u1 + u2, u_support=u2, u_first=u1,
                     installed_regions=list(installed_regions),
                     report=report, cell_averages=averages)


def pair_report(comm: MPI.Comm, contact, contact_arrays: dict) -> dict:
    """static.json's "pairs" (pyfem.static_output.static_report's) over every rank's pairs: their
    count, the normal stress range (compression positive, Pa), the largest shear stress, how many
    are in tension, their states at the hand-over and the largest open gap (m)."""
    if contact is None:
        force, state, gap = np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros(0)
    else:
        force, state, gap = contact.static_force(), np.asarray(contact.state()), contact.gap_offset()
    from pyfem.static import normal_and_shear

    area = np.asarray(contact_arrays["area"], dtype=float)
    N, T = normal_and_shear(force, contact_arrays["normal"])
    counts = comm.allreduce(np.bincount(state, minlength=4)[:4].astype(np.int64))
    return {"count": comm.allreduce(len(N)),
            "normal_stress_min": comm.allreduce(float(np.min(N / area, initial=np.inf)), op=MPI.MIN),
            "normal_stress_max": comm.allreduce(float(np.max(N / area, initial=-np.inf)), op=MPI.MAX),
            "shear_stress_max": comm.allreduce(float(np.max(T / area, initial=-np.inf)), op=MPI.MAX),
            "in_tension": comm.allreduce(int(np.count_nonzero(N < 0.0))),
            "states": dict(zip(("bonded", "stick", "sliding", "separated"), (int(c) for c in counts))),
            "largest_open_gap": comm.allreduce(float(np.max(gap, initial=0.0)), op=MPI.MAX)}


def brief(report: dict) -> dict:
    """run.json's "static" (pyfem.static.StaticState.summary's keys) from static.json's report."""
    from pyfem.static import SUMMARY_KEYS

    return {"stages": [{key: stage[key] for key in SUMMARY_KEYS} for stage in report["stages"]],
            "max_displacement": report["max_displacement"]["value"], "out_of_balance": report["out_of_balance"],
            "seconds": report["seconds"],
            "outputs": "static/static.json, static/fields.xdmf" + (", static/support.csv" if "support" in report else ""),
            **({"steps": report["steps"]} if "steps" in report else {}),
            **({"support": report["support"]} if "support" in report else {})}


def write_support(folder, stage: RankStage, scene) -> None:
    """static/support.csv, static/support.png and static/support.xdmf (+ .h5): the bolts installed in
    the stage as it leaves them (rank 0; pyfem/static_output.py writes the same for the whole model)."""
    from types import SimpleNamespace

    from pyfem.support import segment_rows, write_csv
    from pyfem.support_output import bolt_state, write_outputs

    groups = stage.support_groups
    states = [bolt_state(group, peak=False) for group in groups]
    drawn = write_outputs(folder, states, scene, SimpleNamespace(node_coords=np.array(stage.bounds)), 0.0,
                          "support.png", "after the static stage")
    if drawn:
        stage.report.setdefault("plots", {})["support"] = drawn
    write_csv(folder / "support.csv", [row for group in groups for row in segment_rows(group.bolts, group.name)],
              peak=False)


def monitor_report(stage: "RankStage", monitors, names: list, comm: MPI.Comm) -> dict:
    """static.json's "monitors" (rank 0's; {} elsewhere): each monitor's displacement after stage 1
    and at the end, and its static stress and region, from the rank that reports it."""
    from pyfem.static_output import VOIGT_NAMES

    mine = []
    for k, j in enumerate(monitors.index):
        nodes, weights = monitors.nodes[k], monitors.weights[k]
        first = weights @ stage.u_first.reshape(-1, 3)[nodes]
        total = weights @ stage.u_total.reshape(-1, 3)[nodes]
        entry = {"displacement_stage_1": first.tolist(), "displacement": total.tolist()}
        if monitors.stress is not None:
            sigma = monitors.stress.static[k]
            entry["stress"] = {key: float(sigma[a, b]) for key, (a, b) in VOIGT_NAMES.items()}
            entry["region"] = monitors.stress.regions[k]
        mine.append((int(j), entry))
    gathered = comm.gather(mine, root=0)
    if comm.rank != 0:
        return {}
    by_index = dict(item for rank_items in gathered for item in rank_items)
    return {name: by_index[j] for j, name in enumerate(names)}


def hand_over(stage: RankStage, part, loop, monitors, contact_arrays: dict | None) -> None:
    """The stage's end becomes the dynamic run's start (pyfem.static.hand_over on the ranks): the
    element loop's components and the pairs go on, the monitors' static stress is the stage's."""
    from pyfem.static import monitor_static_stress, welded

    if loop is not None:
        loop.counted.components = list(stage.counted)
        for name, component in zip(loop.counted.arrays, stage.counted):
            loop.counted.initial_stress[name] = component.stress()
        if loop.halo is not None:
            loop.halo.components = list(stage.halo)
            for name, component in zip(loop.halo.arrays, stage.halo):
                loop.halo.initial_stress[name] = component.stress()
    if contact_arrays is not None and stage.pair_forces is not None:  # a linear stage's F0 (pairs new, bonded)
        from pyfem.static import warn_pairs_over_strength

        contact_arrays["static_force"] = np.ascontiguousarray(stage.pair_forces, dtype=np.float64)
        warn_pairs_over_strength(part.scene, contact_arrays, part.comm)
    if contact_arrays is not None and stage.contact is not None:
        contact_arrays["static_force"] = np.ascontiguousarray(stage.contact.static_force())
        if welded(part.scene):  # split after the stage: new bonded pairs with the real strengths and F0
            stage.contact = None
        elif contact_arrays["deterioration"] is not None:  # the wear's clock starts with the record
            stage.contact.set_deterioration(*contact_arrays["deterioration"])
        if stage.contact is not None and contact_arrays.get("release_time") is not None:
            stage.contact.set_release_time(contact_arrays["release_time"])
    if contact_arrays is not None and stage.pair_forces is None and welded(part.scene):
        from pyfem.static import warn_pairs_over_strength

        # The welded relaxed stage's F0 beyond the pairs' strength, as the whole model's hand_over warned
        # (every rank: a collective; a rank may hold no pair, or no stage pairs)
        warn_pairs_over_strength(part.scene, contact_arrays, part.comm)
    stress = monitors.stress
    if stress is not None and len(monitors.index):
        stress.static = monitor_static_stress(stress, stage.installed_regions, stage.u_total, stage.u_support,
                                              None if loop is None else loop.counted.components)


def cell_static_stress(stage: RankStage, part, strain, first: bool = False) -> np.ndarray:
    """(c, 3, 3) the stage's stress at the centroids of the rank's local cells (`strain`:
    pyfem.output.cell_strain_operator of its part, dolfinx's numbering, its `static` the in-situ
    stress), as the whole model's hand_over gives the fields: sigma0 + C : eps(u1 + u2) in the rock,
    C : eps(u2) in the installed cells (the element loop's cells are the laws' stress, written by
    the fields themselves); `first`: after stage 1, sigma0 + C : eps(u1) in the rock, 0 in the
    installed cells."""
    from pyfem.elements import region_cells
    from pyfem.static import static_stress

    installed = np.zeros(len(strain.nodes), dtype=bool)
    for name in stage.installed_regions:
        installed[region_cells(part.model, name)] = True
    sigma0 = strain.static.copy()

    def elastic(u):
        return strain.stress(strain.strain(part.dolfinx_order(u))) - sigma0

    if first:
        stress = elastic(stage.u_first) + sigma0
        stress[installed] = 0.0
        return stress
    final = static_stress(elastic, installed, stage.u_total, stage.u_support)
    final[~installed] += sigma0[~installed]
    return final


def write_fields(path, stage: RankStage, part) -> np.ndarray:
    """static/fields.xdmf by dolfinx on every rank (a collective), the whole model's fields of the
    stage (pyfem.static_output.write_static_fields) in the distributed model's layout: at t = 1 and
    t = 2 (the end of each stage) the displacement since the start and the stage's own (point data),
    the stress (3 x 3 cell data: the laws' cell means in the element loop, as the run's fields), the
    cells active in the stage, plastic strain, damage and damage type. Returns the stage's final cell
    stress (`cell_static_stress`), the static part of the run's fields."""
    from dolfinx import fem, io

    from pyfem.elements import region_cells, voigt_tensor
    from pyfem.output import cell_strain_operator

    model = part.model
    mesh, V = model.mesh, model.V
    n_cells = model.n_cells
    strain = cell_strain_operator(part.scene, model)
    nodes = None
    if model.order > 1:  # every node of a second-order model in the file (pyfem.quadratic_fields)
        from pyfem.quadratic_fields import NodeMesh

        nodes = NodeMesh(model)
        mesh = nodes.mesh
    T = fem.TensorFunctionSpace(mesh, ("DG", 0)) if nodes is None else nodes.T
    Q = fem.FunctionSpace(mesh, ("DG", 0)) if nodes is None else nodes.Q
    tensor_dofs = T.dofmap.list.array.reshape(-1, 1)[:n_cells, 0] if nodes is None else nodes.tensor_dofs
    scalar_dofs = Q.dofmap.list.array.reshape(-1, 1)[:n_cells, 0] if nodes is None else nodes.scalar_dofs
    installed = np.zeros(len(strain.nodes), dtype=bool)
    for name in stage.installed_regions:
        installed[region_cells(model, name)] = True
    u1 = stage.u_first
    final = cell_static_stress(stage, part, strain)
    stages = ((1.0, u1, u1, cell_static_stress(stage, part, strain, first=True), (~installed).astype(float)),
              (2.0, stage.u_total, stage.u_support, final, np.ones(len(installed))))
    with io.XDMFFile(part.comm, str(path), "w") as file:
        file.write_mesh(mesh)
        for (t, total, increment, stress, active), averages in zip(stages, stage.cell_averages):
            for name, values in (("displacement", total), ("stage_displacement", increment)):
                if nodes is None:
                    function = fem.Function(V, name=name)
                    function.x.array[:] = part.dolfinx_order(values)
                else:
                    function = nodes.vector(name)
                    nodes.set_nodal(function, part.dolfinx_order(values))
                file.write_function(function, t)
            cells = {"stress": stress[:n_cells].copy(), "active": active[:n_cells]}
            for key in ("plastic_strain", "damage", "damage_type"):
                cells[key] = np.zeros(n_cells)
            for region in averages.values():
                cells["stress"][region["cells"]] = voigt_tensor(region["stress"])
                for key in ("plastic_strain", "damage", "damage_type"):
                    cells[key][region["cells"]] = region[key]
            for name, values in cells.items():
                tensor = values.ndim == 3
                function = fem.Function(T if tensor else Q, name=name)
                if tensor:
                    function.x.array.reshape(-1, 9)[tensor_dofs] = values.reshape(-1, 9)
                else:
                    function.x.array[scalar_dofs] = values
                function.x.scatter_forward()
                file.write_function(function, t)
    return final

"""Benchmark: time per step of the C++ kernel against a petsc4py loop and against memory bandwidth.

All numbers come from one run on one machine, so they are comparable as ratios:
- the same assembled stiffness (dolfinx, Q1 box) stepped by the kernel (1 and 2 threads)
  and by a petsc4py loop doing the same velocity-Verlet update with MatMult (BAIJ, bs 3)
  and vector operations;
- a STREAM-like triad measured in the same run gives the bandwidth bound: the bytes the
  kernel's format must move per step divided by the triad bandwidth.

Usage:
    /usr/bin/python3 -m pyfem bench [--sizes 30000 200000 700000] [--steps 50] [--out bench.json]
"""
from __future__ import annotations

import argparse
import json
import math
import platform
import time

import numpy as np


def _box_scene(target_dofs: int):
    """A homogeneous Q1 box scene with about target_dofs degrees of freedom."""
    from pyfem.scene import parse_scene

    n = max(2, round((target_dofs / 3.0) ** (1.0 / 3.0)) - 1)  # elements per side
    return parse_scene({
        "title": f"bench {target_dofs}",
        "mesh": {"builder": "box", "size": [float(n), float(n), float(n)], "h": 1.0, "order": 1},
        "materials": {"rock": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0}},
        "time": {"duration": 1.0},
        "boundary": {"type": "free"},
        "output": {"xdmf_interval": 0.0},
    })


def upper_triangle_blocks(stiffness) -> int:
    """Blocks the kernel's symmetric storage keeps: the diagonal and those above it."""
    n_block_rows = stiffness.shape[0] // 3
    rows = np.repeat(np.arange(n_block_rows), np.diff(stiffness.indptr))
    return int(np.count_nonzero(stiffness.indices > rows)) + n_block_rows


def choose_time_step(scene, stiffness, mass: np.ndarray, beta: float,
                     coords: np.ndarray):
    """Stable step of central differences for M^-1 K, with stiffness-proportional damping.

    omega_max^2 is bounded above by Gershgorin row sums of M^-1 K (guaranteed); power
    iteration sharpens it (an estimate from below, so it is raised by 5 % before use and
    never exceeds the bound). With damping ratio xi = beta omega/2 at omega_max the limit is
    dt_crit = (2/omega)(sqrt(1 + xi^2) - xi). Mass-proportional damping and dashpots are
    implicit and do not restrict the step. The power iteration starts from a function of the node
    coordinates (`coords`, (n, 3) m; pyfem.distributed_parts.power_iteration), as the distributed
    model's does: the same estimate for any numbering and rank count.
    """
    from pyfem import _kernels
    from pyfem.clock import POWER_ITERATIONS, time_step_from
    from pyfem.distributed_parts import power_iteration
    from pyfem.effects import bsr_arrays

    indptr, indices, blocks = bsr_arrays(stiffness)
    omega2_bound = _kernels.gershgorin_bound(indptr, indices, blocks, mass)
    omega2_power = None
    if scene["time"].get("power_iteration", True):
        omega2_power = power_iteration((indptr, indices, blocks), mass, np.asarray(coords, dtype=np.float64),
                                       len(mass), POWER_ITERATIONS)
    return time_step_from(scene, omega2_bound, omega2_power, beta)


def stream_triad_bandwidth(n: int = 20_000_000, repeats: int = 5, threads: int = 1) -> float:
    """Best bandwidth (bytes/s) of a[i] = b[i] + s c[i] over `repeats` (24 bytes per element)."""
    from pyfem import _kernels

    a = np.zeros(n)
    b = np.ones(n)
    c = np.full(n, 2.0)
    _kernels.set_num_threads(threads)
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        _kernels.stream_triad(a, b, c, 3.0)
        best = min(best, time.perf_counter() - start)
    return 24.0 * n / best


def kernel_seconds_per_step(stiffness, mass, dt: float, steps: int, threads: int,
                            symmetric_storage: bool = True, single: bool = False) -> float:
    """Best of three: seconds per step of the C++ stepper on the given matrix.

    Args:
        symmetric_storage: True: the stepper's upper-triangle copy of K (default of runs);
            False: the full block-CSR product fused into the update.
        single: the upper triangle's blocks as float32 (`time.matrix_precision = "single"`).
    """
    from pyfem import _kernels
    from pyfem.effects import bsr_arrays

    _kernels.set_num_threads(threads)
    indptr, indices, blocks = bsr_arrays(stiffness)
    stepper = _kernels.Stepper(indptr, indices, blocks, mass, dt, 0.0, 0.0, symmetric_storage, single)
    return stepper_seconds_per_step(stepper, stiffness.shape[0], steps)


def petsc_seconds_per_step(stiffness, mass, dt: float, steps: int, matrix_type: str = "baij"
                           ) -> tuple[float, np.ndarray]:
    """Best of three: seconds per step of the same undamped velocity-Verlet loop in petsc4py.

    Args:
        matrix_type: "baij" (3x3 blocks, PETSc's fastest format for this matrix) or "aij"
            (scalar CSR, the format dolfinx assembles into).

    Returns:
        (seconds per step, final displacement) -- the displacement checks that both loops
        computed the same thing.
    """
    from petsc4py import PETSc

    n = stiffness.shape[0]
    if matrix_type == "baij":
        matrix = PETSc.Mat().createBAIJ(size=(n, n), bsize=3,
                                        csr=(stiffness.indptr.astype(PETSc.IntType),
                                             stiffness.indices.astype(PETSc.IntType),
                                             stiffness.data.reshape(-1)), comm=PETSc.COMM_SELF)
    else:
        csr = stiffness.tocsr()
        matrix = PETSc.Mat().createAIJ(size=(n, n), csr=(csr.indptr.astype(PETSc.IntType),
                                                          csr.indices.astype(PETSc.IntType), csr.data),
                                       comm=PETSc.COMM_SELF)
    matrix.assemble()
    inverse_mass = PETSc.Vec().createWithArray(np.repeat(1.0 / mass, 3), comm=PETSc.COMM_SELF)
    rng = np.random.default_rng(0)
    u0 = 1e-6 * rng.standard_normal(n)
    best = math.inf
    for _ in range(3):
        u = PETSc.Vec().createWithArray(u0.copy(), comm=PETSc.COMM_SELF)
        v = u.duplicate()
        a = u.duplicate()
        f = u.duplicate()
        v.set(0.0)
        a.set(0.0)
        start = time.perf_counter()
        for _ in range(steps):
            v.axpy(0.5 * dt, a)           # v_half
            u.axpy(dt, v)                 # u_{n+1}
            matrix.mult(u, f)             # K u
            a.pointwiseMult(f, inverse_mass)
            a.scale(-1.0)                 # a = -M^-1 K u
            v.axpy(0.5 * dt, a)           # v_{n+1}
        best = min(best, (time.perf_counter() - start) / steps)
    return best, u.getArray().copy()


def bytes_moved_per_step(stiffness, symmetric_storage: bool = True, single: bool = False) -> int:
    """Bytes the kernel must move per step: its matrix once and the vectors of both passes.

    pass A reads v, a, u and writes v, u (5 vectors); pass B reads u, v, f, mass/3 and writes
    v, a (about 6 vectors): 11 vectors of 8 bytes per dof. The upper-triangle format stores
    the diagonal and the blocks above it (72 + 4 bytes each; 36 + 4 as float32 blocks) and adds
    the K u buffer (written, then read: 2 vectors).
    """

    if not symmetric_storage:
        return int(stiffness.data.nbytes + stiffness.indices.nbytes + stiffness.indptr.nbytes
                   + 11 * 8 * stiffness.shape[0])
    return int(upper_triangle_blocks(stiffness) * ((36 if single else 72) + 4) + 8 * (stiffness.shape[0] // 3 + 1)
               + 13 * 8 * stiffness.shape[0])


def stepper_seconds_per_step(stepper, n: int, steps: int, amplitude: float = 1.0e-6) -> float:
    """Best of three: seconds per step of a built stepper from a random displacement of the given
    amplitude (m; small enough that a material law stays elastic), after two warm-up steps (first
    touch of the scratch arrays)."""
    rng = np.random.default_rng(0)
    u, v, a = amplitude * rng.standard_normal(n), np.zeros(n), np.zeros(n)
    stepper.run(u, v, a, 2, 0.0)
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        stepper.run(u, v, a, steps, 0.0)
        best = min(best, (time.perf_counter() - start) / steps)
    return best


def element_loop_rows(target_dofs: int, steps: int, threads: int = 2) -> list[dict]:
    """"Simulate only what a scene calls for", measured in one run on one Q1 box:
    - the stepper the model builds (`pyfem.distributed_model.model_in_memory(...).stepper()`, as a
      run steps it) for a scene without nonlinear tables against a bare kernel Stepper on the same
      matrix (ratio 1: the run is the matrix path, nothing else);
    - the whole box in the element loop with the linear elastic law, Mohr-Coulomb at rest
      (screened elastic: Table 1 sandstone under a small strain), Mohr-Coulomb on its yield surface
      (`yield_surface_seconds`: the case study's yielded zone) and concrete at rest, per step and
      per quadrature point (ns), against the matrix product.
    """
    from pyfem import _kernels
    from pyfem.distributed_model import model_in_memory
    from pyfem.elements import nonlinear_component
    from pyfem.effects import bsr_arrays

    _kernels.set_num_threads(threads)
    scene = _box_scene(target_dofs)
    built = model_in_memory(scene, solve_stage=False)
    _kernels.set_num_threads(threads)
    n = 3 * built.part.n_local
    dt = built.time_step.dt
    mass = built.part.mass
    indptr, indices, blocks = built.part.matrix
    bare = stepper_seconds_per_step(_kernels.Stepper(indptr, indices, blocks, mass, dt, 0.0, 0.0), n, steps,
                                    amplitude=1.0e-9)
    stepper, _ = built.stepper()
    _kernels.set_num_threads(threads)
    scene_path = stepper_seconds_per_step(stepper, n, steps, amplitude=1.0e-9)
    rows = [{"case": "scene without nonlinear tables (the model's stepper) vs bare Stepper", "dofs": n,
             "threads": threads, "ms": 1e3 * scene_path, "reference_ms": 1e3 * bare,
             "ratio": scene_path / bare, "ns_per_point": None}]
    laws = {
        "linear_elastic": None,
        "mohr_coulomb": {"law": "mohr_coulomb", "young_modulus": 8.0e9, "poisson_ratio": 0.24, "cohesion": 1.1e6,
                         "friction_angle": 42.0, "tensile_strength": 1.95e6},
        "concrete_damage": {"law": "concrete_damage", "young_modulus": 8.0e9, "poisson_ratio": 0.24,
                            "cohesion": 1.8e6, "friction_angle": 46.0, "tensile_strength": 1.27e6},
    }
    model = built.part.model  # (one rank: the kernel's numbering is the function space's)
    for name, parameters in laws.items():
        regions = nonlinear_component(model, ["rock"], None if parameters is None else {"rock": parameters})
        indptr, indices, blocks = bsr_arrays(regions.stiffness)
        stepper = _kernels.Stepper(indptr, indices, blocks, mass, dt, 0.0, 0.0)
        for component in regions.components:
            stepper.add_internal_force(component)
        seconds = stepper_seconds_per_step(stepper, n, steps, amplitude=1.0e-9)
        rows.append({"case": f"whole box in the element loop, {name}" + ("" if name == "linear_elastic" else " at rest"),
                     "dofs": n, "threads": threads, "ms": 1e3 * seconds, "reference_ms": 1e3 * bare,
                     "ratio": seconds / bare, "ns_per_point": 1e9 * seconds / regions.n_points})
        if name == "mohr_coulomb":
            seconds, returning = yield_surface_seconds(regions.components[0], model.node_coords, steps)
            rows.append({"case": f"whole box in the element loop, mohr_coulomb on its yield surface "
                                 f"({100 * returning:.0f} % of the points return per step)",
                         "dofs": n, "threads": threads, "ms": 1e3 * seconds, "reference_ms": 1e3 * bare,
                         "ratio": seconds / bare, "ns_per_point": 1e9 * seconds / regions.n_points,
                         "returning_share": returning})
    return rows


LAW_STATES = ("at rest", "near the surface", "yielding")
"""The states of `element_law_rows`."""

GEOMETRY_FORMS = {"dense gradients": {"dense": True}, "J^-1 double": {}, "J^-1 float32": {"single_geometry": True}}
"""Geometry forms of `element_law_rows`: the kernel's gradients argument (pyfem.elements.ElementArrays.kernel_gradients)
and options; a form the kernel does not take (an older build) is skipped."""


def loop_bytes_per_point(state_bytes: int, geometry_bytes: int, n_basis: int, points_per_cell: int,
                         initial_stress: bool = True) -> int:
    """Bytes the element loop must move per quadrature point per step (compute + commit), at rest:
    the committed state read and the trial state written (3 state copies: read, write allocate,
    write; the commit swaps pointers), the geometry (`geometry_bytes`: gradients or J^-1, and the
    weight), sigma0 (48), and per cell the element force written and read back by the node gather
    (2 x 24 k), its node numbers (4 k), its slots in the gather (8 k), the displacement's gather
    (24 k, counted once per cell: neighbours' reuse in cache ignored) and its two energies (16)."""
    per_cell = 2 * 24 * n_basis + 4 * n_basis + 8 * n_basis + 24 * n_basis + 16
    return int(3 * state_bytes + geometry_bytes + (48 if initial_stress else 0) + per_cell / points_per_cell)


def element_law_rows(target_dofs: int, steps: int, bandwidth: dict, threads_list=(1, 2)) -> list[dict]:
    """The element loop per law, geometry form and thread count on one Q1 box (docs/scaling.md "The
    element loop per law"): ns per point per step (compute + commit of the component alone, best of
    three batches) with the points at rest, near the surface and yielding, beside the roofline bound
    of the same run, `loop_bytes_per_point` / the triad bandwidth of that thread count
    (`stream_triad_bandwidth`), and the fraction of it reached.

    Every law starts from an isotropic sigma0 of -5 MPa and is driven by the uniform strain
    eps = k (1e-3, 3e-4, -3e-3): at rest k = 0; near the surface k = 0.9 k_y (k_y the first multiple
    of 1/40 at which a point turns inelastic, up to 10, found by a ramp of its own component); yielding
    k = k_y (1.02 + 0.01 j) at step j, so every step loads beyond the surface. Each state also adds
    random increments of 1e-9 m. `returning` is the share of points whose plastic strain or damage
    grew in one more step of the state's driving."""
    from mpi4py import MPI

    from pyfem import _kernels
    from pyfem.elements import nonlinear_component
    from pyfem.operators import build_model

    scene = _box_scene(target_dofs)
    model = build_model(scene, MPI.COMM_SELF)
    coords = model.node_coords
    drive = np.zeros_like(coords)
    drive[:, 0], drive[:, 1], drive[:, 2] = 1.0e-3 * coords[:, 0], 3.0e-4 * coords[:, 1], -3.0e-3 * coords[:, 2]
    drive = drive.ravel()
    laws = {
        "linear_elastic": {"law": "linear_elastic", "lame_lambda": 2.8e9, "shear_modulus": 3.2e9},
        "mohr_coulomb": {"law": "mohr_coulomb", "young_modulus": 8.0e9, "poisson_ratio": 0.24, "cohesion": 1.1e6,
                         "friction_angle": 42.0, "tensile_strength": 1.95e6},
        "concrete_damage": {"law": "concrete_damage", "young_modulus": 8.0e9, "poisson_ratio": 0.24,
                            "cohesion": 1.8e6, "friction_angle": 46.0, "tensile_strength": 1.27e6},
    }
    rng = np.random.default_rng(1)
    rows = []
    for name, parameters in laws.items():
        regions = nonlinear_component(model, ["rock"], {"rock": parameters})
        arrays = regions.arrays["rock"]
        law, law_parameters = regions.laws["rock"]
        sigma0 = np.zeros(arrays.weights.shape + (6,))
        sigma0[..., :3] = -5.0e6
        points = int(arrays.weights.size)

        def build(form):
            options = dict(GEOMETRY_FORMS[form])
            gradients = arrays.kernel_gradients(dense=options.pop("dense", False))
            return _kernels.HexahedronElements(arrays.cell_nodes, gradients, arrays.weights, law, law_parameters,
                                               initial_stress=sigma0, **options)

        def inelastic(component) -> np.ndarray:
            return (np.asarray(component.plastic_strain()).ravel() > 0.0) | (np.asarray(component.damage()).ravel() > 0.0)

        onset = None
        if name != "linear_elastic":
            ramp = build("dense gradients")
            out = np.zeros(drive.size)
            for k in range(1, 401):
                ramp.compute(drive * k / 40, out)
                ramp.commit()
                if inelastic(ramp).any():
                    onset = k / 40
                    break
        for form in GEOMETRY_FORMS:
            try:
                probe = build(form)
            except (TypeError, ValueError):  # a build without this form
                continue
            if form != "dense gradients" and not hasattr(probe, "geometry_bytes"):
                continue  # a build before the reference form: kernel_gradients gave dense gradients
            for state in LAW_STATES if onset is not None else LAW_STATES[:1]:
                for threads in threads_list:
                    _kernels.set_num_threads(threads)
                    component = build(form)
                    out = np.zeros(drive.size)
                    if state == "at rest":
                        loads = [1.0e-9 * rng.standard_normal(drive.size) for _ in range(3 * steps + 1)]
                    elif state == "near the surface":
                        for k in range(1, 10):
                            component.compute(drive * 0.1 * k * onset, out)
                            component.commit()
                        loads = [drive * 0.9 * onset + 1.0e-9 * rng.standard_normal(drive.size)
                                 for _ in range(3 * steps + 1)]
                    else:
                        for k in range(1, 21):
                            component.compute(drive * 0.05 * k * onset, out)
                            component.commit()
                        loads = [drive * onset * (1.02 + 0.01 * j) + 1.0e-9 * rng.standard_normal(drive.size)
                                 for j in range(3 * steps + 1)]
                    best = math.inf
                    for batch in range(3):
                        start = time.perf_counter()
                        for j in range(batch * steps, (batch + 1) * steps):
                            component.compute(loads[j], out)
                            component.commit()
                        best = min(best, (time.perf_counter() - start) / steps)
                    before = inelastic(component), np.asarray(component.plastic_strain()).ravel().copy(), \
                        np.asarray(component.damage()).ravel().copy()
                    component.compute(loads[-1], out)
                    component.commit()
                    grew = (np.asarray(component.plastic_strain()).ravel() > before[1]) | \
                        (np.asarray(component.damage()).ravel() > before[2])
                    state_bytes = getattr(component, "state_bytes", None)
                    geometry_bytes = getattr(component, "geometry_bytes", None)
                    moved = (None if state_bytes is None else
                             loop_bytes_per_point(state_bytes, geometry_bytes, arrays.cell_nodes.shape[1],
                                                  arrays.weights.shape[1]))
                    ns = 1e9 * best / points
                    bound = None if moved is None else 1e9 * moved / bandwidth[threads]
                    rows.append({"law": name, "geometry": form, "state": state, "threads": threads, "points": points,
                                 "ns_per_point": ns, "returning": float(np.mean(grew)),
                                 "bytes_per_point": moved, "bound_ns_per_point": bound,
                                 "fraction_of_bound": None if bound is None else bound / ns})
    _kernels.set_num_threads(2)
    return rows


def yield_surface_seconds(component, node_coords: np.ndarray, steps: int) -> tuple[float, float]:
    """Best of three batches: seconds per compute + commit of a Mohr-Coulomb component whose points
    sit on its yield surface, as the case study's zone does after its static stage (its rock yields
    up to the zone's edge). Loaded in 20 increments by a uniform strain beyond the yield stress
    (eps_x = 1e-3, eps_y = 3e-4, eps_z = -3e-3 for Table 1's sandstone), then driven by a slow
    further loading with small random increments (1e-7 m), so that part of the points return each
    step and the rest unload into the surface's neighbourhood. Also returns the share of points that
    returned in one more step of the same driving (their plastic strain grew)."""
    rng = np.random.default_rng(1)
    u0 = np.zeros_like(node_coords)
    u0[:, 0], u0[:, 1], u0[:, 2] = 1.0e-3 * node_coords[:, 0], 3.0e-4 * node_coords[:, 1], -3.0e-3 * node_coords[:, 2]
    u0 = u0.ravel()
    out = np.zeros(u0.size)
    for k in range(1, 21):
        component.compute(u0 * k / 20, out)
        component.commit()
    batch = max(steps // 3, 1)
    loads = [u0 * (1.0 + 1.0e-4 * (k + 1)) + 1.0e-7 * rng.standard_normal(u0.size) for k in range(3 * batch + 1)]
    best = math.inf
    for b in range(3):
        start = time.perf_counter()
        for k in range(b * batch, (b + 1) * batch):
            component.compute(loads[k], out)
            component.commit()
        best = min(best, (time.perf_counter() - start) / batch)
    before = np.asarray(component.plastic_strain()).ravel()
    component.compute(loads[-1], out)
    component.commit()
    return best, float(np.mean(np.asarray(component.plastic_strain()).ravel() > before))


ONE_POINT_ROCK = tuple(f'materials.{name}.plasticity.integration="reduced"' for name in ("sandstone", "non_sandstone"))
"""Overrides of the case-3 scenes for one-point rock cells (the lining stays fully integrated)."""


def case_study_rows(presets, steps: int, threads: int = 2, one_point: bool = True) -> list[dict]:
    """The case-3 scene's step (workflows/scenes/case3_contact_PRESET.toml) split into the kernel's
    phases: stiffness product, element loop (Mohr-Coulomb rock zone and concrete lining, at rest:
    a yielding point costs several times more), input forces, contact pairs, update; with
    `one_point` a second row of the same scene with one-point rock cells (ONE_POINT_ROCK). The static
    stage is not solved (the step's cost does not depend on it; its minutes are in run.json)."""
    from pathlib import Path

    from pyfem.scene import load_scene

    scenes = Path(__file__).resolve().parents[1] / "workflows" / "scenes"
    rows = []
    for preset in presets:
        path = scenes / f"case3_contact_{preset}.toml"
        if not path.is_file():  # an installed package carries no workflows
            continue
        for overrides in ((), ONE_POINT_ROCK) if one_point else ((),):
            # Global steps (the phases local stepping's work model, local_stepping.COST_NS, is taken from).
            scene = load_scene(path, ["time.local_stepping=false", *overrides])
            rows.append(_case_row(scene, preset, bool(overrides), steps, threads))
    return rows


def _case_row(scene, preset: str, one_point: bool, steps: int, threads: int) -> dict:
    """One row of `case_study_rows`."""
    from pyfem import _kernels
    from pyfem.clock import phase_split
    from pyfem.distributed_model import model_in_memory

    built = model_in_memory(scene, solve_stage=False)
    stepper, _ = built.stepper()
    _kernels.set_num_threads(threads)
    n = 3 * built.part.n_local
    stepper_seconds_per_step(stepper, n, 2, amplitude=1.0e-9)  # warm-up
    stepper.reset_phase_seconds()
    rng = np.random.default_rng(0)
    u, v, a = 1.0e-9 * rng.standard_normal(n), np.zeros(n), np.zeros(n)
    start = time.perf_counter()
    stepper.run(u, v, a, steps, 0.0)
    seconds = time.perf_counter() - start
    split = phase_split(stepper.phase_seconds(), seconds)
    rock = "one-point Mohr-Coulomb zone" if one_point else "Mohr-Coulomb zone"
    return {"case": f"case 3 {preset} (contact, {rock}, concrete lining, oblique input)",
            "dofs": n, "threads": threads, "ms": 1e3 * seconds / steps,
            "points": built.loop.counted.n_points if built.loop is not None else 0,
            "pairs": len(built.contact_arrays["area"]) if built.contact_arrays else 0,
            "phases": {name: entry["ms_per_step"] for name, entry in split.items()}}


def main(argv=None) -> int:
    """Runs the benchmark, writes the results as JSON and prints a markdown table; returns 0."""
    parser = argparse.ArgumentParser(prog="pyfem bench", description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[30_000, 200_000, 700_000])
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--out", default="bench.json")
    parser.add_argument("--case-study", nargs="*", default=["coarse"], choices=["coarse", "paper"],
                        help="case-3 scenes whose step is split into phases (default coarse; paper builds "
                             "the 500 000-dof model, minutes); none: --case-study with no value")
    parser.add_argument("--element-loop", action="store_true",
                        help="only the element loop per law (element_law_rows) on the first size's box")
    args = parser.parse_args(argv)

    from pyfem import _kernels
    from pyfem.operators import build_model

    rows = []
    bandwidth = {threads: stream_triad_bandwidth(threads=threads) for threads in (1, 2)}
    if args.element_loop:
        result = {"date": time.strftime("%Y-%m-%d"), "machine": f"{platform.node()} {platform.processor()}",
                  "cpu_count": __import__("os").cpu_count(), "triad_GBps": {t: b / 1e9 for t, b in bandwidth.items()},
                  "element_laws": element_law_rows(args.sizes[0], args.steps, bandwidth)}
        with open(args.out, "w") as stream:
            json.dump(result, stream, indent=2)
        print(markdown_table(result))
        return 0
    for target in args.sizes:
        scene = _box_scene(target)
        model = build_model(scene)
        stiffness = model.stiffness
        mass = np.ascontiguousarray(model.mass, dtype=np.float64)
        dt = choose_time_step(scene, stiffness, mass, 0.0, model.node_coords).dt
        petsc_time, petsc_u = petsc_seconds_per_step(stiffness, mass, dt, args.steps, "baij")
        petsc_aij_time, _ = petsc_seconds_per_step(stiffness, mass, dt, args.steps, "aij")
        # Same loop in the kernel from the same start: the displacements must agree.
        from pyfem.effects import bsr_arrays

        indptr, indices, blocks = bsr_arrays(stiffness)
        check = _kernels.Stepper(indptr, indices, blocks, mass, dt, 0.0, 0.0)
        n = stiffness.shape[0]
        u = 1e-6 * np.random.default_rng(0).standard_normal(n)
        v, a = np.zeros(n), np.zeros(n)
        check.run(u, v, a, args.steps, 0.0)
        agreement = float(np.linalg.norm(u - petsc_u) / np.linalg.norm(petsc_u))
        for symmetric_storage, single, storage in ((True, False, "upper triangle"),
                                                   (True, True, "upper triangle, float32 blocks"),
                                                   (False, False, "full, fused")):
            moved = bytes_moved_per_step(stiffness, symmetric_storage, single)
            for threads in (1, 2):
                seconds = kernel_seconds_per_step(stiffness, mass, dt, args.steps, threads, symmetric_storage,
                                                  single)
                bound = moved / bandwidth[threads]
                rows.append({
                    "storage": storage, "dofs": n, "threads": threads,
                    "kernel_ms": 1e3 * seconds, "petsc_ms": 1e3 * petsc_time,
                    "petsc_aij_ms": 1e3 * petsc_aij_time, "speedup_vs_petsc_aij": petsc_aij_time / seconds,
                    "speedup_vs_petsc": petsc_time / seconds, "bandwidth_bound_ms": 1e3 * bound,
                    "fraction_of_bandwidth": bound / seconds, "bytes_per_step": moved,
                    "triad_GBps": bandwidth[threads] / 1e9, "kernel_vs_petsc_rel_diff": agreement,
                    "ns_per_dof": 1e9 * seconds / n,
                })
    element_rows = element_loop_rows(args.sizes[0], args.steps)
    law_rows = element_law_rows(args.sizes[0], args.steps, bandwidth)
    case_rows = case_study_rows(args.case_study, args.steps)
    _kernels.set_num_threads(2)
    result = {"date": time.strftime("%Y-%m-%d"), "machine": f"{platform.node()} {platform.processor()}",
              "cpu_count": __import__("os").cpu_count(), "rows": rows, "element_loop": element_rows,
              "element_laws": law_rows, "case_study": case_rows}
    with open(args.out, "w") as stream:
        json.dump(result, stream, indent=2)
    print(markdown_table(result))
    return 0


def markdown_table(result: dict) -> str:
    """The README's benchmark table."""
    lines = [f"Measured {result['date']} on {result['machine']} ({result['cpu_count']} cores), "
             f"Q1 box, one run; the petsc4py loop is serial MatMult + VecAXPY/PointwiseMult on the same "
             f"matrix as BAIJ (3x3 blocks) and as AIJ (dolfinx's format).", "",
             "| dofs | kernel storage | threads | kernel ms/step | petsc4py BAIJ ms/step | speed-up vs BAIJ | "
             "petsc4py AIJ ms/step | speed-up vs AIJ | bandwidth bound ms | fraction of bound | ns/dof | triad GB/s |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"] if result.get("rows") else []
    for r in result.get("rows", []):
        lines.append(f"| {r['dofs']} | {r['storage']} | {r['threads']} | {r['kernel_ms']:.3f} | {r['petsc_ms']:.3f} | "
                     f"{r['speedup_vs_petsc']:.2f}x | {r['petsc_aij_ms']:.3f} | {r['speedup_vs_petsc_aij']:.2f}x | "
                     f"{r['bandwidth_bound_ms']:.3f} | "
                     f"{100 * r['fraction_of_bandwidth']:.0f} % | {r['ns_per_dof']:.2f} | {r['triad_GBps']:.1f} |")
    if result.get("element_loop"):
        lines += ["", "Effects that are off cost nothing; the element loop where they are on (same run, "
                  "smallest box):", "", "| case | dofs | threads | ms/step | bare matrix ms/step | ratio | ns per point |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for r in result["element_loop"]:
            per_point = "" if r["ns_per_point"] is None else f"{r['ns_per_point']:.0f}"
            lines.append(f"| {r['case']} | {r['dofs']} | {r['threads']} | {r['ms']:.3f} | {r['reference_ms']:.3f} | "
                         f"{r['ratio']:.2f} | {per_point} |")
    if result.get("element_laws"):
        lines += ["", "The element loop per law (compute + commit, Q1 box, same run; bound = bytes per point / triad "
                  "bandwidth):", "", "| law | geometry | state | threads | ns per point | returning | bytes per point | "
                  "bound ns | fraction of bound |", "|---|---|---|---:|---:|---:|---:|---:|---:|"]
        for r in result["element_laws"]:
            bound = "" if r["bytes_per_point"] is None else (f"{r['bytes_per_point']} | {r['bound_ns_per_point']:.0f} | "
                                                             f"{100 * r['fraction_of_bound']:.0f} %")
            lines.append(f"| {r['law']} | {r['geometry']} | {r['state']} | {r['threads']} | {r['ns_per_point']:.0f} | "
                         f"{100 * r['returning']:.0f} % | " + (bound or " | | ") + " |")
    if result.get("case_study"):
        from pyfem.clock import PHASES

        lines += ["", "The case study's step split into the kernel's phases (ms per step, at rest; same run):", "",
                  "| case | dofs | element-loop points | pairs | threads | ms/step | "
                  + " | ".join(PHASES) + " | other |", "|---|---:|---:|---:|---:|---:|" + "---:|" * (len(PHASES) + 1)]
        for r in result["case_study"]:
            lines.append(f"| {r['case']} | {r['dofs']} | {r['points']} | {r['pairs']} | {r['threads']} | {r['ms']:.2f} | "
                         + " | ".join(f"{r['phases'][name]:.2f}" for name in (*PHASES, "other")) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()

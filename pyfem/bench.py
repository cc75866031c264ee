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
    from pyfem.solver import upper_triangle_blocks

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
    args = parser.parse_args(argv)

    from pyfem import _kernels
    from pyfem.operators import build_model
    from pyfem.solver import choose_time_step

    rows = []
    bandwidth = {threads: stream_triad_bandwidth(threads=threads) for threads in (1, 2)}
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
    case_rows = case_study_rows(args.case_study, args.steps)
    _kernels.set_num_threads(2)
    result = {"date": time.strftime("%Y-%m-%d"), "machine": f"{platform.node()} {platform.processor()}",
              "cpu_count": __import__("os").cpu_count(), "rows": rows, "element_loop": element_rows,
              "case_study": case_rows}
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
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
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

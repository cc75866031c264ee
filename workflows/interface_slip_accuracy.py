"""Accuracy against cost of the slip across a rock interface: how fine a mesh reads the relative
displacement of the layers (docs/interface_slip_accuracy.md).

The case study reports the layers' relative displacement across their interface (the paper's Fig. 6:
1.28 / 2.15 / 6.01 cm). No closed form gives the slip of a frictional interface under a wave, so this
study holds each run to a converged reference: the same problem on finer meshes.

The problem (workflows/scenes/contact_two_layer_sv.toml made plane strain): two horizontal layers,
sandstone below and the softer non-sandstone above (Table 1 presets), 60 x 60 m in x-z, the interface at
z = 30 m split into contact node pairs with no cohesion and a 30 deg friction angle, the in-situ stress
of 100 m of cover (the free surface 40 m above the box) pressing it shut; viscoelastic x and z faces
carrying the free field of a vertically incident SV Ricker wavelet (f0 = 5 Hz, 5 cm), roller y faces,
one element thick. The wave's shear exceeds the friction: the upper layer slides on the lower one,
back and forth, and keeps a residual offset. As a control, the same interface between two layers of the
same rock (the upper layer given the sandstone's constants: "homogeneous"): no material contrast across
the sliding surface. And the bimaterial interface with the friction's normal-stress lag on
([contact.normal_lag], Prakash-Clifton: L = 1 cm, V* = 1 m/s, a lag of at most 10 ms): "bimaterial,
lag"; and with a ten times shorter lag, L = 1 mm, on the three finest meshes: "bimaterial, lag 1 mm".

Measured: the slip history (the tangential relative displacement along x) of the pair at the box's
centre (x = 30 m, z = 30 m: a node of every mesh; pairs/I1.csv dux), its peak and its final value, against the finest
run. Knobs: the element size h (Q1: 5, 2.5, 1.25, 0.625, 0.3125 m; Q2: 5, 2.5, 1.25 m), expressed as
elements per shortest shear wavelength (the upper layer's, at 2.5 f0); the time step at the default
safety 0.8 (it follows h) and, at one size, halved.

Finished runs in the --work folder are reused. Outputs: workflows/results/interface_slip.csv and the table
of docs/interface_slip_accuracy.md (printed).

    /usr/bin/python3 workflows/interface_slip_accuracy.py [--work DIR]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem import solver  # noqa: E402
from pyfem.accuracy import highest_frequency, slowest_shear_speed  # noqa: E402
from pyfem.scene import load_scene  # noqa: E402
from wall_stress_accuracy import finished_run  # noqa: E402  (this script's folder is on sys.path)
from study_csv import run_study_main  # noqa: E402  (this script's folder is on sys.path)

SCENE = ROOT / "workflows" / "scenes" / "contact_two_layer_sv.toml"
CENTRE = (30.0, 0.0, 30.0)
DURATION = 0.9  # s: the wavelet up through the interface and back down from the free surface
RUNS = [("bimaterial", 1, 5.0, 0.8), ("bimaterial", 1, 2.5, 0.8), ("bimaterial", 1, 1.25, 0.8),
        ("bimaterial", 1, 0.625, 0.8), ("bimaterial", 1, 0.3125, 0.8), ("bimaterial", 1, 0.625, 0.4),
        ("bimaterial", 2, 5.0, 0.8), ("bimaterial", 2, 2.5, 0.8), ("bimaterial", 2, 1.25, 0.8),
        ("homogeneous", 1, 5.0, 0.8), ("homogeneous", 1, 2.5, 0.8), ("homogeneous", 1, 1.25, 0.8),
        ("homogeneous", 1, 0.625, 0.8), ("homogeneous", 1, 0.3125, 0.8), ("homogeneous", 1, 0.625, 0.4),
        ("bimaterial, lag", 1, 5.0, 0.8), ("bimaterial, lag", 1, 2.5, 0.8), ("bimaterial, lag", 1, 1.25, 0.8),
        ("bimaterial, lag", 1, 0.625, 0.8), ("bimaterial, lag", 1, 0.3125, 0.8), ("bimaterial, lag", 1, 0.625, 0.4),
        ("bimaterial, lag 1 mm", 1, 1.25, 0.8), ("bimaterial, lag 1 mm", 1, 0.625, 0.8),
        ("bimaterial, lag 1 mm", 1, 0.3125, 0.8)]
REFERENCE = {"bimaterial": (1, 0.3125, 0.8), "homogeneous": (1, 0.3125, 0.8),
             "bimaterial, lag": (1, 0.3125, 0.8), "bimaterial, lag 1 mm": (1, 0.3125, 0.8)}  # (order, h, safety)
LAG = {"bimaterial, lag": {"length": 0.01, "velocity": 1.0},       # [contact.normal_lag] of those runs
       "bimaterial, lag 1 mm": {"length": 0.001, "velocity": 1.0}}
RESULTS_CSV = ROOT / "workflows" / "results" / "interface_slip.csv"
COLUMNS = ["contrast", "order", "h", "safety", "per_wavelength", "peak_slip_cm", "final_slip_cm", "peak_error",
           "final_error", "history_error", "dofs", "steps", "loop_seconds"]


def scene(order: int, h: float, safety: float, contrast: str = "bimaterial"):
    overrides = [f"mesh.h={h}", f"mesh.order={order}", f"mesh.size=[60.0, {h}, 60.0]", f"time.duration={DURATION}",
                 f"time.safety={safety}", "contact.cohesion=0", "contact.tensile_strength=0",
                 "wave.motion.ricker.amplitude=0.05", "boundary.face.ymin.type=roller",
                 "boundary.face.ymax.type=roller", "output.interval=0.0025", "output.xdmf_interval=0",
                 f"pair_monitor.0.point=[{CENTRE[0]}, {CENTRE[1]}, {CENTRE[2]}]"]
    for k, z in enumerate((20.0, 45.0, 60.0)):
        overrides.append(f"monitor.{k}.point=[30.0, 0.0, {z}]")
    if contrast in LAG:
        overrides += [f"contact.normal_lag.{key}={value}" for key, value in LAG[contrast].items()]
    scene_ = load_scene(SCENE, overrides)
    if contrast == "homogeneous":
        scene_["materials"]["mudstone"] = dict(scene_["materials"]["sandstone"])
    return scene_


def shortest_wavelength(scene_) -> float:
    """The shortest shear wavelength of the scene (m): the slowest layer's shear speed over 2.5 f0
    (pyfem.accuracy, as `pyfem check` counts it)."""
    return slowest_shear_speed(scene_) / highest_frequency(scene_)


def slip_history(out: Path) -> tuple[np.ndarray, np.ndarray]:
    data = np.genfromtxt(out / "pairs" / "I1.csv", delimiter=",", names=True)
    return data["t"], data["dux"]


def run_study(work: Path) -> list[dict]:
    rows, histories = [], {}
    for contrast, order, h, safety in RUNS:
        scene_ = scene(order, h, safety, contrast)
        out = work / f"{contrast.replace(', ', '_').replace(' ', '_')}_q{order}_h{h:g}_s{safety:g}"
        summary = finished_run(out) or solver.run(scene_, out)
        t, slip = slip_history(out)
        histories[(contrast, order, h, safety)] = (t, slip)
        rows.append({"contrast": contrast, "order": order, "h": h, "safety": safety,
                     "per_wavelength": shortest_wavelength(scene_) / h,
                     "peak_slip_cm": 100 * float(np.abs(slip).max()), "final_slip_cm": 100 * float(slip[-1]),
                     "dofs": summary["dofs"], "steps": summary["steps"], "loop_seconds": summary["loop_seconds"]})
        print(f"{contrast} Q{order} h {h:g} safety {safety:g}: peak {rows[-1]['peak_slip_cm']:.4f} cm, final "
              f"{rows[-1]['final_slip_cm']:.4f} cm, {summary['loop_seconds']:.1f} s", flush=True)
    for row in rows:
        reference_t, reference = histories[(row["contrast"], *REFERENCE[row["contrast"]])]
        t, slip = histories[(row["contrast"], row["order"], row["h"], row["safety"])]
        on_reference = np.interp(t, reference_t, reference)
        peak = np.abs(reference).max()
        row["peak_error"] = float(np.abs(slip).max() / peak - 1.0)
        row["final_error"] = float((slip[-1] - reference[-1]) / peak)   # of the peak: the offset is small
        row["history_error"] = float(np.linalg.norm(slip - on_reference) / np.linalg.norm(on_reference))
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| layers | order | h (m) | elements per wavelength | safety | peak slip (cm) | final slip (cm) | "
             "peak error | final error (of the peak) | history error | dofs | steps | time loop (s) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        is_reference = (row["order"], row["h"], row["safety"]) == REFERENCE[row["contrast"]]
        errors = ("reference",) * 3 if is_reference else (
            f"{100 * row['peak_error']:+.2f} %", f"{100 * row['final_error']:+.2f} %", f"{100 * row['history_error']:.2f} %")
        lines.append(f"| {row['contrast']} | Q{row['order']} | {row['h']:g} | {row['per_wavelength']:.1f} | {row['safety']:g} | "
                     f"{row['peak_slip_cm']:.3f} | {row['final_slip_cm']:.3f} | {errors[0]} | {errors[1]} | {errors[2]} | "
                     f"{row['dofs']} | {row['steps']} | {row['loop_seconds']:.1f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    return run_study_main(__doc__.splitlines()[0], run_study, table, RESULTS_CSV, COLUMNS, "interface_slip_",
                          argv, compact=True)


if __name__ == "__main__":
    sys.exit(main())

"""Accuracy versus cost of the stress at a cavern wall: what the case study reports.

The case study reads the lining's and the rock's stress at a cavern's wall, where the stress
concentrates and the mesh is finest. This study measures how well the wall's stress is resolved
and what it costs, on a problem with an exact answer: an unlined circular tunnel (radius a = 5 m)
in a plane-strain slab (120 x 120 m, 2 m thick, rollers on the thin faces, viscoelastic x and z
faces carrying the free field) under a vertically incident SV Ricker wavelet. For a wave much
longer than the tunnel the wall follows Kirsch's quasi-static solution for a far-field shear tau:
hoop stress sigma_thth = -tau (1 + 3 a^4/r^4) sin 2 theta, a concentration of 4 at the wall.

Knobs, one run per combination:
  * element order Q1 / Q2;
  * element size at the wall h_wall (meshes/tunnel_in_box.py grades it to 8 m far away):
    1.2, 0.6, 0.3 m (h/a = 0.24, 0.12, 0.06);
  * the wave: f0 = 2 Hz (shortest wavelength ~185 m = 37 a: quasi-static, reference Kirsch) and
    f0 = 8 Hz (~46 m = 9 a: dynamic, the wall stress differs from Kirsch; reference the finest
    Q2 run, a converged reference when the two finest Q2 runs agree).
Measured at theta = 45 deg, r = 1.02 a (inside the first element row of every mesh):
  * peak error: |max_t |sigma_thth| / reference peak - 1|;
  * history error: ||sigma_thth(t) - reference(t)|| / ||reference|| (L2 over the run);
cost: the time loop's seconds (run.json loop_seconds) on this machine (2 cores).

Outputs: workflows/results/wall_stress.csv, docs/wall_stress_accuracy.png and
docs/wall_stress_accuracy.md (written whole: this text's findings, the table, the observed
orders); `pyfem check` prints the advice for the wall (`pyfem.accuracy.wall_size_for`) from the
CSV.

Sample runs (from the repository root):
    /usr/bin/python3 workflows/wall_stress_accuracy.py             # the full study, ~15 min
    /usr/bin/python3 workflows/wall_stress_accuracy.py --quick     # Q1 and Q2 at 1.2 and 0.6 m, 2 Hz
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem import solver  # noqa: E402
from pyfem.scene import parse_scene  # noqa: E402

# ----------------------------------------------------------------------------- parameters
RADIUS, SECTION, THICKNESS = 5.0, 120.0, 2.0
CENTRE = np.array([SECTION / 2, THICKNESS / 2, SECTION / 2])
E, NU, RHO = 8.0e9, 0.24, 2600.0
THETA, R_OVER_A = 45.0, 1.02
WALL_SIZES = [1.2, 0.6, 0.3]
ORDERS = [1, 2]
FREQUENCIES = {2.0: "kirsch", 8.0: "finest"}   # f0 (Hz) -> reference
DURATION = {2.0: 1.6, 8.0: 0.8}                # s: the whole wavelet past the tunnel
RESULTS_CSV = ROOT / "workflows" / "results" / "wall_stress.csv"
FIGURE = ROOT / "docs" / "wall_stress_accuracy.png"
DOC = ROOT / "docs" / "wall_stress_accuracy.md"
COLUMNS = ["order", "h_wall", "h_over_a", "f0", "reference", "peak_error", "history_error", "concentration",
           "loop_seconds", "steps", "dofs"]


def monitor_point() -> np.ndarray:
    t = math.radians(THETA)
    return CENTRE + RADIUS * R_OVER_A * np.array([math.cos(t), 0.0, math.sin(t)])


def kirsch_hoop_factor(r_over_a: float, theta: float) -> float:
    """sigma_thth / tau of Kirsch's solution for a far-field shear tau = sigma_xz."""
    return -(1.0 + 3.0 * r_over_a ** -4) * math.sin(math.radians(2.0 * theta))


def scene_for(mesh_file: Path, order: int, f0: float) -> dict:
    return parse_scene({
        "title": f"tunnel wall stress, Q{order}, f0 {f0:g} Hz",
        "mesh": {"builder": "file", "file": str(mesh_file), "order": order},
        "materials": {"rock": {"E": E, "nu": NU, "rho": RHO}},
        "time": {"duration": DURATION[f0]},
        "wave": {"type": "SV", "angle": 0.0, "motion": {"ricker": {"f0": f0, "amplitude": 1.0e-3 * (2.0 / f0)}}},
        "boundary": {"face": {"ymin": {"type": "roller"}, "ymax": {"type": "roller"}}},
        "monitor": [{"name": "wall", "point": monitor_point().tolist()}],
        "output": {"interval": 0.0025, "xdmf_interval": 0.0},
    })


def hoop_history(out: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t, sigma_thth(t)) at the monitor from monitors/wall.csv (Pa)."""
    with open(out / "monitors" / "wall.csv") as handle:
        header = handle.readline().strip().split(",")
    data = np.loadtxt(out / "monitors" / "wall.csv", delimiter=",", skiprows=1)
    column = {key: data[:, k] for k, key in enumerate(header)}
    c, s = math.cos(math.radians(THETA)), math.sin(math.radians(THETA))
    # The dynamic part (no initial stress here): sigma_thth in the x-z plane.
    return column["t"], column["sxx"] * s * s + column["szz"] * c * c - 2 * column["sxz"] * s * c


def free_field_shear(scene, times: np.ndarray) -> np.ndarray:
    """tau(t) = sigma_xz of the free field at the monitor (Pa)."""
    from pyfem.operators import build_model
    from pyfem.seismic.setup import seismic_input_from_scene

    freefield, _ = seismic_input_from_scene(scene, build_model(scene))
    return freefield.stress(monitor_point()[None, :], times)[:, 0, 0, 2]


def mesh(folder: Path, h_wall: float) -> Path:
    path = folder / f"tunnel_h{h_wall:g}.msh"
    if not path.exists():
        subprocess.run([sys.executable, str(ROOT / "meshes" / "tunnel_in_box.py"), str(path), "--radius", str(RADIUS),
                        "--h-wall", str(h_wall)], check=True, timeout=600)
    return path


def errors(t: np.ndarray, hoop: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    peak = float(np.max(np.abs(hoop)) / np.max(np.abs(reference)) - 1.0)
    history = float(np.linalg.norm(hoop - reference) / np.linalg.norm(reference))
    return abs(peak), history


def run_study(sizes=WALL_SIZES, orders=ORDERS, frequencies=tuple(FREQUENCIES), work: Path | None = None) -> list[dict]:
    work = Path(work or tempfile.mkdtemp(prefix="wall_stress_"))
    histories, rows = {}, []
    for f0 in frequencies:
        for order in orders:
            for h_wall in sizes:
                scene = scene_for(mesh(work, h_wall), order, f0)
                out = work / f"q{order}_h{h_wall:g}_f{f0:g}"
                summary = solver.run(scene, out)
                t, hoop = hoop_history(out)
                histories[(f0, order, h_wall)] = (t, hoop, scene)
                rows.append({"order": order, "h_wall": h_wall, "h_over_a": h_wall / RADIUS, "f0": f0,
                             "loop_seconds": summary["loop_seconds"], "steps": summary["steps"],
                             "dofs": summary["dofs"]})
                print(f"f0 {f0:g} Hz, Q{order}, h_wall {h_wall:g} m: {summary['steps']} steps, "
                      f"{summary['loop_seconds']:.1f} s", flush=True)
    for row in rows:
        t, hoop, scene = histories[(row["f0"], row["order"], row["h_wall"])]
        if FREQUENCIES[row["f0"]] == "kirsch":
            reference = kirsch_hoop_factor(R_OVER_A, THETA) * free_field_shear(scene, t)
            row["reference"] = "Kirsch"
        else:  # the finest Q2 run of this frequency
            finest = histories[(row["f0"], max(orders), min(sizes))]
            reference = np.interp(t, finest[0], finest[1])
            row["reference"] = f"Q{max(orders)} h_wall {min(sizes):g} m"
        tau = free_field_shear(scene, t)
        row["peak_error"], row["history_error"] = errors(t, hoop, reference)
        row["concentration"] = float(np.max(np.abs(hoop)) / np.max(np.abs(tau)))
    return rows


def write_csv(rows: list[dict], path: Path = RESULTS_CSV) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({key: (f"{row[key]:.6g}" if isinstance(row[key], float) else row[key]) for key in COLUMNS})


def observed_orders(rows: list[dict]) -> dict:
    """Observed order in h of the history error, per (f0, order), between successive sizes
    (the finest Q2 of a dynamic wave is its own reference and is left out)."""
    result = {}
    for f0 in sorted({row["f0"] for row in rows}):
        for order in sorted({row["order"] for row in rows}):
            series = sorted(((row["h_wall"], row["history_error"]) for row in rows
                             if row["f0"] == f0 and row["order"] == order and row["history_error"] > 0.0),
                            reverse=True)
            result[(f0, order)] = [math.log(e0 / e1) / math.log(h0 / h1)
                                   for (h0, e0), (h1, e1) in zip(series, series[1:])]
    return result


def figure(rows: list[dict], path: Path = FIGURE) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for f0, marker in zip(sorted({row["f0"] for row in rows}), "os"):
        for order, colour in ((1, "C0"), (2, "C3")):
            series = sorted((row for row in rows if row["f0"] == f0 and row["order"] == order
                             and row["history_error"] > 0.0), key=lambda row: row["h_wall"])
            if not series:
                continue
            label = f"Q{order}, f0 {f0:g} Hz ({series[0]['reference']})"
            axes[0].loglog([r["h_over_a"] for r in series], [r["history_error"] for r in series], marker + "-",
                           color=colour, label=label)
            axes[1].loglog([r["loop_seconds"] for r in series], [r["history_error"] for r in series], marker + "-",
                           color=colour, label=label)
    axes[0].set_xlabel("element size at the wall / radius")
    axes[1].set_xlabel("time loop (s, this machine)")
    for ax in axes:
        ax.set_ylabel("hoop stress history error at 1.02 a")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle("stress at a tunnel wall: accuracy against element size and cost", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def table(rows: list[dict]) -> str:
    lines = ["| f0 (Hz) | reference | order | h_wall (m) | h/a | hoop concentration | peak error | history error | "
             "time loop (s) | steps | dofs |", "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for row in sorted(rows, key=lambda r: (r["f0"], r["order"], -r["h_wall"])):
        lines.append(f"| {row['f0']:g} | {row['reference']} | Q{row['order']} | {row['h_wall']:g} | "
                     f"{row['h_over_a']:.2f} | {row['concentration']:.3f} | {100 * row['peak_error']:.2f} % | "
                     f"{100 * row['history_error']:.2f} % | {row['loop_seconds']:.1f} | {row['steps']} | {row['dofs']} |")
    orders = observed_orders(rows)
    lines.append("")
    lines.append("Observed order in h of the history error between successive sizes: " + "; ".join(
        f"f0 {f0:g} Hz Q{order}: " + ", ".join(f"{p:.2f}" for p in values)
        for (f0, order), values in orders.items() if values) + ".")
    return "\n".join(lines)


DOC_HEAD = """# Stress at a cavern wall: accuracy against cost

Written by workflows/wall_stress_accuracy.py (read its header for the problem and the knobs): an
unlined circular tunnel (a = 5 m) in a plane-strain slab under a vertically incident SV Ricker
wavelet; the hoop stress at theta = 45 deg, r = 1.02 a, against Kirsch's quasi-static solution
(f0 = 2 Hz: the shortest wavelength is 37 a) and, for a shorter wave, against the finest Q2 run.
Cost: the time loop on this machine (2 cores), shared with other jobs while it ran: compare
ratios.

What the numbers say, and what they cannot: against Kirsch the error does not fall with h. The
quasi-static solution is itself an approximation at this frequency (the wavelet has energy up to
5 Hz, ka = 0.14 there; how far the dynamic concentration lies from the static one we have not
computed), and a Q1 mesh's stress at a point 2 % of a radius from the
wall is the gradient of a bilinear field across an element whose far side lies 12-24 % of a radius
away. Every run is within 2.5 % of Kirsch's concentration (3.77 at 1.02 a; the cavity seen as
filled, the boundary defect of 2026-11-23, gives 1). The dynamic wave and a converged reference
(the issue's second half) are in the study's full form and not run yet.

`pyfem check` prints, from workflows/results/wall_stress.csv, the largest wall size per order
within 5 % and 1 % (`pyfem.accuracy.wall_size_for`); the layered-cavern builder's default puts
lining_wall / lining_elements = 0.5 m at the wall, 0.04 of the powerhouse's half width.

![wall stress accuracy](wall_stress_accuracy.png)

"""


def update_doc(text: str, doc: Path = DOC) -> None:
    doc.write_text(DOC_HEAD + text + "\n")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="Q1 and Q2 at 1.2 and 0.6 m, 2 Hz only")
    parser.add_argument("--out", type=Path, default=None, help="CSV path (default workflows/results/wall_stress.csv)")
    args = parser.parse_args(argv)
    if args.quick:
        rows = run_study(sizes=[1.2, 0.6], frequencies=(2.0,))
    else:
        rows = run_study()
    write_csv(rows, args.out or RESULTS_CSV)
    text = table(rows)
    print(text)
    if args.out is None and not args.quick:
        figure(rows)
        update_doc(text)
    print(json.dumps({"rows": len(rows)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())

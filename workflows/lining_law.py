"""The lining law alone: when Eq. 21 damages, how much, and whether it can grade.

The case study's lining (the paper's Eq. 21, docs/materials.md "Lining concrete") is driven at one
integration point of the kernel itself (pyfem._kernels.HexahedronElements, one cube cell of edge h
with one point, law "concrete_damage", the scene defaults: E 28 GPa, nu 0.167, f_t 1.27 MPa,
c 1.8 MPa, phi 46 deg, A_t 1, B_t 5e4, A_c 1.4, B_c 1500, G_f 120 N/m) along strain paths:

1. uniaxial tension (strain (e, -nu e, -nu e): stress-free laterally at any damage), for
   B_t = 1e4, 2e4, 5e4, 1e5 and f_t = 1.27 (the scenes, C25's design value), 1.78 (C25's
   characteristic value) and 2.2 MPa, with the crack band (h = 1 m, the lining's elements) and
   without it (G_f = 0: Eq. 21 as printed): the stress at which damage starts, the peak stress,
   the strain and stress at d = 0.3, and whether d = 0.3 lies before the peak (reachable under a
   load that does not fall: graded) or after it (on the softening branch);
2. uniaxial compression (strain (-e, nu e, nu e)): onset, peak, d_c at the peak; and the onset the
   paper's criterion gives read literally (sqrt(sum <eps_i>^2) of the total strain: the Poisson
   expansion, f_t / (nu sqrt 2));
3. compression with a tensile principal stress (s_3 = -5 MPa held, s_1 growing, s_2 = 0, the
   lining wall's state under dynamic shear): the s_1 at which damage starts, against the tension
   criterion's, Mazars' own split of the strain (f_t) and the literal reading;
4. the lining monitors A-D of the case-1 check run (the small model,
   workflows/results/case_study/case1_small): when each first damages, of which type, and the law's
   two criteria at the last sample before (its stress columns are the law's stress at the monitor's
   kernel point).

    /usr/bin/python3 workflows/lining_law.py        # about 20 s
    -> workflows/results/lining_law.md, lining_law.png
"""
from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))

from pyfem import _kernels  # noqa: E402

# Parameters (the scenes' lining: workflows/scenes/case*_coarse.toml, [materials.lining.damage] defaults)
E, NU = 28.0e9, 0.167
LINING = dict(young_modulus=E, poisson_ratio=NU, tensile_strength=1.27e6, cohesion=1.8e6, friction_angle=46.0)
H = 1.0                                   # m, the lining elements' size (1.0 m walls, 1.25 m crown)
B_T = (1.0e4, 2.0e4, 5.0e4, 1.0e5)
F_T = (1.27e6, 1.78e6, 2.2e6)             # Pa
GRADED = 0.3                              # the paper's case-1 lining damage
S3_HELD = -5.0e6                          # Pa, the wall's vertical compression of path 3
MONITOR_C = REPOSITORY / "workflows" / "results" / "case_study" / "case1_small" / "monitors" / "C.csv"
RESULTS = REPOSITORY / "workflows" / "results"
MPA = 1.0e-6


class Point:
    """One integration point of the kernel's lining law: a cube cell of edge h, one Gauss point."""

    def __init__(self, parameters: dict, h: float = H):
        corners = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=float)
        gradients = (2.0 * corners - 1.0) / (4.0 * h)  # d phi_a / dx at the centre (1/m)
        self.x = corners * h
        self.elements = _kernels.HexahedronElements(np.arange(8, dtype=np.int32)[None],
                                                    np.ascontiguousarray(gradients[None, None]),
                                                    np.full((1, 1), h ** 3), "concrete_damage", parameters)
        self._force = np.zeros(24)

    def step(self, strain: np.ndarray) -> tuple[np.ndarray, float, int]:
        """Commits the (3, 3) strain tensor; returns the stress (Voigt, Pa), damage, damage type."""
        self._force[:] = 0.0
        self.elements.compute((self.x @ strain.T).ravel(), self._force)
        self.elements.commit()
        return (self.elements.stress()[0, 0].copy(), float(self.elements.damage()[0, 0]),
                int(self.elements.damage_type()[0, 0]))


def drive(parameters: dict, strains, h: float = H) -> dict:
    point = Point(parameters, h)
    stress, damage, kind = zip(*(point.step(eps) for eps in strains))
    return {"stress": np.array(stress), "damage": np.array(damage), "type": np.array(kind)}


def elastic_strain(stress: np.ndarray) -> np.ndarray:
    """C^-1 : sigma for (n, 6) Voigt stresses [xx, yy, zz, xy, yz, xz]: (n, 3, 3) tensor strains."""
    s = np.asarray(stress, dtype=float)
    trace = s[:, 0] + s[:, 1] + s[:, 2]
    eps = np.zeros((len(s), 3, 3))
    for i in range(3):
        eps[:, i, i] = ((1.0 + NU) * s[:, i] - NU * trace) / E
    for k, (i, j) in zip((3, 4, 5), ((0, 1), (1, 2), (0, 2))):
        eps[:, i, j] = eps[:, j, i] = (1.0 + NU) * s[:, k] / E
    return eps


def uniaxial_tension(parameters: dict, h: float = H, top: float = 12.0, n: int = 4000) -> dict:
    threshold = parameters["tensile_strength"] / E
    e = np.linspace(0.0, top * threshold, n + 1)
    run = drive(parameters, [np.diag([v, -NU * v, -NU * v]) for v in e], h)
    s = run["stress"][:, 0]
    started = np.argmax(run["damage"] > 0.0)
    peak = int(np.argmax(s))
    graded = int(np.argmax(run["damage"] >= GRADED)) if run["damage"].max() >= GRADED else None
    return {"e": e, "s": s, "d": run["damage"], "onset_mpa": s[started - 1] * MPA, "peak_mpa": s[peak] * MPA,
            "d_at_peak": run["damage"][peak],
            "graded_strain": None if graded is None else e[graded] / threshold,
            "graded_mpa": None if graded is None else s[graded] * MPA,
            "graded_before_peak": graded is not None and graded <= peak}


def uniaxial_compression(parameters: dict, h: float = H, top: float = 3.0e-3, n: int = 3000) -> dict:
    e = np.linspace(0.0, top, n + 1)
    run = drive(parameters, [np.diag([-v, NU * v, NU * v]) for v in e], h)
    s = -run["stress"][:, 0]
    started = np.argmax(run["damage"] > 0.0)
    peak = int(np.argmax(s))
    return {"e": e, "s": s, "d": run["damage"], "type": run["type"], "onset_mpa": s[started - 1] * MPA,
            "peak_mpa": s[peak] * MPA, "d_at_peak": run["damage"][peak], "onset_type": int(run["type"][started])}


def literal_equivalent_strain(strain: np.ndarray) -> float:
    """The paper's eps_bar read literally: sqrt(sum <eps_i>^2) of the total principal strains."""
    values = np.linalg.eigvalsh(strain)
    return float(np.sqrt(np.sum(np.maximum(values, 0.0) ** 2)))


def held_compression(parameters: dict, s3: float = S3_HELD, n: int = 3000) -> dict:
    """s_3 = s3 held, s_1 from 0 to 2 f_t, s_2 = 0 (principal axes fixed): the s_1 at which
    the law and the literal criterion start tension damage (strain from the undamaged law)."""
    s1 = np.linspace(0.0, 2.0 * parameters["tensile_strength"], n + 1)
    stresses = np.column_stack([s1, np.zeros_like(s1), np.full_like(s1, s3), np.zeros((len(s1), 3))])
    strains = elastic_strain(stresses)
    run = drive(parameters, strains)
    started = int(np.argmax(run["damage"] > 0.0))
    threshold = parameters["tensile_strength"] / E
    literal = next(i for i, eps in enumerate(strains) if literal_equivalent_strain(eps) > threshold)
    c, phi = parameters["cohesion"], math.radians(parameters["friction_angle"])
    return {"law_onset_mpa": s1[started - 1] * MPA, "law_type": int(run["type"][started]),
            "mohr_coulomb_mpa": (2.0 * c * math.cos(phi) + s3 * (1.0 - math.sin(phi))) / (1.0 + math.sin(phi)) * MPA,
            "literal_onset_mpa": s1[literal - 1] * MPA, "mazars_onset_mpa": parameters["tensile_strength"] * MPA,
            "energy_split_mpa": parameters["tensile_strength"] / (1.0 + NU) * MPA}


def read_monitor(path: Path) -> dict:
    with open(path) as stream:
        rows = list(csv.reader(stream))
    data = np.array(rows[1:], dtype=float)
    return {name: data[:, i] for i, name in enumerate(rows[0])}


def measures(parameters: dict, stress: np.ndarray) -> dict:
    """The law's two criteria at an undamaged point of total stress `stress` (Voigt, Pa), each as a
    share of its threshold (1 = damage starts): the tension measure sqrt(sum <e+_i>^2) / (f_t / E) of
    the energy split's tensile strain, and the Mohr-Coulomb measure / (f_c / E)."""
    s = np.linalg.eigvalsh(np.array([[stress[0], stress[3], stress[5]], [stress[3], stress[1], stress[4]],
                                     [stress[5], stress[4], stress[2]]]))[::-1]
    positive, trace = np.maximum(s, 0.0), max(s.sum(), 0.0)
    tensile = np.maximum(((1.0 + NU) * positive - NU * trace) / E, 0.0)
    sin_phi = math.sin(math.radians(parameters["friction_angle"]))
    f_c = 2.0 * parameters["cohesion"] * math.cos(math.radians(parameters["friction_angle"])) / (1.0 - sin_phi)
    return {"principal_mpa": s * MPA, "tension": float(np.sqrt(np.sum(tensile ** 2))) * E / parameters["tensile_strength"],
            "shear": ((s[0] - s[2]) + (s[0] + s[2]) * sin_phi) / (1.0 - sin_phi) / f_c}


def monitor_onsets(parameters: dict, directory: Path = MONITOR_C.parent) -> dict | None:
    """Where the run's lining monitors first damage: the time, the type, the damage one output
    interval later, and the law's two criteria at the last undamaged sample (the monitor's stress
    columns are the law's stress at its kernel point, so before the onset C^-1 : sigma is its strain;
    the damage jumps within one interval, so the onset itself falls between two samples)."""
    if not (directory / "C.csv").exists():
        return None
    out = {}
    for name in ("A", "B", "C", "D"):
        m = read_monitor(directory / f"{name}.csv")
        stress = np.column_stack([m[k] for k in ("sxx", "syy", "szz", "sxy", "syz", "sxz")])
        entry = {"t": m["t"], "damage": m["damage"], "s1": m["s1"], "onset": None,
                 "largest": max((measures(parameters, row) for row in stress), key=lambda r: r["tension"])}
        if m["damage"].max() > 0.0:
            i = int(np.argmax(m["damage"] > 0.0))
            entry.update(onset=i, onset_t=m["t"][i], onset_type=int(m["damage_type"][i]),
                         damage_next=float(m["damage"][min(i + 1, len(m["t"]) - 1)]),
                         before=measures(parameters, stress[i - 1]))
        out[name] = entry
    return out


def _f(value, fmt="{:.2f}"):
    return "-" if value is None else fmt.format(value)


def main() -> int:
    RESULTS.mkdir(parents=True, exist_ok=True)
    lines = ["# The lining law alone (Eq. 21 as the kernel runs it)", "",
             "Generated by `workflows/lining_law.py`: one integration point of the kernel's `concrete_damage` law "
             f"(a cube of edge {H:g} m, the lining elements' size), E {E * 1e-9:g} GPa, nu {NU}, c 1.8 MPa, phi 46 deg, "
             "A_t 1, A_c 1.4, B_c 1500.", ""]
    # 1. Uniaxial tension.
    lines += ["## Uniaxial tension", "",
              "d = 0.3 'graded' when it lies before the peak stress (a load that does not fall reaches it and "
              "stops there); after the peak it lies on the softening branch, which a stress-driven point only "
              "passes through on its way to the cap. Strain at d = 0.3 in units of the threshold f_t / E.", "",
              "| f_t (MPa) | B_t | crack band | onset (MPa) | peak (MPa) | d at peak | strain at d = 0.3 | "
              "stress at d = 0.3 (MPa) | d = 0.3 before the peak |",
              "|---:|---:|---|---:|---:|---:|---:|---:|---|"]
    curves = {}
    for f_t in F_T:
        for b_t in B_T:
            for band, g_f in (("h = 1 m", 120.0), ("none (Eq. 21)", 0.0)):
                r = uniaxial_tension(dict(LINING, tensile_strength=f_t, B_t=b_t, fracture_energy=g_f))
                if f_t == F_T[0]:
                    curves[(b_t, band)] = r
                lines.append(f"| {f_t * MPA:.2f} | {b_t:.0e} | {band} | {r['onset_mpa']:.3f} | {r['peak_mpa']:.3f} | "
                             f"{r['d_at_peak']:.3f} | {_f(r['graded_strain'])} | {_f(r['graded_mpa'], '{:.3f}')} | "
                             f"{'yes' if r['graded_before_peak'] else 'no'} |")
    lines += ["", "Closed form (A_t = 1, no crack band): d_t = 1 - exp(-B_t (kappa - eps_t)), stress "
              "E kappa (1 - d_t); the stress peaks at kappa = 1/B_t if 1/B_t > eps_t, with "
              "d_t = 1 - exp(-(1 - B_t eps_t)), else at the threshold (B_t eps_t = "
              f"{5.0e4 * 1.27e6 / E:.2f} for the scenes: softening at once). With the crack band the stretch assumes that "
              "softening: B_t < E / f_t lifts the peak above f_t (the 1.62 MPa row), which the scene now refuses "
              "(materials.NAME.damage.B_t). For f_t above 1.45 MPa the onset is the Mohr-Coulomb check's own "
              "uniaxial tensile strength, 2c cos(phi) / (1 + sin(phi)) = "
              f"{2 * 1.8 * math.cos(math.radians(46)) / (1 + math.sin(math.radians(46))):.3f} MPa (shear damage "
              "first).", ""]
    # 2. Uniaxial compression.
    comp = uniaxial_compression(dict(LINING))
    lines += ["## Uniaxial compression", "",
              f"- The law: no tension damage (the tensile strain e+ of the effective stress is 0); compression-shear "
              f"damage (type {comp['onset_type']}: 2 = shear) starts at {comp['onset_mpa']:.2f} MPa (the Mohr-Coulomb "
              f"strength 2c cos(phi)/(1 - sin(phi)) = "
              f"{2 * 1.8 * math.cos(math.radians(46)) / (1 - math.sin(math.radians(46))):.2f} MPa), the stress peaks at "
              f"{comp['peak_mpa']:.2f} MPa with d_c = {comp['d_at_peak']:.3f} (graded and stable up to it).",
              f"- The paper's criterion read literally (sqrt(sum <eps_i>^2) of the total principal strains, tension "
              f"first): the two lateral Poisson strains reach f_t / E at f_t / (nu sqrt 2) = "
              f"{1.27 / (NU * math.sqrt(2.0)):.2f} MPa, where a concrete of f_c 25-30 MPa would be given tension damage "
              "that then softens at once (B_t eps_t > 1).", ""]
    # 3. Compression with a tensile principal stress.
    held = held_compression(dict(LINING))
    lines += [f"## s_3 = {S3_HELD * MPA:g} MPa held, s_1 growing (s_2 = 0)", "",
              f"- The law: damage starts at s_1 = {held['law_onset_mpa']:.3f} MPa, of type {held['law_type']} "
              "(1 tension, 2 shear): the Mohr-Coulomb check of Table 1's c = 1.8 MPa, phi = 46 deg, "
              "s_1 = (2c cos(phi) + s_3 (1 - sin(phi))) / (1 + sin(phi)) = "
              f"{held['mohr_coulomb_mpa']:.3f} MPa, comes first. Its tension criterion would start at "
              f"f_t / (1 + nu) = {held['energy_split_mpa']:.3f} MPa: with a compressive trace the tensile strain of "
              "the energy split, e+ = [(1 + nu) <sigma_e>+ - nu <tr sigma_e>+ I] / E, is (1 + nu) s_1 / E.",
              f"- Mazars' split (nu acting on the sum of the positive principal stresses): {held['mazars_onset_mpa']:.3f} "
              "MPa, f_t itself.",
              f"- The literal reading (total principal strains): {held['literal_onset_mpa']:.3f} MPa.", ""]
    # 4. The lining monitors of the case-1 check run.
    path = monitor_onsets(dict(LINING))
    if path is None:
        lines += ["## The lining monitors of case 1", "", f"No monitor files in {MONITOR_C.parent.relative_to(REPOSITORY)}: "
                  "not drawn.", ""]
    else:
        lines += ["## The lining monitors of case 1 (the small model, the calibrated input)", "",
                  f"The run in {MONITOR_C.parent.relative_to(REPOSITORY)}: where each monitor's kernel point first "
                  "damages, and the law's two criteria (as shares of their thresholds) at the last sample before, "
                  "0.01 s earlier. Principal stresses total (static + dynamic), MPa.", "",
                  "| monitor | onset (s) | type | damage 0.01 s later | principal stresses before (MPa) | "
                  "tension criterion | Mohr-Coulomb criterion |", "|---|---:|---|---:|---|---:|---:|"]
        for name, r in path.items():
            if r["onset"] is None:
                lines.append(f"| {name} | - | - | - | - | {r['largest']['tension']:.3f} (largest) | - |")
                continue
            b4 = r["before"]
            lines.append(f"| {name} | {r['onset_t']:.2f} | {'tension' if r['onset_type'] == 1 else 'shear'} | "
                         f"{r['damage_next']:.4f} | {', '.join(f'{v:.2f}' for v in b4['principal_mpa'])} | "
                         f"{b4['tension']:.3f} | {b4['shear']:.3f} |")
        lines.append("")
    (RESULTS / "lining_law.md").write_text("\n".join(lines))
    # Figure.
    fig, axes = plt.subplots(1, 3 if path is not None else 2, figsize=(15 if path is not None else 10, 4))
    for (b_t, band), r in curves.items():
        style = "-" if band.startswith("h") else "--"
        axes[0].plot(r["e"] / (1.27e6 / E), r["d"], style, lw=1, label=f"B_t {b_t:.0e}, band {band}")
    axes[0].axhline(GRADED, color="k", lw=0.5)
    axes[0].set(xlabel="axial strain / (f_t / E)", ylabel="damage", title="uniaxial tension, f_t 1.27 MPa",
                xlim=(0, 6))
    axes[0].legend(fontsize=6)
    axes[1].plot(comp["e"] * 1e3, comp["s"] * MPA, label="stress (MPa)")
    axes[1].plot(comp["e"] * 1e3, 10 * comp["d"], label="10 x damage")
    axes[1].axhline(1.27 / (NU * math.sqrt(2.0)), color="r", lw=0.8, ls=":", label="literal onset f_t/(nu sqrt 2)")
    axes[1].set(xlabel="axial compressive strain (1e-3)", title="uniaxial compression")
    axes[1].legend(fontsize=7)
    if path is not None:
        for name, r in path.items():
            line, = axes[2].plot(r["t"], r["s1"] * MPA, lw=0.8, label=f"{name}: s_1 (MPa)")
            axes[2].plot(r["t"], r["damage"], "--", lw=1.0, color=line.get_color(), label=f"{name}: damage")
        axes[2].set(xlabel="t (s, record time)", title="lining monitors, case 1 (small model)")
        axes[2].legend(fontsize=6)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(RESULTS / "lining_law.png", dpi=100)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())

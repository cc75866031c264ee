"""The paper's case study end to end: a deep powerhouse cavern in layered rock, three earthquakes.

Zhao, Xiao, Chen & Yang (2021, CJGE 43(12)), Sec. 4-5: the Azad Pattan main powerhouse
(24.9 x 60.15 m, 175.6 m long, concrete lining 1.25 m crown / 1.0 m walls) more than 300 m
deep in 60 % sandstone / 40 % non-sandstone layers dipping 70 deg, shaken by El Centro 1940
N-S scaled to PGA 0.32 g, as SV along x with P carrying 2/3 of the record:

    case 1  vertical incidence, layers welded
    case 2  incidence (1/2, 0, sqrt(3)/2) (30 deg from vertical), layers welded
    case 3  as case 2, with interlayer dynamic contact and its deterioration D(t)

Each case is one scene file, workflows/scenes/case{1,2,3}_*_{coarse,paper}.toml (read their
headers for every modelling choice). This workflow runs them (or reads finished run
directories), then draws figures like the paper's and writes the comparison:

    fig4_input_record.png        the processed input motion (paper Fig. 4)
    fig6_interlayer.png          interlayer relative displacement at the wall (Fig. 6)
    fig7_deterioration.png       D(t) of the wall and crown pairs, case 3 (Fig. 7)
    fig8_displacement.png        |u(t)| at A (crown), B, C (walls), D (floor) (Fig. 8)
    fig9_relative.png            peak displacement of A, B, C relative to D (Fig. 9)
    fig10_principal_stress.png   max principal stress at A and B (Fig. 10)
    fig11_lining_damage.png      the lining unrolled, damage at the end of each run (Fig. 11)
    fig11b_crack_opening.png     the same, the crack band's largest opening (mm): graded where the
                                 damage has saturated (runs since 2026-11-28)
    fig12_damage_type.png        the same, damage type: tension or shear (Fig. 12)
    fig13_deformation.png        the walls' and crown's x offset to the floor, and the offset
                                 across the soft layer's interface (Fig. 13 b, d)
    static_caseN.png             each case after its static stage, section y = 0: principal
                                 stresses, plastic strain (the plastic zone) and damage (the
                                 run's static/section_stress.png)
    comparison.md, summary.json  our numbers next to the paper's; run costs

and replaces the table between the markers of docs/case_study.md.

Quantities (all from the run directories; SI in the files, cm and MPa in the table):
- interlayer relative displacement: u(I8_soft) - u(I8_hard), two rock points 1.9 m to either
  side of interface_8 (normal distance) at the upstream wall; with contact also the node
  pair's own relative displacement u_j - u_i (pairs/wall_up_8.csv), its maximum and its value
  at the end of the run (the "residual");
- lining displacement: |u| at A-D, absolute (the free field's rigid motion included, as the
  paper's "resultant displacement");
- relative displacement of A, B, C: max_t |u_X(t) - u_D(t)| (the deformation of the section)
  and, as the paper may mean, peak |u_X| - peak |u_D|;
- max principal stress at A and B: total (geostatic + dynamic) and dynamic alone.

Sample runs (from the repository root, Debian's Python):

    /usr/bin/python3 workflows/case_study.py                    # the three coarse cases (4.9 s each)
    /usr/bin/python3 workflows/case_study.py --case 3           # one case
    /usr/bin/python3 workflows/case_study.py --report-only      # figures from finished runs
    /usr/bin/python3 workflows/case_study.py --preset paper --case 3 --report-only
    # a variant in its own directory (figures in DIR/results, docs/case_study.md untouched):
    /usr/bin/python3 workflows/case_study.py --runs runs/whole_record --set time.duration=20.0

A stopped run (session end, kill, Ctrl-C) continues from its checkpoint when the same command is
given again (docs/checkpoint.md; --no-resume starts it again).
"""
from __future__ import annotations

import argparse
import json
import pathlib
import shutil
import sys
import time

import numpy as np

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))

# ---------------------------------------------------------------------------------------------
# Parameters

SCENES = REPOSITORY / "workflows" / "scenes"
RUNS = REPOSITORY / "runs" / "case_study"
RESULTS = REPOSITORY / "workflows" / "results" / "case_study"
DOC = REPOSITORY / "docs" / "case_study.md"
CASES = {1: "case1_vertical", 2: "case2_oblique", 3: "case3_contact"}
CASE_LABELS = {1: "case 1 (vertical)", 2: "case 2 (oblique)", 3: "case 3 (oblique + contact)"}
LINING_MONITORS = ("A", "B", "C", "D")
INTERLAYER_MONITORS = ("I8_soft", "I8_hard")
INTERLAYER_PAIR = "wall_up_8"
WALL_PAIRS = ("wall_up_8", "wall_down_8", "wall_up_9", "wall_down_9")
CROWN_PAIR = "crown_9"
CM, MPA = 100.0, 1.0e-6

# The paper's numbers (Sec. 5; cm, MPa), by case. Relative displacements: left wall, right
# wall, crown relative to the floor (B, C, A against D here).
PAPER = {
    1: {"interlayer_max": 1.28, "lining_max": 6.83, "relative": {"B": 3.7, "C": 3.5, "A": 2.1},
        "s1_crown": 1.18, "s1_wall": 1.31},
    2: {"interlayer_max": 2.15, "lining_max": 8.14, "relative": {"B": 4.3, "C": 3.9, "A": 2.3},
        "s1_crown": 1.30, "s1_wall": 1.53},
    3: {"interlayer_max": 6.01, "interlayer_residual": 5.93, "D_wall": (0.71, 0.78), "D_crown": 0.75,
        "lining_max": 10.06, "relative": {"B": 5.9, "C": 4.8, "A": 3.0}, "s1_crown": 1.49, "s1_wall": 1.87},
}

# ---------------------------------------------------------------------------------------------
# Steps


def scene_path(case: int, preset: str) -> pathlib.Path:
    return SCENES / f"{CASES[case]}_{preset}.toml"


def run_dir(case: int, preset: str, runs: pathlib.Path = RUNS) -> pathlib.Path:
    return runs / f"case{case}_{preset}"


def run_case(case: int, preset: str, overrides=(), runs: pathlib.Path = RUNS, resume: bool = True) -> dict:
    """Runs one case's scene into RUNS/caseN_PRESET; returns run.json. A run stopped before its end (the
    checkpoint.npz of an unfinished run, docs/checkpoint.md) of the same scene and overrides is
    continued. A checkpoint of other settings is refused (SceneError naming the first key that
    differs: hours of a long run are not started again by a typo); resume=False starts the run
    again, the stopped one moved aside to caseN_PRESET.previous."""
    from pyfem import checkpoint, solver
    from pyfem.scene import load_scene

    scene = load_scene(scene_path(case, preset), overrides)
    out = run_dir(case, preset, runs)
    if resume and checkpoint.interrupted_run(out):
        saved = checkpoint.read_checkpoint(out, state=False)  # t and the fingerprint; solver.run reads the state
        saved.check_scene(scene)  # before the model is built: another scene is refused at once
        print(f"resuming {scene_path(case, preset).name} in {out} from t = {saved.t:.4g} s", flush=True)
        return solver.run(scene, out, resume=True)
    print(f"running {scene_path(case, preset).name} -> {out}", flush=True)
    return solver.run(scene, out)


def read_csv(path: pathlib.Path) -> dict:
    with open(path) as stream:
        header = stream.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(header)}


def displacement(columns: dict) -> np.ndarray:
    return np.column_stack([columns["ux"], columns["uy"], columns["uz"]])


def load_run(directory: pathlib.Path, finished_only: bool = True) -> dict | None:
    """run.json, monitors and pairs of a run, or None if it has no run.json or, with
    `finished_only`, has not finished (without it a run still going is read up to where it is)."""
    summary_path = directory / "run.json"
    if not summary_path.exists():
        return None
    summary = json.loads(summary_path.read_text())
    if finished_only and summary.get("status") != "finished":
        return None
    monitors = {path.stem: read_csv(path) for path in sorted((directory / "monitors").glob("*.csv"))}
    pairs = {path.stem: read_csv(path) for path in sorted((directory / "pairs").glob("*.csv"))} \
        if (directory / "pairs").exists() else {}
    return {"summary": summary, "monitors": monitors, "pairs": pairs, "dir": directory}


def case_numbers(run: dict) -> dict:
    """The comparison quantities of one run (m, Pa, -)."""
    monitors, pairs, summary = run["monitors"], run["pairs"], run["summary"]
    numbers = {}
    soft, hard = (monitors.get(name) for name in INTERLAYER_MONITORS)
    if soft is not None and hard is not None:
        relative = displacement(soft) - displacement(hard)
        magnitude = np.linalg.norm(relative, axis=1)
        numbers["interlayer_max"] = float(magnitude.max())
        numbers["interlayer_final"] = float(magnitude[-1])
    if INTERLAYER_PAIR in pairs:
        pair = pairs[INTERLAYER_PAIR]
        relative = np.column_stack([pair["dux"], pair["duy"], pair["duz"]])
        magnitude = np.linalg.norm(relative, axis=1)
        numbers["pair_max"] = float(magnitude.max())
        numbers["pair_residual"] = float(magnitude[-1])
        numbers["pair_final_state"] = summary["pairs"][INTERLAYER_PAIR]["final_state"]
    walls = [pairs[name]["D"] for name in WALL_PAIRS if name in pairs]
    if walls:
        late = pairs[WALL_PAIRS[0]]["t"] >= 0.5 * pairs[WALL_PAIRS[0]]["t"][-1]
        numbers["D_wall_range"] = (float(min(d.min() for d in walls)), float(max(d[late].max() for d in walls)))
        numbers["D_wall_final"] = [float(d[-1]) for d in walls]
    if CROWN_PAIR in pairs:
        numbers["D_crown_range"] = (float(pairs[CROWN_PAIR]["D"].min()), float(pairs[CROWN_PAIR]["D"][-1]))
    lining = {name: displacement(monitors[name]) for name in LINING_MONITORS if name in monitors}
    numbers["lining_peak"] = {name: float(np.linalg.norm(u, axis=1).max()) for name, u in lining.items()}
    numbers["lining_max"] = max(numbers["lining_peak"].values())
    if "D" in lining:
        numbers["relative_history"] = {name: float(np.linalg.norm(lining[name] - lining["D"], axis=1).max())
                                       for name in ("A", "B", "C") if name in lining}
        numbers["relative_peaks"] = {name: numbers["lining_peak"][name] - numbers["lining_peak"]["D"]
                                     for name in ("A", "B", "C") if name in lining}
        # The permanent part (the section's convergence as the yielded rock ratchets) and the horizontal
        # racking alone (x: across the cavern), which the relative maximum above mixes.
        numbers["relative_end"] = {name: float(np.linalg.norm(lining[name][-1] - lining["D"][-1]))
                                   for name in ("A", "B", "C") if name in lining}
        numbers["relative_horizontal"] = {name: float(np.abs(lining[name][:, 0] - lining["D"][:, 0]).max())
                                          for name in ("A", "B", "C") if name in lining}
    for key, name in (("crown", "A"), ("wall", "B")):
        columns = monitors.get(name, {})
        if "s1" in columns:
            numbers[f"s1_{key}"] = float(columns["s1"].max())
            numbers[f"s1_{key}_initial"] = float(columns["s1"][0])
            numbers[f"s1_dynamic_{key}"] = float(columns["s1_dynamic"].max())
    for name in ("A", "B"):  # the lining's damage at the monitors (0 without a damage law)
        columns = monitors.get(name, {})
        if "damage" in columns:
            numbers.setdefault("damage_monitor", {})[name] = (float(columns["damage"][0]), float(columns["damage"].max()))
    regions = summary.get("nonlinear_regions") or {}
    if regions:
        numbers["regions"] = {region: {key: values.get(key) for key in
                                       ("peak_damage", "damaged_volume", "yielded_volume", "volume",
                                        "yielded_points_near_zone_edge", "peak_crack_opening",
                                        "cracked_volume_by_opening")}
                              for region, values in regions.items()}
    static = summary.get("static")
    if static:
        numbers["static"] = {"stages": [[stage["name"], stage["iterations"], stage["residual"], stage["seconds"]]
                                        for stage in static["stages"]], "seconds": static["seconds"]}
    record = ((summary.get("scene") or {}).get("wave") or {}).get("motion", {}).get("record") or {}
    numbers["lead_in"] = record.get("lead_in")
    numbers["cost"] = {"wall_seconds": summary["wall_seconds"], "steps": summary["steps"], "dofs": summary["dofs"],
                       "ms_per_step": 1e3 * summary["seconds_per_step"], "dt": summary["dt"],
                       "duration": summary["scene"]["time"]["duration"], "cells": summary["cells"],
                       "energy_balance_error": summary["energy"]["balance_error"]}
    if summary.get("time_per_step"):
        numbers["cost"]["time_per_step"] = summary["time_per_step"]
    if "n_pairs" in summary:
        numbers["cost"]["pairs"] = summary["n_pairs"]
        numbers["pair_states_final"] = summary["pair_states_final"]
    return numbers


# -- figures ----------------------------------------------------------------------------------

def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure_input_record(preset: str, path: pathlib.Path) -> None:
    """Fig. 4: the processed record the scenes feed in (acceleration, velocity, displacement)."""
    from pyfem.scene import load_scene
    from pyfem.seismic.records import plot_record, read_record
    from pyfem.seismic.setup import input_waveform

    scene = load_scene(scene_path(2, preset))
    _, _, processed = input_waveform(scene)
    spec = scene["wave"]["motion"]["record"]
    plot_record(processed, path, raw=read_record(spec["file"], units=spec["units"], format=spec["format"]))


def figure_interlayer(runs: dict, path: pathlib.Path) -> None:
    """Fig. 6: x component of the interlayer relative displacement at the upstream wall."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    for case, run in runs.items():
        soft, hard = (run["monitors"].get(name) for name in INTERLAYER_MONITORS)
        if soft is not None and hard is not None:
            ax.plot(soft["t"], CM * (soft["ux"] - hard["ux"]), lw=1.0,
                    label=f"{CASE_LABELS[case]}: rock points 1.9 m each side")
        if INTERLAYER_PAIR in run["pairs"]:
            pair = run["pairs"][INTERLAYER_PAIR]
            ax.plot(pair["t"], CM * pair["dux"], "k", lw=1.2, label=f"{CASE_LABELS[case]}: node pair {INTERLAYER_PAIR}")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("relative displacement x (cm)")
    ax.set_title("interlayer relative displacement, interface_8, upstream wall (cf. paper Fig. 6)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_deterioration(run: dict, path: pathlib.Path) -> None:
    """Fig. 7: D(t) of the wall pairs and the crown pair (case 3)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    for name in (*WALL_PAIRS, CROWN_PAIR):
        if name in run["pairs"]:
            pair = run["pairs"][name]
            ax.plot(pair["t"], pair["D"], lw=1.6 if name == CROWN_PAIR else 0.9,
                    ls="-" if name == CROWN_PAIR else "--", label=name)
    ax.axhspan(0.71, 0.78, color="C3", alpha=0.1, label="paper: walls 0.71-0.78")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("D(t)")
    ax.set_title("deterioration factor D = eta gamma, case 3 (cf. paper Fig. 7)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_displacements(runs: dict, path: pathlib.Path) -> None:
    """Fig. 8: |u(t)| at A-D, one panel per case."""
    plt = _pyplot()
    fig, axes = plt.subplots(len(runs), 1, figsize=(8, 2.6 * len(runs)), sharex=True, squeeze=False)
    for ax, (case, run) in zip(axes[:, 0], runs.items()):
        for name in LINING_MONITORS:
            if name in run["monitors"]:
                columns = run["monitors"][name]
                ax.plot(columns["t"], CM * np.linalg.norm(displacement(columns), axis=1), lw=0.9, label=name)
        ax.set_ylabel("|u| (cm)")
        ax.set_title(CASE_LABELS[case], fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=4)
    axes[-1, 0].set_xlabel("t (s)")
    fig.suptitle("lining displacement at A (crown), B, C (walls), D (floor) (cf. paper Fig. 8)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_relative(numbers: dict, path: pathlib.Path) -> None:
    """Fig. 9: peak relative displacement of B, C, A against D, ours next to the paper's."""
    plt = _pyplot()
    names = ("B", "C", "A")
    fig, ax = plt.subplots(figsize=(8, 4))
    width = 0.13
    for k, case in enumerate(sorted(numbers)):
        ours = [CM * numbers[case]["relative_history"][name] for name in names]
        paper = [PAPER[case]["relative"][name] for name in names]
        x = np.arange(len(names)) + (k - 1) * 2.2 * width
        ax.bar(x - width / 2, ours, width, color=f"C{k}", label=f"{CASE_LABELS[case]}: ours max|u_X - u_D|")
        ax.bar(x + width / 2, paper, width, color=f"C{k}", alpha=0.4, hatch="//", label=f"{CASE_LABELS[case]}: paper")
    ax.set_xticks(np.arange(len(names)), ["B upstream wall - D", "C downstream wall - D", "A crown - D"])
    ax.set_ylabel("peak relative displacement (cm)")
    ax.set_title("relative displacement of the lining against the floor (cf. paper Fig. 9)")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figure_principal_stress(runs: dict, path: pathlib.Path) -> None:
    """Fig. 10: max principal stress at A and B: dynamic part (and total, dashed)."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for ax, name, title in zip(axes, ("A", "B"), ("A (crown)", "B (upstream wall)")):
        for case, run in runs.items():
            columns = run["monitors"].get(name, {})
            if "s1" not in columns:
                continue
            ax.plot(columns["t"], MPA * columns["s1_dynamic"], lw=0.9, color=f"C{case - 1}",
                    label=f"{CASE_LABELS[case]}: dynamic")
        ax.set_ylabel("s1 (MPa, tension +)")
        ax.set_title(f"{title}: max principal stress of the dynamic increment", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[-1].set_xlabel("t (s)")
    fig.suptitle("lining max principal stress (cf. paper Fig. 10); total = geostatic + dynamic in the CSVs",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def read_last_fields(directory: pathlib.Path) -> dict | None:
    """The last time of a run's fields.xdmf: points (m), cells, point and cell data, or None
    without fields (or without the damage fields the lining maps need)."""
    from pyfem.fields_file import read_fields

    path = directory / "fields.xdmf"
    if not path.exists():
        return None
    fields = read_fields(path)
    last = fields.steps[-1] if fields.steps else None
    if last is None or "damage" not in last[2]:
        return None
    t, point_data, cell_data = last
    return {"t": t, "points": fields.points, "cells": fields.cells, "point_data": point_data, "cell_data": cell_data}


def lining_cells(fields: dict, summary: dict) -> tuple[np.ndarray, np.ndarray]:
    """(cells, centroids) of the lining in the fields' mesh."""
    lining = np.flatnonzero(fields["cell_data"]["region"] == summary["regions"]["lining"])
    return lining, fields["points"][fields["cells"][lining]].mean(axis=1)


def section_angle(centroids: np.ndarray, centre_z: float) -> np.ndarray:
    """Position around the cavern's section (deg): the polar angle about (x = 0, z = centre_z), 90 at
    the crown, 0 the downstream wall (+x), -90 the floor, +-180 the upstream wall."""
    return np.degrees(np.arctan2(centroids[:, 2] - centre_z, centroids[:, 0]))


BAY_HALF_LENGTH = 10.0  # m: the soft-layer bay, |y| < this along the cavern (shaded in the lining maps)


def section_parts(angle: np.ndarray) -> dict:
    """The lining's cells by part of the section, from their `section_angle` (as seen from the
    section's mid-height): crown, walls (both), floor."""
    return {"crown": (angle > 45.0) & (angle < 135.0), "walls": (np.abs(angle) <= 45.0) | (np.abs(angle) >= 135.0),
            "floor": (angle < -45.0) & (angle > -135.0)}


def draw_unrolled(ax, angle: np.ndarray, y: np.ndarray, values: np.ndarray, title: str, **colours):
    """One lining unrolled on `ax` (position around the section against y along the cavern),
    coloured by `values` (the largest drawn last, on top; `colours`: cmap, vmin/vmax or norm), the
    soft-layer bay shaded; returns the scatter for the colour bar."""
    order = np.argsort(values, kind="stable")
    image = ax.scatter(angle[order], y[order], c=values[order], s=5, marker="s", **colours)
    ax.axhspan(-BAY_HALF_LENGTH, BAY_HALF_LENGTH, color="k", alpha=0.06)
    ax.set_xticks([-180, -90, 0, 90, 180], ["up. wall", "floor", "down. wall", "crown", "up. wall"], fontsize=7)
    ax.set_title(title, fontsize=8)
    return image


def figure_lining_damage(runs: dict, path_damage: pathlib.Path, path_type: pathlib.Path,
                         path_opening: pathlib.Path | None = None) -> dict:
    """Figs. 11-12: the lining unrolled (position around the section against y along the cavern),
    coloured by damage and by damage type (tension, shear) at the end of each run, and, where the
    fields have it, by the crack band's opening (mm, log scale: graded where the damage is not);
    returns per case the damaged share of the lining and the peak damage in the soft-layer bay
    (|y| < 10 m), with the opening its largest value and the share opened beyond 0.3 mm, in the bay
    and by part of the section (crown, walls, floor)."""
    from matplotlib.colors import ListedColormap, LogNorm

    plt = _pyplot()
    fields = {case: read_last_fields(run["dir"]) for case, run in runs.items()}
    fields = {case: f for case, f in fields.items() if f is not None}
    if not fields:
        return {}
    figures = {}
    summary = {}
    maps = [("damage", path_damage), ("damage_type", path_type)]
    if path_opening is not None and all("crack_opening" in f["cell_data"] for f in fields.values()):
        maps.append(("crack_opening", path_opening))
    for key, path in maps:
        fig, axes = plt.subplots(1, len(fields), figsize=(4.6 * len(fields) + 1.6, 5.2), squeeze=False, sharey=True)
        for ax, (case, f) in zip(axes[0], sorted(fields.items())):
            cells, centroids = lining_cells(f, runs[case]["summary"])
            angle = section_angle(centroids, centre_z=0.5 * centroids[:, 2].max())
            values = f["cell_data"][key][cells]
            bay = np.abs(centroids[:, 1]) < BAY_HALF_LENGTH
            title = f"{CASE_LABELS[case]}, t = {f['t']:.2f} s"
            if key == "damage":
                image = draw_unrolled(ax, angle, centroids[:, 1], values, title, cmap="inferno_r", vmin=0.0, vmax=1.0)
                summary[case] = {"t": float(f["t"]), "damaged_share": float(np.mean(values > 0.01)),
                                 "peak_damage_bay": float(values[bay].max(initial=0.0)),
                                 "mean_damage_bay": float(values[bay].mean()) if bay.any() else 0.0}
            elif key == "crack_opening":
                mm = np.maximum(1e3 * values, 1e-3)  # below a micrometre: shown as 1 um
                image = draw_unrolled(ax, angle, centroids[:, 1], mm, title, cmap="inferno_r",
                                      norm=LogNorm(vmin=1e-3, vmax=300.0))
                summary[case].update({
                    "peak_opening_mm": float(mm.max(initial=0.0)),
                    "opened_0.3mm_share": float(np.mean(mm > 0.3)),
                    "opened_0.3mm_share_bay": float(np.mean(mm[bay] > 0.3)) if bay.any() else 0.0,
                    "median_opening_mm": {name: float(np.median(mm[where])) if where.any() else 0.0
                                          for name, where in section_parts(angle).items()}})
            else:
                image = draw_unrolled(ax, angle, centroids[:, 1], values, title,
                                      cmap=ListedColormap(["0.85", "C3", "C0"]), vmin=-0.5, vmax=2.5)
        axes[0][0].set_ylabel("y along the cavern (m)")
        colorbar = fig.colorbar(image, ax=axes[0].tolist(), shrink=0.8)
        if key == "damage_type":
            colorbar.set_ticks([0, 1, 2], labels=["none", "tension", "shear"])
            title = "lining damage type at the end of the run (cf. paper Fig. 12); shaded: the soft-layer bay"
        elif key == "crack_opening":
            colorbar.set_label("largest crack opening (mm)")
            title = ("lining crack opening at its largest (the crack band's h d_t kappa_t), unrolled; "
                     "shaded: the soft-layer bay")
        else:
            colorbar.set_label("damage (-)")
            title = "lining damage at the end of the run, unrolled (cf. paper Fig. 11); shaded: the soft-layer bay"
        fig.suptitle(title, fontsize=9)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        figures[key] = path.name
    return summary


def figure_deformation(runs: dict, path: pathlib.Path) -> dict:
    """Fig. 13: deformation modes from the monitors: (a) the walls' x displacement relative to the
    floor at the time of the largest B - D offset, (b) the soft/hard relative displacement across
    interface_8 at the upstream wall (I8_soft - I8_hard) against time. Returns per case the upper
    structure's largest horizontal offset to the floor (paper: 3.1-4.2 cm)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    offsets = {}
    for case, run in runs.items():
        monitors = run["monitors"]
        if not all(name in monitors for name in ("A", "B", "C", "D")):
            continue
        t = monitors["D"]["t"]
        horizontal = {name: monitors[name]["ux"] - monitors["D"]["ux"] for name in ("A", "B", "C")}
        offsets[case] = {name: float(np.abs(values).max()) for name, values in horizontal.items()}
        for name, style in (("A", "-"), ("B", "--"), ("C", ":")):
            axes[0].plot(t, CM * horizontal[name], style, color=f"C{case - 1}", lw=0.9,
                         label=f"{CASE_LABELS[case]}: {name} - D")
        soft, hard = monitors.get(INTERLAYER_MONITORS[0]), monitors.get(INTERLAYER_MONITORS[1])
        if soft is not None and hard is not None:
            axes[1].plot(t, CM * np.linalg.norm(displacement(soft) - displacement(hard), axis=1),
                         color=f"C{case - 1}", lw=0.9, label=CASE_LABELS[case])
    axes[0].set_ylabel("x displacement relative to the floor D (cm)")
    axes[0].set_title("upper structure against the lower: crown A, walls B, C (cf. Fig. 13b)", fontsize=8)
    axes[1].set_ylabel("|u(I8_soft) - u(I8_hard)| (cm)")
    axes[1].set_title("across the interface at the upstream wall (cf. Fig. 13d)", fontsize=8)
    for ax in axes:
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return offsets


# -- table --------------------------------------------------------------------------------------

def _cm(value) -> str:
    return "-" if value is None else f"{CM * value:.2f}"


def _paper(case: int, key: str, fmt="{:.2f}") -> str:
    value = PAPER[case].get(key)
    return "-" if value is None else fmt.format(value)


PAPER_DAMAGE = {1: "~0.3", 2: "", 3: "up to 0.9"}
"""The paper's lining damage (Figs. 11-12): about 0.3 in case 1, up to 0.9 in case 3."""


def comparison_table(numbers: dict, preset: str) -> str:
    """Markdown: one row per quantity, ours | paper for each case."""
    cases = sorted(numbers)
    head = "| quantity | " + " | ".join(f"case {c} ours | case {c} paper" for c in cases) + " |"
    rule = "|---|" + "---:|---:|" * len(cases)
    rows = []

    def row(label, ours, paper):
        rows.append(f"| {label} | " + " | ".join(f"{ours(c)} | {paper(c)}" for c in cases) + " |")

    row("interlayer relative displacement, max (cm): rock points 1.9 m each side of interface_8",
        lambda c: _cm(numbers[c].get("interlayer_max")), lambda c: _paper(c, "interlayer_max"))
    row("same, at the end of the run (cm)",
        lambda c: _cm(numbers[c].get("interlayer_final")), lambda c: _paper(c, "interlayer_residual"))
    row("node pair wall_up_8 relative displacement, max (cm)",
        lambda c: _cm(numbers[c].get("pair_max")), lambda c: _paper(c, "interlayer_max") if c == 3 else "-")
    row("node pair wall_up_8, residual at the end (cm) / final state",
        lambda c: (f"{_cm(numbers[c]['pair_residual'])} / {numbers[c]['pair_final_state']}"
                   if "pair_residual" in numbers[c] else "-"),
        lambda c: _paper(c, "interlayer_residual"))
    row("D(t) at the wall pairs: min .. max over the second half",
        lambda c: ("{:.3f} .. {:.3f}".format(*numbers[c]["D_wall_range"]) if "D_wall_range" in numbers[c] else "-"),
        lambda c: "0.71 .. 0.78" if c == 3 else "-")
    row("D(t) at the crown pair: min / final",
        lambda c: ("{:.3f} / {:.3f}".format(*numbers[c]["D_crown_range"]) if "D_crown_range" in numbers[c] else "-"),
        lambda c: "~0.75" if c == 3 else "-")
    row("lining displacement, max over A-D (cm, absolute)",
        lambda c: _cm(numbers[c]["lining_max"]), lambda c: _paper(c, "lining_max"))
    for name, where in (("B", "upstream wall B"), ("C", "downstream wall C"), ("A", "crown A")):
        row(f"{where} relative to floor D: max_t abs(u_X - u_D) (cm)",
            lambda c, n=name: _cm(numbers[c]["relative_history"][n]),
            lambda c, n=name: f"{PAPER[c]['relative'][n]:.1f}")
        row(f"{where} relative to floor D: peak abs(u_X) - peak abs(u_D) (cm)",
            lambda c, n=name: _cm(numbers[c]["relative_peaks"][n]), lambda c: "")
        row(f"{where} relative to floor D: abs(u_X - u_D) at the end, the permanent part (cm)",
            lambda c, n=name: _cm(numbers[c]["relative_end"][n]), lambda c: "")
        row(f"{where} relative to floor D, horizontal (x) only: max_t abs(u_x(X) - u_x(D)) (cm)",
            lambda c, n=name: _cm(numbers[c]["relative_horizontal"][n]), lambda c: "")
    for key, where in (("crown", "crown A"), ("wall", "wall B")):
        row(f"max principal stress at {where}, dynamic increment alone (MPa)",
            lambda c, k=key: f"{MPA * numbers[c][f's1_dynamic_{k}']:.2f}", lambda c, k=key: _paper(c, f"s1_{k}"))
        row(f"max principal stress at {where}, total = geostatic + dynamic (MPa; initial value)",
            lambda c, k=key: f"{MPA * numbers[c][f's1_{k}']:.2f} ({MPA * numbers[c][f's1_{k}_initial']:.2f})",
            lambda c: "")
    row("lining damage at crown A: after the static stage / max during the run",
        lambda c: ("{:.2f} / {:.2f}".format(*numbers[c]["damage_monitor"]["A"])
                   if "A" in numbers[c].get("damage_monitor", {}) else "-"), lambda c: PAPER_DAMAGE.get(c, ""))
    row("lining damage at wall B: after the static stage / max during the run",
        lambda c: ("{:.2f} / {:.2f}".format(*numbers[c]["damage_monitor"]["B"])
                   if "B" in numbers[c].get("damage_monitor", {}) else "-"), lambda c: "")
    row("lining: damaged volume (d > 0.01) / lining volume (m^3), end of run",
        lambda c: (f"{numbers[c]['regions']['lining']['damaged_volume']:.0f} / "
                   f"{numbers[c]['regions']['lining']['volume']:.0f}" if "lining" in numbers[c].get("regions", {})
                   else "-"), lambda c: "")
    row("lining: largest crack opening (mm) / volume opened beyond 0.3 mm (m^3), end of run",
        lambda c: (f"{1e3 * numbers[c]['regions']['lining']['peak_crack_opening']:.2f} / "
                   f"{numbers[c]['regions']['lining']['cracked_volume_by_opening']['0.3']:.0f}"
                   if (numbers[c].get("regions", {}).get("lining") or {}).get("peak_crack_opening") is not None
                   else "-"),
        lambda c: "")
    row("rock yielded volume in the Mohr-Coulomb zone (m^3; yielded points at the zone's edge)",
        lambda c: (" + ".join(f"{v['yielded_volume']:.0f}" for r, v in numbers[c]["regions"].items() if r != "lining")
                   + " (" + " + ".join(str(v["yielded_points_near_zone_edge"]) for r, v in
                                       numbers[c]["regions"].items() if r != "lining") + ")"
                   if numbers[c].get("regions") else "-"), lambda c: "")
    row("static stage: relaxation steps per stage, out-of-balance, seconds",
        lambda c: ("; ".join(f"{n} {k}, {r:.1e}, {t:.0f} s" for n, k, r, t in numbers[c]["static"]["stages"])
                   if "static" in numbers[c] else "-"), lambda c: "")
    lead_ins = {c: numbers[c].get("lead_in") for c in cases}
    title = f"Preset `{preset}`. Our runs cover time.duration = " + ", ".join(
        f"{numbers[c]['cost']['duration']:g} s (case {c})" for c in cases) + \
        " of motion (t includes the record's filter lead-in: " + ", ".join(
            f"{lead_ins[c]:g} s" if lead_ins[c] is not None else "5.1 s" for c in cases) + ")."
    return title + "\n\n" + "\n".join([head, rule, *rows]) + "\n"


def cost_table(numbers_by_preset: dict) -> str:
    """Markdown: wall time, steps, dofs, time per step of each run."""
    lines = ["| run | cells | dofs | contact pairs | dt (s) | motion (s) | steps | wall (s) | ms/step | energy balance |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for preset, numbers in numbers_by_preset.items():
        for case in sorted(numbers):
            c = numbers[case]["cost"]
            lines.append(f"| case {case} {preset} | {c['cells']} | {c['dofs']} | {c.get('pairs', '-')} | {c['dt']:.4g} | "
                         f"{c['duration']:g} | {c['steps']} | {c['wall_seconds']:.0f} | {c['ms_per_step']:.2f} | "
                         f"{c['energy_balance_error']:.1e} |")
    parts = ("stiffness", "element_loop", "input_forces", "contact", "update", "exchange", "merge", "output", "other")
    split = [(f"case {case} {preset}", numbers[case]["cost"]["time_per_step"]) for preset, numbers in
             numbers_by_preset.items() for case in sorted(numbers) if numbers[case]["cost"].get("time_per_step")]
    if split:
        shown = [part for part in parts if any(part in phases for _, phases in split)]
        lines += ["", "Time per step by part (ms per step, share of the time loop; run.json \"time_per_step\": the "
                  "kernel's phases, the samples' output, and the rest of the loop):", "",
                  "| run | " + " | ".join(part.replace("_", " ") for part in shown) + " |",
                  "|---" + "|---:" * len(shown) + "|"]
        for label, phases in split:
            lines.append(f"| {label} | " + " | ".join(
                f"{phases[part]['ms_per_step']:.2f} ({100 * phases[part]['share']:.0f} %)" if part in phases else "-"
                for part in shown) + " |")
    return "\n".join(lines) + "\n"


def update_doc(text: str, marker: str = "case_study.py") -> None:
    """Replaces a generated block of docs/case_study.md: the one between the markers
    <!-- MARKER: start --> and <!-- MARKER: end -->."""
    start, end = f"<!-- {marker}: start -->", f"<!-- {marker}: end -->"
    if not DOC.exists():
        return
    doc = DOC.read_text()
    if start not in doc or end not in doc:
        return
    before, rest = doc.split(start, 1)
    _, after = rest.split(end, 1)
    DOC.write_text(before + start + "\n" + text + end + after)


def report(presets=("coarse", "paper"), cases=tuple(CASES), runs_dir: pathlib.Path = RUNS,
           results: pathlib.Path = RESULTS, doc: bool = True) -> dict:
    """Figures, comparison.md and summary.json from the finished runs of the presets.

    Args:
        presets: scene sizes to look for ("coarse", "paper").
        cases: case numbers to look for; a case without a finished run is left out.
        runs_dir: where the run directories caseN_PRESET are.
        results: where figures and tables go.
        doc: also replace the generated block of docs/case_study.md.

    Returns:
        {preset: {case: numbers}} of the runs found.
    """
    found = {preset: {case: run for case in cases if (run := load_run(run_dir(case, preset, runs_dir))) is not None}
             for preset in presets}
    if not any(found.values()):  # a fresh clone: nothing to report, and nothing already reported is erased
        print(f"report: no finished run of {', '.join(presets)} in {runs_dir}: nothing written (run the cases "
              "first, or --runs DIR)", file=sys.stderr)
        return {}
    missing = [preset for preset, runs in found.items() if not runs]
    if doc and missing:  # a partial set would drop the other preset's rows from the generated table
        print(f"report: no finished run for preset {', '.join(missing)} in {runs_dir}: docs/case_study.md "
              "left as it is", file=sys.stderr)
        doc = False
    results.mkdir(parents=True, exist_ok=True)
    numbers_by_preset, tables = {}, []
    for preset in presets:
        runs = found[preset]
        if not runs:
            continue
        suffix = "" if preset == "coarse" else f"_{preset}"
        numbers = {case: case_numbers(run) for case, run in runs.items()}
        numbers_by_preset[preset] = numbers
        figure_interlayer(runs, results / f"fig6_interlayer{suffix}.png")
        if 3 in runs and runs[3]["pairs"]:
            figure_deterioration(runs[3], results / f"fig7_deterioration{suffix}.png")
        figure_displacements(runs, results / f"fig8_displacement{suffix}.png")
        figure_relative(numbers, results / f"fig9_relative{suffix}.png")
        figure_principal_stress(runs, results / f"fig10_principal_stress{suffix}.png")
        lining = figure_lining_damage(runs, results / f"fig11_lining_damage{suffix}.png",
                                      results / f"fig12_damage_type{suffix}.png",
                                      results / f"fig11b_crack_opening{suffix}.png")
        offsets = figure_deformation(runs, results / f"fig13_deformation{suffix}.png")
        for case, run in runs.items():  # the static stage's stresses and plastic zone, as the run drew them
            section = run["dir"] / "static" / "section_stress.png"
            if section.exists():
                shutil.copyfile(section, results / f"static_case{case}{suffix}.png")
        for case in numbers:
            if case in lining:
                numbers[case]["lining_damage_map"] = lining[case]
            if case in offsets:
                numbers[case]["upper_structure_offset"] = offsets[case]
        tables.append(comparison_table(numbers, preset))
    figure_input_record("coarse", results / "fig4_input_record.png")
    text = "\n".join(tables) + "\nRun costs (this 2-core machine):\n\n" + cost_table(numbers_by_preset)
    (results / "comparison.md").write_text(text)
    (results / "summary.json").write_text(json.dumps({"paper": PAPER, "ours": numbers_by_preset}, indent=2,
                                                     default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v)))
    if doc:
        update_doc(text)
    print(text)
    return numbers_by_preset


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", type=int, choices=sorted(CASES), action="append",
                        help="run/report this case only (repeatable; default all three)")
    parser.add_argument("--preset", choices=("coarse", "paper"), default="coarse",
                        help="scene size: the coarse mesh (default) or the paper's")
    parser.add_argument("--report-only", action="store_true", help="read finished run directories; run nothing")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="scene override for the runs, e.g. --set time.duration=20.0")
    parser.add_argument("--no-resume", dest="resume", action="store_false",
                        help="start every run again even where a stopped run of the same settings left a "
                             "checkpoint (default: continue it)")
    parser.add_argument("--runs", type=pathlib.Path, default=None, metavar="DIR",
                        help=f"run directories caseN_PRESET here (default {RUNS}); with it, the figures go to "
                             "DIR/results and docs/case_study.md is left alone (a variant, e.g. --set "
                             "time.duration=20.0)")
    args = parser.parse_args(argv)
    cases = args.case or sorted(CASES)
    runs = args.runs if args.runs is not None else RUNS
    if not args.report_only:
        from pyfem.scene import SceneError

        for case in cases:
            start = time.perf_counter()
            try:
                summary = run_case(case, args.preset, args.overrides, runs=runs, resume=args.resume)
            except SceneError as error:  # one line, exit 2; --no-resume starts a stopped run again
                print(f"case {case}: {error} (or --no-resume)", file=sys.stderr)
                return 2
            print(f"case {case}: {summary['steps']} steps, {summary['dofs']} dofs, "
                  f"{time.perf_counter() - start:.0f} s", flush=True)
    # The report always covers every finished run of both sizes, so one case's rerun
    # refreshes the figures without dropping the others.
    if args.runs is None:
        numbers = report()
    else:
        numbers = report(runs_dir=runs, results=runs / "results", doc=False)
    return 0 if numbers else 2


if __name__ == "__main__":
    sys.exit(main())

"""Variants of the case study's case 3 on the coarse mesh: the interfaces on three meshes, the rock's
strength as the cause of the deformation gap, and the friction's normal lag.

The case study (workflows/case_study.py, docs/case_study.md) leaves five questions that one run of
the scene cannot answer:

1. **Do the interlayer quantities converge with the mesh?** The interlayer relative displacement
   at the wall and the deterioration D(t) of the wall and crown pairs were measured on two meshes
   (the coarse and the paper-scale one), which differ in their extents as well as in their cells,
   so they are not a refinement sequence. Group "mesh" runs the coarse scene with the size along the
   cavern, `mesh.parameters.h_cavern`, at 4.5 (the scene's), 3.0 and 2.0 m: a constant ratio of 1.5
   with everything else fixed (the extents, the 0.5 m first rock ring and lining cells, hence the
   same time step; the grading away from the cavern): 43 904, 93 680 and 203 086 cells. Three
   meshes give the observed order and a Richardson estimate of the converged value, and with it
   the grid convergence index (Roache's GCI, safety factor 1.25) of the finest mesh:
   `convergence()`.
2. **Is the rock's strength what makes our section deform 2.5-10x the paper's?** With elastic rock
   the section racks like the paper's; with Table 1's strengths under 300 m of cover the rock
   around the unsupported opening yields through the whole plastic zone. The paper's support
   (systematic bolting, shotcrete, the excavation sequence) is not given; bolted rock is commonly
   modelled as rock of raised cohesion. Group "strength" runs the scene with the cohesion of both
   rocks in the plastic zone raised 2x and 4x (friction angle and tension cut-off as Table 1).
3. **What does the rock's damage change?** The scenes run the rock perfectly plastic (damage_max = 0):
   its plastic-strain damage softened without regularisation and localised the coarse mesh's stage.
   With the crack band (`damage_plastic_displacement`, docs/materials.md) a cell's damage follows
   the plastic displacement across it; group "damage" runs the scene with the rock's damage on
   (d_max 0.9, u_ref = 1 cm: kappa_ref 0.005 in a 2 m cell).
4. **Would weaker interfaces slip by centimetres?** Table 1 gives the interfaces c = 1.0 MPa and
   30 deg; a clay-filled bedding plane may have a tenth of that cohesion and 20 deg. Group
   "interface" runs the scene with c = 0.1 MPa, 20 deg (static and dynamic) and a tensile strength
   of 0.1 MPa.
5. **How much do the friction's normal-stress lag's L and V* move the answer?** They are properties
   of the interface for which we have no values for the paper's rocks (docs/interface_slip_accuracy.md);
   group "lag" runs the scene with `[contact.normal_lag]` at L = 1 cm and 10 cm (V* = 1 m/s), against
   the scene without it (L -> 0 is no lag).

Each variant is the coarse case-3 scene with `--set` overrides over 3 s (the 1 s lead-in and the
record's first 2 s, which hold its PGA): the window `make run` covers. The finest mesh runs on the
distributed model with 2 ranks (a third of the whole model's memory, docs/scaling.md).

    /usr/bin/python3 workflows/case_sensitivity.py                  # every variant, then the report
    /usr/bin/python3 workflows/case_sensitivity.py --group mesh     # one group
    /usr/bin/python3 workflows/case_sensitivity.py --report-only    # read finished runs

Runs go to runs/case_sensitivity/NAME (a stopped run continues from its checkpoint when the same
command is given again); the table goes to workflows/results/case_sensitivity.csv and .md, each
group's histories to workflows/results/case_sensitivity_GROUP.png (docs/case_study.md's section "The
interfaces on three meshes, the rock's strength and the normal lag" summarises them; a block between
the markers <!-- case_sensitivity.py: start/end --> of that page, where there is one, is replaced).
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import pathlib
import subprocess
import sys

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))
sys.path.insert(0, str(REPOSITORY / "workflows"))

import case_study  # noqa: E402  (workflows/case_study.py: load_run, case_numbers, update_doc)
from pyfem.scene import PRESET_STRENGTHS  # noqa: E402

PYTHON = "/usr/bin/python3"
SCENE = REPOSITORY / "workflows" / "scenes" / "case3_contact_coarse.toml"
RUNS = REPOSITORY / "runs" / "case_sensitivity"
RESULTS = REPOSITORY / "workflows" / "results"
DURATION = 2.0          # s of record time: its first 2 s (its PGA at 2.0 s), after the 1 s lead-in at t < 0
REFINEMENT = 1.5        # ratio of neighbouring meshes' h_cavern in group "mesh"
GCI_SAFETY = 1.25       # Roache's safety factor for a three-mesh study
MARKER = "case_sensitivity.py"
TABLE1_COHESION = {rock: PRESET_STRENGTHS[rock]["cohesion"] for rock in ("sandstone", "non_sandstone")}  # Pa


@dataclasses.dataclass(frozen=True)
class Variant:
    name: str
    group: str
    label: str
    overrides: tuple = ()
    ranks: int = 1          # > 1: mpirun, the distributed model
    h_cavern: float | None = None


def _cohesion(factor: float) -> tuple:
    return tuple(f"materials.{rock}.plasticity.cohesion={factor * c:g}" for rock, c in TABLE1_COHESION.items())


def _lag(length: float) -> tuple:
    return (f"contact.normal_lag.length={length:g}", "contact.normal_lag.velocity=1.0")


VARIANTS = (
    Variant("mesh_h4.5", "mesh", "h_cavern 4.5 m (the scene)", h_cavern=4.5),
    Variant("mesh_h3.0", "mesh", "h_cavern 3.0 m", ("mesh.parameters.h_cavern=3.0",), h_cavern=3.0),
    Variant("mesh_h2.0", "mesh", "h_cavern 2.0 m (2 ranks, distributed)",
            ("mesh.parameters.h_cavern=2.0", "parallel.model=distributed"), ranks=2, h_cavern=2.0),
    Variant("cohesion_x2", "strength", "rock cohesion x2 (2.2 / 0.7 MPa)", _cohesion(2.0)),
    Variant("cohesion_x4", "strength", "rock cohesion x4 (4.4 / 1.4 MPa)", _cohesion(4.0)),
    Variant("rock_damage", "damage", "rock damage on, crack band u_ref = 1 cm",
            tuple(f"materials.{rock}.plasticity.{key}" for rock in TABLE1_COHESION
                  for key in ("damage_max=0.9", "damage_plastic_displacement=0.01"))),
    Variant("weak_interfaces", "interface", "interfaces c 0.1 MPa, 20 deg (Table 1: 1.0 MPa, 30 deg)",
            ("contact.cohesion=1.0e5", "contact.friction_angle=20.0", "contact.dynamic_friction_angle=20.0",
             "contact.tensile_strength=1.0e5")),
    Variant("lag_10cm", "lag", "normal lag L = 10 cm, V* = 1 m/s", _lag(0.1)),
    Variant("lag_1cm", "lag", "normal lag L = 1 cm, V* = 1 m/s", _lag(0.01)),
)
GROUPS = ("mesh", "strength", "damage", "interface", "lag")


def command(variant: Variant, runs: pathlib.Path = RUNS) -> list[str]:
    """The command line that runs one variant (with --resume when a checkpoint is there)."""
    from pyfem import checkpoint

    out = runs / variant.name
    line = [PYTHON, "-m", "pyfem", "run", str(SCENE), "--out", str(out), "--set", f"time.duration={DURATION}"]
    for override in variant.overrides:
        line += ["--set", override]
    if checkpoint.interrupted_run(out):
        line.append("--resume")
    if variant.ranks > 1:
        line = ["mpirun", "--allow-run-as-root", "-q", "--bind-to", "none", "-n", str(variant.ranks)] + line
    return line


# ---------------------------------------------------------------------------------------------
# Three meshes


def convergence(values: tuple, ratio: float = REFINEMENT, safety: float = GCI_SAFETY) -> dict:
    """Observed order, Richardson estimate and grid convergence index of three meshes.

    Args:
        values: the quantity on the coarse, medium and fine mesh (sizes h, h / ratio, h / ratio^2).
        ratio: the refinement ratio between neighbours.
        safety: the GCI's safety factor (1.25 for three meshes, Roache 1998).

    Returns:
        {"status", "order", "extrapolated", "gci_fine"}: status "converging" (the two changes have one
        sign and the second is the smaller: order > 0, gci_fine relative to the fine value), or, with
        order, extrapolated and gci_fine None, "oscillating" (the changes alternate in sign),
        "diverging" (the second change is the larger: refinement moves the value more, not less) or
        "unchanged" (a change within 1e-9 of the values, round-off): the sequence is not in its
        asymptotic range.
    """
    coarse, medium, fine = (float(v) for v in values)
    first, second = medium - coarse, fine - medium
    none = {"order": None, "extrapolated": None, "gci_fine": None}
    zero = 1e-9 * max(abs(coarse), abs(medium), abs(fine))  # round-off of a quantity that did not move
    if abs(second) <= zero or abs(first) <= zero:
        return {"status": "unchanged", **none}
    if first * second < 0.0:
        return {"status": "oscillating", **none}
    if abs(second) >= abs(first):
        return {"status": "diverging", **none}
    order = math.log(abs(first / second)) / math.log(ratio)
    growth = ratio ** order - 1.0
    extrapolated = fine + second / growth
    gci = safety * abs(second / fine) / growth if fine != 0.0 else None
    return {"status": "converging", "order": order, "extrapolated": extrapolated, "gci_fine": gci}


# ---------------------------------------------------------------------------------------------
# Report

# The rows: (key, label, unit scale, unit) from case_study.case_numbers.
ROWS = (
    ("stage_displacement", "static stage: largest displacement when the excavation is released", 100, "cm"),
    ("stage_yielded", "static stage: rock yielded at its end", 1, "m^3"),
    ("stage_steps", "static stage: relaxation steps, excavation + support", 1, "-"),
    ("interlayer_max", "interlayer relative displacement, rock points 1.9 m either side of interface_8: max", 100, "cm"),
    ("interlayer_final", "same, at 3 s", 100, "cm"),
    ("pair_max", "node pair wall_up_8: max relative displacement", 1000, "mm"),
    ("crown_pair_max", "node pair crown_9 (interface_9, 0.5 m above the crown): max relative displacement", 100, "cm"),
    ("wall_pairs_bonded", "of the four wall pairs, still bonded at 3 s", 1, "-"),
    ("D_wall_min", "D(t) at the wall pairs: min", 1, "-"),
    ("D_crown_min", "D(t) at the crown pair: min", 1, "-"),
    ("relative_B", "upstream wall B against floor D: max over t of abs(u_B - u_D)", 100, "cm"),
    ("relative_C", "downstream wall C against floor D", 100, "cm"),
    ("relative_A", "crown A against floor D", 100, "cm"),
    ("horizontal_B", "B against D, horizontal (x) only", 100, "cm"),
    ("horizontal_A", "A against D, horizontal (x) only", 100, "cm"),
    ("s1_dynamic_crown", "max principal stress at crown A, dynamic", 1e-6, "MPa"),
    ("s1_dynamic_wall", "max principal stress at wall B, dynamic", 1e-6, "MPa"),
    ("yielded", "rock yielded in the plastic zone, both rocks", 1, "m^3"),
    ("lining_damaged", "lining damaged (d > 0.01; the whole lining is 28 053-28 100)", 1, "m^3"),
    ("sliding", "pairs sliding or separated at 3 s", 1, "-"),
    ("energy", "energy balance error", 1, "-"),
    ("static_seconds", "static stage (excavation, support)", 1, "s"),
    ("wall_seconds", "wall time (2 cores; static stage, set-up check and time loop)", 1, "s"),
    ("ms_per_step", "time loop per (fine) step", 1, "ms"),
    ("ms_stiffness", "of which the stiffness product", 1, "ms"),
    ("ms_element_loop", "of which the element loop (rock plasticity, lining damage)", 1, "ms"),
    ("ms_contact", "of which contact", 1, "ms"),
    ("ms_input_forces", "of which the input forces", 1, "ms"),
    ("ms_output", "of which output", 1, "ms"),
)
STATUS_WORDS = {"oscillating": "oscillates", "diverging": "changes grow", "unchanged": "unchanged"}
NOT_CONVERGED = ("energy", "wall_seconds", "static_seconds", "stage_steps", "wall_pairs_bonded", "lining_damaged")
"""Rows that are costs or counts, without an observed order."""
PARTS = ("stiffness", "element_loop", "contact", "input_forces", "output")


def stage_numbers(directory: pathlib.Path) -> dict:
    """The static stage's rows from DIR/static/static.json (written when the stage ends, before the
    motion), {} without it."""
    import json

    path = directory / "static" / "static.json"
    if not path.exists():
        return {}
    static = json.loads(path.read_text())
    stages = {stage["name"]: stage for stage in static["stages"]}
    regions = static.get("regions") or {}
    return {"stage_displacement": stages.get("excavation", {}).get("max_displacement"),
            "stage_yielded": sum(regions[rock]["yielded_volume"] for rock in TABLE1_COHESION if rock in regions),
            "stage_steps": sum(stage["iterations"] for stage in static["stages"])}


def flat_numbers(numbers: dict, run_pairs: dict | None = None) -> dict:
    """The rows' values (SI) from case_study.case_numbers' dict and run.json's "pairs" (the pair
    monitors' summaries)."""
    flat = {key: numbers.get(key) for key in ("interlayer_max", "interlayer_final", "pair_max")}
    pairs = run_pairs or {}
    if case_study.CROWN_PAIR in pairs:
        flat["crown_pair_max"] = pairs[case_study.CROWN_PAIR]["max_relative_displacement"]
    walls = [pairs[name]["final_state"] for name in case_study.WALL_PAIRS if name in pairs]
    if walls:
        flat["wall_pairs_bonded"] = sum(state == "bonded" for state in walls)
    if "D_wall_range" in numbers:
        flat["D_wall_min"] = numbers["D_wall_range"][0]
    if "D_crown_range" in numbers:
        flat["D_crown_min"] = numbers["D_crown_range"][0]
    for name in ("A", "B", "C"):
        flat[f"relative_{name}"] = numbers.get("relative_history", {}).get(name)
        flat[f"horizontal_{name}"] = numbers.get("relative_horizontal", {}).get(name)
    flat["s1_dynamic_crown"] = numbers.get("s1_dynamic_crown")
    flat["s1_dynamic_wall"] = numbers.get("s1_dynamic_wall")
    regions = numbers.get("regions", {})
    yielded = [regions[rock]["yielded_volume"] for rock in TABLE1_COHESION if rock in regions
               and regions[rock].get("yielded_volume") is not None]
    flat["yielded"] = sum(yielded) if yielded else None
    flat["lining_damaged"] = (regions.get("lining") or {}).get("damaged_volume")
    states = numbers.get("pair_states_final") or {}
    flat["sliding"] = (states.get("sliding", 0) + states.get("separated", 0)) if states else None
    cost = numbers["cost"]
    flat["energy"] = cost["energy_balance_error"]
    flat["wall_seconds"] = cost["wall_seconds"]
    flat["ms_per_step"] = cost["ms_per_step"]
    flat["static_seconds"] = (numbers.get("static") or {}).get("seconds")
    for part in PARTS:
        flat[f"ms_{part}"] = (cost.get("time_per_step") or {}).get(part, {}).get("ms_per_step")
    flat["cells"], flat["dofs"] = cost["cells"], cost["dofs"]
    return flat


DECIMALS = {"cm": 3, "mm": 3, "MPa": 2, "ms": 2, "-": 3}


def _cell(value, scale: float, unit: str) -> str:
    if value is None:
        return "-"
    if unit == "-" and abs(value) < 1e-2 and value != 0:
        return f"{value:.1e}"
    if unit in ("m^3", "s") or (unit == "-" and float(value).is_integer()):
        return f"{value * scale:,.0f}".replace(",", " ")
    return f"{value * scale:.{DECIMALS[unit]}f}"


def tables(found: dict) -> str:
    """Markdown: one table per group, the mesh group with its convergence columns."""
    out = []
    for group in GROUPS:
        members = [v for v in VARIANTS if v.group == group and v.name in found]
        if not members:
            continue
        base = [v for v in VARIANTS if v.name == "mesh_h4.5" and v.name in found]
        columns = members if group == "mesh" else base + members
        header = "| quantity | " + " | ".join(v.label for v in columns) + " |"
        complete_mesh = group == "mesh" and len(members) == 3
        if complete_mesh:
            header += " observed order | extrapolated | GCI of h 2.0 |"
        out.append(header)
        out.append("|---" * (header.count("|") - 1) + "|")
        cells = " | ".join(f"{found[v.name]['cells']:,}".replace(",", " ") for v in columns)
        out.append(f"| cells | {cells} |" + (" | | |" if complete_mesh else ""))
        for key, label, scale, unit in ROWS:
            values = [found[v.name].get(key) for v in columns]
            if all(value is None for value in values):
                continue
            line = f"| {label} ({unit}) | " + " | ".join(_cell(value, scale, unit) for value in values) + " |"
            if complete_mesh:
                if key in NOT_CONVERGED or key.startswith("ms_") or any(value is None for value in values):
                    line += " | | |"
                else:
                    c = convergence(values)
                    if c["status"] == "converging":
                        gci = f"{100 * c['gci_fine']:.1f} %" if c["gci_fine"] is not None else "-"
                        line += f" {c['order']:.2f} | {_cell(c['extrapolated'], scale, unit)} | {gci} |"
                    else:
                        line += f" {STATUS_WORDS[c['status']]} | | |"
            out.append(line)
        out.append("")
    return "\n".join(out)


def figure(runs: dict, group: str, path: pathlib.Path) -> None:
    """One group's histories: the interlayer relative displacement at the wall, D(t) of the crown pair,
    and the wall B and crown A against the floor D."""
    import numpy as np

    plt = case_study._pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    members = [v for v in VARIANTS if v.name in runs and (v.group == group or v.name == "mesh_h4.5")]
    for variant in members:
        run = runs[variant.name]
        monitors, pairs = run["monitors"], run["pairs"]
        soft, hard = (monitors.get(name) for name in case_study.INTERLAYER_MONITORS)
        if soft is not None and hard is not None:
            relative = case_study.displacement(soft) - case_study.displacement(hard)
            axes[0, 0].plot(soft["t"], case_study.CM * np.linalg.norm(relative, axis=1), lw=1.0, label=variant.label)
        if case_study.CROWN_PAIR in pairs:
            axes[0, 1].plot(pairs[case_study.CROWN_PAIR]["t"], pairs[case_study.CROWN_PAIR]["D"], lw=1.0,
                            label=variant.label)
        floor = case_study.displacement(monitors["D"])
        for ax, name in ((axes[1, 0], "B"), (axes[1, 1], "A")):
            ax.plot(monitors[name]["t"], case_study.CM * np.linalg.norm(case_study.displacement(monitors[name]) - floor,
                                                                         axis=1), lw=1.0, label=variant.label)
    titles = ("interlayer relative displacement |u(I8_soft) - u(I8_hard)| (cm)", "D(t), crown pair crown_9",
              "upstream wall B against floor D, |u_B - u_D| (cm)", "crown A against floor D, |u_A - u_D| (cm)")
    for ax, title in zip(axes.flat, titles):
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("t (s)")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"case 3, coarse, 3 s: group {group!r} (workflows/case_sensitivity.py)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_csv(found: dict, path: pathlib.Path) -> None:
    keys = ["cells", "dofs"] + [key for key, *_ in ROWS]
    with open(path, "w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(["variant", "group", "h_cavern", *keys])
        for variant in VARIANTS:
            if variant.name in found:
                writer.writerow([variant.name, variant.group, variant.h_cavern if variant.h_cavern else "",
                                 *(found[variant.name].get(key, "") for key in keys)])


def report(runs: pathlib.Path = RUNS, results: pathlib.Path = RESULTS, doc: bool = True) -> str:
    found, loaded = {}, {}
    for variant in VARIANTS:
        run = case_study.load_run(runs / variant.name)
        if run is not None:
            loaded[variant.name] = run
            found[variant.name] = flat_numbers(case_study.case_numbers(run), run["summary"].get("pairs"))
            found[variant.name].update(stage_numbers(run["dir"]))
    if not found:
        print(f"no finished variant in {runs}", file=sys.stderr)
        return ""
    text = tables(found)
    results.mkdir(parents=True, exist_ok=True)
    write_csv(found, results / "case_sensitivity.csv")
    (results / "case_sensitivity.md").write_text(text)
    for group in GROUPS:
        if any(v.group == group and v.name in loaded for v in VARIANTS):
            figure(loaded, group, results / f"case_sensitivity_{group}.png")
    if doc:
        case_study.update_doc(text, MARKER)
    print(text)
    return text


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--group", choices=GROUPS, action="append", help="run this group only (repeatable)")
    parser.add_argument("--variant", choices=[v.name for v in VARIANTS], action="append",
                        help="run this variant only (repeatable)")
    parser.add_argument("--report-only", action="store_true", help="read finished run directories; run nothing")
    parser.add_argument("--runs", type=pathlib.Path, default=RUNS, metavar="DIR",
                        help=f"run directories here (default {RUNS}); another directory leaves the docs alone")
    args = parser.parse_args(argv)
    if not args.report_only:
        chosen = [v for v in VARIANTS if (not args.group or v.group in args.group)
                  and (not args.variant or v.name in args.variant)]
        for variant in chosen:
            if case_study.load_run(args.runs / variant.name) is not None:
                print(f"{variant.name}: finished, kept", flush=True)
                continue
            line = command(variant, args.runs)
            print(" ".join(line), flush=True)
            code = subprocess.call(line, cwd=REPOSITORY)
            if code != 0:
                print(f"{variant.name}: the run stopped with exit code {code}", file=sys.stderr)
                return code
    report(args.runs, doc=args.runs == RUNS)
    return 0


if __name__ == "__main__":
    sys.exit(main())

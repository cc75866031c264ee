"""Case 3's interlayer slip with the interfaces split before or after the static stage.

Two runs of the coarse case 3 over the record's first 2 s (after its 1 s lead-in at t < 0), one per
value of `[contact] split`:

    OMP_NUM_THREADS=1 nice -n 19 /usr/bin/python3 -m pyfem run workflows/scenes/case3_contact_coarse.toml \\
        --out runs/split_before --set time.duration=2.0
    OMP_NUM_THREADS=1 nice -n 19 /usr/bin/python3 -m pyfem run workflows/scenes/case3_contact_coarse.toml \\
        --out runs/split_after --set time.duration=2.0 --set 'contact.split="after_static"'
    /usr/bin/python3 workflows/split_slip.py runs/split_before runs/split_after --out workflows/results/split_slip

writes OUT.csv and OUT.md: per run and pair monitor, the pair's state and static forces at t = 0, the
largest slip (|tangential relative displacement|) and when, the x component of the relative
displacement (the paper's Fig. 6 quantity: max -6.01 cm, residual -5.93 cm in case 3) at its
largest magnitude, with its sign, and at the end, whether it kept one sign (never beyond 1 % of its
peak on the other side), the same for the component (x, y or z) with the largest excursion, and the
final state and D. Run directories are read as they are (a run
still going is read up to where it is). The committed results were made before record time became
run time: their t runs from the lead-in's start (t_end 3.0 s there is record time 2.0 s).
"""
from __future__ import annotations

import argparse
import csv
import json
import pathlib

import numpy as np

CM = 100.0
STATES = ("bonded", "stick", "sliding", "separated")
COLUMNS = ("split", "pair", "t_end_s", "state_0", "N0_MN", "T0_MN", "peak_slip_cm", "t_peak_slip_s",
           "dux_peak_cm", "sign", "dux_end_cm", "one_signed", "main_component", "main_peak_cm", "main_end_cm",
           "main_one_signed", "state_end", "D_end")


def split_of(run: pathlib.Path) -> str:
    """The run's contact.split from run.json's scene (before_static when absent)."""
    summary = json.loads((run / "run.json").read_text())
    scene = summary.get("scene", {})
    return scene.get("contact", {}).get("split", "before_static") if isinstance(scene, dict) else "?"


def signed_words(other_side: np.ndarray, peak: float) -> str:
    """Whether a history kept one sign: never beyond 1 % of its peak on the other side ("-" below
    1 micrometre: nothing moved)."""
    if abs(peak) < 1e-6:
        return "-"
    return "yes" if np.all(other_side <= 0.01 * abs(peak)) else "no"


def pair_rows(run: pathlib.Path) -> list[dict]:
    rows = []
    split = split_of(run)
    for path in sorted((run / "pairs").glob("*.csv")):
        data = np.genfromtxt(path, delimiter=",", names=True)
        if data.size < 2:
            continue
        slip, dux = np.abs(data["slip"]), data["dux"]
        k, j = int(np.argmax(slip)), int(np.argmax(np.abs(dux)))
        peak = dux[j]
        other_side = -np.sign(peak) * dux
        # The component of the relative displacement with the largest excursion, signed.
        name = max(("dux", "duy", "duz"), key=lambda c: np.abs(data[c]).max())
        main = data[name]
        main_peak = main[int(np.argmax(np.abs(main)))]
        rows.append({
            "split": split, "pair": path.stem, "t_end_s": f"{data['t'][-1]:.3f}",
            "state_0": STATES[int(data["state"][0])], "N0_MN": f"{data['N'][0] / 1e6:.3f}",
            "T0_MN": f"{data['T'][0] / 1e6:.3f}",
            "peak_slip_cm": f"{CM * slip[k]:.3f}", "t_peak_slip_s": f"{data['t'][k]:.3f}",
            "dux_peak_cm": f"{CM * peak:+.3f}", "sign": "-" if peak < 0 else "+",
            "dux_end_cm": f"{CM * dux[-1]:+.3f}",
            "one_signed": signed_words(other_side, peak),
            "main_component": name, "main_peak_cm": f"{CM * main_peak:+.3f}", "main_end_cm": f"{CM * main[-1]:+.3f}",
            "main_one_signed": signed_words(-np.sign(main_peak) * main, main_peak),
            "state_end": STATES[int(data["state"][-1])], "D_end": f"{data['D'][-1]:.4f}",
        })
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=pathlib.Path)
    parser.add_argument("--out", type=pathlib.Path, required=True, help="OUT.csv and OUT.md")
    args = parser.parse_args()
    rows = [row for run in args.runs for row in pair_rows(run)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out.with_suffix(".csv"), "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    lines = ["# Case 3 (coarse): interlayer slip at the pair monitors, split before / after the static stage", "",
             "Made by workflows/split_slip.py (its docstring has the commands). N0, T0: the pair's normal and",
             "shear force at t = 0 (compression positive); dux: x component of the relative displacement",
             "(the paper's Fig. 6 quantity, max -6.01 cm, residual -5.93 cm in case 3); main: the component",
             "of the relative displacement with the largest excursion (a separated pair's includes its opening).", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(row[c]) for c in COLUMNS) + " |" for row in rows]
    lines += ["", "All pairs (run.json pair_states): states at t = 0 and at the end, the most sliding at once.", "",
              "| split | pairs | t = 0 (bonded/stick/sliding/separated) | end | most sliding (t) |", "|---|---|---|---|---|"]
    for run in args.runs:
        summary = json.loads((run / "run.json").read_text())
        states = summary.get("pair_states")
        if not states:
            continue
        first = "/".join(str(states[name][0]) for name in STATES)
        last = "/".join(str(states[name][-1]) for name in STATES)
        k = int(np.argmax(states["sliding"]))
        lines.append(f"| {split_of(run)} | {summary.get('n_pairs')} | {first} | {last} | "
                     f"{states['sliding'][k]} ({states['t'][k]:.2f} s) |")
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

"""Case 3 over the whole record: what the earthquake adds to the interfaces' wear (issue 11).

The paper's deterioration (Eq. 9) lowers the interfaces' strength over t_s whether or not the
ground shakes, and the static stage leaves pairs at their limit; so part of case 3's interlayer
slip is the wear's. This compares two runs of the same scene over the same record, one with the
wave and one with the input scaled to nothing (`--set wave.motion.record.pga=1e-9`):

    /usr/bin/python3 workflows/wave_and_wear.py WAVE_RUN NO_WAVE_RUN --out FIGURE.png

prints, per run, the crown pair's and the wall pairs' slip (max and at the end), their final
state and D, the lining monitors A, B, C against the floor D (max over t and at the end), the
lining's damaged volume, friction and the energy balance; and draws the pairs' slip and D(t) of
both runs. Run directories are read as they are (a run still going is read up to where it is).
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "workflows"))
from case_study import CROWN_PAIR, WALL_PAIRS, _pyplot, displacement, load_run  # noqa: E402

CM = 100.0
STATES = ("bonded", "stick", "sliding", "separated")


def read(directory: pathlib.Path) -> dict:
    """`case_study.load_run` of a run finished or not; exit 2 naming a directory without a run."""
    run = load_run(directory, finished_only=False)
    if run is None:
        print(f"error: {directory}: no run.json (not a run directory of pyfem)", file=sys.stderr)
        sys.exit(2)
    return run


def numbers(run: dict) -> dict:
    """The quantities compared (cm, -, m^3, J)."""
    out = {"status": run["summary"].get("status"), "t_end": float(run["monitors"]["D"]["t"][-1])}
    for name in (CROWN_PAIR, *WALL_PAIRS):
        if name in run["pairs"]:
            pair = run["pairs"][name]
            out[name] = {"max": round(CM * pair["slip"].max(), 3), "end": round(CM * pair["slip"][-1], 3),
                         "t_max": float(pair["t"][np.argmax(pair["slip"])]),
                         "state_end": STATES[int(pair["state"][-1])], "D_end": round(float(pair["D"][-1]), 4)}
    floor = displacement(run["monitors"]["D"])
    for name in "ABC":
        relative = np.linalg.norm(displacement(run["monitors"][name])[:len(floor)] - floor, axis=1)
        out[f"{name}-D"] = {"max": round(CM * relative.max(), 2), "end": round(CM * relative[-1], 2)}
    summary = run["summary"]
    lining = (summary.get("nonlinear_regions") or {}).get("lining")
    if lining is not None:
        out["lining_damaged_m3"] = lining["damaged_volume"]
    energy = summary.get("energy") or {}
    out["friction_J"] = energy.get("friction_dissipation")
    out["balance"] = energy.get("balance_error")
    out["wall_seconds"] = summary.get("wall_seconds")
    return out


def figure(runs: dict, path: pathlib.Path) -> None:
    plt = _pyplot()
    fig, (slip_ax, d_ax) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for (label, run), colour in zip(runs.items(), ("C0", "C1")):
        for name in (CROWN_PAIR, *WALL_PAIRS):
            if name not in run["pairs"]:
                continue
            pair = run["pairs"][name]
            crown = name == CROWN_PAIR
            slip_ax.plot(pair["t"], CM * pair["slip"], color=colour, lw=1.5 if crown else 0.8,
                         ls="-" if crown else ":", label=f"{label}: {name}" if crown or name == WALL_PAIRS[0] else None)
            if crown:
                d_ax.plot(pair["t"], pair["D"], color=colour, lw=1.2, label=f"{label}: {name}")
    slip_ax.axhline(6.01, color="0.5", lw=0.8)
    slip_ax.text(0.2, 6.1, "paper: max 6.01 cm, residual 5.93 cm", fontsize=7, color="0.4")
    slip_ax.set_ylabel("pair slip (cm)")
    slip_ax.set_ylim(bottom=-0.3, top=max(7.0, slip_ax.get_ylim()[1]))
    slip_ax.set_title("case 3, the whole record: pair slip with the wave and with the wear alone", fontsize=9)
    d_ax.axhspan(0.71, 0.78, color="C3", alpha=0.1, label="paper: walls 0.71-0.78")
    d_ax.set_ylabel("D(t)")
    d_ax.set_xlabel("t (s)")
    for ax in (slip_ax, d_ax):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("wave", type=pathlib.Path, help="run directory with the wave")
    parser.add_argument("no_wave", type=pathlib.Path, help="run directory of the same scene, input at 1e-9 g")
    parser.add_argument("--out", type=pathlib.Path, help="figure (PNG)")
    args = parser.parse_args(argv)
    runs = {"with the wave": read(args.wave), "wear alone": read(args.no_wave)}
    print(json.dumps({label: numbers(run) for label, run in runs.items()}, indent=1))
    if args.out is not None:
        figure(runs, args.out)
        print(f"figure: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

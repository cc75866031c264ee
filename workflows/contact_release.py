"""The bond-break spike with and without `contact.release_time` (docs/method.md section 9, "Releasing a
broken bond"), on the two-layer contact scene (workflows/scenes/contact_two_layer_sv.toml) with a weak
interface that breaks under the SV pulse.

    /usr/bin/python3 workflows/contact_release.py [--runs runs/contact_release]

Runs the scene with the interface bonded for good (the reference: the same pulse, no break), then with
the weak interface released at once (the default) and over each release time, and prints a table:
peak acceleration at monitors one cell (5 m) above and below the interface, the slip of the pair monitor, the
energy balance error of run.json, the interface's dissipation and the time step; RUNS/spike.png draws the
acceleration 5 m below the interface of each case beside the bonded run's.
"""
import argparse
import csv
import json
import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "workflows" / "scenes" / "contact_two_layer_sv.toml"
RELEASE_TIMES = [None, 0.005, 0.02]
WEAK = {"cohesion": 2.0e5, "tensile_strength": 2.0e5, "friction_angle": 5.0}
AMPLITUDE = 0.008


def toml_value(value) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    return repr(value)


def toml_text(data: dict, prefix: str = "") -> str:
    plain = {k: v for k, v in data.items() if not isinstance(v, dict) and not (isinstance(v, list) and v
                                                                                 and isinstance(v[0], dict))}
    lines = [f"[{prefix}]"] if prefix and plain else []
    lines += [f"{k} = {toml_value(v)}" for k, v in plain.items()]
    for key, value in data.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and key not in plain:
            lines.append(toml_text(value, name))
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            for entry in value:
                lines.append(f"[[{name}]]\n" + "\n".join(f"{k} = {toml_value(v)}" for k, v in entry.items()))
    return "\n".join(lines)


def scene(contact: dict, release_time) -> str:
    data = tomllib.loads(SCENE.read_text())
    data["wave"]["motion"]["ricker"]["amplitude"] = AMPLITUDE
    data["contact"].update(contact)
    if release_time is not None:
        data["contact"]["release_time"] = release_time
    data["monitor"] = [{"name": "above", "point": [30.0, 5.0, 35.0]}, {"name": "below", "point": [30.0, 5.0, 25.0]}]
    data["output"] = {"interval": 2.0e-4, "xdmf_interval": 0.0}
    data["time"]["duration"] = 0.6
    return toml_text(data) + "\n"


def peak_acceleration(path: Path) -> float:
    with open(path) as handle:
        rows = list(csv.DictReader(handle))
    return max((float(r["ax"]) ** 2 + float(r["ay"]) ** 2 + float(r["az"]) ** 2) ** 0.5 for r in rows)


def slip_mm(path: Path) -> tuple[float, float]:
    """(largest, final) slip of the pair monitor (mm)."""
    with open(path) as handle:
        slip = [abs(float(r["slip"])) for r in csv.DictReader(handle)]
    return 1e3 * max(slip), 1e3 * slip[-1]


def run(folder: Path, name: str, contact: dict, release_time) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.toml"
    path.write_text(scene(contact, release_time))
    out = folder / name
    subprocess.run([sys.executable, "-m", "pyfem", "run", str(path), "--out", str(out)], check=True,
                   stdout=subprocess.DEVNULL)
    summary = json.loads((out / "run.json").read_text())
    states = summary.get("pair_states", {})
    return {"case": name, "release_time": release_time,
            "above": peak_acceleration(out / "monitors" / "above.csv"),
            "below": peak_acceleration(out / "monitors" / "below.csv"),
            "slip": slip_mm(out / "pairs" / "I1.csv"),
            "broken": states, "balance_error": summary["energy"]["balance_error"],
            "friction_dissipation": summary["energy"].get("friction_dissipation"),
            "dt": summary["dt"], "dt_critical": summary["dt_critical"]}


def draw(folder: Path, cases: list[str]) -> None:
    """spike.png: the acceleration 5 m below the interface, each case side by side with the bonded run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    def history(case):
        data = np.genfromtxt(folder / case / "monitors" / "below.csv", delimiter=",", names=True)
        return data["t"], np.sqrt(data["ax"] ** 2 + data["ay"] ** 2 + data["az"] ** 2)

    others = [case for case in cases if case != "bonded"]
    fig, axes = plt.subplots(1, len(others), figsize=(4.2 * len(others), 3.4), sharey=True, squeeze=False)
    t_bonded, a_bonded = history("bonded")
    for ax, case in zip(axes[0], others):
        t, a = history(case)
        ax.plot(t_bonded, a_bonded, color="0.6", lw=0.8, label="bonded")
        ax.plot(t, a, color="C3", lw=0.8, label=case)
        ax.set_title(case.replace("_", " "), fontsize=9)
        ax.set_xlabel("t (s)")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("|a| 5 m below the interface (m/s^2)")
    fig.tight_layout()
    fig.savefig(folder / "spike.png", dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="runs/contact_release")
    folder = Path(parser.parse_args().runs)
    rows = [run(folder, "bonded", {"cohesion": 1.0e12, "tensile_strength": 1.0e12}, None)]
    for release in RELEASE_TIMES:
        rows.append(run(folder, "at_once" if release is None else f"release_{release:g}", WEAK, release))
    (folder / "table.json").write_text(json.dumps(rows, indent=1))
    draw(folder, [r["case"] for r in rows])
    print("| case | release_time (s) | peak accel. 5 m above (m/s^2) | 5 m below (m/s^2) | "
          "largest / final slip at I1 (mm) | balance error | interface dissipation (J) | dt (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['case']} | {r['release_time'] or '-'} | {r['above']:.3g} | {r['below']:.3g} | "
              f"{r['slip'][0]:.3g} / {r['slip'][1]:.3g} | {r['balance_error']:.1e} | {r['friction_dissipation'] or 0:.3g} | {r['dt']:.3g} |")


if __name__ == "__main__":
    main()

"""Two run directories compared history by history (the MPI tests, workflows/strong_scaling.py):
each column's difference against the run's largest value of what the column measures."""
import re
from pathlib import Path

import numpy as np


def dimension(name: str) -> str:
    """What a history column measures: its differences are measured against the run's largest
    value of that kind (a bonded pair's relative displacement is round-off of the mesh's
    displacement, a dynamic stress at the first instants a trace of the static one)."""
    if name in ("slip", "gap") or re.fullmatch(r"d?u[xyz](_ff)?", name):
        return "length"
    if re.fullmatch(r"v[xyz](_ff)?", name):
        return "velocity"
    if re.fullmatch(r"a[xyz](_ff)?", name):
        return "acceleration"
    if re.fullmatch(r"s(xx|yy|zz|xy|yz|xz|1|1_dynamic)", name):
        return "stress"
    if name in ("N", "T"):
        return "force"
    if re.fullmatch(r".+_F[xyz]", name):  # reactions.csv: a face's reaction resultant
        return "reaction"
    return name


def read_history(path: Path) -> tuple[list[str], np.ndarray]:
    return path.read_text().splitlines()[0].split(","), np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def scales(run_dir: Path) -> dict:
    """Largest |value| of each dimension over the run's histories; energy.csv: the largest energy."""
    peaks: dict = {}
    for name in histories(run_dir):
        header, rows = read_history(run_dir / name)
        for k, column in enumerate(header):
            kind = "energy" if name.name == "energy.csv" and column != "t" else dimension(column)
            peaks[kind] = max(peaks.get(kind, 0.0), float(np.abs(rows[:, k]).max()))
    return peaks


def relative_difference(path: Path, reference: Path, scale: dict) -> float:
    """Largest |difference| / scale of its column's dimension over a CSV history's rows."""
    header, x = read_history(reference)
    _, y = read_history(path)
    assert x.shape == y.shape, (path, x.shape, y.shape)
    kinds = ["energy" if reference.name == "energy.csv" and h != "t" else dimension(h) for h in header]
    return float((np.abs(x - y) / np.array([max(scale[kind], 1e-300) for kind in kinds])).max())


def histories(out_dir: Path) -> list[Path]:
    """Every CSV history of a run directory, relative to it, sorted."""
    return sorted(p.relative_to(out_dir) for p in out_dir.rglob("*.csv"))


def largest_differences(run_dir: Path, reference: Path) -> dict:
    """Per dimension (`dimension`; "energy" for energy.csv), the largest relative_difference over
    every history of `reference` (the same files in both)."""
    names = histories(reference)
    if histories(run_dir) != names:
        raise ValueError(f"{run_dir} and {reference} hold different histories")
    scale = scales(reference)
    worst: dict = {}
    for name in names:
        header, x = read_history(reference / name)
        _, y = read_history(run_dir / name)
        if x.shape != y.shape:
            raise ValueError(f"{name}: {y.shape} rows and columns against {x.shape}")
        for k, column in enumerate(header):
            kind = "energy" if name.name == "energy.csv" and column != "t" else dimension(column)
            difference = float(np.abs(x[:, k] - y[:, k]).max()) / max(scale[kind], 1e-300)
            worst[kind] = max(worst.get(kind, 0.0), difference)
    return worst


def largest_difference(run_dir: Path, reference: Path) -> float:
    """The largest of `largest_differences`: over every column of every history."""
    return max(largest_differences(run_dir, reference).values())

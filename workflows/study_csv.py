"""Writing a study's rows to its results CSV (workflows/results/), one helper for every accuracy study;
the tables the program's mesh advice reads (pyfem.accuracy) are copied into the package, pyfem/data/."""
from __future__ import annotations

import csv
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "workflows" / "results"
PROGRAM_TABLES = ROOT / "pyfem" / "data"


def publish(path: Path) -> None:
    """Copies a study's results CSV to the program's table of the same name (pyfem/data/NAME.csv,
    read by pyfem.accuracy) when the study wrote it to workflows/results/ and the program reads it;
    a CSV written elsewhere (a study's --out) changes nothing of the program's."""
    path = Path(path).resolve()
    if path.parent == RESULTS.resolve() and (PROGRAM_TABLES / path.name).is_file():
        shutil.copyfile(path, PROGRAM_TABLES / path.name)


def write_rows(path: Path, rows: list[dict], columns: list[str], compact: bool = False) -> None:
    """Writes `rows` (dicts holding at least `columns`) to the CSV `path` (its folder made if needed),
    the columns in that order; compact: floats with 6 significant digits, else in full; then
    `publish`es it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({key: (f"{row[key]:.6g}" if compact and isinstance(row[key], float) else row[key])
                             for key in columns})
    publish(path)


def run_study_main(description: str, run, table, results_csv: Path, columns: list[str], prefix: str,
                   argv=None, compact: bool = False) -> int:
    """The command line of a study whose only option is --work (the folder of its meshes and runs, a
    temporary one by default): runs `run(work)`, writes its rows to `results_csv` and prints
    `table(rows)`."""
    import argparse
    import tempfile

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--work", type=Path, default=None, help="folder for the meshes and runs (kept)")
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix=prefix))
    work.mkdir(parents=True, exist_ok=True)
    rows = run(work)
    write_rows(results_csv, rows, columns, compact)
    print(table(rows))
    return 0

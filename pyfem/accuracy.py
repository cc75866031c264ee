"""Settings for an error budget, read from the accuracy-versus-cost study.

The study (workflows/accuracy_cost.py) runs a homogeneous box under an oblique SV
Ricker pulse over element order, elements per shortest wavelength, time-step safety
and boundary type, and writes one row per run to workflows/results/accuracy_cost.csv:
the relative L2 error of the monitors against the exact free field and the seconds
the run took. This module turns that table (its copy in the package, pyfem/data/accuracy_cost.csv, as for every
study below) into advice:

* `recommend(error_budget)`: the cheapest measured settings whose error is within the
  budget;
* `element_size_for(scene, error_budget)`: the element size and order a scene needs,
  from the shortest shear wavelength of its materials and its wave's frequency content;
* `wall_size_for(error_budget)`: the element size at a cavern's wall, as a fraction of the
  opening's radius, that keeps the wall's hoop stress within the budget (the wall-stress study,
  workflows/wall_stress_accuracy.py, workflows/results/wall_stress.csv);
* `lining_elements_for(error_budget)`: the elements through a lining that keep the peak hoop stress
  read off its cells within the budget of the true peak at its face (the lining study,
  workflows/lining_stress_accuracy.py, workflows/results/lining_stress.csv, docs/lined_tunnel.md);
* `curved_wall_size_for(error_budget)`: the element size at a non-circular wall, as a fraction of its
  smallest radius of curvature, that kept an elliptical opening's wall stress within the budget (the
  static excavation study, workflows/elliptical_opening.py, workflows/results/elliptical_opening.csv,
  docs/elliptical_opening.md);
* `interface_slip_advice(scene, model)`: per contact interface, its element size in elements per
  shortest wavelength and what the slip study measured at that resolution for alike or dissimilar
  rocks on its two sides (workflows/interface_slip_accuracy.py, workflows/results/interface_slip.csv,
  docs/interface_slip_accuracy.md).

Errors transfer between scenes through the elements per shortest wavelength (the
dispersion error of a given element depends on h / wavelength); seconds do not
transfer, but their ratios do for a given order (cost ~ dofs x steps).
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from pyfem.material import Material

# The studies' tables, copied into the package by the study that writes them (workflows/study_csv.py
# `write_rows`: workflows/results/NAME.csv and pyfem/data/NAME.csv; tests/test_accuracy.py holds
# the two equal): the program reads its own copy, never a study's folder.
DATA = Path(__file__).resolve().parent / "data"
DEFAULT_RESULTS = DATA / "accuracy_cost.csv"
WALL_RESULTS = DATA / "wall_stress.csv"
LINING_RESULTS = DATA / "lining_stress.csv"
ELLIPSE_RESULTS = DATA / "elliptical_opening.csv"
SLIP_RESULTS = DATA / "interface_slip.csv"
# The highest frequency with energy in a Ricker wavelet, in units of its peak frequency f0:
# the amplitude spectrum (f/f0)^2 exp(-(f/f0)^2) at 2.5 f0 is 3 % of its peak at f0.
RICKER_MAX_FREQUENCY_FACTOR = 2.5
# The study's measure of cost: seconds of the time loop (model setup is a fixed cost that does
# not grow with the duration) scaled to one reference volume, because the study's box grows
# with the element size (its monitors keep three elements from every face).
COST_COLUMN = "loop_seconds_per_reference_volume"

_FLOAT_COLUMNS = ("h", "elements_per_wavelength", "safety", "dt", "error", "wall_seconds", "loop_seconds",
                  "box_volume", COST_COLUMN)
_INT_COLUMNS = ("order", "steps", "dofs")


def read_results(results_csv=DEFAULT_RESULTS, cost_column=COST_COLUMN) -> list[dict]:
    """Rows of the study's CSV with numbers converted.

    Args:
        results_csv: path of the CSV (columns order, elements_per_wavelength, safety,
            boundary, error and the cost column at least; others are kept as text or numbers).
        cost_column: the cost column that must be present (the workflow reads older CSVs with
            "loop_seconds" and adds the normalised cost itself).

    Returns:
        list of dicts, one per run.

    Raises:
        FileNotFoundError: no such file (run workflows/accuracy_cost.py first).
        ValueError: a required column is missing.
    """
    path = Path(results_csv)
    with open(path, newline="") as stream:
        rows = list(csv.DictReader(stream))
    required = {"order", "elements_per_wavelength", "safety", "boundary", "error", cost_column}
    missing = required - set(rows[0] if rows else {})
    if missing:
        raise ValueError(f"results_csv = {str(path)!r}: columns {sorted(missing)} missing; "
                         f"allowed is the CSV written by workflows/accuracy_cost.py")
    for row in rows:
        for key in _FLOAT_COLUMNS:
            if key in row and row[key] != "":
                row[key] = float(row[key])
        for key in _INT_COLUMNS:
            if key in row and row[key] != "":
                row[key] = int(float(row[key]))
    return rows


def pareto_front(rows: list[dict], cost=COST_COLUMN) -> list[dict]:
    """Runs no other run beats in both error and cost, cheapest first.

    Args:
        rows: study rows with "error" and the cost column.
        cost: name of the cost column (s).

    Returns:
        The Pareto-optimal rows sorted by increasing cost (and so decreasing error). Runs
        with error >= 1 (no better than no motion at all, e.g. a fixed box without input)
        are never on the front.
    """
    front = []
    for row in sorted((r for r in rows if r["error"] < 1.0), key=lambda r: (r[cost], r["error"])):
        if not front or row["error"] < front[-1]["error"]:
            front.append(row)
    return front


def recommend(error_budget: float, results_csv=DEFAULT_RESULTS, order: int | None = None) -> dict:
    """The cheapest settings of the study whose measured error is within the budget.

    Args:
        error_budget: largest acceptable relative L2 error of the displacement (e.g. 0.05).
        results_csv: the study's CSV.
        order: only runs of this element order (1 or 2); None: any order.

    Returns:
        dict: order (1 or 2), elements_per_wavelength (elements per shortest shear
        wavelength), safety (fraction of the critical time step), boundary, error (the
        measured one), seconds (measured cost, s, of the study's run), "runs" (how
        many runs of the study met the budget) and "coarsest_studied" (True when that is the
        coarsest mesh the study ran at that order: coarser ones may meet the budget too, unmeasured).

    Raises:
        ValueError: the budget is not a positive number, the study has no run of `order`, or no
            run of the study meets it (the message gives the smallest error measured).
    """
    require_budget(error_budget)
    rows = [r for r in read_results(results_csv) if order is None or r["order"] == order]
    if not rows:
        raise ValueError(f"order = {order!r}: the study has no run of this order; allowed: "
                         f"{sorted({r['order'] for r in read_results(results_csv)})}")
    meeting = [r for r in rows if r["error"] <= error_budget]
    if not meeting:
        best = min(rows, key=lambda r: r["error"])
        raise ValueError(f"error_budget = {error_budget!r}: no run of the study reached it (smallest error "
                         f"{best['error']:.3g} with Q{best['order']}, {best['elements_per_wavelength']:.3g} "
                         f"elements per wavelength); allowed is a budget >= {best['error']:.3g} "
                         "or a finer study")
    best = min(meeting, key=lambda r: (r[COST_COLUMN], r["error"]))
    coarsest = min(r["elements_per_wavelength"] for r in rows if r["order"] == best["order"])
    return {"order": best["order"], "elements_per_wavelength": best["elements_per_wavelength"],
            "safety": best["safety"], "boundary": best["boundary"], "error": best["error"],
            "seconds": best[COST_COLUMN], "runs": len(meeting),
            "coarsest_studied": best["elements_per_wavelength"] <= coarsest}


def highest_frequency(scene) -> float:
    """Highest frequency (Hz) the scene's wave carries: 2.5 f0 for a Ricker, band[1] for a record."""
    motion = scene["wave"]["motion"]
    if motion.get("ricker") is not None:
        return RICKER_MAX_FREQUENCY_FACTOR * float(motion["ricker"]["f0"])
    return float(motion["record"]["band"][1])


def slowest_shear_speed(scene) -> float:
    """Smallest shear wave speed sqrt(G / rho) (m/s) over the scene's materials (those with E, nu, rho)."""
    speeds = [Material.from_scene(name, table).s_wave_speed for name, table in scene["materials"].items()
              if all(table.get(key) is not None for key in ("E", "nu", "rho"))]
    if not speeds:
        raise ValueError("scene materials: allowed is at least one material with E, nu and rho")
    return min(speeds)


def element_size_for(scene, error_budget: float, results_csv=DEFAULT_RESULTS,
                     order: int | None = None) -> dict:
    """Element size and order a scene needs to keep its wave-propagation error within a budget.

    The shortest wavelength is the slowest shear speed of the materials over the highest
    frequency of the wave (Ricker: 2.5 f0; record: the band-pass high corner, band[1]);
    the study says how many elements per wavelength the budget needs, and at what order.

    Args:
        scene: validated Scene with a [wave] table.
        error_budget: largest acceptable relative error (e.g. 0.05).
        results_csv: the study's CSV.
        order: advice for this element order (1 or 2); None: the cheapest order.

    Returns:
        dict: h (largest element size, m), order, elements_per_wavelength,
        shortest_wavelength (m), highest_frequency (Hz), shear_speed (m/s, slowest),
        safety, boundary, expected_error (measured in the study), coarsest_studied (recommend),
        and "text", one sentence for ``pyfem check``.

    Raises:
        ValueError: the scene has no wave, or the study cannot meet the budget.
    """
    if scene.get("wave") is None:
        raise ValueError("scene has no [wave]: allowed is a scene with seismic input (its frequency content "
                         "sets the shortest wavelength)")
    advice = recommend(error_budget, results_csv, order)
    frequency = highest_frequency(scene)
    speed = slowest_shear_speed(scene)
    wavelength = speed / frequency
    h = wavelength / advice["elements_per_wavelength"]
    text = (f"for a {100 * error_budget:g} % error: Q{advice['order']} elements of at most h = {h:.3g} m "
            f"({advice['elements_per_wavelength']:.3g} per shortest wavelength {wavelength:.4g} m = "
            f"{speed:.4g} m/s / {frequency:.3g} Hz), time.safety = {advice['safety']:g} "
            f"(study error {100 * advice['error']:.2g} %"
            + ("; the coarsest mesh the study ran, so not a measured limit: a wave that carries more of "
               "its energy near its highest frequency than the study's Ricker pulse needs finer)"
               if advice["coarsest_studied"] else ")"))
    return {"h": h, "order": advice["order"], "elements_per_wavelength": advice["elements_per_wavelength"],
            "shortest_wavelength": wavelength, "highest_frequency": frequency, "shear_speed": speed,
            "safety": advice["safety"], "boundary": advice["boundary"], "expected_error": advice["error"],
            "coarsest_studied": advice["coarsest_studied"], "text": text}


def _wall_peak_error(row: dict) -> float:
    """The larger of a wall-stress study row's peak errors: hoop stress, and racking when the row has it."""
    return max(float(row["peak_error"]), float(row.get("racking_peak_error") or 0.0))


def require_budget(error_budget) -> None:
    """Raises ValueError unless the error budget is a positive finite number (e.g. 0.05)."""
    if not (isinstance(error_budget, (int, float)) and math.isfinite(error_budget) and error_budget > 0):
        raise ValueError(f"error_budget = {error_budget!r}: allowed is a positive relative error, e.g. 0.05")


def coarsest_within(errors: dict, error_budget: float, finer_is_smaller: bool = True):
    """The coarsest mesh of a study whose error, and the error of every finer mesh studied, is within
    the budget (an error is not always monotone in the size, so a coarse size that happens to meet it
    is not advised if a finer one misses it); None when even the finest misses it.

    Args:
        errors: size -> error; the size is an element size (finer: smaller) or, with
            finer_is_smaller=False, a count such as elements through a lining (finer: larger).
        error_budget: the largest acceptable error.
    """
    best = None
    for size in sorted(errors, reverse=not finer_is_smaller):   # finest first
        if errors[size] > error_budget:
            break
        best = size
    return best


def wall_size_for(error_budget: float, results_csv=WALL_RESULTS) -> list[dict]:
    """The largest element size at a cavern wall, per order, that kept the peaks of the wall's hoop
    stress and of the opening's racking (the crown relative to the invert, where the study's CSV has
    it) within a budget of the exact answer (Pao & Mow's series) for every wave of the wall-stress
    study, every smaller size studied included (Q1's error is not monotone in h).

    The peak, not the history: the history's error has a floor set by the truncation faces'
    reflections (docs/wall_stress_accuracy.md), which the model's size controls, not the wall's mesh.

    Args:
        error_budget: largest acceptable relative error of the hoop stress history (e.g. 0.05).
        results_csv: the study's CSV (workflows/results/wall_stress.csv).

    Returns:
        per order (ascending) a dict: order, h_over_a (element size at the wall / the opening's
        radius, the largest measured within the budget at every wave), error (the largest peak
        error over the waves at that size), loop_seconds (the shortest wave's run), ka (k_s a at 2.5 f0 of
        the shortest wave studied) and "text" (one line for ``pyfem check``); an order none of
        whose sizes met the budget says so in its text with h_over_a None.

    Raises:
        ValueError: a budget that is not a positive number, or no study results.
    """
    require_budget(error_budget)
    with open(results_csv, newline="") as stream:
        rows = [row for row in csv.DictReader(stream) if row["reference"] == "Pao-Mow"]
    if not rows:
        raise ValueError(f"{results_csv}: no rows against the exact answer; run workflows/wall_stress_accuracy.py")
    waves = sorted({float(row["f0"]) for row in rows})
    # k_s a of the shortest wave studied, at its highest frequency with energy (2.5 f0): the
    # study's rock (workflows/wall_stress_accuracy.py: E 8 GPa, nu 0.24, 2600 kg/m^3), a = 5 m.
    shear_speed = math.sqrt(8.0e9 / (2.0 * 1.24) / 2600.0)
    ka = 2.0 * math.pi * RICKER_MAX_FREQUENCY_FACTOR * waves[-1] * 5.0 / shear_speed
    advice = []
    for order in sorted({int(row["order"]) for row in rows}):
        by_size = {}
        for row in rows:
            if int(row["order"]) == order:
                by_size.setdefault(float(row["h_over_a"]), []).append(row)
        complete = {h: series for h, series in by_size.items() if len(series) == len(waves)}
        worst = {h: max(series, key=_wall_peak_error) for h, series in complete.items()}
        h_over_a = coarsest_within({h: _wall_peak_error(row) for h, row in worst.items()}, error_budget)
        if h_over_a is not None:
            error = _wall_peak_error(worst[h_over_a])
            what = "hoop stress and racking" if rows[0].get("racking_peak_error") else "hoop stress"
            text = (f"Q{order}: at most {h_over_a:.3g} x the opening's radius at the wall (peak error of the "
                    f"{what} in the study {100 * error:.2g} %, waves down to k_s a = {ka:.2g})")
            seconds = max(float(row["loop_seconds"]) for row in complete[h_over_a])
            advice.append({"order": order, "h_over_a": h_over_a, "error": error, "loop_seconds": seconds, "ka": ka,
                           "text": text})
        else:
            smallest = min(worst.values(), key=_wall_peak_error) if worst else \
                min((row for series in by_size.values() for row in series), key=_wall_peak_error)
            advice.append({"order": order, "h_over_a": None, "error": _wall_peak_error(smallest),
                           "loop_seconds": float(smallest["loop_seconds"]), "ka": ka,
                           "text": f"Q{order}: not reached in the study (smallest peak error "
                                   f"{100 * _wall_peak_error(smallest):.2g} % at "
                                   f"{float(smallest['h_over_a']):.3g} x the radius)"})
    return advice


def curved_wall_size_for(error_budget: float, results_csv=ELLIPSE_RESULTS) -> list[dict]:
    """The largest element size at a non-circular wall, per order, as a fraction of the wall's smallest
    radius of curvature rho, that kept the hoop stress of every wall cell of an elliptical opening within
    a budget of the exact answer (relative to the exact peak) in the static excavation study, every
    smaller size studied included (docs/elliptical_opening.md).

    Args:
        error_budget: largest acceptable relative error (e.g. 0.05).
        results_csv: the study's CSV (workflows/results/elliptical_opening.csv).

    Returns:
        per order (ascending) a dict: order, h_over_rho (None: no size studied met the budget) and
        error (the worst wall cell's at that size, or the smallest studied).

    Raises:
        ValueError: a budget that is not a positive number, or no ellipse rows in the results.
    """
    require_budget(error_budget)
    with open(results_csv, newline="") as stream:
        rows = [row for row in csv.DictReader(stream) if row["shape"] == "ellipse"]
    if not rows:
        raise ValueError(f"{results_csv}: no ellipse rows; run workflows/elliptical_opening.py")
    advice = []
    for order in sorted({int(row["order"]) for row in rows}):
        errors = {float(row["h_over_rho"]): float(row["worst"]) for row in rows if int(row["order"]) == order}
        h_over_rho = coarsest_within(errors, error_budget)
        error = errors[h_over_rho] if h_over_rho is not None else min(errors.values())
        advice.append({"order": order, "h_over_rho": h_over_rho, "error": error})
    return advice


def slip_error_at(per_wavelength: float, dissimilar: bool, results_csv=SLIP_RESULTS, order: int = 1,
                  lag: bool = False) -> dict:
    """What the interface-slip study measured at a resolution: the peak slip's error against its finest
    mesh, interpolated in log(elements per wavelength) between the sizes studied (held at the ends),
    for an interface between dissimilar rocks ("bimaterial", with the normal lag: "bimaterial, lag")
    or alike ones, from the rows of `order` where the study has them, else from Q1's.

    Returns:
        {"peak_error": signed relative error, "history_error", "per_wavelength": the resolution
        asked, "studied": (smallest, largest) resolution of the rows used, "order": the rows' order,
        "contrast": the rows' kind}.

    Raises:
        ValueError: a resolution that is not a positive number, or no such rows in the results.
    """
    if not (isinstance(per_wavelength, (int, float)) and math.isfinite(per_wavelength) and per_wavelength > 0):
        raise ValueError(f"per_wavelength = {per_wavelength!r}: allowed is a positive number")
    contrast = ("bimaterial, lag" if lag else "bimaterial") if dissimilar else "homogeneous"
    with open(results_csv, newline="") as stream:
        kind = [row for row in csv.DictReader(stream) if row["contrast"] == contrast
                and float(row["safety"]) == 0.8 and row["peak_error"] not in ("", "nan")
                and float(row["history_error"]) > 0.0]
    rows = [row for row in kind if int(row["order"]) == order] or [row for row in kind if int(row["order"]) == 1]
    if not rows:
        raise ValueError(f"{results_csv}: no {contrast} rows; run workflows/interface_slip_accuracy.py")
    order = int(rows[0]["order"])
    rows.sort(key=lambda row: float(row["per_wavelength"]))
    x = [math.log(float(row["per_wavelength"])) for row in rows]
    where = min(max(math.log(per_wavelength), x[0]), x[-1])
    peak = float(np.interp(where, x, [float(row["peak_error"]) for row in rows]))
    history = float(np.interp(where, x, [float(row["history_error"]) for row in rows]))
    return {"peak_error": peak, "history_error": history, "per_wavelength": per_wavelength,
            "studied": (float(rows[0]["per_wavelength"]), float(rows[-1]["per_wavelength"])), "order": order,
            "contrast": contrast}


def interface_slip_advice(scene, model, results_csv=SLIP_RESULTS, comm=None, pairs=None,
                          node_index: np.ndarray | None = None) -> dict:
    """Per contact interface of a prepared model: the rocks on its two sides, its element size (the
    median over its pairs of sqrt(nearest x third-nearest neighbour distance), times the order), the
    elements per shortest shear wavelength of
    the slower side at the wave's highest frequency, and what the slip study measured at that
    resolution (`slip_error_at`). {} without contact pairs or a wave.

    Returns:
        interface names (comma-separated where their lines are the same) -> one line for ``pyfem check``.

    The distributed model's (comm, a collective): `pairs` are the pairs this rank steps (each pair on
    one rank), node_index their nodes' function-space node (-1: none on this rank); the sides' regions
    are voted over every rank's pairs and the spacing measured on every rank's pair positions.
    """
    pairs = getattr(model, "pairs", None) if pairs is None else pairs
    if pairs is None or (comm is None and len(pairs) == 0) or scene.get("wave") is None:
        return {}
    frequency = highest_frequency(scene)
    from pyfem.operators import cell_regions

    n_basis = model.V.element.basix_element.dim
    cells = model.V.dofmap.list.array.reshape(-1, n_basis)
    names = {tag: name for name, tag in model.regions.items()}
    node_region = np.full(int(cells.max()) + 1, -1, dtype=np.int64)
    node_region[cells.ravel()] = np.repeat(cell_regions(model).astype(np.int64), n_basis)
    order = int(scene["mesh"]["order"])
    advice = {}
    n_bins = max(model.regions.values(), default=0) + 2

    def regions_of(nodes):
        index = np.asarray(nodes, dtype=np.int64) if node_index is None else node_index[nodes]
        found = np.full(len(index), -1, dtype=np.int64)
        known = (index >= 0) & (index < len(node_region))
        found[known] = node_region[index[known]]
        return found

    for name in pairs.names:
        chosen = pairs.of_interface(name)
        votes = [np.bincount(regions_of(pairs.nodes[chosen, k]) + 1, minlength=n_bins) for k in (0, 1)]
        coords = pairs.coords[chosen]
        if comm is not None:  # every rank's pairs (a node without a cell on its pair's rank does not vote)
            votes = [comm.allreduce(vote[:n_bins]) for vote in votes]
            votes = [np.concatenate([[0], vote[1:]]) if vote[1:].any() else vote for vote in votes]
            coords = np.concatenate(comm.allgather(coords))
        if len(coords) < 2:   # no spacing to measure
            continue
        sides = [names.get(int(vote.argmax()) - 1) for vote in votes]
        tables = [scene["materials"].get(side) or {} for side in sides]
        constants = [tuple(table.get(key) for key in ("E", "nu", "rho")) for table in tables]
        if any(value is None for values in constants for value in values):
            continue
        dissimilar = constants[0] != constants[1]
        speed = min(Material.from_scene(side, table).s_wave_speed for side, table in zip(sides, tables))
        # The node spacing along the interface: per pair the geometric mean of the distances to its
        # nearest and third-nearest neighbours of the same interface (the two edges of a stretched
        # face: sqrt of the face's area), its median over the pairs (h for Q1, h / 2 for Q2).
        from scipy.spatial import cKDTree
        distances = cKDTree(coords).query(coords, k=min(4, len(coords)))[0]
        spacing = np.sqrt(distances[:, 1] * distances[:, -1 if distances.shape[1] < 4 else 3])
        h, coarse = float(np.median(spacing)) * order, float(np.percentile(spacing, 90)) * order
        per_wavelength = speed / frequency / h
        lag = scene["contact"].get("normal_lag") is not None
        try:
            measured = slip_error_at(per_wavelength, dissimilar, results_csv, order, lag)
        except (ValueError, FileNotFoundError) as error:
            advice[name] = f"{sides[0]} | {sides[1]}: no slip advice ({error})"
            continue
        low, high = measured["studied"]
        clipped = "" if low * (1 - 1e-3) <= per_wavelength <= high * (1 + 1e-3) else f" (outside the {low:.3g}-{high:.3g} studied: its end)"
        kind = "dissimilar rocks" if dissimilar else "alike rocks"
        coarser = f" (a tenth of its pairs above {coarse:.3g} m)" if coarse > 1.5 * h else ""
        advice[name] = (f"{sides[0]} | {sides[1]} ({kind}), h ~ {h:.3g} m{coarser}, {per_wavelength:.3g} elements per shortest "
                        f"wavelength {speed / frequency:.4g} m: the slip study ({measured['contrast']}, "
                        f"Q{measured['order']}) measured the peak slip {100 * measured['peak_error']:+.2g} % and "
                        f"its history {100 * measured['history_error']:.2g} % off at this resolution{clipped}"
                        + ("; between dissimilar rocks slip converges slowly without [contact.normal_lag]"
                           if dissimilar and not lag else "")
                        + " (docs/interface_slip_accuracy.md)")
    # Interfaces with the same line are named together.
    grouped = {}
    for name, text in advice.items():
        grouped.setdefault(text, []).append(name)
    return {", ".join(names): text for text, names in grouped.items()}


def lining_elements_for(error_budget: float, results_csv=LINING_RESULTS) -> dict:
    """The fewest elements through a lining, per order, whose cells' largest hoop stress read the true
    peak at the lining's face within a budget, in the lining study (a bending lining after the static
    stage against the closed form, docs/lined_tunnel.md), every finer mesh studied included.

    Args:
        error_budget: largest acceptable relative error of the peak read (e.g. 0.05).
        results_csv: the study's CSV (workflows/results/lining_stress.csv).

    Returns:
        {"per_order": [{"order", "through" (None: not reached), "error", "text"}], "text": one line
        for ``pyfem check``}.

    Raises:
        ValueError: a budget that is not a positive number, or no study results.
    """
    require_budget(error_budget)
    with open(results_csv, newline="") as stream:
        rows = list(csv.DictReader(stream))
    if not rows:
        raise ValueError(f"{results_csv}: no rows; run workflows/lining_stress_accuracy.py")
    per_order = []
    for order in sorted({int(row["order"]) for row in rows}):
        errors = {int(row["through"]): abs(float(row["peak_error"])) for row in rows if int(row["order"]) == order}
        through = coarsest_within(errors, error_budget, finer_is_smaller=False)
        if through is not None:
            text = f"Q{order}: {through} elements through the lining (peak read {100 * errors[through]:.2g} % low)"
            per_order.append({"order": order, "through": through, "error": errors[through], "text": text})
        else:
            finest = max(errors)
            per_order.append({"order": order, "through": None, "error": errors[finest],
                              "text": f"Q{order}: not reached with {finest} (peak read {100 * errors[finest]:.2g} % "
                                      "low): read the face's stress from the field's gradient"})
    return {"per_order": per_order, "text": "; ".join(item["text"] for item in per_order)}



def region_cell_sizes(model, comm=None) -> dict:
    """{region: (n_cells, smallest, largest) element size h (m)} of a model's cells, h being a cell's
    largest vertex distance (a tetrahedron's longest edge; a hexahedron's diagonal over sqrt 3, its
    edge when it is a cube), as the accuracy study's h (the edge of its cubes). comm: the
    distributed model's (a collective): the whole model's, each rank's owned cells merged."""
    from pyfem.operators import cell_regions

    mesh = model.mesh
    tdim = mesh.topology.dim
    connectivity = mesh.geometry.dofmap
    n_cells = mesh.topology.index_map(tdim).size_local
    offsets = np.asarray(connectivity.offsets)
    vertices = np.asarray(connectivity.array, dtype=np.int64).reshape(-1, int(offsets[1] - offsets[0]))[:n_cells]
    corners = 4 if mesh.topology.cell_type.name == "tetrahedron" else 8  # the first nodes are the vertices
    x = mesh.geometry.x[vertices[:, :corners]]
    largest = np.zeros(n_cells)
    for i in range(corners):
        for j in range(i + 1, corners):
            largest = np.maximum(largest, np.linalg.norm(x[:, i] - x[:, j], axis=1))
    h = largest if corners == 4 else largest / np.sqrt(3.0)
    regions = cell_regions(model)[:n_cells]
    names = {tag: name for name, tag in model.regions.items()}
    sizes = {int(tag): (int(np.count_nonzero(regions == tag)), float(h[regions == tag].min()),
                        float(h[regions == tag].max())) for tag in np.unique(regions)}
    if comm is not None:  # each rank's owned cells, merged in the order of the tags
        whole = {}
        for share in comm.allgather(sizes):
            for tag, (count, smallest, largest) in share.items():
                kept = whole.get(tag, (0, np.inf, 0.0))
                whole[tag] = (kept[0] + count, min(kept[1], smallest), max(kept[2], largest))
        sizes = {tag: whole[tag] for tag in sorted(whole)}
    return {names.get(tag, f"tag {tag}"): row for tag, row in sizes.items()}


def resolution_report(scene, model, error_budget: float = 0.05, results_csv=DEFAULT_RESULTS,
                      comm=None) -> tuple[dict, list]:
    """Each region's measured element sizes against the study's advice for its own shear speed.

    Returns:
        ({region: one line for `check`}, [warnings]): a warning where a region's largest cell is
        more than twice the advised h (the box and layered_cavern builders warn from their scene
        keys already; a mesh file is measured here).
    """
    frequency = highest_frequency(scene)
    advice = recommend(error_budget, results_csv, order=scene["mesh"]["order"])
    tetrahedra = model.mesh.topology.cell_type.name == "tetrahedron"
    family = ("P" if tetrahedra else "Q") + str(scene["mesh"]["order"])
    lines, warnings = {}, []
    for name, (count, smallest, largest) in region_cell_sizes(model, comm).items():
        table = scene["materials"].get(name)
        if table is None or any(table.get(key) is None for key in ("E", "nu", "rho")):
            continue
        speed = Material.from_scene(name, table).s_wave_speed
        h = speed / frequency / advice["elements_per_wavelength"]
        lines[name] = (f"{count} {family} cells, h {smallest:.3g}-{largest:.3g} m; {100 * error_budget:g} % advice "
                       f"for its shear speed {speed:.4g} m/s at {frequency:.3g} Hz: h <= {h:.3g} m"
                       + (" (the study ran hexahedra: for tetrahedra a lower bound)" if tetrahedra else ""))
        if largest > 2.0 * h:
            warnings.append(f"mesh: region '{name}' has cells of h up to {largest:.3g} m, {largest / h:.1f}x the "
                            f"{h:.3g} m the accuracy study advises for a {100 * error_budget:g} % error with {family} "
                            f"elements at its shear speed {speed:.4g} m/s and {frequency:.3g} Hz: expect a larger error")
    return lines, warnings

"""Run directory: run.json, monitors/*.csv, energy.csv, fields.xdmf (+ .h5), plots/*.png,
and with contact pairs/*.csv (pair monitors) and the pair-state counts over time.

run.json is written first with "status": "running" and rewritten with "finished",
"interrupted" (Ctrl-C, SIGTERM) or "failed" (any other error) at the end, so a half-written
directory never looks like a finished run. The CSV histories are written row by row as the run
goes (flushed every few seconds of wall time and at the end), so an interrupted or failed run
keeps every sample computed before it stopped. An earlier run in the directory is moved to
`<dir>.previous`, `<dir>.previous-2`, ... (the first free name), never deleted.
"""
from __future__ import annotations

import decimal
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pyfem.operators import NO_REGION, cell_regions  # noqa: F401  (also pyfem.output.cell_regions)

MONITOR_COLUMNS = ["t", "ux", "uy", "uz", "vx", "vy", "vz", "ax", "ay", "az"]
FREEFIELD_COLUMNS = ["ux_ff", "uy_ff", "uz_ff", "vx_ff", "vy_ff", "vz_ff"]
# Stress at the monitor (Pa, tension positive): total = initial (geostatic) + dynamic, its
# largest principal value s1, and s1 of the dynamic increment alone.
STRESS_COLUMNS = ["sxx", "syy", "szz", "sxy", "syz", "sxz", "s1", "s1_dynamic"]
# With nonlinear regions: the law's damage d, its type (0 none, 1 tension, 2 shear) and the
# equivalent plastic strain at the monitor's kernel point (0 in the matrix cells). In a nonlinear
# region the stress columns are the law's stress at that point (total, initial included).
DAMAGE_COLUMNS = ["damage", "damage_type", "plastic_strain"]
_VOIGT = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
ENERGY_COLUMNS = ["t", "kinetic", "strain", "external_work", "damping_work", "balance"]
CONTACT_ENERGY_COLUMNS = ["contact_work", "friction_dissipation"]
# With nonlinear regions: the laws' stored energy Psi and their dissipation since the start (J).
INTERNAL_ENERGY_COLUMNS = ["internal_stored", "internal_dissipation"]
PAIR_COLUMNS = ["t", "dux", "duy", "duz", "slip", "gap", "N", "T", "D", "state"]
PAIR_STATES = ("bonded", "stick", "sliding", "separated")  # kernel state codes 0..3
# Format of the history rows, as np.savetxt wrote them when the files were written at the end.
MONITOR_FORMAT = PAIR_FORMAT = "%.10e"
ENERGY_FORMAT = "%.18e"
# The CSV files are flushed after a sample when this much wall time (s) passed since the last flush.
FLUSH_SECONDS = 2.0
# Symmetric tensors in fields.xdmf: 6 components in the order of XDMF's "Tensor6" attribute,
# which ParaView's XDMF reader expands to the full 3x3 tensor row by row.
TENSOR6_COMPONENTS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))  # xx, xy, xz, yy, yz, zz
# The 8 vertices of a hexahedron in VTK/XDMF order, as (x, y, z) steps on its reference grid.
_VTK_HEXAHEDRON = ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1))
# Cell field "region" of a cell without a region tag (none in a mesh the builders accept).


def _write_json(path: Path, data: dict) -> None:
    """Writes JSON through a temporary file so a reader never sees half a file."""
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_strict_json(data), indent=2, allow_nan=False))
    os.replace(tmp, path)


def _strict_json(value):
    """value with numpy's scalars and arrays as Python's and non-finite numbers as None (null: strict
    JSON has no NaN or Infinity, issue 51)."""
    if isinstance(value, dict):
        return {key: _strict_json(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_strict_json(item) for item in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return _json_default(value)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def max_principal(voigt: np.ndarray) -> np.ndarray:
    """Largest principal value of symmetric tensors given as (n, 6) [xx, yy, zz, xy, yz, xz] (Pa).

    Tension positive (the largest eigenvalue), the paper's "maximum principal stress".
    """
    voigt = np.asarray(voigt, dtype=float).reshape(-1, 6)
    tensor = np.empty((len(voigt), 3, 3))
    for k, (i, j) in enumerate(_VOIGT):
        tensor[:, i, j] = voigt[:, k]
        tensor[:, j, i] = voigt[:, k]
    return np.linalg.eigvalsh(tensor)[:, -1]


def previous_run_dir(out_dir: Path) -> Path:
    """Where an earlier run in out_dir goes: `<out_dir>.previous`, else `.previous-2`, `-3`, ...
    (the first free name)."""
    candidate = out_dir.with_name(out_dir.name + ".previous")
    number = 1
    while candidate.exists():
        number += 1
        candidate = out_dir.with_name(f"{out_dir.name}.previous-{number}")
    return candidate


class CsvHistory:
    """One CSV history file written as the run goes: the header at once, then rows.

    Rows are formatted as np.savetxt formats them (`fmt` for every column, comma-separated)
    and kept until `flush`, which writes them in one piece, so a reader never sees half a row.

    Args:
        path: the file (created or truncated).
        columns: column names (the header line).
        fmt: printf format of every value, e.g. "%.10e".
        resume_at: None: a new file with its header; else a resumed run's file, cut to this many
            bytes (its length at the checkpoint, `size`) and continued.
    """

    def __init__(self, path: Path, columns: list[str], fmt: str, resume_at: int | None = None):
        self.path = Path(path)
        self.n_columns = len(columns)
        self._row_format = ",".join([fmt] * len(columns)) + "\n"
        self._pending: list[str] = []
        if resume_at is None:
            self._file = open(self.path, "w")
            self._file.write(",".join(columns) + "\n")
        else:
            with open(self.path, "r+") as handle:  # rows after the checkpoint go
                handle.truncate(resume_at)
            self._file = open(self.path, "a")

    def size(self) -> int:
        """Flushes and syncs the file to disk; returns its length (bytes), for a checkpoint."""
        self.flush()
        os.fsync(self._file.fileno())
        return self._file.tell()

    def append(self, row) -> None:
        """Queues one row of `n_columns` values."""
        self._pending.append(self._row_format % tuple(row))

    def flush(self) -> None:
        """Writes the queued rows and hands them to the operating system."""
        if self._file.closed:
            return
        if self._pending:
            self._file.write("".join(self._pending))
            self._pending.clear()
        self._file.flush()

    def close(self) -> None:
        """Flushes and closes the file (again: nothing)."""
        if not self._file.closed:
            self.flush()
            self._file.close()


@dataclass
class CellStrain:
    """Cell-average (centroid) strain and stress of a displacement field, for fields.xdmf.

    The strain of each cell is evaluated at its centroid, the mean strain of a Q1 cell and the
    centroid value of a Q2 one: eps = sym(grad u) with grad u_i / dx_l = sum_k u[nodes[c, k], i]
    gradients[c, k, l]; stress = lambda tr(eps) I + 2 G eps + sigma0 (Pa, tension positive).

    Attributes:
        nodes: (c, k) int32 nodes of each cell (its dofmap row).
        gradients: (c, k, 3) basis gradients at the centroid (1/m).
        lame_lambda: (c,) Lame's lambda of each cell's material (Pa).
        shear_modulus: (c,) G of each cell's material (Pa).
        static: (c, 3, 3) initial stress at the centroids (Pa), zero without [initial_stress].

    A cell in no region of the scene's materials gets NaN moduli (its stress is NaN, not a guess).
    """

    nodes: np.ndarray
    gradients: np.ndarray
    lame_lambda: np.ndarray
    shear_modulus: np.ndarray
    static: np.ndarray

    def strain(self, u: np.ndarray) -> np.ndarray:
        """(c, 3, 3) strain of the displacement u (dofs, m) at the cell centroids (-)."""
        nodal = u.reshape(-1, 3)[self.nodes]                                    # (c, k, 3)
        gradient = np.einsum("cki,ckl->cil", nodal, self.gradients)
        return 0.5 * (gradient + gradient.transpose(0, 2, 1))

    def stress(self, strain: np.ndarray) -> np.ndarray:
        """(c, 3, 3) total stress C : strain + sigma0 (Pa) for the cells' strain (c, 3, 3)."""
        trace = np.trace(strain, axis1=1, axis2=2)
        return (self.lame_lambda[:, None, None] * trace[:, None, None] * np.eye(3)
                + 2.0 * self.shear_modulus[:, None, None] * strain + self.static)


def cell_strain_operator(scene, model, cells: np.ndarray | None = None) -> CellStrain:
    """The centroid gradients, materials and initial stress of every cell of the model (or of `cells`,
    local cell indices: the rows follow them).

    Same mapping as `Model.point_gradient_weights`, vectorised over the cells: at the reference
    centroid X_c, J = sum_k x_k (x) dphi_k/dX (dx/dX) and dphi/dx = dphi/dX J^-1.

    Args:
        scene: validated scene ([materials], optional [initial_stress]).
        model: pyfem.operators.Model.
    """
    element = model.V.element.basix_element
    nodes = model.V.dofmap.list.array.reshape(-1, element.dim).astype(np.int32)
    every = len(nodes)
    region_ids = np.full(every, -1, dtype=np.int64)
    for region, tag in model.regions.items():
        in_region = model.cell_tags.indices[model.cell_tags.values == tag]
        region_ids[in_region[in_region < every]] = tag
    if cells is not None:
        nodes, region_ids = nodes[np.asarray(cells, dtype=np.int64)], region_ids[np.asarray(cells, dtype=np.int64)]
    return cell_strain_of(scene, element, nodes, model.node_coords, region_ids, model.regions)


def cell_strain_of(scene, element, nodes: np.ndarray, node_coords: np.ndarray, region_ids: np.ndarray,
                   regions: dict) -> CellStrain:
    """`cell_strain_operator` of the cells with dofmap rows `nodes` (c, k) of the basix `element`, in
    regions `region_ids` (c,) (ids of `regions`: name -> id; a cell of another id gets NaN moduli):
    the distributed model's whole mesh on rank 0 (pyfem/distributed_view.py) as the serial model's."""
    import basix

    from pyfem.initial_stress import stress_field_from_scene
    from pyfem.operators import lame_parameters

    nodes = np.asarray(nodes).astype(np.int32)
    centroid = basix.geometry(element.cell_type).mean(axis=0).reshape(1, 3)
    table = element.tabulate(1, centroid)[:, 0, :, 0]                            # (4, k): phi, dphi/dX
    reference_gradients = table[1:].T                                             # (k, 3)
    coords = node_coords[nodes]                                                   # (c, k, 3)
    jacobian = np.einsum("cka,kb->cab", coords, reference_gradients)              # dx_a/dX_b
    gradients = np.einsum("kb,cbl->ckl", reference_gradients, np.linalg.inv(jacobian))
    n_cells = len(nodes)
    lame_lambda, shear_modulus = np.full(n_cells, np.nan), np.full(n_cells, np.nan)
    for region, tag in regions.items():
        material = scene["materials"].get(region)
        if material is None:
            continue
        in_region = region_ids == tag
        lame_lambda[in_region], shear_modulus[in_region] = lame_parameters(material["E"], material["nu"])
    field = stress_field_from_scene(scene)
    centroids = np.einsum("k,cka->ca", table[0], coords)
    static = np.zeros((n_cells, 3, 3)) if field is None else np.asarray(field(centroids), dtype=np.float64)
    return CellStrain(nodes=nodes, gradients=gradients, lame_lambda=lame_lambda, shear_modulus=shear_modulus,
                      static=static)


def field_mesh(model) -> tuple[np.ndarray, str, np.ndarray, np.ndarray]:
    """The mesh fields.xdmf is written on: every node of the model, in linear cells.

    Q1 hexahedra are written as they are. A Q2 hexahedron (27 nodes) is written as the 8
    hexahedra of its 3 x 3 x 3 node grid, so every node's value is in the file and a viewer
    interpolates linearly between neighbouring nodes (a refined Q1 mesh: the usual way to show
    quadratic results); cell data repeats on the 8 parts. A P1 tetrahedron is written as it is, a P2
    tetrahedron (10 nodes) as the 8 tetrahedra of its vertices and edge nodes (4 at the corners,
    4 around one diagonal of the inner octahedron), likewise.

    Returns:
        (nodes, cell_type, cells, parent): nodes (p,) the model nodes written, in file order;
        cell_type the meshio name ("hexahedron", "tetra"); cells (c', k) indices into `nodes`
        (VTK order); parent (c',) the model cell of each written cell.
    """
    import basix

    element = model.V.element.basix_element
    cell_nodes = model.V.dofmap.list.array.reshape(-1, element.dim)
    n_cells = len(cell_nodes)
    if element.cell_type == basix.CellType.hexahedron:
        degree = model.order
        # Position of each local node on the cell's reference grid (basix points, 0..degree).
        grid = np.rint(np.asarray(element.points) * degree).astype(int)
        local = np.full((degree + 1,) * 3, -1)
        local[grid[:, 0], grid[:, 1], grid[:, 2]] = np.arange(element.dim)
        if np.any(local < 0) or len(grid) != (degree + 1) ** 3:
            raise ValueError(f"fields.xdmf: a hexahedral element of degree {degree} whose nodes are not "
                             "a full grid")
        parts = [[local[i + di, j + dj, k + dk] for di, dj, dk in _VTK_HEXAHEDRON]
                 for k in range(degree) for j in range(degree) for i in range(degree)]
        cell_type, written = "hexahedron", cell_nodes[:, np.array(parts)].reshape(-1, 8)
        parent = np.repeat(np.arange(n_cells), len(parts))
    elif element.cell_type == basix.CellType.tetrahedron and model.order == 1:
        cell_type, written, parent = "tetra", cell_nodes[:, :4], np.arange(n_cells)
    elif element.cell_type == basix.CellType.tetrahedron and model.order == 2:
        parts = _p2_tetrahedron_parts(np.asarray(element.points))
        cell_type, written = "tetra", cell_nodes[:, parts].reshape(-1, 4)
        parent = np.repeat(np.arange(n_cells), len(parts))
        # Each part keeps its parent's orientation only up to the numbering: make every one positive.
        x = model.node_coords[written]
        volume = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
        written[volume < 0] = written[volume < 0][:, [0, 2, 1, 3]]
    else:
        raise ValueError(f"fields.xdmf: cells of type {element.cell_type} are not supported")
    nodes, compact = np.unique(written, return_inverse=True)
    return nodes, cell_type, compact.reshape(written.shape).astype(np.int64), parent


def _p2_tetrahedron_parts(points: np.ndarray) -> np.ndarray:
    """(8, 4) local node indices of the 8 linear tetrahedra of a 10-node tetrahedron whose local
    nodes sit at the reference `points` (basix's element points: 4 vertices, 6 edge midpoints)."""
    vertices = [int(np.argmin(np.linalg.norm(points - corner, axis=1)))
                for corner in np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)]

    def middle(a: int, b: int) -> int:
        return int(np.argmin(np.linalg.norm(points - 0.5 * (points[vertices[a]] + points[vertices[b]]), axis=1)))

    v = vertices
    m = {(a, b): middle(a, b) for a in range(4) for b in range(a + 1, 4)}
    corners = [[v[0], m[0, 1], m[0, 2], m[0, 3]], [m[0, 1], v[1], m[1, 2], m[1, 3]],
               [m[0, 2], m[1, 2], v[2], m[2, 3]], [m[0, 3], m[1, 3], m[2, 3], v[3]]]
    # The inner octahedron around its diagonal m02 - m13; the ring m01, m03, m23, m12.
    ring = [m[0, 1], m[0, 3], m[2, 3], m[1, 2]]
    inner = [[m[0, 2], m[1, 3], ring[k], ring[(k + 1) % 4]] for k in range(4)]
    return np.array(corners + inner, dtype=np.int64)


def time_decimals(*intervals) -> int:
    """Decimals of the shortest of these intervals as written (0.005 -> 3, 0.1 -> 1, 2.5e-5 -> 6),
    at most 15; 0 for none."""
    decimals = 0
    for interval in intervals:
        if interval is not None and interval > 0:
            exponent = decimal.Decimal(repr(float(interval))).normalize().as_tuple().exponent
            decimals = max(decimals, -int(exponent))
    return min(decimals, 15)


def input_motion(simulation) -> dict | None:
    """The input motion the kernel is driven with, its peaks and its 5 %-damped response spectrum.

    The motion is the incident wave's displacement g(t) at the reference point times wave.scale,
    with its velocity and acceleration, as the kernel's waveform table holds them (a record as
    processed: window, taper, resampling, band-pass, baseline, pga; a Ricker wavelet sampled on
    its table grid). Each wave component adds its own scale (listed under "components").

    Returns:
        None without a [wave]; else a dict with the summary for run.json (SI units) and, under
        "_series", (t, a, v, d, spectrum, run end) for `plots.input_motion` (not for run.json).
    """
    from pyfem.seismic.records import STANDARD_GRAVITY
    from pyfem.seismic.spectrum import DEFAULT_PERIODS, STANDARD_DAMPING, peak_values, response_spectrum

    freefield = simulation.freefield
    if freefield is None:
        return None
    scene = simulation.scene
    wave = scene["wave"]
    scale = float(wave.get("scale", 1.0))
    tables = freefield.tables
    t = np.round(tables.t0 + tables.dt * np.arange(tables.g.shape[1]), time_decimals(tables.dt) + 3)
    d, v, a = (scale * np.asarray(values[0], dtype=float) for values in (tables.g, tables.dg, tables.ddg))
    from pyfem.clock import run_origin

    run_end = run_origin(simulation.lead_in, simulation.time_step) + simulation.n_steps * simulation.time_step.dt
    motion = scene["wave"]["motion"]
    record = motion.get("record")
    if record is None:
        from pyfem.seismic.waveforms import ricker, ricker_end

        ricker_motion = motion["ricker"]
        end = ricker_end(ricker_motion["f0"], ricker_motion["t0"])
        if t[-1] < end:
            # The Ricker's table holds only the run's time: the wavelet's own peaks and spectrum come
            # from the whole wavelet on the table's grid (a record's table holds the whole record).
            whole = tables.t0 + tables.dt * np.arange(math.ceil((end - tables.t0) / tables.dt) + 1)
            t = np.round(whole, time_decimals(tables.dt) + 3)
            d, v, a = (scale * values for values in ricker(whole, ricker_motion["f0"], ricker_motion["amplitude"],
                                                          ricker_motion["t0"]))
    inside = t <= run_end + 1e-9 * max(run_end, 1.0)
    spectrum = response_spectrum(a, tables.dt, DEFAULT_PERIODS, STANDARD_DAMPING)
    summary = {
        "kind": "record" if record is not None else "ricker",
        **({"source": str(record["file"])} if record is not None else {}),
        "what": "incident displacement g(t) x wave.scale at the reference point, its velocity and "
                "acceleration, as the kernel's waveform table holds them (a record as processed; a Ricker "
                "wavelet longer than the run on the table's grid beyond the run's end too)",
        "scale": scale,
        "components": [{key: component[key] for key in ("type", "scale", "angle", "azimuth")}
                       for component in scene.wave_components()],
        "dt": float(tables.dt),
        "t_end": float(t[-1]),
        **peak_values(t, a, v, d),
        "within_run": {"until": float(run_end), **peak_values(t[inside], a[inside], v[inside], d[inside])},
        "spectrum": {"damping": spectrum["damping"], "periods": np.round(spectrum["periods"], 6).tolist(),
                     "psa": [float(f"{value:.6g}") for value in spectrum["psa"]]},
        "plot": "plots/input.png",
        "_series": (t, a, v, d, spectrum, run_end),
    }
    summary["pga_g"] = summary["pga"] / STANDARD_GRAVITY
    return summary


def input_title(motion: dict) -> str:
    """plots/input.png's title of an `input_motion`."""
    source = Path(motion["source"]).name if motion["kind"] == "record" else "Ricker wavelet"
    scale = "" if motion["scale"] == 1.0 else f" x wave.scale {motion['scale']:g}"
    return (f"input motion: {source}{scale}: PGA {motion['pga_g']:.3g} g, "
            f"PGV {100 * motion['pgv']:.3g} cm/s, PGD {100 * motion['pgd']:.3g} cm")


def tensor6(tensors: np.ndarray) -> np.ndarray:
    """(n, 6) components xx, xy, xz, yy, yz, zz (XDMF "Tensor6") of symmetric (n, 3, 3) tensors."""
    return np.stack([tensors[:, i, j] for i, j in TENSOR6_COMPONENTS], axis=1)


def energy_summary(energy: np.ndarray, names: list[str] = ENERGY_COLUMNS) -> dict:
    """Final energies and the balance error relative to the largest energy in play."""
    columns = {name: energy[:, i] for i, name in enumerate(names)}
    scale = max(np.max(np.abs(columns["external_work"])), np.max(columns["kinetic"] + columns["strain"]),
                np.max(np.abs(columns["damping_work"])), 1e-300)
    if "contact_work" in columns:
        scale = max(scale, np.max(np.abs(columns["contact_work"])),
                    np.max(np.abs(columns["friction_dissipation"])))
    if "internal_stored" in columns:
        scale = max(scale, np.max(columns["kinetic"] + columns["strain"] + columns["internal_stored"]),
                    np.max(np.abs(columns["internal_dissipation"])))
    final = {name: float(columns[name][-1]) for name in names[1:]}
    final["balance_error"] = float(np.max(np.abs(columns["balance"])) / scale)
    final["reference_energy"] = float(scale)
    return final


def energy_columns(contact: bool, element_loop: bool) -> list[str]:
    """energy.csv's columns: the account's, then contact's work and friction, then the element loop's."""
    return ENERGY_COLUMNS + (CONTACT_ENERGY_COLUMNS if contact else []) + (INTERNAL_ENERGY_COLUMNS if element_loop else [])


def pair_values(contact, normal: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(n_pairs, 9): dux, duy, duz, slip, gap (m), N, T (N), D (-), state of every pair of the
    kernel's ContactPairs `contact` (unit normals `normal`) at the displacement u."""
    delta = np.asarray(contact.relative_displacement(u)).reshape(-1, 3)
    gap = np.einsum("pc,pc->p", delta, normal)
    slip = np.linalg.norm(delta - gap[:, None] * normal, axis=1)
    tangential = np.linalg.norm(np.asarray(contact.tangential_force()).reshape(-1, 3), axis=1)
    return np.column_stack([delta, slip, gap, np.asarray(contact.normal_force()), tangential,
                            np.asarray(contact.deterioration()), np.asarray(contact.state(), dtype=float)])


def pair_peaks(rows: np.ndarray, names: list, where: list) -> dict:
    """run.json "pairs": peaks and final values per pair monitor; rows (nt, m, 10): t, then
    PAIR_COLUMNS[1:]; where: per monitor (pair index, interface name, point)."""
    peaks = {}
    for j, name in enumerate(names):
        index, interface, point = where[j]
        values = rows[:, j, 1:]
        peaks[name] = {
            "pair": index,
            "interface": interface,
            "point": point,
            "max_relative_displacement": float(np.max(np.linalg.norm(values[:, 0:3], axis=1))),
            "max_slip": float(np.max(values[:, 3])),
            "residual_slip": float(values[-1, 3]),
            "max_gap": float(np.max(values[:, 4])),
            "max_N": float(np.max(values[:, 5])),
            "max_T": float(np.max(values[:, 6])),
            "min_D": float(np.min(values[:, 7])),
            "final_state": PAIR_STATES[int(values[-1, 8])],
        }
    return peaks


def pair_state_summary(times: np.ndarray, counts: np.ndarray, n_pairs: int, deterioration) -> dict:
    """run.json's pair_states (counts per state at every sample), pair_states_final, n_pairs and the
    deterioration's words (`deterioration`: contact_arguments' tuple or None)."""
    counts = counts.reshape(-1, len(PAIR_STATES))
    out = {"pair_states": {"t": np.asarray(times).tolist(),
                           **{name: counts[:, k].tolist() for k, name in enumerate(PAIR_STATES)}},
           "pair_states_final": {name: int(counts[-1, k]) for k, name in enumerate(PAIR_STATES)},
           "n_pairs": int(n_pairs)}
    if deterioration is not None:
        from pyfem.interfaces import wear_words

        out["deterioration"] = wear_words(deterioration, float(times[-1]))
    return out


def monitor_rows(t: float, u: np.ndarray, v: np.ndarray, a: np.ndarray, nodes: np.ndarray, weights: np.ndarray,
                 freefield, points: np.ndarray, stress, kernel: dict | None) -> np.ndarray:
    """(m, columns) rows of monitors/NAME.csv at time t (s) for m monitors: u, v, a interpolated from
    their cells' `nodes` with `weights`; the free field at their `points` (with a wave); with `stress`
    (effects.MonitorStress) the total and dynamic stress, s1 of each; `kernel`: the law's values at
    the monitors' kernel points (NonlinearRegions.point_values: its stress replaces the matrix cells'
    where found, then damage, damage type and plastic strain), None without the element loop. The
    whole model's writer and the distributed run (pyfem/distributed_model.py) both write these."""
    values = [np.full((len(nodes), 1), t)]
    for field in (u, v, a):
        values.append(np.einsum("mk,mkc->mc", weights, field.reshape(-1, 3)[nodes]))
    if freefield is not None:
        times = np.array([t])
        values += [freefield.displacement(points, times)[0], freefield.velocity(points, times)[0]]
    if stress is not None:
        dynamic_tensor = stress.dynamic_stress(u)
        dynamic = np.stack([dynamic_tensor[:, i, j] for i, j in _VOIGT], axis=1)
        static = np.stack([stress.static[:, i, j] for i, j in _VOIGT], axis=1)
        total = dynamic + static
        if kernel is not None:
            found = kernel["found"]
            total[found] = kernel["stress"][found]
            dynamic[found] = total[found] - static[found]
        values += [total, max_principal(total)[:, None], max_principal(dynamic)[:, None]]
        if kernel is not None:
            values += [kernel["damage"][:, None], kernel["damage_type"][:, None].astype(float),
                       kernel["plastic_strain"][:, None]]
    return np.hstack(values)


def flush_run(histories: dict, summary: dict, times: list, out_dir: Path) -> float:
    """Writes the queued rows of `histories` (CsvHistory) to disk and the time reached to run.json;
    returns the time.monotonic() of the flush (a run writer's, the whole model's or the distributed)."""
    for history in histories.values():
        history.flush()
    if times:
        summary["time_reached"] = times[-1]
        _write_json(Path(out_dir) / "run.json", summary)
    return time.monotonic()


def monitor_peaks(rows: np.ndarray, columns: list, names: list, times: np.ndarray, regions: list | None) -> dict:
    """Peaks per monitor from its history rows (nt, m, len(columns)): |u|, |v|, |a|; the difference
    from the free field where its columns are; the largest principal stress where the stress
    columns are (regions: each monitor's region); damage and plastic strain where they are."""
    peaks = {}
    column = {name: k for k, name in enumerate(columns)}
    for j, name in enumerate(names):
        u, vel, acc = (rows[:, j, column[f"{q}x"]:column[f"{q}z"] + 1] for q in "uva")
        peak = {"displacement": float(np.max(np.linalg.norm(u, axis=1))),
                "velocity": float(np.max(np.linalg.norm(vel, axis=1))),
                "acceleration": float(np.max(np.linalg.norm(acc, axis=1)))}
        if "ux_ff" in column:
            reference = rows[:, j, column["ux_ff"]:column["uz_ff"] + 1]
            norm = np.linalg.norm(reference)
            peak["freefield_error"] = float(np.linalg.norm(u - reference) / norm) if norm > 0 else math.nan
        if "s1" in column:
            s1, s1_dynamic = rows[:, j, column["s1"]], rows[:, j, column["s1_dynamic"]]
            peak["region"] = regions[j]
            peak["s1_max"] = float(np.max(s1))
            peak["s1_max_time"] = float(times[int(np.argmax(s1))])
            peak["s1_initial"] = float(s1[0])
            peak["s1_dynamic_max"] = float(np.max(s1_dynamic))
        if "damage" in column:
            peak["damage_max"] = float(np.max(rows[:, j, column["damage"]]))
            peak["plastic_strain_max"] = float(np.max(rows[:, j, column["plastic_strain"]]))
        peaks[name] = peak
    return peaks


def peak_memory_mib() -> float:
    """The process's peak resident set size so far (MiB; getrusage's ru_maxrss, KiB on Linux)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


# Dissipation before t = 0 above this share of the run's is reported (run.json "lead_in", a warning).
LEAD_IN_DISSIPATION_SHARE = 0.01


def lead_in_activity(times: np.ndarray, energy: np.ndarray, columns: list, lead_in: float) -> tuple[dict, str] | None:
    """What a record's filter lead-in (t < 0) did to the model, from the energy samples: the plastic
    and damage dissipation (internal_dissipation) and the friction dissipation of the pairs
    (friction_dissipation) reached at the last sample with t <= 0, against their values at the
    end. The lead-in carries the zero-phase filter's precursor, long-period motion that is not quiet
    for a model at its strength (pairs handed over near their friction limit, rock at yield).
    Returns None without a lead-in or without dissipation in it, else (run.json "lead_in", the
    warning's words)."""
    times = np.asarray(times, dtype=float)
    if lead_in <= 0.0 or times.size == 0 or times[0] >= 0.0:
        return None
    names = [name for name in ("internal_dissipation", "friction_dissipation") if name in columns]
    if not names:
        return None
    before = int(np.searchsorted(times, 0.0, side="right")) - 1  # the last sample at t <= 0
    if before < 0:
        return None
    energy = np.asarray(energy, dtype=float).reshape(times.size, len(columns))
    record = {"seconds": float(lead_in)}
    worst = 0.0
    words = []
    for name in names:
        column = energy[:, columns.index(name)]
        start, at_zero, end = float(column[0]), float(column[before]), float(column[-1])
        during, whole = at_zero - start, end - start
        share = during / whole if whole > 0.0 else (1.0 if during > 0.0 else 0.0)
        record[name] = {"before_t0": during, "run": whole, "share": share}
        if during > 0.0 and share > LEAD_IN_DISSIPATION_SHARE:
            worst = max(worst, share)
            kind = "plastically" if name == "internal_dissipation" else "by friction in the pairs"
            words.append(f"{during:.3g} J {kind} ({100 * share:.0f} % of the run's)")
    if not words:
        return record, ""
    reached = " (the run ended before t = 0)" if times[-1] <= 0.0 else ""
    return record, (f"the record's {lead_in:.3g} s lead-in (t < 0) was not quiet: before t = 0{reached} it dissipated "
                    f"{' and '.join(words)}; the filter's precursor carries long-period motion that a model at its "
                    "strength answers; a shorter [wave.motion.record] lead_in cuts it (docs/method.md, 'Time axis')")


def report_lead_in(summary: dict, scene, lead_in: float, times, energy, columns: list) -> None:
    """run.json "lead_in" and, when the lead-in dissipated more than LEAD_IN_DISSIPATION_SHARE of a
    run's plastic or friction dissipation, a warning (scene.warn prints it; run.json keeps it)."""
    found = lead_in_activity(np.asarray(times), np.asarray(energy), list(columns), lead_in)
    if found is None:
        return
    record, message = found
    summary["lead_in"] = record
    if message:
        if scene is not None and hasattr(scene, "warn"):
            scene.warn(message)
        if message not in summary.setdefault("warnings", []):
            summary["warnings"].append(message)

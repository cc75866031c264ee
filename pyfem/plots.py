"""Plots of a run: monitor histories (against the exact free field when there is one), energy,
with contact the pair-state counts and pair monitors, with a [wave] the input motion and its
response spectrum."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # files only; no display on these machines
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _read_csv(path):
    with open(path) as stream:
        header = stream.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, i] for i, name in enumerate(header)}


def monitor(png_path, csv_path) -> None:
    """Displacement, velocity and acceleration components of one monitor against time, and its
    stress history (sxx, syy, szz, sxz and the maximum principal stress s1, total) when the file
    has stress columns.

    Args:
        png_path: output image.
        csv_path: monitors/NAME.csv of a run (m, m/s, m/s^2, Pa); free-field columns, when
            present, are drawn dashed.
    """
    columns = _read_csv(csv_path)
    t = columns["t"]
    with_stress = "sxx" in columns
    fig, axes = plt.subplots(4 if with_stress else 3, 1, figsize=(8, 9 if with_stress else 7), sharex=True)
    if with_stress:
        # Total stress (initial + dynamic), tension positive, and the maximum principal stress.
        ax = axes[-1]
        for name, colour in (("sxx", "C0"), ("syy", "C1"), ("szz", "C2"), ("sxz", "C4"), ("s1", "k")):
            ax.plot(t, 1e-6 * columns[name], colour, lw=1.4 if name == "s1" else 1.0, label=name)
        ax.set_ylabel("stress (MPa)")
        ax.grid(alpha=0.3)
        ax.legend(ncol=5, fontsize=7, title="total stress, tension > 0", title_fontsize=7)
    for ax, (quantity, unit, factor) in zip(axes, (("u", "mm", 1e3), ("v", "mm/s", 1e3), ("a", "m/s$^2$", 1.0))):
        for component, colour in zip("xyz", ("C0", "C1", "C2")):
            ax.plot(t, factor * columns[f"{quantity}{component}"], colour, lw=1.2, label=f"{quantity}{component}")
            reference = columns.get(f"{quantity}{component}_ff")
            if reference is not None:
                ax.plot(t, factor * reference, colour, ls="--", lw=0.9, label=f"{quantity}{component} free field")
        ax.set_ylabel(f"{quantity} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=3, fontsize=7)
    axes[-1].set_xlabel("t (s)")
    axes[0].set_title(f"monitor {png_path.stem.removeprefix('monitor_')}")
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)


def energy(png_path, energy_rows: np.ndarray, columns: list[str]) -> None:
    """Energy balance of a run: kinetic + strain against input work minus damping.

    Args:
        png_path: output image.
        energy_rows: (nt, len(columns)) in J, first column t in s.
        columns: names of the columns.
    """
    data = {name: energy_rows[:, i] for i, name in enumerate(columns)}
    t = data["t"]
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax = axes[0]
    ax.plot(t, data["kinetic"], label="kinetic")
    ax.plot(t, data["strain"], label="strain (incl. boundary springs)")
    ax.plot(t, data["kinetic"] + data["strain"], "k", label="stored")
    ax.plot(t, data["external_work"], "--", label="input work")
    ax.plot(t, data["damping_work"], ":", label="dissipated (dashpots, Rayleigh)")
    ax.set_ylabel("energy (J)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    scale = max(np.max(np.abs(data["external_work"])), np.max(data["kinetic"] + data["strain"]), 1e-300)
    axes[1].plot(t, data["balance"] / scale)
    axes[1].set_ylabel("balance error / max energy")
    axes[1].set_xlabel("t (s)")
    axes[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)


def pair_states(png_path, times: np.ndarray, counts: np.ndarray, names) -> None:
    """Number of contact pairs in each state against time.

    Args:
        png_path: output image.
        times: (nt,) sample times (s).
        counts: (nt, 4) pairs bonded, stick, sliding, separated.
        names: the four state names.
    """
    fig, ax = plt.subplots(figsize=(8, 4))
    for k, name in enumerate(names):
        ax.plot(times, counts[:, k], label=name)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("pairs")
    ax.set_title("interface pair states")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)


def pair_monitor(png_path, csv_path) -> None:
    """Slip, gap, forces and deterioration of one monitored pair against time.

    Args:
        png_path: output image.
        csv_path: pairs/NAME.csv of a run (m, N, -).
    """
    columns = _read_csv(csv_path)
    t = columns["t"]
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    axes[0].plot(t, 1e3 * columns["slip"], label="slip |P_t Delta|")
    axes[0].plot(t, 1e3 * columns["gap"], label="gap n.Delta")
    axes[0].set_ylabel("mm")
    axes[1].plot(t, columns["N"], label="N (compression +)")
    axes[1].plot(t, columns["T"], label="|T|")
    axes[1].set_ylabel("N")
    axes[2].plot(t, columns["D"], label="D")
    axes[2].plot(t, columns["state"] / 3.0, ":", label="state / 3")
    axes[2].set_ylabel("-")
    axes[-1].set_xlabel("t (s)")
    for ax in axes:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"pair monitor {png_path.stem.removeprefix('pair_')}")
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)


def input_motion(png_path, t, acceleration, velocity, displacement, spectrum: dict, run_end: float,
                 title: str = "input motion") -> None:
    """The input motion: acceleration, velocity and displacement against time, and its response
    spectrum (pseudo-acceleration against period).

    Args:
        png_path: output image.
        t, acceleration, velocity, displacement: (n,) s, m/s^2, m/s, m.
        spectrum: `pyfem.seismic.spectrum.response_spectrum` of the acceleration.
        run_end: simulated time the run reaches (s), marked on the histories.
        title: the figure's title.
    """
    from pyfem.seismic.records import STANDARD_GRAVITY

    fig = plt.figure(figsize=(12, 6.5))
    grid = fig.add_gridspec(3, 2, width_ratios=(1.6, 1.0))
    panels = ((acceleration, 1.0 / STANDARD_GRAVITY, "a (g)"), (velocity, 100.0, "v (cm/s)"),
              (displacement, 100.0, "d (cm)"))
    axes = []
    for row, (values, factor, label) in enumerate(panels):
        ax = fig.add_subplot(grid[row, 0], sharex=axes[0] if axes else None)
        ax.plot(t, factor * np.asarray(values), "C0", lw=0.9)
        peak = int(np.argmax(np.abs(values)))
        ax.plot(t[peak], factor * values[peak], "o", color="C3", ms=4,
                label=f"peak {factor * abs(values[peak]):.3g} at {t[peak]:.3g} s")
        if run_end < t[-1]:
            ax.axvline(run_end, color="0.4", ls="--", lw=0.8, label=f"run ends ({run_end:g} s)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
        axes.append(ax)
    axes[-1].set_xlabel("t (s)")
    ax = fig.add_subplot(grid[:, 1])
    ax.semilogx(spectrum["periods"], np.asarray(spectrum["psa"]) / STANDARD_GRAVITY, "C1", lw=1.2)
    ax.axhline(np.max(np.abs(acceleration)) / STANDARD_GRAVITY, color="0.5", ls=":", lw=0.8, label="PGA")
    ax.set_xlabel("period T (s)")
    ax.set_ylabel("pseudo-acceleration PSA (g)")
    ax.set_title(f"response spectrum, {100 * spectrum['damping']:.0f} % damping", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of 2-D points (m, 2), counter-clockwise (Andrew's monotone chain): the outline a
    hexahedron cut by a plane shows when its vertices are projected on that plane."""
    points = np.unique(np.round(points, 9), axis=0)
    if len(points) < 3:
        return points

    def half(sequence):
        chain = []
        for p in sequence:
            while len(chain) >= 2 and np.cross(chain[-1] - chain[-2], p - chain[-2]) <= 0.0:
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(points), half(points[::-1])
    return np.array(lower[:-1] + upper[:-1])


def deformed_section(png_path, coords: np.ndarray, cell_nodes: np.ndarray, displacement: np.ndarray,
                     regions: np.ndarray, region_names: dict, y: float, t: float, title: str = "") -> float:
    """The section y = const of the model drawn undeformed (grey outline) and deformed (cells
    coloured by region), the displacement magnified so that its largest value is 4 % of the
    section's size.

    Args:
        png_path: output image.
        coords: (n, 3) coordinates of the nodes cell_nodes refers to (m).
        cell_nodes: (c, 8) the vertices of the cells cut by the section.
        displacement: (n, 3) displacement to draw (m), usually relative to the section's mean.
        regions: (c,) region id of each cell; region_names: id -> name.
        y: the section (m); t: the time shown (s); title: figure title.

    Returns:
        The magnification used.
    """
    from matplotlib.collections import PolyCollection

    size = float(np.ptp(coords[:, [0, 2]], axis=0).max())
    largest = float(np.linalg.norm(displacement, axis=1).max(initial=0.0))
    scale = 0.04 * size / largest if largest > 0.0 else 1.0
    deformed = coords + scale * displacement
    before = [convex_hull(coords[nodes][:, [0, 2]]) for nodes in cell_nodes]
    after = [convex_hull(deformed[nodes][:, [0, 2]]) for nodes in cell_nodes]
    ids = sorted(set(int(r) for r in regions))
    colour = {region: f"C{k % 10}" for k, region in enumerate(ids)}
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.add_collection(PolyCollection(before, facecolors="none", edgecolors="0.75", linewidths=0.3))
    ax.add_collection(PolyCollection(after, facecolors=[colour[int(r)] for r in regions], edgecolors="k",
                                     linewidths=0.15, alpha=0.85))
    for region in ids:
        ax.plot([], [], "s", color=colour[region], label=region_names.get(region, str(region)))
    ax.autoscale_view()
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title(f"{title}\nsection y = {y:.3g} m at t = {t:.3f} s: displacement relative to the section's mean, "
                 f"x {scale:.3g} (largest {100 * largest:.3g} cm)".strip(), fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return scale

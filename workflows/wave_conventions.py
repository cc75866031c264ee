"""The wave conventions of a scene's [wave] table, drawn from the free field itself.

docs/scene-keys.md ("Wave conventions") says in words how `wave.angle`, `wave.azimuth`, the
polarisations of P, SV and SH, the reference point and `wave.surface` are meant. This script
draws the same conventions, docs/wave-conventions.png, with every arrow and delay taken from
`pyfem.seismic.freefield.FreeField`, the code that makes the seismic input of a run: if the
conventions changed there, the figure would follow.

Three panels:
  * left, the vertical plane of propagation (phi = 0): the default scene's box below a free
    surface, an SV wave at theta = 30 deg arriving from below with its propagation direction
    k and its polarisation, the P polarisation for comparison, the reflected SV and P, and the
    default reference point x0, the box corner the wavefront reaches first (its delay is 0,
    every other point's is positive);
  * middle, the plan view for azimuth phi = 30 deg: the horizontal direction of propagation
    e_h (from +x towards +y) and the SH polarisation e_t = e_z x e_h;
  * right, what the motion g(t) is: the incident displacement at x0. For vertical SV the total
    motion at x0 adds the reflection later, and the free surface moves 2 g.

Sample run (from the repository root, a few seconds):
    /usr/bin/python3 workflows/wave_conventions.py                 # writes docs/wave-conventions.png
    /usr/bin/python3 workflows/wave_conventions.py --out /tmp/w.png
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pyfem.scene import MATERIAL_PRESETS  # noqa: E402
from pyfem.seismic.freefield import FreeField  # noqa: E402
from pyfem.seismic.waveforms import ricker  # noqa: E402

# ----------------------------------------------------------------------------- parameters
OUT = ROOT / "docs" / "wave-conventions.png"
ROCK = MATERIAL_PRESETS["sandstone"]           # E 8 GPa, nu 0.24, rho 2600 kg/m^3
BOX = ([0.0, 0.0, 0.0], [160.0, 20.0, 160.0])  # workflows/scenes/default.toml, m
SURFACE = 200.0                                # z of the free surface, m
ANGLE = 30.0                                   # deg from the vertical (left panel)
AZIMUTH = 30.0                                 # deg from +x towards +y (middle panel)
F0 = 5.0                                       # Ricker peak frequency, Hz (right panel)


def ricker_motion(t):
    """The motion g(t): a unit Ricker wavelet (m, m/s, m/s^2)."""
    return ricker(t, F0, 1.0)


def free_field(wave_type: str, angle: float, azimuth: float = 0.0, surface: float | None = SURFACE):
    """The FreeField of one incident wave in the sandstone half-space below `surface`."""
    return FreeField([dict(type=wave_type, angle=angle, azimuth=azimuth)], ROCK["E"], ROCK["nu"], ROCK["rho"],
                     surface=surface, waveform=ricker_motion, table_grid=(0.0, 1.0e-3, 3000),
                     model_bounds=BOX)


def component(field: FreeField, name: str):
    """The plane-wave component called `name` ("SV incident", "SV->P reflected", ...)."""
    return next(c for c in field.components if c.name == name)


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def box_corners():
    lo, hi = (np.asarray(b) for b in BOX)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def reference_point(field: FreeField, name: str) -> np.ndarray:
    """The box corner where the incident component's delay tau = p.x + offset is 0 (the smallest)."""
    incident = component(field, name)
    corners = box_corners()
    delays = corners @ incident.slowness + incident.delay_offset
    return corners[np.argmin(delays)]


# ----------------------------------------------------------------------------- the panels
def draw_vertical_plane(ax):
    from matplotlib.patches import Rectangle

    sv, p = free_field("SV", ANGLE), free_field("P", ANGLE)
    incident = component(sv, "SV incident")
    k = unit(incident.slowness)                     # propagation direction
    d_sv = unit(incident.amplitude)                 # SV polarisation
    d_p = unit(component(p, "P incident").amplitude)
    x0 = reference_point(sv, "SV incident")
    lo, hi = (np.asarray(b) for b in BOX)
    xz = [0, 2]

    ax.add_patch(Rectangle((lo[0], lo[2]), hi[0] - lo[0], hi[2] - lo[2], fill=False, lw=1.5, color="0.3"))
    ax.text(hi[0] - 4, lo[2] + 6, "model", ha="right", color="0.3")
    ax.plot([-120, 330], [SURFACE, SURFACE], color="saddlebrown", lw=2)
    ax.text(330, SURFACE + 6, "free surface z = wave.surface", ha="right", color="saddlebrown")

    # The incident ray through the box centre up to the surface, and the reflected rays from there.
    centre = 0.5 * (lo + hi)
    hit = centre + k * (SURFACE - centre[2]) / k[2]
    start = hit - 400.0 * k
    ax.annotate("", xy=hit[xz], xytext=start[xz], arrowprops=dict(arrowstyle="-|>", color="k", lw=1.2))
    for name, colour, label in (("SV->SV reflected", "tab:blue", "reflected SV"),
                                ("SV->P reflected", "tab:green", "reflected P")):
        direction = unit(component(sv, name).slowness)
        end = hit + 110.0 * direction
        ax.annotate("", xy=end[xz], xytext=hit[xz], arrowprops=dict(arrowstyle="-|>", color=colour, lw=1.0))
        ax.text(*end[xz], " " + label, color=colour, va="top")

    # The angle from the vertical, at the ray's start.
    arc = np.radians(np.linspace(0.0, ANGLE, 20))
    radius = 60.0
    ax.plot(start[0] + radius * np.sin(arc), start[2] + radius * np.cos(arc), color="k", lw=0.8)
    ax.plot([start[0], start[0]], [start[2], start[2] + 1.3 * radius], color="k", lw=0.6, ls=":")
    ax.text(start[0] - 4, start[2] + 1.35 * radius, "θ = wave.angle", fontsize=9, ha="right")

    # Polarisations at a point on the incident ray.
    point = start + 270.0 * k
    scale = 45.0
    arrows = ((k, "tab:red", "P: d = k"), (d_sv, "tab:blue", "SV: d = cos θ e_h − sin θ e_z"))
    for d, colour, label in arrows:
        tip = point + scale * d
        ax.annotate("", xy=tip[xz], xytext=point[xz], arrowprops=dict(arrowstyle="-|>", color=colour, lw=2.0))
        ax.text(tip[0], tip[2] - (0 if d[2] > 0 else 6), " " + label, color=colour, fontsize=9,
                va="bottom" if d[2] > 0 else "top")
    assert np.allclose(d_p, k)  # P is polarised along its propagation

    # Wavefronts (perpendicular to k): the one through x0 is the first to touch the model.
    along = np.array([k[2], 0.0, -k[0]])
    for offset, style in ((0.0, "-"), (-60.0, "--")):
        a, b = x0 + offset * k - 200.0 * along, x0 + offset * k + 200.0 * along
        ax.plot([a[0], b[0]], [a[2], b[2]], color="tab:orange", lw=1.0, ls=style)
    ax.plot(*x0[xz], "o", color="tab:orange", ms=7)
    ax.text(x0[0] + 8, x0[2] - 30, "x0: default reference point\n(the corner the wave reaches first)",
            color="tab:orange", fontsize=9, va="top")

    ax.set_xlim(-130, 340)
    ax.set_ylim(-170, 240)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)   [e_h = +x for azimuth 0]")
    ax.set_ylabel("z (m), up")
    ax.set_title(f"vertical plane: SV at θ = {ANGLE:g}°, azimuth 0", fontsize=10)


def draw_plan_view(ax):
    sh = free_field("SH", 0.0, AZIMUTH, surface=None)
    sv = free_field("SV", ANGLE, AZIMUTH, surface=None)
    e_h = unit(component(sv, "SV incident").slowness * [1.0, 1.0, 0.0])
    e_t = unit(component(sh, "SH incident").amplitude)
    arrows = ((e_h, "k", "e_h: horizontal propagation"), (e_t, "tab:purple", "SH: d = e_t = e_z × e_h"))
    for v, colour, label in arrows:
        ax.annotate("", xy=v[:2], xytext=(0, 0), arrowprops=dict(arrowstyle="-|>", color=colour, lw=2.0))
        ax.text(*(1.05 * v[:2]), label, color=colour, fontsize=9,
                ha="left" if v[0] > 0 else "right", va="bottom")
    for axis, label in (([1.3, 0.0], "+x"), ([0.0, 1.3], "+y")):
        ax.annotate("", xy=axis, xytext=(0, 0), arrowprops=dict(arrowstyle="->", color="0.5", lw=0.8))
        ax.text(*axis, " " + label, color="0.5")
    arc = np.radians(np.linspace(0.0, AZIMUTH, 20))
    ax.plot(0.45 * np.cos(arc), 0.45 * np.sin(arc), color="k", lw=0.8)
    ax.text(0.5, 0.1, "φ = wave.azimuth", fontsize=9)
    ax.text(-1.25, -0.55, "z (up) out of the page;\nSV: in the vertical plane of e_h", fontsize=8,
            color="0.3")
    ax.set_xlim(-1.3, 1.6)
    ax.set_ylim(-0.7, 1.5)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(f"plan view: azimuth φ = {AZIMUTH:g}°", fontsize=10)


def draw_motion(ax):
    field = free_field("SV", 0.0)
    incident_only = free_field("SV", 0.0, surface=None)
    x0 = reference_point(field, "SV incident")
    top = np.array([x0[0], x0[1], SURFACE])
    t = np.linspace(0.0, 0.8, 1601)
    g = ricker_motion(t)[0]
    ax.plot(t, incident_only.displacement(x0[None, :], t)[:, 0, 0], color="k", lw=2.5, alpha=0.35,
            label="incident wave at x0 = g(t)")
    ax.plot(t, g, color="k", lw=0.8, ls="--", label="the motion g(t) (wave.motion)")
    ax.plot(t, field.displacement(x0[None, :], t)[:, 0, 0], color="tab:blue", lw=1.0,
            label="total (with reflection) at x0")
    ax.plot(t, field.displacement(top[None, :], t)[:, 0, 0], color="saddlebrown", lw=1.0,
            label="total at the free surface: 2 g(t - delay)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("u_x (per unit g)")
    ax.set_title("vertical SV: what the motion g(t) is", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_ylim(-1.1, 2.9)
    ax.grid(alpha=0.3)


def main(argv=None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=OUT, help=f"PNG file (default {OUT.relative_to(ROOT)})")
    args = parser.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), gridspec_kw=dict(width_ratios=[1.35, 0.9, 1.1]))
    draw_vertical_plane(axes[0])
    draw_plan_view(axes[1])
    draw_motion(axes[2])
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110, metadata={"Software": None})
    plt.close(fig)
    print(f"wrote {args.out}")
    return args.out


if __name__ == "__main__":
    main()

"""The case-study mesh (coarse preset) written to a gmsh .msh file.

Builds `pyfem.geometry.layered_cavern.build_layered_cavern` with the
"coarse" preset (about 44 000 hexahedra: the Azad Pattan powerhouse, 24.9 m
x 60.15 m x 175.6 m, lining 1.25 m crown / 1.0 m walls / 1.0 m floor slab,
12 m sandstone / 8 m non-sandstone layers dipping 70 deg, a soft layer
centred on Y = 0) and writes meshes/layered_cavern_coarse.msh (msh 4.1,
about 5 MB: generated on demand, not committed).

The mesh is a gmsh *discrete* model (nodes and elements, no CAD), so a
.geo_unrolled file would hold no geometry and none is written. To look at it:
``gmsh meshes/layered_cavern_coarse.msh`` (Tools > Visibility lists the
physical groups: sandstone, non_sandstone, lining; xmin..zmax,
cavern_surface, lining_inner, cavern_ends, interface_N). To change it, change
the parameters (see `layered_cavern_parameters`) and rerun; a scene can use
the builder directly (``builder = "layered_cavern"`` with a
``[mesh.parameters]`` table) or read this file back with
``builder = "file"``, ``file = "meshes/layered_cavern_coarse.msh"``.

Sample run (from the repository root):
    /usr/bin/python3 meshes/layered_cavern.py                # coarse preset
    /usr/bin/python3 meshes/layered_cavern.py paper out.msh  # ~138 000 hexahedra
"""
import os
import pathlib
import sys
import time

import gmsh

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
from pyfem.geometry.box import gmsh_session  # noqa: E402
from pyfem.geometry.layered_cavern import build_layered_cavern  # noqa: E402

DEFAULT_PATH = pathlib.Path(__file__).resolve().parent / "layered_cavern_coarse.msh"


def write_layered_cavern(path: str | os.PathLike = DEFAULT_PATH, parameters: dict | None = None) -> dict:
    """Build the layered-cavern model and write it to the .msh file `path`.

    Args:
        path: output .msh file.
        parameters: builder parameters (default: the coarse preset).

    Returns:
        The builder's summary (counts, measured dimensions, quality).
    """
    with gmsh_session("layered_cavern"):
        summary = build_layered_cavern(parameters or {"preset": "coarse"})
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(os.fspath(path))
    return summary


def main(argv: list[str]) -> None:
    preset = argv[1] if len(argv) > 1 else "coarse"
    default = DEFAULT_PATH if preset == "coarse" else f"layered_cavern_{preset}.msh"
    path = argv[2] if len(argv) > 2 else default
    start = time.perf_counter()
    summary = write_layered_cavern(path, {"preset": preset})
    seconds = time.perf_counter() - start
    dims = summary["dimensions"]
    print(f"{path}: {summary['cells']} hexahedra, {summary['nodes']} nodes in {seconds:.1f} s")
    print(f"  regions {summary['region_cells']}")
    print(f"  cavern {dims['width']:.2f} x {dims['height']:.2f} x {dims['length']:.2f} m, lining crown "
          f"{dims['lining_crown']:.3f} / wall {dims['lining_wall']:.3f} / floor {dims['lining_floor']:.3f} m")
    print(f"  {len(summary['interfaces'])} interfaces, "
          f"min scaled Jacobian {summary['min_scaled_jacobian']:.3f}, "
          f"edges {summary['min_edge_length']:.3f}..{summary['max_edge_length']:.2f} m, "
          f"dt estimate {summary['critical_time_step']:.3e} s")


if __name__ == "__main__":
    main(sys.argv)

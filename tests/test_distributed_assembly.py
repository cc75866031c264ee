"""The first step of the distributed model (issue 13; docs/scaling.md "Next steps", prototype
workflows/distributed_assembly.py): dolfinx's distributed mesh and assembly, each rank keeping the
owned rows of the stiffness in the kernel's owned + ghost numbering. On 3 ranks (an odd partition,
whose parts meet along edges and at vertices), with dolfinx's ghost modes `shared_facet` (ghost cells
across facets) and `none` (no ghost cells):
- the owned rows have columns the function space's index map does not hold (neighbours through an
  edge or a vertex only; with `none`, every off-rank neighbour): asserted, they are why the kernel's
  numbering adds extra ghosts;
- with the extra ghosts' values from their owners, each rank's owned rows times its local u equal
  PETSc's distributed product to round-off;
- the strain energy summed over the ranks equals the same box assembled on one rank (another
  numbering), the lumped mass's total is the box's;
- the kernel's Stepper of each rank's share (its owned rows, the ghosts' rows from the owned rows'
  transposes and their owners' diagonal blocks, the lumped mass, one ghost exchange per step over
  the index map's and the extra ghosts) steps a Gaussian bump 100 steps as the box assembled and
  stepped whole on one rank does, to round-off (nodes matched by coordinates), after the bump has
  moved by as much as it started with.
"""
import json
import subprocess

import pytest

from test_mpi import ENV, MPIRUN, PYTHON, REPO

# One rule for the MPI tests: a missing launcher fails (conftest.mpi_launcher), never skips.
pytestmark = pytest.mark.usefixtures("mpi_launcher")


@pytest.mark.parametrize("ghost_mode", ["shared_facet", "none"])
def test_owned_rows_in_local_numbering_reproduce_the_distributed_product_and_energy(ghost_mode):
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "3", PYTHON,
                             "workflows/distributed_assembly.py", "10", ghost_mode],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    found = json.loads([line for line in result.stdout.splitlines() if line.startswith("{")][-1])
    shares = found["owned_ghost_extra_per_rank"]
    assert found["ranks"] == 3 and sum(owned for owned, _, _ in shares) == found["nodes"] == 11 ** 3
    assert all(owned > 0 for owned, _, _ in shares)
    assert sum(extra for _, _, extra in shares) > 0, "owned rows reach nodes the index map does not hold"
    assert found["energy"] > 0.0
    assert found["owned_rows_product_error"] < 1e-13
    assert found["energy_difference"] < 1e-13 and found["mass_error"] < 1e-14
    assert found["steps"] == 100 and found["moved"] > 0.5, "the bump moved"
    assert found["stepping_difference"] < 1e-12
    # The element loop's halo: the other ranks' cells touching a rank's owned nodes. Ghost cells
    # across facets hold all but a few (the edge and vertex neighbours); without ghost cells, none.
    halo = found["halo_cells_and_not_on_rank_per_rank"]
    assert all(touching > 0 for touching, _ in halo)
    if ghost_mode == "shared_facet":
        assert 0 < sum(left for _, left in halo) < 0.2 * sum(touching for touching, _ in halo)
    else:
        assert all(left == touching for touching, left in halo)
    print(f"{ghost_mode}: owned/ghost/extra per rank {shares}, product {found['owned_rows_product_error']:.1e}, "
          f"energy against one rank {found['energy_difference']:.1e}, stepped "
          f"{found['stepping_difference']:.1e}; halo cells and not on the rank {halo}")


# The user's models: the free-field box (named faces), a gmsh script's tunnel (unnamed faces found on
# the bounding-box planes, the cavity's wall traction-free), two interfaces split for contact.
OPERATOR_SCENES = ["workflows/scenes/box_vertical_sv.toml", "tests/scenes/mpi_tunnel_tet.toml",
                   "tests/scenes/mpi_hard_contact.toml"]


@pytest.mark.parametrize("scene", OPERATOR_SCENES)
def test_the_model_builders_on_the_distributed_mesh_give_the_one_rank_operators(scene):
    """workflows/distributed_operators.py on 3 ranks: pyfem's mesh builder, materials, lumped mass
    and truncation faces on dolfinx's distributed mesh. Every rank names the same faces and free
    surfaces as one rank does (before 2026-11-28 a rank found the bounding-box planes of its own part
    and the faces' collective assembly waited forever on the tunnel); every node is owned by one
    rank; each owned node's mass and face values (area, normal, rho c_p, rho c_s, G) are the one-rank
    ones to round-off."""
    result = subprocess.run([MPIRUN, "--allow-run-as-root", "--oversubscribe", "-n", "3", PYTHON,
                             "workflows/distributed_operators.py", scene],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    found = json.loads([line for line in result.stdout.splitlines() if line.startswith("{")][-1])["operators"]
    assert found["faces"] == ["xmax", "xmin", "ymax", "ymin", "zmax", "zmin"]
    assert found["faces_equal"] and found["free_surfaces_equal"]
    for name in found["faces"] + ["mass"]:
        assert found[name]["nodes"] > 0 and found[name]["owned"] == found[name]["nodes"], name
        assert found[name]["miscounted_points"] == 0, name
        assert found[name]["difference"] < 1e-14, name
    print(scene, {name: found[name]["nodes"] for name in found["faces"] + ["mass"]})

"""Shared test helpers: one place for tolerances."""
import numpy as np

ROUNDOFF = 1e-10  # relative agreement expected between two evaluations of the same arithmetic
EXACT = 1e-12  # relative agreement of two arrangements of the same sums over a few hundred steps


def rel_error(a, b):
    """Relative L2 error of `a` against the reference `b` (1 if b is zero and a is not)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    denom = np.linalg.norm(b)
    diff = np.linalg.norm(a - b)
    if denom == 0.0:
        return 0.0 if diff == 0.0 else 1.0
    return diff / denom


def observed_orders(hs, errors):
    """Observed convergence orders log(e_i/e_{i+1}) / log(h_i/h_{i+1}) between successive refinements."""
    hs = np.asarray(hs, dtype=float)
    errors = np.asarray(errors, dtype=float)
    return np.log(errors[:-1] / errors[1:]) / np.log(hs[:-1] / hs[1:])


def write_msh_with_quadratic_tetrahedra(path):
    """A unit box meshed with 10-node tetrahedra (gmsh's own second-order elements), its volume the
    physical group "rock": an unsupported mesh (pyfem reads linear cells and builds P2/Q2 on them).

    The gmsh options it sets are put back: gmsh keeps options for the whole process.
    """
    from pyfem._gmsh import gmsh
    from pyfem.geometry import gmsh_session

    with gmsh_session("tets"):
        previous_size = gmsh.option.getNumber("Mesh.MeshSizeMax")
        previous_order = gmsh.option.getNumber("Mesh.ElementOrder")
        volume = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
        gmsh.model.occ.synchronize()
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [volume]), "rock")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
        gmsh.option.setNumber("Mesh.ElementOrder", 2)
        try:
            gmsh.model.mesh.generate(3)
            gmsh.write(str(path))
        finally:
            gmsh.option.setNumber("Mesh.MeshSizeMax", previous_size)
            gmsh.option.setNumber("Mesh.ElementOrder", previous_order)

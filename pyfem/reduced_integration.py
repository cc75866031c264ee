"""One-point integration of Q1 element-loop cells, with the rest of their elastic stiffness kept in
the matrix (`integration = "reduced"` in [materials.NAME.plasticity] / [materials.NAME.damage]).

The element loop evaluates a material law at every quadrature point of every cell, every step: for
the case study's Mohr-Coulomb zone and lining that is most of a step (README "Benchmark"). This
module lets a region's law act once per cell instead of eight times, the way explicit codes for
rock and soil commonly do (uniform-strain hexahedra with hourglass control: Flanagan & Belytschko
1981, Int. J. Numer. Meth. Eng. 17:679), with the hourglass stiffness taken exactly from the
full-integration element:

- **The one-point element.** Per cell the uniform gradient dphi_a/dx averaged over the cell,
  B_bar_a = (1/V) sum_q w_q grad phi_a(x_q) (Flanagan & Belytschko's mean gradient; the cell mean
  that mean dilatation already uses), the weight V = sum_q w_q, and the law at the cell's mean
  strain eps_bar = sym(sum_a u_a (x) B_bar_a). The kernel runs it as a cell with one point.
- **The hourglass stiffness.** For the law's initial elastic moduli (lambda, G),
      K_hg = sum_cells [ sum_q w_q B_q^T C B_q - V B_bar^T C B_bar ],
  the full-integration element matrix (with B-bar's B_q when the region asks for mean dilatation)
  minus the one-point one. It is symmetric and positive semi-definite: u^T K_full u is the cell's
  integral of the strain energy density, a convex quadratic of the strain, and the mean strain's
  energy V W(eps_bar) is below it (Jensen's inequality; with B-bar the volumetric strain is the
  mean at every point and only the deviatoric part enters), so it adds no unstable mode. K_hg is
  linear and goes into the stiffness matrix with the region's other cells (its blocks fill the
  region's rows again: the stiffness product grows, the element loop shrinks).
- **What it means.** In the elastic range the one-point cell plus K_hg *is* the full-integration
  cell: same K, same stable step, the same run to round-off while nothing yields (tested). Once
  the law yields or damages, it acts on the mean strain of the cell only; the strain's variation
  within the cell (the hourglass modes) stays elastic with the initial moduli, so a yielded or
  cracked cell is stiffer than the full-integration one. Outputs of such a region (monitors,
  fields, run.json volumes) are the cell's one point, at its centroid.

Q1 hexahedra only: a Q2 cell's strain varies quadratically within it, too much for one law point
to stand for (not built); the scene refuses `integration = "reduced"` with `mesh.order = 2`.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse

CHUNK_CELLS = 4096
"""Cells per vectorised block of the element matrices (24 x 24 each; ~19 MB per block)."""


def one_point_arrays(full):
    """The kernel arrays of the same cells with one point each.

    Args:
        full: pyfem.elements.ElementArrays of Q1 cells with the full quadrature (q = 8).

    Returns:
        ElementArrays with q = 1: weights (c, 1) the cell volumes V (m^3), points (c, 1, 3) the
        centroids sum_q w_q x_q / V (m), uniform_gradients (c, 8, 3) the mean gradients (1/m), which
        the kernel uses; reference_gradients and inverse_jacobians the averages of the full points'
        (kept so the arrays keep their shapes; not used by the kernel).
    """
    if full.cell_nodes.shape[1] != 8:
        raise ValueError(f"one-point integration is for Q1 hexahedra (8 nodes per cell), not {full.cell_nodes.shape[1]}")
    volume = full.weights.sum(axis=1)
    mean_gradients = np.einsum("cq,cqkl->ckl", full.weights, full.gradients) / volume[:, None, None]
    centroids = np.einsum("cq,cqi->ci", full.weights, full.points) / volume[:, None]
    centre_reference = full.reference_gradients.mean(axis=0, keepdims=True)
    centre_inverse = full.inverse_jacobians.mean(axis=1, keepdims=True)
    return dataclasses.replace(
        full, reference_gradients=np.ascontiguousarray(centre_reference),
        inverse_jacobians=np.ascontiguousarray(centre_inverse), weights=np.ascontiguousarray(volume[:, None]),
        points=np.ascontiguousarray(centroids[:, None, :]), tensor=None,
        uniform_gradients=np.ascontiguousarray(mean_gradients))


def element_matrices(gradients: np.ndarray, weights: np.ndarray, lame_lambda: float, shear_modulus: float,
                     mean_dilatation: bool) -> np.ndarray:
    """Elastic element matrices (c, 8, 3, 8, 3) [a, i, b, j] (N/m) of cells given by their point
    gradients (c, q, 8, 3) (1/m) and weights (c, q) (m^3):
        K = sum_q w_q [lambda g g^T + G (G_aj G_bi + delta_ij G_al G_bl)],
    with mean dilatation (B-bar) the volumetric part at the cell mean gradient g_bar:
        K = sum_q w_q [lambda g_bar g_bar^T + G (...) + 2G/3 (g_bar g_bar^T - g g^T)]."""
    A = np.einsum("cq,cqai,cqbj->caibj", weights, gradients, gradients)  # sum_q w G_ai G_bj
    S = np.einsum("cq,cqal,cqbl->cab", weights, gradients, gradients)    # sum_q w G_al G_bl
    K = shear_modulus * np.einsum("cajbi->caibj", A)  # G_aj G_bi
    K += shear_modulus * np.einsum("cab,ij->caibj", S, np.eye(3))
    if mean_dilatation:
        volume = weights.sum(axis=1)
        mean = np.einsum("cq,cqai->cai", weights, gradients) / volume[:, None, None]
        mean_outer = np.einsum("c,cai,cbj->caibj", volume, mean, mean)
        K += lame_lambda * mean_outer + (2.0 * shear_modulus / 3.0) * (mean_outer - A)
    else:
        K += lame_lambda * A
    return K


def hourglass_stiffness(full, one_point, lame_lambda: float, shear_modulus: float, mean_dilatation: bool,
                        n_nodes: int) -> scipy.sparse.bsr_matrix:
    """K_hg of the cells (module docstring): the full-integration elastic stiffness of the cells
    minus their one-point stiffness, assembled, BSR (3 n_nodes)^2 with (3, 3) blocks (N/m).

    Args:
        full: ElementArrays of the Q1 cells with the full quadrature.
        one_point: `one_point_arrays(full)`.
        lame_lambda, shear_modulus: the law's initial elastic moduli (Pa).
        mean_dilatation: the full-integration element is B-bar's (the region's option).
        n_nodes: nodes of the model.
    """
    n_dofs = 3 * n_nodes
    total = scipy.sparse.csr_matrix((n_dofs, n_dofs))
    for dofs, blocks in hourglass_blocks(full, one_point, lame_lambda, shear_modulus, mean_dilatation):
        total = total + scipy.sparse.csr_matrix(
            (blocks.ravel(), (np.repeat(dofs, 24, axis=1).ravel(), np.tile(dofs, (1, 24)).ravel())),
            shape=(n_dofs, n_dofs))
    return total.tobsr(blocksize=(3, 3))


def hourglass_blocks(full, one_point, lame_lambda: float, shear_modulus: float, mean_dilatation: bool):
    """The cells' K_hg element matrices, CHUNK_CELLS at a time: (dofs (c, 24) 3 node + component of
    `full.cell_nodes`' numbering, matrices (c, 24, 24) (N/m)) (`hourglass_stiffness`'s arguments)."""
    for start in range(0, len(full.cells), CHUNK_CELLS):
        rows = np.arange(start, min(start + CHUNK_CELLS, len(full.cells)))
        gradients = np.einsum("qkm,cqml->cqkl", full.reference_gradients, full.inverse_jacobians[rows])
        weights = full.weights[rows]
        whole = element_matrices(gradients, weights, lame_lambda, shear_modulus, mean_dilatation)
        single = element_matrices(one_point.gradients[rows], one_point.weights[rows], lame_lambda, shear_modulus,
                                  False)
        dofs = (3 * full.cell_nodes[rows][:, :, None] + np.arange(3)).reshape(len(rows), 24)
        yield dofs, (whole - single).reshape(len(rows), 24, 24)


def lame_moduli(young_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(lambda, G) (Pa) of E (Pa) and nu."""
    shear = young_modulus / (2.0 * (1.0 + poisson_ratio))
    return young_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio)), shear

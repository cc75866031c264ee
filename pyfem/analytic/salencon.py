"""Salencon (1969): a circular cavity in a Mohr-Coulomb elastic-perfectly-plastic medium (checked in tests/test_salencon_closed_form.py).

Plane strain, hydrostatic in-situ stress P0, cavity radius a, internal pressure p_i (0: unsupported
wall), cohesion c, friction angle phi, dilation angle psi (non-associated flow), small strain.
References: J. Salencon, "Contraction quasi-statique d'une cavite a symetrie spherique ou cylindrique
dans un milieu elastoplastique", Annales des Ponts et Chaussees 4 (1969) 231-236; Itasca, FLAC
verification problem "Cylindrical Hole in an Infinite Mohr-Coulomb Medium"; C. Carranza-Torres and
C. Fairhurst, IJRMMS 36 (1999) 777-809.

SIGN CONVENTIONS OF THIS HELPER (not the code's):
    stresses are COMPRESSION POSITIVE (P0 > 0, sigma_r(a) = p_i >= 0);
    u_r is the CONVERGENCE, POSITIVE INWARD (towards the axis), the displacement caused by the
    excavation only (zero in the in-situ state).
pyfem's stresses are tension positive and its displacements outward positive: compare_to_stage below
converts the stage's fields into these conventions.

With N_phi = (1 + sin phi)/(1 - sin phi), N_psi = (1 + sin psi)/(1 - sin psi),
sigma_c = 2 c cos phi / (1 - sin phi), A = P0 + sigma_c/(N_phi - 1), D = p_i + sigma_c/(N_phi - 1):

    R0 = a [2/(N_phi + 1) A / D]^(1/(N_phi - 1))            (R0 = a: no plastic zone, 2 P0 - p_i <= N_phi p_i + sigma_c)
    sigma_R0 = (2 P0 - sigma_c)/(N_phi + 1)                   radial stress at r = R0

    plastic zone a <= r <= R0 (sigma_theta = N_phi sigma_r + sigma_c):
        sigma_r     = -sigma_c/(N_phi - 1) + D (r/a)^(N_phi - 1)
        sigma_theta = -sigma_c/(N_phi - 1) + N_phi D (r/a)^(N_phi - 1)
    elastic zone r >= R0 (Lame, with sigma_r(R0) = sigma_R0):
        sigma_r, sigma_theta = P0 -+ (P0 - sigma_R0) (R0/r)^2,   u_r = (P0 - sigma_R0) R0^2 / (2 G r)

Displacement in the plastic zone (derived here, and the same as the FLAC manual's formula):
    total strains (compression positive) eps_r = du_r/dr, eps_theta = u_r/r (u_r inward);
    elastic strains from the stress CHANGE (sigma - P0) by plane-strain Hooke's law,
        eps_r^e = [(1 - nu) dsigma_r - nu dsigma_theta]/(2G),  eps_theta^e = [(1 - nu) dsigma_theta - nu dsigma_r]/(2G),
    i.e. eps_z^e = eps_z^p = 0 (sigma_z is assumed the intermediate principal stress);
    flow rule with the plastic potential sigma_theta - N_psi sigma_r: eps_r^p + N_psi eps_theta^p = 0,
    plastic strains zero at r = R0 (where the point yields; monotonic unloading from p_i = P0).
    So du_r/dr + N_psi u_r/r = eps_r^e + N_psi eps_theta^e, integrated from u_r(R0) of the elastic zone:

    2 G u_r / r = -(1 - 2 nu) A
                  + (1 - nu)(N_phi^2 - 1)/(N_phi + N_psi) D (R0/a)^(N_phi - 1) (R0/r)^(N_psi + 1)
                  + [(1 - nu)(N_phi N_psi + 1)/(N_phi + N_psi) - nu] D (r/a)^(N_phi - 1)

    (Using D (R0/a)^(N_phi - 1) = 2 A/(N_phi + 1), the middle term is 2 (1 - nu)(N_phi - 1)/(N_phi + N_psi)
    A (R0/r)^(N_psi + 1).) nu = (3K - 2G)/(2(3K + G)). This is the exact small-strain solution with the
    elastic strain of the plastic zone taken from its actual stresses; no other approximation is needed
    to reproduce the FLAC numbers (12.17 mm for psi = 0, 28.10 mm for psi = 30 deg).

Caveat (Reed 1988, IJNAMG 12, 173-181): with eps_z^e = 0, sigma_z = P0 + nu (dsigma_r + dsigma_theta)
(returned as "sigma_z"). Near the wall it can exceed sigma_theta (for the FLAC data, r < 1.27 a), so a
three-dimensional Mohr-Coulomb model also yields in the (z, r) plane there and need not reproduce this
plane solution exactly; the closed form ignores it, as Salencon's and FLAC's do.
"""
import math

import numpy as np


def poisson_ratio(G, K):
    """nu from the shear and bulk moduli."""
    return (3.0 * K - 2.0 * G) / (2.0 * (3.0 * K + G))


def salencon(r, a, P0, G, K, cohesion, friction_angle_deg, dilation_angle_deg, p_i=0.0):
    """The closed form at radii r >= a (any array shape; SI units).

    Compression positive, u_r positive inward (see the module's docstring). Returns a dict:
        R0 (plastic radius, = a when nothing yields), plastic (bool), sigma_R0 (radial stress at R0),
        N_phi, N_psi, sigma_c, nu,
        r, sigma_r, sigma_theta, sigma_z, u_r (arrays shaped as r), in_plastic_zone (bool array).
    """
    r = np.asarray(r, dtype=float)
    if np.any(r < a * (1.0 - 1e-12)):
        raise ValueError("salencon: r must be >= a")
    phi = math.radians(friction_angle_deg)
    psi = math.radians(dilation_angle_deg)
    if not 0.0 < phi < math.pi / 2:
        raise ValueError("salencon: 0 < friction angle < 90 deg (N_phi = 1 divides by zero)")
    if not 0.0 <= psi <= phi:
        raise ValueError("salencon: 0 <= dilation angle <= friction angle")
    nu = poisson_ratio(G, K)
    N_phi = (1.0 + math.sin(phi)) / (1.0 - math.sin(phi))
    N_psi = (1.0 + math.sin(psi)) / (1.0 - math.sin(psi))
    sigma_c = 2.0 * cohesion * math.cos(phi) / (1.0 - math.sin(phi))
    A = P0 + sigma_c / (N_phi - 1.0)
    D = p_i + sigma_c / (N_phi - 1.0)
    R0 = a * (2.0 / (N_phi + 1.0) * A / D) ** (1.0 / (N_phi - 1.0))
    plastic = bool(R0 > a)
    if plastic:
        sigma_R0 = (2.0 * P0 - sigma_c) / (N_phi + 1.0)
    else:
        R0, sigma_R0 = a, p_i

    inside = r <= R0
    # Elastic zone (Lame about R0).
    jump = P0 - sigma_R0
    q = (R0 / r) ** 2
    sigma_r = P0 - jump * q
    sigma_theta = P0 + jump * q
    u_r = jump * R0 * R0 / (2.0 * G * r)
    if plastic:
        rp = r[inside]
        x = (rp / a) ** (N_phi - 1.0)
        sigma_r[inside] = -sigma_c / (N_phi - 1.0) + D * x
        sigma_theta[inside] = -sigma_c / (N_phi - 1.0) + N_phi * D * x
        y = (R0 / a) ** (N_phi - 1.0)
        u_r[inside] = rp / (2.0 * G) * (
            -(1.0 - 2.0 * nu) * A
            + (1.0 - nu) * (N_phi ** 2 - 1.0) / (N_phi + N_psi) * D * y * (R0 / rp) ** (N_psi + 1.0)
            + ((1.0 - nu) * (N_phi * N_psi + 1.0) / (N_phi + N_psi) - nu) * D * x)
    sigma_z = P0 + nu * ((sigma_r - P0) + (sigma_theta - P0))
    return {"R0": R0, "plastic": plastic, "sigma_R0": sigma_R0, "N_phi": N_phi, "N_psi": N_psi,
            "sigma_c": sigma_c, "nu": nu, "r": r, "sigma_r": sigma_r, "sigma_theta": sigma_theta,
            "sigma_z": sigma_z, "u_r": u_r, "in_plastic_zone": inside & plastic}


# --- Finite-element comparison (draft: not run yet; needs a plastic static stage) -------------------

def centroids(model):
    """Cell centroids from the vertex nodes of each cell (the first 8 of a hexahedron, 4 of a tetrahedron), as
    tests/test_static.py."""
    n_basis = model.V.element.basix_element.dim
    n_vertices = 4 if model.mesh.topology.cell_type.name == "tetrahedron" else 8  # the first nodes of a cell
    nodes = model.V.dofmap.list.array.reshape(-1, n_basis)[:, :n_vertices]
    return model.node_coords[nodes].mean(axis=1)


def in_plane(points, centre):
    """(r, theta) of points about the tunnel axis (y through `centre`), theta from +x towards +z, as
    tests/test_static.py's in_plane (but r in metres, not r / a)."""
    x = np.asarray(points, dtype=float) - np.asarray(centre, dtype=float)
    return np.hypot(x[..., 0], x[..., 2]), np.arctan2(x[..., 2], x[..., 0])


def radial_displacement(u, theta):
    """Outward u_r of displacements (n, 3) at angles theta (tests/test_static.py's polar, vectorised)."""
    return u[..., 0] * np.cos(theta) + u[..., 2] * np.sin(theta)


def hoop_stress(sigma, theta):
    """sigma_thetatheta of stress tensors (n, 3, 3) in the x-z plane (tests/test_static.py's polar)."""
    c, s = np.cos(theta), np.sin(theta)
    return sigma[:, 0, 0] * s * s + sigma[:, 2, 2] * c * c - 2.0 * sigma[:, 0, 2] * s * c


def _ring(radii, target, band):
    """Cells whose centroid radius is within `band` of the radius nearest `target`."""
    distance = np.abs(radii - target)
    return distance <= distance.min() + band


def _binned(radii, values, width):
    """Means of `values` in rings of `width` (m): (mean radius, mean value) of each non-empty ring."""
    index = np.floor((radii - radii.min()) / width).astype(int)
    counts = np.bincount(index)
    keep = counts > 0
    r_mean = np.bincount(index, weights=radii)[keep] / counts[keep]
    v_mean = np.bincount(index, weights=values)[keep] / counts[keep]
    return r_mean, v_mean


def compare_to_stage(simulation, centre, a, cell_plastic_strain=None, R0=None, band=0.02, bin_width=0.05,
                     plastic_threshold=0.0):
    """The finite-element static stage in the helper's conventions, for comparison with salencon().

    simulation: a pyfem Simulation after a static stage (model.node_coords (n, 3), static.displacement
    (3n,) flat xyz per node, the excavation's increment; static.cell_stress (n_cells, 3, 3) Pa, tension
    positive, at cell centroids). Tunnel axis y through `centre`, radius a (m).
    cell_plastic_strain (n_cells,), optional: any non-negative measure (e.g. equivalent plastic strain).
    R0: the radius at which to report sigma_theta (default: the estimate below; pass salencon()'s R0
    to read the stage at the closed form's radius).
    band, bin_width: relative to a; the width of the ring of cells averaged at a target radius, and
    of the rings in which the plastic fraction / hoop stress are averaged.

    Returns (compression positive, u_r inward positive, as salencon()):
        wall_displacement: mean inward radial displacement of the nodes with |r - a| <= 1e-6 a (m);
        wall_nodes: how many; wall_displacement_spread: max - min over them;
        plastic_radius: from cell_plastic_strain, the radius at which the fraction of plastic cells
            (plastic strain > plastic_threshold) in rings of bin_width a first falls below 1/2
            (interpolated); without it, the radius of the ring of largest mean hoop stress;
        plastic_radius_source: "plastic strain" or "hoop-stress peak";
        sigma_theta_wall, r_wall: mean hoop stress and mean centroid radius of the ring of cells
            nearest r = a (the lead compares with salencon(r_wall, ...), not r = a);
        sigma_theta_R0, r_R0: the same at r = R0 (given, or the estimate);
        cells_wall, cells_R0: the indices of those cells. sigma_theta has a kink at R0, so the ring's
            mean is biased low against salencon(r_R0) (by 1 % for band 0.02 on a fine mesh): compare
            each cell with salencon(cell_r[cells_R0]) and average the differences instead;
        cell_r, cell_sigma_theta: every cell's centroid radius and hoop stress, for plots.
    """
    model, state = simulation.model, simulation.static
    r_node, theta_node = in_plane(model.node_coords, centre)
    u = np.asarray(state.displacement).reshape(-1, 3)
    wall = np.abs(r_node - a) <= 1e-6 * a
    if not np.any(wall):
        raise ValueError(f"compare_to_stage: no node at r = {a} m about {centre}")
    convergence = -radial_displacement(u[wall], theta_node[wall])

    points = centroids(model)
    r_cell, theta_cell = in_plane(points, centre)
    sigma_theta = -hoop_stress(np.asarray(state.cell_stress), theta_cell)

    if cell_plastic_strain is not None:
        plastic = np.asarray(cell_plastic_strain, dtype=float) > plastic_threshold
        r_bin, fraction = _binned(r_cell, plastic.astype(float), bin_width * a)
        below = np.nonzero(fraction < 0.5)[0]
        if not plastic.any():
            plastic_radius = a
        elif below.size == 0:
            plastic_radius = float(r_bin[-1])
        elif below[0] == 0:
            plastic_radius = a
        else:
            i = below[0]
            f0, f1 = fraction[i - 1], fraction[i]
            plastic_radius = float(r_bin[i - 1] + (f0 - 0.5) / (f0 - f1) * (r_bin[i] - r_bin[i - 1]))
        source = "plastic strain"
    else:
        r_bin, hoop = _binned(r_cell, sigma_theta, bin_width * a)
        plastic_radius = float(r_bin[np.argmax(hoop)])
        source = "hoop-stress peak"

    at_wall = _ring(r_cell, a, band * a)
    target = plastic_radius if R0 is None else R0
    at_R0 = _ring(r_cell, target, band * a)
    return {
        "wall_displacement": float(convergence.mean()),
        "wall_nodes": int(wall.sum()),
        "wall_displacement_spread": float(convergence.max() - convergence.min()),
        "plastic_radius": float(plastic_radius),
        "plastic_radius_source": source,
        "sigma_theta_wall": float(sigma_theta[at_wall].mean()),
        "r_wall": float(r_cell[at_wall].mean()),
        "sigma_theta_R0": float(sigma_theta[at_R0].mean()),
        "r_R0": float(r_cell[at_R0].mean()),
        "cells_wall": np.nonzero(at_wall)[0],
        "cells_R0": np.nonzero(at_R0)[0],
        "cell_r": r_cell,
        "cell_sigma_theta": sigma_theta,
    }

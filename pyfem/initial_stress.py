"""Initial (static) stress state and the static forces it puts on contact pairs (docs/method.md section 8).

Geostatic stress (compression negative, z up), from a scene's [initial_stress]:

    sigma_v(z)  = -rho g (z_s - z)           overburden of density rho below the surface z_s
    sigma_zz    = k_z sigma_v
    sigma_xx    = k_x sigma_v,   sigma_yy = k_y sigma_v,   no shear

(the paper: k = [1.4, 1.2, 1.15], k_z a factor on the vertical stress). The
dynamic run solves for the increment over this state; the contact law needs
the total normal force, so each pair gets its static force
F_i = A_i sigma0(x_i) n_i: the force side j exerts on node i (n from side i to
side j; with compression negative a compressed horizontal interface pushes
node i down).

Uniform stress, `[initial_stress] stress = [sxx, syy, szz, syz, sxz, sxy]` (Pa, compression
negative; this order, the scene's, differs from the kernel's Voigt order xx yy zz xy yz xz, so
`stress_tensor` names every component): the same tensor everywhere, no body force to balance.

Any stress field works: `pair_static_forces` takes a callable x (m, 3) -> (m, 3, 3). With a static
stage ([static], pyfem/static.py) the pairs' static forces come from the stage instead.
"""
from __future__ import annotations

import typing

import numpy as np

STANDARD_GRAVITY = 9.81  # m/s^2

StressField = typing.Callable[[np.ndarray], np.ndarray]


def geostatic_stress(surface: float, rho: float, k: typing.Sequence[float] = (1.0, 1.0, 1.0),
                     gravity: float = STANDARD_GRAVITY) -> StressField:
    """The geostatic stress field below a horizontal ground surface.

    Args:
        surface: z of the ground surface z_s (m).
        rho: overburden density (kg/m^3).
        k: [k_x, k_y, k_z]: sigma_xx / sigma_v, sigma_yy / sigma_v, factor on sigma_v (-).
        gravity: g (m/s^2).

    Returns:
        A function x (m, 3) (m) -> sigma (m, 3, 3) (Pa), compression negative.
    """
    k_x, k_y, k_z = (float(value) for value in k)

    def stress(x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, dtype=float))
        vertical = -rho * gravity * (surface - x[:, 2])
        sigma = np.zeros((len(x), 3, 3))
        sigma[:, 0, 0] = k_x * vertical
        sigma[:, 1, 1] = k_y * vertical
        sigma[:, 2, 2] = k_z * vertical
        return sigma

    return stress


def stress_tensor(stress: typing.Sequence[float]) -> np.ndarray:
    """(3, 3) symmetric tensor of a stress given in the scene's order [sxx, syy, szz, syz, sxz, sxy] (Pa)."""
    sxx, syy, szz, syz, sxz, sxy = (float(value) for value in stress)
    return np.array([[sxx, sxy, sxz], [sxy, syy, syz], [sxz, syz, szz]])


def uniform_stress(stress: typing.Sequence[float]) -> StressField:
    """The same stress everywhere.

    Args:
        stress: [sxx, syy, szz, syz, sxz, sxy] (Pa, compression negative), the scene's order.

    Returns:
        A function x (m, 3) (m) -> sigma (m, 3, 3) (Pa).
    """
    tensor = stress_tensor(stress)

    def field(x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return np.repeat(tensor[None], len(x), axis=0)

    return field


def stress_field_from_scene(scene: typing.Mapping) -> StressField | None:
    """The scene's [initial_stress] field (uniform or geostatic), or None when the effect is off."""
    settings = scene.get("initial_stress")
    if settings is None:
        return None
    if settings.get("stress") is not None:
        return uniform_stress(settings["stress"])
    return geostatic_stress(settings["surface"], settings["rho"], settings["k"])


def pair_static_forces(coords: np.ndarray, area: np.ndarray, normal: np.ndarray,
                       stress: StressField | None) -> np.ndarray:
    """Static force on node i of each pair: F = A sigma0(x) n (N).

    Args:
        coords: (n, 3) pair positions (m).
        area: (n,) lumped pair areas (m^2).
        normal: (n, 3) unit normals from side i towards side j.
        stress: stress field x -> (n, 3, 3) (Pa), or None (no initial stress: zero forces).

    Returns:
        (n, 3) force side j exerts on node i in the static state (N), C-contiguous.
    """
    coords = np.asarray(coords, dtype=float)
    if stress is None or len(coords) == 0:
        return np.zeros((len(coords), 3))
    sigma = np.asarray(stress(coords), dtype=float)
    if sigma.shape != (len(coords), 3, 3):
        raise ValueError(f"stress field returned shape {sigma.shape}; expected {(len(coords), 3, 3)}")
    return np.ascontiguousarray(np.asarray(area, dtype=float)[:, None] * np.einsum("mab,mb->ma", sigma, normal))

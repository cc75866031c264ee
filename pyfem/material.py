"""One isotropic material: elastic constants, wave speeds, impedances and their validation.

Every part that needs Lame's constants, the wave speeds or the impedances of a material
(the assembled operators, the free field, the layered-cavern time-step estimate, the accuracy
advice, the monitors) builds a `Material` instead of repeating the formulas:

    lambda = E nu / ((1 + nu)(1 - 2 nu)),  G = E / (2 (1 + nu)),  K = E / (3 (1 - 2 nu)),
    M = lambda + 2 G (P-wave modulus),     c_p = sqrt(M / rho),   c_s = sqrt(G / rho).

`ELASTIC_RANGES` are the ranges the scene's schema checks ([materials.NAME] E, nu, rho);
`check_elastic` checks them for any caller. `YOUNG_MODULUS_RANGE` and `DENSITY_RANGE` are the
scene's plausibility ranges (a value outside them is almost always a unit slip).
No dolfinx, no other pyfem module: anything may import this one.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
import typing

# key -> (description, lower, upper): each constant must lie strictly between its bounds.
ELASTIC_RANGES = {
    "E": ("Young's modulus E (Pa)", 0.0, math.inf),
    "nu": ("Poisson's ratio", -1.0, 0.5),
    "rho": ("density (kg/m^3)", 0.0, math.inf),
}
"""The range of each elastic constant of [materials.NAME] (open intervals)."""

# Plausible ranges for rock and concrete (and the odd steel part): a value outside them is almost
# always a unit slip (GPa or MPa for Pa, t/m^3 for kg/m^3), which would give a meaningless run.
YOUNG_MODULUS_RANGE = (1.0e7, 3.0e11)  # Pa: soft soil-like rock ... above steel
DENSITY_RANGE = (500.0, 8000.0)        # kg/m^3: above porous fill ... steel

NONLINEAR_TABLES = ("plasticity", "damage")
"""Sub-tables of [materials.NAME] that make a region nonlinear (element loop of the kernel)."""


def interval(key: str) -> str:
    """The range of constant `key` (E, nu, rho) written as an interval: "(0, inf)", "(-1, 0.5)"."""
    _, lo, hi = ELASTIC_RANGES[key]
    return f"({lo:g}, {hi:g})"


def allowed(key: str) -> str:
    """What constant `key` allows, in the scene's words: "Poisson's ratio must lie in (-1, 0.5)"."""
    description, lo, hi = ELASTIC_RANGES[key]
    if math.isinf(hi):
        return f"{description} must be a finite number > {lo:g}"
    return f"{description} must lie in {interval(key)}"


def check_elastic(E, nu, rho, prefix: str = "") -> tuple[float, float, float]:
    """(E, nu, rho) as floats when each is a finite number in its `ELASTIC_RANGES` range.

    Args:
        E, nu, rho: Young's modulus (Pa), Poisson's ratio (-), density (kg/m^3).
        prefix: put before the key in the message, e.g. "materials.rock.".

    Raises:
        ValueError: "{prefix}{key} = {value!r}: {allowed(key)}" for the first bad constant.
    """
    values = {"E": E, "nu": nu, "rho": rho}
    for key, value in values.items():
        _, lo, hi = ELASTIC_RANGES[key]
        good = (isinstance(value, numbers.Real) and not isinstance(value, bool)
                and math.isfinite(value) and lo < value < hi)
        if not good:
            raise ValueError(f"{prefix}{key} = {value!r}: {allowed(key)}")
    return float(E), float(nu), float(rho)


@dataclasses.dataclass(frozen=True)
class Material:
    """A linear isotropic material with its optional nonlinear sub-table.

    Attributes:
        E: Young's modulus (Pa).
        nu: Poisson's ratio (-).
        rho: density (kg/m^3).
        name: the scene's material (region) name; "" when none.
        plasticity: [materials.NAME.plasticity] as the validated scene holds it (Mohr-Coulomb
            rock), or None.
        damage: [materials.NAME.damage] as the validated scene holds it (lining concrete), or None.

    Raises:
        ValueError: on construction, a constant outside `ELASTIC_RANGES` (message names
        materials.NAME.KEY when `name` is given), or both sub-tables given.
    """

    E: float
    nu: float
    rho: float
    name: str = ""
    plasticity: typing.Optional[dict] = dataclasses.field(default=None, hash=False)
    damage: typing.Optional[dict] = dataclasses.field(default=None, hash=False)

    def __post_init__(self):
        prefix = f"materials.{self.name}." if self.name else ""
        E, nu, rho = check_elastic(self.E, self.nu, self.rho, prefix)
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "rho", rho)
        for table in NONLINEAR_TABLES:
            value = getattr(self, table)
            if value is not None:
                object.__setattr__(self, table, dict(value))
        if self.plasticity is not None and self.damage is not None:
            raise ValueError(f"materials.{self.name or 'NAME'}: a material has one nonlinear law, "
                             "[plasticity] (Mohr-Coulomb rock) or [damage] (concrete), not both")

    @classmethod
    def from_scene(cls, name: str, table: typing.Mapping) -> "Material":
        """The material of [materials.NAME] (a validated scene's table: E, nu, rho, and the
        optional plasticity / damage sub-tables; other keys such as preset are ignored).

        Raises:
            ValueError: "materials.NAME.KEY: missing" for a missing E, nu or rho, or a bad value.
        """
        for key in ELASTIC_RANGES:
            if table.get(key) is None:
                raise ValueError(f"materials.{name}.{key}: missing (needed: E in Pa, nu, rho in kg/m^3)")
        return cls(E=table["E"], nu=table["nu"], rho=table["rho"], name=name,
                   plasticity=table.get("plasticity"), damage=table.get("damage"))

    @property
    def lame_lambda(self) -> float:
        """Lame's first parameter lambda = E nu / ((1 + nu)(1 - 2 nu)) (Pa)."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def shear_modulus(self) -> float:
        """G = mu = E / (2 (1 + nu)) (Pa)."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lame(self) -> tuple[float, float]:
        """(lambda, G) (Pa)."""
        return self.lame_lambda, self.shear_modulus

    @property
    def bulk_modulus(self) -> float:
        """K = E / (3 (1 - 2 nu)) (Pa)."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    @property
    def p_wave_modulus(self) -> float:
        """M = lambda + 2 G = E (1 - nu) / ((1 + nu)(1 - 2 nu)) (Pa)."""
        return self.lame_lambda + 2.0 * self.shear_modulus

    @property
    def p_wave_speed(self) -> float:
        """c_p = sqrt(M / rho) (m/s)."""
        return math.sqrt(self.p_wave_modulus / self.rho)

    @property
    def s_wave_speed(self) -> float:
        """c_s = sqrt(G / rho) (m/s)."""
        return math.sqrt(self.shear_modulus / self.rho)

    @property
    def impedances(self) -> tuple[float, float]:
        """(rho c_p, rho c_s), the P- and S-wave impedances (kg/(m^2 s)): the viscous boundary's
        dashpots per unit area and velocity."""
        return self.rho * self.p_wave_speed, self.rho * self.s_wave_speed

    @property
    def nonlinear_table(self) -> typing.Optional[str]:
        """"plasticity" or "damage" when the material has that sub-table, else None (linear elastic)."""
        for table in NONLINEAR_TABLES:
            if getattr(self, table) is not None:
                return table
        return None


def scene_materials(scene: typing.Mapping) -> dict[str, Material]:
    """Material of every [materials.NAME] of a validated scene, by name."""
    return {name: Material.from_scene(name, table) for name, table in scene["materials"].items()}

"""Scene files (TOML) -> validated, fully defaulted settings.

A scene says what to model and which physical effects to simulate. This module
reads it, applies command-line overrides, checks every key against one
declarative schema (`SCHEMA` below) and returns a `Scene`: a plain nested dict
in which every key of the schema is present (optional settings that were not
given are ``None``), except the optional effect tables (``wave``, ``damping``,
``initial_stress``, ``contact``, ``contact.deterioration``, ``static``) and the two motion
kinds (``wave.motion.ricker`` / ``wave.motion.record``) and the nonlinear material
tables (``materials.NAME.plasticity`` / ``materials.NAME.damage``): those are present only
when the scene gives them, because their presence is what switches an effect on.

Units are SI (m, kg, s, Pa); angles are in degrees; z points up.

Any problem is a `SceneError` that names the dotted key, the value found and
what is allowed, e.g.::

    scene key 'materials.rock.nu' = 0.6: Poisson's ratio must lie in (-1, 0.5)
"""
from __future__ import annotations

import contextlib
import copy
import difflib
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from pyfem import material as _material
from pyfem.material import DENSITY_RANGE, NONLINEAR_TABLES, YOUNG_MODULUS_RANGE
from pyfem.errors import SceneError, _show  # noqa: F401  (SceneError: the public name is pyfem.scene.SceneError)
from pyfem.excavation_steps import ONE_STEP_KEYS, model_excavation, static_steps  # noqa: F401  (the scene's API)

EFFECT_ORDER = ("seismic_input", "damping", "initial_stress", "contact", "deterioration")
"""Every effect a scene can switch on, in the order `Scene.effects` lists them."""

MATERIAL_PRESETS = {
    # The paper's Table 1; densities are not in the paper (docs/method.md section 10).
    "sandstone": dict(E=8.0e9, nu=0.24, rho=2600.0),
    "non_sandstone": dict(E=2.0e9, nu=0.30, rho=2400.0),
    "concrete": dict(E=28.0e9, nu=0.167, rho=2500.0),
}
"""Elastic constants of the paper's Table 1, selectable with ``preset = "NAME"``."""

PRESET_STRENGTHS = {
    # The paper's Table 1 (Pa, deg).
    "sandstone": dict(cohesion=1.10e6, friction_angle=42.0, tensile_strength=1.95e6),
    "non_sandstone": dict(cohesion=0.35e6, friction_angle=26.0, tensile_strength=0.25e6),
    "concrete": dict(cohesion=1.80e6, friction_angle=46.0, tensile_strength=1.27e6),
}
"""Strength parameters of the paper's Table 1: the defaults of cohesion, friction_angle and
tensile_strength in [materials.NAME.plasticity] / [materials.NAME.damage] of a material with
that preset (a material without a preset gives them)."""

# NONLINEAR_TABLES (the sub-tables of [materials.NAME] that make a region nonlinear) and the
# plausible ranges YOUNG_MODULUS_RANGE and DENSITY_RANGE (outside them: a unit slip) are
# pyfem.material's, like the ranges of E, nu and rho in the schema below.
# A cohesion or tensile strength of an interface below this (but > 0) is negligible next to any
# geostatic stress and is a value in MPa or kPa written as Pa; 0 means none.
SMALLEST_STRENGTH = 100.0              # Pa

BOX_REGION = "rock"
"""The single region (cell tag name) of the ``box`` mesh builder."""

# Boundary types of a truncation face: viscoelastic and viscous faces carry the seismic input,
# fixed and roller faces are kernel constraints (roller: normal component held), free is free.
BOUNDARY_TYPES = ("viscoelastic", "viscous", "fixed", "roller", "free")
# During a static stage a truncation face is held (roller: normal component; fixed) or carries the
# in-situ traction only (free); docs/static.md.
STATIC_BOUNDARY_TYPES = ("roller", "fixed", "free")
OUTPUT_FIELDS = ("displacement", "velocity", "acceleration", "stress", "strain", "damage")
"""Field names ``output.fields`` may list ("damage": cell fields damage, damage_type, plastic_strain)."""

FIELDS_NOT_PRODUCED: dict = {}
"""Field names a user may expect that nothing produces yet, and why."""

_FILENAME_SAFE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


def _missing(key: str, allowed: str) -> SceneError:
    return SceneError(key, None, allowed, f"scene key '{key}' is missing: {allowed}")


# ---------------------------------------------------------------------------
# Schema vocabulary: each spec checks one value and says what it allows.
# ---------------------------------------------------------------------------

REQUIRED = object()
"""Default marking a key the scene must give."""


def _is_number(value: Any) -> bool:
    # bool is an int in Python but never a number in a scene.
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass(frozen=True)
class Interval:
    """A real interval written as in mathematics: ``"(0, inf)"``, ``"[0, 1)"``."""

    text: str

    def bounds(self) -> tuple[float, float, bool, bool]:
        lo_text, hi_text = self.text[1:-1].split(",")
        return float(lo_text), float(hi_text), self.text[0] == "(", self.text[-1] == ")"

    def contains(self, x: float) -> bool:
        lo, hi, lo_open, hi_open = self.bounds()
        if not math.isfinite(x):
            return False
        above = x > lo if lo_open else x >= lo
        below = x < hi if hi_open else x <= hi
        return above and below

    def condition(self) -> str:
        """The interval as a condition: ``"> 0"``, ``"in [0, 1)"``, ``""`` for all reals."""
        lo, hi, lo_open, hi_open = self.bounds()
        if math.isinf(lo) and math.isinf(hi):
            return ""
        if math.isinf(hi):
            return f"{'>' if lo_open else '>='} {lo:g}"
        if math.isinf(lo):
            return f"{'<' if hi_open else '<='} {hi:g}"
        return f"in {self.text}"

    def words(self) -> str:
        condition = self.condition()
        if not condition:
            return "be a finite number"
        if condition.startswith("in "):
            return "lie " + condition
        return "be a finite number " + condition


ANY_REAL = "(-inf, inf)"
POSITIVE = "(0, inf)"
NON_NEGATIVE = "[0, inf)"


@dataclass(frozen=True)
class Number:
    """A real number (int or float in TOML; never a bool), stored as float."""

    description: str
    interval: str = ANY_REAL
    default: Any = REQUIRED

    @property
    def allowed(self) -> str:
        return f"{self.description} must {Interval(self.interval).words()}"

    def check(self, value: Any, key: str) -> float:
        if not _is_number(value) or not Interval(self.interval).contains(float(value)):
            raise SceneError(key, value, self.allowed)
        return float(value)


@dataclass(frozen=True)
class Choice:
    """One of a fixed set of strings or integers (types must match exactly)."""

    description: str
    options: tuple
    default: Any = REQUIRED

    @property
    def allowed(self) -> str:
        return "must be one of " + ", ".join(_show(o) for o in self.options) + f" ({self.description})"

    def check(self, value: Any, key: str) -> Any:
        for option in self.options:
            if type(value) is type(option) and value == option:
                return value
        raise SceneError(key, value, self.allowed)


@dataclass(frozen=True)
class Text:
    """A string; with ``filename_safe``, letters, digits, ``_ . -`` only."""

    description: str
    default: Any = REQUIRED
    filename_safe: bool = False

    @property
    def allowed(self) -> str:
        if self.filename_safe:
            return f"{self.description} must be a non-empty name of letters, digits, '_', '.', '-'"
        return f"{self.description} must be a non-empty string"

    def check(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise SceneError(key, value, self.allowed)
        if self.filename_safe and not _FILENAME_SAFE.match(value):
            raise SceneError(key, value, self.allowed)
        return value


@dataclass(frozen=True)
class FilePath(Text):
    """A path to an existing file; resolved by `_resolve_files` after the schema pass."""


@dataclass(frozen=True)
class Flag:
    """A TOML boolean."""

    description: str
    default: Any = REQUIRED

    @property
    def allowed(self) -> str:
        return f"{self.description} must be true or false"

    def check(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise SceneError(key, value, self.allowed)
        return value


@dataclass(frozen=True)
class Vector:
    """A fixed-length array of real numbers, each in `interval`."""

    description: str
    length: int
    interval: str = ANY_REAL
    default: Any = REQUIRED
    increasing: bool = False

    @property
    def allowed(self) -> str:
        text = f"{self.description} must be {self.length} numbers"
        condition = Interval(self.interval).condition()
        if condition:
            text += ", each " + condition
        if self.increasing:
            text += ", increasing"
        return text

    def check(self, value: Any, key: str) -> list[float]:
        interval = Interval(self.interval)
        if (not isinstance(value, list) or len(value) != self.length
                or not all(_is_number(x) and interval.contains(float(x)) for x in value)):
            raise SceneError(key, value, self.allowed)
        numbers = [float(x) for x in value]
        if self.increasing and any(b <= a for a, b in zip(numbers, numbers[1:])):
            raise SceneError(key, value, self.allowed)
        return numbers


@dataclass(frozen=True)
class TextList:
    """An array of strings, optionally from a fixed set, optionally non-empty."""

    description: str
    default: Any = REQUIRED
    options: tuple | None = None
    non_empty: bool = False
    unavailable: dict | None = None  # item -> why it is not among the options (yet)

    @property
    def allowed(self) -> str:
        text = f"{self.description} must be {'a non-empty' if self.non_empty else 'an'} array of strings"
        if self.options:
            text += " from " + ", ".join(_show(o) for o in self.options)
        return text

    def check(self, value: Any, key: str) -> list[str]:
        if (not isinstance(value, list) or (self.non_empty and not value)
                or not all(isinstance(x, str) and x for x in value)):
            raise SceneError(key, value, self.allowed)
        if self.options is not None:
            for index, item in enumerate(value):
                if self.unavailable and item in self.unavailable:
                    raise SceneError(f"{key}.{index}", item, self.unavailable[item])
                if item not in self.options:
                    raise SceneError(f"{key}.{index}", item, self.allowed)
        if len(set(value)) != len(value):
            raise SceneError(key, value, self.allowed + " without repeats")
        return list(value)


@dataclass(frozen=True)
class VectorList:
    """A non-empty array of fixed-length arrays of real numbers (e.g. lines [x0, y0, z0, x1, y1, z1])."""

    description: str
    length: int
    default: Any = REQUIRED

    @property
    def allowed(self) -> str:
        return f"{self.description} must be a non-empty array of arrays of {self.length} finite numbers"

    def check(self, value: Any, key: str) -> list[list[float]]:
        if not isinstance(value, list) or not value:
            raise SceneError(key, value, self.allowed)
        interval = Interval(ANY_REAL)
        for index, item in enumerate(value):
            if (not isinstance(item, list) or len(item) != self.length
                    or not all(_is_number(x) and interval.contains(float(x)) for x in item)):
                raise SceneError(f"{key}.{index}", item, self.allowed)
        return [[float(x) for x in item] for item in value]


@dataclass(frozen=True)
class FreeTable:
    """A table passed through unchecked (checked by whoever reads it)."""

    description: str
    default: Any = None

    @property
    def allowed(self) -> str:
        return f"{self.description} must be a table"

    def check(self, value: Any, key: str) -> dict:
        if not isinstance(value, dict):
            raise SceneError(key, value, self.allowed)
        return copy.deepcopy(value)


@dataclass(frozen=True)
class Table:
    """A TOML table with a fixed set of keys.

    Attributes:
        fields: Key -> spec of each allowed key.
        description: What the table is, for messages.
        presence: ``"filled"``: absent means all defaults; ``"optional"``: absent
            means left out of the scene (an effect off); ``"required"``.
        shorthand: If set, a plain string ``s`` stands for ``{shorthand = s}``.
        not_read: Key -> why nothing reads it: keys a user may write here (from an older
            version, or ahead of a feature) that are refused with that reason rather than
            as unknown.
    """

    fields: dict
    description: str
    presence: str = "filled"
    shorthand: str | None = None
    not_read: dict | None = None

    @property
    def allowed(self) -> str:
        return f"{self.description} must be a table with keys " + ", ".join(self.fields)

    def check(self, value: Any, key: str) -> dict:
        if self.shorthand is not None and isinstance(value, str):
            value = {self.shorthand: value}
        if not isinstance(value, dict):
            raise SceneError(key, value, self.allowed)
        prefix = f"{key}." if key else ""
        for name in value:
            if self.not_read and name in self.not_read:
                raise SceneError(prefix + str(name), value[name], self.not_read[name])
            if name not in self.fields:
                raise _unknown_key(prefix + str(name), value[name],
                                   [prefix + valid for valid in self.fields])
        result = {}
        for name, spec in self.fields.items():
            given = value.get(name)  # None (from to_json) counts as absent
            if given is not None:
                result[name] = spec.check(given, prefix + name)
            elif isinstance(spec, Table):
                if spec.presence == "required":
                    raise _missing(prefix + name, spec.allowed)
                if spec.presence == "filled":
                    result[name] = spec.check({}, prefix + name)
            elif spec.default is REQUIRED:
                raise _missing(prefix + name, spec.allowed)
            else:
                result[name] = copy.deepcopy(spec.default)
        return result


@dataclass(frozen=True)
class TableMap:
    """A table of named sub-tables, e.g. ``[materials.NAME]``."""

    entry: Table
    description: str
    default: Any = REQUIRED

    @property
    def allowed(self) -> str:
        return f"{self.description} must be a table of named tables (at least one)"

    def check(self, value: Any, key: str) -> dict:
        if not isinstance(value, dict) or not value:
            raise SceneError(key, value, self.allowed)
        result = {}
        for name, sub in value.items():
            if not _FILENAME_SAFE.match(name):
                raise SceneError(f"{key}.{name}", sub,
                                 "names must be letters, digits, '_', '.', '-'")
            result[name] = self.entry.check(sub, f"{key}.{name}")
        return result


@dataclass(frozen=True)
class TableList:
    """An array of tables, e.g. ``[[monitor]]``; entries named by key ``name`` are unique."""

    entry: Table
    description: str
    default: Any = field(default_factory=list)

    @property
    def allowed(self) -> str:
        return f"{self.description} must be an array of tables ([[...]])"

    def check(self, value: Any, key: str) -> list[dict]:
        if not isinstance(value, list):
            raise SceneError(key, value, self.allowed)
        result = [self.entry.check(item, f"{key}.{index}") for index, item in enumerate(value)]
        seen: dict[str, int] = {}
        for index, item in enumerate(result):
            name = item.get("name")
            if name is None:
                continue
            if name in seen:
                raise SceneError(f"{key}.{index}.name", name,
                                 f"names must be unique; {key}.{seen[name]} has this name already")
            seen[name] = index
        return result


def _unknown_key(key: str, value: Any, candidates: Sequence[str]) -> SceneError:
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.6)
    if not close:
        # A key in the wrong table: look for the same leaf name anywhere.
        leaf = key.rsplit(".", 1)[-1]
        close = [k for k in _all_schema_keys() if k.rsplit(".", 1)[-1] == leaf][:1]
    hint = f"; did you mean '{close[0]}'?" if close else ""
    allowed = "valid keys here: " + ", ".join(candidates)
    return SceneError(key, value, allowed, f"unknown scene key '{key}'{hint}")


# ---------------------------------------------------------------------------
# The schema: every scene key, its type, range and default (docs/method.md section 13, README "A scene").
# ---------------------------------------------------------------------------

_STRENGTH_NOT_READ = (
    "not read here: strengths go in [materials.NAME.plasticity] (rock, Mohr-Coulomb: cohesion, "
    "friction_angle, dilation_angle, tensile_strength) or [materials.NAME.damage] (concrete: "
    "cohesion, friction_angle, tensile_strength, fracture_energy); a material without either "
    "table is linear elastic; interface strengths go in [contact]")

# Where the law is evaluated: at every quadrature point, or once per Q1 cell at its mean strain with
# the rest of the cells' elastic stiffness in the matrix (pyfem/reduced_integration.py).
_INTEGRATION = Choice("points of the law per cell: \"full\" (the matrix's quadrature, 8 per Q1 cell) or "
                      "\"reduced\" (one at the cell's mean strain, Q1 only; the elastic stiffness of the strain's "
                      "variation in the cell stays in the matrix)", ("full", "reduced"), default="full")

# Rock: Mohr-Coulomb with tension cut-off, perfectly plastic unless the scene asks for softening
# damage (damage_max > 0, with its scale; docs/materials.md). The three strengths default to
# PRESET_STRENGTHS of the material's preset (required without a preset).
_PLASTICITY = Table({
    "cohesion": Number("cohesion c (Pa)", NON_NEGATIVE, default=None),
    "friction_angle": Number("friction angle phi (deg)", "[0, 90)", default=None),
    "dilation_angle": Number("dilation angle psi (deg)", "[0, 90)", default=0.0),
    "tensile_strength": Number("tensile strength of the cut-off (Pa; >= c cot(phi): none)",
                               NON_NEGATIVE, default=None),
    "damage_max": Number("largest damage d_max (0: no damage, perfect plasticity; > 0: softening, with its "
                         "scale damage_plastic_strain or damage_plastic_displacement)", "[0, 1)", default=0.0),
    # None: DAMAGE_PLASTIC_STRAIN when damage_max = 0 (unused), filled in by _check_nonlinear_material;
    # with damage_max > 0 the scene gives it or the crack band's damage_plastic_displacement (not both).
    "damage_plastic_strain": Number("equivalent plastic strain scale kappa_ref of the damage",
                                    POSITIVE, default=None),
    # The crack band (docs/materials.md "Crack band of the rock"): kappa_ref = u_ref / h per cell.
    "damage_plastic_displacement": Number("plastic displacement scale u_ref of the damage's crack band (m; 0: none)",
                                          NON_NEGATIVE, default=0.0),
    # None: on for Q1 (volumetric locking of plastic flow), off for Q2.
    "mean_dilatation": Flag("mean dilatation (B-bar) in the region's cells", default=None),
    # Where the law acts: the region's cells whose centroid lies in the box; the others stay linear
    # elastic in the stiffness matrix (the far field of a cavern model, which does not yield).
    "zone": Vector("box [xmin, ymin, zmin, xmax, ymax, zmax] (m) of the cells with the law; the region's other "
                   "cells stay linear elastic", 6, default=None),
    "integration": _INTEGRATION,
}, "[materials.NAME.plasticity]", presence="optional")
DAMAGE_PLASTIC_STRAIN = 0.005
"""The kappa_ref handed to the kernel when the rock has no damage (damage_max = 0: it scales nothing)."""
PLASTIC_DISPLACEMENT_RANGE = (1.0e-5, 1.0)
"""Plausible u_ref of the rock's crack band (m): outside it, a unit slip (mm or cm written as m)."""
_ROCK_DAMAGE_NOT_READ = ("not read here: the rock's damage (damage_max, damage_plastic_strain and its crack band "
                         "damage_plastic_displacement) goes in [materials.NAME.plasticity] (Mohr-Coulomb rock); "
                         "the concrete law's crack band is fracture_energy in [materials.NAME.damage]")

# Lining concrete: Eq. 21 of the paper with crack band (docs/materials.md). Strengths as above.
_DAMAGE = Table({
    "cohesion": Number("cohesion c of the compression-shear criterion (Pa)", POSITIVE, default=None),
    "friction_angle": Number("friction angle phi (deg)", "[0, 90)", default=None),
    "tensile_strength": Number("tensile strength f_t (Pa)", POSITIVE, default=None),
    "fracture_energy": Number("fracture energy G_f (N/m; 0: no crack band)", NON_NEGATIVE, default=120.0),
    "A_t": Number("Eq. 21 tension constant A_t", "(0, 1]", default=1.0),
    "B_t": Number("Eq. 21 tension constant B_t", POSITIVE, default=5.0e4),
    "A_c": Number("Eq. 21 compression constant A_c", POSITIVE, default=1.4),
    "B_c": Number("Eq. 21 compression constant B_c", POSITIVE, default=1.5e3),
    "stiffness_recovery": Number("share s of d_t acting in compression", "[0, 1]", default=0.0),
    "damage_max": Number("cap of the damage (stiffness floor)", "[0, 1)", default=0.9999),
    "integration": _INTEGRATION,
}, "[materials.NAME.damage]", presence="optional",
   not_read={key: _ROCK_DAMAGE_NOT_READ for key in ("damage_plastic_strain", "damage_plastic_displacement")})

_MATERIAL = Table({
    "preset": Choice("material preset (the paper's Table 1, docs/method.md section 10)", tuple(MATERIAL_PRESETS), default=None),
    # Required unless preset; descriptions and ranges are pyfem.material's (ELASTIC_RANGES).
    **{key: Number(_material.ELASTIC_RANGES[key][0], _material.interval(key), default=None)
       for key in ("E", "nu", "rho")},
    "plasticity": _PLASTICITY,
    "damage": _DAMAGE,
}, "a material", not_read={
    **{key: _STRENGTH_NOT_READ for key in ("cohesion", "friction_angle", "dilation_angle", "tensile_strength")},
    **{key: _ROCK_DAMAGE_NOT_READ for key in ("damage_max", "damage_plastic_strain", "damage_plastic_displacement")},
})

SUPPORT_TYPES = ("bolt", "cable")
"""`support.NAME.type`: "bolt" fully grouted (no plate, no pretension, no free length); "cable" with a head
plate, a free (ungrouted) length at the head and a pretension."""

# A group of rock bolts or anchor cables (docs/method.md "Rock bolts and cables", pyfem/support.py):
# explicit lines, or a pattern normal to a named surface.
_SUPPORT = Table({
    "type": Choice("support type: \"bolt\" (fully grouted, no plate) or \"cable\" (head plate, free length, "
                   "pretension)", SUPPORT_TYPES, default="bolt"),
    "lines": VectorList("bolts as lines [x0, y0, z0, x1, y1, z1], head (rock face) to tip (m)", 6, default=None),
    "surface": Text("named surface the pattern's bolts start on, normal to it, into the rock", default=None),
    "spacing": Vector("pattern spacing [around the section, along the axis] (m)", 2, POSITIVE, default=None),
    "length": Number("length of each bolt of the pattern (m)", POSITIVE, default=None),
    "diameter": Number("steel diameter d (m; area pi d^2 / 4)", "(0, 0.5]"),
    "E": Number("steel Young's modulus (Pa)", POSITIVE, default=2.0e11),
    "yield_force": Number("axial capacity in tension and compression (N)", POSITIVE),
    "bond_stiffness": Number("grout shear stiffness per metre of bolt (N/m^2: N/m per m)", POSITIVE),
    "bond_strength": Number("grout shear strength per metre of bolt (N/m)", POSITIVE),
    "pretension": Number("pretension of a cable's free length (N)", NON_NEGATIVE, default=0.0),
    "free_length": Number("ungrouted length at a cable's head (m)", NON_NEGATIVE, default=0.0),
    "segment": Number("element length along a bolt (m)", POSITIVE, default=None),
}, "a support group")

_WAVE_TYPE = Choice("wave type", ("P", "SV", "SH"))
CONTACT_SPLITS = ("before_static", "after_static")
"""`contact.split`: the interfaces split before the static stage (their law acts in it) or after it."""

SCHEMA = Table({
    "title": Text("title", default="untitled"),
    "mesh": Table({
        "builder": Choice("mesh builder", ("box", "layered_cavern", "file"), default="box"),
        "origin": Vector("min corner (m)", 3, default=[0.0, 0.0, 0.0]),
        "size": Vector("box size (m)", 3, POSITIVE, default=None),   # required for box
        "h": Number("target element size (m)", POSITIVE, default=None),  # required for box
        "order": Choice("element order", (1, 2), default=1),
        "file": FilePath("mesh file", default=None),                 # required for file
        "layers": TableList(Table({
            "material": Text("layer material (a [materials] table)"),
            "thickness": Number("layer thickness (m)", POSITIVE),
        }, "a layer"), "[[mesh.layers]] (box, bottom up)", default=None),
        "parameters": FreeTable("builder parameters (layered_cavern, file)"),
    }, "[mesh]"),
    "materials": TableMap(_MATERIAL, "[materials.NAME]"),
    "time": Table({
        "duration": Number("duration (s)", POSITIVE),
        "safety": Number("safety factor on the critical step", "(0, 1]", default=0.8),
        "dt": Number("fixed time step (s)", POSITIVE, default=None),
        "power_iteration": Flag("sharpen the critical step by power iteration", default=True),
        "matrix_precision": Choice("storage of the stiffness matrix's blocks in the kernel", ("double", "single"),
                                   default="double"),
        "local_stepping": Choice("multi-rate stepping: each cell and contact pair at its own stable rate; \"auto\": "
                                 "on where the scene allows it and it is predicted to pay over the whole run "
                                 "(docs/local_stepping.md \"When it is on\")", (True, False, "auto"),
                                 default="auto"),
    }, "[time]"),
    "wave": Table({
        "type": Choice("wave type", ("P", "SV", "SH"), default=None),  # or [[wave.component]]
        "angle": Number("incidence angle from vertical (deg)", "[0, 90)", default=None),
        "azimuth": Number("azimuth (deg)", default=None),
        "scale": Number("motion scale factor", default=1.0),
        "surface": Number("z of the free surface (m)", default=None),
        "medium": Text("half-space material name", default=None),
        "reference_point": Vector("reference point (m)", 3, default=None),
        "component": TableList(Table({
            "type": _WAVE_TYPE,
            "scale": Number("component scale factor", default=1.0),
            "angle": Number("incidence angle from vertical (deg)", "[0, 90)", default=0.0),
            "azimuth": Number("azimuth (deg)", default=0.0),
        }, "a wave component"), "[[wave.component]]"),
        # Horizontal layers over the half-space of wave.medium, top down from wave.surface: the free
        # field is then that of the layered site (pyfem.seismic.layered, docs/method.md).
        "layers": TableList(Table({
            "medium": Text("layer material (a [materials] table)"),
            "thickness": Number("layer thickness (m)", POSITIVE),
        }, "a free-field layer"), "[[wave.layers]] (top down from wave.surface)", default=None),
        # Where the free field comes from (pyfem/seismic/drm.py, docs/boundaries.md): the closed form on
        # the truncation faces, or the domain-reduction method's forces from an auxiliary run.
        "free_field": Table({
            "method": Choice("how the free field enters: \"half_space\" (the closed form of wave.medium or "
                             "[[wave.layers]] on the truncation faces) or \"drm\" (the domain-reduction method: "
                             "the motion of `auxiliary` on the layer of cells inside the truncation faces)",
                             ("half_space", "drm"), default="half_space"),
            "auxiliary": FilePath("the auxiliary scene of method \"drm\": the same rock without the cavern on a "
                                  "larger mesh whose nodes include the main model's", default=None),
        }, "the free field's method"),
        "motion": Table({
            "ricker": Table({
                "f0": Number("Ricker peak frequency (Hz)", POSITIVE),
                "amplitude": Number("Ricker displacement amplitude (m)"),
                "t0": Number("Ricker centre time (s)", NON_NEGATIVE, default=None),  # 1.5/f0
            }, "a Ricker wavelet", presence="optional"),
            "record": Table({
                "file": FilePath("accelerogram file"),
                "units": Choice("record units", ("g", "m/s2", "cm/s2")),
                "dt": Number("sample step of a one-column record (s)", POSITIVE, default=None),
                "pga": Number("target peak ground acceleration (g)", POSITIVE, default=None),
                # Where pga is set (pyfem.seismic.records.SCALE_MODES): on the processed window (its
                # peak is pga) or on the whole raw record before the window, taper, filter, correction.
                "scale": Choice("where `pga` is set: \"after_filter\" (the processed motion's peak is pga) or "
                                "\"before_filter\" (the whole raw record is scaled to peak pga, then windowed, "
                                "tapered, filtered and baseline-corrected: the processed peak is lower)",
                                ("after_filter", "before_filter"), default="after_filter"),
                "window": Vector("time window [start, end] (s)", 2, NON_NEGATIVE,
                                 default=None, increasing=True),
                "band": Vector("band-pass [f_low, f_high] (Hz)", 2, POSITIVE,
                               default=[0.1, 25.0], increasing=True),
                "format": Choice("record format", ("auto", "plain", "at2"), default="auto"),
                # None: keep the zero-phase filter's precursor where it exceeds 1e-3 of the peak
                # (seconds before the window start); 0: start at the window (more baseline correction).
                "lead_in": Number("seconds kept before the window start (s)", NON_NEGATIVE, default=None),
            }, "an accelerogram", presence="optional", shorthand="file"),
        }, "[wave.motion]", presence="required"),
    }, "[wave]", presence="optional"),
    "boundary": Table({
        # The truncation faces (docs/boundaries.md): where the model is cut. Cavity and lining
        # surfaces are never among them; they are traction-free.
        "type": Choice("boundary type", BOUNDARY_TYPES, default="viscoelastic"),
        "faces": TextList("truncation faces (physical surface names)", default=None, non_empty=True),
        "face": TableMap(Table({
            "type": Choice("boundary type of this face", BOUNDARY_TYPES),
        }, "a face's boundary"), "[boundary.face.NAME]", default=None),
        "alpha_N": Number("normal spring factor alpha_N", POSITIVE, default=4.0 / 3.0),
        "alpha_T": Number("tangential spring factor alpha_T", POSITIVE, default=2.0 / 3.0),
        "centre": Vector("scattering centre (m)", 3, default=None),   # default model centre
    }, "[boundary]"),
    "monitor": TableList(Table({
        "name": Text("monitor name", filename_safe=True),
        "point": Vector("monitor point (m)", 3),
    }, "a monitor"), "[[monitor]]"),
    "output": Table({
        "interval": Number("monitor sample interval (s)", POSITIVE, default=0.01),
        "xdmf_interval": Number("field output interval (s; 0: no fields)", NON_NEGATIVE,
                                default=0.1),
        "fields": TextList("output fields", default=["displacement", "velocity"],
                           options=OUTPUT_FIELDS, unavailable=FIELDS_NOT_PRODUCED),
        "checkpoint_interval": Number("wall time between periodic checkpoints (s; 0: none; a stop and the "
                                      "run's end write one)", NON_NEGATIVE, default=300.0),
    }, "[output]"),
    "parallel": Table({
        "model": Choice("how the MPI ranks of `mpirun -n N` (N > 1) hold the model: each rank builds and "
                        "steps only its part of dolfinx's distributed mesh (docs/scaling.md \"The distributed "
                        "model\"); \"whole\", every rank building the whole model, was removed: under mpirun "
                        "every run is the distributed model", ("distributed",), default="distributed"),
    }, "[parallel]"),
    "damping": Table({
        "ratio": Number("damping ratio", "[0, 1)", default=None),
        "frequencies": Vector("frequencies [f1, f2] (Hz)", 2, POSITIVE,
                              default=None, increasing=True),
        "alpha": Number("mass-proportional coefficient alpha (1/s)", NON_NEGATIVE, default=None),
        "beta": Number("stiffness-proportional coefficient beta (s)", NON_NEGATIVE, default=None),
    }, "[damping]", presence="optional"),
    "initial_stress": Table({
        # Geostatic (surface, rho, k) or uniform (stress); one of the two (docs/static.md).
        "surface": Number("z of the ground surface (m)", default=None),
        "rho": Number("overburden density (kg/m^3)", POSITIVE, default=None),
        "k": Vector("stress ratios [k_x, k_y, k_z]", 3, POSITIVE, default=[1.0, 1.0, 1.0]),
        "stress": Vector("uniform initial stress [sxx, syy, szz, syz, sxz, sxy] (Pa, compression negative)", 6,
                         default=None),
    }, "[initial_stress]", presence="optional"),
    "static": Table({
        # A static stage before the dynamic run (docs/static.md): present = on.
        "excavate": TextList("regions removed by the excavation", default=[]),
        "relaxation": Number("fraction lambda of the excavation load released before install", "[0, 1]",
                             default=0.5),
        "install": TextList("regions activated stress-free after the first release", default=[]),
        "support": TextList("support groups ([support.NAME]) installed with the install regions, after the "
                            "first release", default=[]),
        # An excavation sequence (benches top down) instead of the four keys above (docs/static.md).
        "step": TableList(Table({
            "excavate": TextList("regions this step removes", default=[]),
            "relaxation": Number("fraction lambda of this step's excavation load released before its install and "
                                 "support", "[0, 1]", default=0.5),
            "install": TextList("regions activated stress-free after this step's first release", default=[]),
            "support": TextList("support groups ([support.NAME]) installed with this step's install regions",
                                default=[]),
        }, "an excavation step"), "[[static.step]] (an excavation sequence, in order)", default=None),
        "gravity": Flag("the materials' weight as a body force of the stage", default=False),
        "tolerance": Number("relative residual ||f - f_int|| / ||f|| the stage must reach (default 1e-8 for "
                            "the linear solve, 1e-5 for dynamic relaxation)", "(0, 0.1]", default=None),
        "solver": Choice("static solver: direct or iterative (linear elastic), relaxation (dynamic relaxation "
                         "with the kernel: plasticity, damage and the contact pair law); auto: relaxation when "
                         "a material has [plasticity] or [damage], else direct or iterative by size",
                         ("auto", "direct", "iterative", "relaxation"), default="auto"),
        "max_steps": Number("largest number of dynamic-relaxation steps per stage", "[1, 1e9]", default=200000),
        "boundary": Table({
            "type": Choice("boundary type of the truncation faces during the stage", STATIC_BOUNDARY_TYPES,
                           default="roller"),
            "face": TableMap(Table({
                "type": Choice("boundary type of this face during the stage", STATIC_BOUNDARY_TYPES),
            }, "a face's boundary during the stage"), "[static.boundary.face.NAME]", default=None),
        }, "[static.boundary]"),
    }, "[static]", presence="optional"),
    "support": TableMap(_SUPPORT, "[support.NAME]", default=None),
    "contact": Table({
        "interfaces": TextList("interface names: named surfaces (a box's layers: interface_1, ...) that neither "
                               "cross nor end on one another inside the model (they may reach the outer "
                               "boundary)", non_empty=True),
        "cohesion": Number("interface cohesion (Pa)", NON_NEGATIVE),
        "friction_angle": Number("static friction angle (deg)", "[0, 90)"),
        "dynamic_friction_angle": Number("dynamic friction angle (deg)", "[0, 90)",
                                         default=None),  # = friction_angle
        "tensile_strength": Number("interface tensile strength (Pa)", NON_NEGATIVE,
                                   default=None),        # = cohesion
        "split": Choice("when the interfaces are split: \"before_static\": the pairs act with their law in the "
                        "static stage (bond, slip, opening; no deterioration); \"after_static\": the stage runs "
                        "welded (the pairs bonded whatever their force: the unsplit mesh's stage) and the dynamic "
                        "run starts with the pairs carrying the welded stage's forces under their real strengths "
                        "and D(t); without [static] the two are the same", CONTACT_SPLITS, default="before_static"),
        "deterioration": Table({
            "R0": Number("residual factor R0", "(0, 1]", default=0.75),
            "lambda": Number("decay rate lambda", NON_NEGATIVE, default=5.0),
            "m": Number("velocity factor m", POSITIVE, default=0.883),
            "n": Number("velocity offset n (m/s)", POSITIVE, default=0.02),
            "p": Number("velocity exponent p", NON_NEGATIVE, default=0.032),
        }, "[contact.deterioration]", presence="optional"),
        "release_time": Number("time over which a broken bond's cohesion and tensile strength fall to zero "
                               "(s; time-weakening: the pair's force falls from its strength over this time "
                               "instead of in one step)", POSITIVE, default=None),
        "normal_lag": Table({
            "length": Number("slip length L of the normal-stress lag (m)", POSITIVE),
            "velocity": Number("reference velocity V* of the normal-stress lag (m/s)", NON_NEGATIVE),
        }, "[contact.normal_lag]", presence="optional"),
    }, "[contact]", presence="optional"),
    "pair_monitor": TableList(Table({
        "name": Text("pair monitor name", filename_safe=True),
        "point": Vector("pair monitor point (m)", 3),
    }, "a pair monitor"), "[[pair_monitor]]"),
    "bolt_monitor": TableList(Table({
        "name": Text("bolt monitor name", filename_safe=True),
        "point": Vector("bolt monitor point (m)", 3),
        "group": Text("support group ([support.NAME]) whose segments it looks in", default=None),
    }, "a bolt monitor"), "[[bolt_monitor]]"),
}, "the scene")
"""The whole scene vocabulary. Conditional rules live in `_check_rules`."""


def _all_schema_keys(spec: Any = SCHEMA, prefix: str = "") -> list[str]:
    keys = []
    fields = getattr(spec, "fields", None)
    if fields is None and hasattr(spec, "entry"):
        fields = spec.entry.fields
        prefix += "0." if isinstance(spec, TableList) else "NAME."
    for name, sub in (fields or {}).items():
        keys.append(prefix + name)
        keys.extend(_all_schema_keys(sub, prefix + name + "."))
    return keys


# ---------------------------------------------------------------------------
# The validated scene.
# ---------------------------------------------------------------------------

class Scene(dict):
    """Validated, fully defaulted settings of one scene (a plain nested dict).

    Attributes:
        source: The scene file path (``"<dict>"`` for `parse_scene` without one).
        effects: Names of the effects that are on, in `EFFECT_ORDER`.
        warnings: One line each on what a user may mean but is probably a mistake (a mesh far
            coarser than its waves need, a run shorter than its record, ...). Filled by
            validation; the solver may add more with `warn` before the run directory is
            written. The CLI prints them, run.json keeps them.
        on_warning: Called with each message `warn` adds (the CLI prints it), or ``None``.
    """

    def __init__(self, settings: dict, source: str, warnings: Iterable[str] = ()):
        super().__init__(settings)
        self.source = source
        self.warnings: list[str] = list(warnings)
        self.on_warning = None
        present = {
            "seismic_input": "wave" in self,
            "damping": "damping" in self,
            "initial_stress": "initial_stress" in self,
            "contact": "contact" in self,
            "deterioration": "deterioration" in self.get("contact", {}),
        }
        self.effects = tuple(name for name in EFFECT_ORDER if present[name])

    def warn(self, message: str) -> None:
        """Adds a warning (one line, no ``warning:`` prefix) unless it is there already."""
        if message not in self.warnings:
            self.warnings.append(message)
            if self.on_warning is not None:
                self.on_warning(message)

    def to_json(self) -> dict:
        """The settings as a JSON-serialisable dict (`parse_scene` accepts it back)."""
        return json.loads(json.dumps(dict(self)))

    def model_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) corners of the model (m) for builder ``box``; ``None`` otherwise."""
        mesh = self["mesh"]
        if mesh["builder"] != "box":
            return None
        lo = np.asarray(mesh["origin"], dtype=float)
        return lo, lo + np.asarray(mesh["size"], dtype=float)

    def wave_components(self) -> list[dict]:
        """Incident plane waves as a list of {type, scale, angle, azimuth} (deg).

        One entry built from the top-level ``wave`` keys when no
        ``[[wave.component]]`` is given. ``scale`` is the component's own factor;
        ``wave.scale`` multiplies the motion g(t) shared by all of them.
        Empty when seismic input is off.
        """
        wave = self.get("wave")
        if wave is None:
            return []
        if wave["component"]:
            return copy.deepcopy(wave["component"])
        return [dict(type=wave["type"], scale=1.0, angle=wave["angle"], azimuth=wave["azimuth"])]


def rayleigh_coefficients(ratio: float, f1: float, f2: float) -> tuple[float, float]:
    """Rayleigh damping C = alpha M + beta K with damping ratio `ratio` at f1 and f2.

    The modal damping ratio is xi(f) = alpha / (4 pi f) + beta pi f; it equals
    `ratio` at both frequencies and is below it between them.

    Args:
        ratio: Target damping ratio (-).
        f1: Lower frequency (Hz), > 0.
        f2: Upper frequency (Hz), > f1.

    Returns:
        (alpha in 1/s, beta in s).
    """
    alpha = 4.0 * math.pi * ratio * f1 * f2 / (f1 + f2)
    beta = ratio / (math.pi * (f1 + f2))
    return alpha, beta


# ---------------------------------------------------------------------------
# Conditional rules: what one table cannot say about itself.
# ---------------------------------------------------------------------------

def _check_rules(settings: dict, base_dirs: Sequence[Path], warnings: list[str]) -> None:
    """Apply the cross-key rules and derived defaults in place; append warnings to `warnings`."""
    _check_mesh(settings)
    _check_materials(settings, warnings)
    _check_time(settings)
    if "wave" in settings:
        _check_wave(settings)
    _check_boundary(settings)
    if "damping" in settings:
        _check_damping(settings["damping"])
        if settings.get("wave", {}).get("free_field", {}).get("method") == "drm" and settings["damping"]["beta"]:
            raise SceneError("damping.beta", settings["damping"]["beta"], "0 with wave.free_field.method = \"drm\" "
                             "(its forces hold no stiffness-damping term; mass-proportional alpha is allowed)")
    if "contact" in settings:
        contact = settings["contact"]
        if settings["mesh"]["builder"] == "box" and settings["mesh"]["layers"]:
            known = layer_interface_names(settings)
            for index, name in enumerate(contact["interfaces"]):
                if name not in known:
                    raise SceneError(f"contact.interfaces.{index}", name,
                                     "must name an interface of the layered box: "
                                     + ", ".join(known))
        for name in ("cohesion", "tensile_strength"):
            _check_strength(f"contact.{name}", contact[name])
        if contact["dynamic_friction_angle"] is None:
            contact["dynamic_friction_angle"] = contact["friction_angle"]
        if contact["tensile_strength"] is None:
            contact["tensile_strength"] = contact["cohesion"]
    elif settings["pair_monitor"]:
        raise SceneError("pair_monitor", settings["pair_monitor"],
                         "pair monitors need a [contact] table")
    if "initial_stress" in settings:
        _check_initial_stress(settings["initial_stress"], warnings)
    if "static" in settings:
        _check_static(settings)
        _check_steps(settings)
    _check_support(settings)
    _check_output(settings, warnings)
    _check_points_inside(settings)
    _resolve_files(settings, base_dirs)
    if "record" in settings.get("wave", {}).get("motion", {}):
        _check_record(settings, warnings)
    if "ricker" in settings.get("wave", {}).get("motion", {}):
        _check_ricker_duration(settings, warnings)
    if "wave" in settings:
        _check_resolution(settings, warnings)


def _check_mesh(settings: dict) -> None:
    mesh = settings["mesh"]
    builder_rules = {
        "box": ("size", "h"),
        "file": ("file",),
        "layered_cavern": (),
    }
    for name in builder_rules[mesh["builder"]]:
        if mesh[name] is None:
            spec = SCHEMA.fields["mesh"].fields[name]
            raise _missing(f"mesh.{name}", f"{spec.allowed} (required by builder "
                                           f"{_show(mesh['builder'])})")
    if mesh["builder"] != "box" and mesh["layers"] is not None:
        raise SceneError("mesh.layers", mesh["layers"], "layers are a setting of builder \"box\" only")
    if mesh["builder"] == "box" and mesh["parameters"] is not None:
        raise SceneError("mesh.parameters", mesh["parameters"],
                         "builder \"box\" takes no parameters (use size, h)")
    # Keys the chosen builder does not read are refused: a user who sets mesh.h on a file mesh
    # expects a finer mesh and would not get one.
    sizes_from = {"file": "the file", "layered_cavern": "mesh.parameters (h_cavern, h_far, ...)"}
    if mesh["builder"] in sizes_from:
        builder, where = _show(mesh["builder"]), sizes_from[mesh["builder"]]
        for name in ("size", "h"):
            if mesh[name] is not None:
                raise SceneError(f"mesh.{name}", mesh[name], f"not read by builder {builder}: mesh.{name} "
                                 f"is a setting of builder \"box\" only (sizes come from {where})")
        if mesh["origin"] != SCHEMA.fields["mesh"].fields["origin"].default:
            raise SceneError("mesh.origin", mesh["origin"], f"not read by builder {builder}: mesh.origin "
                             f"is a setting of builder \"box\" only (coordinates come from {where})")
    if mesh["builder"] == "file" and mesh["parameters"] is not None:
        raise SceneError("mesh.parameters", mesh["parameters"], "not read by builder \"file\": it takes "
                         "no parameters (everything comes from the file)")
    if mesh["builder"] == "box":
        _check_box_fits_in_memory(mesh)


# Peak memory of building a box model (gmsh's mesh, dolfinx's assembly, the kernel's matrix) per
# degree of freedom, measured with `pyfem check` on Q1 and Q2 boxes of 0.1-0.7 million dofs
# (2026-11-27: 3.7 and 7.8 kB per dof at the peak, Python and dolfinx's own 0.2 GB beside).
PEAK_BYTES_PER_DOF = {1: 3.7e3, 2: 7.8e3}


def physical_memory_bytes() -> float:
    """The memory this process may use (bytes): the machine's physical memory, or a smaller cgroup
    limit (a container's)."""
    import os

    total = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit.isdigit():
            total = min(total, float(limit))
    except OSError:
        pass
    return total


def _box_dofs(mesh: dict, h: float) -> float:
    """Degrees of freedom of the box builder's mesh at element size h (pyfem/geometry/box.py: n_i =
    ceil(L_i / h) elements per side, a layered box ceil(t / h) per layer in z), as a float (no
    overflow for a tiny h)."""
    def elements(length: float) -> float:
        return max(1.0, math.ceil(min(length / h, 1e15) - 1e-9))

    size, order = mesh["size"], mesh["order"]
    layers = mesh.get("layers")
    n_z = sum(elements(layer["thickness"]) for layer in layers) if layers else elements(size[2])
    return 3.0 * (order * elements(size[0]) + 1) * (order * elements(size[1]) + 1) * (order * n_z + 1)


def _check_box_fits_in_memory(mesh: dict) -> None:
    """Refuses a box whose mesh.h would need more memory than the machine has, before gmsh meshes
    it for minutes (a typo such as h = 0.2 for 2.0 asked for 12.5 million cells)."""
    order, h = mesh["order"], mesh["h"]
    per_dof, have = PEAK_BYTES_PER_DOF[order], physical_memory_bytes()
    dofs = _box_dofs(mesh, h)
    if per_dof * dofs <= have:
        return
    # The smallest h that fits, by bisection on the same count (a thin side does not shrink with h).
    low, high = h, max(mesh["size"])
    if per_dof * _box_dofs(mesh, high) > have:
        smallest_text = "no h: even one element per side is too large for this machine"
    else:
        for _ in range(100):
            middle = math.sqrt(low * high)
            low, high = (low, middle) if per_dof * _box_dofs(mesh, middle) <= have else (middle, high)
        step = 10.0 ** (math.floor(math.log10(high)) - 1)
        smallest = math.ceil(high / step) * step  # two significant digits, rounded up
        smallest_text = f"h >= {smallest:.3g} m for this box and order on this machine"
    cells = dofs / 3.0 / order ** 3
    raise SceneError("mesh.h", h, smallest_text,
                     f"scene key 'mesh.h' = {h:g}: the box would have about {cells:.3g} Q{order} cells "
                     f"({dofs / 1e6:.3g} million dofs), about {per_dof * dofs / 2**30:.3g} GiB at the peak of "
                     f"its assembly, more than this machine's {have / 2**30:.1f} GiB; allowed: {smallest_text}")


def _check_materials(settings: dict, warnings: list[str]) -> None:
    mesh = settings["mesh"]
    if mesh["builder"] == "box" and mesh["layers"]:
        _check_layers(settings)
    elif mesh["builder"] == "box":
        allowed = f"builder \"box\" has the single region \"{BOX_REGION}\""
        for name in settings["materials"]:
            if name != BOX_REGION:
                explain = allowed + f"; define [materials.{BOX_REGION}] only"
                raise SceneError(f"materials.{name}", name, explain,
                                 f"scene key 'materials.{name}': no region \"{name}\" "
                                 f"in the mesh; {explain}")
        if BOX_REGION not in settings["materials"]:
            raise _missing(f"materials.{BOX_REGION}", allowed)
    for name, material in settings["materials"].items():
        preset = MATERIAL_PRESETS.get(material["preset"], {})
        for key, value in preset.items():
            if material[key] is None:  # explicit keys override the preset
                material[key] = value
        for key in ("E", "nu", "rho"):
            if material[key] is None:
                spec = _MATERIAL.fields[key]
                raise _missing(f"materials.{name}.{key}",
                               f"{spec.allowed} (or give preset = one of "
                               + ", ".join(_show(p) for p in MATERIAL_PRESETS) + ")")
        _check_young_modulus(f"materials.{name}.E", material["E"])
        _check_density(f"materials.{name}.rho", material["rho"], warnings)
        _check_nonlinear_material(name, material, mesh["order"])


def _check_nonlinear_material(name: str, material: dict, order: int) -> None:
    """[materials.NAME.plasticity] / [materials.NAME.damage]: one of them, strengths from the preset
    when not given, cross-key ranges; mean_dilatation resolved for the element order."""
    given = [table for table in NONLINEAR_TABLES if table in material]
    if len(given) > 1:
        raise SceneError(f"materials.{name}", given, "a material has one nonlinear "
                         "law: [plasticity] (Mohr-Coulomb rock) or [damage] (concrete), not both")
    if not given:
        return
    table = given[0]
    key, values = f"materials.{name}.{table}", material[table]
    spec = _MATERIAL.fields[table]
    preset = PRESET_STRENGTHS.get(material["preset"], {})
    for strength in ("cohesion", "friction_angle", "tensile_strength"):
        if values[strength] is None:
            values[strength] = preset.get(strength)
        if values[strength] is None:
            raise _missing(f"{key}.{strength}", spec.fields[strength].allowed + " (or give the material a "
                           "preset: " + ", ".join(_show(p) for p in PRESET_STRENGTHS) + ")")
    for strength in ("cohesion", "tensile_strength"):
        _check_strength(f"{key}.{strength}", values[strength], "a material strength")
    if values["integration"] == "reduced" and order != 1:
        raise SceneError(f"{key}.integration", "reduced", "\"full\" with mesh.order = 2 (one point per cell is "
                         "for Q1 hexahedra: a Q2 cell's strain varies quadratically within it, too much for one "
                         "law point)")
    if table == "plasticity":
        if values["dilation_angle"] > values["friction_angle"]:
            raise SceneError(f"{key}.dilation_angle", values["dilation_angle"], "the dilation angle must "
                             f"not exceed the friction angle {values['friction_angle']:g} deg (a larger one "
                             "makes plastic flow create energy)")
        if values["friction_angle"] == 0.0 and values["cohesion"] == 0.0:
            raise SceneError(f"{key}.cohesion", 0.0,
                             "must be > 0 when friction_angle = 0 (the material would have no shear strength)")
        _check_rock_damage_scale(key, values)
        if values["mean_dilatation"] is None:
            values["mean_dilatation"] = order == 1
        zone = values.get("zone")
        if zone is not None and not all(zone[k] < zone[k + 3] for k in range(3)):
            raise SceneError(f"{key}.zone", zone, "a box [xmin, ymin, zmin, xmax, ymax, zmax] with each minimum "
                             "below its maximum (m)")
    elif values["fracture_energy"] > 0.0 and values["A_t"] != 1.0:
        raise SceneError(f"{key}.A_t", values["A_t"], "must be 1 when fracture_energy > 0 (with A_t < 1 the "
                         "stress keeps (1 - A_t) f_t forever and no fracture energy can be matched); set "
                         "fracture_energy = 0 for the unregularised law")
    elif values["fracture_energy"] > 0.0 and values["B_t"] * values["tensile_strength"] < material["E"]:
        # The crack band stretches Eq. 21's softening from the peak at f_t; with B_t f_t / E < 1 the curve
        # first hardens past f_t (peak at 1 / B_t), and the stretch lifts that branch further (B_t = 1e4:
        # 1.62 MPa for f_t = 1.27 MPa; workflows/results/lining_law.md).
        raise SceneError(f"{key}.B_t", values["B_t"], f"at least E / f_t = {material['E'] / values['tensile_strength']:.4g} "
                         "when fracture_energy > 0 (a smaller B_t gives Eq. 21 a hardening branch past f_t, which the "
                         "crack band lifts above f_t); set fracture_energy = 0 for the unregularised law")


def _check_rock_damage_scale(key: str, values: dict) -> None:
    """The rock damage's scale: damage_plastic_strain (kappa_ref in every cell) or the crack band's
    damage_plastic_displacement (u_ref / h per cell), not both; damage (damage_max > 0) needs one of
    them, a crack band needs damage, and a u_ref outside PLASTIC_DISPLACEMENT_RANGE is a unit slip.
    Without damage, damage_plastic_strain becomes DAMAGE_PLASTIC_STRAIN (the kernel's, unused)."""
    u_ref = values["damage_plastic_displacement"]
    if values["damage_max"] > 0.0 and u_ref == 0.0 and values["damage_plastic_strain"] is None:
        raise SceneError(f"{key}.damage_max", values["damage_max"], "softening damage needs its scale: give "
                         "damage_plastic_strain (kappa_ref, the same in every cell, e.g. 0.005) or "
                         "damage_plastic_displacement (the crack band's u_ref in m, e.g. 0.01), or leave "
                         "damage_max out (0: perfectly plastic Mohr-Coulomb)")
    if u_ref > 0.0:
        name = f"{key}.damage_plastic_displacement"
        if values["damage_max"] == 0.0:
            raise SceneError(name, u_ref, "0 when damage_max = 0 (no damage: the crack band would scale "
                             "nothing); give damage_max > 0 to soften the rock")
        if values["damage_plastic_strain"] is not None:
            raise SceneError(name, u_ref, "0 beside damage_plastic_strain = "
                             f"{_scientific(values['damage_plastic_strain'])}: give one scale of the damage, "
                             "damage_plastic_strain (the same in every cell) or damage_plastic_displacement "
                             "(the crack band: u_ref / h in each cell), not both")
        lo, hi = PLASTIC_DISPLACEMENT_RANGE
        if not lo <= u_ref <= hi:
            raise SceneError(name, u_ref, f"a plastic displacement (m) in [{_scientific(lo)}, {_scientific(hi)}] "
                             "(kappa h, the plastic displacement across a band one cell wide at which the damage reaches 63 % of damage_max)"
                             + _unit_hint(u_ref, PLASTIC_DISPLACEMENT_RANGE, (("mm", 1.0e-3), ("cm", 1.0e-2))))
    if values["damage_plastic_strain"] is None:
        values["damage_plastic_strain"] = DAMAGE_PLASTIC_STRAIN


def _scientific(x: float) -> str:
    """A number as one would write it in a scene: 8.0e9, 2600.0, 1.0e-3."""
    if 1.0 <= abs(x) < 1.0e5:
        return repr(float(f"{x:.6g}"))
    mantissa, exponent = f"{x:.6e}".split("e")
    mantissa = mantissa.rstrip("0")
    return f"{mantissa}{'0' if mantissa.endswith('.') else ''}e{int(exponent)}"


def _unit_hint(value: float, plausible: tuple[float, float], units: Sequence[tuple[str, float]]) -> str:
    """'; looks like GPa: write 8.0e9' for the units that would bring `value` into `plausible`."""
    lo, hi = plausible
    fits = [(unit, value * factor) for unit, factor in units if lo <= value * factor <= hi]
    if not fits:
        return ""
    (unit, fixed), others = fits[0], fits[1:]
    hint = f"; looks like {unit}: write {_scientific(fixed)}"
    if others:
        hint += " (or " + ", ".join(f"{u}: {_scientific(f)}" for u, f in others) + ")"
    return hint


def _check_young_modulus(key: str, E: float) -> None:
    """E outside `YOUNG_MODULUS_RANGE` is an error that says which unit it looks like."""
    lo, hi = YOUNG_MODULUS_RANGE
    if lo <= E <= hi:
        return
    allowed = f"Young's modulus (Pa) of rock or concrete must lie in [{_scientific(lo)}, {_scientific(hi)}]"
    raise SceneError(key, E, allowed + _unit_hint(E, YOUNG_MODULUS_RANGE,
                                                   (("GPa", 1.0e9), ("MPa", 1.0e6), ("kPa", 1.0e3))))


def _check_density(key: str, rho: float, warnings: list[str]) -> None:
    """rho below `DENSITY_RANGE` is an error (t/m^3 for kg/m^3); above it, a warning (a heavy
    part may be meant, e.g. a numerical test with a rigid mass)."""
    lo, hi = DENSITY_RANGE
    if rho < lo:
        raise SceneError(key, rho, f"density (kg/m^3) of rock or concrete must lie in [{lo:g}, {hi:g}]"
                         + _unit_hint(rho, DENSITY_RANGE, (("t/m^3", 1.0e3),)))
    if rho > hi:
        warnings.append(f"{key} = {_scientific(rho)} kg/m^3 is above {hi:g} kg/m^3 (steel), heavier "
                        "than any rock or concrete; used as given")


def _check_strength(key: str, value: float | None, what: str = "an interface strength") -> None:
    """A strength in (0, SMALLEST_STRENGTH) Pa is an error: it is a value in MPa (or kPa) written
    as Pa; 0 is allowed and means none."""
    if value is None or value == 0.0 or value >= SMALLEST_STRENGTH:
        return
    raise SceneError(key, value, f"{what} in Pa is 0 (none) or at least "
                     f"{SMALLEST_STRENGTH:g} Pa (below that it is negligible next to any geostatic stress)"
                     + _unit_hint(value, (1.0e3, 1.0e8), (("MPa", 1.0e6), ("kPa", 1.0e3))))


def _check_initial_stress(initial: dict, warnings: list[str]) -> None:
    """[initial_stress]: the geostatic form (surface, rho, k) or the uniform one (stress), not both."""
    if initial["stress"] is not None:
        for name in ("surface", "rho"):
            if initial[name] is not None:
                raise SceneError(f"initial_stress.{name}", initial[name], "a setting of the geostatic form: give "
                                 "initial_stress.stress (uniform) or surface, rho and k (geostatic), not both")
        if initial["k"] != SCHEMA.fields["initial_stress"].fields["k"].default:
            raise SceneError("initial_stress.k", initial["k"], "a setting of the geostatic form: give "
                             "initial_stress.stress (uniform) or surface, rho and k (geostatic), not both")
        return
    for name in ("surface", "rho"):
        if initial[name] is None:
            spec = SCHEMA.fields["initial_stress"].fields[name]
            raise _missing(f"initial_stress.{name}", f"{spec.allowed} (the geostatic form: surface, rho, k), or "
                           "give initial_stress.stress = [sxx, syy, szz, syz, sxz, sxy] (Pa) for a uniform stress")
    _check_density("initial_stress.rho", initial["rho"], warnings)


def _check_static(settings: dict) -> None:
    """[static]: something to load the stage, no region both excavated and installed."""
    static = settings["static"]
    if "initial_stress" not in settings and not static["gravity"]:
        raise SceneError("static", {}, "a static stage needs a load: an [initial_stress] table (its excavation "
                         "load), or static.gravity = true (the materials' weight)")
    both = [name for name in static["install"] if name in static["excavate"]]
    if both:
        index = static["install"].index(both[0])
        raise SceneError(f"static.install.{index}", both[0], "a region is excavated (static.excavate) or "
                         "installed (static.install), not both")


def one_step_form(settings: dict, raw: dict) -> dict:
    """[[static.step]] entries or the one-step keys (ONE_STEP_KEYS), not both; one step is the
    one-step form (written back into [static], so the two give the same run)."""
    static = settings.get("static")
    steps = (static or {}).get("step")
    if steps is None:
        return settings
    given = [key for key in ONE_STEP_KEYS if key in (raw.get("static") or {})]
    if given:
        raise SceneError(f"static.{given[0]}", static[given[0]], "a key of the one-step form: give "
                         "static.excavate, relaxation, install and support, or [[static.step]] entries, not both")
    if not steps:
        raise SceneError("static.step", [], "an excavation sequence needs at least one [[static.step]] entry")
    if len(steps) == 1:
        static.update(steps[0], step=None)
    return settings


def _check_steps(settings: dict) -> None:
    """[[static.step]]: each step excavates; a region excavated or installed once, never both; a
    support group of the scene, installed once; solved by dynamic relaxation; no contact pairs yet."""
    static = settings["static"]
    steps = static.get("step")
    if not steps:
        return
    if static["solver"] in ("direct", "iterative"):
        raise SceneError("static.solver", static["solver"], "an excavation sequence ([[static.step]]) is solved by "
                         "dynamic relaxation: \"relaxation\" or \"auto\"")
    if "contact" in settings:
        raise SceneError("static.step", f"{len(steps)} steps", "an excavation sequence of several steps with contact "
                         "pairs is not written yet: one step (the one-step form), or no [contact]")
    seen: dict[tuple, str] = {}
    groups = settings.get("support") or {}
    for k, step in enumerate(steps):
        key = f"static.step.{k}"
        if not step["excavate"]:
            raise SceneError(f"{key}.excavate", [], "each step of a sequence excavates at least one region")
        for part in ("excavate", "install", "support"):
            for index, name in enumerate(step[part]):
                if part == "support" and name not in groups:
                    raise SceneError(f"{key}.support.{index}", name, "must name a [support.NAME] group: "
                                     + (", ".join(groups) or "the scene has none"))
                what = "group" if part == "support" else "region"
                if (what, name) in seen:
                    raise SceneError(f"{key}.{part}.{index}", name, f"a {what} is excavated or installed once "
                                     f"in a sequence: {seen[what, name]} names it already")
                seen[what, name] = f"{key}.{part}"
                material = settings["materials"].get(name)
                if part == "excavate" and k > 0 and material is None:
                    raise SceneError(f"{key}.excavate.{index}", name, "a region excavated after the first step is "
                                     f"in the model until then: it needs its [materials.{name}] table")
                if part == "excavate" and k > 0 and any(material.get(t) is not None for t in NONLINEAR_TABLES):
                    raise SceneError(f"{key}.excavate.{index}", name, "a region excavated after the first step "
                                     "is linear elastic until then (its stress sigma0 + C : eps(u) is what its "
                                     "excavation releases): no [plasticity] or [damage] table")
    elastic_installs = [k for k, step in enumerate(steps) for name in step["install"] if not any(
        (settings["materials"].get(name) or {}).get(t) is not None for t in NONLINEAR_TABLES)]
    if len(set(elastic_installs)) > 1:
        k = sorted(set(elastic_installs))[1]
        raise SceneError(f"static.step.{k}.install", steps[k]["install"], "linear elastic regions are installed in "
                         f"one step of a sequence (static.step.{elastic_installs[0]} installs one already); a "
                         "region installed in another step needs a [damage] or [plasticity] law (its stress is "
                         "then its law's)")


def _check_support(settings: dict) -> None:
    """[support.NAME]: lines or a pattern (surface, spacing, length), not both; a bolt has no plate,
    pretension or free length; every line longer than the free length; static.support names groups."""
    groups = settings.get("support") or {}
    for name, group in groups.items():
        key = f"support.{name}"
        pattern = [part for part in ("surface", "spacing", "length") if group[part] is not None]
        if group["lines"] is not None and pattern:
            raise SceneError(f"{key}.{pattern[0]}", group[pattern[0]], f"a pattern key: give {key}.lines "
                             "(explicit bolts) or surface, spacing and length (a pattern), not both")
        if group["lines"] is None:
            if not pattern:
                raise _missing(f"{key}.lines", f"a support group needs its bolts: {key}.lines = [[x0, y0, z0, "
                               "x1, y1, z1], ...] (m), or a pattern: surface, spacing and length")
            missing = [part for part in ("surface", "spacing", "length") if group[part] is None]
            if missing:
                spec = _SUPPORT.fields[missing[0]]
                raise _missing(f"{key}.{missing[0]}", f"{spec.allowed} (a pattern needs surface, spacing and length)")
        if group["type"] == "bolt":
            for part in ("pretension", "free_length"):
                if group[part] != 0.0:
                    raise SceneError(f"{key}.{part}", group[part], f"must be 0 for {key}.type = \"bolt\" (fully "
                                     "grouted, no plate): a pretension or free length needs type = \"cable\"")
        if group["pretension"] > group["yield_force"]:
            raise SceneError(f"{key}.pretension", group["pretension"], f"must not exceed {key}.yield_force = "
                             f"{group['yield_force']:g} N")
        if group["pretension"] > 0.0 and group["free_length"] == 0.0:
            raise SceneError(f"{key}.pretension", group["pretension"], f"needs a free length ({key}.free_length > 0): "
                             "the pretension is locked off in the ungrouted length")
        shortest = (min(math.dist(line[:3], line[3:]) for line in group["lines"]) if group["lines"] is not None
                    else group["length"])
        for index, line in enumerate(group["lines"] or []):
            if math.dist(line[:3], line[3:]) == 0.0:
                raise SceneError(f"{key}.lines.{index}", line, "a bolt needs a length: head and tip must differ")
        if group["free_length"] >= shortest:
            raise SceneError(f"{key}.free_length", group["free_length"], f"must be shorter than the shortest bolt "
                             f"of the group ({shortest:.6g} m)")
        if group["segment"] is not None and group["segment"] > shortest:
            raise SceneError(f"{key}.segment", group["segment"], f"must not exceed the shortest bolt of the group "
                             f"({shortest:.6g} m)")
    for index, monitor in enumerate(settings.get("bolt_monitor") or []):
        if not groups:
            raise SceneError(f"bolt_monitor.{index}", monitor["name"], "bolt monitors need a [support.NAME] group")
        if monitor["group"] is not None and monitor["group"] not in groups:
            raise SceneError(f"bolt_monitor.{index}.group", monitor["group"], "must name a [support.NAME] group: "
                             + ", ".join(groups))
    static = settings.get("static")
    for index, name in enumerate(static["support"] if static else []):
        if name not in groups:
            raise SceneError(f"static.support.{index}", name, "must name a [support.NAME] group: "
                             + (", ".join(groups) or "the scene has none"))


def _check_output(settings: dict, warnings: list[str]) -> None:
    output = settings["output"]
    default_fields = SCHEMA.fields["output"].fields["fields"].default
    if output["xdmf_interval"] == 0.0 and output["fields"] != default_fields:
        warnings.append(f"output.fields = {_show(output['fields'])} but output.xdmf_interval = 0: "
                        "no fields are written")
    nonlinear = any(table in material for material in settings["materials"].values()
                    for table in NONLINEAR_TABLES)
    if "damage" in output["fields"] and not nonlinear:
        warnings.append("output.fields lists \"damage\" but no material has a [plasticity] or [damage] "
                        "table: the damage fields are zero everywhere")


def _check_record(settings: dict, warnings: list[str]) -> None:
    """Reads and processes the accelerogram as the run will: a malformed file, or a window outside
    the record, is an error now; a duration shorter than the processed motion is a warning."""
    from pyfem.seismic.records import read_record
    from pyfem.seismic.setup import processed_record

    spec = settings["wave"]["motion"]["record"]
    try:
        record = read_record(spec["file"], units=spec["units"], dt=spec["dt"], format=spec["format"])
    except ValueError as error:
        where = "" if spec["file"] in str(error) else f"{spec['file']}: "
        raise SceneError("wave.motion.record.file", spec["file"], "", "scene key 'wave.motion.record.file': "
                         f"not a readable accelerogram: {where}{error}") from None
    t_first, t_last = float(record.t[0]), float(record.t[-1])
    window = spec["window"]
    if window is not None and not (t_first - 0.5 * record.dt <= window[0]
                                   and window[1] <= t_last + 0.5 * record.dt
                                   and window[1] - window[0] >= 2 * record.dt):
        raise SceneError("wave.motion.record.window", window, f"the window must lie inside the record "
                         f"[{t_first:g}, {t_last:g}] s of {spec['file']}")
    with _python_warnings_to(warnings, "wave.motion.record"):
        try:
            processed = processed_record(spec, record)
        except ValueError as error:
            raise SceneError("wave.motion.record", None, "",
                             f"scene key 'wave.motion.record': cannot process the record: {error}") from None
    if spec["pga"] is None and spec["scale"] != "after_filter":
        warnings.append(f"wave.motion.record.scale = {_show(spec['scale'])} without wave.motion.record.pga: "
                        "nothing is scaled, the record keeps its own amplitude")
    # Record time is run time: t = 0 is the window's start, the filter's lead-in runs before it.
    duration, motion = settings["time"]["duration"], float(processed.t[-1] - processed.record_start)
    if duration < motion * (1.0 - 1e-9):
        start, end = processed.window
        warnings.append(
            f"time.duration = {duration:g} s is shorter than the record's window [{start:g}, {end:g}] s = "
            f"{motion:.4g} s (record time; the run starts {processed.record_start:.3g} s earlier, at the filter's "
            "lead-in, see wave.motion.record.lead_in): the run stops before the record ends")


def _check_ricker_duration(settings: dict, warnings: list[str]) -> None:
    """A run that stops before the Ricker wavelet has passed the reference point is warned of (a
    0.1 s run of a 5 Hz wavelet centred at 0.3 s saw none of it and printed a PGA of 0.001 g)."""
    from pyfem.seismic.waveforms import ricker_end

    ricker = settings["wave"]["motion"]["ricker"]
    t0 = ricker["t0"]  # its default 1.5/f0 set by _check_wave
    end = ricker_end(ricker["f0"], t0)
    duration = settings["time"]["duration"]
    if duration < end * (1.0 - 1e-9):
        stops = "before the wavelet's peak" if duration < t0 else "before the wavelet has passed"
        warnings.append(f"time.duration = {duration:g} s is shorter than the Ricker wavelet's motion at the "
                        f"reference point (peak at t0 = {t0:.4g} s, over by t0 + 1.5/f0 = {end:.4g} s): "
                        f"the run stops {stops}")


@contextlib.contextmanager
def _python_warnings_to(warnings: list[str], key: str) -> Iterator[None]:
    """Python warnings raised in the body become one-line scene warnings about `key`."""
    import warnings as python_warnings

    with python_warnings.catch_warnings(record=True) as caught:
        python_warnings.simplefilter("always")
        yield
    for warning in caught:
        warnings.append(f"{key}: {' '.join(str(warning.message).split())}")


def _check_resolution(settings: dict, warnings: list[str]) -> None:
    """A mesh more than twice as coarse as the accuracy study's advice for a 5 % error is a warning.

    The element size is mesh.h (box) or mesh.parameters h_far (layered_cavern, the far field that
    carries the waves in); a file mesh is not checked (its size is known only once loaded).
    """
    from pyfem import accuracy

    mesh = settings["mesh"]
    if mesh["builder"] == "box":
        h, key = mesh["h"], "mesh.h"
    elif mesh["builder"] == "layered_cavern":
        from pyfem.geometry.layered_cavern import layered_cavern_parameters

        try:
            h, key = layered_cavern_parameters(mesh["parameters"] or {})["h_far"], "mesh.parameters.h_far"
        except ValueError as error:
            raise scene_error_from(error) or error
    else:
        return
    budget = 0.05
    try:
        advice = accuracy.element_size_for(settings, budget, order=mesh["order"])
    except (ValueError, FileNotFoundError):
        return  # no study for this order or budget: no advice to compare with
    if h > 2.0 * advice["h"]:
        warnings.append(
            f"{key} = {h:g} m is {h / advice['h']:.1f}x the element size the accuracy study advises for a "
            f"{100 * budget:g} % error with Q{advice['order']} elements, h <= {advice['h']:.3g} m "
            f"({advice['elements_per_wavelength']:.3g} per shortest shear wavelength "
            f"{advice['shortest_wavelength']:.4g} m at {advice['highest_frequency']:.3g} Hz): expect a larger error")


def _check_layers(settings: dict) -> None:
    """A layered box: each layer names a material table, every table is used, thicknesses sum to size z."""
    mesh = settings["mesh"]
    layers = mesh["layers"]
    materials = settings["materials"]
    for index, layer in enumerate(layers):
        if layer["material"] not in materials:
            raise SceneError(f"mesh.layers.{index}.material", layer["material"],
                             "must name a [materials] table: " + ", ".join(materials))
    used = {layer["material"] for layer in layers}
    for name in materials:
        if name not in used:
            raise SceneError(f"materials.{name}", name, "every material of a layered box must be "
                             "the material of a layer (regions are named by material)")
    total = sum(layer["thickness"] for layer in layers)
    if mesh["size"] is not None and not math.isclose(total, mesh["size"][2], rel_tol=1e-9):
        raise SceneError("mesh.layers", [layer["thickness"] for layer in layers],
                         f"layer thicknesses must sum to mesh.size z = {mesh['size'][2]:g} m (they sum to {total:g})")


def layer_interface_names(scene: dict) -> list[str]:
    """Names of the interfaces of a layered box, bottom up ("interface_1", ...); empty otherwise."""
    layers = scene["mesh"].get("layers") or []
    return [f"interface_{k}" for k in range(1, len(layers))]


def _check_time(settings: dict) -> None:
    time = settings["time"]
    if time["dt"] is not None and time["dt"] >= time["duration"]:
        raise SceneError("time.dt", time["dt"],
                         f"fixed time step must be shorter than time.duration = {time['duration']:g} s")
    if time["dt"] is not None and time["safety"] != SCHEMA.fields["time"].fields["safety"].default:
        raise SceneError("time.safety", time["safety"],
                         "not read when time.dt is given (the fixed step is used as it is, after a check "
                         "against the stable step): give time.dt or a time.safety other than the default 0.8, "
                         "not both")


def _check_wave(settings: dict) -> None:
    wave = settings["wave"]
    if wave["component"]:
        for name in ("type", "angle", "azimuth"):
            if wave[name] is not None:
                raise SceneError(f"wave.{name}", wave[name],
                                 f"give wave.{name} inside each [[wave.component]], "
                                 "not at the top level as well")
    else:
        if wave["type"] is None:
            raise _missing("wave.type", _WAVE_TYPE.allowed + " (or give [[wave.component]])")
        wave["angle"] = 0.0 if wave["angle"] is None else wave["angle"]
        wave["azimuth"] = 0.0 if wave["azimuth"] is None else wave["azimuth"]

    motion = wave["motion"]
    kinds = [kind for kind in ("ricker", "record") if kind in motion]
    if len(kinds) != 1:
        raise SceneError("wave.motion", kinds,
                         "give exactly one of wave.motion.ricker or wave.motion.record")
    if "ricker" in motion and motion["ricker"]["t0"] is None:
        motion["ricker"]["t0"] = 1.5 / motion["ricker"]["f0"]

    materials = settings["materials"]
    if wave["medium"] is None:
        if len(materials) != 1:
            raise _missing("wave.medium", "half-space material name is required when there is "
                           "more than one material: one of " + ", ".join(materials))
        wave["medium"] = next(iter(materials))
    elif wave["medium"] not in materials:
        raise SceneError("wave.medium", wave["medium"],
                         "must name a material of [materials]: " + ", ".join(materials))
    for index, layer in enumerate(wave["layers"] or []):
        if layer["medium"] not in materials:
            raise SceneError(f"wave.layers.{index}.medium", layer["medium"],
                             "must name a material of [materials]: " + ", ".join(materials))
    if wave["layers"] and wave["surface"] is None:
        raise _missing("wave.surface", "[[wave.layers]] hang from the free surface: give its z (m)")
    free_field = wave["free_field"]
    if free_field["method"] == "drm":
        if free_field["auxiliary"] is None:
            raise _missing("wave.free_field.auxiliary", "method \"drm\" records the free field on an auxiliary "
                           "scene's run: give its TOML file")
        if wave["layers"]:
            raise SceneError("wave.layers", [layer["thickness"] for layer in wave["layers"]],
                             "wave.free_field.method = \"drm\" takes the free field from the auxiliary scene: "
                             "give [[wave.layers]] there, not here")
    elif free_field["auxiliary"] is not None:
        raise SceneError("wave.free_field.auxiliary", free_field["auxiliary"],
                         "read by wave.free_field.method = \"drm\" only (method is \"half_space\")")


def _check_boundary(settings: dict) -> None:
    bounds = Scene.model_bounds(settings)  # works on the plain dict too
    if settings["boundary"]["centre"] is None and bounds is not None:
        settings["boundary"]["centre"] = list(0.5 * (bounds[0] + bounds[1]))


def _check_damping(damping: dict) -> None:
    """Fill alpha and beta; a ratio given at two frequencies is converted to them."""
    by_ratio = damping["ratio"] is not None or damping["frequencies"] is not None
    by_coefficients = damping["alpha"] is not None or damping["beta"] is not None
    if by_ratio:
        for name in ("ratio", "frequencies"):
            if damping[name] is None:
                spec = SCHEMA.fields["damping"].fields[name]
                raise _missing(f"damping.{name}", spec.allowed)
        derived = rayleigh_coefficients(damping["ratio"], *damping["frequencies"])
        given = (damping["alpha"], damping["beta"])
        # alpha/beta next to a ratio are accepted only as the values derived from
        # it (a scene written back by Scene.to_json has both).
        if by_coefficients and not all(g is not None and math.isclose(g, d, rel_tol=1e-12)
                                       for g, d in zip(given, derived)):
            raise SceneError("damping", {k: v for k, v in damping.items() if v is not None},
                             "give either ratio and frequencies, or alpha and/or beta, not both")
        damping["alpha"], damping["beta"] = derived
    elif by_coefficients:
        damping["alpha"] = damping["alpha"] or 0.0
        damping["beta"] = damping["beta"] or 0.0
    else:
        raise _missing("damping.ratio", "[damping] needs ratio and frequencies, "
                       "or alpha and/or beta")


def _check_points_inside(settings: dict) -> None:
    bounds = Scene.model_bounds(settings)
    if bounds is None:
        return
    lo, hi = bounds
    tolerance = 1e-9 * (hi - lo)
    inside = f"must lie inside the box [{', '.join(f'{x:g}' for x in lo)}] - " \
             f"[{', '.join(f'{x:g}' for x in hi)}]"
    for table in ("monitor", "pair_monitor", "bolt_monitor"):
        for index, entry in enumerate(settings[table]):
            point = np.asarray(entry["point"])
            if np.any(point < lo - tolerance) or np.any(point > hi + tolerance):
                raise SceneError(f"{table}.{index}.point", entry["point"], inside)
    top = hi[2] - tolerance[2]
    for key in ("wave", "initial_stress"):
        surface = settings.get(key, {}).get("surface")
        if surface is not None and surface < top:
            raise SceneError(f"{key}.surface", surface,
                             f"the surface must not lie below the top of the box (z = {hi[2]:g})")


def _resolve_files(settings: dict, base_dirs: Sequence[Path]) -> None:
    """Replace relative file paths by existing absolute ones.

    A relative path is looked up next to the scene file first, then in the
    current directory (the repository root, where the CLI is run from).
    """
    entries = [("mesh.file", settings["mesh"], "file")]
    record = settings.get("wave", {}).get("motion", {}).get("record")
    if record is not None:
        entries.append(("wave.motion.record.file", record, "file"))
    free_field = settings.get("wave", {}).get("free_field")
    if free_field is not None:
        entries.append(("wave.free_field.auxiliary", free_field, "auxiliary"))
    for key, table, name in entries:
        if table[name] is None:
            continue
        given = Path(table[name]).expanduser()
        candidates = [given] if given.is_absolute() else [d / given for d in base_dirs]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise SceneError(key, table[name], "no such file (looked in "
                             + ", ".join(str(c) for c in candidates) + ")")
        table[name] = str(found.resolve())


# ---------------------------------------------------------------------------
# Overrides and entry points.
# ---------------------------------------------------------------------------

_OVERRIDE_SYNTAX = "an override must read key.path=value (e.g. mesh.h=2.5, monitor.0.point=[1,2,3])"


def _parse_override(text: str) -> tuple[list[str], Any]:
    key, equals, value_text = text.partition("=")
    key = key.strip()
    parts = key.split(".")
    if not equals or not key or any(not p.strip() for p in parts):
        raise SceneError(key or text, text, _OVERRIDE_SYNTAX,
                         f"bad override {_show(text)}: {_OVERRIDE_SYNTAX}")
    value_text = value_text.strip()
    try:
        value = tomllib.loads(f"value = {value_text}")["value"]
    except tomllib.TOMLDecodeError:
        value = value_text  # a bare word: the string itself
    return [p.strip() for p in parts], value


def apply_overrides(raw: dict, overrides: Iterable[str]) -> dict:
    """A copy of the raw scene with ``key.path=value`` overrides applied.

    Values are read as TOML values when they parse as one (numbers, booleans,
    arrays, inline tables, quoted strings), otherwise as plain strings. A
    numeric path part indexes an array (``monitor.0.point=[1,2,3]``). Missing
    tables on the way are created (an override can switch an effect on).

    Raises:
        SceneError: bad syntax, or a path through a value that is not a table/array.
    """
    raw = copy.deepcopy(raw)
    for text in overrides:
        parts, value = _parse_override(text)
        node: Any = raw
        for depth, part in enumerate(parts):
            here = ".".join(parts[:depth + 1])
            last = depth == len(parts) - 1
            if isinstance(node, list):
                if not part.isdigit() or int(part) >= len(node):
                    raise SceneError(here, text, f"index must be 0..{len(node) - 1} "
                                                 f"for an array of {len(node)}")
                if last:
                    node[int(part)] = value
                else:
                    node = node[int(part)]
            elif isinstance(node, dict):
                if last:
                    node[part] = value
                else:
                    node = node.setdefault(part, {})
            else:
                parent = ".".join(parts[:depth])
                raise SceneError(parent, node, f"'{parent}' is not a table; cannot set {here}")
    return raw


def parse_scene(data: dict, source: str = "<dict>", overrides: Iterable[str] = (),
                base_dir: str | Path | None = None) -> Scene:
    """Validate a scene given as a dict (as read from TOML).

    Args:
        data: The raw scene. ``None`` values count as absent keys.
        source: Where it came from, for messages and `Scene.source`.
        overrides: ``"key.path=value"`` strings applied before validation.
        base_dir: Directory relative file paths are looked up in first
            (then the current directory). Default: the current directory.

    Returns:
        The validated `Scene`.

    Raises:
        SceneError: naming the first offending key.
    """
    base_dirs = [Path.cwd()] if base_dir is None else [Path(base_dir), Path.cwd()]
    warnings: list[str] = []
    try:
        raw = apply_overrides(data, overrides)
        settings = one_step_form(SCHEMA.check(raw, ""), raw)
        _check_rules(settings, base_dirs, warnings)
    except SceneError as error:
        error.source = str(source)
        raise
    return Scene(settings, str(source), warnings)


_KEY_AT_START = re.compile(r"^(?P<key>(?:%s)(?:\.[A-Za-z0-9_-]+)*)(?P<rest>(?: = |: ).*)$"
                           % "|".join(re.escape(name) for name in SCHEMA.fields), re.DOTALL)


def scene_error_from(error: ValueError) -> SceneError | None:
    """The SceneError a ValueError stands for when its message starts with a scene key.

    Builders and readers deeper down (pyfem.geometry, pyfem.mesh, pyfem.interfaces) report bad
    input as ``ValueError("mesh.parameters.h_far = 3.0: must be >= ...")``. Such an error is the
    user's, and becomes ``scene key 'mesh.parameters.h_far' = 3.0: must be >= ...``. Any other
    ValueError is a bug and gives ``None`` (the caller re-raises it).
    """
    if isinstance(error, SceneError):
        return error
    text = " ".join(str(error).split())  # one line
    match = _KEY_AT_START.match(text)
    if match is None:
        return None
    key = match.group("key")
    return SceneError(key, None, match.group("rest").lstrip(" =:"), f"scene key '{key}'{match.group('rest')}")


def load_scene(path: str | Path, overrides: Iterable[str] = ()) -> Scene:
    """Read, override and validate a scene file.

    Args:
        path: The TOML scene file.
        overrides: ``"key.path=value"`` strings (see `apply_overrides`).

    Returns:
        The validated `Scene` with ``source`` = `path`.

    Raises:
        FileNotFoundError: the scene file does not exist.
        SceneError: the file cannot be read or is not TOML (message names file and line), or a
            key is wrong.
    """
    path = Path(path)
    try:
        with open(path, "rb") as stream:
            text = stream.read()
    except FileNotFoundError:
        raise
    except OSError as error:  # a directory, no permission
        scene_error = SceneError(None, str(path), "a readable TOML file",
                                 f"{path}: cannot read the scene file ({error.strerror or error})")
        scene_error.source = str(path)
        raise scene_error from None
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        scene_error = SceneError(None, None, "valid TOML", f"{path}: not valid TOML: {error}")
        scene_error.source = str(path)
        raise scene_error from None
    return parse_scene(data, source=str(path), overrides=overrides, base_dir=path.parent)

"""The scene-key reference, docs/scene-keys.md, generated from the schema of `pyfem.scene`.

`reference` walks `pyfem.scene.SCHEMA` and writes one markdown table per scene table: every
key with its full dotted path (``NAME`` stands for the name of a named table such as
``[materials.rock]``, ``0`` for the index of an entry of an array of tables such as
``[[monitor]]``), its type, unit, default, allowed values, whether a scene must give it, and
what it is. Units come from the schema's descriptions, which carry them in parentheses:
"(Pa)", "(m)", "(s)", "(deg)".

What the schema cannot say is written here by hand, next to the generator: the conditional
rules that live in code (`pyfem.scene._check_rules`) in `RULES`, what a key left unset means
(its default is computed from other keys, or it switches something off) in `UNSET`, what an
optional table switches on besides the effects of `pyfem.scene.EFFECT_ORDER` in `SWITCHES`,
and the numbers without a unit in `DIMENSIONLESS`. tests/test_scene_keys.py checks that each
entry names a key that exists, that every key has what it needs, and that the document is the
one this module writes: a key added to the schema fails that test until the document is
regenerated (and, where needed, an entry is added here).

    /usr/bin/python3 -m pyfem keys            # print the reference
    /usr/bin/python3 -m pyfem keys --write    # rewrite docs/scene-keys.md

The wave conventions (`WAVE_CONVENTIONS`) are checked against `pyfem.seismic.freefield` by the
same test file; their figure, docs/wave-conventions.png, is drawn by
workflows/wave_conventions.py from the free field itself.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Iterator

from pyfem import scene as scene_module
from pyfem.scene import (REQUIRED, SCHEMA, Choice, FilePath, Flag, FreeTable, Interval, Number,
                         Scene, Table, TableList, TableMap, Text, TextList, Vector, VectorList)

DOCUMENT = Path("docs") / "scene-keys.md"
"""Where the reference lives, relative to the repository root."""

WRITE_COMMAND = "/usr/bin/python3 -m pyfem keys --write"
"""The command that regenerates `DOCUMENT` (run from the repository root)."""

# A unit in a description: "(Pa)", "(m; ...)", "(Pa, compression negative)".
_UNIT = re.compile(r"\((Pa|m|s|deg|Hz|kg/m\^3|N/m\^2|N/m|N|m/s|1/s|g)[;,:)]")

DIMENSIONLESS = (
    "materials.NAME.nu",
    "materials.NAME.plasticity.damage_max",
    "materials.NAME.plasticity.damage_plastic_strain",
    "materials.NAME.damage.A_t",
    "materials.NAME.damage.B_t",
    "materials.NAME.damage.A_c",
    "materials.NAME.damage.B_c",
    "materials.NAME.damage.stiffness_recovery",
    "materials.NAME.damage.damage_max",
    "time.safety",
    "wave.scale",
    "wave.component.0.scale",
    "boundary.alpha_N",
    "boundary.alpha_T",
    "damping.ratio",
    "initial_stress.k",
    "static.relaxation",
    "static.step.0.relaxation",
    "static.tolerance",
    "static.max_steps",
    "contact.deterioration.R0",
    "contact.deterioration.lambda",  # eta = R0 + (1 - R0) exp(-lambda t / t_s)
    "contact.deterioration.m",       # gamma = m (|dv_t| + n)^(-p), the paper's constant
    "contact.deterioration.p",
)
"""Numbers whose description carries no unit because they have none."""

UNSET = {
    "mesh.size": "none; required by builder \"box\"",
    "mesh.h": "none; required by builder \"box\"",
    "mesh.file": "none; required by builder \"file\"",
    "mesh.layers": "none: one region, rock",
    "mesh.parameters": "the \"coarse\" preset (builder \"layered_cavern\", below)",
    "materials.NAME.preset": "none",
    "materials.NAME.E": "the preset's; required without a preset",
    "materials.NAME.nu": "the preset's; required without a preset",
    "materials.NAME.rho": "the preset's; required without a preset",
    "materials.NAME.plasticity.cohesion": "the preset's (the paper's Table 1); required without a preset",
    "materials.NAME.plasticity.friction_angle": "the preset's; required without a preset",
    "materials.NAME.plasticity.tensile_strength": "the preset's; required without a preset",
    "materials.NAME.plasticity.mean_dilatation": "true for `mesh.order` = 1, false for 2",
    "materials.NAME.plasticity.damage_plastic_strain": "none: without damage (`materials.NAME.plasticity.damage_max` = 0) "
                                                       "it scales nothing; with damage it or "
                                                       "`materials.NAME.plasticity.damage_plastic_displacement` is required",
    "materials.NAME.damage.cohesion": "the preset's (the paper's Table 1); required without a preset",
    "materials.NAME.damage.friction_angle": "the preset's; required without a preset",
    "materials.NAME.damage.tensile_strength": "the preset's; required without a preset",
    "time.dt": "`time.safety` x the critical step the program computes",
    "wave.type": "none; required unless `wave.component` is given",
    "wave.angle": "0 (vertical incidence)",
    "wave.azimuth": "0 (propagation towards +x)",
    "wave.surface": "none: no free surface, the incident wave alone",
    "wave.medium": "the scene's only material; required with more than one",
    "wave.reference_point": "per incident wave, the model corner its wavefront reaches first",
    "wave.layers": "none: the free field of the homogeneous half-space of `wave.medium`",
    "wave.free_field.auxiliary": "none; required by method \"drm\"",
    "wave.motion.ricker.t0": "1.5 / f0",
    "wave.motion.record.dt": "from the file (time column or header); required when the file does not give it",
    "wave.motion.record.pga": "the record's own peak",
    "wave.motion.record.window": "the whole record",
    "wave.motion.record.lead_in": "from where the filter's precursor exceeds 1e-3 of the peak",
    "boundary.faces": "surfaces named xmin .. zmax, else the exterior facets on the bounding-box planes",
    "boundary.face": "every truncation face has `boundary.type`",
    "boundary.centre": "the centre of the model's bounding box",
    "damping.ratio": "none; with `damping.frequencies`, or give `damping.alpha` / `damping.beta`",
    "damping.frequencies": "none; with `damping.ratio`",
    "damping.alpha": "from ratio and frequencies, else 0",
    "damping.beta": "from ratio and frequencies, else 0",
    "initial_stress.surface": "none; required by the geostatic form",
    "initial_stress.rho": "none; required by the geostatic form",
    "initial_stress.stress": "none: the geostatic form",
    "static.boundary.face": "every truncation face has `static.boundary.type`",
    "static.step": "none: the one-step form (`static.excavate`, `static.relaxation`, `static.install`, `static.support`)",
    "materials.NAME.plasticity.zone": "the whole region",
    "static.tolerance": "1e-8 for the linear solve (relative residual), 1e-5 for dynamic relaxation "
                        "(out-of-balance force ratio)",
    "contact.dynamic_friction_angle": "= `contact.friction_angle`",
    "contact.tensile_strength": "= `contact.cohesion`",
    "support": "none: no rock support",
    "support.NAME.lines": "none; give `support.NAME.lines` or the pattern `support.NAME.surface`, "
                          "`support.NAME.spacing` and `support.NAME.length`",
    "support.NAME.surface": "none; with `support.NAME.spacing` and `support.NAME.length`: a pattern",
    "support.NAME.spacing": "none; required by a pattern",
    "support.NAME.length": "none; required by a pattern",
    "support.NAME.segment": "about the size of the cells the bolt crosses (their nodes' spacing along x, y, z)",
    "bolt_monitor.0.group": "none: the segments of every group",
    "contact.release_time": "off: a broken bond's strength goes in one step (nothing to compute; "
                            "docs/method.md section 9, \"Releasing a broken bond\")",
}
"""What a key whose schema default is None means when the scene leaves it out."""

RULES = {
    "mesh": [
        "builder \"box\" needs `mesh.size` and `mesh.h`; only it reads `mesh.origin` and `mesh.layers`, "
        "and it takes no `mesh.parameters`",
        "builder \"file\" needs `mesh.file` and refuses `mesh.size`, `mesh.h`, `mesh.origin`, "
        "`mesh.parameters`",
        "builder \"layered_cavern\" reads `mesh.parameters` and refuses `mesh.size`, `mesh.h`, `mesh.origin`",
    ],
    "mesh.layers.0": [
        "each `mesh.layers.0.material` names a table of `materials`, every material is some layer's, "
        "and the thicknesses sum to `mesh.size` z; the interfaces are named interface_1, interface_2, ... "
        "bottom up",
    ],
    "materials.NAME": [
        "`materials.NAME.E`, `materials.NAME.nu` and `materials.NAME.rho` are given or come from "
        "`materials.NAME.preset` (given keys win)",
        "E outside [1e7, 3e11] Pa and rho below 500 kg/m^3 are refused as unit slips "
        "(the message says which unit it looks like); rho above 8000 kg/m^3 is a warning",
        "builder \"box\" without layers has one region, rock: the only material is `[materials.rock]`",
        "at most one of `materials.NAME.plasticity` and `materials.NAME.damage`",
    ],
    "materials.NAME.plasticity": [
        "`materials.NAME.plasticity.dilation_angle` <= `materials.NAME.plasticity.friction_angle`",
        "`materials.NAME.plasticity.cohesion` > 0 when the friction angle is 0",
        "a strength in (0, 100) Pa is refused (a value in MPa written as Pa); 0 means none",
        "without `materials.NAME.plasticity.damage_max` (0) the rock is perfectly plastic; "
        "`materials.NAME.plasticity.damage_max` > 0 (softening) needs its scale, "
        "`materials.NAME.plasticity.damage_plastic_strain` or the crack band's "
        "`materials.NAME.plasticity.damage_plastic_displacement` > 0, not both; a crack band needs "
        "`materials.NAME.plasticity.damage_max` > 0",
    ],
    "materials.NAME.damage": [
        "`materials.NAME.damage.A_t` = 1 when `materials.NAME.damage.fracture_energy` > 0",
        "`materials.NAME.damage.B_t` >= E / `materials.NAME.damage.tensile_strength` when "
        "`materials.NAME.damage.fracture_energy` > 0",
        "a strength below 100 Pa is refused (a value in MPa written as Pa)",
    ],
    "time": [
        "`time.dt` < `time.duration`",
        "with `time.dt` a fixed step is used as given, after a check against the stable step, and "
        "`time.safety` is not read: a `time.safety` other than its default 0.8 beside `time.dt` is refused "
        "(the default may stay written, as the shipped scenes write it)",
    ],
    "wave": [
        "either `wave.type` (with `wave.angle`, `wave.azimuth`) or `wave.component`, not both",
        "`wave.medium` names a table of `materials`",
        "`wave.surface` not below the model top (its highest mesh node; for builders \"file\" and "
        "\"layered_cavern\" checked once the mesh is read, the message giving the top z)",
        "at least one truncation face must be viscoelastic or viscous (they carry the input)",
        "a mesh more than twice as coarse as the accuracy study advises for 5 % error at the wave's "
        "highest frequency is a warning (`pyfem check` prints the advice)",
    ],
    "wave.motion": [
        "exactly one of `wave.motion.ricker` and `wave.motion.record`",
    ],
    "wave.motion.record": [
        "`wave.motion.record.file` is looked up next to the scene, then in the current directory",
        "`wave.motion.record.window` lies inside the record",
        "`wave.motion.record.scale` other than \"after_filter\" without `wave.motion.record.pga` is a "
        "warning (nothing is scaled); `pyfem check` prints the raw record's peak, the window's raw peak "
        "and the processed motion's PGA, PGV and PGD",
        "a `time.duration` shorter than the window is a warning (record time: t = 0 is the window's start; the lead-in runs at t < 0)",
    ],
    "damping": [
        "`damping.ratio` with `damping.frequencies` (converted to alpha, beta), or `damping.alpha` "
        "and/or `damping.beta` (the other 0), not both",
    ],
    "initial_stress": [
        "geostatic form: `initial_stress.surface`, `initial_stress.rho` (and `initial_stress.k`); "
        "uniform form: `initial_stress.stress`; not both",
        "`initial_stress.surface` not below the model top (its highest mesh node; for builders \"file\" and "
        "\"layered_cavern\" checked once the mesh is read, the message giving the top z)",
        "initial stresses beyond a nonlinear material's strength are a warning (returned to it at t = 0)",
    ],
    "static": [
        "needs a load: an `initial_stress` table or `static.gravity` = true",
        "`static.support` names groups of `support`, installed with `static.install`; a group not listed is "
        "installed at the start of the dynamic run; a stage with support is solved by dynamic relaxation "
        "(`static.solver` \"direct\" and \"iterative\" refuse it)",
        "a region is in `static.excavate` or in `static.install`, not both",
        "`static.step` entries or the one-step keys `static.excavate`, `static.relaxation`, `static.install`, "
        "`static.support`, not both; one entry is the one-step form",
    ],
    "static.step.0": [
        "each step excavates at least one region; a region is excavated or installed once in a sequence",
        "a region excavated after the first step is linear elastic (its `materials.NAME` table has no "
        "`materials.NAME.plasticity` or `materials.NAME.damage`)",
        "linear elastic `static.step.0.install` regions in one step only (in other steps they have a law)",
        "an install region touches no region a later step excavates (checked once the model is built)",
        "`static.step.0.support` names groups of `support`, each installed in one step",
        "a sequence of several steps is solved by dynamic relaxation (`static.solver` \"relaxation\" or "
        "\"auto\"); `contact` in it is not written yet (refused)",
    ],
    "contact": [
        "in a layered box, `contact.interfaces` are interface_1, interface_2, ... (bottom up)",
        "a strength in (0, 100) Pa is refused (a value in MPa written as Pa); 0 means none",
    ],
    "monitor.0": [
        "`monitor.0.point` inside the box (builder \"box\")",
    ],
    "support.NAME": [
        "either `support.NAME.lines` or the pattern `support.NAME.surface`, `support.NAME.spacing`, "
        "`support.NAME.length`, not both",
        "the pattern: rows every `support.NAME.spacing` [1] m along the surface's axis (the direction its "
        "normals are perpendicular to), bolts every `support.NAME.spacing` [0] m of arc length around each row's "
        "section, each normal to the surface into the rock (away from `static.install` regions)",
        "type \"bolt\": `support.NAME.pretension` = 0 and `support.NAME.free_length` = 0; "
        "a pretension needs a free length and at most `support.NAME.yield_force`",
        "`support.NAME.free_length` and `support.NAME.segment` shorter than the shortest bolt",
        "every bolt node lies in a cell of the model (not outside it, not in an excavated region); "
        "checked once the mesh is built",
        "`support.NAME.surface` names a surface of the mesh",
        "refused under mpirun and with `time.local_stepping` = true (\"auto\" is off)",
    ],
    "pair_monitor.0": [
        "needs a `contact` table",
        "`pair_monitor.0.point` inside the box (builder \"box\")",
    ],
    "bolt_monitor.0": [
        "needs a `support` table; `bolt_monitor.0.group` names one of its groups (none given: every group's "
        "segments)",
        "`bolt_monitor.0.point` inside the box (builder \"box\")",
    ],
    "output": [
        "`output.fields` other than the default with `output.xdmf_interval` = 0 is a warning (no fields "
        "written); \"damage\" without a nonlinear material is a warning (zero everywhere)",
    ],
}
"""Conditional rules per table (dotted path, as in the document), written from
`pyfem.scene._check_rules` and the checks it calls."""

EFFECTS = {
    "seismic_input": "plane P/SV/SH waves enter as equivalent nodal forces on the viscoelastic and "
                     "viscous truncation faces; monitors also record the exact free field",
    "damping": "Rayleigh damping C = alpha M + beta K",
    "initial_stress": "an initial stress state: the run solves for the increment over it; contact "
                      "strength and reported stresses use the total",
    "contact": "the listed interfaces are split into node pairs with bond, Coulomb slip, "
               "separation and re-contact",
    "deterioration": "the interface strength decays as D(t) = eta(t) gamma(slip rate) "
                     "(the paper's Eqs. 8-11)",
}
"""What each effect of `pyfem.scene.EFFECT_ORDER` does."""

SWITCHES = {
    "materials.NAME.plasticity": "the region's cells leave the stiffness matrix for the kernel's element "
                                 "loop: perfectly plastic Mohr-Coulomb with tension cut-off, softening "
                                 "plastic-strain damage only with `materials.NAME.plasticity.damage_max` > 0 "
                                 "(docs/materials.md)",
    "materials.NAME.damage": "the region's cells leave the stiffness matrix for the kernel's element "
                             "loop: the paper's concrete damage (Eq. 21) with crack band (docs/materials.md)",
    "wave.motion.ricker": "the input motion g(t) is a Ricker wavelet",
    "wave.motion.record": "the input motion g(t) is a processed accelerogram",
    "static": "a static stage before the dynamic run: excavation, relaxation, support "
              "(docs/static.md)",
    "contact.normal_lag": "the friction sees an effective normal force N* that follows N with a lag, "
                          "dN*/dt = -(slip rate + velocity) / length (N* - N) (Prakash-Clifton; "
                          "docs/interface_slip_accuracy.md)",
}
"""What an optional table switches on when it is no effect of `EFFECT_ORDER`."""

PURPOSE = {
    "mesh": "the model's geometry and elements",
    "mesh.layers.0": "one horizontal layer of a box, bottom up; regions and interfaces are named after them",
    "materials.NAME": "the material of one region, named as the mesh's region (physical volume)",
    "materials.NAME.plasticity": "rock: perfectly plastic Mohr-Coulomb with tension cut-off; softening damage "
                                 "if asked (`materials.NAME.plasticity.damage_max` > 0)",
    "materials.NAME.damage": "lining concrete: the paper's damage law (Eq. 21) with crack band",
    "time": "duration and time step",
    "wave": "seismic input: incident plane waves under a free surface (see Wave conventions)",
    "wave.component.0": "one of several incident plane waves, superposed",
    "wave.free_field": "where the free field comes from: the closed form on the truncation faces or the domain-reduction method (docs/boundaries.md, \"Dipping layers\")",
    "wave.layers.0": "one horizontal layer of the free field's site, top down from `wave.surface` (docs/method.md, \"Layered free field\")",
    "wave.motion": "the input motion g(t): the incident wave's displacement at the reference point",
    "wave.motion.ricker": "a Ricker wavelet (displacement)",
    "wave.motion.record": "an accelerogram, processed as in docs/method.md section 7",
    "boundary": "the truncation faces, where the model is cut out of the earth (docs/boundaries.md)",
    "boundary.face.NAME": "the boundary type of one truncation face",
    "monitor.0": "a point whose histories go to monitors/NAME.csv",
    "output": "what is written, and how often",
    "parallel": "how the ranks of `mpirun -n N python3 -m pyfem run` hold the model (docs/scaling.md)",
    "damping": "Rayleigh damping",
    "initial_stress": "the initial stress: geostatic or uniform",
    "static": "a static stage before the dynamic run (docs/static.md)",
    "static.step.0": "one step of an excavation sequence, in order (benches top down; docs/static.md, "
                     "\"An excavation sequence\")",
    "static.boundary": "the truncation faces during the static stage",
    "static.boundary.face.NAME": "the type of one truncation face during the static stage",
    "contact": "contact on the named interfaces (docs/method.md section 9)",
    "contact.deterioration": "the decay of the interfaces' strength, with time from the record window's start "
                             "whether or not they shear (docs/method.md section 9; R0 = 1: no wear)",
    "contact.normal_lag": "the lag of the normal force the friction sees (regularises sliding between "
                          "dissimilar rocks)",
    "support.NAME": "a group of rock bolts or anchor cables: axial bars tied to the rock by their grout "
                    "(docs/method.md, \"Rock bolts and cables\")",
    "pair_monitor.0": "the contact pair nearest a point, its histories in pairs/NAME.csv",
    "bolt_monitor.0": "the bolt segment nearest a point, its axial force and bond slip histories in bolts/NAME.csv",
}
"""What each table is for (its description in the schema is only its name)."""

LAYERED_CAVERN_DERIVED = {"h_near": "lining_wall / lining_elements",
                          "layer_reference_z": "floor_z + height / 2"}
"""The parameters of builder "layered_cavern" whose default is computed from others."""

LAYERED_CAVERN_NOTE = ("Lengths in m, `dip` in deg; `preset` picks the extents and element sizes "
                       "(\"coarse\" or \"paper\"), given keys win; `materials` here only sizes the time-step "
                       "estimate (the run uses the scene's `materials`). `internal_concrete = true` adds region "
                       "\"internal_concrete\" (machine piers, turbine and generator floor slabs, wind covers; "
                       "dimensions: `INTERNAL_CONCRETE` in `pyfem/geometry/layered_cavern.py`, our assumption, "
                       "docs/case_study.md) for the scene to give a material and to install with the lining; "
                       "its grid lines refine the whole mesh, so the default (false) keeps the old mesh.")

WAVE_CONVENTIONS = """\
## Wave conventions

![Wave conventions](wave-conventions.png)

*Drawn by `workflows/wave_conventions.py` from `pyfem.seismic.freefield` (the same code that
makes the input): left, the vertical plane of propagation for SV at 30 deg; middle, the plan
view for azimuth 30 deg; right, the input motion g(t) against the total motion for vertical SV.*

Axes: z up; in the case study x across the cavern, y along its axis. The details, with the
reflection coefficients and post-critical incidence: [method.md](method.md) sections 6 and 7.

- **`wave.angle`** θ: the angle of the propagation direction from the vertical,
  0 <= θ < 90 deg; 0 is vertical incidence. (The paper's α, between wavefront and horizontal,
  is the same angle.)
- **`wave.azimuth`** φ: the direction of the horizontal part of the propagation, from +x
  towards +y: e_h = (cos φ, sin φ, 0). Waves travel **upwards** along
  k = sin θ e_h + cos θ e_z: with φ = 0 and θ > 0 a wave arrives from below on the -x side and
  moves towards +x and up.
- **Polarisations** of the incident wave (the displacement direction for positive g), with
  e_t = e_z x e_h:

  | type | polarisation d | at θ = 0, φ = 0 |
  |---|---|---|
  | P | k, along the propagation | +z |
  | SV | cos θ e_h - sin θ e_z, in the vertical plane of k, towards +e_h | +x |
  | SH | e_t, horizontal, perpendicular to k | +y |

- **The motion g(t)** (`wave.motion`, scaled by `wave.scale` and each component's `scale`) is
  the displacement of the *incident* wave alone at the **reference point** x0: the incident
  wave moves as u = d g(t - k.(x - x0)/c). A record's acceleration (after processing, scaled to
  `pga`) is g''. It is neither the motion at the free surface nor the total motion at x0: those
  add the reflected waves (near the surface and for long periods about twice the incident
  motion at vertical incidence, right panel).
- **Reference point**: by default, per incident wave, the corner of the model's bounding box
  that its wavefront reaches first (the smallest k.x), so no node has a negative delay and
  every node starts at rest; `wave.reference_point` puts it elsewhere (the paper: the model
  origin), with a warning when that cuts off more than 1e-3 of the input's peak somewhere on
  the boundary.
- **Free surface** `wave.surface`: the z of a horizontal traction-free surface at or above the
  model top. The free field is the incident wave plus its reflections there (P and SV convert
  into each other; SH reflects as SH; beyond the critical angle of SV the reflected P is
  evanescent). Without `wave.surface`, the incident wave alone (a full space).
- **Several waves**: `wave.component` (`[[wave.component]]`) superposes incident waves, each
  with its own `type`, `angle`, `azimuth` and `scale` on the common motion g, e.g. the paper's
  SV with the record plus P with 2/3 of it, both at θ = 30 deg, φ = 0.
"""
"""The wave conventions section (checked against pyfem.seismic by tests/test_scene_keys.py)."""


# ---------------------------------------------------------------------------
# Walking the schema.
# ---------------------------------------------------------------------------

def _sub_table(spec: Any) -> tuple[Table | None, str]:
    """The table a spec opens and the placeholder its entries add to the path."""
    if isinstance(spec, Table):
        return spec, ""
    if isinstance(spec, TableMap):
        return spec.entry, "NAME"
    if isinstance(spec, TableList):
        return spec.entry, "0"
    return None, ""


def tables(spec: Table = SCHEMA, path: str = "") -> Iterator[tuple[str, Table]]:
    """Every table of the schema as (dotted path, Table), depth first in schema order; the root is ""."""
    yield path, spec
    for name, sub in spec.fields.items():
        table, placeholder = _sub_table(sub)
        if table is not None:
            key = f"{path}.{name}" if path else name
            yield from tables(table, f"{key}.{placeholder}" if placeholder else key)


def schema_keys() -> list[str]:
    """Every key the schema accepts, as dotted paths with NAME / 0 placeholders."""
    return [f"{path}.{name}" if path else name for path, table in tables() for name in table.fields]


def key_specs() -> dict[str, Any]:
    """Dotted path -> spec of every key of the schema."""
    return {f"{path}.{name}" if path else name: spec
            for path, table in tables() for name, spec in table.fields.items()}


def unit(path: str, spec: Any) -> str | None:
    """The unit of a number or vector key from its description, "-" for `DIMENSIONLESS`, "" for
    keys that are not numbers; None for a number with neither (a defect: tests fail)."""
    if not isinstance(spec, (Number, Vector, VectorList)):
        return ""
    found = _UNIT.search(spec.description)
    if found:
        return found.group(1)
    return "-" if path in DIMENSIONLESS else None


def effects_switched_by(path: str) -> list[str]:
    """The effects of `EFFECT_ORDER` that the optional table at `path` switches on, asked of
    `pyfem.scene.Scene` itself (its effects follow the presence of tables)."""
    parts = path.split(".")

    def nested(parts: list[str]) -> dict:
        settings: dict = {}
        node = settings
        for part in parts:
            node = node.setdefault("name" if part == "NAME" else part, {})
        return settings

    with_table = Scene(nested(parts), "<keys>").effects
    without = Scene(nested(parts[:-1]), "<keys>").effects
    return [effect for effect in with_table if effect not in without]


def optional_tables() -> list[str]:
    """Paths of the tables whose presence switches something on (presence "optional")."""
    specs = key_specs()
    return [path for path, spec in specs.items() if isinstance(spec, Table) and spec.presence == "optional"]


# ---------------------------------------------------------------------------
# The document.
# ---------------------------------------------------------------------------

def _value(value: Any) -> str:
    """A default as it would be written in a scene, floats short (4/3 -> 1.33333)."""
    if isinstance(value, float):
        if value != 0.0 and not 1.0e-3 <= abs(value) < 1.0e5:
            return scene_module._scientific(value)  # 8.0e9, 1.0e-8
        text = repr(value)
        return text if len(text) <= 9 else f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + "}"
    return scene_module._show(value)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _type(spec: Any) -> str:
    if isinstance(spec, Number):
        return "number"
    if isinstance(spec, Vector):
        return f"{spec.length} numbers"
    if isinstance(spec, VectorList):
        return f"array of {spec.length}-number arrays"
    if isinstance(spec, Choice):
        if any(isinstance(o, bool) for o in spec.options):
            return "boolean or " + " or ".join(scene_module._show(o) for o in spec.options if not isinstance(o, bool))
        return "integer" if all(isinstance(o, int) for o in spec.options) else "string"
    if isinstance(spec, FilePath):
        return "file path"
    if isinstance(spec, Text):
        return "string"
    if isinstance(spec, Flag):
        return "boolean"
    if isinstance(spec, TextList):
        return "array of strings"
    if isinstance(spec, FreeTable):
        return "table"
    if isinstance(spec, Table):
        return "table" + (f" or string (= {{{spec.shorthand} = ...}})" if spec.shorthand else "")
    if isinstance(spec, TableMap):
        return "tables by name"
    if isinstance(spec, TableList):
        return "array of tables"
    raise TypeError(f"no type name for {type(spec).__name__}")


def _allowed(spec: Any) -> str:
    if isinstance(spec, Number):
        return Interval(spec.interval).condition() or "any finite number"
    if isinstance(spec, Vector):
        condition = Interval(spec.interval).condition()
        text = f"each {condition}" if condition else "finite"
        return text + (", increasing" if spec.increasing else "")
    if isinstance(spec, Choice):
        return ", ".join(scene_module._show(o) for o in spec.options)
    if isinstance(spec, VectorList):
        return "non-empty; finite"
    if isinstance(spec, Text) and spec.filename_safe:
        return "letters, digits, _ . -"
    if isinstance(spec, Text):
        return "non-empty"
    if isinstance(spec, Flag):
        return "true, false"
    if isinstance(spec, TextList):
        parts = ["non-empty"] if spec.non_empty else []
        if spec.options:
            parts.append("from " + ", ".join(scene_module._show(o) for o in spec.options))
        parts.append("no repeats")
        return "; ".join(parts)
    if isinstance(spec, TableMap):
        return "at least one; names of letters, digits, _ . -"
    if isinstance(spec, TableList):
        return "names unique" if "name" in spec.entry.fields else "any number"
    return "see below"  # a table or free table: its own section


def _default_and_required(path: str, spec: Any) -> tuple[str, str]:
    if isinstance(spec, Table):
        return {"filled": ("all defaults", "no"), "optional": ("absent: off", "no"),
                "required": ("", "yes")}[spec.presence]
    if isinstance(spec, TableMap):
        return ("", "yes") if spec.default is REQUIRED else (UNSET.get(path, "none"), "no")
    default = spec.default
    if default is REQUIRED:
        return "", "yes"
    if default is None:
        return UNSET.get(path, "none"), "no"
    if default == [] and isinstance(spec, TableList):
        return "none", "no"
    return _value(default), "no"


def switched_on(path: str) -> str:
    """What the optional table at `path` switches on, in words."""
    switched = [f"**{effect}**: {EFFECTS.get(effect, '(not described: add it to EFFECTS)')}"
                for effect in effects_switched_by(path)]
    if path in SWITCHES:
        switched.append(SWITCHES[path])
    return "; ".join(switched)


def _meaning(path: str, spec: Any) -> str:
    if _sub_table(spec)[0] is not None:
        text = PURPOSE.get(_table_path(path, spec), spec.description)
    else:
        # The unit has its own column: "box size (m)" -> "box size".
        text = _UNIT.sub(lambda m: "" if m.group(0).endswith(")") else "(", spec.description)
        text = text.replace(" ()", "").replace("( ", "(").replace("(; ", "(").strip()
    if isinstance(spec, Table) and spec.presence == "optional":
        effects = effects_switched_by(path)
        text += f"; switches on {', '.join(f'**{e}**' for e in effects)}" if effects else "; present: on"
    return text


def _anchor(path: str) -> str:
    return "key-" + re.sub(r"[^a-z0-9]+", "-", path.lower()).strip("-")


def _section(path: str, table: Table) -> list[str]:
    title = f"`{path}`" if path else "The scene (top level)"
    path_anchor = _anchor(path) if path else "key-top-level"
    lines = [f'### <a id="{path_anchor}"></a>{title}', ""]
    spec = key_specs().get(path.removesuffix(".0").removesuffix(".NAME")) if path else None
    if spec is not None:
        what = PURPOSE.get(path, spec.description)
        what = what[0].upper() + what[1:]
        if isinstance(spec, TableList):
            what += f"; written `[[{path.removesuffix('.0')}]]`, any number of them"
        elif isinstance(spec, TableMap):
            what += f"; written `[{path.replace('NAME', 'name')}]`, one per name"
        elif spec.presence == "optional":
            what += f"; absent: off; present: {switched_on(path)}"
        else:
            what += {"filled": "; absent: all defaults", "required": "; required"}[spec.presence]
        lines += [what + ".", ""]
    if path in RULES:
        lines += ["Rules: " + "; ".join(RULES[path]) + ".", ""]
    if table.not_read:
        reasons: dict[str, list[str]] = {}
        for name, reason in table.not_read.items():
            reasons.setdefault(reason, []).append(f"`{name}`")
        for reason, names in reasons.items():
            lines += [f"Refused with a reason: {', '.join(names)}: {reason}.", ""]
    lines += ["| key | type | unit | default | allowed | required | meaning |",
              "|---|---|---|---|---|---|---|"]
    for name, sub in table.fields.items():
        key = f"{path}.{name}" if path else name
        if _sub_table(sub)[0] is not None or isinstance(sub, FreeTable):  # a section of its own
            shown = f"[`{key}`](#{_anchor(_table_path(key, sub))})"
        else:
            shown = f"`{key}`"
        default, required = _default_and_required(key, sub)
        cells = (shown, _type(sub), unit(key, sub) or "", default, _allowed(sub), required,
                 _meaning(key, sub))
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return lines + [""]


def _table_path(key: str, spec: Any) -> str:
    placeholder = _sub_table(spec)[1]
    return f"{key}.{placeholder}" if placeholder else key


def _layered_cavern_section() -> list[str]:
    from pyfem.geometry.layered_cavern import COMMON_PARAMETERS, PARAMETER_KEYS, PRESETS

    heading = f'### <a id="{_anchor("mesh.parameters")}"></a>`mesh.parameters` of builder "layered_cavern"'
    lines = [heading, "",
             "Checked by `pyfem.geometry.layered_cavern.layered_cavern_parameters` (the file builder takes "
             "no parameters). " + LAYERED_CAVERN_NOTE, "",
             "| key | preset \"coarse\" (default) | preset \"paper\" |", "|---|---|---|"]
    for name in PARAMETER_KEYS:
        if name == "preset":
            coarse, paper = _value("coarse"), _value("paper")
        elif name in PRESETS["coarse"]:
            coarse, paper = _value(PRESETS["coarse"][name]), _value(PRESETS["paper"][name])
        else:
            value = COMMON_PARAMETERS[name]
            coarse = paper = LAYERED_CAVERN_DERIVED.get(name, "derived") if value is None else _value(value)
        lines.append(f"| `mesh.parameters.{name}` | {_cell(coarse)} | {_cell(paper)} |")
    return lines + [""]


def reference() -> str:
    """The whole reference as markdown (the content of docs/scene-keys.md)."""
    lines = [
        "# Scene keys",
        "",
        f"<!-- Generated from pyfem/scene.py by pyfem/scene_keys.py: do not edit; regenerate with "
        f"`{WRITE_COMMAND}`. -->",
        "",
        "Every key a scene (TOML) accepts, generated from the schema in `pyfem/scene.py`; "
        "`/usr/bin/python3 -m pyfem keys` prints this page. A key is written as its full dotted path, as in "
        "`--set` overrides and error messages: `NAME` stands for the name of a named table "
        "(`materials.NAME.E` is `E` in `[materials.rock]`), `0` for the index of an entry of an "
        "array of tables (`monitor.0.point` is `point` in the first `[[monitor]]`). Units are SI "
        "(m, kg, s, Pa), angles in degrees, z up; \"-\": no unit. \"required\": the scene must give "
        "it (a key of an optional table only when the table is present); keys that are required "
        "only in some cases say so under default and in the table's rules. Anything else (an unknown "
        "key, a wrong type, a value outside \"allowed\") stops before a run with a message naming the "
        "key, the value and what is allowed.",
        "",
        "## What a table switches on",
        "",
        "Each effect is on only when its table is present; an effect that is off costs nothing.",
        "",
        "| table | present: switches on |",
        "|---|---|",
    ]
    for path in optional_tables():
        switched = [f"**{effect}**: {EFFECTS.get(effect, '')}" for effect in effects_switched_by(path)]
        if path in SWITCHES:
            switched.append(SWITCHES[path])
        lines.append(f"| [`{path}`](#{_anchor(path)}) | {_cell('; '.join(switched))} |")
    lines += ["", "## Keys", ""]
    for path, table in tables():
        lines += _section(path, table)
    lines += _layered_cavern_section()
    lines.append(WAVE_CONVENTIONS)
    return "\n".join(lines).rstrip("\n") + "\n"


def repository_document() -> Path | None:
    """docs/scene-keys.md of the source tree this package was imported from; None for an
    installed package (no docs/ next to it)."""
    root = Path(__file__).resolve().parents[1]
    if (root / "docs").is_dir() and (root / "pyfem" / "scene.py").is_file():
        return root / DOCUMENT
    return None

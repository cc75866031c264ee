"""Hexahedral mesh of the paper's case study: a powerhouse cavern in dipping layers.

`build_layered_cavern(parameters)` fills the current gmsh model with a
structured 8-node hexahedral mesh of one large cavern (the Azad Pattan main
powerhouse, seed paper Sec. 4: 175.6 m long, 24.9 m wide, 60.15 m high,
arched crown, concrete lining 1.25 m in the crown and 1.0 m in the walls) in
rock made of alternating layers (60 % sandstone / 40 % non-sandstone) whose
interfaces strike across the cavern axis and dip at 70 deg.

Coordinates (SI, m): x across the cavern (positive downstream, so the
upstream wall is at x = -width/2), y along the cavern axis, z up. The cavern
centre line is x = 0; the cavern floor (excavation bottom) is z = floor_z
(default 0); the middle of the cavern length is Y = 0, the paper's
monitoring section.

How the mesh is made ("sheared extrusion", docs/method.md section 12):

1. The x-z cross-section is meshed with quadrilaterals in numpy: an O-grid
   of radial lines from the lining's inner face through the lining
   (`lining_elements` equal cells) and, from the excavation surface, through
   the rock out to the model's rectangle (geometric grading, first cell
   `h_near`, ratio <= `grading`, last cell <= `h_far`); the space inside the
   lining is a Coons patch (the "excavation").
2. The section is extruded along y through stations Y_k, where the node
   (x, z) of station k sits at y = Y_k + w_k * s * (z - z_ref) * cot(dip)
   (s = -1 when the layers dip towards +y, +1 towards -y). Over the cavern's
   length w_k = 1: every station plane is parallel to the bedding and every
   layer interface is a station, i.e. an exact plane made of element faces.
   In the two y margins w_k falls linearly to 0 so that the model's y faces
   are the vertical planes y = +-(length/2 + margin_y): the model is a box.
3. The hexahedra are handed to gmsh as a discrete model (nodes, elements,
   physical groups), which `dolfinx.io.gmshio.model_to_mesh` reads like any
   gmsh model.

Physical groups: volumes named by the layer materials (default "sandstone",
"non_sandstone"), "lining", "shotcrete" (only with shotcrete > 0: a layer that
thick, one element, on the rock face, the outer part of the lining's thickness),
"internal_concrete" (only with internal_concrete = True) and "excavation" (only
with excavated = False);
surfaces "xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "cavern_surface"
(the excavation surface along the cavern: the lining's outer face, in
contact with the rock), "lining_inner" (the lining's inner face),
"cavern_ends" (the two end planes of the excavated prism, lining ring and
excavation, where they meet the rock beyond the cavern's ends; with
cavern_surface it closes the excavation) and "interface_1",
"interface_2", ... (the rock part of every layer interface over the cavern's
length, in increasing y).

What the geometry simplifies (say so when comparing with the paper):
- one cavern only: no transformer hall, tailrace or access tunnels; the
  internal concrete only with internal_concrete = True (below);
- the lining is a closed ring of uniform material: walls `lining_wall` thick,
  the crown `lining_crown` thick at the apex (the inner arc passes through
  the inner wall tops, so the crown lining thickens smoothly from
  `lining_wall` at the springline to `lining_crown`), and a floor slab
  `lining_floor` thick on the excavation floor (the paper's lower concrete
  structures, reduced to a slab);
- the crown is a circular arc of rise `arch_rise` (not given in the paper;
  default 8 m) through the wall tops; the cavern is a prism along y whose two
  end faces are planes parallel to the bedding (sheared by cot(dip));
- layers are straight, parallel planes of constant thickness; they are exact
  (at the dip, named, available for contact) over the cavern's length; in the
  y margins their boundaries turn towards the vertical y faces and are
  welded material boundaries, not named interfaces;
- a cavern end within `h_near` of a layer interface is moved onto it, so no
  sliver elements appear (the summary reports the meshed length);
- the O-grid gives every ring the contour's number of divisions, so far from
  the cavern the tangential size is the model side / that number (up to
  ~30 m in the paper preset) rather than `h_far`.

With internal_concrete = True the excavation's grid gets grid lines at the
faces of the powerhouse's internal concrete (`INTERNAL_CONCRETE`: four units,
five machine piers across the hall below the generator floor, the turbine and
generator floor slabs with each unit's pit open, a square wind cover ring
around each unit between them; our assumption of typical dimensions, the
paper gives none), its cells become region "internal_concrete", and below the
springline the excavation's grid is a tensor grid (straight rows and columns)
instead of the Coons patch. The concrete's nodes on the lining's inner face
are the lining's (a conforming mesh). The extra grid lines run through the
whole model, so the mesh is finer than without the option (coarse preset,
79 520 cells instead of 47 936 with excavated = False).

When contact splits an interface, its nodes on the cavern surface are split
too; the lining (not a layer) stays attached to one side there.

Opening the mesh in gmsh: `/usr/bin/python3 meshes/layered_cavern.py` writes
meshes/layered_cavern_coarse.msh; `gmsh meshes/layered_cavern_coarse.msh`
shows it (Tools > Visibility lists the physical groups). It is a discrete
mesh, so there is no .geo to edit; a scene reads it back with
``builder = "file"``, ``file = "meshes/layered_cavern_coarse.msh"``.
"""
from __future__ import annotations

import copy
import math
import numbers
import typing

from pyfem._gmsh import gmsh
import numpy as np

from pyfem.material import Material, check_elastic

# gmsh element type numbers.
GMSH_QUADRANGLE_4 = 3
GMSH_HEXAHEDRON_8 = 5

LINING_REGION = "lining"
EXCAVATION_REGION = "excavation"
SHOTCRETE_REGION = "shotcrete"
CONCRETE_REGION = "internal_concrete"

# The powerhouse's internal concrete (internal_concrete = true): our assumption, typical of large
# underground powerhouses (the paper names machine piers, the generator and turbine floor slabs and
# the wind cover but gives no dimension). Heights are above floor_z; y positions are measured at
# z = layer_reference_z along the sheared stations, so every plane "across y" is parallel to the
# bedding (dip), not vertical. The cells are cut out of the excavation's structured grid, which
# gets grid lines at every face below, so the parts have exactly these dimensions and share their
# nodes with the lining's inner face.
INTERNAL_CONCRETE = {
    "unit_centres": (-30.0, 0.0, 30.0, 60.0),   # m, y of the four units (Y = 0, the monitoring section, is unit 2)
    "pier_thickness": 2.0,                      # m, along y; the piers halfway between units and at both ends
    "turbine_floor": (16.0, 17.0),              # m, bottom and top of the turbine floor slab
    "generator_floor": (24.0, 25.0),            # m, bottom and top of the generator floor slab
    "wind_cover_inner": 13.0,                   # m, inner side of the square ring (in plan) around each unit
    "wind_cover_wall": 1.0,                     # m, its wall; from the turbine floor's top to the generator floor
}
CONCRETE_PARTS = ("machine_piers", "turbine_floor", "generator_floor", "wind_cover")
OUTER_FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
CAVERN_SURFACES = ("cavern_surface", "lining_inner", "cavern_ends")

# Parameters shared by the presets (the paper's case study, seed paper Sec. 4).
# None means "derived from other parameters" (see `layered_cavern_parameters`).
COMMON_PARAMETERS = {
    "width": 24.9,            # m, excavation width
    "height": 60.15,          # m, excavation floor to crown top
    "arch_rise": 8.0,         # m, crown arc above the wall tops
    "length": 175.6,          # m, along y
    "floor_z": 0.0,           # m, z of the excavation floor
    "lining_crown": 1.25,     # m, at the crown apex
    "lining_wall": 1.0,       # m
    "lining_floor": 1.0,      # m, floor slab
    "lining_elements": 2,     # elements through the lining thickness
    "shotcrete": 0.0,         # m, a shotcrete layer on the rock face (region "shotcrete", one element thick;
                              # the outer part of the lining's thickness); 0: none
    "h_near": None,           # m, first rock cell normal to the cavern; default lining_wall / lining_elements
    "layers": [{"material": "non_sandstone", "thickness": 8.0},   # layers[0] is centred on Y = 0
               {"material": "sandstone", "thickness": 12.0}],     # 60 % / 40 % by thickness
    "dip": 70.0,              # deg
    "dip_direction": "+y",    # the layers dip towards +y (paper: dip NE, y axis N58E)
    "layer_offset": 0.0,      # m, y of the centre of layers[0] at z = layer_reference_z
    "layer_reference_z": None,  # m, default floor_z + height / 2 (cavern mid-height)
    "excavated": True,        # False: the excavation cells are present as region "excavation"
    "internal_concrete": False,  # True: region "internal_concrete" (machine piers, floor slabs, wind covers)
    "materials": {            # for the time-step estimate only (Pa, -, kg/m^3; the paper's Table 1, densities docs/method.md section 10)
        "sandstone": {"E": 8.0e9, "nu": 0.24, "rho": 2600.0},
        "non_sandstone": {"E": 2.0e9, "nu": 0.30, "rho": 2400.0},
        "lining": {"E": 28.0e9, "nu": 0.167, "rho": 2500.0},
    },
}

PRESETS = {
    # Runs on a 2-core machine: 43 904 hexahedra, 46 832 nodes, min scaled Jacobian 0.54.
    "coarse": {"half_width_x": 100.0, "below": 80.0, "above": 80.0, "margin_y": 60.0,
               "h_cavern": 4.5, "h_far": 25.0, "grading": 1.3},
    # The paper's 138 972 elements: 138 040 hexahedra, 144 366 nodes, min scaled Jacobian 0.46.
    "paper": {"half_width_x": 150.0, "below": 150.0, "above": 150.0, "margin_y": 100.0,
              "h_cavern": 3.0, "h_far": 25.0, "grading": 1.25},
}

PARAMETER_KEYS = ("preset", *COMMON_PARAMETERS, *PRESETS["coarse"])

_PREFIX = "mesh.parameters."


# --------------------------------------------------------------------------------------------
# Parameters


def layered_cavern_parameters(parameters: typing.Mapping | None = None) -> dict:
    """The complete, validated parameter set of `build_layered_cavern`.

    Args:
        parameters: any subset of `PARAMETER_KEYS`; "preset" ("coarse",
            default, or "paper") picks the defaults of the model extents and
            element sizes, explicit keys override. Lengths in m, angles in deg.

    Returns:
        dict with every key of `PARAMETER_KEYS` set (derived defaults filled).

    Raises:
        ValueError: naming the parameter ("mesh.parameters.KEY"), its value
            and what is allowed.
    """
    given = dict(parameters or {})
    unknown = sorted(set(given) - set(PARAMETER_KEYS))
    if unknown:
        raise ValueError(f"{_PREFIX}{unknown[0]} = {given[unknown[0]]!r}: unknown parameter of builder "
                         f"\"layered_cavern\" (allowed: {', '.join(PARAMETER_KEYS)})")
    preset = given.get("preset", "coarse")
    if preset not in PRESETS:
        raise ValueError(f"{_PREFIX}preset = {preset!r}: allowed are {', '.join(map(repr, PRESETS))}")
    p = copy.deepcopy(COMMON_PARAMETERS)
    p.update(PRESETS[preset])
    p.update(copy.deepcopy(given))
    p["preset"] = preset

    for key in ("width", "height", "arch_rise", "length", "lining_crown", "lining_wall", "lining_floor",
                "half_width_x", "below", "above", "margin_y", "h_cavern", "h_far"):
        p[key] = _positive(key, p[key])
    p["floor_z"] = _finite("floor_z", p["floor_z"])
    p["shotcrete"] = _finite("shotcrete", p["shotcrete"])
    thinnest = min(p["lining_wall"], p["lining_crown"], p["lining_floor"])
    if not 0.0 <= p["shotcrete"] < thinnest:
        raise ValueError(f"{_PREFIX}shotcrete = {p['shotcrete']!r}: the shotcrete layer's thickness (m) must lie in "
                         f"[0, {thinnest:g}) (0: none; it is the outer part of the lining's thinnest side, "
                         "lining_wall, lining_crown, lining_floor)")
    p["layer_offset"] = _finite("layer_offset", p["layer_offset"])
    if not isinstance(p["lining_elements"], numbers.Integral) or isinstance(p["lining_elements"], bool) \
            or p["lining_elements"] < 2:
        raise ValueError(f"{_PREFIX}lining_elements = {p['lining_elements']!r}: an integer >= 2 "
                         "(docs/method.md section 3: at least two elements through the lining)")
    p["lining_elements"] = int(p["lining_elements"])
    if p["h_near"] is None:
        p["h_near"] = p["lining_wall"] / p["lining_elements"]
    p["h_near"] = _positive("h_near", p["h_near"])
    p["grading"] = _finite("grading", p["grading"])
    if not 1.0 < p["grading"] <= 2.0:
        raise ValueError(f"{_PREFIX}grading = {p['grading']!r}: the largest ratio of neighbouring "
                         "element sizes must lie in (1, 2]")
    if p["h_far"] < p["h_near"]:
        raise ValueError(f"{_PREFIX}h_far = {p['h_far']!r}: must be >= h_near = {p['h_near']:g} m")
    p["dip"] = _finite("dip", p["dip"])
    if not 0.0 < p["dip"] <= 90.0:
        raise ValueError(f"{_PREFIX}dip = {p['dip']!r}: the dip of the layers must lie in (0, 90] deg")
    if p["dip_direction"] not in ("+y", "-y"):
        raise ValueError(f"{_PREFIX}dip_direction = {p['dip_direction']!r}: allowed are '+y' and '-y'")
    if not isinstance(p["excavated"], bool):
        raise ValueError(f"{_PREFIX}excavated = {p['excavated']!r}: true or false")
    if not isinstance(p["internal_concrete"], bool):
        raise ValueError(f"{_PREFIX}internal_concrete = {p['internal_concrete']!r}: true or false (the "
                         "machine piers, floor slabs and wind covers as region \"internal_concrete\")")
    _check_layers(p["layers"])
    _check_materials(p["materials"])

    half_width = p["width"] / 2
    if p["lining_wall"] >= half_width:
        raise ValueError(f"{_PREFIX}lining_wall = {p['lining_wall']!r}: must be < width / 2 = "
                         f"{half_width:g} m")
    if p["arch_rise"] > half_width:
        raise ValueError(f"{_PREFIX}arch_rise = {p['arch_rise']!r}: must be <= width / 2 = {half_width:g} m "
                         "(at most a semicircular crown)")
    if p["arch_rise"] <= p["lining_crown"]:
        raise ValueError(f"{_PREFIX}arch_rise = {p['arch_rise']!r}: must exceed lining_crown = "
                         f"{p['lining_crown']:g} m (the inner face of the crown is an arc too)")
    if p["arch_rise"] - p["lining_crown"] > half_width - p["lining_wall"]:
        raise ValueError(f"{_PREFIX}lining_crown = {p['lining_crown']!r}: the inner crown arc would be more "
                         "than a semicircle; need arch_rise - lining_crown <= width / 2 - lining_wall")
    if p["height"] - p["arch_rise"] <= p["lining_floor"]:
        raise ValueError(f"{_PREFIX}height = {p['height']!r}: the walls (height - arch_rise = "
                         f"{p['height'] - p['arch_rise']:g} m) must be taller than lining_floor = "
                         f"{p['lining_floor']:g} m")
    if p["half_width_x"] <= half_width + p["h_near"]:
        raise ValueError(f"{_PREFIX}half_width_x = {p['half_width_x']!r}: must exceed width / 2 + h_near = "
                         f"{half_width + p['h_near']:g} m")
    for key in ("below", "above"):
        if p[key] <= p["h_near"]:
            raise ValueError(f"{_PREFIX}{key} = {p[key]!r}: must exceed h_near = {p['h_near']:g} m")

    if p["layer_reference_z"] is None:
        p["layer_reference_z"] = p["floor_z"] + p["height"] / 2
    p["layer_reference_z"] = _finite("layer_reference_z", p["layer_reference_z"])
    # The sheared station planes turn vertical across each y margin; they stay in order
    # (no inverted element) only if the margin exceeds the largest y shift of a plane.
    z_bottom = p["floor_z"] - p["below"]
    z_top = p["floor_z"] + p["height"] + p["above"]
    shift = max(abs(z_top - p["layer_reference_z"]), abs(z_bottom - p["layer_reference_z"])) \
        / math.tan(math.radians(p["dip"]))
    if p["margin_y"] <= shift:
        raise ValueError(f"{_PREFIX}margin_y = {p['margin_y']!r}: must exceed the largest y shift of a layer "
                         f"plane over the model height, {shift:.4g} m (= max |z - layer_reference_z| * "
                         "cot(dip)), so the layers can turn to the vertical y faces")
    if p["internal_concrete"]:
        _check_internal_concrete(p)
    return p


def concrete_layout(p: dict) -> dict:
    """Where the internal concrete lies (m): its grid lines and its parts' boxes.

    Returns:
        dict: "x", "z", "y" (sorted faces: x across, z above floor_z added, y at
        layer_reference_z), "piers" (list of (y_lo, y_hi)), "units" (y centres),
        "block" (y_lo, y_hi of the unit block, the piers' outer faces),
        "half_inner"/"half_outer" (half sides of the wind cover ring), "width"
        (the lining's inner width), "z_floor" (top of the floor lining) and the
        slabs' and wind cover's z ranges.
    """
    c = INTERNAL_CONCRETE
    z0 = p["floor_z"]
    units = np.array(c["unit_centres"], dtype=float)
    spacing = np.diff(units)
    half_pier = c["pier_thickness"] / 2
    walls = np.concatenate([[units[0] - spacing[0] / 2], units[:-1] + spacing / 2, [units[-1] + spacing[-1] / 2]])
    piers = [(float(y - half_pier), float(y + half_pier)) for y in walls]
    half_inner = c["wind_cover_inner"] / 2
    half_outer = half_inner + c["wind_cover_wall"]
    turbine = (z0 + c["turbine_floor"][0], z0 + c["turbine_floor"][1])
    generator = (z0 + c["generator_floor"][0], z0 + c["generator_floor"][1])
    y_faces = [face for pier in piers for face in pier]
    y_faces += [float(u + s * h) for u in units for s in (-1, 1) for h in (half_inner, half_outer)]
    return {"x": sorted({-half_outer, -half_inner, 0.0, half_inner, half_outer}),
            "z": sorted({*turbine, *generator}), "y": sorted(set(y_faces)),
            "piers": piers, "units": units.tolist(), "block": (piers[0][0], piers[-1][1]),
            "half_inner": half_inner, "half_outer": half_outer,
            "width": p["width"] - 2 * p["lining_wall"], "z_floor": z0 + p["lining_floor"],
            "turbine_floor": turbine, "generator_floor": generator, "wind_cover": (turbine[1], generator[0])}


def concrete_volumes(p: dict) -> dict:
    """Closed-form volume of each part of the internal concrete (m^3).

    The stations' shear keeps volumes (Cavalieri), so every part is a set of boxes:
    the piers from the floor lining to the generator floor across the inner width;
    the two slabs over the unit block less the piers (turbine floor) and less each
    unit's pit (the wind cover's inside); the wind covers' square rings.
    """
    lay = concrete_layout(p)
    width, n_units = lay["width"], len(lay["units"])
    pit = (2 * lay["half_inner"]) ** 2
    block = lay["block"][1] - lay["block"][0]
    pier_y = sum(hi - lo for lo, hi in lay["piers"])
    (t0, t1), (g0, g1), (w0, w1) = lay["turbine_floor"], lay["generator_floor"], lay["wind_cover"]
    return {"machine_piers": pier_y * width * (g0 - lay["z_floor"]),
            "turbine_floor": ((block - pier_y) * width - n_units * pit) * (t1 - t0),
            "generator_floor": (block * width - n_units * pit) * (g1 - g0),
            "wind_cover": n_units * ((2 * lay["half_outer"]) ** 2 - pit) * (w1 - w0)}


def _check_internal_concrete(p: dict) -> None:
    lay = concrete_layout(p)
    key = f"{_PREFIX}internal_concrete"
    z_spring = p["floor_z"] + p["height"] - p["arch_rise"]
    if not lay["z_floor"] < lay["z"][0] or not lay["z"][-1] < z_spring:
        raise ValueError(f"{key} = true: the floor slabs (z = {lay['z'][0]:g} to {lay['z'][-1]:g} m) must lie "
                         f"between the floor lining's top ({lay['z_floor']:g} m) and the springline ({z_spring:g} m)")
    if not lay["half_outer"] < lay["width"] / 2:
        raise ValueError(f"{key} = true: the wind cover ({2 * lay['half_outer']:g} m) must be narrower than "
                         f"the lining's inner width ({lay['width']:g} m)")
    half_length = p["length"] / 2
    if not -half_length < lay["block"][0] or not lay["block"][1] < half_length:
        raise ValueError(f"{key} = true: the unit block (y = {lay['block'][0]:g} to {lay['block'][1]:g} m) "
                         f"must lie within the cavern (length {p['length']:g} m)")


def _divisions(faces: typing.Sequence[float], lo: float, hi: float, size: float) -> np.ndarray:
    """Node fractions 0..1 over [lo, hi] with a node at every face and cells <= size."""
    points = [lo, *[f for f in faces if lo < f < hi], hi]
    nodes = [lo]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil((b - a) / size - 1e-9))
        nodes.extend(a + (b - a) * np.arange(1, n + 1) / n)
        nodes[-1] = b
    return (np.array(nodes) - lo) / (hi - lo)


def _finite(key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{_PREFIX}{key} = {value!r}: a finite number")
    return float(value)


def _positive(key: str, value) -> float:
    value = _finite(key, value)
    if value <= 0.0:
        raise ValueError(f"{_PREFIX}{key} = {value!r}: must be > 0 (m)")
    return value


def _check_layers(layers) -> None:
    if not isinstance(layers, (list, tuple)) or not layers:
        raise ValueError(f"{_PREFIX}layers = {layers!r}: a non-empty list of {{material, thickness}}")
    for index, layer in enumerate(layers):
        key = f"layers.{index}"
        if not isinstance(layer, typing.Mapping) or set(layer) != {"material", "thickness"}:
            raise ValueError(f"{_PREFIX}{key} = {layer!r}: a table with exactly the keys material, thickness")
        name = layer["material"]
        if not isinstance(name, str) or not name or name in (LINING_REGION, EXCAVATION_REGION, SHOTCRETE_REGION):
            raise ValueError(f"{_PREFIX}{key}.material = {name!r}: a non-empty name other than "
                             f"{LINING_REGION!r}, {EXCAVATION_REGION!r} and {SHOTCRETE_REGION!r}")
        _positive(f"{key}.thickness", layer["thickness"])


def _check_materials(materials) -> None:
    if not isinstance(materials, typing.Mapping):
        raise ValueError(f"{_PREFIX}materials = {materials!r}: a table NAME -> {{E, nu, rho}}")
    for name, material in materials.items():
        if not isinstance(material, typing.Mapping) or not {"E", "nu", "rho"} <= set(material):
            raise ValueError(f"{_PREFIX}materials.{name} = {material!r}: needs E (Pa), nu, rho (kg/m^3)")
        check_elastic(material["E"], material["nu"], material["rho"], prefix=f"{_PREFIX}materials.{name}.")


# --------------------------------------------------------------------------------------------
# Cross-section (x-z) O-grid


class _Section(typing.NamedTuple):
    xz: np.ndarray            # (n2, 2) node coordinates (x, z)
    quads: np.ndarray         # (q, 4) node ids, clockwise in (x, z) so that +y extrusion is right-handed
    zone: np.ndarray          # (q,) 0 lining, 1 rock, 2 excavation (inside the lining)
    edges: dict               # name -> (e, 2) node ids of the boundary edges
    ring: np.ndarray          # (J + 1, P) node ids of ring j (0: lining inner face), contour index i
    counts: dict              # n_floor, n_wall, n_rock, perimeter


ZONE_LINING, ZONE_ROCK, ZONE_EXCAVATION, ZONE_SHOTCRETE = 0, 1, 2, 3


def _contour(half_width: float, z_floor: float, z_spring: float, z_apex: float, n_floor: int,
             n_wall: int, floor_fractions: np.ndarray | None = None,
             wall_fractions: np.ndarray | None = None) -> np.ndarray:
    """Closed counter-clockwise contour: floor, right wall, crown arc, left wall.

    Returns (2 n_floor + 2 n_wall, 2) points; the floor and the arc have
    n_floor segments each (equal in x / in angle), the walls n_wall (equal in z).
    Point 0 is the left floor corner; the crown apex is a point (n_floor even).
    `floor_fractions` (symmetric about 1/2) and `wall_fractions`, nodes 0..1 of
    n + 1 entries, replace the equal divisions (the internal concrete's grid lines).
    """
    t_floor = np.arange(n_floor) / n_floor if floor_fractions is None else floor_fractions[:-1]
    t_wall = np.arange(n_wall) / n_wall if wall_fractions is None else wall_fractions[:-1]
    down_wall = t_wall if wall_fractions is None else 1 - wall_fractions[::-1][:-1]
    floor = np.column_stack([-half_width + 2 * half_width * t_floor, np.full(n_floor, z_floor)])
    right = np.column_stack([np.full(n_wall, half_width), z_floor + (z_spring - z_floor) * t_wall])
    rise = z_apex - z_spring
    radius = (half_width**2 + rise**2) / (2 * rise)
    z_centre = z_apex - radius
    phi0 = math.atan2(z_spring - z_centre, half_width)
    phi = phi0 + (math.pi - 2 * phi0) * t_floor
    arc = np.column_stack([radius * np.cos(phi), z_centre + radius * np.sin(phi)])
    arc[0] = (half_width, z_spring)  # exact end point and apex, not their round-off
    arc[n_floor // 2] = (0.0, z_apex)
    left = np.column_stack([np.full(n_wall, -half_width), z_spring - (z_spring - z_floor) * down_wall])
    return np.vstack([floor, right, arc, left])


def _graded_fractions(first: float, ratio: float, cap: float, lengths: np.ndarray) -> tuple[np.ndarray, int]:
    """Node fractions 0..1 along lines of `lengths`, cells growing from `first`.

    The cell sizes are min(first r^m, cap), m = 0..n-1: geometric growth, then
    constant at `cap`. n is the fewest cells that reach the longest line with
    r = `ratio`; each line then gets its own r <= `ratio` (bisection) so that
    its cells add up to its length.

    Returns:
        fractions (lines, n + 1) and n.
    """
    def sizes(r: np.ndarray, n: int) -> np.ndarray:
        return np.minimum(first * r[..., None] ** np.arange(n), cap)

    n = 1
    while sizes(np.array(ratio), n).sum() < lengths.max():
        n += 1
    lo = np.full(lengths.shape, 0.2)
    hi = np.full(lengths.shape, ratio)
    for _ in range(100):
        r = 0.5 * (lo + hi)
        too_long = sizes(r, n).sum(axis=1) > lengths
        hi = np.where(too_long, r, hi)
        lo = np.where(too_long, lo, r)
    sums = np.concatenate([np.zeros((len(lengths), 1)), np.cumsum(sizes(0.5 * (lo + hi), n), axis=1)], axis=1)
    return sums / sums[:, -1:], n   # exactly 1 at the outer end


def _cross_section(p: dict) -> _Section:
    half = p["width"] / 2
    z0 = p["floor_z"]
    z_spring = z0 + p["height"] - p["arch_rise"]
    arc_length_estimate = p["width"] + 2 * p["arch_rise"]  # a little above the arc's length
    n_floor = max(2, 2 * round((p["width"] + arc_length_estimate) / 2 / (2 * p["h_cavern"])))
    n_wall = max(1, math.ceil((z_spring - z0) / p["h_cavern"] - 1e-9))
    n_lining = p["lining_elements"]
    f_floor = f_wall = None
    if p["internal_concrete"]:  # grid lines at the internal concrete's faces (else the equal divisions)
        lay = concrete_layout(p)
        inner_half, z_in = half - p["lining_wall"], z0 + p["lining_floor"]
        f_floor = _divisions(lay["x"], -inner_half, inner_half, p["h_cavern"])
        f_wall = _divisions(lay["z"], z_in, z_spring, p["h_cavern"])
        n_floor, n_wall = len(f_floor) - 1, len(f_wall) - 1
    outer = _contour(half, z0, z_spring, z0 + p["height"], n_floor, n_wall, f_floor, f_wall)
    inner = _contour(half - p["lining_wall"], z0 + p["lining_floor"], z_spring,
                     z0 + p["height"] - p["lining_crown"], n_floor, n_wall, f_floor, f_wall)
    t = p["shotcrete"]
    # With shotcrete the lining's rings end on the shotcrete's inner face, t inside the rock face.
    lining_outer = (_contour(half - t, z0 + t, z_spring, z0 + p["height"] - t, n_floor, n_wall, f_floor, f_wall)
                    if t > 0.0 else outer)
    n_face = n_lining + (1 if t > 0.0 else 0)  # the ring on the rock face (the excavation surface)
    perimeter = len(outer)

    # The model's rectangle, with the same division as the contour: each side of the
    # cavern maps to one side of the rectangle (an O-grid).
    X = p["half_width_x"]
    z_bottom, z_top = z0 - p["below"], z0 + p["height"] + p["above"]
    t_floor = np.arange(n_floor) / n_floor if f_floor is None else f_floor[:-1]
    t_wall = np.arange(n_wall) / n_wall if f_wall is None else f_wall[:-1]
    down_wall = t_wall if f_wall is None else 1 - f_wall[::-1][:-1]
    rectangle = np.vstack([
        np.column_stack([-X + 2 * X * t_floor, np.full(n_floor, z_bottom)]),
        np.column_stack([np.full(n_wall, X), z_bottom + (z_top - z_bottom) * t_wall]),
        np.column_stack([X - 2 * X * t_floor, np.full(n_floor, z_top)]),
        np.column_stack([np.full(n_wall, -X), z_top - (z_top - z_bottom) * down_wall]),
    ])

    # Rock: radial cells from h_near, growing by <= grading up to h_far.
    lengths = np.linalg.norm(rectangle - outer, axis=1)
    fractions, n_rock = _graded_fractions(p["h_near"], p["grading"], p["h_far"], lengths)
    radial = lengths[:, None] * np.diff(fractions, axis=1)

    n_rings = n_face + n_rock + 1
    ring_xz = np.empty((n_rings, perimeter, 2))
    for j in range(n_lining + 1):
        ring_xz[j] = inner + (j / n_lining) * (lining_outer - inner)
    if t > 0.0:
        ring_xz[n_face] = outer
    for m in range(1, n_rock + 1):
        ring_xz[n_face + m] = outer + fractions[:, m, None] * (rectangle - outer)
    ring = np.arange(n_rings * perimeter).reshape(n_rings, perimeter)

    # Excavation: Coons patch on the inner contour, a along x (floor/arc), b along z (walls).
    grid = np.full((n_floor + 1, n_wall + 1), -1, dtype=np.int64)
    a = np.arange(n_floor + 1)
    b = np.arange(n_wall + 1)
    grid[:, 0] = ring[0, a % perimeter]
    grid[n_floor, :] = ring[0, n_floor + b]
    grid[:, n_wall] = ring[0, n_floor + n_wall + (n_floor - a)]
    grid[0, :] = ring[0, (2 * n_floor + n_wall + (n_wall - b)) % perimeter]
    flat_ring = ring_xz.reshape(-1, 2)
    bottom, top = flat_ring[grid[:, 0]], flat_ring[grid[:, n_wall]]
    left, right = flat_ring[grid[0, :]], flat_ring[grid[n_floor, :]]
    u = (a / n_floor)[:, None, None]
    v = (b / n_wall)[None, :, None]
    coons = ((1 - v) * bottom[:, None] + v * top[:, None] + (1 - u) * left[None] + u * right[None]
             - ((1 - u) * (1 - v) * bottom[0] + u * (1 - v) * bottom[-1]
                + (1 - u) * v * top[0] + u * v * top[-1]))
    if p["internal_concrete"]:  # below the springline a tensor grid: straight rows and columns
        coons[1:-1, 1:-1, 0] = bottom[1:-1, 0][:, None]
        coons[1:-1, 1:-1, 1] = left[1:-1, 1][None, :]
    inside = np.zeros_like(grid, dtype=bool)
    inside[1:-1, 1:-1] = True
    n_inside = int(inside.sum())
    grid[inside] = n_rings * perimeter + np.arange(n_inside)
    xz = np.vstack([flat_ring, coons[inside]])

    quads, zones = [], []
    i = np.arange(perimeter)
    for j in range(n_rings - 1):
        following = (i + 1) % perimeter
        quads.append(np.column_stack([ring[j, i], ring[j, following],
                                      ring[j + 1, following], ring[j + 1, i]]))
        zones.append(np.full(perimeter, ZONE_LINING if j < n_lining else ZONE_SHOTCRETE if j < n_face
                             else ZONE_ROCK))
    aa, bb = np.meshgrid(np.arange(n_floor), np.arange(n_wall), indexing="ij")
    aa, bb = aa.ravel(), bb.ravel()
    quads.append(np.column_stack([grid[aa, bb], grid[aa, bb + 1], grid[aa + 1, bb + 1], grid[aa + 1, bb]]))
    zones.append(np.full(len(aa), ZONE_EXCAVATION))
    quads, zones = np.vstack(quads), np.concatenate(zones)
    # Clockwise in (x, z) makes the hexahedron (quad at y_k, quad at y_k+1) right-handed.
    corners = xz[quads]
    signed_area = 0.5 * np.sum(corners[:, :, 0] * np.roll(corners[:, :, 1], -1, axis=1)
                               - np.roll(corners[:, :, 0], -1, axis=1) * corners[:, :, 1], axis=1)
    counter_clockwise = signed_area > 0
    quads[counter_clockwise] = quads[counter_clockwise][:, ::-1]

    def ring_edges(j: int, start: int, stop: int) -> np.ndarray:
        k = np.arange(start, stop)
        return np.column_stack([ring[j, k], ring[j, (k + 1) % perimeter]])

    outer_ring = n_rings - 1
    edges = {
        "zmin": ring_edges(outer_ring, 0, n_floor),
        "xmax": ring_edges(outer_ring, n_floor, n_floor + n_wall),
        "zmax": ring_edges(outer_ring, n_floor + n_wall, 2 * n_floor + n_wall),
        "xmin": ring_edges(outer_ring, 2 * n_floor + n_wall, perimeter),
        "cavern_surface": ring_edges(n_face, 0, perimeter),
        "lining_inner": ring_edges(0, 0, perimeter),
    }
    counts = {"n_floor": n_floor, "n_wall": n_wall, "n_rock": n_rock, "perimeter": perimeter,
              "max_rock_ratio": float(np.max(radial[:, 1:] / radial[:, :-1]))}
    return _Section(xz, quads, zones, edges, ring, counts)


# --------------------------------------------------------------------------------------------
# Stations along y


class _Stations(typing.NamedTuple):
    Y: np.ndarray             # (K + 1,) station positions at z = z_ref (m)
    w: np.ndarray             # (K + 1,) shear weight: 1 over the cavern length, 0 at the y faces
    material: list            # (K,) layer material of each interval
    in_cavern: np.ndarray     # (K,) interval inside the cavern's length
    interfaces: list          # station index of each named interface, increasing y
    cavern_ends: tuple        # station indices of the cavern's two end planes


def _layer_boundaries(p: dict, y_min: float, y_max: float) -> tuple[np.ndarray, list]:
    """Layer boundaries (y at z_ref) covering [y_min, y_max] and the material between them.

    layers[0] is centred on layer_offset; the list repeats towards +y and,
    backwards, towards -y.
    """
    sin_dip = math.sin(math.radians(p["dip"]))
    layers = p["layers"]
    widths = [layer["thickness"] / sin_dip for layer in layers]
    first_lo = p["layer_offset"] - widths[0] / 2
    bounds, materials = [first_lo], []
    index, y = 0, first_lo
    while y < y_max:
        y += widths[index % len(layers)]
        materials.append(layers[index % len(layers)]["material"])
        bounds.append(y)
        index += 1
    index, y = -1, first_lo
    while y > y_min:
        y -= widths[index % len(layers)]
        materials.insert(0, layers[index % len(layers)]["material"])
        bounds.insert(0, y)
        index -= 1
    return np.array(bounds), materials


def _stations(p: dict) -> _Stations:
    half_length = p["length"] / 2
    y_max = half_length + p["margin_y"]
    y_min = -y_max
    bounds, materials = _layer_boundaries(p, y_min, y_max)
    # Snap a cavern end lying within h_near of a layer boundary onto it: no sliver cells.
    ends = []
    for end in (-half_length, half_length):
        nearest = bounds[np.argmin(np.abs(bounds - end))]
        ends.append(nearest if abs(nearest - end) < p["h_near"] else end)
    y_lo, y_hi = ends
    # Boundaries closer than half the local element size to a y face are dropped (the
    # sliver joins its neighbour): next to the faces the blend squeezes cells further.
    face_size = min(p["h_far"], p["h_cavern"] + (p["grading"] - 1) * p["margin_y"])
    inner_bounds = bounds[(bounds > y_min + face_size / 2) & (bounds < y_max - face_size / 2)]
    breaks = np.unique(np.concatenate([[y_min, y_lo, y_hi, y_max], inner_bounds]))
    if p["internal_concrete"]:  # stations at the piers' and wind covers' faces too
        breaks = np.unique(np.concatenate([breaks, concrete_layout(p)["y"]]))

    # Each interval between breaks is one material: the layer holding its middle (a layer
    # boundary dropped next to a face hands its sliver to the neighbour layer).
    break_middle = 0.5 * (breaks[:-1] + breaks[1:])
    break_layer = np.clip(np.searchsorted(bounds, break_middle) - 1, 0, len(materials) - 1)
    stations, interval_material = [breaks[0]], []
    for lo, hi, layer in zip(breaks[:-1], breaks[1:], break_layer):
        if y_lo <= lo and hi <= y_hi:
            size = p["h_cavern"]
        else:  # geometric growth away from the cavern end: h(d) = h_cavern + (grading - 1) d
            distance = (y_lo - 0.5 * (lo + hi)) if hi <= y_lo else (0.5 * (lo + hi) - y_hi)
            size = min(p["h_far"], p["h_cavern"] + (p["grading"] - 1) * distance)
        n = max(1, math.ceil((hi - lo) / size - 1e-9))
        stations.extend(lo + (hi - lo) * np.arange(1, n + 1) / n)
        stations[-1] = hi
        interval_material += [materials[layer]] * n
    Y = np.array(stations)

    w = np.ones_like(Y)
    below, above = Y < y_lo, Y > y_hi
    w[below] = (Y[below] - y_min) / (y_lo - y_min)
    w[above] = (y_max - Y[above]) / (y_max - y_hi)

    middle = 0.5 * (Y[:-1] + Y[1:])
    in_cavern = (middle > y_lo) & (middle < y_hi)
    station_of = {float(y): k for k, y in enumerate(Y)}
    interfaces = [station_of[float(y)] for y in inner_bounds if y_lo <= y <= y_hi]
    cavern_ends = (station_of[float(y_lo)], station_of[float(y_hi)])
    return _Stations(Y, w, interval_material, in_cavern, interfaces, cavern_ends)


# --------------------------------------------------------------------------------------------
# Extrusion, quality, gmsh model

# Neighbours of each hexahedron corner in right-handed order (gmsh/VTK node numbering).
_CORNER_NEIGHBOURS = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                               [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
_HEX_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                       [0, 4], [1, 5], [2, 6], [3, 7]])


def scaled_jacobians(x: np.ndarray, hexahedra: np.ndarray) -> np.ndarray:
    """Minimum scaled Jacobian of each 8-node hexahedron over its corners.

    At each corner, det[e1, e2, e3] / (|e1| |e2| |e3|) of the three edges to
    its neighbours (right-handed): 1 for a cube, <= 0 for an inverted corner.

    Args:
        x: (n, 3) node coordinates (m).
        hexahedra: (c, 8) node indices in gmsh order.

    Returns:
        (c,) minimum scaled Jacobian per element.
    """
    corners = x[hexahedra]                                   # (c, 8, 3)
    edges = corners[:, _CORNER_NEIGHBOURS] - corners[:, :, None, :]   # (c, 8, 3, 3)
    determinant = np.linalg.det(edges)
    norms = np.prod(np.linalg.norm(edges, axis=3), axis=2)
    return np.min(determinant / norms, axis=1)


def build_layered_cavern(parameters: typing.Mapping | None = None) -> dict:
    """Mesh the layered-rock cavern model with hexahedra in the current gmsh model.

    The current gmsh model receives the nodes, the 8-node hexahedra (one
    discrete volume per region), the tagged 4-node quadrilaterals (one
    discrete surface per name) and the physical groups described in the
    module docstring. Call it inside `pyfem.geometry.gmsh_session`.

    Args:
        parameters: see `layered_cavern_parameters` (lengths m, angles deg).

    Returns:
        Summary dict: "parameters" (resolved), "cells", "nodes",
        "region_cells" and "region_volumes" (m^3) per region, "boundaries"
        (physical surface names), "interfaces" (per named interface: name,
        y at z_ref, dip, and pair-monitor points just inside the rock of the
        upstream/downstream walls on the interface, nearest the section Y = 0),
        "monitor_points" (A crown, B upstream wall, C downstream wall,
        D floor on the lining's inner face at Y = 0) and
        "monitor_points_excavation" (the same on the excavation surface),
        "dimensions" (measured from the mesh nodes: width, height, length,
        lining thicknesses, model bounds), "min_scaled_jacobian",
        "min_edge_length", "max_edge_length" (m), "critical_time_step" (s,
        min over regions of the smallest edge / c_p, for the regions with a
        material in parameters["materials"]), "section" (cross-section
        counts), "stations" (number of y stations).

    Raises:
        ValueError: a bad parameter, or an inverted element.
    """
    p = layered_cavern_parameters(parameters)
    section = _cross_section(p)
    stations = _stations(p)
    n2 = len(section.xz)
    n_stations = len(stations.Y)
    cot_dip = 1.0 / math.tan(math.radians(p["dip"]))
    sign = -1.0 if p["dip_direction"] == "+y" else 1.0

    # Nodes of station k: y = Y_k + w_k s (z - z_ref) cot(dip).
    x2, z2 = section.xz[:, 0], section.xz[:, 1]
    y = stations.Y[:, None] + stations.w[:, None] * sign * (z2[None] - p["layer_reference_z"]) * cot_dip
    x = np.column_stack([np.tile(x2, n_stations), y.ravel(), np.tile(z2, n_stations)])

    # Hexahedra interval by interval, with their region names.
    region_names = list(dict.fromkeys(layer["material"] for layer in p["layers"]))
    region_names.append(LINING_REGION)
    if p["shotcrete"] > 0.0:
        region_names.append(SHOTCRETE_REGION)
    if not p["excavated"]:
        region_names.append(EXCAVATION_REGION)
    if p["internal_concrete"]:
        region_names.append(CONCRETE_REGION)
    cells_of: dict[str, list] = {name: [] for name in region_names}
    part_of: dict[str, list] = {name: [] for name in CONCRETE_PARTS}
    excavation = section.zone == ZONE_EXCAVATION
    centroids = section.xz[section.quads[excavation]].mean(axis=1)
    for k in range(n_stations - 1):
        hexahedra = np.hstack([k * n2 + section.quads, (k + 1) * n2 + section.quads])
        if stations.in_cavern[k]:
            cells_of[LINING_REGION].append(hexahedra[section.zone == ZONE_LINING])
            if p["shotcrete"] > 0.0:
                cells_of[SHOTCRETE_REGION].append(hexahedra[section.zone == ZONE_SHOTCRETE])
            cells_of[stations.material[k]].append(hexahedra[section.zone == ZONE_ROCK])
            empty = hexahedra[excavation]
            if p["internal_concrete"]:
                parts = _concrete_parts(p, centroids, 0.5 * (stations.Y[k] + stations.Y[k + 1]))
                concrete = np.zeros(len(empty), dtype=bool)
                for name, mask in parts.items():
                    part_of[name].append(empty[mask])
                    concrete |= mask
                cells_of[CONCRETE_REGION].append(empty[concrete])
                empty = empty[~concrete]
            if not p["excavated"]:
                cells_of[EXCAVATION_REGION].append(empty)
        else:
            cells_of[stations.material[k]].append(hexahedra)
    cells = {name: np.vstack(blocks) for name, blocks in cells_of.items() if blocks}
    region_names = [name for name in region_names if name in cells]

    # Named surfaces.
    def extruded(edges: np.ndarray, intervals: typing.Iterable[int]) -> np.ndarray:
        lo, hi = edges[:, 0], edges[:, 1]
        return np.vstack([np.column_stack([k * n2 + lo, k * n2 + hi, (k + 1) * n2 + hi, (k + 1) * n2 + lo])
                          for k in intervals])

    all_intervals = range(n_stations - 1)
    cavern_intervals = [k for k in all_intervals if stations.in_cavern[k]]
    k_lo, k_hi = stations.cavern_ends
    surfaces = {name: extruded(section.edges[name], all_intervals) for name in ("xmin", "xmax")}
    surfaces["ymin"] = section.quads
    surfaces["ymax"] = (n_stations - 1) * n2 + section.quads
    surfaces.update({name: extruded(section.edges[name], all_intervals) for name in ("zmin", "zmax")})
    lining_quads = section.quads[(section.zone == ZONE_LINING) | (section.zone == ZONE_SHOTCRETE)]
    excavation_quads = section.quads[section.zone == ZONE_EXCAVATION]
    cap_quads = np.vstack([lining_quads, excavation_quads])
    surfaces["cavern_surface"] = extruded(section.edges["cavern_surface"], cavern_intervals)
    surfaces["lining_inner"] = extruded(section.edges["lining_inner"], cavern_intervals)
    surfaces["cavern_ends"] = np.vstack([k_lo * n2 + cap_quads, k_hi * n2 + cap_quads])
    rock_quads = section.quads[section.zone == ZONE_ROCK]
    interface_names = []
    for number, k in enumerate(stations.interfaces, start=1):
        name = f"interface_{number}"
        surfaces[name] = k * n2 + rock_quads
        interface_names.append(name)

    # Keep only the nodes of cells (the excavation's inner nodes go with excavated = True).
    all_cells = np.vstack([cells[name] for name in region_names])
    used = np.zeros(len(x), dtype=bool)
    used[all_cells.ravel()] = True
    new_index = np.full(len(x), -1, dtype=np.int64)
    new_index[used] = np.arange(int(used.sum()))
    x = x[used]
    cells = {name: new_index[c] for name, c in cells.items()}
    parts = {name: new_index[np.vstack(blocks)] for name, blocks in part_of.items() if blocks}
    surfaces = {name: new_index[s] for name, s in surfaces.items()}
    all_cells = new_index[all_cells]

    # Quality: fail loudly on an inverted element.
    jacobians = scaled_jacobians(x, all_cells)
    min_jacobian = float(jacobians.min())
    if min_jacobian <= 0.0:
        worst = all_cells[int(np.argmin(jacobians))]
        raise ValueError(f"mesh.parameters: the layered_cavern builder made {int(np.sum(jacobians <= 0))} "
                         f"inverted hexahedra (min scaled Jacobian {min_jacobian:.3g}, e.g. near "
                         f"{x[worst].mean(axis=0).round(2).tolist()} m); check "
                         "mesh.parameters margin_y, dip and the element sizes")
    edge_lengths = {name: np.linalg.norm(x[c[:, _HEX_EDGES[:, 1]]] - x[c[:, _HEX_EDGES[:, 0]]], axis=2)
                    for name, c in cells.items()}
    p_wave_speeds = {name: Material.from_scene(name, table).p_wave_speed
                     for name, table in p["materials"].items()}
    if SHOTCRETE_REGION in region_names and SHOTCRETE_REGION not in p_wave_speeds and LINING_REGION in p_wave_speeds:
        p_wave_speeds[SHOTCRETE_REGION] = p_wave_speeds[LINING_REGION]  # (concrete too, when not given)
    if LINING_REGION in p_wave_speeds:  # the internal concrete is the lining's concrete
        p_wave_speeds.setdefault(CONCRETE_REGION, p_wave_speeds[LINING_REGION])
    time_steps = {name: float(edge_lengths[name].min()) / p_wave_speeds[name]
                  for name in region_names if name in p_wave_speeds}

    _add_to_gmsh(x, cells, region_names, surfaces)

    volumes = {name: float(hexahedron_volumes(x, c).sum()) for name, c in cells.items()}
    summary = {
        "parameters": p,
        "cells": int(len(all_cells)),
        "nodes": int(len(x)),
        "region_cells": {name: int(len(cells[name])) for name in region_names},
        "region_volumes": volumes,
        "regions": region_names,
        "boundaries": list(surfaces),
        "interfaces": _interface_summary(p, stations, interface_names, sign, cot_dip),
        "monitor_points": _monitor_points(p, on_lining=True),
        "monitor_points_excavation": _monitor_points(p, on_lining=False),
        "dimensions": _measured_dimensions(x, surfaces),
        "min_scaled_jacobian": min_jacobian,
        "min_edge_length": float(min(e.min() for e in edge_lengths.values())),
        "max_edge_length": float(max(e.max() for e in edge_lengths.values())),
        "critical_time_step": min(time_steps.values()) if time_steps else None,
        "critical_time_step_by_region": time_steps,
        "section": dict(section.counts, quads=int(len(section.quads)), lining_elements=p["lining_elements"]),
        "stations": int(n_stations),
    }
    if p["internal_concrete"]:
        summary["internal_concrete"] = {
            "layout": concrete_layout(p),
            "part_cells": {name: int(len(c)) for name, c in parts.items()},
            "part_volumes": {name: float(hexahedron_volumes(x, c).sum()) for name, c in parts.items()},
            "closed_form_volumes": concrete_volumes(p)}
    return summary


def _concrete_parts(p: dict, centroids: np.ndarray, y: float) -> dict:
    """Which excavation cells of one station interval are internal concrete, part by part.

    Args:
        centroids: (q, 2) x, z of the excavation quads (a tensor grid below the springline).
        y: the interval's middle at layer_reference_z.

    Returns:
        part name -> (q,) bool, disjoint (a pier wins over the turbine floor it crosses).
    """
    lay = concrete_layout(p)
    x, z = centroids[:, 0], centroids[:, 1]
    in_block = lay["block"][0] < y < lay["block"][1]
    in_pier = any(lo < y < hi for lo, hi in lay["piers"])
    plan = [max(abs(x_i), abs(y - u)) for x_i in x for u in lay["units"]]
    plan = np.array(plan).reshape(len(x), len(lay["units"])).min(axis=1)   # the square "radius" to the nearest unit
    in_pit = plan < lay["half_inner"]
    in_ring = (plan > lay["half_inner"]) & (plan < lay["half_outer"])

    def between(bounds: tuple) -> np.ndarray:
        return (z > bounds[0]) & (z < bounds[1])

    piers = (z > lay["z_floor"]) & (z < lay["generator_floor"][0]) & in_pier
    return {"machine_piers": piers,
            "turbine_floor": between(lay["turbine_floor"]) & in_block & ~in_pit & ~piers,
            "generator_floor": between(lay["generator_floor"]) & in_block & ~in_pit,
            "wind_cover": between(lay["wind_cover"]) & in_ring & ~piers}


def hexahedron_volumes(x: np.ndarray, hexahedra: np.ndarray) -> np.ndarray:
    """Volume of each trilinear 8-node hexahedron (m^3), exact (2x2x2 Gauss).

    Args:
        x: (n, 3) node coordinates (m).
        hexahedra: (c, 8) node indices in gmsh order.
    """
    # Reference corners of the gmsh hexahedron in [-1, 1]^3.
    reference = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                          [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
    g = 1 / math.sqrt(3)
    corners = x[hexahedra]
    volume = np.zeros(len(hexahedra))
    for point in reference * g:   # the Gauss points, weight 1 each
        # d N_a / d xi_i of the trilinear shape functions at `point`.
        factors = 1 + reference * point                                    # (8, 3)
        derivatives = np.empty((8, 3))
        for i in range(3):
            others = [m for m in range(3) if m != i]
            derivatives[:, i] = reference[:, i] * factors[:, others[0]] * factors[:, others[1]] / 8
        jacobian = np.einsum("cai,aj->cij", corners, derivatives)
        volume += np.linalg.det(jacobian)
    return volume


def _add_to_gmsh(x: np.ndarray, cells: dict, region_names: list, surfaces: dict) -> None:
    """Nodes, elements and physical groups into the current gmsh model (a discrete model)."""
    node_tags = np.arange(1, len(x) + 1)   # 1..n: dolfinx's gmshio requires contiguous tags
    element_tag = 1
    for number, name in enumerate(region_names, start=1):
        entity = gmsh.model.addDiscreteEntity(3)
        if number == 1:
            gmsh.model.mesh.addNodes(3, entity, node_tags, x.ravel())
        block = cells[name]
        element_tags = np.arange(element_tag, element_tag + len(block))
        gmsh.model.mesh.addElementsByType(entity, GMSH_HEXAHEDRON_8, element_tags, (block + 1).ravel())
        element_tag += len(block)
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [entity]), name)
    for name, quads in surfaces.items():
        entity = gmsh.model.addDiscreteEntity(2)
        element_tags = np.arange(element_tag, element_tag + len(quads))
        gmsh.model.mesh.addElementsByType(entity, GMSH_QUADRANGLE_4, element_tags, (quads + 1).ravel())
        element_tag += len(quads)
        gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [entity]), name)


def _interface_summary(p: dict, stations: _Stations, names: list, sign: float, cot_dip: float) -> list:
    """Per named interface: its y at z_ref and the pair-monitor points near the walls at Y = 0.

    The point lies on the interface plane, h_near into the rock from each wall
    (x = -+(width/2 + h_near)), at the height of the wall nearest to where the
    plane crosses the section Y = 0.
    """
    z_ref = p["layer_reference_z"]
    z_floor, z_spring = p["floor_z"], p["floor_z"] + p["height"] - p["arch_rise"]
    summary = []
    for name, k in zip(names, stations.interfaces):
        y_ref = float(stations.Y[k])
        # Plane: y = y_ref + s (z - z_ref) cot(dip); it meets y = 0 at z = z_ref - y_ref / (s cot).
        z_cross = z_ref - y_ref / (sign * cot_dip) if cot_dip > 0 else (z_floor + z_spring) / 2
        z = min(max(z_cross, z_floor), z_spring)
        y = y_ref + sign * (z - z_ref) * cot_dip
        x_wall = p["width"] / 2 + p["h_near"]
        summary.append({"name": name, "y_reference": y_ref, "dip": p["dip"],
                        "point_upstream": [-x_wall, y, z], "point_downstream": [x_wall, y, z]})
    return summary


def _monitor_points(p: dict, on_lining: bool) -> dict:
    """Points A (crown), B (upstream wall), C (downstream wall), D (floor) at Y = 0 (m).

    With `on_lining`, on the lining's inner face (the paper's lining monitors);
    otherwise on the excavation surface. B and C are at the cavern's mid-height.
    """
    z0, half = p["floor_z"], p["width"] / 2
    z_mid = z0 + p["height"] / 2
    if on_lining:
        return {"A": [0.0, 0.0, z0 + p["height"] - p["lining_crown"]],
                "B": [-(half - p["lining_wall"]), 0.0, z_mid],
                "C": [half - p["lining_wall"], 0.0, z_mid],
                "D": [0.0, 0.0, z0 + p["lining_floor"]]}
    return {"A": [0.0, 0.0, z0 + p["height"]], "B": [-half, 0.0, z_mid], "C": [half, 0.0, z_mid],
            "D": [0.0, 0.0, z0]}


def _measured_dimensions(x: np.ndarray, surfaces: dict) -> dict:
    """Cavern and model dimensions measured from the nodes of the named surfaces (m)."""
    def nodes(name: str) -> np.ndarray:
        return x[np.unique(surfaces[name])]

    outer = nodes("cavern_surface")
    inner = nodes("lining_inner")
    tolerance = 1e-9 * float(np.abs(x).max())
    apex = outer[(np.abs(outer[:, 0]) < tolerance) & (outer[:, 2] > outer[:, 2].max() - tolerance)]
    return {
        "width": float(outer[:, 0].max() - outer[:, 0].min()),
        "height": float(outer[:, 2].max() - outer[:, 2].min()),
        "lining_crown": float(outer[:, 2].max() - inner[:, 2].max()),
        "lining_wall": float(inner[:, 0].min() - outer[:, 0].min()),
        "lining_floor": float(inner[:, 2].min() - outer[:, 2].min()),
        # Along y on the crown apex line (x = 0, z = top): both ends are shifted alike.
        "length": float(np.ptp(apex[:, 1])),
        "model_min": x.min(axis=0).tolist(),
        "model_max": x.max(axis=0).tolist(),
    }

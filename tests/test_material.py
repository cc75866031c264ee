"""pyfem.material: one material type (elastic constants, wave speeds, impedances, validation), and
the import order of the modules around the interfaces (no import circle)."""
import ast
import math
import pathlib
import subprocess
import sys
from fractions import Fraction

import pytest

from conftest import ROUNDOFF
from pyfem import material as material_module
from pyfem.material import Material, check_elastic, scene_materials

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]

# The paper's sandstone (Table 1; density docs/method.md section 10).
E, NU, RHO = 8.0e9, 0.24, 2600.0


def hand(E, nu):
    """lambda, G, K, M (Pa) in exact rational arithmetic from the textbook formulas."""
    E, nu = Fraction(E), Fraction(nu)
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    G = E / (2 * (1 + nu))
    K = E / (3 * (1 - 2 * nu))
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    return float(lam), float(G), float(K), float(M)


def test_sandstone_constants_against_hand_formulas():
    rock = Material(E=E, nu=NU, rho=RHO, name="sandstone")
    lam, G, K, M = hand(E, NU)
    # By hand: lambda = 1.92e9 / 0.6448, G = 8e9 / 2.48, K = 8e9 / 1.56.
    assert lam == pytest.approx(2.977667493796526e9, rel=1e-15)
    assert G == pytest.approx(3.225806451612903e9, rel=1e-15)
    assert rock.lame_lambda == pytest.approx(lam, rel=ROUNDOFF)
    assert rock.shear_modulus == pytest.approx(G, rel=ROUNDOFF)
    assert rock.lame == (rock.lame_lambda, rock.shear_modulus)
    assert rock.bulk_modulus == pytest.approx(K, rel=ROUNDOFF)
    assert rock.bulk_modulus == pytest.approx(lam + 2.0 * G / 3.0, rel=ROUNDOFF)
    assert rock.p_wave_modulus == pytest.approx(M, rel=ROUNDOFF)
    assert rock.p_wave_modulus == pytest.approx(K + 4.0 * G / 3.0, rel=ROUNDOFF)
    assert rock.p_wave_speed == pytest.approx(math.sqrt(M / RHO), rel=ROUNDOFF)
    assert rock.s_wave_speed == pytest.approx(math.sqrt(G / RHO), rel=ROUNDOFF)
    assert rock.p_wave_speed == pytest.approx(1904.38, abs=0.01)   # m/s
    assert rock.s_wave_speed == pytest.approx(1113.86, abs=0.01)   # m/s
    assert rock.p_wave_speed / rock.s_wave_speed == pytest.approx(math.sqrt(2 * (1 - NU) / (1 - 2 * NU)),
                                                                  rel=ROUNDOFF)
    rho_cp, rho_cs = rock.impedances
    assert rho_cp == pytest.approx(RHO * rock.p_wave_speed, rel=ROUNDOFF)
    assert rho_cs == pytest.approx(RHO * rock.s_wave_speed, rel=ROUNDOFF)
    assert rock.nonlinear_table is None


@pytest.mark.parametrize("E, nu, rho", [(8.0e9, 0.24, 2600.0), (2.0e9, 0.30, 2400.0), (28.0e9, 0.167, 2500.0),
                                        (1.0e7, -0.5, 500.0), (3.0e11, 0.499, 8000.0)])
def test_same_numbers_as_the_formulas_it_replaces(E, nu, rho):
    """The formulas the operators, the free field, the layered cavern and the accuracy advice
    each had (copied here as they were), and the alias kept in pyfem.operators."""
    from pyfem.operators import lame_parameters

    m = Material(E=E, nu=nu, rho=rho)
    # pyfem/operators.py lame_parameters and _cell_materials
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    G = E / (2.0 * (1.0 + nu))
    assert lame_parameters(E, nu) == (lam, G)
    assert m.lame == (lam, G)
    assert m.impedances == pytest.approx((rho * math.sqrt((lam + 2.0 * G) / rho), rho * math.sqrt(G / rho)),
                                         rel=ROUNDOFF)
    # pyfem/seismic/freefield.py lame_constants
    assert (m.p_wave_speed, m.s_wave_speed) == pytest.approx((math.sqrt((lam + 2.0 * G) / rho),
                                                              math.sqrt(G / rho)), rel=ROUNDOFF)
    # pyfem/geometry/layered_cavern.py _p_wave_speed
    assert m.p_wave_speed == pytest.approx(math.sqrt(E * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * rho)), rel=ROUNDOFF)
    # pyfem/accuracy.py slowest_shear_speed
    assert m.s_wave_speed == pytest.approx(math.sqrt(E / (2.0 * (1.0 + nu)) / rho), rel=ROUNDOFF)


def test_the_users_of_the_type_report_its_numbers():
    from pyfem import accuracy
    from pyfem.seismic.freefield import FreeField

    soft, stiff = Material(E=2.0e9, nu=0.30, rho=2400.0), Material(E=E, nu=NU, rho=RHO)
    scene = {"materials": {"soft": {"E": soft.E, "nu": soft.nu, "rho": soft.rho},
                           "stiff": {"E": stiff.E, "nu": stiff.nu, "rho": stiff.rho}}}
    assert accuracy.slowest_shear_speed(scene) == soft.s_wave_speed
    free_field = FreeField([{"wave_type": "P"}], E, NU, RHO, waveform=lambda t: (0.0 * t, 0.0 * t, 0.0 * t),
                           table_grid=(0.0, 0.01, 10), reference_point=[0.0, 0.0, 0.0])
    assert (free_field.lam, free_field.mu) == stiff.lame
    assert (free_field.c_p, free_field.c_s, free_field.rho) == (stiff.p_wave_speed, stiff.s_wave_speed, RHO)
    assert free_field.material == stiff


@pytest.mark.parametrize("key, values", [
    ("E", (-1.0, 0.24, 2600.0)), ("E", (0.0, 0.24, 2600.0)), ("E", (math.inf, 0.24, 2600.0)),
    ("nu", (8e9, 0.5, 2600.0)), ("nu", (8e9, -1.0, 2600.0)), ("nu", (8e9, math.nan, 2600.0)),
    ("nu", (8e9, True, 2600.0)), ("rho", (8e9, 0.24, 0.0)), ("rho", (8e9, 0.24, "2600")),
])
def test_bad_constants_name_the_key_and_the_scene_range(key, values):
    from pyfem.scene import SCHEMA

    allowed = SCHEMA.fields["materials"].entry.fields[key].allowed  # the scene's own wording
    with pytest.raises(ValueError) as caught:
        Material(*values, name="rock")
    assert str(caught.value).startswith(f"materials.rock.{key} = ")
    assert str(caught.value).endswith(allowed)
    with pytest.raises(ValueError, match=r"^mesh\.parameters\.materials\.x\." + key):
        check_elastic(*values, prefix="mesh.parameters.materials.x.")


def test_scene_schema_reads_the_ranges_of_the_material_module():
    from pyfem.scene import SCHEMA

    fields = SCHEMA.fields["materials"].entry.fields
    assert {key: fields[key].interval for key in ("E", "nu", "rho")} == \
        {"E": "(0, inf)", "nu": "(-1, 0.5)", "rho": "(0, inf)"}
    for key in ("E", "nu", "rho"):
        assert fields[key].interval == material_module.interval(key)
        assert fields[key].allowed == material_module.allowed(key)


def test_from_scene_keeps_the_nonlinear_sub_table():
    from pyfem.scene import parse_scene

    raw = {"mesh": {"builder": "box", "size": [10.0, 10.0, 10.0], "h": 5.0},
           "materials": {"rock": {"preset": "sandstone", "plasticity": {"dilation_angle": 5.0}}},
           "time": {"duration": 0.1}}
    scene = parse_scene(raw)
    rock = scene_materials(scene)["rock"]
    assert (rock.name, rock.E, rock.nu, rock.rho) == ("rock", 8.0e9, 0.24, 2600.0)
    assert rock.nonlinear_table == "plasticity" and rock.damage is None
    assert rock.plasticity == dict(scene["materials"]["rock"]["plasticity"])
    assert rock.plasticity["cohesion"] == 1.10e6 and rock.plasticity["dilation_angle"] == 5.0
    assert rock.plasticity is not scene["materials"]["rock"]["plasticity"]  # a copy: the scene stays as it was
    hash(rock)  # frozen and hashable although it holds a dict
    with pytest.raises(AttributeError):
        rock.E = 1.0e9


def test_from_scene_rejects_a_missing_constant_and_two_laws():
    with pytest.raises(ValueError, match=r"materials\.rock\.rho: missing"):
        Material.from_scene("rock", {"E": 8.0e9, "nu": 0.24})
    with pytest.raises(ValueError, match="one nonlinear law"):
        Material(E, NU, RHO, name="rock", plasticity={}, damage={})


# ---------------------------------------------------------------------------------------------
# Import order: the interfaces, the mesh and the operators each import first, and the modules
# around them import one another in one direction only (no circle, not even through an import
# inside a function).

@pytest.mark.parametrize("module", ["pyfem.interfaces", "pyfem.mesh", "pyfem.operators"])
def test_each_imports_first_in_a_fresh_interpreter(module):
    result = subprocess.run([sys.executable, "-c", f"import {module}"], cwd=REPOSITORY, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_numpy_only_modules_load_no_dolfinx():
    code = ("import sys, pyfem.interface_split, pyfem.material; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dolfinx', 'ufl', 'petsc4py', 'gmsh')))")
    result = subprocess.run([sys.executable, "-c", code], cwd=REPOSITORY, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def _pyfem_imports(module: str) -> set[str]:
    """The pyfem modules `module` imports anywhere in its source (module level or in a function)."""
    path = REPOSITORY.joinpath(*module.split(".")).with_suffix(".py")
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            found |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return {name for name in found if name.startswith("pyfem.")}


def test_no_import_circle_among_interfaces_operators_mesh():
    modules = ["pyfem.operators", "pyfem.mesh", "pyfem.interfaces", "pyfem.interface_split", "pyfem.assembly",
               "pyfem.material"]
    graph = {module: _pyfem_imports(module) & set(modules) for module in modules}
    assert graph["pyfem.interface_split"] == set() and graph["pyfem.assembly"] == set()
    assert graph["pyfem.material"] == set()
    # Depth-first search for a back edge.
    state = {}

    def visit(node, path):
        state[node] = "open"
        for target in sorted(graph[node]):
            assert state.get(target) != "open", "import circle: " + " -> ".join(path + [target])
            if target not in state:
                visit(target, path + [target])
        state[node] = "done"

    for module in modules:
        if module not in state:
            visit(module, [module])

"""The case-study variants' workflow (workflows/case_sensitivity.py): its three-mesh convergence
estimate against quantities of known order, and its variants as scenes pyfem accepts."""
import pathlib
import sys

import pytest

REPOSITORY = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY / "workflows"))

import case_sensitivity  # noqa: E402
from pyfem.scene import load_scene  # noqa: E402


@pytest.mark.parametrize("order", [1.0, 2.0, 0.7])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_convergence_recovers_order_and_limit(order, sign):
    # q(h) = q* + C h^p on h, h / 1.5, h / 1.5^2: the observed order is p and the Richardson
    # estimate q*, exactly; the GCI of the fine mesh covers its true error by the safety factor.
    limit, constant, h = 0.63, sign * 0.2, 4.5
    values = [limit + constant * (h / 1.5 ** k) ** order for k in range(3)]
    c = case_sensitivity.convergence(values)
    assert c["status"] == "converging"
    assert c["order"] == pytest.approx(order, rel=1e-12)
    assert c["extrapolated"] == pytest.approx(limit, rel=1e-12)
    true_error = abs(values[2] - limit) / abs(values[2])
    assert c["gci_fine"] == pytest.approx(case_sensitivity.GCI_SAFETY * true_error, rel=1e-10)


@pytest.mark.parametrize("values, status", [((1.0, 1.2, 1.1), "oscillating"), ((1.0, 1.0, 1.1), "unchanged"),
                                            ((1.0, 1.1, 1.1), "unchanged"),
                                            ((7.85e-5, 2.8e-17, 1.4e-17), "unchanged"), ((3.3, 1.9, 0.48), "diverging")])
def test_convergence_refuses_a_sequence_outside_its_asymptotic_range(values, status):
    # Alternating changes, a change that vanishes or grows (the crown pair's slip on the case's three
    # meshes, cm) give no order and no extrapolation: said, not computed.
    c = case_sensitivity.convergence(values)
    assert c["status"] == status and c["order"] is None and c["extrapolated"] is None


@pytest.mark.parametrize("variant", case_sensitivity.VARIANTS, ids=lambda v: v.name)
def test_variants_are_scenes_pyfem_accepts(variant):
    # Every override names a real key with an allowed value (a typo would cost an hour's run).
    scene = load_scene(case_sensitivity.SCENE, [f"time.duration={case_sensitivity.DURATION}", *variant.overrides])
    assert scene["time"]["duration"] == case_sensitivity.DURATION
    if variant.h_cavern is not None and variant.h_cavern != 4.5:
        assert scene["mesh"]["parameters"]["h_cavern"] == variant.h_cavern
    if variant.group == "interface":
        assert scene["contact"]["cohesion"] < 1.0e6 and scene["contact"]["friction_angle"] < 30.0
    if variant.group == "lag":
        assert scene["contact"]["normal_lag"]["length"] > 0
    if variant.group == "strength":
        for rock, cohesion in case_sensitivity.TABLE1_COHESION.items():
            assert scene["materials"][rock]["plasticity"]["cohesion"] > cohesion
    line = case_sensitivity.command(variant, pathlib.Path("/nonexistent"))
    assert ("mpirun" in line) == (variant.ranks > 1) and "--resume" not in line


def test_mesh_group_is_a_refinement_sequence():
    sizes = [v.h_cavern for v in case_sensitivity.VARIANTS if v.group == "mesh"]
    assert len(sizes) == 3
    assert sizes[0] / sizes[1] == pytest.approx(case_sensitivity.REFINEMENT)
    assert sizes[1] / sizes[2] == pytest.approx(case_sensitivity.REFINEMENT)

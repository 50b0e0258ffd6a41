"""The approach to contact (issue 30): the hand comes on along P_d from wherever it was placed
until a link is within the contact tolerance, past the placement too, so where a hand's grasp
centre lies on its approach axis decides only where the search starts; a hand that travels the
whole bound without touching missed the object."""

import numpy as np
import pytest
import yaml

from pipeline.errors import BadParamsError
from pipeline.hands.spec import HANDS, export_hand, get_hand
from pipeline.params import SimulateParams
from pipeline.trial.engine import GraspEngine
from pipeline.trial.reference import ReferenceEngine
from test_simulation import cube, cylinder

TOLERANCE = SimulateParams().contact_tolerance_m


def moved_spec(tmp_path, hand, shift):
    """A spec of ``hand`` exported to ``tmp_path`` with its grasp centre ``shift`` m farther
    from the palm along the approach."""
    path = export_hand(hand, tmp_path)
    spec = yaml.safe_load(path.read_text())
    spec["grasp_centre"] = [
        float(value) for value in np.add(spec["grasp_centre"], shift * np.asarray(spec["approach"]))
    ]
    spec["name"] = f"{hand.name}_moved_{round(shift * 1000)}mm"
    moved = tmp_path / f"{spec['name']}.yaml"
    moved.write_text(yaml.safe_dump(spec))
    return get_hand(str(moved))


def test_barrett_grasp_centre_moved_along_the_approach_changes_no_outcome(tmp_path):
    """The exported Barrett spec with its grasp centre 1 and 2 cm farther from the palm, on the
    5 cm cylinder from 6 directions: every trial is force closure with the default's epsilon
    and closed base pose (the hand came on to the same place), and the palm touches the
    cylinder's side in the closed hand."""
    angles = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    approach = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(6)])
    grasp, orient = np.tile([0.0, 0.0, 0.01], (6, 1)), np.tile([0.0, 0.0, 1.0], (6, 1))
    default = GraspEngine(cylinder(), HANDS["barrett"]).run(grasp, approach, orient, [None] * 6)
    for shift in (0.01, 0.02):
        hand = moved_spec(tmp_path, HANDS["barrett"], shift)
        moved = GraspEngine(cylinder(), hand).run(grasp, approach, orient, [None] * 6)
        for before, after in zip(default, moved):
            assert before.outcome == after.outcome == "force_closure"
            assert after.epsilon == pytest.approx(before.epsilon, abs=1e-6)
            np.testing.assert_allclose(after.base_position, before.base_position, atol=1e-9)
            # it came on farther past its placement by the shift
            assert after.retract_m == pytest.approx(before.retract_m - shift, abs=1e-9)
            palm = after.contact_links == 0
            assert "palm" in after.touched and palm.any()
            np.testing.assert_allclose(np.hypot(*after.contact_points[palm, :2].T), 0.025, atol=2e-4)


@pytest.mark.parametrize("name", ["parallel_jaw", "franka"])
def test_a_hand_placed_3_cm_clear_of_a_cube_comes_on_to_touch_it(name):
    """The hand placed along the 4 cm cube's top face normal, its nearest link (the palm) 3 cm
    above the face: no retreat, then it comes on until the palm is within the tolerance of
    the face, to the very pose it reaches from a placement at the cube's centre, and closes
    there to force closure."""
    engine = GraspEngine(cube(), HANDS[name])
    down, across = [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]
    near = engine.trial([0.0, 0.0, 0.0], down, across)
    lift = 0.03 - (TOLERANCE - near.retract_m)  # the palm's gap when placed at the centre, made 3 cm
    far = engine.trial([0.0, 0.0, lift], down, across)
    assert far.approach_m == pytest.approx(0.03 - TOLERANCE, abs=1e-9) and far.retract_m == -far.approach_m
    np.testing.assert_allclose(far.base_position, near.base_position, atol=1e-9)
    assert far.outcome == "force_closure" and engine.model.links[0] in far.touched
    palm = far.contact_links == 0
    np.testing.assert_allclose(far.contact_points[palm, 2], 0.02, atol=1e-9)  # on the top face


def test_a_hand_aimed_past_a_small_object_misses_it_as_documented():
    """The jaw aimed down 10 cm beside the 4 cm cube: it comes on its whole bound (the hand's
    largest graspable diameter, or the param) with no link within the tolerance, and the trial
    is ``no_contact`` with the fingers left open; the pybullet reference says the same."""
    jaw = HANDS["parallel_jaw"]
    target = ([0.1, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0])
    for bound, travel in ((-1.0, jaw.max_graspable_diameter), (0.05, 0.05)):
        missed = GraspEngine(cube(), jaw, approach_max_m=bound).trial(*target)
        assert missed.outcome == "no_contact" and missed.touched == () and missed.close_steps == 0
        assert (missed.retract_m, missed.approach_m) == (pytest.approx(-travel), pytest.approx(travel))
        assert missed.joint_positions == tuple(jaw.preshape(None)[joint] for joint in jaw.limits)
        assert missed.finger_stops == ("none", "none") and "approach passed the object" in missed.message
    reference = ReferenceEngine(cube(), jaw)
    theirs = reference.trial(*target)
    reference.close()
    assert (theirs.outcome, theirs.retract_m) == ("no_contact", pytest.approx(-jaw.max_graspable_diameter))


def test_a_negative_approach_bound_other_than_minus_one_is_refused():
    with pytest.raises(BadParamsError, match="simulate.approach_max_m must be -1"):
        SimulateParams(approach_max_m=-0.5)

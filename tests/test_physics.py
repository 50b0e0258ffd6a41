"""The physics check of a closed grasp (pipeline.checks.physics, stage ``check``): known outcomes on
analytic shapes."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from pipeline.checks.physics import PhysicsCheck, PhysicsSettings, convex_parts
from pipeline.geometry.mass import mesh_volume
from pipeline.hands.spec import HANDS
from pipeline.trial.engine import GraspEngine
from test_simulation import cube, surface


@pytest.fixture(scope="module")
def jaw_on_cube():
    """The jaw squeezing a 4 cm cube across two faces (the trial engine's force-closure
    grasp along a face normal) and the check of that cube."""
    engine = GraspEngine(cube(), HANDS["parallel_jaw"])
    result = engine.trial([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0])
    assert result.outcome == "force_closure"
    check = PhysicsCheck(cube().vertices, cube().faces, HANDS["parallel_jaw"], engine.model)
    yield result, check
    check.close()


def test_a_cube_is_one_convex_part_of_its_own_volume():
    """V-HACD of a convex box keeps it whole: one part whose hull is the 4 cm cube (64 cm^3),
    grown by V-HACD's voxels (65.9 cm^3 when written: within 5 %, never smaller)."""
    from pipeline.bullet import pybullet

    client = pybullet.connect(pybullet.DIRECT)
    try:
        parts = convex_parts(cube().vertices, cube().faces, client=client)
    finally:
        pybullet.disconnect(physicsClientId=client)
    assert len(parts) == 1
    assert 0.04**3 * (1 - 1e-6) <= ConvexHull(parts[0]).volume <= 0.04**3 * 1.05
    assert mesh_volume(cube().vertices, cube().faces) == pytest.approx(0.04**3, rel=1e-9)


def test_the_jaw_squeezing_a_cube_holds_it_through_the_lift_and_the_shake(jaw_on_cube):
    """32 g of cube between two pads pressing with 20 N each: held. The two fingers are
    force-limited servos of their own, so a push along the closing axis shifts the cube and
    both pads with it (under a shake of its own weight): slip under 2 cm, hardly a turn."""
    result, check = jaw_on_cube
    physics = check.check(result.base_position, result.base_orientation, result.joint_positions)
    assert physics.outcome == "held" and physics.success
    assert physics.slip_m < 0.02 and physics.turn_rad < 0.05


def test_the_check_is_deterministic(jaw_on_cube):
    result, check = jaw_on_cube
    first = check.check(result.base_position, result.base_orientation, result.joint_positions)
    again = check.check(result.base_position, result.base_orientation, result.joint_positions)
    assert first == again


def test_a_jaw_closing_beside_the_cube_has_no_grasp_and_one_on_it_grips_it(jaw_on_cube):
    """The jaw 10 cm beside the cube closes on air: no_grasp. Opened fully where the trial
    closed it, it closes (the squeeze drives the pads to their limit) onto the cube and holds."""
    result, check = jaw_on_cube
    beside = np.asarray(result.base_position) + [0.1, 0.0, 0.0]
    assert check.check(beside, result.base_orientation, result.joint_positions).outcome == "no_grasp"
    assert check.check(result.base_position, result.base_orientation, (0.0, 0.0)).outcome == "held"


@pytest.mark.parametrize("name", ["barrett", "armar3"])
def test_fingertips_on_a_sphere_wider_than_the_hand_drop_it(name):
    """A 20 cm ball (2 kg at 500 kg/m^3) touched by the fingertips only (the trial: no force
    closure, distal links touching): it falls out of the hand."""
    ball = surface("primitive:sphere", radius=0.1)
    engine = GraspEngine(ball, HANDS[name])
    result = engine.trial([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0])
    assert result.outcome == "no_force_closure" and all("distal" in link for link in result.touched)
    check = PhysicsCheck(ball.vertices, ball.faces, HANDS[name], engine.model)
    physics = check.check(result.base_position, result.base_orientation, result.joint_positions)
    check.close()
    assert physics.outcome in ("dropped", "no_grasp") and not physics.success
    assert np.isnan(physics.slip_m) or physics.slip_m > 1.0  # it fell far


def test_a_plate_resting_on_the_fingertips_holds_against_gravity_but_not_a_sideways_shake():
    """A 16 x 16 x 2 cm plate (256 g) on the jaw's pad tips, the hand under it (approach +z):
    the trial's contacts all lie on the bottom face, so epsilon is 0 (no force closure), yet the plate rests
    on the pads. The check says so: without shakes it is held; a shake of one body weight
    sideways beats the pads' friction (mu 0.5 x its weight) and the plate slides off."""
    plate = surface("primitive:box", extents=(0.16, 0.16, 0.02))
    engine = GraspEngine(plate, HANDS["parallel_jaw"])
    result = engine.trial([0.0, 0.0, -0.01], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    assert result.outcome == "no_force_closure" and result.epsilon == 0.0
    assert np.allclose(result.contact_points[:, 2], -0.01)  # every contact on the bottom face
    pose = (result.base_position, result.base_orientation, result.joint_positions)
    still = PhysicsSettings.defaults()
    check = PhysicsCheck(
        plate.vertices, plate.faces, HANDS["parallel_jaw"], engine.model, parts=[plate.vertices], settings=still
    )
    try:
        shaken = check.check(*pose)
        check.settings = dataclasses.replace(still, shake_g=0.0)
        lifted = check.check(*pose)
    finally:
        check.close()
    assert lifted.outcome == "held" and lifted.slip_m < 0.005
    assert shaken.outcome in ("dropped", "slipped") and shaken.slip_m > 0.05


def test_the_parts_of_the_half_size_object_are_its_full_size_parts_halved(tmp_path):
    """Stage ``decompose`` runs V-HACD once per object, and each scale's check scales its parts:
    V-HACD voxelises the mesh's own box, so the table (legs under a top: six parts) at half
    size decomposes into its full-size parts, halved (to V-HACD's rounding of 0.5 um)."""
    from pipeline.checks.physics import ConvexParts, decompose
    from pipeline.geometry.sampling import sample_object
    from pipeline.params import SampleParams

    def table(scale):
        options = {**dataclasses.asdict(SampleParams()), "count": 2000}
        return sample_object("primitive:table", scale=scale, rng=np.random.default_rng(0), **options)

    full = decompose(table(1.0), vhacd_resolution=100_000)
    half = decompose(table(0.5), vhacd_resolution=100_000, scale=0.5)
    assert full.scale == 1.0 and len(full.parts) == len(half.parts) == 6
    halved = full.at_scale(0.5)
    assert halved.scale == 0.5 and np.array_equal(halved.part_start, half.part_start)
    np.testing.assert_allclose(halved.vertices, half.vertices, rtol=0, atol=1e-6)
    assert full.at_scale(1.0) is full and halved.key != full.key
    halved.save(tmp_path / "parts.npz")
    loaded = ConvexParts.load(tmp_path / "parts.npz")
    assert (loaded.scale, loaded.key) == (0.5, halved.key) and np.array_equal(loaded.vertices, halved.vertices)

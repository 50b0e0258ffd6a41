"""The MuJoCo lift-and-shake (pipeline.checks.mujoco_check) beside pybullet's (pipeline.checks.physics): the same
known outcomes on analytic shapes from both engines, MuJoCo's open start, the URDF's mimic joint
as an equality constraint, determinism."""

import dataclasses

import numpy as np
import pytest

from pipeline.bullet import pybullet
from pipeline.checks.mujoco_check import MujocoCheck, MujocoSettings, build_spec
from pipeline.geometry.mass import inertia
from pipeline.checks.physics import PhysicsCheck, PhysicsSettings
from pipeline.hands.kinematics import base_poses
from pipeline.hands.spec import HANDS, Finger
from pipeline.outputs.evaluate import InPlaceEngine
from pipeline.params import CheckParams, SimulateParams
from test_simulation import cube, surface

ENGINES = ("pybullet", "mujoco")
DOWN = (np.array([[0.0, 0.0, -1.0]]), np.array([[1.0, 0.0, 0.0]]))  # approach -z (hand above), P_o along x


def franka_coupled():
    """The Panda hand as its URDF has it: ``panda_finger_joint2`` a ``<mimic>`` of joint 1 (the
    built-in ``franka`` releases it: each finger a closing group of its own)."""
    franka = HANDS["franka"]
    limits = franka.limits["panda_finger_joint1"]
    return dataclasses.replace(
        franka,
        name="franka_coupled",
        fingers=(Finger(("panda_finger_joint1",), (-1.0,)),),
        limits={"panda_finger_joint1": limits},
        preshapes={"parallel": {"panda_finger_joint1": limits[1]}},
    )


def make_check(engine, shape, hand, model, physics=None):
    """The check of ``engine`` on the convex ``shape`` (its own vertices: one part)."""
    physics = physics or PhysicsSettings.defaults()
    if engine == "pybullet":
        return PhysicsCheck(shape.vertices, shape.faces, hand, model, parts=[shape.vertices], settings=physics)
    return MujocoCheck(
        shape.vertices, shape.faces, hand, model, parts=[shape.vertices], settings=MujocoSettings(physics)
    )


def placed(shape, hand, grasp):
    """The hand with its grasp centre at ``grasp`` (3,), approaching down, closed in place:
    (TrialResult, engine, open joints (J,))."""
    engine = InPlaceEngine(shape, hand)
    opened = np.array([hand.preshape()[joint] for joint in engine.model.joints])
    (result,) = engine.close_in_place(base_poses(hand, np.array([grasp], float), *DOWN), opened[None])
    return result, engine, opened


def final_joints(engine, check, names):
    """Every named joint's value (rad or m) in ``check``'s simulation now."""
    if engine == "pybullet":
        return np.array([check._call(pybullet.getJointState, check.hand, check.joint_index[name])[0] for name in names])
    return np.array([check.data.qpos[check.qpos[name]] for name in names])


@pytest.fixture(scope="module")
def jaw_on_cube():
    """The jaw closed in place across two faces of a 4 cm cube (force closure)."""
    result, engine, opened = placed(cube(), HANDS["parallel_jaw"], [0.0, 0.0, 0.0])
    assert result.outcome == "force_closure"
    return result, engine, opened


def pose(result):
    return result.base_position, result.base_orientation, result.joint_positions


def starts(engine, check, result, opened):
    """The check of ``result``'s closed hand, and on MuJoCo also from the open hand; the check closed."""
    try:
        found = [check.check(*pose(result))]
        if engine == "mujoco":
            found.append(check.check(*pose(result), open_joints=opened))
    finally:
        check.close()
    return found


@pytest.mark.parametrize("engine", ENGINES)
def test_the_jaw_squeezing_a_cube_holds_it_and_one_beside_it_has_no_grasp(jaw_on_cube, engine):
    """32 g of cube between two pads pressing with 20 N each: held through the lift and the
    shake (slip under the 2 cm threshold: a shake along the closing axis carries both
    force-limited pads and the cube with it; hardly a turn). The jaw 10 cm beside it closes on
    air: no_grasp. On MuJoCo the open start (the pads closing from fully open on the free
    cube) holds it too."""
    result, model_engine, opened = jaw_on_cube
    check = make_check(engine, cube(), HANDS["parallel_jaw"], model_engine.model)
    try:
        held = check.check(*pose(result))
        beside = check.check(np.add(result.base_position, [0.1, 0.0, 0.0]), *pose(result)[1:])
        starts = [held]
        if engine == "mujoco":
            starts.append(check.check(*pose(result), open_joints=opened))
            assert (
                check.check(
                    np.add(result.base_position, [0.1, 0.0, 0.0]), *pose(result)[1:], open_joints=opened
                ).outcome
                == "no_grasp"
            )
    finally:
        check.close()
    for physics in starts:
        assert physics.outcome == "held" and physics.slip_m < 0.02 and physics.turn_rad < 0.05
    assert beside.outcome == "no_grasp" and np.isnan(beside.slip_m)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["barrett", "armar3"])
def test_fingertips_on_a_ball_wider_than_the_hand_drop_it(engine, name):
    """A 20 cm ball (2 kg at 500 kg/m^3) touched by the distal links only (no force closure):
    it falls out of the hand, on both engines and from both of MuJoCo's starts."""
    ball = surface("primitive:sphere", radius=0.1)
    model_engine = InPlaceEngine(ball, HANDS[name])
    result = model_engine.trial([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0])
    assert result.outcome == "no_force_closure" and all("distal" in link for link in result.touched)
    check = make_check(engine, ball, HANDS[name], model_engine.model)
    opened = np.array([HANDS[name].preshape()[joint] for joint in model_engine.model.joints])
    found = starts(engine, check, result, opened)
    for physics in found:
        assert physics.outcome in ("dropped", "no_grasp") and not physics.success
        assert np.isnan(physics.slip_m) or physics.slip_m > 1.0  # it fell far


@pytest.mark.parametrize("engine", ENGINES)
def test_pads_whose_edges_press_on_a_balls_upper_half_squeeze_it_out(engine):
    """The jaw's pads end 15 mm above the centre of a 6 cm ball, so they touch it with their
    lower edges, where its normal points 30 deg below the horizontal: beyond the friction cone
    (atan 0.5 = 26.6 deg) every contact force pushes the ball down, out of the hand. The
    kinematic close says no force closure; both engines lose the ball before the lift."""
    ball = surface("primitive:sphere", radius=0.03)
    result, model_engine, opened = placed(ball, HANDS["parallel_jaw"], [0.0, 0.0, 0.043])
    assert result.outcome == "no_force_closure" and set(result.touched) == {"left_pad", "right_pad"}
    assert (result.contact_points[:, 2] > 0.01).all()  # on the upper half
    check = make_check(engine, ball, HANDS["parallel_jaw"], model_engine.model)
    found = starts(engine, check, result, opened)
    assert all(physics.outcome in ("no_grasp", "dropped") for physics in found)


def test_the_open_start_centres_a_cube_that_a_coupled_pinch_stops_on_one_pad():
    """The Panda with its fingers coupled (the URDF's mimic), placed 1 cm off the cube's centre
    along the closing axis: the kinematic close stops both fingers when the first pad touches
    the cube, which cannot move there, so one pad touches and the grasp is no force closure.
    On MuJoCo the free cube is pushed to the middle by the first pad until the second meets
    it: held, both pads touching, the equality constraint keeping the fingers within 0.5 mm of
    each other."""
    hand = franka_coupled()
    result, model_engine, opened = placed(cube(), hand, [0.0, 0.01, 0.0])
    assert result.outcome == "no_force_closure" and result.touched == ("panda_leftfinger",)
    check = make_check("mujoco", cube(), hand, model_engine.model)
    for start in ({}, {"open_joints": opened}):
        physics = check.check(*pose(result), **start)
        assert physics.outcome == "held" and physics.turn_rad < 0.05, start
        first, second = final_joints("mujoco", check, ["panda_finger_joint1", "panda_finger_joint2"])
        assert abs(first - second) < 5e-4 and abs(first - 0.02) < 1e-3  # centred on the 4 cm cube


@pytest.mark.parametrize("name", ["barrett", "armar3", "coupled"])
def test_the_servos_close_each_hand_to_the_same_joints_on_both_engines(name):
    """Far from the object, every joint (the Panda's mimic too) driven from the open preshape
    toward it plus the squeeze (0.5 rad, clipped; the Panda's fingers to their stop) ends the
    settle where the other engine's does: within 0.02 rad (the servos' own settling) or 0.5 mm."""
    hand = franka_coupled() if name == "coupled" else HANDS[name]
    model = InPlaceEngine(cube(), hand).model
    opened = np.array([hand.preshape()[joint] for joint in model.joints])
    names = list(model.joint_values(opened))
    found = {}
    for engine in ENGINES:
        check = make_check(engine, cube(), hand, model)
        try:
            assert check.check((1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), opened).outcome == "no_grasp"
            found[engine] = final_joints(engine, check, names)
        finally:
            check.close()
    expected = np.array(
        list(model.joint_values(np.clip(opened + 0.5 * np.sign(model.closing), model.lower, model.upper)).values())
    )
    tolerance = 5e-4 if name == "coupled" else 0.02
    np.testing.assert_allclose(found["mujoco"], found["pybullet"], atol=tolerance)
    np.testing.assert_allclose(found["mujoco"], expected, atol=tolerance)


def test_the_check_is_deterministic_and_keeps_no_state(jaw_on_cube):
    """The same check twice gives the same result, also after a different check in between."""
    result, model_engine, opened = jaw_on_cube
    check = make_check("mujoco", cube(), HANDS["parallel_jaw"], model_engine.model)
    first = check.check(*pose(result))
    check.check(*pose(result), open_joints=opened)
    check.check(np.add(result.base_position, [0.1, 0.0, 0.0]), *pose(result)[1:])
    assert check.check(*pose(result)) == first


def test_the_model_holds_the_parts_the_mass_and_the_coupling():
    """The object: one free body, one mesh geom per convex part (here two opposite faces of the
    cube, flat as V-HACD's parts of a thin plate can be: made 1 mm slabs), the stated mass, the
    cube's centre and inertia (m a^2 / 6 about each axis); the coupled Panda: one servo, its mimic an
    equality constraint (q2 = 0 + 1 x q1), the base a mocap body; no hand link collides with
    another."""
    shape = cube()
    hand = franka_coupled()
    model = InPlaceEngine(shape, hand).model
    mass = 0.2
    centre, moments = inertia(shape.vertices, shape.faces, mass)
    np.testing.assert_allclose(centre, 0.0, atol=1e-12)
    np.testing.assert_allclose(moments, [mass * 0.04**2 / 6] * 3 + [0.0] * 3, atol=1e-12)
    halves = [shape.vertices[shape.vertices[:, 0] <= 0], shape.vertices[shape.vertices[:, 0] >= 0]]
    settings = MujocoSettings.defaults()
    assert settings == MujocoSettings.from_params(CheckParams(), SimulateParams().mu)  # the params' defaults
    spec = build_spec(hand, model, halves, mass_kg=mass, centre=centre, inertia=moments, settings=settings)
    compiled = spec.compile()
    body = compiled.body("object")
    assert float(body.mass[0]) == mass and compiled.nmocap == 1 and compiled.nu == 1
    np.testing.assert_allclose(compiled.body_inertia[body.id], moments[:3], rtol=1e-9)
    assert (compiled.geom_bodyid == body.id).sum() == 2
    parts = np.flatnonzero(compiled.geom_bodyid == body.id)
    # each face a slab about x = -+2 cm (MuJoCo puts a mesh geom at its centroid), 1 mm thick
    np.testing.assert_allclose(np.sort(compiled.geom_pos[parts, 0]), [-0.02, 0.02], atol=1e-7)
    np.testing.assert_allclose(np.sort(compiled.geom_aabb[parts, 3:], axis=1), [[0.0005, 0.02, 0.02]] * 2, atol=1e-7)
    assert compiled.neq == 1 and compiled.eq_data[0][:2].tolist() == [0.0, 1.0]
    hand_geoms = compiled.geom_bodyid != body.id
    assert (compiled.geom_conaffinity[hand_geoms] == 0).all() and (compiled.geom_contype[~hand_geoms] == 0).all()
    assert (compiled.geom_condim == 4).all() and (compiled.geom_friction[:, 1] == settings.torsional_friction_m).all()


def test_a_simulation_that_blows_up_is_an_error_and_writes_no_log(jaw_on_cube, tmp_path, monkeypatch):
    """A shake of 1e20 body weights makes MuJoCo's accelerations overflow; MuJoCo then warns and
    resets the state itself, which would read as no_grasp: the check says ``error``, MuJoCo's
    default MUJOCO_LOG.TXT is not written into the working folder, and the next check is
    unaffected."""
    monkeypatch.chdir(tmp_path)
    result, model_engine, _ = jaw_on_cube
    check = make_check("mujoco", cube(), HANDS["parallel_jaw"], model_engine.model)
    normal = check.settings
    check.settings = MujocoSettings(dataclasses.replace(normal.physics, shake_g=1e20))
    blown = check.check(*pose(result))
    check.settings = normal
    assert blown.outcome == "error" and np.isnan(blown.slip_m)
    assert check.check(*pose(result)).outcome == "held"
    assert not list(tmp_path.iterdir())

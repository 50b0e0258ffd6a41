"""Pictures of the hands, open (the default preshape) and closed, from pybullet's software
renderer (headless: no display or GPU needed)."""

import numpy as np

from ..bullet import load_hand_body, pybullet

#: view direction of ``frame="scene"`` pictures, weights of the hand's wrap, side and approach axes
SCENE_VIEW = (0.8, 0.35, -0.25)


def closed_joints(hand):
    """{joint: value} of the hand closed on nothing: every finger driven through its coupling
    until its first joint reaches a limit."""
    joints = hand.preshape()
    for finger in hand.fingers:

        def room(joint, ratio):  # closing parameter left until the joint's limit
            lower, upper = hand.limits[joint]
            return (upper - joints[joint]) / ratio if ratio > 0 else (lower - joints[joint]) / ratio

        travel = min(room(joint, ratio) for joint, ratio in zip(finger.joints, finger.ratios) if ratio != 0)
        for joint, ratio in zip(finger.joints, finger.ratios):
            lower, upper = hand.limits[joint]
            joints[joint] = float(np.clip(joints[joint] + ratio * travel, lower, upper))
    return joints


def _with_mimics(hand, joints):
    """``joints`` plus the values of the URDF's mimic joints (pybullet ignores <mimic>)."""
    from ..hands.kinematics import hand_model

    model = hand_model(hand)
    if not model.mimics:
        return joints
    return {**model.joint_values([joints[name] for name in model.joints]), **joints}


def render_hand(
    hand, joints, *, base=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)), surface=None, size=(480, 480), frame="hand"
):
    """(height, width, 3) uint8 image of ``hand`` in the joint state ``joints`` (name -> value)
    at the base pose ``base`` (position, quaternion x y z w), with the object mesh of
    ``surface`` (SurfaceSamples) if given. ``frame="hand"``: a three-quarter view framed on
    the open hand, with the approach axis up. ``frame="scene"``: a view mostly along the wrap
    axis (:data:`SCENE_VIEW`, fingers in profile), object frame z up, framed on the posed hand
    and the part of the mesh near it."""
    if frame not in ("hand", "scene"):
        raise ValueError(f"frame must be 'hand' or 'scene', got {frame!r}")
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = load_hand_body(hand, client)
        names = {
            pybullet.getJointInfo(body, index, physicsClientId=client)[1].decode(): index
            for index in range(pybullet.getNumJoints(body, physicsClientId=client))
        }
        rotation = np.array(pybullet.getMatrixFromQuaternion(base[1])).reshape(3, 3)
        # frame the open hand, in its own frame, so open and closed pictures match
        # pybullet places a base by its inertial frame; ``base`` is the URDF base frame's pose
        inertial = pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[3:5]

        def place(position, quaternion):
            pybullet.resetBasePositionAndOrientation(
                body,
                *pybullet.multiplyTransforms(tuple(position), tuple(quaternion), *inertial),
                physicsClientId=client,
            )

        place((0, 0, 0), (0, 0, 0, 1))
        for joint, value in _with_mimics(hand, hand.preshape()).items():
            pybullet.resetJointState(body, names[joint], value, physicsClientId=client)
        boxes = np.array([pybullet.getAABB(body, index, physicsClientId=client) for index in [-1, *names.values()]])
        low, high = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
        up = np.asarray(hand.approach, float)
        side = np.cross(up, hand.wrap)
        target = (low + high) / 2
        eye = target + 1.7 * np.linalg.norm(high - low) * (0.55 * np.asarray(hand.wrap) + 0.75 * side + 0.35 * up)
        target, eye, up = (rotation @ target + base[0], rotation @ eye + base[0], rotation @ up)
        place(base[0], base[1])
        for joint, value in _with_mimics(hand, joints).items():
            pybullet.resetJointState(body, names[joint], value, physicsClientId=client)
        if frame == "scene":  # fingers in profile, object frame z up, framed on the hand and the mesh near it
            boxes = np.array([pybullet.getAABB(body, index, physicsClientId=client) for index in [-1, *names.values()]])
            low, high = boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)
            if surface is not None and len(surface.vertices):
                margin = 0.5 * np.linalg.norm(high - low)  # a large object is shown around the hand only
                low = np.minimum(low, np.maximum(surface.vertices.min(axis=0), low - margin))
                high = np.maximum(high, np.minimum(surface.vertices.max(axis=0), high + margin))
            direction = rotation @ (
                SCENE_VIEW[0] * np.asarray(hand.wrap) + SCENE_VIEW[1] * side + SCENE_VIEW[2] * np.asarray(hand.approach)
            )
            direction /= np.linalg.norm(direction)
            up = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else rotation @ np.asarray(hand.approach)
            target = (low + high) / 2
            eye = target + 1.4 * np.linalg.norm(high - low) * direction
        if surface is not None:
            shape = pybullet.createVisualShape(
                pybullet.GEOM_MESH,
                vertices=surface.vertices.tolist(),
                indices=surface.faces.ravel().tolist(),
                rgbaColor=(0.85, 0.55, 0.25, 1.0),
                physicsClientId=client,
            )
            pybullet.createMultiBody(0, baseVisualShapeIndex=shape, physicsClientId=client)
        view = pybullet.computeViewMatrix(eye.tolist(), target.tolist(), up.tolist(), physicsClientId=client)
        projection = pybullet.computeProjectionMatrixFOV(40, size[0] / size[1], 0.01, 10, physicsClientId=client)
        image = pybullet.getCameraImage(
            size[0],
            size[1],
            view,
            projection,
            renderer=pybullet.ER_TINY_RENDERER,
            lightDirection=(eye - target).tolist(),
            physicsClientId=client,
        )[2]
        return np.asarray(image, np.uint8).reshape(size[1], size[0], 4)[..., :3]
    finally:
        pybullet.disconnect(physicsClientId=client)


def render_open_closed(hand, path, *, surface=None, target=None, size=(480, 480)):
    """Write a PNG of ``hand`` open (left) and closed (right) side by side; returns the path.

    With ``surface`` and ``target`` (P_g, P_d, P_o) the hand runs that grasp trial and the
    right picture shows it closed on the object; without, it closes on nothing."""
    from PIL import Image

    from ..artefacts import atomic_write

    if surface is None:
        pictures = [render_hand(hand, hand.preshape(), size=size), render_hand(hand, closed_joints(hand), size=size)]
    else:
        from ..trial.engine import GraspEngine

        result = GraspEngine(surface, hand).trial(*target)
        base = (result.base_position, result.base_orientation)
        closed = dict(zip(hand.limits, result.joint_positions))
        pictures = [
            render_hand(hand, hand.preshape(), base=base, surface=surface, size=size),
            render_hand(hand, closed, base=base, surface=surface, size=size),
        ]
    image = np.concatenate(pictures, axis=1)
    atomic_write(path, lambda stream: Image.fromarray(image).save(stream, format="PNG"))
    return path


def render_builtin_hands(folder, *, size=(400, 400)):
    """``<folder>/<hand>.png`` for every built-in hand: the parallel jaws on a 4 cm cube, the
    others on a 5 cm cylinder, approached orthogonally; returns the paths."""
    from pathlib import Path

    from ..geometry.sampling import sample_object
    from ..hands.spec import HANDS
    from ..params import SampleParams

    def surface(shape, **keywords):
        return sample_object(
            f"primitive:{shape}", shape=keywords, rng=np.random.default_rng(0), source_key=shape, **vars(SampleParams())
        )

    scenes = {"box": surface("box", extents=[0.04] * 3), "cylinder": surface("cylinder", radius=0.025, height=0.12)}
    target = ([0.0, 0.0, 0.01], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    return [
        render_open_closed(
            hand,
            Path(folder) / f"{name}.png",
            size=size,
            target=target,
            surface=scenes["box" if name in ("parallel_jaw", "franka") else "cylinder"],
        )
        for name, hand in HANDS.items()
    ]

"""Physics check of a closed grasp: does the hand hold the object in a dynamic
simulation, as the grasp datasets judge (DexGraspNet, DexGraspBench)?

The check starts from a trial's closed hand (:class:`pipeline.trial.engine.TrialResult`: base
pose and joints) and runs pybullet's dynamics (headless, its own client):

- the object is a dynamic body made of convex parts (pybullet can only move convex shapes;
  :func:`convex_parts`: pybullet's built-in V-HACD), its mass its mesh volume times
  ``density_kg_m3`` but at most ``payload_kg`` (:func:`object_mass`: an object heavier than the
  payload is checked at the payload, so a held rate describes grasps, not weights), its
  friction ``mu``;
- the hand is held still, fixed in the world, every joint (mimics included) a position servo
  limited to the hand's ``joint_effort`` (:data:`EFFORT` by joint kind unless its spec says):
  it starts opened by ``open_back`` (rad or m along each joint's closing direction) and is
  driven toward the closed pose closed further by ``squeeze`` (clipped at the joint limits),
  far enough past the object that a touching joint pushes at its effort limit: a constant grip,
  as a hand closing under its motors' torque. Gravity is on from the start (in the hand's
  frame, lifting the hand at a constant speed is the object under gravity). For ``settle_s``
  the object is damped (``settle_damping``, Bullet's velocity damping): it settles where the
  fingers' forces and its weight balance, or slides out of a hand whose forces cannot balance
  (a pinch on a slope, pads squeezing a wedge);
- then, undamped, the lift (``lift_s``, the time a 10 cm lift takes) and the shake: each along
  +-x, +-y, +-z (world) is a force of ``shake_g`` times the object's weight, ``shake_s`` each,
  on top of gravity, as DexGraspBench applies external forces.

Outcome: ``no_grasp`` (the object touches no hand link after the settle), ``dropped`` (no
link touches it at the end), ``slipped`` (it moved more than ``slip_m`` or turned more than
``slip_rad`` relative to the hand, still touching), ``held``; ``slip_m`` is how far its centre
moved from where the settle left it.

The object's convex parts are an artefact of their own (:class:`ConvexParts`, stage
``decompose``), computed once per object and scale; the checks of a run's trials are
:func:`pipeline.checks.protocol.check_trials` (stage ``check``).

On real meshes the parts bulge about 1.5 mm past the mesh (V-HACD voxels), so a closed hand
starts within -0.5..+0.6 mm of them. Most grasps the kinematic trial calls force closure drop a
light curved object such as the duck (docs/checks.md): two opposing fingertips let it turn about
the line through them under gravity (a point contact resists no torque about its normal), a
third contact pressing from above carries none of the weight, and pads squeezing a curved side
push it out (the kinematic force closure counts every point within the 2 mm tolerance; the
squeezing pads touch only the first ones).
"""

import os
import tempfile
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..artefacts import _Artefact, content_key
from ..bullet import BulletClient, load_hand_body, pybullet
from ..errors import DegenerateGeometryError
from ..geometry.mass import centre_of_mass, mesh_volume

#: the servo limit of a joint whose hand does not give ``joint_effort``: N (prismatic), N m
EFFORT = {"prismatic": 20.0, "revolute": 1.5}


@dataclass(frozen=True)
class PhysicsSettings:
    """How the check runs: the ``checks`` params of the same names (their defaults and
    documentation live in :class:`pipeline.params.CheckParams`), the friction ``mu`` of the
    trials, and the simulation's time step. SI units."""

    mu: float
    density_kg_m3: float
    open_back: float
    squeeze: float
    settle_damping: float
    settle_s: float
    lift_s: float
    shake_g: float
    shake_s: float
    slip_m: float
    slip_rad: float
    payload_kg: float = -1.0
    timestep_s: float = 1.0 / 240.0

    @classmethod
    def defaults(cls):
        """The settings of the default params."""
        from ..params import CheckParams, SimulateParams

        return cls(**CheckParams().physics_settings(SimulateParams().mu))


@dataclass(frozen=True)
class PhysicsResult:
    """``outcome`` (no_grasp, dropped, slipped, held), ``slip_m`` (m) and ``turn_rad`` of the
    object relative to the hand from the end of the settle to the end."""

    outcome: str
    slip_m: float = float("nan")
    turn_rad: float = float("nan")

    @property
    def success(self):
        return self.outcome == "held"


def _quietly(action):
    """Run ``action()`` with this process's stdout silenced (V-HACD prints its progress there)."""
    import sys

    sys.stdout.flush()
    saved, devnull = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        return action()
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


def convex_parts(vertices, faces, *, client, resolution=1000000):
    """The convex parts (list of (v, 3) float vertex arrays, m) of a closed mesh, by pybullet's
    V-HACD with ``resolution`` voxels (deterministic for the same mesh)."""
    import trimesh

    with tempfile.TemporaryDirectory() as folder:
        source, target = os.path.join(folder, "object.obj"), os.path.join(folder, "parts.obj")
        trimesh.Trimesh(vertices, faces, process=False).export(source)
        log = os.path.join(folder, "log.txt")
        _quietly(lambda: pybullet.vhacd(source, target, log, resolution=resolution, physicsClientId=client))
        parts, current = [], []
        with open(target) as stream:
            for line in stream:
                if line.startswith("o ") and current:
                    parts.append(np.array(current))
                    current = []
                elif line.startswith("v "):
                    current.append([float(value) for value in line.split()[1:4]])
        if current:
            parts.append(np.array(current))
    return parts


@dataclass(frozen=True)
class ConvexParts(_Artefact):
    """An object's convex decomposition (``parts.npz``, stage ``decompose``): ``vertices``
    (v, 3) float64 m, the parts' vertices one part after another, part k in rows
    ``part_start[k]:part_start[k + 1]`` ((p + 1,) int64), of the object at ``scale`` (the
    factor of its size it was decomposed at: :meth:`at_scale` gives the parts at another);
    ``mass_kg`` is not stored (it depends on the density)."""

    vertices: np.ndarray
    part_start: np.ndarray
    scale: float
    key: str

    KIND = "convex_parts"
    ARRAYS = {"vertices": (np.float64, 3), "part_start": (np.int64, None)}

    @property
    def parts(self):
        """The parts as a list of (v_k, 3) arrays."""
        return [self.vertices[a:b] for a, b in zip(self.part_start[:-1], self.part_start[1:])]

    def at_scale(self, scale):
        """The parts of the object at ``scale``: the vertices times ``scale / self.scale``; these
        parts themselves at their own scale. The sampled mesh at a scale is the object's mesh
        times it, and V-HACD voxelises the mesh's own box, so the parts it finds at another
        scale are mostly these scaled (x0.5 against x1.0: to 0.5 um on 13 of the 14 default
        objects; on the octopus 12 of its 21 parts differ)."""
        if scale == self.scale:
            return self
        key = content_key("at_scale", {"scale": scale}, self.key)
        return ConvexParts(self.vertices * (scale / self.scale), self.part_start, scale=scale, key=key)


def decompose(surface, *, vhacd_resolution=1000000, physics=True, scale=1.0):
    """The :class:`ConvexParts` of ``surface``'s mesh (a SurfaceSamples with faces, of the object
    at ``scale``), by V-HACD with ``vhacd_resolution`` voxels; none without the ``physics``
    checks, which alone use them."""
    if not physics:
        key = content_key("decompose", {"vhacd_resolution": vhacd_resolution, "physics": False}, surface.key)
        return ConvexParts(np.empty((0, 3)), np.zeros(1, np.int64), scale=scale, key=key)
    client = BulletClient()
    try:
        parts = convex_parts(surface.vertices, surface.faces, client=client.client, resolution=vhacd_resolution)
    finally:
        client.close()
    if not parts:
        raise DegenerateGeometryError(f"{surface.source}: V-HACD found no convex part of the mesh")
    sizes = [len(part) for part in parts]
    return ConvexParts(
        np.concatenate(parts) if parts else np.empty((0, 3)),
        np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        scale=scale,
        key=content_key("decompose", {"vhacd_resolution": vhacd_resolution}, surface.key),
    )


def object_mass(settings, vertices, faces):
    """The checked object's mass (kg): its mesh volume times ``settings.density_kg_m3``, at most
    ``settings.payload_kg`` (the graspable-mass rule; -1: no cap)."""
    mass = settings.density_kg_m3 * mesh_volume(vertices, faces)
    return mass if settings.payload_kg < 0 else min(mass, settings.payload_kg)


class PhysicsCheck(BulletClient):
    """Checks closed grasps of one hand on one object (see the module docstring).

    Parameters
    ----------
    vertices, faces : the object's closed mesh (m, object frame = world)
    hand : pipeline.hands.spec.Hand
    model : pipeline.hands.kinematics.HandModel
        The hand's model (joint order, closing directions, mimics).
    parts : list of (v, 3) float, optional
        The object's convex parts (:func:`convex_parts`; computed here if not given).
    settings : PhysicsSettings, optional
        Default: :meth:`PhysicsSettings.defaults`. The servos' force limit is the hand's
        ``joint_effort``.
    """

    def __init__(self, vertices, faces, hand, model, *, parts=None, settings=None):
        self.settings, self.model = settings or PhysicsSettings.defaults(), model
        super().__init__()
        try:
            self._build(vertices, faces, hand, parts)
        except BaseException:
            self.close()  # a failed set-up leaves no pybullet client behind
            raise

    def _build(self, vertices, faces, hand, parts):
        settings, call = self.settings, self._call
        call(pybullet.setTimeStep, settings.timestep_s)
        parts = convex_parts(vertices, faces, client=self.client) if parts is None else parts
        shape = self._compound(parts)
        self.mass = object_mass(settings, vertices, faces)
        # pybullet's base position is the centre of mass: the mesh's own, so torques are right
        self.centre = tuple(centre_of_mass(np.asarray(vertices, float), np.asarray(faces)))
        self.object = call(
            pybullet.createMultiBody, self.mass, shape, baseInertialFramePosition=self.centre, basePosition=self.centre
        )
        call(pybullet.changeDynamics, self.object, -1, lateralFriction=settings.mu)
        self.hand = load_hand_body(hand, self.client)
        info = [call(pybullet.getJointInfo, self.hand, k) for k in range(call(pybullet.getNumJoints, self.hand))]
        self.joint_index = {row[1].decode(): row[0] for row in info}
        # each joint's grip: the hand's effort, else the default of its kind
        kinds = {row[1].decode(): ("prismatic" if row[2] == pybullet.JOINT_PRISMATIC else "revolute") for row in info}
        self.effort = {name: hand.joint_effort or EFFORT[kind] for name, kind in kinds.items()}
        for link in range(-1, len(info)):
            call(pybullet.changeDynamics, self.hand, link, lateralFriction=1.0)
        self.base_inertial = call(pybullet.getDynamicsInfo, self.hand, -1)[3:5]
        self.saved = call(pybullet.saveState)

    def _compound(self, parts):
        """One collision shape of the convex ``parts``: an OBJ file with an object per part,
        which pybullet reads as a compound of their hulls."""
        from scipy.spatial import ConvexHull, QhullError

        lines, offset = [], 1
        for number, part in enumerate(parts):
            try:
                hull = ConvexHull(part)
            except QhullError:  # a flat part (V-HACD on a thin plate): joggled into a solid
                hull = ConvexHull(part, qhull_options="QJ")
            lines.append(f"o part{number}")
            lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in part]
            lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in hull.simplices]
            offset += len(part)
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "parts.obj")
            with open(path, "w") as stream:
                stream.write("\n".join(lines) + "\n")
            return self._call(pybullet.createCollisionShape, pybullet.GEOM_MESH, fileName=path)

    def _drive(self, q):
        """Position targets ``q`` (J,) for every moving joint, mimics through the model."""
        for name, value in self.model.joint_values(q).items():
            self._call(
                pybullet.setJointMotorControl2,
                self.hand,
                self.joint_index[name],
                pybullet.POSITION_CONTROL,
                targetPosition=value,
                force=self.effort[name],
            )

    def _touching(self):
        return len(self._call(pybullet.getContactPoints, self.hand, self.object)) > 0

    def _steps(self, seconds, force=None):
        for _ in range(max(int(round(seconds / self.settings.timestep_s)), 1)):
            if force is not None:
                position = self._call(pybullet.getBasePositionAndOrientation, self.object)[0]
                self._call(pybullet.applyExternalForce, self.object, -1, force.tolist(), position, pybullet.WORLD_FRAME)
            self._call(pybullet.stepSimulation)

    def check(self, base_position, base_orientation, joints):
        """Check one closed grasp: the hand's URDF base at ``base_position`` (3,) m with
        ``base_orientation`` (4,) quaternion x y z w, ``joints`` (J,) in the model's order.
        Returns a :class:`PhysicsResult`."""
        settings, model, call = self.settings, self.model, self._call
        call(pybullet.restoreState, self.saved)
        call(pybullet.setGravity, 0.0, 0.0, -9.81)
        call(pybullet.resetBasePositionAndOrientation, self.object, self.centre, [0.0, 0.0, 0.0, 1.0])
        call(pybullet.resetBaseVelocity, self.object, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        position, orientation = pybullet.multiplyTransforms(
            tuple(base_position), tuple(base_orientation), *self.base_inertial
        )
        call(pybullet.resetBasePositionAndOrientation, self.hand, position, orientation)
        direction = np.sign(model.closing)
        closed = np.asarray(joints, float)
        start = np.clip(closed - settings.open_back * direction, model.lower, model.upper)
        for name, value in model.joint_values(start).items():
            call(pybullet.resetJointState, self.hand, self.joint_index[name], value)
        self._drive(np.clip(closed + settings.squeeze * direction, model.lower, model.upper))
        damping = settings.settle_damping
        call(pybullet.changeDynamics, self.object, -1, linearDamping=damping, angularDamping=damping)
        self._steps(settings.settle_s)
        call(pybullet.changeDynamics, self.object, -1, linearDamping=0.0, angularDamping=0.0)
        if not self._touching():
            return PhysicsResult("no_grasp")
        hand_pose = call(pybullet.getBasePositionAndOrientation, self.hand)
        held_at = self._relative(hand_pose)
        weight = self.mass * 9.81
        self._steps(settings.lift_s)
        for axis in range(3):
            for sign in (1.0, -1.0):
                force = np.zeros(3)
                force[axis] = sign * settings.shake_g * weight
                self._steps(settings.shake_s, force)
        moved = self._relative(hand_pose)
        slip = float(np.linalg.norm(moved[0] - held_at[0]))
        turn = float((Rotation.from_quat(moved[1]) * Rotation.from_quat(held_at[1]).inv()).magnitude())
        if not self._touching():
            return PhysicsResult("dropped", slip, turn)
        if slip > settings.slip_m or turn > settings.slip_rad:
            return PhysicsResult("slipped", slip, turn)
        return PhysicsResult("held", slip, turn)

    def _relative(self, hand_pose):
        """The object's pose (position, quaternion) in the hand's base frame."""
        position, orientation = self._call(pybullet.getBasePositionAndOrientation, self.object)
        inverse = pybullet.invertTransform(*hand_pose)
        moved = pybullet.multiplyTransforms(*inverse, position, orientation)
        return np.asarray(moved[0]), np.asarray(moved[1])

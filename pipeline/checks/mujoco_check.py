"""A second physics opinion: the lift-and-shake of :mod:`pipeline.checks.physics` on MuJoCo,
with soft contacts, elliptic friction cones and torsional friction.

The protocol is pybullet's check (:class:`pipeline.checks.physics.PhysicsCheck`, the same
:class:`~pipeline.checks.physics.PhysicsSettings`, the same outcomes): a hand held still at the grasp's
base pose, every actuated joint a position servo limited to the hand's ``joint_effort``, driven
``squeeze`` past the closed pose; gravity; the object damped for ``settle_s``, then undamped for
``lift_s`` and a shake of ``shake_g`` body weights along +-x, +-y, +-z (world), ``shake_s`` each;
``no_grasp`` / ``dropped`` / ``slipped`` / ``held`` by the same thresholds. What differs is the
contact model and one more way to start:

- **Model** (:func:`build_spec`): the object is a free body made of its convex parts (one mesh
  geom each: MuJoCo collides a mesh's hull), its mass stated, its centre of mass and inertia
  those of the closed mesh at that mass; the hand is its URDF (a built-in's generated text, a
  file hand's subtree with its collision meshes) on a mocap body at the base pose, a URDF
  ``<mimic>`` joint an equality constraint on its leader (MuJoCo's URDF reader drops ``<mimic>``).
  Contacts are MuJoCo's soft ones with elliptic cones, ``condim`` 4 (sliding and torsional
  friction: a pinch resists a turn about the line through its contacts, which a point contact
  cannot), friction ``mu`` on both sides and ``torsional_friction_m``; the hand's links do not
  collide with each other.
- **Two starts**: ``closed`` (the trial's closed joints opened by ``open_back``, as pybullet's
  check) and ``open`` (:meth:`MujocoCheck.check` with ``open_joints``: the hand opened to its
  preshape, closing for ``close_s`` under its servos on a free object without gravity, which may
  shift and turn while the fingers close, as FleX's and the MuJoCo benchmarks' grippers close;
  then the same settle, lift and shake). The open start needs no kinematic trial at all: a
  grasp whose fingers stop one by one against an object that cannot move (a pinch the
  kinematic close scores as no force closure) gets its chance to centre.

Every check restarts from the same state (``mj_resetData``), so it depends only on its inputs.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import DegenerateGeometryError
from ..geometry.mass import inertia
from .physics import EFFORT, PhysicsResult, PhysicsSettings, object_mass

#: starts of a check: from the trial's closed joints, or from the open hand
STARTS = ("closed", "open")
GRAVITY = 9.81


@dataclass(frozen=True)
class MujocoSettings:
    """MuJoCo's own knobs; the protocol is ``physics`` (:class:`PhysicsSettings`, pybullet's).
    SI units: ``torsional_friction_m`` is MuJoCo's torsional coefficient (m: the radius of the
    patch whose friction resists a turn about the normal), ``close_s`` the open start's closing
    time, ``servo_error`` (rad or m) the joint error at which a servo's force reaches its limit, ``impratio`` MuJoCo's
    ratio of frictional to normal constraint impedance."""

    physics: PhysicsSettings
    torsional_friction_m: float = 0.005
    condim: int = 4
    close_s: float = 0.5
    timestep_s: float = 0.002
    servo_error: float = 0.005
    impratio: float = 10.0

    @classmethod
    def defaults(cls):
        return cls(PhysicsSettings.defaults())

    @classmethod
    def from_params(cls, checks, mu):
        """The settings of :class:`pipeline.params.CheckParams` ``checks`` at friction ``mu``."""
        physics = PhysicsSettings(**checks.physics_settings(mu))
        return cls(physics, torsional_friction_m=checks.torsional_friction_m, close_s=checks.close_s)


def _mujoco():
    import mujoco

    # MuJoCo's default warning handler prints and appends to MUJOCO_LOG.TXT in the working folder
    # (a stage's or the user's); the one warning that matters here, an unstable step (MuJoCo then
    # resets the state itself), is read from the data's counters instead (MujocoCheck._steps)
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(lambda message: None)
    return mujoco


def solid_part(part, *, thickness=0.001):
    """A convex part (v, 3) MuJoCo can take a hull of: a flat or straight one (V-HACD on a thin
    plate; fewer than 3 dimensions) made a slab ``thickness`` m thick about itself, else as is."""
    part = np.asarray(part, np.float64)
    _, spread, axes = np.linalg.svd(part - part.mean(axis=0), full_matrices=True)
    spread = np.concatenate([spread, np.zeros(3 - len(spread))])
    flat = axes[spread <= 1e-9 * max(spread[0], 1e-12)]
    for axis in flat:
        part = np.concatenate([part - 0.5 * thickness * axis, part + 0.5 * thickness * axis])
    return part


def hand_urdf(hand):
    """The hand's URDF text as MuJoCo should read it: mesh paths kept whole, no static links
    fused, visual shapes dropped."""
    from ..hands.spec import hand_urdf_text

    options = '<mujoco><compiler strippath="false" fusestatic="false" discardvisual="true"/></mujoco>'
    return hand_urdf_text(hand).replace("</robot>", options + "</robot>", 1)


def build_spec(hand, model, parts, *, mass_kg, centre, inertia, settings):
    """The MjSpec of ``hand`` (its URDF; :class:`pipeline.hands.kinematics.HandModel` ``model``) and an
    object of convex ``parts`` (list of (v, 3) float, m, object frame = world) weighing
    ``mass_kg`` with its centre of mass ``centre`` (3,) and ``inertia`` (6,) (:func:`pipeline.geometry.mass.inertia`).
    Names: body ``object`` (free joint ``object``), actuators ``servo:<joint>``, the hand's
    base body a mocap body."""
    mujoco = _mujoco()
    mu = settings.physics.mu
    friction = [mu, settings.torsional_friction_m, 0.0]
    # MuJoCo's contact stiffness scales with the bodies' mass: at its defaults (0.02 s, impedance
    # 0.9-0.95 over 1 mm) a 20 N pad sinks 2 cm into a 32 g cube. Two time steps and 0.95-0.99
    # over 0.5 mm keep it under 0.1 mm
    contact = ([2 * settings.timestep_s, 1.0], [0.95, 0.99, 0.0005, 0.5, 2.0])
    spec = mujoco.MjSpec.from_string(hand_urdf(hand))
    spec.option.timestep = settings.timestep_s
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -GRAVITY]
    spec.option.impratio = (
        settings.impratio
    )  # elliptic cones: friction stiffer than the normal, so a held pinch does not creep
    # several contacts between two flat faces (a pad on a box face), not one: the pad resists a turn
    spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_MULTICCD
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.boundmass, spec.compiler.boundinertia = 1e-3, 1e-7  # a URDF link without <inertial>
    base = spec.body(model.links[0])
    base.mocap = True
    for geom in spec.geoms:  # the hand's: contype 1 meets the object's conaffinity 1, never its own links
        geom.contype, geom.conaffinity = 1, 0
        geom.condim, geom.friction = settings.condim, friction
        geom.solref, geom.solimp = contact
    for joint in spec.joints:
        joint.armature = 1e-3  # the servos' stiffness stays stable at the time step
        joint.damping = 0.0
    body = spec.worldbody.add_body(name="object")
    body.add_freejoint(name="object")
    body.explicitinertial = True
    body.mass, body.ipos, body.fullinertia = float(mass_kg), list(map(float, centre)), list(map(float, inertia))
    for number, part in enumerate(parts):
        mesh = spec.add_mesh(name=f"part{number}")
        mesh.uservert = solid_part(part).reshape(-1).tolist()
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL  # no volume needed: a flat V-HACD part loads
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh.name,
            contype=0,
            conaffinity=1,
            condim=settings.condim,
            friction=friction,
            solref=contact[0],
            solimp=contact[1],
        )
    effort = {}
    for number, name in enumerate(model.joints):
        prismatic = bool(model.prismatic[list(model.driver).index(number)])
        effort[name] = hand.joint_effort or EFFORT["prismatic" if prismatic else "revolute"]
        servo = spec.add_actuator(name=f"servo:{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        gain = effort[name] / settings.servo_error
        servo.set_to_position(kp=gain, kv=0.05 * gain)
        servo.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        servo.forcerange = [-effort[name], effort[name]]
    for name, link in model.mimics:
        leader = model.joints[model.driver[link]]
        equality = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=name, name2=leader)
        equality.data[:2] = [float(model.offset[link]), float(model.multiplier[link])]
        equality.solref, equality.solimp = contact  # MuJoCo's default lets a 20 N grip stretch it 4 mm
    return spec


class _Unstable(Exception):
    """MuJoCo's state became NaN or infinite (an unstable contact): the check's outcome is ``error``."""


class MujocoCheck:
    """Checks grasps of one hand on one object on MuJoCo (see the module docstring); the
    interface of :class:`pipeline.checks.physics.PhysicsCheck`.

    Parameters
    ----------
    vertices, faces : the object's closed mesh (m, object frame = world)
    hand : pipeline.hands.spec.Hand
    model : pipeline.hands.kinematics.HandModel
    parts : list of (v, 3) float
        The object's convex parts (stage ``decompose``; the mesh itself when convex).
    settings : MujocoSettings, optional
    """

    def __init__(self, vertices, faces, hand, model, *, parts, settings=None):
        mujoco = _mujoco()
        self.settings = settings or MujocoSettings.defaults()
        self.model = model
        physics = self.settings.physics
        self.mass = object_mass(physics, vertices, faces)
        centre, moments = inertia(vertices, faces, self.mass)
        spec = build_spec(hand, model, parts, mass_kg=self.mass, centre=centre, inertia=moments, settings=self.settings)
        try:
            self.mj = spec.compile()
        except ValueError as err:
            raise DegenerateGeometryError(f"MuJoCo cannot build {hand.name} with the object: {err}") from None
        self.data = mujoco.MjData(self.mj)
        self.object = self.mj.body("object").id
        joint = self.mj.joint("object")
        self.object_qpos, self.object_dof = int(joint.qposadr[0]), int(joint.dofadr[0])
        self.hand_bodies = np.array(
            [self.mj.body_rootid[b] == self.mj.body(model.links[0]).id for b in range(self.mj.nbody)]
        )
        self.qpos = {
            name: int(self.mj.joint(name).qposadr[0]) for name in model.joint_values(np.zeros(len(model.joints)))
        }
        self.servo = [self.mj.actuator(f"servo:{name}").id for name in model.joints]
        # the settle's damping: pybullet's velocity damping d (a fraction per second) is the
        # exponential rate -ln(1 - d), here as a viscous force on the object's six velocities
        rate = -np.log(1.0 - physics.settle_damping)
        rotational = float(np.mean(moments[:3]))
        self.settle_damping = rate * np.array([self.mass] * 3 + [rotational] * 3)

    def close(self):
        """Nothing to release (the interface of :class:`pipeline.checks.physics.PhysicsCheck`)."""

    def _steps(self, seconds):
        mujoco = _mujoco()
        count = max(int(round(seconds / self.mj.opt.timestep)), 1)
        mujoco.mj_step(self.mj, self.data, nstep=count)
        # an unstable step (NaN or huge accelerations): MuJoCo warns and resets the state to the
        # model's initial one, which would read as no_grasp
        if self.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number or not np.isfinite(self.data.qpos).all():
            raise _Unstable

    def _touching(self):
        count = self.data.ncon
        if not count:
            return False
        bodies = self.mj.geom_bodyid[np.stack([self.data.contact.geom1[:count], self.data.contact.geom2[:count]])]
        return bool(((bodies == self.object).any(axis=0) & self.hand_bodies[bodies].any(axis=0)).any())

    def _object_in_hand(self, hand_position, hand_rotation):
        """The object's centre of mass (3,) and orientation (Rotation) in the hand's base frame."""
        centre = hand_rotation.inv().apply(self.data.xipos[self.object] - hand_position)
        quaternion = self.data.xquat[self.object]  # w x y z
        return centre, hand_rotation.inv() * Rotation.from_quat(quaternion[[1, 2, 3, 0]])

    def _set_joints(self, q):
        for name, value in self.model.joint_values(q).items():
            self.data.qpos[self.qpos[name]] = value

    def check(self, base_position, base_orientation, joints, *, open_joints=None):
        """Check one grasp: the hand's URDF base at ``base_position`` (3,) m with
        ``base_orientation`` (4,) quaternion x y z w; ``joints`` (J,) its closed joints in the
        model's order. With ``open_joints`` (J,) the check starts from the open hand closing on
        the free object (the ``open`` start), else from ``joints`` opened by ``open_back``.
        Returns a :class:`pipeline.checks.physics.PhysicsResult` (``error`` if the simulation blew up)."""
        try:
            return self._check(base_position, base_orientation, joints, open_joints)
        except _Unstable:
            return PhysicsResult("error")

    def _check(self, base_position, base_orientation, joints, open_joints):
        mujoco = _mujoco()
        settings, physics, model = self.settings, self.settings.physics, self.model
        data = self.data
        mujoco.mj_resetData(self.mj, data)
        data.mocap_pos[0] = base_position
        data.mocap_quat[0] = np.asarray(base_orientation, float)[[3, 0, 1, 2]]
        direction = np.sign(model.closing)
        closed = np.asarray(joints, float)
        target = np.clip(closed + physics.squeeze * direction, model.lower, model.upper)
        data.ctrl[self.servo] = target
        damping = self.mj.dof_damping[self.object_dof : self.object_dof + 6]
        if open_joints is not None:
            self._set_joints(np.clip(np.asarray(open_joints, float), model.lower, model.upper))
            data.ctrl[self.servo] = np.where(direction > 0, model.upper, np.where(direction < 0, model.lower, target))
            self.mj.opt.gravity[:] = 0.0
            damping[:] = 0.0
            mujoco.mj_forward(self.mj, data)
            self._steps(settings.close_s)
            self.mj.opt.gravity[:] = [0.0, 0.0, -GRAVITY]
        else:
            self._set_joints(np.clip(closed - physics.open_back * direction, model.lower, model.upper))
        damping[:] = self.settle_damping
        try:
            self._steps(physics.settle_s)
        finally:
            damping[:] = 0.0
        if not self._touching():
            return PhysicsResult("no_grasp")
        hand_position, hand_rotation = np.array(data.mocap_pos[0]), Rotation.from_quat(base_orientation)
        held_at = self._object_in_hand(hand_position, hand_rotation)
        self._steps(physics.lift_s)
        weight = self.mass * GRAVITY
        for axis in range(3):
            for sign in (1.0, -1.0):
                data.xfrc_applied[self.object, :3] = 0.0
                data.xfrc_applied[self.object, axis] = sign * physics.shake_g * weight
                self._steps(physics.shake_s)
        data.xfrc_applied[self.object] = 0.0
        moved = self._object_in_hand(hand_position, hand_rotation)
        slip = float(np.linalg.norm(moved[0] - held_at[0]))
        turn = float((moved[1] * held_at[1].inv()).magnitude())
        if not self._touching():
            return PhysicsResult("dropped", slip, turn)
        if slip > physics.slip_m or turn > physics.slip_rad:
            return PhysicsResult("slipped", slip, turn)
        return PhysicsResult("held", slip, turn)

"""Robot hands: kinematics, limits and preshapes, declared in one place per hand.

A hand is a URDF (links with box, sphere, cylinder, capsule or mesh collision shapes, several
per link; revolute and prismatic joints; ``<mimic>`` joints; read by :mod:`pipeline.hands.urdf`) plus
the declarations the planner needs, in the hand's base frame (metres, radians):

- ``approach``: unit axis the palm faces; the hand moves along it toward the object (P_d).
- ``wrap``: unit axis the fingers wrap about (P_o), orthogonal to ``approach``.
- ``grasp_centre``: the point placed at the grasp target P_g.
- ``fingers``: closing groups; each lists its joints from the palm outward with coupling ratios
  (joint velocity = ratio x the finger's closing speed; a negative ratio closes toward the
  lower limit). A URDF ``<mimic>`` joint follows its leader unless a finger lists it.
- ``limits``: joint name -> (lower, upper); in a spec, optional (the URDF's by default).
- ``base_link``: the hand's root link when its URDF is a larger robot (default: the URDF's root).
- ``preshapes``: name -> {joint: value} of the open hand; unnamed joints sit at their lower
  limit. The first preshape is the default; every hand has ``parallel``.
- ``max_graspable_diameter``: the largest sphere the hand can hold (paper IV).
- ``joint_effort``: the force (N, prismatic) or torque (N m, revolute) each joint's servo
  squeezes with in the physics check (:mod:`pipeline.checks.physics`); optional in a spec. The
  default (None, the built-ins too): 20 N for a prismatic joint (about a Franka finger's
  continuous force), 1.5 N m for a revolute one (about 15 N at a Barrett fingertip).

Built-in hands are generated from published kinematics in the common frame
``approach = +z``, ``wrap = +x``, palm top at the finger joint plane:

- ``barrett``: BH8-280. Palm 89 x 89 x 75.4 mm; finger 3 at (0, -50, 75.4) mm; fingers 1 and 2
  on spread axes at x = +-25 mm (spread 0..pi, opposite senses), proximal joints 50 mm out;
  proximal 0..2.44 rad, link 70 mm; distal 0..0.84 rad = 0.344 x proximal, link 55 mm.
- ``armar3``: ARMAR-III-like. Four fingers in a row at x = -37.8, -10.8, 13.2, 35.2 mm (the
  published 0/27/51/73 mm spacing, centred), proximal 40.2 mm, distal 58.8 / 58.8 / 51.3 /
  43.8 mm; a thumb (phalanges 40.2 and 58.8 mm) on a palm joint (-pi/2..pi/2). The real palm
  faces the object with the thumb 48.9 mm in front of it; folded into the common frame, the
  finger row and the thumb sit at y = +-47 mm so the open hand spans the published 9.4 cm
  graspable diameter. Finger joints 0..pi/2 (the model's 0..pi folds fingers through the palm).
  One actuator per digit: distal = 0.5 x proximal, so the proximal phalanx meets the object first
  and the tip wraps on (with 1:1 the tips met a 5 cm cylinder beyond its axis, pushing it out of
  the hand, and 20 of 36 grasps failed).
- ``parallel_jaw``: Franka-like. Two 20 x 8 x 50 mm pads on prismatic joints, 0-80 mm stroke.
- ``franka``: the Panda hand itself, read in place from pybullet_data (see :func:`_franka`).

A user's hand is a URDF plus a YAML (or TOML) spec with the same keys (see :func:`export_hand`,
which writes a built-in hand in that form); ``--hand path/to/spec.yaml`` works wherever a built-in
name does.
"""

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ..errors import BadParamsError
from .urdf import read_urdf


@dataclass(frozen=True)
class Finger:
    """A closing group: joints from the palm outward and their coupling ratios."""

    joints: tuple
    ratios: tuple


@dataclass(frozen=True)
class Link:
    """A box-shaped link: full ``size`` (3,) metres, box centre ``centre`` (3,) in the link frame."""

    name: str
    size: tuple
    centre: tuple = (0.0, 0.0, 0.0)
    rgba: tuple = (0.55, 0.57, 0.62, 1.0)


@dataclass(frozen=True)
class Joint:
    """A URDF joint: ``origin`` (3,) metres in the parent frame, ``axis`` (3,) unit."""

    name: str
    parent: str
    child: str
    kind: str
    origin: tuple
    axis: tuple = (1.0, 0.0, 0.0)


@dataclass(frozen=True)
class Hand:
    """A hand's planning declarations (see the module docstring); ``urdf`` is a file path or
    None for a built-in hand, whose URDF :func:`urdf_text` writes from ``links``/``joints``."""

    name: str
    max_graspable_diameter: float
    preshapes: dict = field(default_factory=lambda: {"parallel": {}})
    approach: tuple = (0.0, 0.0, 1.0)
    wrap: tuple = (1.0, 0.0, 0.0)
    grasp_centre: tuple = (0.0, 0.0, 0.0)
    fingers: tuple = ()
    limits: dict = field(default_factory=dict)
    links: tuple = ()
    joints: tuple = ()
    urdf: str = None
    base_link: str = None
    joint_effort: float = None

    def key(self):
        """A hashable summary of everything that defines the hand (for caches)."""
        return (
            self.name,
            self.urdf,
            self.base_link,
            self.approach,
            self.wrap,
            self.grasp_centre,
            self.fingers,
            tuple(self.limits.items()),
            tuple((k, tuple(v.items())) for k, v in self.preshapes.items()),
            self.links,
            self.joints,
        )

    @property
    def default_preshape(self):
        return next(iter(self.preshapes))

    def preshape(self, name=None):
        """{joint: value} of the open hand for preshape ``name`` (default: the first)."""
        name = name or self.default_preshape
        if name not in self.preshapes:
            raise BadParamsError(f"hand {self.name}: unknown preshape {name!r} (has: {', '.join(self.preshapes)})")
        values = {joint: lower for joint, (lower, _) in self.limits.items()}
        values.update(self.preshapes[name])
        return values


def _finger_chain(prefix, parent, origin, axis, lengths, *, width=0.022, thickness=0.018, spread=None):
    """Links and joints of a straight finger pointing +z, closing about ``axis``."""
    links, joints = [], []
    if spread is not None:  # a knuckle on a spread axis, the proximal joint ``spread[1]`` out
        spread_axis, offset = spread
        links.append(Link(f"{prefix}_knuckle", (width, 0.02, 0.01), (0.0, 0.0, -0.005)))
        joints.append(Joint(f"{prefix}_spread", parent, f"{prefix}_knuckle", "revolute", origin, spread_axis))
        parent, origin = f"{prefix}_knuckle", offset
    for segment, length in zip(("proximal", "distal"), lengths):
        links.append(Link(f"{prefix}_{segment}", (width, thickness, length), (0.0, 0.0, length / 2)))
        joints.append(Joint(f"{prefix}_{segment[:4]}", parent, f"{prefix}_{segment}", "revolute", origin, axis))
        parent, origin = f"{prefix}_{segment}", (0.0, 0.0, length)
    return links, joints


def _barrett():
    palm_top = 0.0754
    links, joints = [Link("palm", (0.089, 0.089, palm_top), (0.0, 0.0, palm_top / 2), (0.2, 0.2, 0.22, 1.0))], []
    for prefix, x, spread_axis in (("f1", 0.025, (0.0, 0.0, -1.0)), ("f2", -0.025, (0.0, 0.0, 1.0))):
        chain = _finger_chain(
            prefix, "palm", (x, 0.0, palm_top), (1.0, 0.0, 0.0), (0.070, 0.055), spread=(spread_axis, (0.0, 0.05, 0.0))
        )
        links += chain[0]
        joints += chain[1]
    chain = _finger_chain("f3", "palm", (0.0, -0.05, palm_top), (-1.0, 0.0, 0.0), (0.070, 0.055))
    links += chain[0]
    joints += chain[1]
    limits = {"f1_spread": (0.0, math.pi), "f2_spread": (0.0, math.pi)}
    fingers = []
    for prefix in ("f1", "f2", "f3"):
        limits.update({f"{prefix}_prox": (0.0, 2.44), f"{prefix}_dist": (0.0, 0.84)})
        fingers.append(Finger((f"{prefix}_prox", f"{prefix}_dist"), (1.0, 0.344)))
    return Hand(
        "barrett",
        0.14,
        {"parallel": {}},
        grasp_centre=(0.0, 0.0, palm_top + 0.035),
        fingers=tuple(fingers),
        limits=limits,
        links=tuple(links),
        joints=tuple(joints),
    )


def _armar3():
    palm_top = 0.0404
    links = [Link("palm", (0.10, 0.12, palm_top), (0.0, 0.0, palm_top / 2), (0.25, 0.3, 0.45, 1.0))]
    joints, fingers, limits = [], [], {}
    for prefix, x, distal in (
        ("index", -0.0378, 0.0588),
        ("middle", -0.0108, 0.0588),
        ("ring", 0.0132, 0.0513),
        ("pinky", 0.0352, 0.0438),
    ):
        chain = _finger_chain(
            prefix, "palm", (x, 0.047, palm_top), (1.0, 0.0, 0.0), (0.0402, distal), width=0.018, thickness=0.016
        )
        links += chain[0]
        joints += chain[1]
        fingers.append(Finger((f"{prefix}_prox", f"{prefix}_dist"), (1.0, 0.5)))
        limits.update({f"{prefix}_prox": (0.0, math.pi / 2), f"{prefix}_dist": (0.0, math.pi / 2)})
    # the thumb: a metacarpal on the palm joint, then two phalanges, all closing about -x
    links.append(Link("thumb_metacarpal", (0.02, 0.018, 0.02), (0.0, 0.0, 0.01)))
    joints.append(
        Joint("thumb_palm", "palm", "thumb_metacarpal", "revolute", (-0.0243, -0.047, 0.02925), (-1.0, 0.0, 0.0))
    )
    chain = _finger_chain(
        "thumb", "thumb_metacarpal", (0.0, 0.0, 0.02), (-1.0, 0.0, 0.0), (0.0402, 0.0588), width=0.02, thickness=0.018
    )
    links += chain[0]
    joints += chain[1]
    fingers.append(Finger(("thumb_palm", "thumb_prox", "thumb_dist"), (1.0, 1.0, 0.5)))
    limits.update(
        {"thumb_palm": (-math.pi / 2, math.pi / 2), "thumb_prox": (0.0, math.pi / 2), "thumb_dist": (0.0, math.pi / 2)}
    )
    preshapes = {
        "parallel": {"thumb_palm": -0.2},
        "power": {"thumb_palm": -0.2, "index_prox": 0.3, "middle_prox": 0.3, "ring_prox": 0.3, "pinky_prox": 0.3},
        "precision": {"thumb_palm": 0.2},
    }
    return Hand(
        "armar3",
        0.094,
        preshapes,
        grasp_centre=(0.0, 0.0, palm_top + 0.035),
        fingers=tuple(fingers),
        limits=limits,
        links=tuple(links),
        joints=tuple(joints),
    )


def _parallel_jaw():
    palm_top = 0.06
    links = [Link("palm", (0.05, 0.20, palm_top), (0.0, 0.0, palm_top / 2), (0.85, 0.85, 0.88, 1.0))]
    joints, fingers, limits = [], [], {}
    for name, side in (("left", 1.0), ("right", -1.0)):
        links.append(Link(f"{name}_pad", (0.02, 0.008, 0.05), (0.0, side * 0.004, 0.025), (0.3, 0.3, 0.32, 1.0)))
        joints.append(
            Joint(f"{name}_slide", "palm", f"{name}_pad", "prismatic", (0.0, side * 0.04, palm_top), (0.0, -side, 0.0))
        )
        fingers.append(Finger((f"{name}_slide",), (1.0,)))
        limits[f"{name}_slide"] = (0.0, 0.04)
    return Hand(
        "parallel_jaw",
        0.08,
        {"parallel": {}},
        grasp_centre=(0.0, 0.0, palm_top + 0.025),
        fingers=tuple(fingers),
        limits=limits,
        links=tuple(links),
        joints=tuple(joints),
    )


def _franka():
    """The Franka Emika Panda hand, read in place from pybullet_data's ``franka_panda/panda.urdf``
    (the subtree from ``panda_hand``, its collision meshes ``meshes/collision/*.obj``). Its two
    prismatic fingers open toward their upper limit (0.04 m each, the 80 mm stroke), so they close
    with ratio -1. In the URDF the second finger is a ``<mimic>`` of the first: on an object that
    cannot move, that coupling would stop both fingers at the first touch, where the real gripper
    (or the object) shifts until both touch. As for ``parallel_jaw``, each finger is therefore a
    closing group of its own, the kinematic trial's stand-in for that centring (a spec that lists
    a mimic joint as a finger releases it). The grasp centre is the URDF's own
    ``panda_grasptarget`` (105 mm along +z, the approach axis)."""
    import pybullet_data

    from .urdf import read_urdf

    urdf = str(Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf")
    robot = read_urdf(urdf, base_link="panda_hand")
    names = ("panda_finger_joint1", "panda_finger_joint2")
    limits = {name: robot.joint(name).limits for name in names}
    return Hand(
        "franka",
        0.08,
        {"parallel": {name: limits[name][1] for name in names}},
        grasp_centre=(0.0, 0.0, 0.105),
        fingers=tuple(Finger((name,), (-1.0,)) for name in names),
        limits=limits,
        urdf=urdf,
        base_link="panda_hand",
    )


HANDS = {hand.name: hand for hand in (_armar3(), _barrett(), _parallel_jaw(), _franka())}
SPEC_SUFFIXES = (".yaml", ".yml", ".toml")


def is_spec_path(name):
    """Whether ``name`` names a hand spec file rather than a built-in hand."""
    return str(name).endswith(SPEC_SUFFIXES)


def get_hand(name):
    """A built-in hand by name, or a user hand from a ``.yaml``/``.yml``/``.toml`` spec path."""
    if is_spec_path(name):
        return load_hand(name)
    if name not in HANDS:
        raise BadParamsError(f"unknown hand {name!r} (built-in: {', '.join(HANDS)}; or a spec .yaml/.toml)")
    return HANDS[name]


def urdf_text(hand):
    """The URDF of a built-in hand: box links with equal visual and collision shapes."""

    def vec(values):
        return " ".join(f"{value:.6g}" for value in values)

    lines = ['<?xml version="1.0"?>', f'<robot name="{hand.name}">']
    for link in hand.links:
        box = f'<origin xyz="{vec(link.centre)}"/><geometry><box size="{vec(link.size)}"/></geometry>'
        lines += [
            f'  <link name="{link.name}">',
            '    <inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>',
            f'    <visual>{box}<material name="{link.name}_colour"><color rgba="{vec(link.rgba)}"/></material></visual>',
            f"    <collision>{box}</collision>",
            "  </link>",
        ]
    for joint in hand.joints:
        lower, upper = hand.limits[joint.name]
        lines += [
            f'  <joint name="{joint.name}" type="{joint.kind}">',
            f'    <parent link="{joint.parent}"/><child link="{joint.child}"/>',
            f'    <origin xyz="{vec(joint.origin)}"/><axis xyz="{vec(joint.axis)}"/>',
            f'    <limit lower="{lower:.6g}" upper="{upper:.6g}" effort="10" velocity="1"/>',
            "  </joint>",
        ]
    return "\n".join(lines + ["</robot>", ""])


def hand_urdf_text(hand):
    """A URDF of the hand alone, rooted at its base frame (a file hand's mesh paths made absolute)."""
    from .urdf import subtree_text

    return urdf_text(hand) if hand.urdf is None else subtree_text(hand.urdf, hand.base_link)


def spec_dict(hand, urdf_name):
    """The YAML-ready spec of ``hand`` referring to the URDF file ``urdf_name``."""
    spec = {
        "name": hand.name,
        "urdf": urdf_name,
        "max_graspable_diameter": hand.max_graspable_diameter,
        "approach": list(hand.approach),
        "wrap": list(hand.wrap),
        "grasp_centre": list(hand.grasp_centre),
        "fingers": [{"joints": list(finger.joints), "ratios": list(finger.ratios)} for finger in hand.fingers],
        "limits": {joint: list(bounds) for joint, bounds in hand.limits.items()},
        "preshapes": {name: dict(values) for name, values in hand.preshapes.items()},
    }
    if hand.base_link:
        spec["base_link"] = hand.base_link
    if hand.joint_effort is not None:
        spec["joint_effort"] = hand.joint_effort
    return spec


def export_hand(hand, folder):
    """Write ``<name>.urdf`` and ``<name>.yaml`` into ``folder``; returns the spec path."""
    from ..artefacts import atomic_write

    folder = Path(folder)
    if hand.urdf is None:
        urdf_name = f"{hand.name}.urdf"
        atomic_write(folder / urdf_name, lambda stream: stream.write(urdf_text(hand).encode()))
    else:  # a file hand's URDF is referred to where it is (its meshes sit beside it)
        urdf_name = str(Path(hand.urdf).resolve())
    text = yaml.safe_dump(spec_dict(hand, urdf_name), sort_keys=False, default_flow_style=None).encode()
    atomic_write(folder / f"{hand.name}.yaml", lambda stream: stream.write(text))
    return folder / f"{hand.name}.yaml"


def load_hand(path):
    """A user hand from a YAML or TOML spec next to (or pointing at) its URDF."""
    path = Path(path)
    try:
        text = path.read_text()
        raw = tomllib.loads(text) if path.suffix == ".toml" else yaml.safe_load(text)
    except FileNotFoundError:
        raise BadParamsError(f"{path}: hand spec not found") from None
    except (yaml.YAMLError, tomllib.TOMLDecodeError) as err:
        raise BadParamsError(
            f"{path}: hand spec is not valid {path.suffix[1:].upper()} ({str(err).splitlines()[0]})"
        ) from None
    if not isinstance(raw, dict):
        raise BadParamsError(f"{path}: hand spec must be a mapping")
    required = ("name", "urdf", "max_graspable_diameter", "approach", "wrap", "grasp_centre", "fingers", "preshapes")
    optional = ("limits", "base_link", "joint_effort")  # the URDF's limits, its root, by joint kind
    missing = [key for key in required if key not in raw]
    if missing:
        raise BadParamsError(f"{path}: hand spec lacks {', '.join(missing)}")
    unknown = sorted(set(raw) - set(required) - set(optional))
    if unknown:
        raise BadParamsError(f"{path}: hand spec has unknown key {unknown[0]!r}")
    urdf = (path.parent / raw["urdf"]).resolve()
    if not urdf.is_file():
        raise BadParamsError(f"{path}: URDF {raw['urdf']!r} not found")
    base_link = None if raw.get("base_link") is None else str(raw["base_link"])
    try:
        robot = read_urdf(urdf, base_link=base_link)
    except BadParamsError as err:
        raise BadParamsError(f"{path}: {err}") from None
    try:
        fingers = tuple(Finger(tuple(map(str, f["joints"])), tuple(map(float, f["ratios"]))) for f in raw["fingers"])
        # a mimic joint that the spec lists as a finger is released from its leader
        movable = {joint.name: joint for joint in robot.joints if joint.kind != "fixed"}
        declared = [joint for finger in fingers for joint in finger.joints]
        unknown_joint = next((joint for joint in declared if joint not in movable), None)
        if unknown_joint is not None:
            raise BadParamsError(
                f"{path}: finger joint {unknown_joint!r} is not a movable joint of "
                f"{Path(urdf).name} below {robot.root!r}"
            )
        # the spec's limits in its order (the trials' joint order), the URDF's for joints it leaves out
        limits = {str(joint): (float(lo), float(hi)) for joint, (lo, hi) in (raw.get("limits") or {}).items()}
        limits.update({joint: movable[joint].limits for joint in declared if joint not in limits})
        preshapes = {
            str(name): {str(j): float(v) for j, v in (values or {}).items()}
            for name, values in raw["preshapes"].items()
        }
        approach, wrap, centre = (tuple(float(v) for v in raw[key]) for key in ("approach", "wrap", "grasp_centre"))
        diameter = float(raw["max_graspable_diameter"])
        effort = None if raw.get("joint_effort") is None else float(raw["joint_effort"])
    except (TypeError, ValueError, KeyError, AttributeError) as err:
        raise BadParamsError(f"{path}: malformed hand spec ({err})") from None
    problems = _spec_problems(fingers, limits, preshapes, approach, wrap, centre, diameter)
    unknown_joint = next((joint for joint in limits if robot.joint(joint) is None), None)
    if unknown_joint is not None:
        problems.insert(0, f"joint {unknown_joint!r} is not in {Path(urdf).name} below {robot.root!r}")
    if effort is not None and not (effort > 0 and math.isfinite(effort)):
        problems.append("joint_effort must be a positive number (N or N m)")
    if problems:
        raise BadParamsError(f"{path}: {problems[0]}")
    return Hand(
        str(raw["name"]),
        diameter,
        preshapes,
        approach,
        wrap,
        centre,
        fingers,
        limits,
        urdf=str(urdf),
        base_link=base_link,
        joint_effort=effort,
    )


def _spec_problems(fingers, limits, preshapes, approach, wrap, centre, diameter):
    problems = []
    if not (diameter > 0 and math.isfinite(diameter)):
        problems.append("max_graspable_diameter must be a positive number of metres")
    if len(approach) != 3 or len(wrap) != 3 or len(centre) != 3:
        problems.append("approach, wrap and grasp_centre must be 3-vectors")
    elif (
        abs(np.linalg.norm(approach) - 1) > 1e-6
        or abs(np.linalg.norm(wrap) - 1) > 1e-6
        or abs(np.dot(approach, wrap)) > 1e-6
    ):
        problems.append("approach and wrap must be orthogonal unit vectors")
    if not fingers:
        problems.append("fingers must list at least one closing group")
    for finger in fingers:
        if len(finger.joints) != len(finger.ratios) or not finger.joints:
            problems.append("each finger needs as many ratios as joints")
        missing = [joint for joint in finger.joints if joint not in limits]
        if missing:
            problems.append(f"finger joint {missing[0]!r} has no limits")
    if "parallel" not in preshapes:
        problems.append("preshapes must include 'parallel'")
    for values in preshapes.values():
        for joint, value in values.items():
            if joint not in limits or not limits[joint][0] <= value <= limits[joint][1]:
                problems.append(f"preshape joint {joint!r} unknown or outside its limits")
    return problems

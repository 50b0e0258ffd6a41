"""URDF reading: a robot hand's links, collision shapes and joints as plain data.

Only what a kinematic grasp trial needs is read: each link's ``<collision>`` elements (box,
sphere, cylinder, capsule, or a mesh file that trimesh reads: OBJ, STL, DAE, PLY), each joint's
type, parent, child, ``<origin xyz rpy>``, ``<axis>``, ``<limit>`` and ``<mimic>``. A hand can be
a subtree of a larger robot (``base_link``): the Franka Panda hand is ``panda_hand`` of the arm's
URDF. Mesh file names are resolved the way pybullet does: ``package://pkg/rest`` and
``file://`` prefixes are dropped and the rest is looked up beside the URDF, then up its folders.

pybullet ignores ``<mimic>``; here it is read, and :mod:`pipeline.hands.kinematics` enforces it.
"""

import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadParamsError

JOINT_KINDS = ("revolute", "continuous", "prismatic", "fixed")


@dataclass(frozen=True)
class Shape:
    """One collision shape: ``kind`` box | sphere | cylinder | capsule | mesh, ``size`` (box: full
    extents; sphere: (radius,); cylinder and capsule: (radius, length); mesh: scale (3,)),
    ``mesh`` the resolved file path, ``pose`` (4, 4) in the link frame (metres)."""

    kind: str
    size: tuple
    pose: np.ndarray
    mesh: str = ""


@dataclass(frozen=True)
class UrdfJoint:
    """A joint: ``origin`` (4, 4) child joint frame in the parent link frame, ``axis`` (3,) unit;
    ``limits`` (lower, upper) in rad or m; ``mimic`` (leader, multiplier, offset) or None."""

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    limits: tuple
    mimic: tuple = None


@dataclass(frozen=True)
class Robot:
    """A kinematic tree from ``root``: its links' collision shapes and its joints, parents first."""

    name: str
    root: str
    shapes: dict
    joints: tuple
    path: str

    def joint(self, name):
        return next((joint for joint in self.joints if joint.name == name), None)


def pose_matrix(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)):
    """(4, 4) transform of a URDF ``<origin>``: fixed-axis roll, pitch, yaw (Rz Ry Rx), then xyz."""
    roll, pitch, yaw = rpy
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    pose = np.eye(4)
    pose[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    pose[:3, 3] = xyz
    return pose


def _floats(text, count, where):
    try:
        values = tuple(float(value) for value in (text or "").split())
    except ValueError:
        values = ()
    if len(values) != count:
        raise BadParamsError(f"{where}: expected {count} numbers, got {text!r}")
    return values


def _origin(element, where):
    found = element.find("origin") if element is not None else None
    if found is None:
        return np.eye(4)
    return pose_matrix(_floats(found.get("xyz", "0 0 0"), 3, where), _floats(found.get("rpy", "0 0 0"), 3, where))


def resolve_mesh(filename, urdf_path):
    """The file a URDF mesh ``filename`` names, as pybullet finds it (see the module docstring)."""
    name = filename
    for prefix in ("file://", "package://"):
        if name.startswith(prefix):
            name = name[len(prefix) :]
    candidates = [Path(name)] if Path(name).is_absolute() else []
    parts = Path(name).parts
    folder = Path(urdf_path).resolve().parent
    for base in (folder, *folder.parents[:3]):
        candidates += [base / Path(*parts[start:]) for start in range(len(parts))]
    found = next((path for path in candidates if path.is_file()), None)
    if found is None:
        raise BadParamsError(f"{urdf_path}: collision mesh {filename!r} not found")
    return str(found)


def _shape(collision, urdf_path, where):
    geometry = collision.find("geometry")
    element = geometry[0] if geometry is not None and len(geometry) else None
    if element is None:
        raise BadParamsError(f"{where}: <collision> without a geometry")
    pose = _origin(collision, where)
    if element.tag == "box":
        return Shape("box", _floats(element.get("size"), 3, where), pose)
    if element.tag == "sphere":
        return Shape("sphere", _floats(element.get("radius"), 1, where), pose)
    if element.tag in ("cylinder", "capsule"):
        return Shape(
            element.tag, _floats(element.get("radius"), 1, where) + _floats(element.get("length"), 1, where), pose
        )
    if element.tag == "mesh":
        scale = _floats(element.get("scale", "1 1 1"), 3, where)
        return Shape("mesh", scale, pose, resolve_mesh(element.get("filename", ""), urdf_path))
    raise BadParamsError(f"{where}: unsupported collision geometry <{element.tag}>")


def read_urdf(path, *, base_link=None, text=None):
    """The kinematic tree of the URDF at ``path`` (or of ``text``, with ``path`` naming it), from
    ``base_link`` (default: the root link) down.

    Returns
    -------
    Robot

    Raises
    ------
    BadParamsError
        Unreadable XML, a missing ``base_link``, an unknown joint type, a mesh file not found.
    """
    try:
        root = ElementTree.fromstring(text) if text is not None else ElementTree.parse(path).getroot()
    except (ElementTree.ParseError, OSError) as err:
        raise BadParamsError(f"{path}: URDF cannot be read ({err})") from None
    links = {link.get("name"): link for link in root.findall("link")}
    children = {}
    joints = {}
    for element in root.findall("joint"):
        name, kind = element.get("name"), element.get("type")
        where = f"{path}: joint {name!r}"
        if kind not in JOINT_KINDS:
            raise BadParamsError(f"{where}: unsupported type {kind!r} (use {', '.join(JOINT_KINDS)})")
        parent, child = element.find("parent").get("link"), element.find("child").get("link")
        axis = np.array(
            _floats(element.find("axis").get("xyz"), 3, where) if element.find("axis") is not None else (1.0, 0.0, 0.0)
        )
        if kind != "fixed" and not np.linalg.norm(axis) > 0:
            raise BadParamsError(f"{where}: zero axis")
        limit = element.find("limit")
        if kind == "continuous" or limit is None:
            limits = (-np.pi, np.pi) if kind in ("revolute", "continuous") else (0.0, 0.0)
        else:
            limits = (float(limit.get("lower", 0.0)), float(limit.get("upper", 0.0)))
        mimic = element.find("mimic")
        if mimic is not None:
            mimic = (mimic.get("joint"), float(mimic.get("multiplier", 1.0)), float(mimic.get("offset", 0.0)))
        joints[child] = UrdfJoint(
            name,
            "revolute" if kind == "continuous" else kind,
            parent,
            child,
            _origin(element, where),
            axis / (np.linalg.norm(axis) or 1.0),
            limits,
            mimic,
        )
        children.setdefault(parent, []).append(child)
    if base_link is None:
        roots = [name for name in links if name not in joints]
        base_link = roots[0] if roots else None
    if base_link not in links:
        raise BadParamsError(f"{path}: base link {base_link!r} is not in the URDF")
    order, queue = [], [base_link]
    while queue:  # parents before children
        link = queue.pop(0)
        order.append(link)
        queue += children.get(link, [])
    shapes = {
        link: tuple(_shape(collision, path, f"{path}: link {link!r}") for collision in links[link].findall("collision"))
        for link in order
    }
    return Robot(root.get("name", ""), base_link, shapes, tuple(joints[link] for link in order[1:]), str(path))


def subtree_text(path, base_link):
    """URDF text of the subtree of ``path`` from ``base_link``, mesh file names made absolute, for
    loading a hand that is part of a larger robot into pybullet (which loads whole files)."""
    tree = ElementTree.parse(path)
    root = tree.getroot()
    robot = read_urdf(path, base_link=base_link)
    keep_links = {robot.root} | {joint.child for joint in robot.joints}
    keep_joints = {joint.name for joint in robot.joints}
    for element in list(root):
        if (element.tag == "link" and element.get("name") not in keep_links) or (
            element.tag == "joint" and element.get("name") not in keep_joints
        ):
            root.remove(element)
    for mesh in root.iter("mesh"):
        try:
            mesh.set("filename", resolve_mesh(mesh.get("filename", ""), path))
        except BadParamsError:  # a visual mesh that is not there: pybullet draws nothing for it
            pass
    return ElementTree.tostring(root, encoding="unicode")

"""Grasp sets made elsewhere: reading a grasp dataset's file and the gripper frame conventions
(``medial-grasp evaluate``; docs/evaluate.md).

Files read:

- ACRONYM's HDF5 layout as the dataset ships it: ``grasps/transforms`` (n, 4, 4), T_object_gripper
  in metres; ``object/file`` (a mesh, relative to the HDF5 file's folder unless absolute) times
  ``object/scale`` in its own coordinates, never recentred; ``object/mass`` (kg) and
  ``object/friction`` when present; ``gripper/type`` and ``gripper/configuration``;
  ``grasps/qualities/flex/object_in_gripper`` (0/1) as the file's own label when present;
- the project's own exports (``medial-grasp export``), HDF5 or JSON: the same keys, plus the
  simulated mesh (``object/vertices``, ``object/faces``) and each grasp's open joints
  (``grasps/pregrasp_joints``).

Gripper frames (:data:`GRIPPER_FRAMES`): a file's transform is the pose of its gripper's frame;
the trial engine places the hand's URDF base frame, ``T_object_base = T_object_gripper @
T_gripper_base``. ``panda`` is ACRONYM's Panda: approach +z, fingers along +-x; the built-in
``franka`` (pybullet_data's ``panda_hand``) has its fingers along +-y, the same hand turned
+90 degrees about z, so T_gripper_base = Rz(+90 deg). Its ``gripper/configuration`` (1,) is each
finger's opening (m, 0.04 fully open). Every other ``gripper/type`` is a hand's name (built in, or
a spec's): the frame is that hand's URDF base frame and ``gripper/configuration`` (J,) its open
joints in the hand's joint order. Without a configuration the hand opens to its default preshape.
"""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadInputError

#: the base frame of the built-in hand in a dataset gripper's frame: exact integers, so
#: T_object_gripper @ T_gripper_base and back moves no bit
GRIPPER_FRAMES = {
    "panda": ("franka", np.array([[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1.0]]))
}
#: dataset gripper names of the built-in hands that have one
DATASET_GRIPPER = {hand: gripper for gripper, (hand, _) in GRIPPER_FRAMES.items()}
LABEL = "grasps/qualities/flex/object_in_gripper"
#: an exported file's frame attribute for a dataset gripper's frame (the others: the URDF base frame)
DATASET_FRAMES = {
    "panda": "ACRONYM's Panda gripper frame: approach +z, fingers along +-x; the franka URDF's base frame "
    "(panda_hand, the same origin) is it turned +90 deg about z: T_gripper_base"
}
RIGID_TOLERANCE = 1e-6  # per entry of R^T R - I, and of the last row


@dataclass(frozen=True)
class GraspSet:
    """A grasp file's grasps, placed for one of this project's hands.

    ``transforms`` (n, 4, 4): T_object_gripper as in the file; ``base`` (n, 4, 4): T_object_base
    of ``hand``'s URDF base frame; ``open_joints`` (n, J) in ``hand_model(hand).joints`` order
    (rad or m); ``vertices`` (v, 3) m and ``faces`` (f, 3): the object in the grasps' frame;
    ``mass_kg``, ``friction``: the file's (None when absent); ``labels`` (n,) float: the file's
    own success label (1 / 0, NaN where absent), or None when the file has none."""

    path: str
    gripper: str
    hand: object
    transforms: np.ndarray
    base: np.ndarray
    open_joints: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    mesh_file: str
    scale: float
    mass_kg: float | None
    friction: float | None
    labels: np.ndarray | None
    label_name: str = LABEL

    def __len__(self):
        return len(self.transforms)


def resolve_hand(path, gripper, hands=()):
    """The hand of ``gripper`` (a file's ``gripper/type``) and T_gripper_base (4, 4).

    ``hands``: hands that are not built in, found by name."""
    from ..hands.spec import HANDS

    named = {**HANDS, **{hand.name: hand for hand in hands}}
    if gripper in GRIPPER_FRAMES:
        name, frame = GRIPPER_FRAMES[gripper]
        return named[name], frame
    if gripper in named:
        return named[gripper], np.eye(4)
    known = ", ".join(sorted(set(GRIPPER_FRAMES) | set(named)))
    raise BadInputError(
        f"{path}: unknown gripper/type {gripper!r} (known: {known}; a hand of your own: --hand SPEC named {gripper!r})"
    )


def rigid_inverse(transform):
    """The inverse (4, 4) of a rigid ``transform`` (4, 4): exact for an integer rotation and translation."""
    transform = np.asarray(transform, np.float64)
    inverse = np.eye(4)
    inverse[:3, :3] = transform[:3, :3].T
    inverse[:3, 3] = -(transform[:3, :3].T @ transform[:3, 3])
    return inverse


def dataset_frame(hand):
    """(``gripper/type``, T_gripper_base (4, 4)) of ``hand`` in a grasp file: a built-in hand
    with a dataset gripper (franka: ACRONYM's ``panda``) in that gripper's frame, every other
    hand under its own name in its URDF base frame (the identity)."""
    gripper = DATASET_GRIPPER.get(hand.name)
    if gripper is None:
        return hand.name, np.eye(4)
    return gripper, GRIPPER_FRAMES[gripper][1]


def check_rigid(path, transforms):
    """Raise BadInputError naming the first of ``transforms`` (n, 4, 4) that is not a rigid motion."""
    transforms = np.asarray(transforms, np.float64)
    if transforms.ndim != 3 or transforms.shape[1:] != (4, 4):
        raise BadInputError(f"{path}: grasps/transforms must be (n, 4, 4), got shape {transforms.shape}")
    if not len(transforms):
        raise BadInputError(f"{path}: holds no grasps (grasps/transforms is empty)")
    finite = np.isfinite(transforms).all(axis=(1, 2))
    rotation = transforms[:, :3, :3]
    with np.errstate(invalid="ignore"):
        gap = np.abs(np.swapaxes(rotation, 1, 2) @ rotation - np.eye(3)).max(axis=(1, 2))
        row = np.abs(transforms[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1)
        determinant = np.linalg.det(np.where(finite[:, None, None], rotation, np.eye(3)))
    rigid = finite & (gap <= RIGID_TOLERANCE) & (row <= RIGID_TOLERANCE) & (determinant > 0)
    if not rigid.all():
        first = int(np.flatnonzero(~rigid)[0])
        why = (
            "holds NaN or infinite values"
            if not finite[first]
            else f"is not a rigid motion (|R^T R - I| {gap[first]:.2g}, det {determinant[first]:.3g}, "
            f"last row {transforms[first, 3].tolist()})"
        )
        raise BadInputError(f"{path}: grasps/transforms[{first}] {why}")


def _open_joints(path, hand, gripper, configuration, count):
    """(count, J) open joints from a file's ``gripper/configuration`` (None: the default preshape)."""
    from ..hands.kinematics import hand_model

    joints = hand_model(hand).joints
    if configuration is None:
        opened = [hand.preshape()[joint] for joint in joints]
    else:
        configuration = np.atleast_1d(np.asarray(configuration, np.float64))
        wanted = 1 if gripper in GRIPPER_FRAMES else len(joints)
        if configuration.shape != (wanted,) or not np.isfinite(configuration).all():
            raise BadInputError(
                f"{path}: gripper/configuration of {gripper!r} must be {wanted} finite numbers, got {configuration.tolist()}"
            )
        opened = np.repeat(configuration, len(joints)) if gripper in GRIPPER_FRAMES else configuration
    return np.tile(np.asarray(opened, np.float64), (count, 1))


def _mesh(path, mesh, file_entry, scale):
    """(vertices, faces, mesh file) of the object: ``mesh`` if given, else ``file_entry``
    (absolute, or relative to the grasp file's folder), times ``scale``, never recentred."""
    from .export_runs import load_mesh

    if mesh is None:
        if not file_entry:
            raise BadInputError(f"{path}: names no object/file; give the mesh with --mesh")
        mesh = Path(file_entry) if Path(file_entry).is_absolute() else Path(path).parent / file_entry
        if not mesh.is_file():
            raise BadInputError(
                f"{path}: its object/file {file_entry} is not found at {mesh}; give the mesh with --mesh"
            )
    vertices, faces = load_mesh(("source", str(mesh), float(scale)))
    return vertices, faces, str(mesh)


def read_grasp_set(path, *, mesh=None, hands=()):
    """The :class:`GraspSet` of an ACRONYM-layout HDF5 file or one of the project's exports
    (see the module docstring). ``mesh`` (a path) replaces the file's ``object/file``; ``hands``
    are hands that are not built in, found by the file's ``gripper/type``. Raises
    BadInputError, naming the file, for anything that cannot be read or used."""
    path = Path(path)
    if not path.is_file():
        raise BadInputError(f"{path}: file not found")
    if path.stat().st_size == 0:
        raise BadInputError(f"{path}: file is empty")
    entries = _read_json(path) if path.suffix.lower() == ".json" else _read_hdf5(path)
    if entries["transforms"] is None:
        raise BadInputError(f"{path}: has no grasps/transforms (not a grasp file in ACRONYM's layout)")
    check_rigid(path, entries["transforms"])
    transforms = np.asarray(entries["transforms"], np.float64)
    gripper = entries["gripper"]
    if gripper is None:
        raise BadInputError(f"{path}: has no gripper/type")
    hand, frame = resolve_hand(path, gripper, hands)
    if entries["pregrasp_joints"] is not None:
        from ..hands.kinematics import hand_model

        opened = np.asarray(entries["pregrasp_joints"], np.float64)
        wanted = (len(transforms), len(hand_model(hand).joints))
        if opened.shape != wanted or not np.isfinite(opened).all():
            raise BadInputError(f"{path}: grasps/pregrasp_joints must be {wanted} finite values, got {opened.shape}")
    else:
        opened = _open_joints(path, hand, gripper, entries["configuration"], len(transforms))
    if mesh is None and entries["vertices"] is not None:  # the project's export: the simulated mesh itself
        vertices, faces, mesh_file = entries["vertices"], entries["faces"], str(entries["file"])
    else:
        vertices, faces, mesh_file = _mesh(path, mesh, entries["file"], entries["scale"])
    labels = entries["labels"]
    if labels is not None:
        labels = np.asarray(labels, np.float64).reshape(-1)
        if len(labels) != len(transforms):
            raise BadInputError(f"{path}: {LABEL} has {len(labels)} values for {len(transforms)} grasps")
    for key in ("mass_kg", "friction"):
        value = entries[key]
        if value is not None and not (np.isfinite(value) and value > 0):
            raise BadInputError(f"{path}: object/{key.removesuffix('_kg')} must be a positive number, got {value}")
    return GraspSet(
        str(path),
        gripper,
        hand,
        transforms,
        transforms @ frame,
        opened,
        np.asarray(vertices, np.float64),
        np.asarray(faces, np.int64),
        mesh_file,
        float(entries["scale"]),
        entries["mass_kg"],
        entries["friction"],
        labels,
    )


def _read_hdf5(path):
    import h5py

    try:
        h5 = h5py.File(path, "r")
    except OSError as err:
        raise BadInputError(f"{path}: cannot be read as HDF5 ({err})") from None
    with h5:

        def get(key, kind=None):
            if key not in h5 or not isinstance(h5[key], h5py.Dataset):
                return None
            value = h5[key][()]
            if kind is str:
                return value.decode() if isinstance(value, bytes) else str(value)
            if kind is float:
                return float(np.asarray(value, np.float64).reshape(-1)[0])
            return value

        scale = get("object/scale", float)
        return {
            "transforms": get("grasps/transforms"),
            "gripper": get("gripper/type", str),
            "configuration": get("gripper/configuration"),
            "pregrasp_joints": get("grasps/pregrasp_joints"),
            "file": get("object/file", str),
            "scale": 1.0 if scale is None else scale,
            "mass_kg": get("object/mass", float),
            "friction": get("object/friction", float),
            "labels": get(LABEL),
            "vertices": get("object/vertices"),
            "faces": get("object/faces"),
        }


def _read_json(path):
    """The entries of one of the project's JSON exports (their label: the recorded force closure)."""
    from .export_files import read_grasps

    try:
        json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise BadInputError(f"{path}: cannot be read as JSON ({err})") from None
    try:
        found = read_grasps(path)
    except (KeyError, TypeError) as err:
        raise BadInputError(f"{path}: not a medial-grasp JSON export (missing {err})") from None
    return {
        "transforms": found["transforms"] if len(found["transforms"]) else np.zeros((0, 4, 4)),
        "gripper": found["hand"],
        "configuration": None,
        "pregrasp_joints": found["pregrasp_joints"],
        "file": found["object_file"],
        "scale": found["scale"],
        "mass_kg": None,
        "friction": None,
        "labels": found["force_closure"].astype(np.float64),
        "vertices": found["vertices"],
        "faces": found["faces"],
    }

"""The export's two file formats: ACRONYM's HDF5 layout (:func:`write_acronym`) and JSON
(:func:`write_json`), their header texts, and :func:`read_grasps`, which reads either back into
arrays (docs/export.md)."""

import json
from pathlib import Path

import numpy as np

from .grasp_sets import DATASET_FRAMES, GRIPPER_FRAMES, dataset_frame, rigid_inverse

FORMATS = ("acronym", "json")
SUFFIXES = {"acronym": ".h5", "json": ".json"}
FORMAT_VERSION = "medial-grasp grasps 1"
UNITS = "metres and radians (a prismatic joint in metres)"
OBJECT_FRAME = "the object mesh file's coordinates times object scale: the mesh as simulated, in metres"
HAND_FRAME = "the hand URDF's root link frame (base_link)"
TRANSFORM = "T_object_hand: maps points of the hand's base frame into the object frame (row-major 4x4)"
GRIPPER_TRANSFORM = (
    "T_object_gripper: maps points of the dataset gripper's frame into the object frame (row-major 4x4); "
    "T_object_hand = T_object_gripper @ gripper/T_gripper_base"
)
PREGRASP = (
    "the closed pose moved back along -approach (object frame) by approach_m + standoff_m, with the "
    "preshape's joints: where the trial's approach started, plus the standoff"
)
RANKING = (
    "best first: force closure before not; then physics success held, unchecked, failed; then "
    "robust_fc high to low, unchecked last; then epsilon high to low; ties in trial order"
)
SUCCESS = "object_in_gripper is the force-closure verdict of the kinematic trial (1 force closure, 0 not)"


def file_stem(run, hand_name):
    """``<object>-<scale>-<hand>``: the export's file name without suffix."""
    return f"{run.object}-{float(run.scale)}-{hand_name}"


def hand_info(hand):
    """The hand's frame conventions and joints, JSON-ready: name, base_link, approach, wrap,
    grasp_centre (hand frame, m), joint_names, mimic_joints {name: [leader, multiplier, offset]}."""
    from ..hands.kinematics import hand_model

    model = hand_model(hand)
    return {
        "name": hand.name,
        "base_link": model.links[0],
        "approach": [float(v) for v in hand.approach],
        "wrap": [float(v) for v in hand.wrap],
        "grasp_centre": [float(v) for v in hand.grasp_centre],
        "joint_names": list(model.joints),
        "mimic_joints": {
            name: [model.joints[model.driver[link]], float(model.multiplier[link]), float(model.offset[link])]
            for name, link in model.mimics
        },
    }


def obj_bytes(vertices, faces):
    """Wavefront OBJ text of a triangle mesh, every coordinate to 17 digits (read back exactly)."""
    import io

    stream = io.BytesIO()
    np.savetxt(stream, np.asarray(vertices, np.float64).reshape(-1, 3), fmt="v %.17g %.17g %.17g")
    np.savetxt(stream, np.asarray(faces, np.int64).reshape(-1, 3) + 1, fmt="f %d %d %d")
    return stream.getvalue()


def _header(run, hand, info, *, mesh_file, urdf_file, standoff, found):
    return {
        "format": FORMAT_VERSION,
        "units": UNITS,
        "object_frame": OBJECT_FRAME,
        "hand_frame": HAND_FRAME,
        "transform": TRANSFORM,
        "pregrasp": PREGRASP,
        "ranking": RANKING,
        "standoff_m": float(standoff),
        "source": run.origin,
        "trials": found["trials"],
        "skipped": found["skipped"],
        "object": {"name": run.object, "file": mesh_file, "scale": float(run.scale)},
        "hand": {**info, "urdf": urdf_file},
    }


def write_json(path, run, hand, found, *, mesh_file, urdf_file, standoff):
    """Write one JSON document of ``found`` (:func:`pipeline.outputs.export.grasps`), atomically: the header indented,
    then one grasp a line; unchecked ``physics_success`` and ``robust_fc`` are null."""
    from ..artefacts import atomic_write, json_ready

    header = _header(
        run, hand, hand_info(hand), mesh_file=mesh_file, urdf_file=urdf_file, standoff=standoff, found=found
    )
    names = found["joint_names"]
    physics = [None if np.isnan(value) else bool(value) for value in found["physics_success"]]
    robust = [None if np.isnan(value) else float(value) for value in found["robust_fc"]]
    lines = [
        json.dumps(
            {
                "rank": rank + 1,
                "trial": int(found["trial"][rank]),
                "pose": found["transforms"][rank].tolist(),
                "pregrasp_pose": found["pregrasp_transforms"][rank].tolist(),
                "joints": dict(zip(names, found["joints"][rank].tolist())),
                "pregrasp_joints": dict(zip(names, found["pregrasp_joints"][rank].tolist())),
                "outcome": str(found["outcome"][rank]),
                "epsilon": float(found["epsilon"][rank]),
                "physics_success": physics[rank],
                "robust_fc": robust[rank],
                "planner": str(found["planner"][rank]),
                "sphere_class": str(found["sphere_class"][rank]),
                "preshape": str(found["preshape"][rank]),
                "approach_m": float(found["approach_m"][rank]),
            },
            allow_nan=False,
        )
        for rank in range(len(found["trial"]))
    ]
    text = json.dumps({**json_ready(header), "grasps": []}, indent=1, allow_nan=False)
    if lines:  # the last key's empty list, filled one grasp a line
        text = text.removesuffix("[]\n}") + "[\n  " + ",\n  ".join(lines) + "\n ]\n}"
    atomic_write(path, lambda stream: stream.write(text.encode() + b"\n"))


def write_acronym(path, run, hand, found, *, mesh_file, urdf_file, standoff, vertices, faces):
    """Write one HDF5 file of ``found`` (:func:`pipeline.outputs.export.grasps`) in ACRONYM's layout, atomically; the
    simulated mesh (``vertices`` (v, 3) m, ``faces``) also goes in bit for bit."""
    import h5py

    from ..artefacts import atomic_path

    gripper, frame = dataset_frame(hand)
    info = gripper_info(hand_info(hand), frame)
    header = _header(run, hand, info, mesh_file=mesh_file, urdf_file=urdf_file, standoff=standoff, found=found)
    if gripper in DATASET_FRAMES:
        header.update(hand_frame=DATASET_FRAMES[gripper], transform=GRIPPER_TRANSFORM)
    to_gripper = rigid_inverse(frame)
    text = h5py.string_dtype()
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as h5:
        for key in ("format", "units", "object_frame", "hand_frame", "transform", "pregrasp", "ranking", "source"):
            h5.attrs[key] = header[key]
        h5.attrs["standoff_m"] = header["standoff_m"]
        h5.attrs["trials"] = header["trials"]
        h5.attrs["skipped"] = json.dumps(header["skipped"])
        for outcome, count in header["skipped"].items():
            h5.attrs[f"skipped_{outcome}"] = count
        h5.attrs["success"] = SUCCESS
        h5["object/file"] = mesh_file
        h5["object/scale"] = float(run.scale)
        h5["object/name"] = run.object
        # the mesh as simulated, bit for bit (file x scale can be one rounding off it)
        h5.create_dataset("object/vertices", data=np.asarray(vertices, np.float64), compression="gzip")
        h5.create_dataset("object/faces", data=np.asarray(faces, np.int64), compression="gzip")
        h5["object"].attrs["frame"] = OBJECT_FRAME
        h5["gripper/type"] = gripper
        h5["gripper/urdf"] = urdf_file
        h5["gripper/joint_names"] = np.array(info["joint_names"], dtype=text)
        h5["gripper/configuration"] = gripper_configuration(hand, gripper)
        h5["gripper/T_gripper_base"] = frame
        for key in ("base_link", "approach", "wrap", "grasp_centre"):
            h5["gripper"].attrs[key] = info[key]
        h5["gripper"].attrs["mimic_joints"] = json.dumps(info["mimic_joints"])
        h5["gripper"].attrs["frame"] = header["hand_frame"]
        group = h5.create_group("grasps")
        # exact: T_gripper_base holds integers (grasp_sets.GRIPPER_FRAMES)
        group["transforms"] = found["transforms"] @ to_gripper
        group["transforms"].attrs["frame"] = header["transform"]
        group["pregrasp_transforms"] = found["pregrasp_transforms"] @ to_gripper
        group["pregrasp_transforms"].attrs["frame"] = PREGRASP
        group["joints"] = found["joints"]
        group["joints"].attrs["names"] = info["joint_names"]
        group["pregrasp_joints"] = found["pregrasp_joints"]
        group["joint_names"] = np.array(info["joint_names"], dtype=text)
        for key in ("outcome", "planner", "sphere_class", "preshape"):
            group[key] = np.array(list(found[key]), dtype=text)
        group["trial"] = found["trial"]
        group["approach_m"] = found["approach_m"]
        group.attrs["ranking"] = RANKING
        qualities = group.create_group("qualities")
        qualities["flex/object_in_gripper"] = found["force_closure"].astype(np.int64)
        qualities["flex/object_in_gripper"].attrs["meaning"] = SUCCESS
        qualities["force_closure"] = found["force_closure"]
        qualities["epsilon"] = found["epsilon"]
        qualities["physics_success"] = found["physics_success"]
        qualities["physics_success"].attrs["meaning"] = "1 held, 0 not held, NaN unchecked"
        qualities["robust_fc"] = found["robust_fc"]
        qualities["robust_fc"].attrs["meaning"] = "fraction of noisy copies in force closure, NaN unchecked"


def gripper_info(info, frame):
    """:func:`hand_info` ``info`` with ``approach``, ``wrap`` and ``grasp_centre`` in the frame
    of a file's gripper, T_gripper_base ``frame`` (4, 4) (the identity: unchanged)."""
    rotation, shift = frame[:3, :3], frame[:3, 3]
    moved = {key: (rotation @ info[key]).tolist() for key in ("approach", "wrap")}
    return {**info, **moved, "grasp_centre": (rotation @ info["grasp_centre"] + shift).tolist()}


def gripper_configuration(hand, gripper):
    """A file's ``gripper/configuration``: the open hand; ACRONYM's ``panda`` (1,) the opening of
    each finger (m), every other hand (J,) its default preshape in ``joint_names`` order."""
    from ..hands.kinematics import hand_model

    opened = hand.preshape()
    joints = [float(opened[joint]) for joint in hand_model(hand).joints]
    return np.array(joints[:1] if gripper in GRIPPER_FRAMES else joints, np.float64)


def read_grasps(path):
    """An exported file (either format) as arrays.

    Returns
    -------
    dict
        ``transforms`` and ``pregrasp_transforms`` (n, 4, 4) float64 (T_object_hand, m);
        ``joints`` and ``pregrasp_joints`` (n, J) float64; ``joint_names`` (J,) tuple;
        ``outcome``, ``planner``, ``sphere_class``, ``preshape`` (n,) str; ``trial`` (n,)
        int64; ``epsilon``, ``physics_success`` (1/0/NaN), ``robust_fc`` (NaN unchecked),
        ``approach_m`` (n,) float64; ``force_closure`` (n,) bool; ``hand`` (its name: ``franka``
        for a file's ``panda``, whose poses are turned back into the hand's base frame),
        ``urdf`` and ``object_file`` (absolute paths), ``scale``, ``standoff_m``, ``skipped``;
        ``vertices`` (v, 3) float64 m and ``faces`` (f, 3) int64: the simulated mesh (the HDF5
        file's own copy; from JSON, the object file times the scale).
    """
    path = Path(path)
    if path.suffix == ".json":
        document = json.loads(path.read_text())
        listed = document["grasps"]
        names = tuple(document["hand"]["joint_names"])
        found = {
            "transforms": np.array([g["pose"] for g in listed], np.float64).reshape(-1, 4, 4),
            "pregrasp_transforms": np.array([g["pregrasp_pose"] for g in listed], np.float64).reshape(-1, 4, 4),
            "joints": np.array([[g["joints"][n] for n in names] for g in listed], np.float64).reshape(-1, len(names)),
            "pregrasp_joints": np.array([[g["pregrasp_joints"][n] for n in names] for g in listed], np.float64).reshape(
                -1, len(names)
            ),
            "joint_names": names,
            "trial": np.array([g["trial"] for g in listed], np.int64),
            "epsilon": np.array([g["epsilon"] for g in listed], np.float64),
            "physics_success": np.array(
                [np.nan if g["physics_success"] is None else float(g["physics_success"]) for g in listed], np.float64
            ),
            "robust_fc": np.array([np.nan if g["robust_fc"] is None else g["robust_fc"] for g in listed], np.float64),
            "approach_m": np.array([g["approach_m"] for g in listed], np.float64),
            **{key: np.array([g[key] for g in listed], dtype=str) for key in ("outcome", "planner", "sphere_class")},
            "preshape": np.array([g["preshape"] for g in listed], dtype=str),
            "hand": document["hand"]["name"],
            "urdf": str(path.parent / document["hand"]["urdf"]),
            "object_file": str(path.parent / document["object"]["file"]),
            "scale": float(document["object"]["scale"]),
            "standoff_m": float(document["standoff_m"]),
            "skipped": dict(document["skipped"]),
        }
        found["force_closure"] = found["outcome"] == "force_closure"
        found["vertices"], found["faces"] = _obj_mesh(found["object_file"], found["scale"])
        return found
    import h5py

    with h5py.File(path, "r") as h5:
        group, qualities = h5["grasps"], h5["grasps/qualities"]
        found = {
            key: group[key][()] for key in ("transforms", "pregrasp_transforms", "joints", "pregrasp_joints", "trial")
        }
        found["approach_m"] = group["approach_m"][()]
        found["joint_names"] = tuple(group["joint_names"].asstr()[()])
        for key in ("outcome", "planner", "sphere_class", "preshape"):
            found[key] = np.array(group[key].asstr()[()], dtype=str)
        for key in ("epsilon", "force_closure", "physics_success", "robust_fc"):
            found[key] = qualities[key][()]
        hand_name = gripper = h5["gripper/type"].asstr()[()]
        if gripper in GRIPPER_FRAMES:  # back to the hand's URDF base frame, exactly
            hand_name, frame = GRIPPER_FRAMES[gripper]
            for key in ("transforms", "pregrasp_transforms"):
                found[key] = found[key] @ frame
        found.update(
            hand=hand_name,
            urdf=str(path.parent / h5["gripper/urdf"].asstr()[()]),
            object_file=str(path.parent / h5["object/file"].asstr()[()]),
            scale=float(h5["object/scale"][()]),
            standoff_m=float(h5.attrs["standoff_m"]),
            skipped=json.loads(h5.attrs["skipped"]),
            vertices=h5["object/vertices"][()],
            faces=h5["object/faces"][()],
        )
    return found


def _obj_mesh(path, scale):
    import trimesh

    mesh = trimesh.load(path, process=False, force="mesh")
    return np.asarray(mesh.vertices, np.float64) * scale, np.asarray(mesh.faces, np.int64)

"""Export a run's grasps for a robot: one file per object, scale and hand, in ACRONYM's HDF5
layout or as JSON (``python -m pipeline export``; docs/export.md).

A grasp is a trial whose hand closed: outcome ``force_closure``, ``no_force_closure`` or
``no_contact`` (:data:`EXPORTED`); the others (``collision``, ``step_cap``, ``error``, and any new
outcome) are counted as skipped. Per grasp, in the object frame (the mesh as simulated, metres):

- ``transform`` (4, 4): T_object_hand, the pose of the hand's URDF base frame as it closed
  (HDF5: a hand with a dataset gripper, ``franka``, in that gripper's frame instead, ACRONYM's
  ``panda``: :func:`pipeline.outputs.grasp_sets.dataset_frame`),
  recomputed from the trial's candidate and ``retract_m`` exactly as the trial engine placed it
  (and checked against the trial's ``base_*`` / ``base_q*`` columns), so that
  :meth:`pipeline.trial.engine.GraspEngine.replay` of it and of ``joints`` gives the recorded
  outcome and epsilon;
- ``pregrasp`` (4, 4): the same orientation backed off along -approach (the trial's unit P_d)
  by ``approach_m`` (where the trial's approach started, the hand just clear of the object)
  plus ``standoff`` metres, with the open preshape's joints;
- ``joints`` (J,): the closed actuated joints, ``joint_names`` order (the hand's ``limits``);
- ``outcome``, ``epsilon``, ``planner`` (any value), ``sphere_class``, ``physics_success``
  (1 held, 0 not held, NaN unchecked) and ``robust_fc`` (NaN unchecked) of the checks.

Ranked best first (:func:`rank_order`): force closure first, then physics success (held,
unchecked, failed), then robust force closure (high first, unchecked last), then epsilon
(high first); ties keep the trials' order.
"""

import functools
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..errors import ArtefactError, BadInputError, BadParamsError
from ..trial.engine import OUTCOMES
from .grasp_sets import DATASET_FRAMES, GRIPPER_FRAMES, dataset_frame, rigid_inverse

FORMATS = ("acronym", "json")
SUFFIXES = {"acronym": ".h5", "json": ".json"}
#: outcomes with a closed hand on (or about) the object: the exported ones
EXPORTED = ("force_closure", "no_force_closure", "no_contact")
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
POSE_TOLERANCE = 1e-9  # m, and per rotation-matrix entry: recomputed pose against the recorded one


@dataclass(frozen=True)
class Run:
    """The trials of one object, scale and hand as found on disk.

    ``trials`` holds the hand's rows with the checks' columns (missing where unchecked) and
    ``trial``, the row in the file ``origin``; ``mesh`` says where the simulated mesh is:
    ``("surface", path)`` a surface.npz, ``("source", source, scale)`` a mesh the sample stage
    rebuilds."""

    object: str
    scale: float
    hand: str
    trials: pd.DataFrame
    mesh: tuple
    origin: str


def rank_order(force_closure, physics_success, robust_fc, epsilon):
    """Indices that sort grasps best first (see the module docstring).

    Parameters
    ----------
    force_closure : (n,) bool
    physics_success : (n,) float
        1 held, 0 checked and not held, NaN unchecked.
    robust_fc : (n,) float
        Fraction of noisy copies in force closure, NaN unchecked.
    epsilon : (n,) float

    Returns
    -------
    (n,) int64
    """
    force_closure = np.asarray(force_closure, bool)
    physics_success, robust_fc, epsilon = (np.asarray(v, np.float64) for v in (physics_success, robust_fc, epsilon))
    physics = np.where(np.isnan(physics_success), 1, np.where(physics_success > 0, 0, 2))
    unchecked = np.isnan(robust_fc)
    # np.lexsort sorts by its last key first
    keys = (
        np.arange(len(epsilon)),
        -np.nan_to_num(epsilon, nan=-np.inf),
        np.where(unchecked, 0.0, -robust_fc),
        unchecked,
        physics,
        ~force_closure,
    )
    return np.lexsort(keys).astype(np.int64)


def closed_poses(trials, hand):
    """(n, 4, 4) T_object_hand of each trial's closed hand, as the trial engine computed it.

    The engine placed the hand on the candidate (:func:`pipeline.hands.kinematics.base_poses` on
    the unit P_d) and moved it ``retract_m`` back along P_d; the same arithmetic here gives the
    same bits. Raises ArtefactError if a pose differs from the trial's recorded ``base_*``,
    ``base_q*`` (a hand spec changed since the run)."""
    from ..arrays import vectors
    from ..hands.kinematics import base_poses

    if not len(trials):
        return np.zeros((0, 4, 4))
    approach = vectors(trials, "approach")
    approach = approach / np.linalg.norm(approach, axis=1, keepdims=True)
    poses = base_poses(hand, vectors(trials, "grasp"), approach, vectors(trials, "orient"))
    poses[:, :3, 3] -= trials.retract_m.to_numpy(np.float64)[:, None] * approach
    recorded = Rotation.from_quat(trials[[f"base_q{axis}" for axis in "xyzw"]].to_numpy(np.float64)).as_matrix()
    position_gap = np.abs(poses[:, :3, 3] - vectors(trials, "base")).max()
    rotation_gap = np.abs(poses[:, :3, :3] - recorded).max()
    if not max(position_gap, rotation_gap) <= POSE_TOLERANCE:
        raise ArtefactError(
            f"hand {hand.name}: the trials' recorded hand poses do not follow from their candidates "
            f"(off by {max(position_gap, rotation_gap):.3g}); was the hand spec changed since the run?"
        )
    return poses


def grasps(trials, hand, *, standoff):
    """The exported grasps of one hand's trials, best first.

    Parameters
    ----------
    trials : pandas.DataFrame
        One hand's trials (:mod:`pipeline.trial.protocol` columns), optionally with the checks' columns
        (``physics_success``, ``robust_fc``; missing values where unchecked) and ``trial`` (the
        row numbers to report; default the table's positions).
    hand : Hand
    standoff : float
        Metres beyond the start of the trial's approach for the pre-grasp pose.

    Returns
    -------
    dict
        ``trial`` (n,) int64; ``transforms`` and ``pregrasp_transforms`` (n, 4, 4) float64;
        ``joints`` and ``pregrasp_joints`` (n, J) float64 in ``joint_names`` (J,) order;
        ``outcome``, ``planner``, ``sphere_class``, ``preshape`` (n,) str; ``epsilon``,
        ``physics_success`` and ``robust_fc`` (n,) float64; ``force_closure`` (n,) bool;
        ``approach`` (n, 3) unit, ``approach_m`` (n,) metres; ``trials`` (int) and
        ``skipped`` ({outcome: count}).
    """
    from ..hands.kinematics import hand_model

    if not (np.isfinite(standoff) and standoff >= 0):
        raise BadParamsError(f"export: standoff must be a distance >= 0 m, got {standoff!r}")
    model = hand_model(hand)
    outcome = trials.outcome.astype(str).to_numpy()
    closed = np.isin(outcome, EXPORTED)
    kept = trials[closed]
    skipped = {name: 0 for name in OUTCOMES if name not in EXPORTED}
    skipped.update(pd.Series(outcome[~closed], dtype=object).value_counts().to_dict())
    rows = kept.trial.to_numpy(np.int64) if "trial" in kept else np.flatnonzero(closed).astype(np.int64)
    physics = _checked(kept, "physics_success")
    robust = _checked(kept, "robust_fc")
    epsilon = kept.epsilon.to_numpy(np.float64)
    force_closure = outcome[closed] == "force_closure"
    order = rank_order(force_closure, physics, robust, epsilon)
    kept = kept.iloc[order]
    transforms = closed_poses(kept, hand)
    approach = kept[[f"approach_{axis}" for axis in "xyz"]].to_numpy(np.float64).reshape(-1, 3)
    approach = approach / np.linalg.norm(approach, axis=1, keepdims=True)
    back = kept.approach_m.to_numpy(np.float64) + standoff
    pregrasp = transforms.copy()
    pregrasp[:, :3, 3] -= back[:, None] * approach
    joints = np.array([np.asarray(value, np.float64) for value in kept.joints]).reshape(len(kept), len(model.joints))
    preshapes = kept.preshape.astype(str).to_numpy()
    shapes = {name: [hand.preshape(name)[joint] for joint in model.joints] for name in set(preshapes)}
    open_joints = np.array([shapes[name] for name in preshapes], np.float64).reshape(len(kept), len(model.joints))
    return {
        "trial": rows[order],
        "transforms": transforms,
        "pregrasp_transforms": pregrasp,
        "joints": joints,
        "pregrasp_joints": open_joints,
        "joint_names": tuple(model.joints),
        "outcome": outcome[closed][order],
        "planner": kept.planner.astype(str).to_numpy(),
        "sphere_class": kept.sphere_class.astype(str).to_numpy(),
        "preshape": preshapes,
        "epsilon": epsilon[order],
        "force_closure": force_closure[order],
        "physics_success": physics[order],
        "robust_fc": robust[order],
        "approach": approach,
        "approach_m": kept.approach_m.to_numpy(np.float64),
        "trials": int(len(trials)),
        "skipped": {str(name): int(count) for name, count in skipped.items()},  # every non-closed outcome
    }


def _checked(trials, column):
    """(n,) float64 of a check column: 1/0 or the value, NaN where unchecked or absent."""
    if column not in trials:
        return np.full(len(trials), np.nan)
    values = trials[column]
    if column == "physics_success":
        values = values.astype("boolean").astype("Float64")
        if "physics_outcome" in trials:  # the physics check off: robust only, no verdict
            values = values.where(trials.physics_outcome.astype(str) != "")
    return pd.to_numeric(values, errors="coerce").to_numpy(np.float64, na_value=np.nan)


# ---------------------------------------------------------------------------------------------
# finding the runs of a folder


def find_runs(run_dir, *, data=None, scale=1.0, warn=None):
    """Every object x scale x hand with trials under ``run_dir``.

    Parameters
    ----------
    run_dir : path
        One of: a ``plan --out`` folder (trials.parquet beside surface.npz and summary.json), a
        ``batch`` output (objects/ and trials/), a DVC ``data/`` tree (or any folder above or in
        one: ``<object>/<scale>/surface.npz`` and ``<object>/<scale>/<hand>/trials.parquet``, each
        with its checks.parquet if there), the ``report/`` folder (trials.parquet with ``object``
        and ``scale`` columns), or a folder holding several plan folders.
    data : path, optional
        The DVC data/ tree holding a report's meshes (default: ``run_dir/../data``).
    scale : float
        A batch's ``--scale`` (its output does not record it); checked against its trials.
    warn : callable(str), optional
        Called with a line for each batch trials file left out (its object not done).

    Returns
    -------
    list of Run, sorted by object, scale and hand
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise BadInputError(f"{run_dir}: no such folder")
    table = run_dir / "trials.parquet"
    if table.is_file() and (run_dir / "surface.npz").is_file():
        runs = _plan_runs(run_dir)
    elif table.is_file() and {"object", "scale"} <= set(_columns(table)):
        runs = _report_runs(run_dir, Path(data) if data else run_dir.parent / "data")
    elif (run_dir / "objects").is_dir() and (run_dir / "trials").is_dir():
        runs = _batch_runs(run_dir, scale, warn or (lambda line: None))
    else:
        runs = []
        for found in _trial_files(run_dir):
            if (found.parent / "surface.npz").is_file():
                runs += _plan_runs(found.parent)
            elif (found.parent.parent / "surface.npz").is_file():
                runs += _dvc_runs(found)
    runs = [run for run in runs if len(run.trials)]
    if not runs:
        raise BadInputError(
            f"{run_dir}: holds no trials (give a `plan --out` folder, a `batch` output, the DVC data/ tree "
            "or the report/ folder)"
        )
    return sorted(runs, key=lambda run: (run.object, run.scale, run.hand))


def _columns(path):
    import pyarrow.parquet

    try:
        return pyarrow.parquet.read_schema(path).names
    except Exception as err:  # noqa: BLE001 - pyarrow raises many types for a bad file
        raise ArtefactError(f"{path}: not a readable parquet table ({type(err).__name__})") from None


def _trial_files(folder):
    """trials.parquet files under ``folder``, hidden folders (.venv, .dvc, .git) skipped."""
    for root, folders, files in os.walk(folder):
        folders[:] = sorted(name for name in folders if not name.startswith("."))
        if "trials.parquet" in files:
            yield Path(root) / "trials.parquet"


def _numbered(trials):
    return trials.reset_index(drop=True).assign(trial=np.arange(len(trials), dtype=np.int64))


def _with_checks(trials, checks_path):
    from ..artefacts import read_table
    from ..checks.protocol import with_checks

    try:
        return with_checks(trials, read_table(checks_path) if checks_path.is_file() else None)
    except ArtefactError as err:
        raise ArtefactError(f"{checks_path}: {err}") from None


def _by_hand(trials, *, object, scale, mesh, origin):
    return [
        Run(object, float(scale), str(hand), rows, mesh, origin)
        for hand, rows in trials.groupby(trials.hand.astype(str), sort=True)
    ]


def _plan_runs(folder):
    from ..artefacts import read_table

    summary = folder / "summary.json"
    if not summary.is_file():
        raise ArtefactError(f"{summary}: missing (a plan folder names its object and scale there)")
    meta = json.loads(summary.read_text())
    if not {"source", "scale"} <= set(meta):
        raise ArtefactError(f"{summary}: no source or scale (not written by `plan`?)")
    trials = _numbered(read_table(folder / "trials.parquet"))
    if not len(trials):
        return []
    trials = _with_checks(trials, folder / "checks.parquet")
    name = Path(str(meta["source"]).split(":")[-1]).stem or folder.name
    return _by_hand(
        trials, object=name, scale=meta["scale"], mesh=("surface", str(folder / "surface.npz")), origin=str(folder)
    )


def _dvc_runs(path):
    from ..artefacts import read_table

    run = path.parent.parent
    try:
        scale = float(run.name)
    except ValueError:
        raise BadInputError(f"{run}: a DVC run folder is data/<object>/<scale>; {run.name!r} is no scale") from None
    trials = _numbered(read_table(path))
    if not len(trials):
        return []
    trials = _with_checks(trials, path.with_name("checks.parquet"))
    return _by_hand(
        trials, object=run.parent.name, scale=scale, mesh=("surface", str(run / "surface.npz")), origin=str(path)
    )


def _report_runs(folder, data):
    from ..artefacts import read_table

    trials = _numbered(read_table(folder / "trials.parquet"))
    runs = []
    for (name, scale), rows in trials.groupby([trials.object.astype(str), trials.scale.astype(float)], sort=True):
        surface = _scale_folder(data / name, scale) / "surface.npz"
        if not surface.is_file():
            raise BadInputError(
                f"{folder / 'trials.parquet'}: no mesh for {name} x{scale:g}: {surface} is missing "
                "(give the DVC data/ tree with --data)"
            )
        runs += _by_hand(rows, object=name, scale=scale, mesh=("surface", str(surface)), origin=str(folder))
    return runs


def _scale_folder(folder, scale):
    """``folder/<scale>``: the folder whose name is the number ``scale`` (``1.0`` or ``1``)."""
    if folder.is_dir():
        for child in sorted(folder.iterdir()):
            try:
                if float(child.name) == scale:
                    return child
            except ValueError:
                continue
    return folder / str(float(scale))


def _batch_runs(folder, scale, warn):
    from ..artefacts import read_table

    sources = {}
    if any((folder / "objects").glob("*.parquet")):
        objects = pd.read_parquet(folder / "objects", columns=["object", "status", "source"])
        objects = objects[objects.status == "ok"]  # a summary row marks an object done
        sources = dict(zip(objects.object, objects.source))
    runs = []
    for path in sorted((folder / "trials").glob("*.parquet")):
        trials = _numbered(read_table(path))
        if not len(trials):
            continue
        name = str(trials.object.iloc[0])
        if name not in sources:  # written before the batch stopped: it plans the object again
            warn(f"{path}: left out, object {name!r} is not done in {folder / 'objects'}")
            continue
        mesh = ("source", str(sources[name]), float(scale))
        _check_batch_scale(trials, mesh, path)
        runs += _by_hand(trials, object=name, scale=scale, mesh=mesh, origin=str(path))
    return runs


def _check_batch_scale(trials, mesh, path):
    """The baseline trials' grasp points are surface samples: they lie on the mesh at the batch's scale."""
    from ..arrays import vectors
    from ..geometry.mesh_query import ObjectMesh

    baseline = trials[trials.planner.astype(str) == "baseline"]
    if not len(baseline):
        return
    vertices, faces = load_mesh(mesh)
    gap = ObjectMesh(vertices, faces, grid_cells=8).distance(vectors(baseline, "grasp")).max()
    size = np.linalg.norm(np.ptp(vertices, axis=0))
    if not gap <= 1e-6 * max(size, 1.0):
        raise BadInputError(
            f"{path}: its trials are not on {mesh[1]} at scale {mesh[2]:g} (off by {gap:.3g} m): "
            "give the batch's --scale"
        )


@functools.lru_cache(maxsize=8)
def load_mesh(mesh):
    """(vertices (v, 3) float64 metres, faces (f, 3) int64) of a :class:`Run`'s ``mesh``."""
    if mesh[0] == "surface":
        from ..artefacts import SurfaceSamples

        surface = SurfaceSamples.load(mesh[1])
        return surface.vertices, surface.faces
    from ..geometry.objects import load_source, validate_mesh

    with warnings.catch_warnings():  # the batch warned of its repairs when it ran
        warnings.simplefilter("ignore")
        kind, *loaded = load_source(mesh[1], scale=mesh[2])
        if kind != "mesh":
            raise BadInputError(f"{mesh[1]}: a point cloud has no grasps to export")
        solid = validate_mesh(loaded[0], name=mesh[1], min_extent=0.0, max_extent=np.inf)
    vertices, faces = np.asarray(solid.vertices, np.float64), np.asarray(solid.faces, np.int64)
    vertices.setflags(write=False)  # cached: shared by every caller
    faces.setflags(write=False)
    return vertices, faces


# ---------------------------------------------------------------------------------------------
# writing and reading the files


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
    """Write one JSON document of ``found`` (:func:`grasps`), atomically: the header indented,
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
    """Write one HDF5 file of ``found`` (:func:`grasps`) in ACRONYM's layout, atomically; the
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


def export(runs, out, *, fmt, standoff=0.05, hands=(), progress=None):
    """Write one file per run of ``runs`` (:func:`find_runs`) into ``out``, beside each object's
    mesh (``<object>-<scale>.obj``, the simulated mesh divided by the scale) and each hand's
    URDF (``<hand>.urdf``).

    Parameters
    ----------
    fmt : {"acronym", "json"}
    standoff : float
        Metres the pre-grasp pose stands off beyond the start of the trial's approach.
    hands : list of Hand
        Hands that are not built in, found by name in the trials.
    progress : callable(str), optional
        Called with a line per file written.

    Returns
    -------
    list of (Path, int): each file and its number of grasps
    """
    from ..artefacts import atomic_write
    from ..hands.spec import hand_urdf_text

    if fmt not in FORMATS:
        raise BadParamsError(f"export: unknown format {fmt!r} (use one of: {', '.join(FORMATS)})")
    out = Path(out)
    named = {hand.name: hand for hand in hands}
    resolved = {run.hand: _hand(run, named) for run in runs}  # every hand known before a file is written
    stems = {}
    for run in runs:
        stem = file_stem(run, resolved[run.hand].name)
        if stem in stems:
            raise BadInputError(f"{run.origin} and {stems[stem]}: both give {stem}{SUFFIXES[fmt]}; export them apart")
        stems[stem] = run.origin
    meshes = {}  # mesh file -> the run mesh it holds
    for run in runs:
        mesh_file = f"{run.object}-{float(run.scale)}.obj"
        if meshes.setdefault(mesh_file, run.mesh) != run.mesh:
            raise BadInputError(
                f"{run.origin}: another run of {run.object} x{run.scale:g} has another mesh; export them apart"
            )
    written, urdfs = [], set()
    for run in runs:
        hand = resolved[run.hand]
        try:
            found = grasps(run.trials, hand, standoff=standoff)
        except ArtefactError as err:
            raise ArtefactError(f"{run.origin}: {err}") from None
        vertices, faces = load_mesh(run.mesh)
        mesh_file, urdf_file = f"{run.object}-{float(run.scale)}.obj", f"{hand.name}.urdf"
        if meshes.pop(mesh_file, None) is not None:  # each mesh file once
            text = obj_bytes(vertices / float(run.scale), faces)
            atomic_write(out / mesh_file, lambda stream, text=text: stream.write(text))
        if urdf_file not in urdfs:
            text = hand_urdf_text(hand).encode()
            atomic_write(out / urdf_file, lambda stream, text=text: stream.write(text))
            urdfs.add(urdf_file)
        path = out / f"{file_stem(run, hand.name)}{SUFFIXES[fmt]}"
        keywords = dict(mesh_file=mesh_file, urdf_file=urdf_file, standoff=standoff)
        if fmt == "acronym":
            write_acronym(path, run, hand, found, vertices=vertices, faces=faces, **keywords)
        else:
            write_json(path, run, hand, found, **keywords)
        count = len(found["trial"])
        written.append((path, count))
        if progress:
            closed = int(found["force_closure"].sum())
            checked = int((~np.isnan(found["physics_success"]) | ~np.isnan(found["robust_fc"])).sum())
            skipped = ", ".join(f"{name} {number}" for name, number in found["skipped"].items())
            progress(
                f"wrote {path}: {count} grasps of {found['trials']} trials ({closed} force closure, {checked} checked; "
                f"skipped: {skipped})"
            )
    return written


def _hand(run, named):
    from ..hands.spec import HANDS, get_hand

    if run.hand in named:
        return named[run.hand]
    try:
        return get_hand(run.hand)
    except BadParamsError:
        raise BadInputError(
            f"{run.origin}: unknown hand {run.hand!r} in the trials (built-in: {', '.join(HANDS)}; "
            "give its spec with --hand SPEC)"
        ) from None


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


def replay_file(path, *, hand=None, settings=None):
    """Replay every grasp of an exported file through the trial engine from the file alone: its
    mesh, poses and joints (:meth:`pipeline.trial.engine.GraspEngine.replay`).

    Parameters
    ----------
    hand : Hand, optional
        Default: the built-in hand the file names.
    settings : SimulateParams, optional
        The run's ``simulate`` params (their defaults when None).

    Returns
    -------
    found : dict (:func:`read_grasps`), results : list of TrialResult in the file's order
    """
    from types import SimpleNamespace

    from ..hands.spec import get_hand
    from ..trial.engine import GraspEngine

    found = read_grasps(path)
    mesh = SimpleNamespace(vertices=found["vertices"], faces=found["faces"])
    engine = GraspEngine(mesh, hand or get_hand(found["hand"]), settings)
    return found, engine.replay(found["transforms"], found["joints"])

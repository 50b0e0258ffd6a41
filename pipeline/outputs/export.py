"""Export a run's grasps for a robot: one file per object, scale and hand, in ACRONYM's HDF5
layout or as JSON (``python -m pipeline export``; docs/export.md). Here: which trials are grasps, their
poses and their order, and :func:`export`; the runs found on disk are in :mod:`.export_runs`, the
files' writers and reader in :mod:`.export_files`, the replay of a file in :mod:`.replay`.

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

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..errors import ArtefactError, BadInputError, BadParamsError
from ..trial.engine import OUTCOMES
from .export_files import FORMATS, SUFFIXES, file_stem, obj_bytes, write_acronym, write_json
from .export_runs import load_mesh

#: outcomes with a closed hand on (or about) the object: the exported ones
EXPORTED = ("force_closure", "no_force_closure", "no_contact")
POSE_TOLERANCE = 1e-9  # m, and per rotation-matrix entry: recomputed pose against the recorded one


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


def export(runs, out, *, fmt, standoff=0.05, hands=(), progress=None):
    """Write one file per run of ``runs`` (:func:`pipeline.outputs.export_runs.find_runs`) into ``out``, beside each object's
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

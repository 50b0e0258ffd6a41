"""Label a grasp set with this project's verdicts and grade them against the set's own labels
(``medial-grasp evaluate``; docs/evaluate.md).

Per grasp of a :class:`pipeline.outputs.grasp_sets.GraspSet`:

1. the trial: the hand placed at the grasp's pose, open at its joints, closed where it is
   (:meth:`InPlaceEngine.close_in_place`: no retreat, no approach; a placed hand
   that overlaps the object is ``collision``), then its ``outcome``, ``force_closure`` and
   ``epsilon``;
2. robust force closure (:mod:`pipeline.checks.robust`): ``robust_samples`` copies of the pose with the
   ``checks`` params' pose and friction noise about the hand's grasp centre, each backed out
   until clear and closed there (a robot with that error stops where it meets the object),
   graded at its own friction: ``robust_fc`` and ``robust_epsilon``;
3. the lift-and-shake of the chosen engines (``checks.engine``, ``--engine``) of a hand that
   closed on the object (``force_closure`` or ``no_force_closure``; the rest are ``no_grasp``):
   pybullet's (:class:`pipeline.checks.physics.PhysicsCheck`: ``physics_outcome``,
   ``physics_success``, ``physics_slip_m``, ``physics_turn_rad``), MuJoCo's from the closed pose
   (:class:`pipeline.checks.mujoco_check.MujocoCheck`: ``mujoco_*``) and from the open hand closing on
   the free object (``mujoco_open_*``); a check that did not run is "" / NaN.

The object's mass and friction are the file's (``object/mass``, ``object/friction``); without
them, its mesh volume times ``checks.density_kg_m3``, at most ``checks.payload_kg`` (the
graspable-mass rule of the checks), and ``simulate.mu``. The friction is that of
every verdict (force closure and the physics check alike). Seeds: grasp ``i``'s copies come from
``SeedSequence([seed, i])``, so its labels do not depend on the sample, the chunks or the workers.
"""

import time

import numpy as np
import pandas as pd

from ..checks.protocol import PHYSICS_CHECKS
from ..errors import BadInputError, BadParamsError
from ..hands.kinematics import link_poses
from ..trial.engine import CLOSED, GraspEngine, TrialResult
from ..trial.proximity import collides

#: verdicts graded against a file's labels: column, and the value counted as "success"
VERDICTS = {
    "force_closure": "force closure",
    "physics_success": "pybullet lift-and-shake held",
    "mujoco_success": "MuJoCo lift-and-shake held",
    "mujoco_open_success": "MuJoCo held, closed on free object",
    "robust_fc": "robust force closure >= 0.5",
}
#: scores whose ROC AUC against the labels is reported
SCORES = ("epsilon", "robust_fc")
CHUNK = 8  # grasps a worker takes at a time: a progress step


def sample_rows(count, sample, seed):
    """Sorted rows (int64) of a seeded sample of ``sample`` of ``count`` grasps (all for -1 or more)."""
    if sample is None or sample < 0 or sample >= count:
        return np.arange(count, dtype=np.int64)
    if sample == 0:
        raise BadParamsError("evaluate: --sample must be a positive number of grasps (or -1 for all)")
    return np.sort(np.random.default_rng(seed).choice(count, sample, replace=False)).astype(np.int64)


def candidates_of(hand, base):
    """The (P_g, P_d, P_o) (n, 3) each of ``base`` (n, 4, 4) T_object_base places ``hand`` on:
    :func:`pipeline.hands.kinematics.base_poses` of them gives ``base`` back (to rounding)."""
    rotation = base[:, :3, :3]
    grasp = rotation @ np.asarray(hand.grasp_centre, float) + base[:, :3, 3]
    return grasp, rotation @ np.asarray(hand.approach, float), rotation @ np.asarray(hand.wrap, float)


class InPlaceEngine(GraspEngine):
    """The trial engine on hands placed at given poses (a grasp dataset's), closed there: no
    approach. See :meth:`close_in_place`."""

    def close_in_place(self, base, joints, *, back_out=False, mu=None):
        """Trials of hands at ``base`` (n, 4, 4) T_object_base (metres, rigid), opened at
        ``joints`` (n, J) (``hand_model(hand).joints`` order), closed where they are, graded at
        the friction coefficients ``mu`` (n,) (default the settings').

        A placed hand that overlaps the object is ``collision``; with ``back_out`` it is first
        moved back along its approach axis, as a trial's retreat (``retract_step_m`` steps, at
        most ``retract_max_m``). Returns a list of n TrialResult (``approach_m`` 0)."""
        model = self.model
        base = np.asarray(base, np.float64).reshape(-1, 4, 4).copy()
        q = np.asarray(joints, np.float64).reshape(len(base), len(model.joints))
        if not (np.isfinite(base).all() and np.isfinite(q).all()):
            raise BadInputError("close_in_place: a pose or joint value is not finite")
        q = np.clip(q, model.lower, model.upper)
        results = [TrialResult("collision")] * len(base)
        if not len(base):
            return results
        start = time.perf_counter()
        direction = base[:, :3, :3] @ np.asarray(self.hand.approach, float)
        placed = link_poses(model, base, q)
        if back_out:
            retreat = self._retreat(placed, direction)
        else:
            retreat = np.where(collides(self.mesh, model, placed)[0], np.inf, 0.0)
        start = self._lap("retreat", start)
        rows = np.flatnonzero(np.isfinite(retreat))
        placed = base[rows]
        placed[:, :3, 3] -= retreat[rows, None] * direction[rows]
        closed, stops, steps = self._close(placed, q[rows])
        start = self._lap("closing", start)
        mu = None if mu is None else np.asarray(mu, np.float64)[rows]
        grades = self._grade_closed(placed, closed, stops, steps, retreat[rows], np.zeros(len(rows)), mu)
        for number, result in zip(rows, grades):
            results[number] = result
        self._lap("contacts", start)
        return results


class Labeller:
    """The verdicts of one hand on one object (see the module docstring): the engines built once,
    :meth:`label` per batch of grasps.

    Parameters
    ----------
    vertices, faces : the object's closed mesh (m)
    hand : Hand
    parts : list of (v, 3) float
        The object's convex parts (the physics check's body).
    settings : SimulateParams
        How the trials run (the ``simulate`` params, ``mu`` the object's).
    physics : dict
        The lift-and-shake engines to run: ``pybullet`` (a PhysicsSettings) and/or ``mujoco``
        (a MujocoSettings); empty: none.
    robust : dict
        ``samples``, ``pose_sigma_m``, ``angle_sigma_rad``, ``mu_sigma``.
    seed : int
    """

    def __init__(self, vertices, faces, hand, parts, *, settings, physics, robust, seed):
        from types import SimpleNamespace

        self.engine = InPlaceEngine(SimpleNamespace(vertices=vertices, faces=faces), hand, settings)
        self.hand, self.robust, self.seed = hand, robust, seed
        self.checks = {}
        if "pybullet" in physics:
            from ..checks.physics import PhysicsCheck

            self.checks["pybullet"] = PhysicsCheck(
                vertices, faces, hand, self.engine.model, parts=parts, settings=physics["pybullet"]
            )
        if "mujoco" in physics:
            from ..checks.mujoco_check import MujocoCheck

            self.checks["mujoco"] = MujocoCheck(
                vertices, faces, hand, self.engine.model, parts=parts, settings=physics["mujoco"]
            )

    def close(self):
        for check in self.checks.values():
            check.close()

    def label(self, rows, base, open_joints):
        """The labels table of grasps ``rows`` (n,) (their numbers in the file: the seeds) at
        ``base`` (n, 4, 4) T_object_base with ``open_joints`` (n, J)."""
        from ..checks.robust import perturbed_candidates, robust_summary
        from ..hands.kinematics import base_poses

        results = self.engine.close_in_place(base, open_joints)
        frame = pd.DataFrame(
            {
                "grasp": np.asarray(rows, np.int64),
                "outcome": [result.outcome for result in results],
                "force_closure": [result.outcome == "force_closure" for result in results],
                "epsilon": [result.epsilon for result in results],
                "contacts": [len(result.contact_points) for result in results],
                "touched": [",".join(result.touched) for result in results],
                "joints": [list(result.joint_positions) for result in results],
            }
        )
        samples = self.robust["samples"]
        if samples:
            settings = self.engine.settings
            grasp, approach, orient = candidates_of(self.hand, base)
            moved = perturbed_candidates(
                grasp,
                approach,
                orient,
                [np.random.SeedSequence([self.seed, int(row)]) for row in rows],
                samples=samples,
                pose_sigma_m=self.robust["pose_sigma_m"],
                angle_sigma_rad=self.robust["angle_sigma_rad"],
                mu=settings.mu,
                mu_sigma=self.robust["mu_sigma"],
            )
            copies = self.engine.close_in_place(
                base_poses(self.hand, *moved[:3]), np.repeat(open_joints, samples, axis=0), back_out=True, mu=moved[3]
            )
            frame["robust_fc"], frame["robust_epsilon"] = robust_summary(copies, samples)
        else:
            frame["robust_fc"] = frame["robust_epsilon"] = np.nan
        for check, engine_name in PHYSICS_CHECKS.items():
            engine = self.checks.get(engine_name)
            physics = [("no_grasp" if engine else "", np.nan, np.nan)] * len(results)
            start = {}
            for k, result in enumerate(results):
                if engine is None or result.outcome not in CLOSED:
                    continue
                if check == "mujoco_open":
                    start = {"open_joints": open_joints[k]}
                found = engine.check(result.base_position, result.base_orientation, result.joint_positions, **start)
                physics[k] = (found.outcome, found.slip_m, found.turn_rad)
            frame[f"{check}_outcome"] = [outcome for outcome, _, _ in physics]
            frame[f"{check}_success"] = frame[f"{check}_outcome"] == "held"
            frame[f"{check}_slip_m"] = np.array([slip for _, slip, _ in physics], float)
            frame[f"{check}_turn_rad"] = np.array([turn for _, _, turn in physics], float)
        return frame


def object_parts(vertices, faces, *, vhacd_resolution):
    """The physics check's convex parts (list of (v, 3)): the mesh itself when it is convex (its
    hull's volume equals its own), else V-HACD's."""
    from types import SimpleNamespace

    from scipy.spatial import ConvexHull

    from ..checks.physics import decompose
    from ..geometry.mass import mesh_volume

    hull_volume = ConvexHull(vertices).volume
    if abs(hull_volume - mesh_volume(vertices, faces)) <= 1e-9 * hull_volume:
        return [np.asarray(vertices, np.float64)]
    surface = SimpleNamespace(vertices=vertices, faces=faces, source="the object", key="evaluate")
    return decompose(surface, vhacd_resolution=vhacd_resolution).parts


_WORKER = {}


def _start(arguments):
    _WORKER["labeller"] = Labeller(*arguments[0], **arguments[1])


def _chunk(rows, base, open_joints):
    return _WORKER["labeller"].label(rows, base, open_joints)


def label_grasps(
    grasp_set, rows, *, settings, physics, robust, seed, vhacd_resolution=1000000, workers=1, progress=None
):
    """The labels table of ``grasp_set``'s grasps ``rows`` (one row each, in ``rows``' order;
    columns in the module docstring, plus ``label``: the file's own, NaN where it has none).

    ``settings``, ``physics``, ``robust``, ``seed``: as :class:`Labeller` takes them, the parts
    made here (:func:`object_parts`); ``workers`` processes (results do not depend on it);
    ``progress(done, total)`` after each chunk of grasps."""
    parts = object_parts(grasp_set.vertices, grasp_set.faces, vhacd_resolution=vhacd_resolution)
    arguments = (
        (grasp_set.vertices, grasp_set.faces, grasp_set.hand, parts),
        dict(settings=settings, physics=physics, robust=robust, seed=seed),
    )
    chunks = [rows[first : first + CHUNK] for first in range(0, len(rows), CHUNK)]
    jobs = [(chunk, grasp_set.base[chunk], grasp_set.open_joints[chunk]) for chunk in chunks]
    frames = []
    if progress:
        progress(0, len(rows))
    if workers <= 1:
        labeller = Labeller(*arguments[0], **arguments[1])
        try:
            for job in jobs:
                frames.append(labeller.label(*job))
                if progress:
                    progress(len(job[0]), len(rows))
        finally:
            labeller.close()
    else:
        from concurrent.futures import ProcessPoolExecutor

        from ..pool import context

        with ProcessPoolExecutor(workers, mp_context=context(), initializer=_start, initargs=(arguments,)) as pool:
            for job, frame in zip(jobs, pool.map(_chunk, *zip(*jobs))):
                frames.append(frame)
                if progress:
                    progress(len(job[0]), len(rows))
    table = pd.concat(frames, ignore_index=True)
    labels = grasp_set.labels
    table["label"] = labels[rows] if labels is not None else np.nan
    return table


def roc_auc(score, label):
    """ROC AUC (float, NaN without both classes) of ``score`` (n,) against 0/1 ``label`` (n,):
    the probability that a random success scores above a random failure, ties counted half
    (Mann-Whitney U over the ranks)."""
    from scipy.stats import rankdata

    score, label = np.asarray(score, np.float64), np.asarray(label, bool)
    positives, negatives = int(label.sum()), int((~label).sum())
    if not positives or not negatives:
        return float("nan")
    ranks = rankdata(score)
    return float((ranks[label].sum() - positives * (positives + 1) / 2) / (positives * negatives))


def confusion(predicted, label):
    """Confusion table and rates of 0/1 ``predicted`` (n,) against 0/1 ``label`` (n,):
    ``tp``, ``fp``, ``fn``, ``tn`` counts, ``balanced_accuracy`` (the mean of the two classes'
    recall), ``precision``, ``recall``, ``accuracy``; a rate of no cases is NaN."""
    predicted, label = np.asarray(predicted, bool), np.asarray(label, bool)
    tp, fp = int((predicted & label).sum()), int((predicted & ~label).sum())
    fn, tn = int((~predicted & label).sum()), int((~predicted & ~label).sum())
    rate = lambda top, bottom: top / bottom if bottom else float("nan")  # noqa: E731
    recall, specificity = rate(tp, tp + fn), rate(tn, tn + fp)
    return {
        "tp": tp,
        "fp": fp,
        "fn": fn,
        "tn": tn,
        "balanced_accuracy": float(np.nanmean([recall, specificity])) if tp + fn or tn + fp else float("nan"),
        "precision": rate(tp, tp + fp),
        "recall": recall,
        "accuracy": rate(tp + tn, len(label)),
    }


def agreement(table):
    """Each verdict's :func:`confusion` against the labels table's ``label`` and the
    :func:`roc_auc` of each of :data:`SCORES`, over the grasps with a label (and, for a verdict
    or score, a value). Returns a JSON-ready dict; None when no grasp has a label."""
    labelled = table[table.label.notna()]
    if not len(labelled):
        return None
    label = labelled.label.to_numpy(float) > 0.5
    verdicts = {}
    for column, meaning in VERDICTS.items():
        values = labelled[column]
        known = values.notna().to_numpy().copy()
        if column.endswith("_success"):  # a lift-and-shake: where it ran
            known &= (labelled[column.removesuffix("success") + "outcome"] != "").to_numpy()
        if not known.any():
            continue
        predicted = values.to_numpy(float)[known] >= 0.5
        verdicts[column] = {"meaning": meaning, "grasps": int(known.sum()), **confusion(predicted, label[known])}
    scores = {}
    for column in SCORES:
        known = labelled[column].notna().to_numpy()
        if known.any():
            scores[column] = roc_auc(labelled[column].to_numpy(float)[known], label[known])
    return {
        "labelled": int(len(labelled)),
        "label_success_rate": float(label.mean()),
        "verdicts": verdicts,
        "roc_auc": scores,
    }


def agreement_text(found):
    """The agreement (:func:`agreement`) as a few printable lines."""
    lines = [
        f"{found['labelled']} labelled grasps, {100 * found['label_success_rate']:.1f} % labelled success",
        f"{'verdict':34} {'tp':>5} {'fp':>5} {'fn':>5} {'tn':>5} {'bal.acc':>8} {'precision':>9} {'recall':>7}",
    ]
    for row in found["verdicts"].values():
        lines.append(
            f"{row['meaning']:34} {row['tp']:5d} {row['fp']:5d} {row['fn']:5d} {row['tn']:5d} "
            f"{row['balanced_accuracy']:8.3f} {row['precision']:9.3f} {row['recall']:7.3f}"
        )
    lines.append("ROC AUC: " + ", ".join(f"{name} {value:.3f}" for name, value in found["roc_auc"].items()))
    return lines


def verdict_settings(grasp_set, params, *, engine=None):
    """(trial settings, physics dict, robust dict) of ``params`` for the object of
    ``grasp_set``: its friction and mass where the file states them (its mass as it is, not
    capped at ``checks.payload_kg``). The physics dict holds the settings of the lift-and-shake
    engines to run (:class:`Labeller`): ``engine`` (``pybullet``, ``mujoco`` or ``both``;
    default ``checks.engine``), none with ``checks.physics`` false."""
    import dataclasses

    from ..checks.mujoco_check import MujocoSettings
    from ..geometry.mass import mesh_volume

    mu = grasp_set.friction if grasp_set.friction is not None else params.simulate.mu
    settings = dataclasses.replace(params.simulate, mu=mu)
    checks = params.checks
    if grasp_set.mass_kg is not None:
        density = grasp_set.mass_kg / mesh_volume(grasp_set.vertices, grasp_set.faces)
        checks = dataclasses.replace(checks, density_kg_m3=density, payload_kg=-1.0)
    engine = checks.engine if engine is None else engine
    mujoco = MujocoSettings.from_params(checks, mu)
    physics = {}
    if checks.physics:
        physics = {"pybullet": mujoco.physics, "mujoco": mujoco}
        physics = {name: value for name, value in physics.items() if engine in (name, "both")}
    robust = {
        "samples": checks.robust_samples,
        "pose_sigma_m": checks.pose_sigma_m,
        "angle_sigma_rad": checks.angle_sigma_rad,
        "mu_sigma": checks.mu_sigma,
    }
    return settings, physics, robust


#: the labels written into the annotated grasp file, under grasps/qualities/medial_grasp/
QUALITY_COLUMNS = (
    "force_closure",
    "epsilon",
    "robust_fc",
    "robust_epsilon",
    *(f"{check}_{column}" for check in PHYSICS_CHECKS for column in ("success", "slip_m", "turn_rad")),
)
#: the verdicts' outcome strings written beside them
OUTCOME_COLUMNS = ("outcome", *(f"{check}_outcome" for check in PHYSICS_CHECKS))


def write_labels(out, grasp_set, table, found, *, meta):
    """Write ``DIR/labels.parquet`` (``table``), the grasp file with the labels added
    (``DIR/<name>``: an HDF5 file's own datasets untouched, ours under
    ``grasps/qualities/medial_grasp/``, NaN or "" for a grasp not labelled; a JSON export with a
    ``medial_grasp`` entry per grasp) and, with labels in the file, ``DIR/agreement.json``
    (``found``), each atomically. ``meta``: what the labels were made with (JSON-ready).
    Returns the paths written."""
    import json
    import shutil
    from pathlib import Path

    from ..artefacts import atomic_path, atomic_write, json_ready, write_table

    out, source = Path(out), Path(grasp_set.path)
    count = len(grasp_set)
    full = pd.DataFrame(index=np.arange(count))
    for column in OUTCOME_COLUMNS:
        full[column] = ""
        full.loc[table.grasp.to_numpy(), column] = table[column].to_numpy()
    for column in QUALITY_COLUMNS:
        full[column] = np.nan
        full.loc[table.grasp.to_numpy(), column] = table[column].to_numpy(float)
    for check in PHYSICS_CHECKS:  # a check that did not run says nothing
        full.loc[table.grasp.to_numpy()[table[f"{check}_outcome"].to_numpy() == ""], f"{check}_success"] = np.nan
    written = [out / "labels.parquet"]
    write_table(written[0], table)
    annotated = out / source.name
    if source.suffix.lower() == ".json":
        document = json.loads(source.read_text())
        for number, grasp in enumerate(document["grasps"]):
            grasp["medial_grasp"] = json_ready({column: full[column].iloc[number] for column in full.columns})
        document["medial_grasp"] = json_ready(meta)
        text = json.dumps(document, indent=1, allow_nan=False).encode() + b"\n"
        atomic_write(annotated, lambda stream: stream.write(text))
    else:
        import h5py

        with atomic_path(annotated) as tmp:
            shutil.copyfile(source, tmp)
            with h5py.File(tmp, "a") as h5:
                qualities = h5.require_group("grasps/qualities")
                if "medial_grasp" in qualities:
                    del qualities["medial_grasp"]
                group = qualities.create_group("medial_grasp")
                group["labelled"] = np.isin(np.arange(count), table.grasp.to_numpy())
                for column in OUTCOME_COLUMNS:
                    group[column] = np.array(full[column].tolist(), dtype=h5py.string_dtype())
                for column in QUALITY_COLUMNS:
                    group[column] = full[column].to_numpy(float)
                group.attrs["made_with"] = json.dumps(json_ready(meta))
    written.append(annotated)
    if found is not None:
        text = json.dumps(json_ready({**meta, **found}), indent=1, allow_nan=False).encode() + b"\n"
        written.append(out / "agreement.json")
        atomic_write(written[-1], lambda stream: stream.write(text))
    return written

"""Recordings of the grasp trials, on the ``trial`` timeline of the .rrd files the
:mod:`.recording` module starts (its docstring lists the entities), and a whole chain run's
recording and log (:func:`record_chain`)."""

import dataclasses

import numpy as np

from ..arrays import vectors
from ..logbook import mcap_log
from ..trial.engine import OUTCOMES, trial_settings
from .recording import (
    log_candidates,
    log_concavities,
    log_spheres,
    log_surface,
    log_symmetry,
    rerun_recording,
    send_blueprint,
)

TRIAL_TIMELINE = "trial"
OUTCOME_COLOURS = {
    "force_closure": (40, 170, 60),
    "no_force_closure": (230, 160, 0),
    "no_contact": (120, 120, 120),
    "collision": (220, 40, 40),
    "error": (0, 0, 0),
}


def log_trials(stream, root, surface, hand, trials, contacts, *, settings=None):
    """One step of the ``trial`` timeline per row of ``trials`` (one hand's; the contacts'
    ``trial`` column indexes its rows): the hand's link boxes at approach, after retract and
    closed, the contacts with normals and friction cones, epsilon and the outcome. Sent
    column-wise, one call per entity for all trials."""
    import rerun as rr
    from scipy.spatial.transform import Rotation

    from ..hands.kinematics import hand_boxes, hand_model
    from ..trial.quality import friction_cone

    settings = trial_settings(settings)
    count, path = len(trials), f"{root}/trials/{hand.name}"
    steps = [rr.TimeColumn(TRIAL_TIMELINE, sequence=np.arange(count))]
    base = trials[["base_x", "base_y", "base_z"]].to_numpy()
    quaternion = trials[["base_qx", "base_qy", "base_qz", "base_qw"]].to_numpy()
    placed = np.isfinite(base).all(axis=1) & np.isfinite(quaternion).all(axis=1)  # not an early error
    colours = np.array([OUTCOME_COLOURS.get(str(outcome), (0, 0, 0)) for outcome in trials.outcome], np.uint8)
    approach_start = base + trials.retract_m.to_numpy()[:, None] * vectors(trials, "approach")
    model = hand_model(hand, spacing=settings.link_point_spacing_m)
    # joints in the model's order: the closed ones from the trials (the hand's limits order), the
    # open ones the default preshape; a joint neither names stays at 0
    open_joints = hand.preshape()
    opened = np.tile([open_joints.get(joint, 0.0) for joint in model.joints], (int(placed.sum()), 1))
    limits = list(hand.limits)
    recorded = np.array(trials.joints[placed].tolist(), np.float64).reshape(len(opened), len(limits))
    closed = np.column_stack(
        [recorded[:, limits.index(joint)] if joint in limits else np.zeros(len(opened)) for joint in model.joints]
    ).reshape(len(opened), len(model.joints))
    for name, positions, joints in (
        ("approach", approach_start, opened),
        ("retracted", base, opened),
        ("closed", base, closed),
    ):
        centres, rotations, _ = hand_boxes(model, positions[placed], quaternion[placed], joints)
        links = len(model.box_half)
        centres, rotations = centres.reshape(-1, 3), rotations.reshape(-1, 3, 3)
        # the closed hand solid, its approach and retracted poses as outlines behind it
        fill = rr.components.FillMode.Solid if name == "closed" else rr.components.FillMode.MajorWireframe
        stream.log(f"{path}/hand/{name}", rr.Boxes3D.from_fields(fill_mode=fill), static=True)
        stream.send_columns(
            f"{path}/hand/{name}",
            indexes=steps,
            columns=rr.Boxes3D.columns(
                centers=centres,
                half_sizes=np.tile(model.box_half, (len(opened), 1)),
                quaternions=Rotation.from_matrix(rotations).as_quat() if len(rotations) else np.zeros((0, 4)),
                colors=np.repeat(colours[placed], links, axis=0),
            ).partition(np.where(placed, links, 0)),
        )
    contacts = contacts.sort_values("trial", kind="stable")
    per_trial = np.bincount(contacts.trial.to_numpy(), minlength=count) if len(contacts) else np.zeros(count, int)
    position, normal = contacts[["x", "y", "z"]].to_numpy(), contacts[["nx", "ny", "nz"]].to_numpy()
    scale = 0.03 * float(np.linalg.norm(np.ptp(surface.points, axis=0)))
    edges = settings.cone_edges
    cone = friction_cone(-normal, mu=settings.mu, edges=edges) if len(normal) else np.zeros((0, edges, 3))
    tips = position[:, None] + scale * cone / np.linalg.norm(cone, axis=2, keepdims=True)
    strips = np.stack([np.broadcast_to(position[:, None], tips.shape), tips], axis=2).reshape(-1, 2, 3)
    stream.send_columns(
        f"{path}/contacts",
        indexes=steps,
        columns=rr.Points3D.columns(positions=position, colors=np.tile([[230, 30, 30]], (len(position), 1))).partition(
            per_trial
        ),
    )
    stream.send_columns(
        f"{path}/normals",
        indexes=steps,
        columns=rr.Arrows3D.columns(origins=position, vectors=-scale * normal).partition(per_trial),
    )
    stream.send_columns(
        f"{path}/cones", indexes=steps, columns=rr.LineStrips3D.columns(strips=strips).partition(per_trial * edges)
    )
    stream.send_columns(
        f"{root}/epsilon/{hand.name}", indexes=steps, columns=rr.Scalars.columns(scalars=trials.epsilon.to_numpy(float))
    )
    stream.send_columns(
        f"{root}/outcome/{hand.name}",
        indexes=steps,
        columns=[
            *rr.Scalars.columns(scalars=[float(OUTCOMES.index(str(outcome))) for outcome in trials.outcome]),
            *rr.TextLog.columns(
                text=[
                    f"{planner} {outcome} eps {epsilon:.4f}"
                    for planner, outcome, epsilon in zip(trials.planner, trials.outcome, trials.epsilon)
                ]
            ),
        ],
    )
    joints = [np.asarray(values, float).ravel() for values in trials.joints]
    stream.send_columns(
        f"{path}/joints",
        indexes=steps,
        columns=rr.AnyValues.columns(joints_rad=np.concatenate(joints) if joints else np.zeros(0)).partition(
            [len(values) for values in joints]
        ),
    )


def record_chain(rrd_path, mcap_path, artefacts, summary_dict, *, name, hands, settings=None):
    """Record a chain run (:func:`pipeline.plan.run_chain`'s artefacts) as one .rrd and one .mcap.

    Parameters
    ----------
    rrd_path, mcap_path : str or Path
    artefacts : dict stage -> artefact, with ``trials`` and ``contacts`` if simulated
    summary_dict : dict
        :func:`pipeline.plan.summary` (counts and timings go to the MCAP log).
    name : str
        The object's name: the entity root is ``/<name>`` and the recording id ``name``.
    hands : list of Hand
    settings : SimulateParams, optional
        How the trials ran (mu and cone edges draw the cones; the defaults when None).
    """
    root = f"/{name}"
    surface, candidates = artefacts["sample"], artefacts["candidates"]
    with rerun_recording(rrd_path, recording_id=name) as stream:
        send_blueprint(stream, root)
        log_surface(stream, root, surface)
        log_spheres(stream, root, artefacts["mat"])
        log_symmetry(
            stream,
            root,
            artefacts["classify"],
            with_candidates=np.unique(candidates.sphere_index[candidates.sphere_class != "encompassing"]),
        )
        if "concavity" in artefacts:
            log_concavities(stream, root, artefacts["concavity"])
        log_candidates(stream, root, candidates)
        if "trials" in artefacts:
            trials, contacts = artefacts["trials"], artefacts["contacts"]
            for hand in hands:
                rows = np.flatnonzero(trials.hand.to_numpy() == hand.name)
                own = contacts[contacts.trial.isin(rows)].assign(trial=lambda frame: np.searchsorted(rows, frame.trial))
                log_trials(
                    stream, root, surface, hand, trials.iloc[rows].reset_index(drop=True), own, settings=settings
                )
    with mcap_log(mcap_path, "plan") as log:
        log.log(
            "/params",
            {
                "source": summary_dict["source"],
                "scale": summary_dict["scale"],
                "seed": summary_dict["seed"],
                "hands": [hand.name for hand in hands],
                **dataclasses.asdict(trial_settings(settings)),
            },
        )
        log.log(
            "/counts",
            {**summary_dict["counts"], "classes": summary_dict["classes"], "candidates": summary_dict["candidates"]},
        )
        for stage, seconds in summary_dict["timings_s"].items():  # the chain's stages, one process
            log.log("/timing", {"stage": stage, "seconds": seconds})
        if not len(candidates):
            log.log("/warning", {"message": f"{name}: no candidate grasp (no sphere of the reduced set fits a hand)"})
        if "trials" in artefacts:
            log.trials(artefacts["trials"])

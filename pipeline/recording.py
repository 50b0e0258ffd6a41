"""Recordings of what the planner did: rerun ``.rrd`` files for the 3D viewer (the MCAP logs
are :mod:`pipeline.logbook`). Only the commands and stages record; the algorithms return the
values shown.

rerun entities (metres, the object frame; ``root`` is ``/<object>``): ``surface/mesh``,
``surface/samples`` (with ``surface/normals``), ``spheres`` (every medial sphere as an ellipsoid
coloured red -> green -> blue by diameter, object angle per sphere), ``reduced`` (the reduced
set, coloured by class), ``symmetry/e1``, ``symmetry/e2``, ``symmetry/cog`` (spheres carrying
candidates), ``candidates/<hand>/approach`` (arrows ending at P_g along P_d) and
``candidates/<hand>/orient`` (P_o marks), ``concavities/<n>`` (the concavities' solids, counted
ones in the ``encompassing`` colour) and ``encompassing_spheres`` (the filled object's spheres in
them), and on the ``trial`` timeline, one step per trial,
``trials/<hand>/hand/{approach,retracted,closed}`` (the hand's link boxes),
``trials/<hand>/joints`` (the closed joint values, rad, in the order of the hand's limits),
``trials/<hand>/contacts`` with ``normals`` and ``cones``, and the scalars ``epsilon/<hand>`` and
``outcome/<hand>`` (the outcome as its index in ``simulation.OUTCOMES``, with a text line per
trial); grouped by quantity so that each plot of the blueprint takes a whole subtree.

Files are written beside their final name and renamed into place when complete: an interrupted
run never leaves a truncated file under the final name.
"""

import contextlib
import time

import numpy as np

from .artefacts import atomic_path, atomic_write
from .arrays import vectors
from .colours import CLASS_COLOURS as FIGURE_CLASS_COLOURS
from .colours import diameter_colours
from .logbook import mcap_log

TRIAL_TIMELINE = "trial"
# the figures' class colours (paper Fig. 5), plus the classes without candidates
CLASS_COLOURS = {
    **{name: tuple(round(255 * value) for value in rgb) for name, rgb in FIGURE_CLASS_COLOURS.items()},
    "interior": (150, 150, 150),
    "surface": (90, 90, 90),
}
OUTCOME_COLOURS = {
    "force_closure": (40, 170, 60),
    "no_force_closure": (230, 160, 0),
    "no_contact": (120, 120, 120),
    "collision": (220, 40, 40),
    "error": (0, 0, 0),
}


@contextlib.contextmanager
def rerun_recording(path, *, recording_id, application_id="medial-grasp"):
    """A ``rerun.RecordingStream`` saving to ``path`` (.rrd), renamed into place on success.

    Recordings with the same ``application_id`` and ``recording_id`` merge in the viewer, so
    the stages of one object can each write their own file.
    """
    import rerun as rr

    with atomic_path(path) as tmp:
        stream = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False)
        stream.set_log_time_enabled(False)  # no wall-clock timeline: the trial index is the time
        stream.save(tmp)
        try:
            yield stream
        finally:
            stream.flush()
            stream.disconnect()


def log_surface(stream, root, surface, *, max_normals=2000, seed=0):
    """The object mesh, its surface samples and (a seeded subset of) their outward normals."""
    import rerun as rr

    stream.log(
        f"{root}/surface/mesh",
        rr.Mesh3D(vertex_positions=surface.vertices, triangle_indices=surface.faces, albedo_factor=(200, 140, 70, 120)),
        static=True,
    )
    stream.log(
        f"{root}/surface/samples",
        rr.Points3D(surface.points, radii=0.25 * surface.spacing, colors=(110, 110, 110)),
        static=True,
    )
    shown = np.random.default_rng(seed).permutation(len(surface.points))[:max_normals]
    stream.log(
        f"{root}/surface/normals",
        rr.Arrows3D(
            origins=surface.points[shown], vectors=4 * surface.spacing * surface.normals[shown], colors=(60, 120, 220)
        ),
        static=True,
    )


def log_spheres(stream, root, spheres):
    """Every medial sphere as an ellipsoid, coloured by diameter, with its object angle (deg)."""
    import rerun as rr

    colours = (255 * diameter_colours(2 * spheres.radii)).astype(np.uint8)
    stream.log(
        f"{root}/spheres",
        rr.Ellipsoids3D(centers=spheres.centers, radii=spheres.radii, colors=colours, fill_mode="solid"),
        rr.AnyValues(object_angle_deg=np.degrees(spheres.object_angle), radius_m=spheres.radii),
        static=True,
    )


def log_symmetry(stream, root, symmetry, *, with_candidates=None):
    """The reduced set coloured by class; e1, e2 and the neighbourhood centre of gravity of the
    spheres listed in ``with_candidates`` (sphere indices; all if None)."""
    import rerun as rr

    names = np.asarray(symmetry.class_names())
    colours = np.array([CLASS_COLOURS[name] for name in names], np.uint8).reshape(-1, 3)
    stream.log(
        f"{root}/reduced",
        rr.Points3D(symmetry.centers, radii=0.5 * symmetry.radii, colors=colours, labels=names, show_labels=False),
        rr.AnyValues(rho=symmetry.rho, sphere_index=symmetry.sphere_index),
        static=True,
    )
    chosen = (
        np.ones(len(symmetry), bool) if with_candidates is None else np.isin(symmetry.sphere_index, with_candidates)
    )
    axes = symmetry.axes.reshape(-1, 3, 3)[chosen]
    length = 2 * symmetry.radii[chosen, None]
    for number, colour in ((0, (200, 30, 30)), (1, (30, 60, 220))):
        stream.log(
            f"{root}/symmetry/e{number + 1}",
            rr.Arrows3D(origins=symmetry.centers[chosen], vectors=length * axes[:, number], colors=colour),
            static=True,
        )
    stream.log(f"{root}/symmetry/cog", rr.Points3D(symmetry.cog[chosen], colors=(0, 0, 0)), static=True)


def log_concavities(stream, root, concavities):
    """The concavities' solids (counted ones in the ``encompassing`` colour, the others grey)
    and the filled object's encompassing spheres in the same colour."""
    import rerun as rr

    for number in range(len(concavities.volume)):
        faces = concavities.faces[concavities.face_part == number]
        colour = CLASS_COLOURS["encompassing"] if concavities.counted[number] else CLASS_COLOURS["interior"]
        stream.log(
            f"{root}/concavities/{number}",
            rr.Mesh3D(
                vertex_positions=concavities.vertices,
                triangle_indices=faces,
                albedo_factor=(*colour, 90),
            ),
            rr.AnyValues(
                volume_m3=concavities.volume[number],
                width_m=concavities.width[number],
                mouth_width_m=concavities.mouth_width[number],
                mouths=concavities.mouths[number],
            ),
            static=True,
        )
    if not len(concavities):  # rerun refuses empty AnyValues
        return
    stream.log(
        f"{root}/encompassing_spheres",
        rr.Ellipsoids3D(
            centers=concavities.centers,
            radii=concavities.radii,
            colors=CLASS_COLOURS["encompassing"],
            fill_mode="majorwireframe",
        ),
        rr.AnyValues(concavity=concavities.part, sphere_index=concavities.sphere_index),
        static=True,
    )


def log_candidates(stream, root, candidates, *, length=None):
    """Per hand: the candidates' approach as arrows of ``length`` (m; default 5 % of the grasp
    points' bounding-box diagonal) ending at P_g along P_d, coloured by sphere class, and P_o as
    a short mark at P_g."""
    import rerun as rr

    if length is None:
        grasp = vectors(candidates, "grasp")
        length = 0.05 * float(np.linalg.norm(np.ptp(grasp, axis=0))) if len(grasp) > 1 else 0.01
        length = length or 0.01
    for hand, rows in candidates.groupby("hand", sort=True):
        grasp, approach, orient = (vectors(rows, prefix) for prefix in ("grasp", "approach", "orient"))
        colours = np.array([CLASS_COLOURS.get(str(name), (0, 0, 0)) for name in rows.sphere_class], np.uint8)
        stream.log(
            f"{root}/candidates/{hand}/approach",
            rr.Arrows3D(origins=grasp - length * approach, vectors=length * approach, colors=colours),
            rr.AnyValues(candidate_id=rows.id.to_numpy()),
            static=True,
        )
        stream.log(
            f"{root}/candidates/{hand}/orient",
            rr.Arrows3D(origins=grasp, vectors=0.3 * length * orient, colors=(220, 0, 220)),
            static=True,
        )


def log_trials(stream, root, surface, hand, trials, contacts, *, settings=None):
    """One step of the ``trial`` timeline per row of ``trials`` (one hand's; the contacts'
    ``trial`` column indexes its rows): the hand's link boxes at approach, after retract and
    closed, the contacts with normals and friction cones, epsilon and the outcome. Sent
    column-wise, one call per entity for all trials."""
    import rerun as rr
    from scipy.spatial.transform import Rotation

    from .quality import friction_cone
    from .kinematics import hand_boxes, hand_model
    from .simulation import OUTCOMES

    settings = settings or {}
    count, path = len(trials), f"{root}/trials/{hand.name}"
    steps = [rr.TimeColumn(TRIAL_TIMELINE, sequence=np.arange(count))]
    base = trials[["base_x", "base_y", "base_z"]].to_numpy()
    quaternion = trials[["base_qx", "base_qy", "base_qz", "base_qw"]].to_numpy()
    placed = np.isfinite(base).all(axis=1) & np.isfinite(quaternion).all(axis=1)  # not an early error
    colours = np.array([OUTCOME_COLOURS.get(str(outcome), (0, 0, 0)) for outcome in trials.outcome], np.uint8)
    approach_start = base + trials.retract_m.to_numpy()[:, None] * vectors(trials, "approach")
    model = hand_model(hand, spacing=settings.get("link_point_spacing_m", 0.003))
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
    edges = settings.get("cone_edges", 8)
    cone = friction_cone(-normal, mu=settings.get("mu", 0.5), edges=edges) if len(normal) else np.zeros((0, edges, 3))
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


def send_blueprint(stream, root):
    """Open on the 3D scene beside the trial scalars."""
    import rerun.blueprint as rrb

    stream.send_blueprint(
        rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(origin=root, name="object, spheres, grasps"),
                rrb.Vertical(
                    rrb.TimeSeriesView(origin=f"{root}/epsilon", name="epsilon"),
                    rrb.TimeSeriesView(origin=f"{root}/outcome", name="outcome (0 force closure ... 4 error)"),
                    rrb.TextLogView(origin=f"{root}/outcome", name="trials"),
                ),
                column_shares=[3, 1],
            )
        )
    )


def record_stage(run, draw):
    """Write a DVC stage's recording (:class:`pipeline.stage_io.StageRun` ``run``): ``draw(stream,
    root)`` logs the entities under ``root``. With params ``record`` off the .rrd is written
    empty, so that DVC still finds the declared output."""
    if not run.rrd:
        return
    start = time.perf_counter()
    if not run.enabled:
        atomic_write(run.rrd, lambda stream: None)
        return
    root = f"/{run.recording_id}"
    with rerun_recording(run.rrd, recording_id=run.recording_id) as stream:
        send_blueprint(stream, root)
        draw(stream, root)
    run.record_seconds += time.perf_counter() - start


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
    settings : dict, optional
        The trials' :class:`GraspWorld` keywords (mu and cone edges draw the cones).
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
                **(settings or {}),
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

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
them), and, drawn by :mod:`.trial_recording` on the ``trial`` timeline, one step per trial,
``trials/<hand>/hand/{approach,retracted,closed}`` (the hand's link boxes),
``trials/<hand>/joints`` (the closed joint values, rad, in the order of the hand's limits),
``trials/<hand>/contacts`` with ``normals`` and ``cones``, and the scalars ``epsilon/<hand>`` and
``outcome/<hand>`` (the outcome as its index in ``pipeline.trial.engine.OUTCOMES``, with a text line per
trial); grouped by quantity so that each plot of the blueprint takes a whole subtree.

Files are written beside their final name and renamed into place when complete: an interrupted
run never leaves a truncated file under the final name.
"""

import contextlib
import time

import numpy as np

from .. import seeds
from ..arrays import vectors
from ..artefacts import atomic_path, atomic_write
from .colours import CLASS_COLOURS as FIGURE_CLASS_COLOURS
from .colours import diameter_colours

# the figures' class colours (paper Fig. 5), plus the classes without candidates
CLASS_COLOURS = {
    **{name: tuple(round(255 * value) for value in rgb) for name, rgb in FIGURE_CLASS_COLOURS.items()},
    "interior": (150, 150, 150),
    "surface": (90, 90, 90),
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
    shown = seeds.shown_normals(seed).permutation(len(surface.points))[:max_normals]
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

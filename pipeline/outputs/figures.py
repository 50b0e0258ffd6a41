"""The report's figures as images: the grid of medial spheres with the candidate grasps (paper
Fig. 5) and the best force-closure grasps (paper Fig. 7).

Every function takes artefacts and returns ``(height, width, 3) uint8`` RGB arrays; writing
them (as PNG) is the caller's job. Plots use a :class:`matplotlib.figure.Figure` on its own Agg
canvas (no pyplot state, no display); grasps use :func:`pipeline.outputs.render.render_hand`. The same
inputs give byte-identical images.

References
----------
M. Przybylski, T. Asfour, R. Dillmann, "Planning grasps for robotic hands using a novel object
representation based on the medial axis transform", IROS 2011: Fig. 5 (spheres coloured red ->
green -> blue by growing diameter; candidates as approach lines, orange from a local symmetry
axis, green from a local symmetry plane, magenta P_o at their ends) and Fig. 7.
"""

import numpy as np

from ..arrays import vectors
from ..errors import BadInputError
from .colours import CLASS_COLOURS, CLASS_LABELS, E1_COLOUR, E2_COLOUR, ORIENT_COLOUR, REDUCED_COLOUR, diameter_colours

DPI = 100


def _canvas(size):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI)
    FigureCanvasAgg(figure)
    return figure


def _pixels(figure):
    figure.canvas.draw()
    return np.array(figure.canvas.buffer_rgba())[..., :3]


def _cube_axes(axes, low, high, view):
    """Equal scaling: the same span on x, y and z, around the middle of ``low``..``high``."""
    middle, half = (low + high) / 2, (high - low).max() / 2
    for setter, centre in zip((axes.set_xlim, axes.set_ylim, axes.set_zlim), middle):
        setter(centre - half, centre + half)
    axes.set_box_aspect((1, 1, 1))
    axes.view_init(*view)
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.set_zlabel("z (m)")
    axes.tick_params(labelsize=7)


def candidate_lines(symmetry, candidates, *, length, max_lines=2000, seed=0):
    """Line segments of the candidate grasps of some spheres (paper Fig. 5, lower rows).

    Per drawn sphere: e1 and e2 (centred on the centre, ``length / 2`` long); per distinct
    approach P_d an approach line from P_g back along -P_d, ``length`` long; at its far end P_o
    (``length / 4``, centred; a flipped candidate shares the line). Spheres are drawn in a
    random order (``seed``) until the next would exceed ``max_lines`` segments.

    Parameters
    ----------
    symmetry : Symmetry
        ``sphere_index`` ascending, as :func:`pipeline.geometry.symmetry.classify` makes it.
    candidates : pandas.DataFrame
        Candidates of one hand (columns :data:`pipeline.geometry.candidates.COLUMNS`) made from ``symmetry``.
    length : float, metres
    max_lines : int
    seed : int

    Returns
    -------
    segments : (m, 2, 3) float64, metres, object frame
    kinds : (m,) str, ``e1``, ``e2``, ``orient`` or the sphere class of an approach line
    drawn : int, spheres drawn (of ``candidates.sphere_index.nunique()``)
    """
    index = np.asarray(symmetry.sphere_index)
    sphere = candidates.sphere_index.to_numpy()
    row = np.searchsorted(index, sphere).clip(0, max(len(index) - 1, 0))
    if len(sphere) and (len(index) == 0 or not np.array_equal(index[row], sphere)):
        raise BadInputError("candidates: sphere_index holds spheres that are not in the symmetry's reduced set")
    approach = vectors(candidates, "approach")
    # one line per (sphere, P_d); the flipped twin differs in the sign of P_o only
    _, first = np.unique(np.column_stack([sphere, np.round(approach, 9)]), axis=0, return_index=True)
    first = np.sort(first)
    spheres, per_sphere = np.unique(sphere[first], return_counts=True)
    order = np.random.default_rng(seed).permutation(len(spheres))
    take = order[np.cumsum(2 * per_sphere[order] + 2) <= max_lines]
    first = first[np.isin(sphere[first], spheres[take])]
    rows = np.searchsorted(index, spheres[np.sort(take)])

    grasp, direction = vectors(candidates, "grasp")[first], approach[first]
    orient, centres = vectors(candidates, "orient")[first], np.asarray(symmetry.centers)[rows]
    end = grasp - length * direction
    axes = np.asarray(symmetry.axes).reshape(-1, 3, 3)[rows]
    segments = np.concatenate(
        [
            np.stack([centres - length / 4 * axes[:, 0], centres + length / 4 * axes[:, 0]], axis=1),
            np.stack([centres - length / 4 * axes[:, 1], centres + length / 4 * axes[:, 1]], axis=1),
            np.stack([grasp, end], axis=1),
            np.stack([end - length / 8 * orient, end + length / 8 * orient], axis=1),
        ]
    ).reshape(-1, 2, 3)
    kinds = np.concatenate(
        [
            np.repeat(["e1", "e2"], len(rows)),
            candidates.sphere_class.astype(str).to_numpy()[first].astype(object),
            np.full(len(first), "orient", dtype=object),
        ]
    ).astype(str)
    return segments, kinds, len(take)


def sphere_figure(
    spheres,
    symmetry,
    candidates,
    *,
    hand=None,
    title="",
    size=(1200, 600),
    approach_length=0.1,
    max_lines=2000,
    max_points=20000,
    seed=0,
    view=(25.0, -60.0),
    concavities=None,
):
    """The grid of medial spheres and the candidate grasps of one object (paper Fig. 5).

    Left: every sphere centre, marker area growing with the radius, coloured by
    :func:`diameter_colours`. Right: the reduced set's centres (grey dots); for some spheres
    with candidates, e1, e2, the approach lines coloured by sphere class and P_o (see
    :func:`candidate_lines`). Both panels share equal, metre axes.

    Parameters
    ----------
    spheres : MedialSpheres or SphereGrid
    symmetry : Symmetry
    candidates : pandas.DataFrame
        The candidates table.
    hand : str, optional
        Whose candidates to draw; default the table's first hand.
    title : str
    size : (width, height) int, pixels
    approach_length : float
        Approach line length as a fraction of the object's bounding-box diagonal.
    max_lines, max_points : int
        At most this many segments (right) and sphere centres (left, a random subset).
    seed : int
        Seeds the subsets; the same seed gives the same image.
    view : (elevation, azimuth) float, degrees
    concavities : Concavities, optional
        The object's encompassing spheres (stage ``concavity``): drawn on the right in the
        ``encompassing`` colour with their candidates; without them those candidates are left out.

    Returns
    -------
    (height, width, 3) uint8
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    from matplotlib.lines import Line2D
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    centres, radii = np.asarray(spheres.centers), np.asarray(spheres.radii)
    if len(radii) == 0:
        raise BadInputError("spheres: is empty")
    low, high = (centres - radii[:, None]).min(axis=0), (centres + radii[:, None]).max(axis=0)
    length = approach_length * float(np.linalg.norm(high - low))
    if hand is None:
        hand = str(candidates.hand.iloc[0]) if len(candidates) else ""
    mine = candidates[candidates.hand == hand]
    around = (mine.sphere_class == "encompassing").to_numpy()
    segments, kinds, drawn = candidate_lines(symmetry, mine[~around], length=length, max_lines=max_lines, seed=seed)
    if concavities is not None and around.any():
        more = candidate_lines(
            concavities.spheres_for(np.inf), mine[around], length=length, max_lines=max_lines // 2, seed=seed
        )
        segments, kinds, drawn = np.concatenate([segments, more[0]]), np.concatenate([kinds, more[1]]), drawn + more[2]
    else:
        mine = mine[~around]
    if len(segments):
        low = np.minimum(low, segments.reshape(-1, 3).min(axis=0))
        high = np.maximum(high, segments.reshape(-1, 3).max(axis=0))

    figure = _canvas(size)
    if title:
        figure.suptitle(title, fontsize=11)
    top = 0.86 if title else 0.9
    left = figure.add_axes((0.07, 0.03, 0.43, top - 0.03), projection="3d")
    shown = np.arange(len(radii))
    if len(radii) > max_points:
        shown = np.sort(np.random.default_rng(seed).choice(len(radii), max_points, replace=False))
    span = np.ptp(radii)
    area = 1.0 + 24.0 * ((radii[shown] - radii.min()) / span if span > 0 else 0.5)
    left.scatter(*centres[shown].T, s=area, c=diameter_colours(2.0 * radii)[shown], linewidths=0, depthshade=False)
    _cube_axes(left, low, high, view)
    left.set_title(
        f"medial spheres: {len(radii)}" + (f" ({len(shown)} shown)" if len(shown) < len(radii) else ""), fontsize=9
    )
    colours = ScalarMappable(
        Normalize(2e3 * radii.min(), 2e3 * radii.max()),
        LinearSegmentedColormap.from_list("diameter", [(1, 0, 0), (0, 1, 0), (0, 0, 1)]),
    )
    bar = figure.colorbar(colours, cax=figure.add_axes((0.05, 0.25 * top, 0.012, 0.5 * top)))
    bar.set_label("sphere diameter (mm)", fontsize=8)
    bar.ax.yaxis.set_ticks_position("left")
    bar.ax.yaxis.set_label_position("left")
    bar.ax.tick_params(labelsize=7)

    right = figure.add_axes((0.52, 0.03, 0.46, top - 0.03), projection="3d")
    right.scatter(*np.asarray(symmetry.centers).T, s=0.5, c=[REDUCED_COLOUR], linewidths=0, depthshade=False)
    if concavities is not None and len(concavities):
        right.scatter(
            *np.asarray(concavities.centers).T, s=0.5, c=[CLASS_COLOURS["encompassing"]], linewidths=0, depthshade=False
        )
    palette = {"e1": E1_COLOUR, "e2": E2_COLOUR, "orient": ORIENT_COLOUR, **CLASS_COLOURS}
    if len(segments):
        right.add_collection3d(
            Line3DCollection(segments, colors=[palette.get(kind, (0, 0, 0)) for kind in kinds], linewidths=0.7)
        )
    _cube_axes(right, low, high, view)
    total = mine.sphere_index.nunique()
    right.set_title(
        f"reduced set: {len(symmetry)} spheres\n{hand or 'no hand'}: {len(mine)} candidates on "
        f"{total} spheres" + (f" ({drawn} drawn)" if drawn < total else ""),
        fontsize=9,
    )
    present = [kind for kind in CLASS_COLOURS if (kinds == kind).any()]
    handles = [Line2D([], [], marker=".", linestyle="", color=REDUCED_COLOUR, label="reduced set")]
    handles += [Line2D([], [], color=CLASS_COLOURS[kind], label=CLASS_LABELS[kind]) for kind in present]
    if len(segments):
        handles += [
            Line2D([], [], color=colour, label=label)
            for colour, label in ((ORIENT_COLOUR, "P_o"), (E1_COLOUR, "e1"), (E2_COLOUR, "e2"))
        ]
    right.legend(handles=handles, loc="upper left", fontsize=7, frameon=False)
    return _pixels(figure)


def best_grasps(trials, *, hand=None, count=3, planner="mat"):
    """The ``count`` force-closure trials of ``planner`` with the highest epsilon, best first.

    Parameters
    ----------
    trials : pandas.DataFrame
        The trials table (see :mod:`pipeline.trial.protocol`).
    hand : str, optional
        Only this hand's trials.
    count : int

    Returns
    -------
    pandas.DataFrame, rows of ``trials`` (index kept: the ``trial`` of the contacts table);
    ties in epsilon keep the table's order. Fewer rows when fewer trials are force closure.
    """
    if len(trials) == 0:
        return trials
    keep = (trials.outcome == "force_closure").to_numpy() & (trials.planner == planner).to_numpy()
    if hand is not None:
        keep &= (trials.hand == hand).to_numpy()
    rows = np.flatnonzero(keep)
    order = rows[np.argsort(-trials.epsilon.to_numpy()[rows], kind="stable")]
    return trials.iloc[order[:count]]


def grasp_images(surface, hand, trials, *, count=3, size=(400, 400), planner="mat"):
    """Pictures of ``hand``'s best force-closure grasps on the object (paper Fig. 7).

    Parameters
    ----------
    surface : SurfaceSamples
        The object; its mesh is drawn.
    hand : Hand
    trials : pandas.DataFrame
        The trials table; only ``hand``'s trials of ``planner`` count (see :func:`best_grasps`).
    count : int
    size : (width, height) int, pixels

    Returns
    -------
    list of (height, width, 3) uint8, best first: each trial's hand at its base pose
    (``base_*``, ``base_q*``) with its closed joints, framed on the hand and the object
    near it. Fewer than ``count`` (or none) when fewer trials are force closure.
    """
    from .render import render_hand

    images = []
    for row in best_grasps(trials, hand=hand.name, count=count, planner=planner).itertuples():
        joints = np.asarray(row.joints, dtype=np.float64)
        if joints.shape != (len(hand.limits),):
            raise BadInputError(
                f"trials: joints of trial {row.Index} have shape {joints.shape}, "
                f"hand {hand.name!r} has {len(hand.limits)} joints"
            )
        base = ((row.base_x, row.base_y, row.base_z), (row.base_qx, row.base_qy, row.base_qz, row.base_qw))
        images.append(
            render_hand(
                hand, dict(zip(hand.limits, joints.tolist())), base=base, surface=surface, size=size, frame="scene"
            )
        )
    return images


def image_grid(images, columns, *, pad=8):
    """Tile images row by row on white, ``pad`` pixels around and between them.

    Parameters
    ----------
    images : non-empty list of (h, w, 3) uint8
        Cells take the largest height and width; a smaller image sits at its cell's top left.
    columns : int, >= 1
    pad : int, pixels

    Returns
    -------
    (rows * (H + pad) + pad, columns' * (W + pad) + pad, 3) uint8, with columns' = min(columns,
    len(images)).
    """
    if not images:
        raise ValueError("images: empty list, nothing to tile")
    if columns < 1:
        raise ValueError(f"columns must be >= 1, got {columns}")
    height, width = max(image.shape[0] for image in images), max(image.shape[1] for image in images)
    columns = min(columns, len(images))
    rows = -(-len(images) // columns)
    grid = np.full((rows * (height + pad) + pad, columns * (width + pad) + pad, 3), 255, np.uint8)
    for number, image in enumerate(images):
        top, left = pad + (number // columns) * (height + pad), pad + (number % columns) * (width + pad)
        grid[top : top + image.shape[0], left : left + image.shape[1]] = image
    return grid


def calibration_figure(table, *, size=(900, 360)):
    """Held % per bin of the analytic scores (:func:`pipeline.outputs.report.calibration`'s table), MAT
    and the baseline, one line style per lift-and-shake (solid pybullet, dashed MuJoCo, dotted
    MuJoCo's open start): epsilon bins on the left (0 = no force closure, then the
    force-closure trials' deciles), robust force closure on the right. Returns (h, w, 3) uint8."""
    figure = _canvas(size)
    titles = {"epsilon": "epsilon (bin 0: no force closure; 1-10: deciles)", "robust_fc": "robust force closure"}
    styles = {"physics": ("o-", "pybullet"), "mujoco": ("s--", "MuJoCo"), "mujoco_open": ("^:", "MuJoCo open")}
    for number, score in enumerate(("epsilon", "robust_fc")):
        axes = figure.add_subplot(1, 2, number + 1)
        for check, (style, name) in styles.items():
            for planner, colour in (("mat", "tab:blue"), ("baseline", "tab:orange")):
                rows = table[(table.check == check) & (table.score == score) & (table.planner == planner)]
                if not rows.checked.sum():
                    continue
                x = rows.bin.to_numpy() if score == "epsilon" else (rows.low.to_numpy() + rows.high.to_numpy()) / 2
                label = f"{planner}, {name} ({rows.checked.sum()})"
                axes.plot(x, rows.physics_success_pct, style, color=colour, label=label, markersize=3)
        axes.set_xlabel(titles[score], fontsize=8)
        axes.set_ylabel("held in the lift-and-shake (%)", fontsize=8)
        axes.set_ylim(-5, 105)
        axes.tick_params(labelsize=7)
        axes.legend(fontsize=6, title="checked trials", title_fontsize=6)
        axes.grid(alpha=0.3)
    figure.tight_layout()
    return _pixels(figure)

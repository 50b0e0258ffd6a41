"""Candidate grasps from the symmetry classes (stage ``candidates``, paper III-C).

A candidate is a grasp target P_g (the sphere centre), an approach direction P_d (unit,
the direction the hand moves), a hand orientation P_o (unit, the axis the fingers wrap
around, orthogonal to P_d) and a preshape. Only spheres whose diameter the hand can grasp
get candidates. Per class:

- ``axis`` and ``pair``: ``approach_directions`` directions evenly spaced in the plane
  orthogonal to e1, starting at e2; P_o = e1.
- ``rim``: P_o = e1; P_d = e2 or -e2, whichever moves the hand from outside the rim toward
  the neighbourhood's centre of gravity (paper: -e2 when the angle to it is >= 90 degrees).
  With ``centre_rims`` P_g moves across the rim, along P_d x P_o, so that the open hand's
  finger gap is centred on all the object's material between its fingers, where that fits
  the gap (:func:`centre_on_material`): a thin wall round a cavity narrower than the hand (a
  cup's) is then grasped with the cavity's far wall inside the hand, not with fingers landing
  on it. A plate's edge or a solid's rim has its material centred on the sphere already.
- ``interior``: none.
- ``isolated`` (a spherical part): the six directions +-x, +-y, +-z of the object frame,
  with P_o = z for the four horizontal approaches and P_o = x for the two vertical ones.

- ``encompassing`` (:mod:`pipeline.geometry.concavity`): the filled object's spheres inside a
  container's concavity no wider than ``max_width_ratio`` x the hand's limit, their candidates
  made by their own class on the filled object as above, labelled ``encompassing``;
  ``sphere_index`` (and so ``id``) of these rows indexes the filled object's sphere grid.

With ``flipped_candidates`` (Simox's default) every candidate is repeated with P_o = -P_o,
so an axis sphere gives 8 candidates and a rim sphere 2.

Candidate ids are stable: ``sphere_index * 64 + k``, k the candidate's rank for its sphere.
"""

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from ..hands.kinematics import open_gap
from .symmetry import AXIS, CLASSES, ISOLATED, PAIR, RIM

#: ``sphere_class`` of the candidates: the classes of :mod:`pipeline.geometry.symmetry` and ``encompassing``
CANDIDATE_CLASSES = CLASSES + ("encompassing",)
IDS_PER_SPHERE = 64
_ISOLATED_APPROACH = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
_ISOLATED_ORIENT = np.array([[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [1, 0, 0], [1, 0, 0]], float)

COLUMNS = [
    "hand",
    "id",
    "sphere_index",
    "sphere_class",
    "diameter_m",
    "preshape",
    "grasp_x",
    "grasp_y",
    "grasp_z",
    "approach_x",
    "approach_y",
    "approach_z",
    "orient_x",
    "orient_y",
    "orient_z",
]


CENTRING_CHUNK = 64  # rim candidates whose neighbourhoods are gathered at once (memory)
RIM_CLEARANCE_M = 0.002
"""Room (m) left between the material and each side of the finger gap for a rim's P_g to be
moved (the trial's contact tolerance: closer, a finger would start touching)."""


def centre_on_material(grasp, approach, orient, radius, centres, radii, gap):
    """Grasp points moved across P_d so the open hand's finger gap is centred on the material
    between its fingers, where that fits in the gap.

    Parameters
    ----------
    grasp, approach, orient : (n, 3) float
        P_g (m), P_d and P_o (unit) of the candidates.
    radius : (n,) float
        Their spheres' radii (m): material from this far behind P_g along P_d on counts.
    centres, radii : (m, 3), (m,) float
        The object's medial spheres (its material), m.
    gap : tuple
        :func:`pipeline.hands.kinematics.open_gap` of the hand's preshape.

    Returns
    -------
    (n, 3) float: P_g moved along u = P_d x P_o by the offset that puts the middle of the
    material's extent along u (spheres whose centres lie between the fingers: within the
    fingers' half width along P_o, from ``radius`` behind P_g to the fingers' reach along P_d,
    within the gap's width along u) on the middle of the gap; unmoved where that extent is
    wider than the gap less :data:`RIM_CLEARANCE_M` each side.
    """
    lo, hi, half_width, reach = gap
    width = hi - lo
    across = np.cross(approach, orient)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    moved = grasp.copy()
    # a sphere wider than the gap cannot fit in it with its neighbours
    candidates = np.flatnonzero(2 * radius <= width - 2 * RIM_CLEARANCE_M)
    tree = cKDTree(centres)
    for first in range(0, len(candidates), CENTRING_CHUNK):
        rows = candidates[first : first + CENTRING_CHUNK]
        # the ball round the box between the fingers: along P_o, P_d, u half extents
        # half_width, (reach + radius) / 2, width, centred ahead of P_g
        middle = grasp[rows] + approach[rows] * ((reach - radius[rows]) / 2)[:, None]
        ball = np.sqrt(half_width**2 + ((reach + radius[rows]) / 2) ** 2 + width**2)
        found = tree.query_ball_point(middle, ball, return_sorted=False)
        owner = np.repeat(np.arange(len(rows)), [len(near) for near in found])
        index = np.concatenate([np.asarray(near, np.int64) for near in found])
        offset = centres[index] - grasp[rows][owner]
        along, ahead, side = (np.einsum("ij,ij->i", offset, axis[rows][owner]) for axis in (orient, approach, across))
        between = (
            (np.abs(along) <= half_width) & (ahead >= -radius[rows][owner]) & (ahead <= reach) & (np.abs(side) <= width)
        )
        low, high = np.full(len(rows), np.inf), np.full(len(rows), -np.inf)
        np.minimum.at(low, owner[between], side[between] - radii[index[between]])
        np.maximum.at(high, owner[between], side[between] + radii[index[between]])
        fits = high - low <= width - 2 * RIM_CLEARANCE_M
        shift = np.where(fits, (low + high - lo - hi) / 2, 0.0)
        moved[rows] += shift[:, None] * across[rows]
    return moved


def generate(
    symmetry,
    hand,
    *,
    approach_directions=4,
    flipped_candidates=True,
    centre_rims=True,
    preshape=None,
    label=None,
):
    """Candidate grasps for one hand, as a table.

    Parameters
    ----------
    symmetry : Symmetry
    hand : Hand
    approach_directions : int
        Directions around an axis.
    flipped_candidates : bool
    centre_rims : bool
        Move rim candidates' P_g to centre the open hand on the material between its fingers
        (:func:`centre_on_material`); false: P_g at the sphere centre, as the paper.
    preshape : str, optional
        Defaults to the hand's first preshape.
    label : str, optional
        ``sphere_class`` of every row (default: the sphere's class).

    Returns
    -------
    pandas.DataFrame
        One row per candidate, columns :data:`COLUMNS`; grasp_* in metres (object frame),
        approach_* = P_d and orient_* = P_o as unit vectors.
    """
    axes = np.asarray(symmetry.axes).reshape(-1, 3, 3)
    e1, e2, e3 = axes[:, 0], axes[:, 1], axes[:, 2]
    class_id = np.asarray(symmetry.class_id)
    graspable = 2.0 * np.asarray(symmetry.radii) <= hand.max_graspable_diameter
    rows, approach, orient = [], [], []

    tube = np.flatnonzero(graspable & np.isin(class_id, (AXIS, PAIR)))
    angle = 2.0 * np.pi * np.arange(approach_directions) / approach_directions
    approach.append(
        (np.cos(angle)[None, :, None] * e2[tube, None] + np.sin(angle)[None, :, None] * e3[tube, None]).reshape(-1, 3)
    )
    orient.append(np.repeat(e1[tube], approach_directions, axis=0))
    rows.append(np.repeat(tube, approach_directions))

    rim = np.flatnonzero(graspable & (class_id == RIM))
    toward_cog = np.asarray(symmetry.cog)[rim] - np.asarray(symmetry.centers)[rim]
    sign = np.where((e2[rim] * toward_cog).sum(axis=1) <= 0, -1.0, 1.0)  # angle >= 90 deg -> -e2
    approach.append(sign[:, None] * e2[rim])
    orient.append(e1[rim])
    rows.append(rim)

    single = np.flatnonzero(graspable & (class_id == ISOLATED))
    approach.append(np.tile(_ISOLATED_APPROACH, (len(single), 1)))
    orient.append(np.tile(_ISOLATED_ORIENT, (len(single), 1)))
    rows.append(np.repeat(single, len(_ISOLATED_APPROACH)))

    row, approach, orient = np.concatenate(rows), np.concatenate(approach), np.concatenate(orient)
    if flipped_candidates:
        row, approach, orient = (
            np.concatenate([row, row]),
            np.concatenate([approach, approach]),
            np.concatenate([orient, -orient]),
        )
    # group by sphere, keeping the generation order inside each sphere: stable ranks
    order = np.argsort(row, kind="stable")
    row, approach, orient = row[order], approach[order], orient[order]
    start = np.searchsorted(row, row, side="left")
    rank = np.arange(len(row)) - start
    sphere_index = np.asarray(symmetry.sphere_index)[row]
    centers = np.asarray(symmetry.centers)[row]
    preshape = preshape or hand.default_preshape
    moved = class_id[row] == RIM
    gap = open_gap(hand, preshape) if centre_rims and moved.any() else None
    if gap is not None:
        radii = np.asarray(symmetry.radii, float)
        centers = centers.copy()
        centers[moved] = centre_on_material(
            centers[moved], approach[moved], orient[moved], radii[row[moved]], np.asarray(symmetry.centers), radii, gap
        )
    table = pd.DataFrame(
        {
            "hand": hand.name,
            "id": sphere_index * IDS_PER_SPHERE + rank,
            "sphere_index": sphere_index,
            "sphere_class": pd.Categorical(
                np.asarray(CLASSES)[class_id[row]] if label is None else np.full(len(row), label),
                categories=CANDIDATE_CLASSES,
            ),
            "diameter_m": 2.0 * np.asarray(symmetry.radii)[row],
            "preshape": preshape,
            "grasp_x": centers[:, 0],
            "grasp_y": centers[:, 1],
            "grasp_z": centers[:, 2],
            "approach_x": approach[:, 0],
            "approach_y": approach[:, 1],
            "approach_z": approach[:, 2],
            "orient_x": orient[:, 0],
            "orient_y": orient[:, 1],
            "orient_z": orient[:, 2],
        }
    )
    return table.sort_values("id", kind="stable").reset_index(drop=True)


def generate_for_hands(
    symmetry,
    concavities,
    hands,
    *,
    approach_directions=4,
    flipped_candidates=True,
    centre_rims=True,
    max_width_ratio=1.0,
):
    """The ``candidates`` stage as a pure function: one table, a block of rows per hand, its
    ``encompassing`` candidates after the others.

    Parameters
    ----------
    symmetry : Symmetry
    concavities : Concavities or None
        The encompassing spheres (stage ``concavity``); None: none.
    hands : list of Hand
    approach_directions, flipped_candidates, centre_rims
        See :func:`generate`.
    max_width_ratio : float
        See :meth:`pipeline.geometry.concavity.Concavities.spheres_for`.

    Returns
    -------
    pandas.DataFrame, columns :data:`COLUMNS`; ``(hand, sphere_class == "encompassing", id)`` is unique
    """
    options = dict(approach_directions=approach_directions, flipped_candidates=flipped_candidates)
    tables = []
    for hand in hands:
        tables.append(generate(symmetry, hand, **options, centre_rims=centre_rims))
        if concavities is not None and len(concavities):
            # the encompassing spheres are a part of the filled object, not all its material
            spheres = concavities.spheres_for(hand.max_graspable_diameter, max_width_ratio)
            tables.append(generate(spheres, hand, **options, centre_rims=False, label="encompassing"))
    return pd.concat(tables, ignore_index=True)

"""Candidate grasps from the symmetry classes (stage ``candidates``, paper III-C).

A candidate is a grasp target P_g (the sphere centre), an approach direction P_d (unit,
the direction the hand moves), a hand orientation P_o (unit, the axis the fingers wrap
around, orthogonal to P_d) and a preshape. Only spheres whose diameter the hand can grasp
get candidates. Per class:

- ``axis`` and ``pair``: ``approach_directions`` directions evenly spaced in the plane
  orthogonal to e1, starting at e2; P_o = e1.
- ``rim``: P_o = e1; P_d = e2 or -e2, whichever moves the hand from outside the rim toward
  the neighbourhood's centre of gravity (paper: -e2 when the angle to it is >= 90 degrees).
- ``interior``: none.
- ``isolated`` (a spherical part): the six directions +-x, +-y, +-z of the object frame,
  with P_o = z for the four horizontal approaches and P_o = x for the two vertical ones.

- ``encompassing`` (:mod:`pipeline.concavity`): the filled object's spheres inside a
  container's concavity no wider than ``max_width_ratio`` x the hand's limit, their candidates
  made by their own class on the filled object as above, labelled ``encompassing``;
  ``sphere_index`` (and so ``id``) of these rows indexes the filled object's sphere grid.

With ``flipped_candidates`` (Simox's default) every candidate is repeated with P_o = -P_o,
so an axis sphere gives 8 candidates and a rim sphere 2.

Candidate ids are stable: ``sphere_index * 64 + k``, k the candidate's rank for its sphere.
"""

import numpy as np
import pandas as pd

from .symmetry import AXIS, CLASSES, ISOLATED, PAIR, RIM

#: ``sphere_class`` of the candidates: the classes of :mod:`pipeline.symmetry` and ``encompassing``
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


def generate(symmetry, hand, *, approach_directions=4, flipped_candidates=True, preshape=None, label=None):
    """Candidate grasps for one hand, as a table.

    Parameters
    ----------
    symmetry : Symmetry
    hand : Hand
    approach_directions : int
        Directions around an axis.
    flipped_candidates : bool
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
            "preshape": preshape or hand.default_preshape,
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
    symmetry, concavities, hands, *, approach_directions=4, flipped_candidates=True, max_width_ratio=1.0
):
    """The ``candidates`` stage as a pure function: one table, a block of rows per hand, its
    ``encompassing`` candidates after the others.

    Parameters
    ----------
    symmetry : Symmetry
    concavities : Concavities or None
        The encompassing spheres (stage ``concavity``); None: none.
    hands : list of Hand
    max_width_ratio : float
        See :meth:`pipeline.concavity.Concavities.spheres_for`.

    Returns
    -------
    pandas.DataFrame, columns :data:`COLUMNS`; ``(hand, sphere_class == "encompassing", id)`` is unique
    """
    options = dict(approach_directions=approach_directions, flipped_candidates=flipped_candidates)
    tables = []
    for hand in hands:
        tables.append(generate(symmetry, hand, **options))
        if concavities is not None and len(concavities):
            spheres = concavities.spheres_for(hand.max_graspable_diameter, max_width_ratio)
            tables.append(generate(spheres, hand, **options, label="encompassing"))
    return pd.concat(tables, ignore_index=True)

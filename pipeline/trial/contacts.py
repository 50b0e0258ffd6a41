"""The contact model of a grasp trial, as the peers' tools define it.

1. Every hand link, the palm included, whose distance to the object
   (:func:`pipeline.trial.proximity.measure`) is within the contact tolerance touches it, and every
   touching pair of that measure is a contact candidate: a link surface point's closest mesh
   point with the touched triangle's outward normal (on an object edge or corner, the link
   face's normal reversed: the object's feature against the link's face), or a mesh feature
   point (a vertex, a point on a non-flat edge) near the link with the link face's normal
   reversed (off a link edge or corner, the link face there that best faces the object's own
   normal). On a smooth surface's facet seams (faces within 30 deg) that normal is clamped into
   the seam's normal cone, the surface's own normal: a fingertip's tilt on a 96-gon mug made
   opposite normals and a force closure the real surface does not give
   (:func:`pipeline.geometry.mesh_query.feature_contact_normals`). So a link the closing rule stopped
   always has contacts.
2. Per link, candidates whose normals lie within ``coplanar_deg`` of a seed normal form one
   contact region, seeds taken from the most touched normal down. Regions are not chained
   from neighbour to neighbour: a finger along a round chair leg touches facets 4 deg apart,
   which a chain merged into one region whose hull, across its mean normal, kept only the
   finger face's own normal and lost the leg's curvature (Barrett on the chair 89 -> 52 %
   force closure on the same closed hands once contacts were measured every 1 mm). As GraspIt! does, a
   region is replaced by the corners of its 2D convex hull in the plane across its mean normal:
   a face contact becomes its polygon's corners, a line contact its two ends, a point stays a
   point. Each corner keeps its own normal. Every corner counts, as in GraspIt (the epsilon
   computation, :mod:`pipeline.trial.quality`, grows a hull from the extreme wrenches, so many
   contacts cost little). ``max_corners`` can cap them per link, chosen farthest first (from the
   one farthest from their centroid, so the choice follows the geometry, not the order found);
   a cap of 4 drops a facetted part's other facets, which moved Barrett on the chair's legs
   from 80 to 31 % force closure.

On a tessellated curved surface the normal is the touched facet's: it differs from the smooth
surface's by at most half the angle between neighbouring facets (under a degree on the built-in
objects' meshes).
"""

import numpy as np
from numba import njit, types
from numba.typed import Dict

from ..tol import tol


def region_corners(points, normals, *, coplanar_deg=5.0, merge_m=None, max_corners=0):
    """Indices of the contacts that represent one link's contact candidates.

    Parameters
    ----------
    points : (n, 3) float, metres
    normals : (n, 3) float, outward unit normals
    coplanar_deg : float
        Largest angle (degrees) between normals of one region.
    merge_m : float, optional
        Candidates closer than this (m) with agreeing normals count once (default
        :attr:`pipeline.tol.Tolerances.contact_merge_m`).
    max_corners : int
        Most contacts kept for the link, farthest first; 0 = every corner.

    Returns
    -------
    (k,) int, sorted: the hull corners of every region.
    """
    points, normals = np.asarray(points, np.float64), np.asarray(normals, np.float64)
    if len(points) <= 2:
        return np.arange(len(points))
    merge_m = tol.contact_merge_m if merge_m is None else merge_m
    # candidates are compared after rounding: several measures can find the same touching point
    rounded = np.round(np.concatenate((points, normals), axis=1), tol.point_decimals)
    corners = _corners(points, normals, rounded, np.cos(np.radians(coplanar_deg)), merge_m, tol.straight_turn)
    return np.sort(_farthest(points, corners, max_corners))


_ROW, _NORMAL = types.UniTuple(types.float64, 6), types.UniTuple(types.float64, 3)


@njit(cache=True)
def _corners(points, normals, rounded, agree_cos, merge_m, straight):
    """Sorted indices of the hull corners of every region (see :func:`region_corners`): each
    rounded candidate once (its first occurrence); regions of (rounded) normals within
    ``agree_cos`` of a seed's; per region :func:`_hull_2d` (``straight``: :attr:`pipeline.tol.Tolerances.straight_turn`)."""
    count = len(points)
    seen = Dict.empty(key_type=_ROW, value_type=types.int64)
    rows = np.empty(count, np.int64)
    kept = 0
    for row in range(count):
        key = (rounded[row, 0], rounded[row, 1], rounded[row, 2], rounded[row, 3], rounded[row, 4], rounded[row, 5])
        if key not in seen:
            seen[key] = row
            rows[kept] = row
            kept += 1
    rows = rows[:kept]
    # regions are found among the distinct normals: a link lying on one facet touches it at
    # many points, but the facets and link faces involved are few
    distinct = Dict.empty(key_type=_NORMAL, value_type=types.int64)
    which = np.empty(kept, np.int64)
    first_row = np.empty(kept, np.int64)
    for position in range(kept):
        row = rows[position]
        key = (rounded[row, 3], rounded[row, 4], rounded[row, 5])
        if key not in distinct:
            first_row[len(distinct)] = row
            distinct[key] = len(distinct)
        which[position] = distinct[key]
    # each region gathers the normals within agree_cos of its seed, seeds taken from the most
    # touched normal down (ties: the smaller normal, lexicographically), so the regions do not
    # hang on the order the measure found the points in
    found = len(distinct)
    counts = np.zeros(found, np.int64)
    for position in range(kept):
        counts[which[position]] += 1
    order = np.arange(found)
    for one in range(1, found):  # insertion sort: few distinct normals
        moving, place = order[one], one
        while place > 0 and _before(counts, rounded, first_row, moving, order[place - 1]):
            order[place] = order[place - 1]
            place -= 1
        order[place] = moving
    labels = np.full(found, -1, np.int64)
    for seed in order:
        if labels[seed] >= 0:
            continue
        a = rounded[first_row[seed], 3:]
        for other in range(found):
            b = rounded[first_row[other], 3:]
            if labels[other] < 0 and a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= agree_cos:
                labels[other] = seed
    region = labels[which]
    corner = np.zeros(count, np.bool_)
    for label in np.unique(region):
        members = rows[region == label]
        for index in _hull_2d(points[members], normals[members], merge_m, straight):
            corner[members[index]] = True
    return np.flatnonzero(corner)


@njit(cache=True)
def _before(counts, rounded, first_row, one, other):
    """Whether distinct normal ``one`` seeds before ``other``: more touching points, then the
    smaller rounded normal."""
    if counts[one] != counts[other]:
        return counts[one] > counts[other]
    for axis in range(3, 6):
        a, b = rounded[first_row[one], axis], rounded[first_row[other], axis]
        if a != b:
            return a < b
    return False


@njit(cache=True)
def _hull_2d(points, normals, merge_m, straight):
    """Corners (indices) of the 2D convex hull of (k, 3) points across their mean normal: the
    two ends when they are (nearly) on a line, the first when they are (nearly) one point."""
    count = len(points)
    if count == 1:
        return np.zeros(1, np.int64)
    normal = normals.sum(axis=0)
    normal /= np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = np.cross(normal, helper)
    first /= np.linalg.norm(first)
    second = np.cross(normal, first)
    offset = points - points[0]
    plane = np.empty((count, 2))
    plane[:, 0], plane[:, 1] = offset @ first, offset @ second
    centred = plane - plane.sum(axis=0) / count
    # the spreads (singular values) and main axis of the centred points, from their 2 x 2 scatter
    xx, xy, yy = (centred[:, 0] ** 2).sum(), (centred[:, 0] * centred[:, 1]).sum(), (centred[:, 1] ** 2).sum()
    largest = (xx + yy) / 2 + np.sqrt(((xx - yy) / 2) ** 2 + xy**2)
    smallest = max(xx * yy - xy**2, 0.0) / largest if largest > 0 else 0.0
    if np.sqrt(largest) <= merge_m:
        return np.zeros(1, np.int64)
    if np.sqrt(smallest) > merge_m * np.sqrt(count):
        return _monotone_chain(plane, straight)
    axis = np.array([largest - yy, xy]) if xx >= yy else np.array([xy, largest - xx])
    along = centred @ (axis / np.linalg.norm(axis))
    return np.unique(np.array([along.argmin(), along.argmax()]))


@njit(cache=True)
def _monotone_chain(plane, straight):
    """Sorted indices of the corners of the convex hull of (k, 2) points (Andrew's monotone
    chain); a point on an edge, its turn within ``straight`` x the extent squared, is not a
    corner (as with Qhull)."""
    order = np.argsort(plane[:, 1], kind="mergesort")
    order = order[np.argsort(plane[order, 0], kind="mergesort")]
    extent = max(plane[:, 0].max() - plane[:, 0].min(), plane[:, 1].max() - plane[:, 1].min())
    slack = straight * extent * extent
    chain = np.empty(2 * len(order) + 1, np.int64)
    size = 0
    for sweep in range(2):  # the lower hull left to right, then the upper one back
        start = size
        for step in range(len(order)):
            index = order[step] if sweep == 0 else order[len(order) - 1 - step]
            while size >= start + 2:
                a, b = plane[chain[size - 2]], plane[chain[size - 1]]
                turn = (b[0] - a[0]) * (plane[index, 1] - a[1]) - (b[1] - a[1]) * (plane[index, 0] - a[0])
                if turn > slack:
                    break
                size -= 1
            chain[size] = index
            size += 1
        size -= 1  # each half ends where the other starts
    return np.unique(chain[:size])


def _farthest(points, indices, count):
    """At most ``count`` (0: all) of ``indices``: the one farthest from their centroid, then each time
    the one farthest from those kept; ties go to the smallest (x, y, z), so that the choice
    follows the geometry, not the order."""
    if not count or len(indices) <= count:
        return indices
    chosen = points[indices]
    # lexicographic rank of each point: the tie-break
    rank = np.empty(len(chosen), np.int64)
    rank[np.lexsort(chosen.T[::-1])] = np.arange(len(chosen))

    def pick(values):
        values = np.round(values, tol.point_decimals)
        values[kept] = -np.inf  # never twice, though several corners share a position
        best = values == values.max()
        return int(np.flatnonzero(best)[rank[best].argmin()])

    kept = []
    kept.append(pick(np.linalg.norm(chosen - chosen.mean(axis=0), axis=1)))
    gap = np.linalg.norm(chosen - chosen[kept[0]], axis=1)
    while len(kept) < count:
        kept.append(pick(gap))
        gap = np.minimum(gap, np.linalg.norm(chosen - chosen[kept[-1]], axis=1))
    return indices[kept]

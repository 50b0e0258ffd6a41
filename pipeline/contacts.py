"""The contact model of a grasp trial, as the peers' tools define it (facts.md 8).

1. Every hand link, the palm included, whose distance to the object
   (:func:`pipeline.proximity.measure`) is within the contact tolerance touches it, and every
   touching pair of that measure is a contact candidate: a link surface point's closest mesh
   point with the touched triangle's outward normal, or a mesh feature point (a vertex, a
   point on a non-flat edge) near the link with the link face's normal reversed (off a link
   edge or corner, the link face there that best faces the object's own normal). So
   a link the closing rule stopped always has contacts.
2. Per link, candidates whose normals agree within ``coplanar_deg`` form one contact region
   (connected by agreement, so a smoothly curved patch is one region). As GraspIt! does, a
   region is replaced by the corners of its 2D convex hull in the plane across its mean normal:
   a face contact becomes its polygon's corners, a line contact its two ends, a point stays a
   point. Each corner keeps its own normal. Every corner counts, as in GraspIt (the epsilon
   computation, :mod:`pipeline.quality`, grows a hull from the extreme wrenches, so many
   contacts cost little). ``max_corners`` can cap them per link, chosen farthest first (from the
   one farthest from their centroid, so the choice follows the geometry, not the order found);
   a cap of 4 drops a facetted part's other facets, which moved Barrett on the chair's legs
   from 80 to 31 % force closure.

On a tessellated curved surface the normal is the touched facet's: it differs from the smooth
surface's by at most half the angle between neighbouring facets (under a degree on the built-in
objects' meshes).
"""

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from .tol import tol


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
    if len(points) <= 2:
        return np.arange(len(points))
    merge_m = tol.contact_merge_m if merge_m is None else merge_m
    # each candidate once: several measures can find the same touching point
    rows = np.sort(np.unique(np.round(np.c_[points, normals], tol.point_decimals), axis=0, return_index=True)[1])
    points, normals = points[rows], normals[rows]
    # regions are found among the distinct normals: a link lying on one facet touches it at
    # many points, but the facets and link faces involved are few
    distinct, inverse = np.unique(np.round(normals, tol.point_decimals), axis=0, return_inverse=True)
    agree = distinct @ distinct.T >= np.cos(np.radians(coplanar_deg))
    region = (
        np.zeros(len(points), np.int64)
        if agree.all()
        else connected_components(agree, directed=False)[1][inverse.reshape(-1)]
    )
    keep = []
    for label in np.unique(region):
        members = np.flatnonzero(region == label)
        corners = members[_hull_2d(points[members], normals[members].mean(axis=0), merge_m)]
        keep += list(corners)
    return np.sort(rows[_farthest(points, np.array(keep, dtype=np.int64), max_corners)])


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


def _hull_2d(points, normal, merge_m):
    """Corners of the 2D convex hull of points across ``normal``: two ends when they are on a
    line, one when they are (nearly) one point."""
    if len(points) == 1:
        return np.array([0])
    normal = normal / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = np.cross(normal, helper)
    first /= np.linalg.norm(first)
    plane = np.column_stack([(points - points[0]) @ first, (points - points[0]) @ np.cross(normal, first)])
    centred = plane - plane.mean(axis=0)
    _, spread, axes = np.linalg.svd(centred, full_matrices=False)
    if spread[0] <= merge_m:
        return np.array([0])
    if spread[1] > merge_m * np.sqrt(len(points)):
        try:
            return np.sort(ConvexHull(plane).vertices)
        except QhullError:
            pass
    along = centred @ axes[0]
    return np.unique([along.argmin(), along.argmax()])

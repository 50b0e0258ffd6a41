"""Distance from the origin to the boundary of a point set's convex hull, by an expanding polytope.

The Ferrari-Canny epsilon (:mod:`pipeline.trial.quality`) is this distance for the grasp's wrenches in
6D. The expanding polytope algorithm (EPA, as GJK's penetration-depth step does in 3D) finds it
without the whole hull: start from a simplex of the points, then repeatedly take the polytope's
facet nearest the origin, find the point farthest along its normal (the support) and, while that
point lies beyond the facet, add it (beneath-beyond: the facets it sees are replaced by cones from
their horizon ridges to it). The polytope is inside the whole hull, so its nearest facet is never
farther than the whole hull's boundary; when no point lies beyond that facet, the facet supports
the whole hull and its distance is the answer. A point added sees the facet it was found for, so
the polytope grows by one point a round, only where the answer is decided: a grasp's 100-400
wrenches end on a polytope of 15-35 of them, where Qhull's whole hull has 10,000-50,000 facets.

Degenerate input (a flat simplex, a sliver facet, a surface that does not close) is reported
rather than guessed around, and the caller falls back to Qhull.

References
----------
van den Bergen, G. (2001). Proximity queries and penetration depth computation on 3D game
objects. Game Developers Conference.
Edelsbrunner, H. (1987). Algorithms in combinatorial geometry, ch. 8 (beneath-beyond).
"""

import numpy as np
from numba import njit

from ..tol import tol

# an index of a point takes this many bits of a ridge's key (its dimension - 1 indices packed in
# one int64), so the points are at most 2 ** bits
_KEY_BITS = 63


def nearest_facet(points, *, beyond=None, inside=None, flat=None):
    """Signed distance (float) from the origin to the boundary of the convex hull of ``points``
    (positive inside), or None when the points are too degenerate for the expanding polytope.

    Parameters
    ----------
    points : (n, d) float
        Full-rank points (their affine span is all of R^d), d >= 2.
    beyond : float, optional
        A point must lie this far past a facet's plane to count as beyond it; the answer is then
        within ``beyond`` of the exact distance (default :attr:`pipeline.tol.Tolerances.hull_beyond`).
    inside : float, optional
        A support at most this far past the origin puts the origin outside the hull, and the
        search ends (default :attr:`pipeline.tol.Tolerances.hull_inside`).
    flat : float, optional
        A facet with a vertex nearer than this x its edge's length to the span of its other
        edges is a sliver: None (default :attr:`pipeline.tol.Tolerances.hull_sliver`).

    Returns
    -------
    float or None
        Outside the hull: a value <= ``inside`` (a support, not the exact distance).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    count, dimension = points.shape
    if dimension < 2 or count <= dimension or count >= 2 ** (_KEY_BITS // (dimension - 1)):
        return None
    beyond = tol.hull_beyond if beyond is None else beyond
    inside = tol.hull_inside if inside is None else inside
    flat = tol.hull_sliver if flat is None else flat
    found, distance = _expand(points, beyond, inside, flat, _KEY_BITS // (dimension - 1))
    return float(distance) if found else None


@njit(cache=True)
def _dot(first, second):
    total = 0.0
    for axis in range(len(first)):
        total += first[axis] * second[axis]
    return total


@njit(cache=True)
def _plane(points, vertices, centre, flat, basis, normal):
    """Write into ``normal`` (d,) the unit normal of the hyperplane through ``points[vertices]``
    (d,), facing away from ``centre``; returns its offset and whether it is well defined (no
    Gram-Schmidt residual under ``flat``). ``basis`` (d - 1, d) is scratch."""
    dimension = points.shape[1]
    origin = points[vertices[0]]
    for row in range(dimension - 1):
        edge = basis[row]
        apex = points[vertices[row + 1]]
        for axis in range(dimension):
            edge[axis] = apex[axis] - origin[axis]
        length = np.sqrt(_dot(edge, edge))
        for _ in range(2):  # modified Gram-Schmidt, reorthogonalised
            for earlier in range(row):
                along = _dot(edge, basis[earlier])
                for axis in range(dimension):
                    edge[axis] -= along * basis[earlier, axis]
        residual = np.sqrt(_dot(edge, edge))
        if residual <= flat * max(length, 1e-300):
            return 0.0, False
        for axis in range(dimension):
            edge[axis] /= residual
    # the normal: the coordinate axis least in the span, less its part in the span
    best = -1.0
    for unit in range(dimension):
        size = 1.0
        for row in range(dimension - 1):
            size -= basis[row, unit] ** 2
        if size > best:
            best, chosen = size, unit
    for axis in range(dimension):
        normal[axis] = 1.0 if axis == chosen else 0.0
    for _ in range(2):
        for row in range(dimension - 1):
            along = _dot(normal, basis[row])
            for axis in range(dimension):
                normal[axis] -= along * basis[row, axis]
    size = np.sqrt(_dot(normal, normal))
    for axis in range(dimension):
        normal[axis] /= size
    offset = _dot(normal, origin)
    side = _dot(normal, centre) - offset
    if side > 0:
        for axis in range(dimension):
            normal[axis] = -normal[axis]
        offset, side = -offset, -side
    return offset, -side > flat * flat


@njit(cache=True)
def _argmax(values):
    best = 0
    for position in range(1, len(values)):
        if values[position] > values[best]:
            best = position
    return best


@njit(cache=True)
def _key(vertices, skip, bits):
    """int64 key of the ridge ``vertices`` (sorted) without position ``skip``."""
    key = 0
    for position in range(len(vertices)):
        if position != skip:
            key = (key << bits) | vertices[position]
    return key


@njit(cache=True)
def _simplex(points, flat):
    """Indices (d + 1,) of a well-spread simplex of ``points``: each vertex the farthest from the
    affine span of those before (the first: farthest from the centroid); and False if flat."""
    count, dimension = points.shape
    chosen = np.empty(dimension + 1, np.int64)
    mean = np.zeros(dimension)
    for row in range(count):
        for axis in range(dimension):
            mean[axis] += points[row, axis] / count
    residual = np.empty((count, dimension))
    lengths = np.empty(count)
    for row in range(count):
        for axis in range(dimension):
            residual[row, axis] = points[row, axis] - mean[axis]
        lengths[row] = _dot(residual[row], residual[row])
    chosen[0] = _argmax(lengths)
    for row in range(count):
        for axis in range(dimension):
            residual[row, axis] = points[row, axis] - points[chosen[0], axis]
        lengths[row] = _dot(residual[row], residual[row])
    extent = np.sqrt(lengths[_argmax(lengths)])
    direction = np.empty(dimension)
    for vertex in range(1, dimension + 1):
        chosen[vertex] = _argmax(lengths)
        longest = np.sqrt(lengths[chosen[vertex]])
        if longest <= flat * extent:
            return chosen, False
        for axis in range(dimension):
            direction[axis] = residual[chosen[vertex], axis] / longest
        for row in range(count):
            along = _dot(residual[row], direction)
            for axis in range(dimension):
                residual[row, axis] -= along * direction[axis]
            lengths[row] = _dot(residual[row], residual[row])
    return chosen, True


@njit(cache=True)
def _expand(points, beyond, inside, flat, bits):
    """(found, signed distance): see :func:`nearest_facet`."""
    count, dimension = points.shape
    simplex, spread = _simplex(points, flat)
    if not spread:
        return False, 0.0
    centre = np.zeros(dimension)
    for vertex in simplex:
        for axis in range(dimension):
            centre[axis] += points[vertex, axis] / (dimension + 1)
    basis = np.empty((dimension - 1, dimension))
    capacity = 512
    vertices = np.empty((capacity, dimension), np.int64)
    normals = np.empty((capacity, dimension))
    offsets = np.empty(capacity)
    facets = 0
    _sort_by(simplex, simplex.copy(), dimension + 1)
    for skip in range(dimension + 1):
        column = 0
        for place in range(dimension + 1):
            if place != skip:
                vertices[facets, column] = simplex[place]
                column += 1
        offsets[facets], fine = _plane(points, vertices[facets], centre, flat, basis, normals[facets])
        if not fine:
            return False, 0.0
        facets += 1
    visible = np.empty(capacity, np.int64)
    keys = np.empty(capacity * dimension, np.int64)
    order = np.empty(capacity * dimension, np.int64)
    ridges = np.empty((capacity * dimension, dimension), np.int64)
    for _ in range(count):  # each round adds a point, so this many rounds always suffice
        nearest = 0
        for facet in range(1, facets):
            if offsets[facet] < offsets[nearest]:
                nearest = facet
        distance = offsets[nearest]
        apex, support = 0, -np.inf
        for row in range(count):
            along = _dot(points[row], normals[nearest])
            if along > support:
                apex, support = row, along
        if support <= inside or support - distance <= beyond:
            return True, min(distance, support)
        seen = 0
        for facet in range(facets):
            if _dot(normals[facet], points[apex]) - offsets[facet] > beyond:
                visible[seen] = facet
                seen += 1
        # a ridge of the seen facets is on the horizon when it borders an unseen one: it
        # appears once among the seen facets (each ridge of a closed surface joins two facets)
        for number in range(seen):
            for skip in range(dimension):
                keys[number * dimension + skip] = _key(vertices[visible[number]], skip, bits)
        total = seen * dimension
        for position in range(total):
            order[position] = position
        _sort_by(keys, order, total)
        horizon = 0
        position = 0
        while position < total:
            end = position + 1
            while end < total and keys[end] == keys[position]:
                end += 1
            if end - position == 1:
                facet, skip = visible[order[position] // dimension], order[position] % dimension
                # the ridge's vertices in order, with the apex put in its place
                column = 0
                for place in range(dimension):
                    if place != skip:
                        ridges[horizon, column] = vertices[facet, place]
                        column += 1
                column = dimension - 1
                while column > 0 and ridges[horizon, column - 1] > apex:
                    ridges[horizon, column] = ridges[horizon, column - 1]
                    column -= 1
                ridges[horizon, column] = apex
                horizon += 1
            elif end - position > 2:
                return False, 0.0
            position = end
        # the unseen facets stay (moved down in place), the cones from the horizon to the apex
        # join them
        kept = 0
        number = 0
        for facet in range(facets):
            if number < seen and visible[number] == facet:
                number += 1
                continue
            if kept != facet:
                vertices[kept] = vertices[facet]
                normals[kept] = normals[facet]
                offsets[kept] = offsets[facet]
            kept += 1
        if kept + horizon > capacity:
            capacity = 2 * (kept + horizon)
            vertices, normals, offsets = _grown(vertices, normals, offsets, kept, capacity)
        for number in range(horizon):
            row = kept + number
            vertices[row] = ridges[number]
            offsets[row], fine = _plane(points, vertices[row], centre, flat, basis, normals[row])
            if not fine:
                return False, 0.0
        facets = kept + horizon
        if len(visible) < capacity:
            visible = np.empty(capacity, np.int64)
            keys = np.empty(capacity * dimension, np.int64)
            order = np.empty(capacity * dimension, np.int64)
            ridges = np.empty((capacity * dimension, dimension), np.int64)
    return False, 0.0


@njit(cache=True)
def _grown(vertices, normals, offsets, used, capacity):
    """The facet arrays with room for ``capacity`` facets, their first ``used`` kept."""
    grown = (
        np.empty((capacity, vertices.shape[1]), np.int64),
        np.empty((capacity, normals.shape[1])),
        np.empty(capacity),
    )
    grown[0][:used], grown[1][:used], grown[2][:used] = vertices[:used], normals[:used], offsets[:used]
    return grown


@njit(cache=True)
def _sort_by(keys, payload, count):
    """Sort ``keys[:count]`` in place, ``payload`` alongside (Shell sort, Ciura's gaps: short
    to compile, and the horizon's few hundred keys need no more)."""
    for gap in (701, 301, 132, 57, 23, 10, 4, 1):
        for position in range(gap, count):
            key, carried = keys[position], payload[position]
            place = position
            while place >= gap and keys[place - gap] > key:
                keys[place], payload[place] = keys[place - gap], payload[place - gap]
                place -= gap
            keys[place], payload[place] = key, carried

"""Hand-object proximity: the distance of each hand link to the object, collisions, and the
touching pairs, all from one measure so that a link the closing rule stops always has contacts.

The distance of a link to the object is the smaller of two exact one-sided distances:

- link to mesh: the exact distance (:class:`pipeline.geometry.mesh_query.ObjectMesh`) from each of the
  link's surface points (every corner and edge, faces at the model's spacing) to the mesh;
- mesh to link: from each mesh feature point near the link (every vertex, and points along
  every non-flat edge: :class:`pipeline.geometry.mesh_query.Features`) to the link's convex pieces (the plane
  distance off a face, the nearest hull edge's off an edge or corner: exact); spheres covering
  each piece bound it where no vertex is near.

Between them they see a link corner on an object face and an object corner on a link face. The
signed distance grid only skips points that are certainly farther than ``near`` (or certainly
inside or outside), so a distance at or below ``near`` is always the exact measure above, and
one above it a lower bound that keeps steps conservative.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..geometry.mesh_query import grid_bounds, grid_clearance
from ..hands.kinematics import carry, transform
from ..tol import tol


@dataclass(frozen=True)
class Touches:
    """The pairs of a measure within ``tolerance``: ``pair`` (t,) index of the (trial, link) pair,
    ``points`` (t, 3) on the object, ``normals`` (t, 3) the object's outward normal there (the
    touched triangle's; at an object edge or corner minus the link face's, moved into the
    feature's normal cone on a smooth surface: :func:`pipeline.geometry.mesh_query.feature_contact_normals`)."""

    pair: np.ndarray
    points: np.ndarray
    normals: np.ndarray


def _starts(owner, count):
    return np.searchsorted(owner, np.arange(count + 1))


def measure(mesh, model, poses, rows, links, *, near, tolerance=None, features=None, capped=False):
    """Distance (m) of link ``links[i]`` of pose ``rows[i]`` to the object.

    Parameters
    ----------
    mesh : ObjectMesh
    model : HandModel
    poses : (n, L, 4, 4) float
        Link poses (:func:`pipeline.hands.kinematics.link_poses`).
    rows, links : (m,) int
        The (pose, link) pairs to measure.
    near : float
        Distances at or below it are exact (see the module docstring).
    tolerance : float, optional
        Also return the :class:`Touches` within it (``tolerance <= near``).
    features : Features, optional
        The mesh features measured against the links (default ``mesh.features``).
    capped : bool
        The caller uses no distance above ``near`` but as ``near`` itself (the closing caps its
        steps there; the touches need only those within ``tolerance``): a pair farther than
        ``near`` may then get any lower bound above it, which spares the exact queries of the
        link points that their cover sphere's centre shows to be that far.

    Returns
    -------
    (m,) float, and Touches when ``tolerance`` is given. Links without geometry are inf.
    """
    count = len(model.links)
    features = mesh.features if features is None else features
    flat = np.ascontiguousarray(poses, np.float64).reshape(-1, 4, 4)
    slot = rows * count + links
    distance, close = _link_bounds(flat, slot, links, model.link_centre, model.link_radius, near, *mesh.clearance_grid)
    touches = ([], [], [])
    if len(close) * len(model.cover_radius) <= BLOCK_COVERS:  # the usual few pairs: one run, no sums
        runs = [close] if len(close) else []
    else:
        covers = np.diff(model.link_cover_start)
        runs = _runs(close, covers[links[close]], close, BLOCK_COVERS)
    for run in runs:
        _measure_close(mesh, model, features, flat, slot, run, near, tolerance, distance, touches, capped)
    if tolerance is None:
        return distance
    joined = [
        np.concatenate(part) if part else np.zeros((0,) + shape) for part, shape in zip(touches, ((), (3,), (3,)))
    ]
    return distance, Touches(joined[0].astype(np.int64), *joined[1:])


#: how much a measure or a collision test takes at once: a measure's pairs go through their
#: exact queries, and a collision test's hands through its vertex test, in runs of about this
#: many cover spheres of their links, and a collision test's hands through its point test in
#: runs of about this many link points (:func:`_runs`), so that their temporaries stay near
#: 20 MB however many hands they take. In one run, measuring 1,024 closed franka hands at
#: once took 131 MB (1.3 million cover spheres), which a fresh trial worker's first chunk had to
#: fault in from the system
BLOCK_COVERS, BLOCK_POINTS = 1 << 17, 1 << 17


def _runs(items, sizes, owner, block):
    """``items`` (k,) in consecutive runs of about ``block`` of their ``sizes`` (k,) each, never
    parting two items of one ``owner`` (k,), sorted; the items whole when all fit in one run."""
    total = np.cumsum(sizes)
    if not len(total) or total[-1] <= block:
        return [items]
    first = np.flatnonzero(np.diff(owner, prepend=owner[0] - 1))  # each owner's first item
    run = (total - sizes)[first] // block  # the run each owner starts in
    return np.split(items, first[1:][np.diff(run) > 0])


def _measure_close(mesh, model, features, flat, slot, close, near, tolerance, distance, touches, capped=False):
    """The exact part of :func:`measure` for the pairs ``close``, each nearer than ``near`` by its
    bound: lowers ``distance`` (one entry per pair, in place) and appends their touches within
    ``tolerance`` (if given) to the lists ``touches``. A pair's answer depends on its own link
    and pose alone, so any split of the pairs gives the same."""
    pair, cover, centres, clearance = _covers(mesh, model, flat, slot, close)
    keep = -np.inf if tolerance is None else tolerance
    # the mesh-to-link side first: its cheap, exact gaps let the link points below skip the
    # exact queries (the costly part) of every point that cannot lower its link's distance
    feature_pair, vertex, normal = _vertex_side(
        features, model, flat, slot, pair, cover, centres, clearance, near, distance, floor=0.0, keep=keep
    )
    # link points: those of cover spheres within reach; the others are farther than
    # ``near``, bounded below by their sphere
    point_row, point, world = _near_points(
        distance, pair, cover, clearance, model.cover_reach, near, flat, slot, model.cover_point_start, model.points
    )
    point_pair = pair[point_row]
    lower = mesh.clearance(world)
    exact = _worth_exact(lower, distance, point_pair, near, keep)
    if capped:
        _spare_far_points(mesh, centres, point_row, world, near, exact, lower)
    found = mesh.closest(world[exact])
    lower[exact] = found.distances
    _minimum_at(distance, point_pair, lower)
    if tolerance is not None:
        hit = found.distances <= tolerance
        normals = found.normals[hit]
        # on an object edge or corner the contact is the object's feature against the link's
        # face (the mesh-to-link side's normal), not against one of the faces meeting there;
        # on a smooth surface's facet seams, the surface's normal
        border = mesh.on_border(found.at(hit))
        on_edge = np.flatnonzero(exact)[hit][border]
        link_face = _link_face_normal(
            model,
            flat,
            slot[point_pair[on_edge]],
            point[on_edge],
            world[on_edge] - found.points[hit][border],
            normals[border],
        )
        normals[border] = mesh.clamp_on_border(link_face, found.at(hit).at(border))
        touches[0].append(point_pair[exact][hit])
        touches[1].append(found.points[hit])
        touches[2].append(normals)
        touches[0].append(feature_pair)
        touches[1].append(features.points[vertex])
        touches[2].append(features.clamp(-normal, vertex))


def _spare_far_points(mesh, centres, point_row, world, near, exact, lower):
    """Drop from ``exact`` (in place) the link points that their cover sphere's centre
    (``centres[point_row]``) shows to be farther than ``near``: a point is no nearer than the
    centre's exact distance less its own distance to the centre. Such a point's ``lower`` bound
    (in place) becomes that one, above ``near``: a pair's distance within ``near`` is unchanged,
    one above it stays above it. A centre is queried only where the grid allows it to spare
    :data:`MIN_SPARED` of its points or more."""
    grid, origin, voxel, slack, _ = mesh.clearance_grid
    offset, spheres = _hopeful_centres(exact, point_row, world, centres, near, grid, origin, voxel, slack, MIN_SPARED)
    if len(spheres):
        centre_distance = np.full(len(centres), -np.inf)
        centre_distance[spheres] = mesh.distance(centres[spheres])
        _spare(exact, lower, point_row, offset, centre_distance, near)


#: the fewest link points a cover sphere's centre query must be able to spare (one query for
#: one point gains nothing)
MIN_SPARED = 2


@njit(cache=True)
def _hopeful_centres(exact, point_row, world, centres, near, grid, origin, voxel, slack, min_spared):
    """:func:`_spare_far_points`' first step: each ``exact`` point's distance to its sphere's
    centre plus :data:`PRUNE_SLACK_M` (m,) (inf for the others), and the spheres (k,) where the
    grid's upper bound on the centre's distance leaves ``min_spared`` points or more that the
    centre's exact distance could show to be farther than ``near``."""
    used = np.zeros(len(centres), np.bool_)
    for point in range(len(world)):
        used[point_row[point]] |= exact[point]
    rows = np.flatnonzero(used)
    low, high = grid_bounds(centres[rows], grid, origin, voxel, slack)
    upper = np.empty(len(centres))  # the centres' largest distance by the grid
    upper[rows] = np.maximum(high, -low)
    offset = np.full(len(world), np.inf)
    hopeful = np.zeros(len(centres), np.int64)
    for point in range(len(world)):
        if exact[point]:
            row = point_row[point]
            squared = 0.0
            for axis in range(3):
                squared += (world[point, axis] - centres[row, axis]) ** 2
            offset[point] = np.sqrt(squared) + PRUNE_SLACK_M
            if upper[row] - offset[point] > near:
                hopeful[row] += 1
    return offset, np.flatnonzero(hopeful >= min_spared)


@njit(cache=True)
def _spare(exact, lower, point_row, offset, centre_distance, near):
    """:func:`_spare_far_points`' last step, in place: the ``exact`` points whose sphere's
    ``centre_distance`` less their ``offset`` passes ``near`` are spared, with that bound."""
    for point in range(len(exact)):
        if exact[point]:
            bound = centre_distance[point_row[point]] - offset[point]
            if bound > near:
                exact[point] = False
                lower[point] = bound


def _covers(mesh, model, flat, slot, close):
    """The cover spheres of the pairs ``close``: their pair (k,), cover (k,), world centres (k, 3)
    and clearance (k,) m (a lower bound on their centres' distance to the object)."""
    pair, cover, centres = _link_ranges(flat, slot, close, len(model.links), model.link_cover_start, model.cover_centre)
    return pair, cover, centres, mesh.clearance(centres)


# The gathers and bounds between the exact queries, compiled: a closing pass measures a few
# hundred pairs, where each numpy call's own cost (microseconds) outweighs its arithmetic. Each
# float is the one numpy computed (single operations, in the same order; points moved by
# :func:`pipeline.hands.kinematics.carry`, as :func:`transform` moves them).


@njit(cache=True)
def _link_bounds(poses, slots, links, link_centre, link_radius, near, grid, origin, voxel, slack, box):
    """(m,) each pair's distance bound (its link's bounding sphere's clearance less its radius;
    inf for a link without geometry) and the pairs (k,) whose bound is within ``near``, inf too
    (their exact measure follows). Pair ``i`` is link ``links[i]`` at ``poses[slots[i]]``;
    ``grid`` to ``box``: :attr:`pipeline.geometry.mesh_query.ObjectMesh.clearance_grid`."""
    centres = np.empty((len(slots), 3))
    for pair in range(len(slots)):
        carry(poses[slots[pair]], link_centre[links[pair]], centres[pair])
    clearance = grid_clearance(centres, grid, origin, voxel, slack, box)
    distance = np.full(len(slots), np.inf)
    close = np.empty(len(slots), np.int64)
    found = 0
    for pair in range(len(slots)):
        radius = link_radius[links[pair]]
        if radius > 0:
            bound = clearance[pair] - radius
            if bound <= near:
                close[found] = pair
                found += 1
            else:
                distance[pair] = max(bound, 0.0)
    return distance, close[:found]


@njit(cache=True)
def _gather_ranges(poses, pose_of, owner, key, start, local):
    """The link-frame points ``local[start[key[i]]:start[key[i] + 1]]`` of each item ``i`` (k,),
    moved by ``poses[pose_of[i]]``: the owner (c,) (``owner[i]``), index in ``local`` (c,) and
    world position (c, 3) of each."""
    total = 0
    for item in range(len(key)):
        total += start[key[item] + 1] - start[key[item]]
    point_owner, index, world = np.empty(total, np.int64), np.empty(total, np.int64), np.empty((total, 3))
    row = 0
    for item in range(len(key)):
        pose = poses[pose_of[item]]
        for point in range(start[key[item]], start[key[item] + 1]):
            point_owner[row], index[row] = owner[item], point
            carry(pose, local[point], world[row])
            row += 1
    return point_owner, index, world


@njit(cache=True)
def _link_ranges(poses, slots, pairs, link_count, link_start, local):
    """The link-frame points ``local`` of each pair's link, pair ``p`` of ``pairs`` (k,) being
    link ``slots[p] % link_count`` at the pose ``poses[slots[p]]``, its points
    ``local[link_start[link]:link_start[link + 1]]`` (the cover spheres' centres, or the link
    points): their pair (c,), index in ``local`` (c,) and world positions (c, 3)."""
    slot = slots[pairs]
    return _gather_ranges(poses, slot, pairs, slot % link_count, link_start, local)


@njit(cache=True)
def _sphere_floor(best, pair, cover, centres, clearance, cover_radius, near, above_near):
    """:func:`_vertex_side`'s bound from the cover spheres (``pair``, ``cover``, ``centres``,
    ``clearance``, (c,) each): lowers ``best[pair]`` (in place) to ``above_near`` (the float just
    above ``near``) for a sphere within its reach (its radius plus ``near``) of the object, to its
    clearance less its radius for one farther; returns the pair, cover, centre and reach of
    those within it."""
    reach = np.empty(len(pair))
    within = np.zeros(len(pair), np.bool_)
    for row in range(len(pair)):
        reach[row] = cover_radius[cover[row]] + near
        within[row] = clearance[row] <= reach[row]
        bound = above_near if within[row] else clearance[row] - cover_radius[cover[row]]
        if bound < best[pair[row]]:
            best[pair[row]] = bound
    return pair[within], cover[within], centres[within], reach[within]


@njit(cache=True)
def _near_points(distance, pair, cover, clearance, cover_reach, near, poses, slots, cover_point_start, points):
    """The link points of the cover spheres (``pair``, ``cover``, ``clearance`` (c,) each) within
    ``near`` of the object by their reach: their sphere's row (m,), index in ``points`` (m,)
    and world positions (m, 3). The farther spheres lower ``distance[pair]`` (in place) to their
    clearance less their reach, a bound on all their points."""
    far = np.zeros(len(pair), np.bool_)
    for row in range(len(pair)):
        gap = clearance[row] - cover_reach[cover[row]]
        far[row] = gap > near
        if far[row] and gap < distance[pair[row]]:
            distance[pair[row]] = gap
    within = np.flatnonzero(~far)
    return _gather_ranges(poses, slots[pair[within]], within, cover[within], cover_point_start, points)


@njit(cache=True)
def _prune_limit(best, near, keep):
    """How far (m) a point or feature may be from a link whose distance so far is ``best`` and
    still matter: a farther one changes neither that distance (past it by
    :data:`PRUNE_SLACK_M`) nor the touches within ``keep``; never past ``near``."""
    return min(near, max(keep, best + PRUNE_SLACK_M))


@njit(cache=True)
def _worth_exact(lower, distance, point_pair, near, keep):
    """(m,) bool: the points whose lower bound ``lower`` (m,) is within :func:`_prune_limit` of
    their pair's ``distance`` so far: only their exact distance can change the answer."""
    worth = np.empty(len(lower), np.bool_)
    for row in range(len(lower)):
        worth[row] = lower[row] <= _prune_limit(distance[point_pair[row]], near, keep)
    return worth


def _link_face_normal(model, flat, slot, point, offset, fallback):
    """(k, 3) outward object normals of link points ``point`` (k,) (of the link poses
    ``flat[slot]``) off an object edge or corner by ``offset`` (k, 3), world: minus the normal
    of the link face through the point that best faces the object there (the largest
    ``-n . offset``), as the mesh-to-link side gives an object feature under a link face; a
    point on no face of its piece's hull (inside a concave mesh shape) keeps ``fallback``."""
    rotation = flat[slot, :3, :3]
    local_offset = np.einsum("kji,kj->ki", rotation, offset)
    planes = model.planes[model.cover_piece[model.point_cover[point]]]  # (k, F, 4), padded with -inf
    signed = np.einsum("kfi,ki->kf", planes[..., :3], model.points[point]) + planes[..., 3]
    score = np.where(np.abs(signed) <= tol.edge_tie_m, -np.einsum("kfi,ki->kf", planes[..., :3], local_offset), -np.inf)
    best = score.argmax(axis=1)
    rows = np.arange(len(point))
    normal = -np.einsum("kij,kj->ki", rotation, planes[rows, best, :3])
    return np.where(np.isfinite(score[rows, best])[:, None], normal, fallback)


def _vertex_side(features, model, flat, slot, pair, cover, centres, clearance, near, best, *, floor, keep):
    """Mesh ``features`` (:class:`pipeline.geometry.mesh_query.Features`) against the convex pieces of
    the cover spheres ``cover`` of pairs ``pair`` (:func:`_covers`, with their ``centres`` and
    ``clearance``).

    Lowers ``best`` (one entry per pair, in place) to the ``max(distance, floor)`` of every
    feature within ``near`` of a pair's pieces (the distance to the piece: the largest plane
    distance, negative inside), and to the lower bound of each cover sphere too far for any
    feature to be within ``near`` (which keeps a link's distance a bound when its nearest part
    is a face away from its edges). Returns the features at most ``keep`` from their piece:
    their pair (k,), feature (k,) and contact normal (k, 3) pointing out of the link
    (:func:`_piece_gap`)."""
    # a cover sphere farther than its reach holds no vertex: it is at least its clearance less
    # its radius away; past a near one's reach, every feature is farther than ``near`` from it
    # (just above near: never a touch)
    pair, cover, centres, reach = _sphere_floor(
        best, pair, cover, centres, clearance, model.cover_radius, near, np.nextafter(near, np.inf)
    )
    if not len(pair):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    rows, vertex, face_normal = _feature_hits(
        flat,
        slot[pair],
        centres,
        reach,
        model.cover_piece[cover],
        pair,
        best,
        floor,
        keep,
        features.points,
        features.normals,
        features.cells,
        model.planes,
        model.piece_edges,
        model.edge_planes,
        near,
        tol.edge_tie_m,
    )
    normal = np.einsum("mij,mj->mi", flat[slot[pair[rows]], :3, :3], face_normal)
    return pair[rows], vertex, normal


#: a feature whose plane distance to a piece is this far past its pair's best is skipped: its
#: exact distance can only be larger (the planes are rounded to 1e-9 m; ample room)
PRUNE_SLACK_M = 1e-6


@njit(cache=True)
def _feature_hits(
    poses,
    slots,
    centres,
    reach,
    pieces,
    targets,
    best,
    floor,
    keep,
    features,
    feature_normals,
    cells,
    planes,
    edges,
    sides,
    near,
    tie,
):
    """The features near the cover spheres' pieces (``centres`` (c, 3) world, ``reach`` (c,) m,
    ``pieces`` (c,), carried by the link poses ``poses[slots]``). Lowers ``best[targets[row]]``
    to ``max(distance, floor)`` of each feature within ``near`` of a row's piece, and returns
    those at most ``keep`` from it: per hit the cover's row, the feature and the normal (link
    frame) of :func:`_piece_gap`. A feature in several covers of one piece in a
    row counts once. A feature that cannot lower ``best`` and is past ``keep`` is dropped at the
    first plane that shows it (the min, hence ``best``, is the same)."""
    origin, size, shape, starts, items, binned = cells
    capacity = 1024
    rows, found, normals = np.empty(capacity, np.int64), np.empty(capacity, np.int64), np.empty((capacity, 3))
    seen = np.full(len(features), -1, np.int64)
    hits, group, previous = 0, -1, (-1, -1)
    local, facing = np.empty(3), np.empty(3)
    low, high = np.empty(3, np.int64), np.empty(3, np.int64)
    for row in range(len(centres)):
        piece = pieces[row]
        if (slots[row], piece) != previous:
            group, previous = group + 1, (slots[row], piece)
        pose = poses[slots[row]]
        for axis in range(3):
            low[axis] = max(int(np.floor((centres[row, axis] - reach[row] - origin[axis]) / size)), 0)
            high[axis] = min(int(np.floor((centres[row, axis] + reach[row] - origin[axis]) / size)), shape[axis] - 1)
        for i in range(low[0], high[0] + 1):
            di = _beyond(centres[row, 0] - origin[0], i, size)
            for j in range(low[1], high[1] + 1):
                dj = di + _beyond(centres[row, 1] - origin[1], j, size)
                if dj > reach[row] * reach[row]:
                    continue
                for k in range(low[2], high[2] + 1):
                    # a cell whose box lies beyond the reach holds no feature within it
                    if dj + _beyond(centres[row, 2] - origin[2], k, size) > reach[row] * reach[row]:
                        continue
                    cell = (i * shape[1] + j) * shape[2] + k
                    for position in range(starts[cell], starts[cell + 1]):
                        # the reach test first, on the cell's own run of coordinates: most
                        # features fail it, and it reads memory in order
                        dx = binned[position, 0] - centres[row, 0]
                        dy = binned[position, 1] - centres[row, 1]
                        dz = binned[position, 2] - centres[row, 2]
                        if dx * dx + dy * dy + dz * dz > reach[row] * reach[row]:
                            continue
                        feature = items[position]
                        if seen[feature] == group:
                            continue
                        seen[feature] = group
                        mx = binned[position, 0] - pose[0, 3]
                        my = binned[position, 1] - pose[1, 3]
                        mz = binned[position, 2] - pose[2, 3]
                        for axis in range(3):
                            local[axis] = pose[0, axis] * mx + pose[1, axis] * my + pose[2, axis] * mz
                            facing[axis] = -(
                                pose[0, axis] * feature_normals[feature, 0]
                                + pose[1, axis] * feature_normals[feature, 1]
                                + pose[2, axis] * feature_normals[feature, 2]
                            )
                        target = targets[row]
                        limit = _prune_limit(best[target], near, keep)
                        gap, face = _piece_gap(planes[piece], edges[piece], sides[piece], local, facing, limit, tie)
                        if gap > limit:  # the covers bound the farther ones
                            continue
                        best[target] = min(best[target], max(gap, floor))
                        if gap > keep:
                            continue
                        if hits == capacity:
                            capacity *= 2
                            rows, found, normals = (
                                _grown(rows, capacity),
                                _grown(found, capacity),
                                _grown(normals, capacity),
                            )
                        rows[hits], found[hits] = row, feature
                        for axis in range(3):
                            normals[hits, axis] = planes[piece, face, axis]
                        hits += 1
    return rows[:hits], found[:hits], normals[:hits]


@njit(cache=True)
def _beyond(coordinate, index, size):
    """Squared distance along one axis from ``coordinate`` to cell ``index`` of ``size`` (0 inside)."""
    gap = max(index * size - coordinate, coordinate - (index + 1) * size, 0.0)
    return gap * gap


@njit(cache=True)
def _grown(values, capacity):
    out = np.empty((capacity,) + values.shape[1:], values.dtype)
    out[: len(values)] = values
    return out


@njit(cache=True)
def _piece_gap(planes, edges, sides, local, facing, near, tie):
    """Signed distance of the link-frame point ``local`` (3,) to its convex piece (``planes``
    (F, 4), ``edges`` (E, 2, 3), ``sides`` (E, 2), padded) and the plane (row of ``planes``)
    whose normal is the contact's; beyond ``near`` only a lower bound (the distance off the
    first plane found past it).

    Off a face (its foot on the face's plane inside the piece) that face's plane distance;
    off an edge or corner the nearest hull edge's distance, and of the faces at the nearest
    edges the one whose normal best agrees with ``facing`` (the object's inward normal there,
    link frame), the link having no normal of its own there. Scalar loops: this runs per
    feature, where small arrays would cost more than the arithmetic."""
    x, y, z = local[0], local[1], local[2]
    gap, face, count, above = -np.inf, 0, 0, 0
    while count < len(planes) and planes[count, 3] > -np.inf:
        signed = planes[count, 0] * x + planes[count, 1] * y + planes[count, 2] * z + planes[count, 3]
        if signed > near:  # one plane past ``near`` is bound enough
            return signed, count
        if signed > gap:
            gap, face = signed, count
        above += signed > 0
        count += 1
    if gap > near or above <= 1:
        return gap, face
    # the largest plane distance is the distance when the point's foot on that face lies in
    # the piece (a point above a face beside an obtuse edge is off both planes)
    inside = True
    for plane in range(count):
        cosine = (
            planes[plane, 0] * planes[face, 0] + planes[plane, 1] * planes[face, 1] + planes[plane, 2] * planes[face, 2]
        )
        signed = planes[plane, 0] * x + planes[plane, 1] * y + planes[plane, 2] * z + planes[plane, 3]
        if signed - gap * cosine > 0:
            inside = False
            break
    if inside:
        return gap, face
    best, used = np.inf, 0
    while used < len(edges) and np.isfinite(edges[used, 0, 0]):
        best = min(best, _segment_distance(x, y, z, edges[used]))
        used += 1
    # at a corner several edges are nearest: all their faces are candidates, so that the
    # choice does not hang on rounding
    agree = -np.inf
    for edge in range(used):
        if _segment_distance(x, y, z, edges[edge]) <= best + tie:
            for side in range(2):
                plane = sides[edge, side]
                value = planes[plane, 0] * facing[0] + planes[plane, 1] * facing[1] + planes[plane, 2] * facing[2]
                if value > agree:
                    agree, face = value, plane
    return best, face


@njit(cache=True)
def _segment_distance(x, y, z, segment):
    """Distance of the point (x, y, z) to the (2, 3) ``segment``."""
    ox, oy, oz = x - segment[0, 0], y - segment[0, 1], z - segment[0, 2]
    sx, sy, sz = segment[1, 0] - segment[0, 0], segment[1, 1] - segment[0, 1], segment[1, 2] - segment[0, 2]
    along = min(max((ox * sx + oy * sy + oz * sz) / (sx * sx + sy * sy + sz * sz), 0.0), 1.0)
    rx, ry, rz = ox - along * sx, oy - along * sy, oz - along * sz
    return np.sqrt(rx * rx + ry * ry + rz * rz)


@njit(cache=True)
def _minimum_at(out, index, values):
    """``np.minimum.at(out, index, values)``, in place: out[index[i]] = min(out[index[i]], values[i])
    (numpy's unbuffered ``at`` costs about 0.1 ms a call on the trial's arrays)."""
    for position in range(len(index)):
        if values[position] < out[index[position]]:
            out[index[position]] = values[position]


def _points_inside(mesh, model, flat, slot, rows, unsure, starts, along, hit, deepest):
    """The link points (``starts``: each link's first in ``model.points``) of the pairs ``unsure``
    inside the mesh, for :func:`collides`: marks their hands (``rows``) in ``hit`` and lowers each
    one's ``deepest`` (in place). A hand's answer depends on its own pairs alone, all of them in
    ``unsure`` or none."""
    pair, _, world = _link_ranges(flat, slot, unsure, len(model.links), starts, model.points)
    low, high = mesh.bounds(world)
    inside = high < 0
    _minimum_at(deepest, rows[pair[inside]], high[inside])
    hit[rows[pair[inside]]] = True
    # the exact (ray parity) test only where the grid is unsure and the hand not yet known to hit
    check = np.flatnonzero((low <= 0) & ~inside & ~hit[rows[pair]])
    inside[check] = mesh.inside(world[check])
    hit[rows[pair[inside]]] = True
    if along is not None and inside.any():
        # a point inside stays inside until its ray along the move leaves the mesh (a margin
        # for the casts' float32)
        owner = rows[pair[inside]]
        exit_m = mesh.exit_distance(world[inside], along[owner]) - 1e-6
        _minimum_at(deepest, owner, -exit_m)


def collides(mesh, model, poses, *, overlap=None, along=None):
    """The hand at each of the (n, L, 4, 4) link poses overlaps the object: a link's surface
    point inside the mesh, or a mesh vertex deeper than ``overlap`` (m) inside a link's convex
    piece (default :attr:`pipeline.tol.Tolerances.overlap_m`). A link swallowed whole by the
    object has its points inside; an object part swallowed by a link has its vertices inside.

    Returns (n,) bool, and (n,) how far (m) each overlapping hand can certainly be translated
    and still overlap (0 if none is known): in any direction, from the distance grid's bounds on
    points inside; with ``along`` (n, 3) unit directions, translated along them, at least as far
    as the nearest exit of the mesh of any point found inside (exact ray casts)."""
    overlap = tol.overlap_m if overlap is None else overlap
    count, total = len(model.links), len(poses)
    flat = poses.reshape(-1, 4, 4)
    slot = np.arange(total * count)
    rows, links = np.divmod(slot, count)
    radius = model.link_radius[links]
    low, high = mesh.bounds(transform(flat, slot, model.link_centre[links]))
    swallowed = (high < -radius) & (radius > 0)  # the whole link is inside
    hit = np.zeros(total, bool)
    hit[rows[swallowed]] = True
    # signed distance is 1-Lipschitz: a point at most s < 0 inside stays inside for a move < -s;
    # per hand the deepest such bound (the most negative s), so depth = -deepest
    deepest = np.zeros(total)
    _minimum_at(deepest, rows[swallowed], high[swallowed] + radius[swallowed])
    unsure = np.flatnonzero((radius > 0) & (low <= radius) & (high >= -radius) & ~hit[rows])
    if not len(unsure):
        return hit, -deepest
    # every link point of those links (a sphere-level cull costs more than it saves here: a
    # hand being retreated is close to the surface)
    starts = _starts(model.point_link, count)
    for run in _runs(unsure, np.diff(starts)[links[unsure]], rows[unsure], BLOCK_POINTS):
        _points_inside(mesh, model, flat, slot, rows, run, starts, along, hit, deepest)
    unsure = unsure[~hit[rows[unsure]]]  # the vertex test only where no link point is inside
    deepest_feature = np.full(len(slot), np.inf)
    covers = np.diff(model.link_cover_start)
    for run in _runs(unsure, covers[links[unsure]], rows[unsure], BLOCK_COVERS):
        spheres = _covers(mesh, model, flat, slot, run)
        _vertex_side(mesh.features, model, flat, slot, *spheres, 0.0, deepest_feature, floor=-np.inf, keep=-np.inf)
    hit[rows[deepest_feature < -overlap]] = True
    return hit, -deepest

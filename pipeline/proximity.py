"""Hand-object proximity: the distance of each hand link to the object, collisions, and the
touching pairs, all from one measure so that a link the closing rule stops always has contacts.

The distance of a link to the object is the smaller of two exact one-sided distances:

- link to mesh: the exact distance (:class:`pipeline.mesh_query.ObjectMesh`) from each of the
  link's surface points (every corner and edge, faces at the model's spacing) to the mesh;
- mesh to link: from each mesh feature point near the link (every vertex, and points along
  every non-flat edge: :attr:`ObjectMesh.features`) to the link's convex pieces (the plane
  distance off a face, the nearest hull edge's off an edge or corner: exact); spheres covering
  each piece bound it where no vertex is near.

Between them they see a link corner on an object face and an object corner on a link face. The
signed distance grid only skips points that are certainly farther than ``near`` (or certainly
inside or outside), so a distance at or below ``near`` is always the exact measure above, and
one above it a lower bound that keeps steps conservative.
"""

import itertools
from dataclasses import dataclass

import numpy as np

from .arrays import expand_ranges
from .kinematics import transform
from .tol import tol


@dataclass(frozen=True)
class Touches:
    """The pairs of a measure within ``tolerance``: ``pair`` (t,) index of the (trial, link) pair,
    ``points`` (t, 3) on the object, ``normals`` (t, 3) the object's outward normal there (the
    touched triangle's, or minus the link face's for a mesh vertex touching the link)."""

    pair: np.ndarray
    points: np.ndarray
    normals: np.ndarray


def _starts(owner, count):
    return np.searchsorted(owner, np.arange(count + 1))


def measure(mesh, model, poses, rows, links, *, near, tolerance=None):
    """Distance (m) of link ``links[i]`` of pose ``rows[i]`` to the object.

    Parameters
    ----------
    mesh : ObjectMesh
    model : HandModel
    poses : (n, L, 4, 4) float
        Link poses (:func:`pipeline.kinematics.link_poses`).
    rows, links : (m,) int
        The (pose, link) pairs to measure.
    near : float
        Distances at or below it are exact (see the module docstring).
    tolerance : float, optional
        Also return the :class:`Touches` within it (``tolerance <= near``).

    Returns
    -------
    (m,) float, and Touches when ``tolerance`` is given. Links without geometry are inf.
    """
    count = len(model.links)
    flat = poses.reshape(-1, 4, 4)
    slot = rows * count + links
    distance = np.full(len(rows), np.inf)
    radius = model.link_radius[links]
    centre = transform(flat, slot, model.link_centre[links])
    bound = mesh.clearance(centre) - radius
    has = radius > 0
    close = np.flatnonzero(has & (bound <= near))
    distance[has] = np.maximum(bound[has], 0.0)
    distance[close] = np.inf
    touches = ([], [], [])
    if len(close):
        starts = _starts(model.point_link, count)
        owner, point = expand_ranges(starts[links[close]], np.diff(starts)[links[close]])
        pair = close[owner]
        world = transform(flat, slot[pair], model.points[point])
        lower = mesh.clearance(world)
        exact = lower <= near
        found = mesh.closest(world[exact])
        lower[exact] = found.distances
        np.minimum.at(distance, pair, lower)
        if tolerance is not None:
            hit = found.distances <= tolerance
            touches[0].append(pair[exact][hit])
            touches[1].append(found.points[hit])
            touches[2].append(found.normals[hit])
        bounds = []
        pair, vertex, signed, normal = _vertex_side(mesh, model, flat, slot, close, near, bounds)
        np.minimum.at(distance, *bounds[0])
        gap = np.maximum(signed, 0.0)
        np.minimum.at(distance, pair, gap)
        if tolerance is not None:
            hit = gap <= tolerance
            touches[0].append(pair[hit])
            touches[1].append(mesh.features[vertex[hit]])
            touches[2].append(-normal[hit])
    if tolerance is None:
        return distance
    joined = [
        np.concatenate(part) if part else np.zeros((0,) + shape) for part, shape in zip(touches, ((), (3,), (3,)))
    ]
    return distance, Touches(joined[0].astype(np.int64), *joined[1:])


def _vertex_side(mesh, model, flat, slot, close, near, bounds=None):
    """Mesh features within ``near`` of the convex pieces of the pairs ``close``: their pair (k,),
    feature (k,), distance to the piece (k,) m (the largest plane distance, negative, inside) and the contact
    normal (k, 3) pointing out of the link (:func:`_piece_distance`). ``bounds``, a list, receives (pairs, m) of
    the cover spheres too far for any vertex to be within ``near``: their lower bounds, which
    keep the link's distance a bound when its nearest part is a face away from its edges."""
    count = len(model.links)
    cover_link = model.piece_link[model.cover_piece]
    starts = _starts(cover_link, count)
    link = slot[close] % count
    owner, cover = expand_ranges(starts[link], np.diff(starts)[link])
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)))
    pair = close[owner]
    centres = transform(flat, slot[pair], model.cover_centre[cover])
    reach = model.cover_radius[cover] + near
    clearance = mesh.clearance(centres)
    needed = clearance <= reach  # a cover sphere farther than its reach holds no vertex
    if bounds is not None:
        # a far cover is at least its clearance less its radius away; past a near one's reach,
        # every feature is farther than ``near`` from it (just above near: never a touch)
        bounds.append((pair, np.where(needed, np.nextafter(near, np.inf), clearance - model.cover_radius[cover])))
    if not needed.any():
        return empty
    pair, cover = pair[needed], cover[needed]
    found = mesh.feature_tree.query_ball_point(centres[needed], reach[needed], return_sorted=False)
    sizes = np.fromiter(map(len, found), np.int64, len(found))
    if not sizes.sum():
        return empty
    vertex = np.fromiter(itertools.chain.from_iterable(found), np.int64, sizes.sum())
    which = np.repeat(np.arange(len(cover)), sizes)
    piece = model.cover_piece[cover][which]
    # a feature reached by several of a piece's overlapping covers is measured once, in the
    # order found
    key = (pair[which] * len(model.planes) + piece) * len(mesh.features) + vertex
    first = np.sort(np.unique(key, return_index=True)[1])
    which, piece, vertex = which[first], piece[first], vertex[first]
    chosen = flat[slot[pair[which]]]
    local = np.einsum("mji,mj->mi", chosen[:, :3, :3], mesh.features[vertex] - chosen[:, :3, 3])
    facing = np.einsum("mji,mj->mi", chosen[:, :3, :3], -mesh.feature_normals[vertex])
    gap, face_normal = _piece_distance(model, piece, local, facing, near)
    # only features within ``near`` matter: the covers bound the farther ones
    within = np.flatnonzero(gap <= near)
    normal = np.einsum("mij,mj->mi", chosen[within, :3, :3], face_normal[within])
    return pair[which[within]], vertex[within], gap[within], normal


def _piece_distance(model, piece, local, facing, near):
    """Signed distance (m,) of link-frame points ``local`` (m, 3) to their convex ``piece`` (m,),
    and the contact normal (m, 3, link frame) pointing out of the piece; beyond ``near`` only a
    lower bound (the largest plane distance) and no normal.

    Off a face (its foot on the face's plane inside the piece) that face's plane distance and
    normal; off an edge or corner the nearest hull edge's distance, and of the faces at the nearest edges the one whose
    normal best agrees with ``facing`` (m, 3; the object's inward normal there, in the link
    frame), the link having no normal of its own there. Each piece is measured with its own
    planes and edges (the model pads them to the largest piece's count)."""
    gap, normal = np.empty(len(piece)), np.empty((len(piece), 3))
    order = np.argsort(piece, kind="stable")
    bounds = np.searchsorted(piece[order], np.arange(len(model.planes) + 1))
    for number in np.flatnonzero(np.diff(bounds)):
        rows = order[bounds[number] : bounds[number + 1]]
        planes = model.planes[number]
        planes = planes[planes[:, 3] > -np.inf]
        signed = local[rows] @ planes[:, :3].T + planes[:, 3]
        face = signed.argmax(axis=1)
        gap[rows], normal[rows] = signed[np.arange(len(rows)), face], planes[face, :3]
        corner = ((signed > 0).sum(axis=1) > 1) & (gap[rows] <= near)
        # the largest plane distance is the distance when the point's foot on that face lies in
        # the piece (a point above a face beside an obtuse edge is off both planes)
        foot = signed[corner] - gap[rows][corner, None] * (planes[face[corner], :3] @ planes[:, :3].T)
        corner[np.flatnonzero(corner)[(foot <= 0).all(axis=1)]] = False
        if corner.any():
            edges = model.piece_edges[number]
            count = int(np.isfinite(edges[:, 0, 0]).sum())
            at = rows[corner]
            distance = _segment_distances(local[at], edges[:count])
            gap[at] = distance.min(axis=1)
            # at a corner several edges are nearest: all their faces are candidates, so that
            # the choice does not hang on rounding
            nearest = distance <= gap[at][:, None] + tol.edge_tie_m
            sides = planes[model.edge_planes[number, :count], :3]  # (E, 2, 3)
            agree = np.where(nearest[..., None], np.einsum("eki,ci->cek", sides, facing[at]), -np.inf)
            best = agree.reshape(len(at), -1).argmax(axis=1)
            normal[at] = sides.reshape(-1, 3)[best]
    return gap, normal


def _segment_distances(points, segments):
    """(m, E) distances of (m, 3) points to (E, 2, 3) segments."""
    start, span = segments[:, 0], segments[:, 1] - segments[:, 0]
    offset = points[:, None] - start  # (m, E, 3)
    along = np.clip(np.einsum("mek,ek->me", offset, span) / np.einsum("ek,ek->e", span, span), 0.0, 1.0)
    rest = offset - along[..., None] * span
    return np.sqrt(np.einsum("mek,mek->me", rest, rest))


def collides(mesh, model, poses, *, overlap=None):
    """The hand at each of the (n, L, 4, 4) link poses overlaps the object: a link's surface
    point inside the mesh, or a mesh vertex deeper than ``overlap`` (m) inside a link's convex
    piece (default :attr:`pipeline.tol.Tolerances.overlap_m`). A link swallowed whole by the
    object has its points inside; an object part swallowed by a link has its vertices inside.

    Returns (n,) bool, and (n,) how far (m) each overlapping hand can certainly be translated
    and still overlap (from the distance grid's bounds on points inside; 0 if none is known)."""
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
    depth = np.zeros(total)
    # signed distance is 1-Lipschitz: a point at most s < 0 inside stays inside for a move < -s
    np.maximum.at(depth, rows[swallowed], -high[swallowed] - radius[swallowed])
    unsure = np.flatnonzero((radius > 0) & (low <= radius) & (high >= -radius) & ~hit[rows])
    if not len(unsure):
        return hit, depth
    starts = _starts(model.point_link, count)
    owner, point = expand_ranges(starts[links[unsure]], np.diff(starts)[links[unsure]])
    pair = unsure[owner]
    world = transform(flat, pair, model.points[point])
    low, high = mesh.bounds(world)
    inside = high < 0
    np.maximum.at(depth, rows[pair[inside]], -high[inside])
    check = np.flatnonzero((low <= 0) & ~inside)
    inside[check] = mesh.inside(world[check])
    hit[rows[pair[inside]]] = True
    unsure = unsure[~hit[rows[unsure]]]  # the vertex test only where no link point is inside
    pair, _, signed, _ = _vertex_side(mesh, model, flat, slot, unsure, 0.0)
    hit[rows[pair[signed < -overlap]]] = True
    return hit, depth

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

from dataclasses import dataclass

import numpy as np

from .arrays import expand_ranges
from .kinematics import transform


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
    joined = [np.concatenate(part) if part else np.zeros((0,) + shape) for part, shape in
              zip(touches, ((), (3,), (3,)))]
    return distance, Touches(joined[0].astype(np.int64), *joined[1:])


def _vertex_side(mesh, model, flat, slot, close, near, bounds=None):
    """Mesh vertices within ``near`` of the convex pieces of the pairs ``close``: their pair (k,),
    vertex (k,), largest signed plane distance (k,) m (negative inside the piece) and the contact
    normal (k, 3) pointing out of the link: the link face's; off a link edge or corner, that of
    the two faces at the nearest edge which best faces the object's own normal there. ``bounds``, a list, receives (pairs, m) of
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
        bounds.append((pair, np.where(needed, np.nextafter(near, np.inf),
                                      clearance - model.cover_radius[cover])))
    if not needed.any():
        return empty
    pair, cover = pair[needed], cover[needed]
    found = mesh.feature_tree.query_ball_point(centres[needed], reach[needed], return_sorted=False)
    sizes = np.fromiter((len(item) for item in found), np.int64, len(found))
    if not sizes.sum():
        return empty
    vertex = np.concatenate([np.asarray(item, np.int64) for item in found if len(item)])
    which = np.repeat(np.arange(len(cover)), sizes)
    piece = model.cover_piece[cover]
    chosen = flat[slot[pair[which]]]
    local = np.einsum("mji,mj->mi", chosen[:, :3, :3], mesh.features[vertex] - chosen[:, :3, 3])
    planes = model.planes[piece[which]]
    signed = np.einsum("mfk,mk->mf", planes[..., :3], local) + planes[..., 3]
    face = signed.argmax(axis=1)
    gap = signed[np.arange(len(face)), face]
    outward = np.einsum("mij,mj->mi", chosen[:, :3, :3], planes[np.arange(len(face)), face, :3])
    # off a link face (one plane positive) the face's plane distance is the distance and its
    # normal the contact's; off an edge or corner the nearest hull edge gives the distance, and
    # the object's own (vertex) normal is the contact's, the link having none there
    on_face = (signed > 0).sum(axis=1) <= 1
    normal = outward.copy()
    corner = np.flatnonzero(~on_face)
    if len(corner):
        owner_piece = piece[which][corner]
        gap[corner], edge = _segment_distance(local[corner], model.piece_edges[owner_piece])
        # of the two link faces at the nearest edge, the one facing the object's own normal there
        sides = model.planes[owner_piece[:, None], model.edge_planes[owner_piece, edge], :3]  # (c, 2, 3)
        sides = np.einsum("mij,mkj->mki", chosen[corner, :3, :3], sides)
        facing = np.einsum("mki,mi->mk", sides, -mesh.feature_normals[vertex[corner]]).argmax(axis=1)
        normal[corner] = sides[np.arange(len(corner)), facing]
    return pair[which], vertex, gap, normal


def _segment_distance(points, segments):
    """Distance (m,) of (m, 3) points to the nearest of their (m, E, 2, 3) segments (NaN-padded),
    and which segment (m,) that is."""
    start, span = segments[:, :, 0], segments[:, :, 1] - segments[:, :, 0]
    offset = points[:, None] - start
    with np.errstate(invalid="ignore", divide="ignore"):
        along = np.clip(np.einsum("mek,mek->me", offset, span) / np.einsum("mek,mek->me", span, span), 0.0, 1.0)
    foot = start + along[..., None] * span
    distance = np.linalg.norm(points[:, None] - foot, axis=2)
    best = np.where(np.isnan(distance), np.inf, distance).argmin(axis=1)
    rows = np.arange(len(points))
    return distance[rows, best], best


def collides(mesh, model, poses, *, overlap=1e-6):
    """(n,) bool: the hand at each of the (n, L, 4, 4) link poses overlaps the object: a link's
    surface point inside the mesh, or a mesh vertex deeper than ``overlap`` (m) inside a link's
    convex piece. A link swallowed whole by the object has its points inside; an object part
    swallowed by a link has its vertices inside."""
    count, total = len(model.links), len(poses)
    flat = poses.reshape(-1, 4, 4)
    slot = np.arange(total * count)
    rows, links = np.divmod(slot, count)
    radius = model.link_radius[links]
    low, high = mesh.bounds(transform(flat, slot, model.link_centre[links]))
    hit = np.zeros(total, bool)
    hit[rows[(high < -radius) & (radius > 0)]] = True  # the whole link is inside
    unsure = np.flatnonzero((radius > 0) & (low <= radius) & (high >= -radius) & ~hit[rows])
    if not len(unsure):
        return hit
    starts = _starts(model.point_link, count)
    owner, point = expand_ranges(starts[links[unsure]], np.diff(starts)[links[unsure]])
    pair = unsure[owner]
    world = transform(flat, pair, model.points[point])
    low, high = mesh.bounds(world)
    inside = high < 0
    check = np.flatnonzero((low <= 0) & ~inside)
    inside[check] = mesh.inside(world[check])
    hit[rows[pair[inside]]] = True
    unsure = unsure[~hit[rows[unsure]]]  # the vertex test only where no link point is inside
    pair, _, signed, _ = _vertex_side(mesh, model, flat, slot, unsure, 0.0)
    hit[rows[pair[signed < -overlap]]] = True
    return hit

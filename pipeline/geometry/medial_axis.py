"""Medial axis point clouds from oriented surface samples (stage ``medial_axis``).

Two methods, one output: per ball a centre, a radius, the sample it belongs to and the
samples that define it.

- ``shrinking_ball`` (default): every sample's inner ball starts huge and shrinks
  through its nearest sample until empty, vectorised over all samples with one batched
  k=2 kd-tree query per iteration.
- ``voronoi_poles``: the inner Voronoi pole of each sample from Qhull's Delaunay
  tetrahedralisation (the Power Crust / Tight Cocone family the paper used), kept as
  the reference the benchmark compares against.

References
----------
Ma, Bae, Choi, "3D medial axis point approximation using nearest neighbors and the normal
field", The Visual Computer 28, 2012. Amenta, Choi, Kolluri, "The power crust", 2001.
"""

import numpy as np
from pykdtree.kdtree import KDTree

from ..arrays import group_rows, unit_rows
from ..artefacts import MedialAxis, content_key
from ..errors import BadInputError, DegenerateGeometryError
from ..validate import as_points

POLISH_EPS = 0.0  # exact: the polish pass is what makes radii and centres accurate


def shrinking_ball(
    points, normals, *, eps=0.2, min_chord=0.0, min_separation=0.0, max_iterations=30, samples=None, initial_radii=None
):
    """Shrinking-ball medial axis: one inner ball per sample.

    A ball touching sample ``p`` with centre ``p - r n`` that contains sample ``q`` is
    replaced by the ball through ``p`` and ``q``: ``r = |p - q|^2 / (2 n . (p - q))``,
    until no sample lies strictly inside. When ``|p - q| < min_chord``, or when ``p`` and
    ``q`` are less than ``min_separation`` apart as seen from the new centre, the last ball
    is kept instead: such a ``q`` is a neighbour of ``p`` on the same surface whose tiny
    offset (noise, tessellation) would collapse the ball.

    Parameters
    ----------
    points : (n, 3) float64, metres
    normals : (n, 3) float64, unit, outward
    eps : float
        Approximate-NN slack of the kd-tree queries (0 = exact, slow on tubes).
    min_chord : float, metres
    min_separation : float, radians in [0, pi)
    max_iterations : int
    samples : (k,) int64, optional
        Grow only these samples' balls (default: all).
    initial_radii : (k,) float64, optional
        Start radii (default: twice the bounding-box diagonal); a ball only shrinks.

    Returns
    -------
    centers : (m, 3) float64
    radii : (m,) float64
    sample_index : (m,) int64
        The sample ``p`` of each ball; samples whose ball never formed are left out.
    second_contact : (m,) int64
        The sample ``q`` that stopped the ball (-1 for a given ball that did not change).
    """
    points = as_points("points", points)
    normals = as_points("normals", normals)
    if normals.shape != points.shape:
        raise BadInputError(f"normals: expected shape {points.shape}, got {normals.shape}")
    # float32 tree: 2-3x faster queries; neighbour choice is then exact to ~1e-7 relative,
    # and every distance that decides anything is recomputed in float64 below
    tree = KDTree(points.astype(np.float32))
    count = len(points)
    radii = np.full(count, 2.0 * np.linalg.norm(np.ptp(points, axis=0)))
    active = np.arange(count) if samples is None else np.asarray(samples, dtype=np.int64)
    if initial_radii is not None:
        radii[active] = initial_radii
    second = np.full(count, -1, dtype=np.int64)
    formed = np.zeros(count, dtype=bool)
    formed[active] = initial_radii is not None  # given balls exist already, they can only shrink
    grown = active.copy()
    for _ in range(max_iterations):
        if not active.size:
            break
        centre = points[active] - radii[active, None] * normals[active]
        _, neighbour = tree.query(centre.astype(np.float32), k=2, eps=eps)
        self_hit = neighbour[:, 0] == active
        q_index = np.where(self_hit, neighbour[:, 1], neighbour[:, 0]).astype(np.int64)
        q_distance = np.linalg.norm(points[q_index] - centre, axis=1)
        chord_vector = points[active] - points[q_index]
        chord_sq = (chord_vector**2).sum(axis=1)
        denominator = 2.0 * (normals[active] * chord_vector).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            new_radius = chord_sq / denominator
        empty = q_distance >= radii[active] * (1.0 - 1e-12)
        # separation angle of p and q from the new centre: sin(angle / 2) = chord / (2 r)
        separated = chord_sq >= (2.0 * new_radius * np.sin(min_separation / 2.0)) ** 2
        shrinks = (
            ~empty
            & (chord_sq >= min_chord**2)
            & separated
            & (denominator > 0)
            & (new_radius < radii[active])
            & (new_radius > 0)
        )
        # a ball is formed once it is empty or once a shrink step was taken from it
        formed[active[empty]] = True
        second[active[empty]] = q_index[empty]
        moved = active[shrinks]
        radii[moved] = new_radius[shrinks]
        second[moved] = q_index[shrinks]
        formed[moved] = True
        active = moved
    keep = grown[formed[grown]]
    centers = points[keep] - radii[keep, None] * normals[keep]
    return centers, radii[keep], keep, second[keep]


def inner_balls(points, normals, centers):
    """(m,) bool: the balls whose centre lies inside the object, behind the outward normal of
    its nearest sample.

    A ball the approximate growing pass wrongly found empty can keep its huge start radius
    when the exact polish may not shrink it (the separation rule); its centre then lies
    outside the object (seen on a thin-walled vase: three 0.24 m spheres beside it).
    """
    _, nearest = KDTree(points).query(centers, k=1)
    nearest = nearest.astype(np.int64)
    return ((centers - points[nearest]) * normals[nearest]).sum(axis=1) < 0.0


def merge_close(centers, radii, *, absolute, relative):
    """Group balls of nearly the same centre and radius; one representative per group.

    Balls fall in the same group when their radii share a bin of relative width
    ``relative`` and their centres a voxel of edge ``max(absolute, relative * r)``.

    Parameters
    ----------
    centers : (m, 3) float64
    radii : (m,) float64, > 0
    absolute : float, metres
    relative : float, fraction of the radius

    Returns
    -------
    keep : (s,) int64
        The first ball of every group, in input order.
    group : (m,) int64
        For every ball, the position in ``keep`` of its representative.
    """
    if absolute <= 0 and relative <= 0:
        return np.arange(len(centers)), np.arange(len(centers))
    if relative > 0:
        level = np.floor(np.log(radii) / np.log1p(relative))
        edge = np.maximum(absolute, relative * np.exp(level * np.log1p(relative)))
    else:
        level, edge = np.zeros(len(radii)), np.full(len(radii), absolute)
    first, inverse = group_rows(np.column_stack([level, np.floor(centers / edge[:, None])]).astype(np.int64))
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return np.sort(first), rank[inverse]


def spread_contacts(centers, surface_points, group, defining):
    """Three defining samples per group whose directions from the centre are spread widest.

    A double sweep over the group's defining samples: start at the first, take the one
    at the largest angle from it, then the one at the largest angle from that. The three
    bound the group's object angle from below and usually attain it (a merged ball at a
    sphere's centre is defined by samples all over the surface).

    Parameters
    ----------
    centers : (s, 3) float64, one per group
    surface_points : (n, 3) float64
    group : (m,) int64, group of every merged ball
    defining : (m, c) int64, -1 padded

    Returns
    -------
    (s, 3) int64, -1 where a group has a single ball (its own samples say it all) or none
    """
    shared = (np.bincount(group, minlength=len(centers)) > 1)[group]
    owner = np.repeat(group[shared], defining.shape[1])
    sample = defining[shared].ravel()
    valid = sample >= 0
    owner, sample = owner[valid], sample[valid]
    direction = unit_rows(surface_points[sample] - centers[owner])
    order = np.argsort(owner, kind="stable")
    owner, sample, direction = owner[order], sample[order], direction[order]
    picked = np.full((len(centers), 3), -1, dtype=np.int64)
    present, first = np.unique(owner, return_index=True)
    anchor = first
    picked[present, 0] = sample[anchor]
    for column in (1, 2):
        cosine = (direction * direction[np.repeat(anchor, np.diff(np.r_[first, len(owner)]))]).sum(axis=1)
        widest = np.lexsort((cosine, owner))  # per group, smallest cosine first
        anchor = widest[first]
        picked[present, column] = sample[anchor]
    return picked


def voronoi_poles(points, normals):
    """Inner Voronoi pole of every sample: the farthest Voronoi vertex on the inner side.

    Parameters
    ----------
    points : (n, 3) float64, metres
    normals : (n, 3) float64, unit, outward

    Returns
    -------
    centers : (m, 3) float64
    radii : (m,) float64, the circumradius of the pole's tetrahedron
    sample_index : (m,) int64
    tetrahedron : (m, 4) int64, the 4 samples on the pole's ball
    """
    points = as_points("points", points)
    normals = as_points("normals", normals)
    if len(points) < 5:
        raise BadInputError("points: need at least 5 for a Delaunay tetrahedralisation")
    from scipy.spatial import Delaunay  # here: scipy.spatial costs 0.5 s to import, for this method only

    # joggled input: exact Delaunay of the coplanar samples of a box face stalls Qhull (45 s at 20k)
    simplices = Delaunay(points, qhull_options="QJ").simplices.astype(np.int64)
    corner = points[simplices]
    edges = corner[:, 1:] - corner[:, :1]
    determinant = np.linalg.det(edges)
    solid = np.abs(determinant) > 1e-12 * np.einsum("tij,tij->t", edges, edges) ** 1.5
    simplices, corner, edges = simplices[solid], corner[solid], edges[solid]
    offset = np.linalg.solve(2.0 * edges, (edges**2).sum(axis=2)[..., None])[..., 0]
    circumcentre = corner[:, 0] + offset
    circumradius = np.linalg.norm(offset, axis=1)
    diagonal = np.linalg.norm(np.ptp(points, axis=0))
    tet = np.repeat(np.arange(len(simplices)), 4)
    sample = simplices.ravel()
    inner = ((circumcentre[tet] - points[sample]) * normals[sample]).sum(axis=1) < 0
    inner &= circumradius[tet] < diagonal
    tet, sample = tet[inner], sample[inner]
    # per sample, the tetrahedron with the largest circumradius
    order = np.lexsort((-circumradius[tet], sample))
    first = np.unique(sample[order], return_index=True)[1]
    pole_tet, pole_sample = tet[order][first], sample[order][first]
    return circumcentre[pole_tet], circumradius[pole_tet], pole_sample, simplices[pole_tet]


def medial_axis(
    surface,
    *,
    method="shrinking_ball",
    kdtree_eps=4.0,
    min_chord_factor=4.0,
    min_separation_deg=20.0,
    max_iterations=30,
    merge_factor=0.5,
    merge_relative=0.01,
):
    """The ``medial_axis`` stage as a pure function.

    Balls are grown (approximate queries for speed), balls of nearly the same centre and
    radius merged (:func:`merge_close`: on a tube or a sphere many samples grow the same
    ball), and each kept shrinking ball polished with exact queries, which the merge made
    affordable. Each kept ball lists its own samples plus the three defining samples of its
    group spread widest (:func:`spread_contacts`).

    Parameters
    ----------
    surface : SurfaceSamples
    method : {'shrinking_ball', 'voronoi_poles'}
    kdtree_eps : float
        Approximate-NN slack of the growing pass.
    min_chord_factor : float
        Minimum chord of the shrinking ball, in median sample spacings.
    min_separation_deg : float
        Minimum angle between the two contacts of a shrinking step, degrees.
    merge_factor : float
        Smallest merge voxel, in median sample spacings.
    merge_relative : float
        Merge voxel and radius bin as a fraction of the radius.

    Returns
    -------
    MedialAxis
    """
    params = dict(
        method=method,
        kdtree_eps=kdtree_eps,
        min_chord_factor=min_chord_factor,
        min_separation_deg=min_separation_deg,
        max_iterations=max_iterations,
        merge_factor=merge_factor,
        merge_relative=merge_relative,
    )
    points, normals = surface.points, surface.normals
    shrink = dict(
        min_chord=min_chord_factor * surface.spacing,
        min_separation=np.radians(min_separation_deg),
        max_iterations=max_iterations,
    )
    if method == "shrinking_ball":
        centers, radii, sample_index, second = shrinking_ball(points, normals, eps=kdtree_eps, **shrink)
        defining = np.stack([sample_index, second], axis=1)
    elif method == "voronoi_poles":
        centers, radii, sample_index, defining = voronoi_poles(points, normals)
    else:
        raise BadInputError(f"medial_axis.method: unknown method {method!r}")
    if not len(centers):
        raise DegenerateGeometryError(f"{surface.source}: no medial ball formed (are the normals outward?)")
    keep, group = merge_close(centers, radii, absolute=merge_factor * surface.spacing, relative=merge_relative)
    spread = spread_contacts(centers[keep], points, group, defining)
    centers, radii, sample_index, defining = centers[keep], radii[keep], sample_index[keep], defining[keep]
    if method == "shrinking_ball":
        _, radii, _, second = shrinking_ball(
            points, normals, eps=POLISH_EPS, samples=sample_index, initial_radii=radii, **shrink
        )
        centers = points[sample_index] - radii[:, None] * normals[sample_index]
        defining[:, 1] = np.where(second >= 0, second, defining[:, 1])
        inner = inner_balls(points, normals, centers)
        centers, radii, sample_index, defining, spread = (
            centers[inner],
            radii[inner],
            sample_index[inner],
            defining[inner],
            spread[inner],
        )
    return MedialAxis(
        centers=centers,
        radii=radii,
        sample_index=sample_index,
        contacts=np.concatenate([defining, spread], axis=1),
        method=method,
        key=content_key("medial_axis", params, surface.key),
    )

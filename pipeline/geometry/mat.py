"""Medial sphere reconstruction from a medial axis point cloud (stage ``mat``, paper II-A).

For every medial axis point the sphere's radius is the distance to the nearest surface
sample, its touching points are the samples within ``r (1 + tau)`` of the centre, and its
object angle is the largest angle between two touching points seen from the centre
(paper II-B). The contact set is the ``max_contacts`` nearest touching samples plus the
samples that defined the ball in the medial axis method (shrinking ball: p and q; Voronoi
poles: the 4 tetrahedron vertices) when they touch: the nearest samples alone can all lie
on one side of a thick part, the defining ones never do.
"""

import numpy as np
from pykdtree.kdtree import KDTree

from ..arrays import padded_rows
from ..artefacts import MedialSpheres, content_key
from ..errors import DegenerateGeometryError
from ..validate import as_points
from .cell_grid import CellGrid

_ANGLE_CHUNK = 1 << 14


def nearest_samples(surface_points, centers, *, count, search="kdtree", kdtree_eps=0.0, cell_density=4.0):
    """The ``count`` nearest surface samples of every centre, nearest first.

    Parameters
    ----------
    surface_points : (n, 3) float64
    centers : (m, 3) float64
    search : {'kdtree', 'grid'}
        pykdtree, or the paper's cell grid (:class:`pipeline.geometry.cell_grid.CellGrid`, exact).
    kdtree_eps : float
        Approximate-NN slack of the kd-tree: the k-th returned sample is within (1 + eps)
        of the true k-th distance. Exact queries stall where many samples are equidistant
        (a sphere's centre, a tube's axis).

    Returns
    -------
    distances : (m, count) float64, nearest first up to float32 ties; inf where fewer samples exist
    indices : (m, count) int64, -1 where fewer samples exist
    """
    count = min(count, len(surface_points))
    if search == "kdtree":
        # float32 tree for speed; distances are recomputed in float64 (the order is float32's,
        # so near-ties may swap: callers take the minimum, not the first)
        _, indices = KDTree(surface_points.astype(np.float32)).query(
            centers.astype(np.float32), k=count, eps=kdtree_eps
        )
        indices = indices.reshape(len(centers), count).astype(np.int64)
        return np.linalg.norm(surface_points[indices] - centers[:, None, :], axis=2), indices
    grid = CellGrid.build(surface_points, cell_density=cell_density)
    nearest_distance, _ = grid.nearest(centers)
    # every sample within twice the nearest distance holds the count nearest when the
    # surface is sampled densely; grow the radius for the few centres that lack them
    radius = 2.0 * nearest_distance + grid.cell_size
    indices = np.full((len(centers), count), -1, dtype=np.int64)
    distances = np.full((len(centers), count), np.inf)
    active = np.arange(len(centers))
    while active.size:
        indptr, hits, hit_distance = grid.query_radius(centers[active], radius[active])
        enough = np.diff(indptr) >= count
        indices[active[enough]] = padded_rows(indptr, hits, count)[enough]
        distances[active[enough]] = padded_rows(indptr, hit_distance, count, fill=np.inf)[enough]
        active = active[~enough]
        radius[active] *= 2.0
    return distances, indices


def object_angle(centers, surface_points, contacts):
    """Largest angle between two contacts seen from the centre, radians in [0, pi].

    Parameters
    ----------
    centers : (m, 3) float64
    surface_points : (n, 3) float64
    contacts : (m, k) int64, valid entries first, -1 padded

    Returns
    -------
    (m,) float64; 0 where fewer than two contacts
    """
    angles = np.zeros(len(centers))
    for start in range(0, len(centers), _ANGLE_CHUNK):
        block = slice(start, start + _ANGLE_CHUNK)
        # padding repeats the first contact: it adds only pairs already present
        index = np.where(contacts[block] >= 0, contacts[block], contacts[block, :1])
        direction = surface_points[np.maximum(index, 0)] - centers[block, None, :]
        # float32 is ample: an angle error of ~1e-7 rad against thresholds of degrees
        direction = (direction / np.linalg.norm(direction, axis=2, keepdims=True)).astype(np.float32)
        cosine = (direction @ direction.transpose(0, 2, 1)).min(axis=(1, 2))
        angles[block] = np.where(contacts[block, 0] >= 0, np.arccos(np.clip(cosine, -1.0, 1.0)), 0.0)
    return angles


def reconstruct(surface, axis, *, tau=0.01, max_contacts=4, search="kdtree", kdtree_eps=0.2, cell_density=4.0):
    """The ``mat`` stage as a pure function: medial spheres from samples and medial axis.

    Parameters
    ----------
    surface : SurfaceSamples
    axis : MedialAxis
    tau : float
        Relative slack of the touching test, ``|p - X| <= r (1 + tau)``.
    max_contacts : int
        Nearest touching samples kept per sphere (plus the method's defining samples).
    search : {'kdtree', 'grid'}
    kdtree_eps : float
        Approximate-NN slack of the kd-tree search for touching samples. The radius stays
        exact: it is the smaller of the method's ball radius (the distance to its own
        sample; the polished shrinking balls and the Delaunay poles are empty) and the
        nearest distance found.
    cell_density : float
        C of eq. 1 for the grid search.

    Returns
    -------
    MedialSpheres
    """
    params = dict(tau=tau, max_contacts=max_contacts, search=search, kdtree_eps=kdtree_eps, cell_density=cell_density)
    points = surface.points
    centers = as_points("medial axis centers", axis.centers)
    defining = np.array(axis.contacts)
    distances, nearest = nearest_samples(
        points, centers, count=max_contacts, search=search, kdtree_eps=kdtree_eps, cell_density=cell_density
    )
    closest = np.argmin(distances, axis=1)
    radii = np.minimum(distances[np.arange(len(centers)), closest], axis.radii)
    touch_limit = radii[:, None] * (1.0 + tau)
    # an inner ball sees its nearest sample from behind that sample's outward normal; a
    # ball that never shrank into the object (a stray normal) sees it from the front
    first = nearest[np.arange(len(centers)), closest]
    inside = ((centers - points[first]) * surface.normals[first]).sum(axis=1) < 0
    nearest = np.where(distances <= touch_limit, nearest, -1)
    safe = np.where(defining >= 0, defining, 0)
    defining_distance = np.linalg.norm(points[safe] - centers[:, None, :], axis=2)
    defining = np.where((defining >= 0) & (defining_distance <= touch_limit), defining, -1)
    # drop defining samples already among the nearest so each contact is listed once
    defining[(defining[:, :, None] == nearest[:, None, :]).any(axis=2)] = -1
    contacts = np.concatenate([nearest, defining], axis=1)
    # compact: valid contacts first, in order (nearest first, then defining)
    contacts = np.take_along_axis(contacts, np.argsort(contacts < 0, axis=1, kind="stable"), axis=1)
    solid = (radii > 0) & inside
    if not solid.any():
        raise DegenerateGeometryError(f"{surface.source}: no medial sphere lies inside the surface")
    centers, radii, contacts = centers[solid], radii[solid], contacts[solid]
    return MedialSpheres(
        centers=centers,
        radii=radii,
        contacts=contacts,
        object_angle=object_angle(centers, points, contacts),
        key=content_key("mat", params, surface.key, axis.key),
    )

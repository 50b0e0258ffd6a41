"""Area-uniform surface samples with oriented normals (stage ``sample``).

Normals are interpolated from per-corner normals that are smoothed only across edges
flatter than a crease angle: a tessellated cylinder gets the smooth normals it needs
(face normals would turn every facet edge into a spurious medial sheet), and a
box keeps its exact face normals at its sharp edges.
"""

import numpy as np
import scipy.sparse
from pykdtree.kdtree import KDTree

from ..arrays import expand_ranges, unit_rows
from ..artefacts import SurfaceSamples, content_key
from ..errors import BadInputError
from ..validate import as_points
from .objects import check_size, load_source, validate_mesh


def corner_normals(vertices, faces, *, sharp_angle):
    """Unit normal at each triangle corner, smoothed over adjacent faces within ``sharp_angle``.

    Parameters
    ----------
    vertices : (v, 3) float64
    faces : (f, 3) int64
    sharp_angle : float
        Radians; a neighbouring face whose normal deviates more is across a crease.

    Returns
    -------
    (f, 3, 3) float64
        ``[face, corner]`` -> unit normal.
    """
    triangles = vertices[faces]
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    face_normals = unit_rows(cross)
    # weights = corner angle x face area: angle weights alone keep a quad strip's split
    # diagonals from tilting the normal sideways; the area factor keeps small faces
    # (a cap's first ring on a long tube) from tilting it along the tube
    to_next = unit_rows((np.roll(triangles, -1, axis=1) - triangles).reshape(-1, 3))
    to_prev = unit_rows((np.roll(triangles, 1, axis=1) - triangles).reshape(-1, 3))
    corner_angle = np.arccos(np.clip((to_next * to_prev).sum(axis=1), -1.0, 1.0))
    corner_vertex = faces.ravel()
    corner_face = np.repeat(np.arange(len(faces)), 3)
    # vertex -> incident faces (CSR, data = the face's angle at that vertex)
    incidence = scipy.sparse.csr_matrix((corner_angle, (corner_vertex, corner_face)), shape=(len(vertices), len(faces)))
    pair_corner, position = expand_ranges(incidence.indptr[corner_vertex], np.diff(incidence.indptr)[corner_vertex])
    pair_face = incidence.indices[position]
    smooth = (face_normals[corner_face[pair_corner]] * face_normals[pair_face]).sum(1) >= np.cos(sharp_angle)
    weight = (incidence.data[position] * np.linalg.norm(cross, axis=1)[pair_face])[smooth]
    summed = np.zeros((len(corner_vertex), 3))
    for axis in range(3):
        summed[:, axis] = np.bincount(
            pair_corner[smooth], weights=weight * face_normals[pair_face[smooth], axis], minlength=len(corner_vertex)
        )
    return unit_rows(summed).reshape(-1, 3, 3)


def sample_mesh(vertices, faces, count, *, rng, sharp_angle):
    """Area-uniform random samples with crease-aware interpolated normals.

    Parameters
    ----------
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64, outward (counter-clockwise) winding
    count : int
    rng : numpy.random.Generator
    sharp_angle : float, radians

    Returns
    -------
    points : (count, 3) float64
    normals : (count, 3) float64, unit, outward
    face_index : (count,) int64
    """
    triangles = vertices[faces]
    areas = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    face_index = rng.choice(len(faces), size=count, p=areas / areas.sum())
    # uniform barycentrics: reflect the unit square's upper triangle
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    weights = np.stack([1 - u - v, u, v], axis=1)
    points = np.einsum("nk,nkj->nj", weights, triangles[face_index])
    normals = np.einsum("nk,nkj->nj", weights, corner_normals(vertices, faces, sharp_angle=sharp_angle)[face_index])
    return points, unit_rows(normals), face_index


def estimate_cloud_normals(points, *, neighbours):
    """Outward unit normals for an unoriented point cloud (open3d plane fit + orientation).

    Parameters
    ----------
    points : (n, 3) float64
    neighbours : int
        k of the kNN plane fit and of the orientation propagation graph.

    Returns
    -------
    (n, 3) float64
    """
    import open3d

    cloud = open3d.geometry.PointCloud(open3d.utility.Vector3dVector(points))
    cloud.estimate_normals(open3d.geometry.KDTreeSearchParamKNN(neighbours))
    cloud.orient_normals_consistent_tangent_plane(neighbours)
    normals = unit_rows(np.asarray(cloud.normals))
    # propagation fixes relative signs only; outward means away from the centroid on average
    if ((points - points.mean(0)) * normals).sum() < 0:
        normals = -normals
    return normals


def median_spacing(points):
    """Median distance from each point to its nearest other point, metres."""
    distances, _ = KDTree(points).query(points, k=2)
    return float(np.median(distances[:, 1]))


def sample_object(
    source,
    *,
    count,
    rng,
    sharp_angle_deg,
    min_extent_m,
    max_extent_m,
    cloud_normal_neighbours,
    scale=1.0,
    shape=None,
    source_key="",
):
    """Load, validate and sample one object: the whole ``sample`` stage as a pure function.

    Parameters
    ----------
    source : str
        See :mod:`pipeline.geometry.objects`.
    count : int
        Samples to draw from a mesh (a point cloud is used as given).
    rng : numpy.random.Generator
    scale : float
        Uniform factor on the coordinates.
    source_key : str
        Content hash of the source (file bytes or spec), folded into the artefact key.

    Returns
    -------
    SurfaceSamples
    """
    params = dict(
        count=count,
        sharp_angle_deg=sharp_angle_deg,
        min_extent_m=min_extent_m,
        max_extent_m=max_extent_m,
        cloud_normal_neighbours=cloud_normal_neighbours,
        scale=scale,
        shape=shape or {},
    )  # no shape keywords: one key, whether None or {}
    loaded = load_source(source, scale=scale, shape=shape)
    key = content_key("sample", params, source_key)
    if loaded[0] == "mesh":
        mesh = validate_mesh(loaded[1], name=source, min_extent=min_extent_m, max_extent=max_extent_m)
        return mesh_samples(
            mesh.vertices, mesh.faces, count=count, rng=rng, sharp_angle_deg=sharp_angle_deg, source=source, key=key
        )
    _, points, normals = loaded
    points = as_points(f"{source}: points", points)
    if len(points) < 100:
        raise BadInputError(f"{source}: point cloud has {len(points)} points, need at least 100")
    check_size(points, name=source, min_extent=min_extent_m, max_extent=max_extent_m)
    if normals is None:
        normals = estimate_cloud_normals(points, neighbours=cloud_normal_neighbours)
    normals = unit_rows(as_points(f"{source}: normals", normals))
    if not (np.linalg.norm(normals, axis=1) > 0).all():
        raise BadInputError(f"{source}: some normals have zero length")
    no_mesh = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return _surface(points, normals, np.full(len(points), -1), *no_mesh, source=source, key=key)


def mesh_samples(vertices, faces, *, count, rng, sharp_angle_deg, source, key=""):
    """:class:`SurfaceSamples` of a closed mesh, ``vertices`` (v, 3) m and ``faces`` (f, 3), that
    is valid already (``sample_object`` checks a user's mesh first)."""
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    points, normals, face_index = sample_mesh(vertices, faces, count, rng=rng, sharp_angle=np.radians(sharp_angle_deg))
    return _surface(points, normals, face_index, vertices, faces, source=source, key=key)


def _surface(points, normals, face_index, vertices, faces, *, source, key):
    return SurfaceSamples(
        points=points,
        normals=normals,
        face_index=face_index,
        vertices=vertices,
        faces=faces,
        spacing=median_spacing(points),
        source=source,
        key=key,
    )

"""The object as the grasp trial sees it: its triangle mesh, queried exactly.

Exact queries (open3d's ``RaycastingScene``): the closest mesh point of a point,
the triangle it lies on and that triangle's outward normal; the distance; inside or outside
(ray parity, so the mesh must be closed, as ``sample`` makes sure). They decide every contact,
stop and collision of a trial.

One approximate structure makes the trial's steps cheap and is never used to decide anything:
a signed distance grid, exact at its nodes. The signed distance is 1-Lipschitz, so for any
point p and any node v, ``s(v) - |p - v| <= s(p) <= s(v) + |p - v|``: :meth:`ObjectMesh.bounds`
returns these bounds from the nearest node, and a point whose bounds do not straddle a
threshold needs no exact query.
"""

import os
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..tol import tol


def edge_points(vertices, faces, face_normals, spacing):
    """Points (m, 3) strictly inside the mesh's non-flat edges longer than ``spacing``, at most
    ``spacing`` apart, with the mean of the two faces' normals (m, 3), half the angle between
    those normals (m,) rad and the edge's unit direction (m, 3): the edge's normal cone."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    pairs, edges = mesh.face_adjacency, mesh.face_adjacency_edges
    bent = mesh.face_adjacency_angles > tol.crease_rad
    start, end = vertices[edges[bent, 0]], vertices[edges[bent, 1]]
    counts = np.ceil(np.linalg.norm(end - start, axis=1) / spacing).astype(int) - 1
    owner = np.repeat(np.arange(len(start)), np.maximum(counts, 0))
    if not len(owner):
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    rank = np.arange(len(owner)) - np.repeat(
        np.cumsum(np.maximum(counts, 0)) - np.maximum(counts, 0), np.maximum(counts, 0)
    )
    fraction = (rank + 1) / (counts[owner] + 1)
    points = start[owner] + fraction[:, None] * (end - start)[owner]
    normals = face_normals[pairs[bent][owner, 0]] + face_normals[pairs[bent][owner, 1]]
    half_angles = mesh.face_adjacency_angles[bent][owner] / 2.0
    directions = (end - start)[owner] / np.linalg.norm(end - start, axis=1)[owner, None]
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True), half_angles, directions


def clamp_to_cone(normals, axes, half_angles, edges):
    """(n, 3) unit normals moved into each object feature's normal cone, the only directions a
    contact force there can push along: ``axes`` (n, 3) unit and ``half_angles`` (n,) rad; along
    an edge (``edges`` (n, 3) its unit direction, 0 at a vertex) the cone is the arc between its
    two faces' normals, so a normal's component along the edge goes first. A normal inside is
    kept; one outside goes to the rim, in its own plane with the axis. A link face's normal at a
    near-flat edge (a 96-gon's 3.75 deg) thus becomes the surface's, not the face's own tilt."""
    normals = np.asarray(normals, np.float64)
    across = normals - np.einsum("ij,ij->i", normals, edges)[:, None] * edges
    length = np.linalg.norm(across, axis=1, keepdims=True)
    across = np.where(length > 1e-12, across / np.maximum(length, 1e-300), axes)
    cos = np.clip(np.einsum("ij,ij->i", across, axes), -1.0, 1.0)
    tilt = across - cos[:, None] * axes
    tilt_length = np.linalg.norm(tilt, axis=1, keepdims=True)
    tilt = np.where(tilt_length > 1e-12, tilt / np.maximum(tilt_length, 1e-300), 0.0)
    rim = np.cos(half_angles)[:, None] * axes + np.sin(half_angles)[:, None] * tilt
    return np.where((cos < np.cos(half_angles))[:, None], rim, across)


def feature_contact_normals(normals, axes, half_angles, edges):
    """(n, 3) contact normals at object edges and corners from the link faces' reversed
    ``normals`` (n, 3): on the facets of a smooth surface (a cone's half angle at most
    :attr:`pipeline.tol.Tolerances.smooth_half_rad`) the surface's, the normal clamped into the
    cone (:func:`clamp_to_cone`), whatever the link's tilt (a fingertip's corner on a 96-gon);
    at a sharp edge or corner (a box's) the link face's, which lies against it."""
    smooth = np.asarray(half_angles) <= tol.smooth_half_rad
    normals = np.array(normals, np.float64)
    normals[smooth] = clamp_to_cone(normals[smooth], axes[smooth], half_angles[smooth], edges[smooth])
    return normals


def barycentric(points, corners):
    """(n, 3) barycentric coordinates of (n, 3) ``points`` in the (n, 3, 3) triangles ``corners``
    (of their projection on the triangle's plane)."""
    ab, ac, ap = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], points - corners[:, 0]
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    d00, d01, d11, d20, d21 = dot(ab, ab), dot(ab, ac), dot(ac, ac), dot(ap, ab), dot(ap, ac)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = (d11 * d20 - d01 * d21) / (d00 * d11 - d01 * d01)
        w = (d00 * d21 - d01 * d20) / (d00 * d11 - d01 * d01)
    return np.stack([1 - v - w, v, w], axis=1)


@dataclass(frozen=True)
class NormalCones:
    """The normal cones of a closed mesh's edges and corners, the directions a contact force
    there can push along (:func:`clamp_to_cone`). ``vertex_normals`` (v, 3) area-weighted unit
    normals and ``vertex_half`` (v,) rad: a circular cone around a vertex's faces' normals;
    ``neighbours`` (f, 3) the face across the edge facing each corner (:func:`_neighbours`); an
    edge's cone is the arc between its two faces' normals."""

    vertices: np.ndarray
    faces: np.ndarray
    face_normals: np.ndarray
    vertex_normals: np.ndarray
    vertex_half: np.ndarray
    neighbours: np.ndarray

    @classmethod
    def of(cls, vertices, faces, face_normals):
        accumulated = np.zeros_like(vertices)
        crossed = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
        for corner in range(3):
            np.add.at(accumulated, faces[:, corner], crossed)
        normals = accumulated / np.maximum(np.linalg.norm(accumulated, axis=1, keepdims=True), 1e-300)
        lowest = np.ones(len(vertices))
        np.minimum.at(lowest, faces.ravel(), np.einsum("fcj,fj->fc", normals[faces], face_normals).ravel())
        return cls(vertices, faces, face_normals, normals, np.arccos(np.clip(lowest, -1.0, 1.0)), _neighbours(faces))

    def at_border(self, triangles, weights):
        """(axes (k, 3), half angles (k,), edges (k, 3)) of the edge or corner of ``triangles``
        (k,) nearest the barycentric ``weights`` (k, 3): a corner where two weights are within
        :attr:`pipeline.tol.Tolerances.border` of 0, else the edge facing the smallest one."""
        order = np.argsort(weights, axis=1)
        at_corner = weights[np.arange(len(triangles)), order[:, 1]] <= tol.border
        corner = self.faces[triangles, order[:, 2]]
        opposite = order[:, 0]
        first, second = self.face_normals[triangles], self.face_normals[self.neighbours[triangles, opposite]]
        middle = first + second
        middle /= np.maximum(np.linalg.norm(middle, axis=1, keepdims=True), 1e-300)
        half = np.arccos(np.clip(np.einsum("ij,ij->i", first, second), -1.0, 1.0)) / 2.0
        start = self.vertices[self.faces[triangles, (opposite + 1) % 3]]
        edge = self.vertices[self.faces[triangles, (opposite + 2) % 3]] - start
        edge /= np.maximum(np.linalg.norm(edge, axis=1, keepdims=True), 1e-300)
        return (
            np.where(at_corner[:, None], self.vertex_normals[corner], middle),
            np.where(at_corner, self.vertex_half[corner], half),
            np.where(at_corner[:, None], 0.0, edge),
        )

    def clamp(self, normals, points, triangles):
        """(k, 3) ``normals`` at ``points`` (k, 3) on an edge or corner of ``triangles`` (k,)
        moved into that feature's normal cone."""
        weights = barycentric(points, self.vertices[self.faces[triangles]])
        return feature_contact_normals(normals, *self.at_border(triangles, weights))


def _neighbours(faces):
    """(f, 3) int: the face across the edge facing each corner of each face (a closed mesh's
    edges each join two faces; an edge of one face only, or of more than two, gives the face
    itself, a flat cone)."""
    half = faces[:, [[1, 2], [2, 0], [0, 1]]]  # (f, 3, 2): the edge facing corner k
    key = np.sort(half, axis=2)
    key = key[..., 0] * (faces.max() + 1) + key[..., 1]
    order = np.argsort(key.ravel(), kind="stable")
    ranked = key.ravel()[order]
    neighbours = np.repeat(np.arange(len(faces)), 3)
    pairs = np.flatnonzero(ranked[1:] == ranked[:-1])
    alone = np.ones(len(ranked) + 1, bool)  # a key shared by exactly two half-edges pairs them
    alone[1:-1] = ranked[1:] != ranked[:-1]
    single = pairs[alone[pairs] & alone[pairs + 2]]
    neighbours[order[single]] = order[single + 1] // 3
    neighbours[order[single + 1]] = order[single] // 3
    return neighbours.reshape(-1, 3)


@dataclass(frozen=True)
class Features:
    """The mesh's own convex features, which a flat link face can be nearest: every vertex, and
    points along every edge between faces that are not coplanar (an object edge under a link
    face is nearest it somewhere along the edge). ``points`` (m, 3); ``normals`` (m, 3) orient
    them (area-weighted at vertices, the two faces' mean along edges) and are the axes of their
    normal cones, ``half_angles`` (m,) rad and ``edges`` (m, 3) (0 at vertices) the rest
    (:func:`clamp_to_cone`); ``cells``: the points
    binned in cubic cells (origin, cell size, shape, CSR starts, point indices, the points in
    that order: :func:`_cells`),
    for the link pieces' ball queries (:func:`pipeline.trial.proximity._feature_hits`)."""

    points: np.ndarray
    normals: np.ndarray
    half_angles: np.ndarray
    edges: np.ndarray
    cells: tuple

    def clamp(self, normals, index):
        """(k, 3) ``normals`` at features ``index`` (k,) moved into their normal cones."""
        return feature_contact_normals(normals, self.normals[index], self.half_angles[index], self.edges[index])


FEATURE_CELL_M = 0.006  # the feature bins' side: a link cover's ball (about 1 cm) spans a few
FEATURE_CELLS = 64  # the most bins along an axis: a 1 m object gets 1.6 cm bins, not 5 M of them


def _cells(points, size):
    """(origin (3,), size, shape (3,), starts (c + 1,), indices (n,), binned (n, 3)): the (n, 3)
    ``points`` binned in cubic cells of ``size`` m (larger if :data:`FEATURE_CELLS` cells along an
    axis do not span them), as compressed rows: cell ``c = (i * shape[1] + j) * shape[2] + k``
    holds ``indices[starts[c]:starts[c + 1]]``, in increasing order, and ``binned`` is
    ``points[indices]``, so that a cell's points are read in one run of memory."""
    origin = points.min(axis=0) if len(points) else np.zeros(3)
    upper = points.max(axis=0) if len(points) else np.zeros(3)
    size = max(size, float((upper - origin).max()) / (FEATURE_CELLS - 1))
    shape = np.floor((upper - origin) / size).astype(np.int64) + 1
    index = np.floor((points - origin) / size).astype(np.int64)
    cell = (index[:, 0] * shape[1] + index[:, 1]) * shape[2] + index[:, 2]
    order = np.argsort(cell, kind="stable")
    starts = np.searchsorted(cell[order], np.arange(int(np.prod(shape)) + 1))
    return origin, float(size), shape, starts.astype(np.int64), order.astype(np.int64), points[order]


@njit(cache=True)
def grid_bounds(points, grid, origin, voxel, slack):
    """(n,) lower and upper bounds on the signed distance of (n, 3) points from the ``grid``'s
    nearest node (see :meth:`ObjectMesh.bounds`; compiled code calls it with the first four of
    :attr:`ObjectMesh.clearance_grid`)."""
    low, high = np.empty(len(points)), np.empty(len(points))
    last = np.array(grid.shape) - 1
    cell = np.empty(3, np.int64)
    for point in range(len(points)):
        squared = 0.0
        for axis in range(3):
            cell[axis] = min(max(np.int64(np.rint((points[point, axis] - origin[axis]) / voxel)), 0), last[axis])
            squared += (points[point, axis] - (origin[axis] + cell[axis] * voxel)) ** 2
        reach = np.sqrt(squared) + slack
        node = grid[cell[0], cell[1], cell[2]]
        low[point], high[point] = node - reach, node + reach
    return low, high


@njit(cache=True)
def grid_clearance(points, grid, origin, voxel, slack, box):
    """(n,) lower bounds on the unsigned distance of (n, 3) points (see :meth:`ObjectMesh.clearance`;
    compiled code calls it with :attr:`ObjectMesh.clearance_grid`)."""
    low, high = grid_bounds(points, grid, origin, voxel, slack)
    out = np.empty(len(points))
    for point in range(len(points)):
        squared = 0.0
        for axis in range(3):
            beyond = max(box[0, axis] - points[point, axis], points[point, axis] - box[1, axis], 0.0)
            squared += beyond * beyond
        out[point] = max(low[point], -high[point], 0.0, np.sqrt(squared))
    return out


@dataclass(frozen=True)
class Closest:
    """Exact closest-point answers for (n,) queries: ``points`` (n, 3) on the mesh, ``triangles``
    (n,) int, ``normals`` (n, 3) the triangles' outward unit normals, ``distances`` (n,) m."""

    points: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    distances: np.ndarray

    def at(self, rows):
        """The answers of ``rows`` (an index or a mask)."""
        return Closest(self.points[rows], self.triangles[rows], self.normals[rows], self.distances[rows])


def grid_nodes(vertices, grid_cells):
    """The signed distance grid of a mesh with (v, 3) ``vertices``: its origin (3,) and voxel (m),
    ``grid_cells`` along the bounding box's longest side and two more beyond each side, its
    shape (3,) and its nodes (n, 3) in C order."""
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    voxel = float((high - low).max() / grid_cells)
    origin = low - 2 * voxel
    shape = np.ceil((high - low) / voxel).astype(int) + 5
    axes = [origin[k] + voxel * np.arange(shape[k]) for k in range(3)]
    return origin, voxel, shape, np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def grid_distances(vertices, faces, grid_cells):
    """(n,) the exact signed distances (m) of the :func:`grid_nodes` of the closed mesh
    (``vertices`` (v, 3), ``faces`` (f, 3)), on every CPU this process may use: what
    :class:`ObjectMesh` builds its grid from, for another process to compute."""
    import open3d

    vertices = np.asarray(vertices, np.float64)
    nodes = grid_nodes(vertices, grid_cells)[-1]
    scene = _scene(open3d, vertices, np.asarray(faces, np.int64))
    query = open3d.core.Tensor(np.ascontiguousarray(nodes, np.float32))
    threads = len(os.sched_getaffinity(0))
    return scene.compute_signed_distance(query, nthreads=threads).numpy().astype(np.float64)


def _scene(open3d, vertices, faces):
    """open3d's ray casting scene of the mesh (float32 vertices, uint32 faces)."""
    scene = open3d.t.geometry.RaycastingScene()
    scene.add_triangles(open3d.core.Tensor(vertices.astype(np.float32)), open3d.core.Tensor(faces.astype(np.uint32)))
    return scene


class ObjectMesh:
    """A closed triangle mesh (metres, object frame) with exact queries and a distance grid.

    Parameters
    ----------
    vertices : (v, 3) float
    faces : (f, 3) int
    grid_cells : int
        Grid nodes along the longest side of the bounding box (plus a margin of two cells).
    edge_spacing : float
        Largest gap (m) between the mesh's feature points along an edge (``features``, the
        :class:`Features` a moving hand is measured against).
    contact_edge_spacing : float, optional
        The same for ``contact_features``, which the closed hand's contacts are measured
        against (default ``edge_spacing``).
    grid : callable, optional
        Returns the grid nodes' signed distances as :func:`grid_distances` computes them
        (computed here when None). Called last, so that another process can compute them while
        this one builds the rest.
    """

    def __init__(self, vertices, faces, *, grid_cells=40, edge_spacing=0.003, contact_edge_spacing=None, grid=None):
        import open3d

        self._o3d = open3d
        #: threads of open3d's queries: the CPUs this process may use (open3d's pool is sized once,
        #: at its first use); one where each process of a pool has a core of its own
        self.threads = len(os.sched_getaffinity(0))
        self.vertices = np.asarray(vertices, np.float64)
        self.faces = np.asarray(faces, np.int64)
        corners = self.vertices[self.faces]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        self.face_normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        self.scene = self._scene()
        # vertex normals (area weighted) orient contacts found at mesh vertices; with the
        # faces' neighbours they give every edge's and corner's normal cone
        self.cones = NormalCones.of(self.vertices, self.faces, self.face_normals)
        self.features = self._features(edge_spacing)
        self.contact_features = (
            self.features if contact_edge_spacing in (None, edge_spacing) else self._features(contact_edge_spacing)
        )
        self.box = np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])
        self.origin, self.voxel, shape, nodes = grid_nodes(self.vertices, grid_cells)
        self.grid = (self.signed_distance(nodes) if grid is None else grid()).reshape(shape)

    def _scene(self):
        return _scene(self._o3d, self.vertices, self.faces)

    def __getstate__(self):
        # open3d's scene does not pickle; it is rebuilt from the mesh (milliseconds), while the
        # grid, the costly part (its exact distances), travels as it is
        return {name: value for name, value in vars(self).items() if name not in ("_o3d", "scene")}

    def __setstate__(self, state):
        import open3d

        vars(self).update(state, _o3d=open3d)
        self.scene = self._scene()

    def _features(self, spacing):
        along, along_normals, along_half, along_edges = edge_points(
            self.vertices, self.faces, self.face_normals, spacing
        )
        points = np.concatenate([self.vertices, along])
        vertex_normals, vertex_half = self.cones.vertex_normals, self.cones.vertex_half
        return Features(
            points,
            np.concatenate([vertex_normals, along_normals]),
            np.concatenate([vertex_half, along_half]),
            np.concatenate([np.zeros_like(vertex_normals), along_edges]),
            _cells(points, FEATURE_CELL_M),
        )

    def _tensor(self, points):
        return self._o3d.core.Tensor(np.ascontiguousarray(points, np.float32))

    def closest(self, points):
        """Exact closest mesh points of (n, 3) points; a :class:`Closest`."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return Closest(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
        answer = self.scene.compute_closest_points(self._tensor(points), nthreads=self.threads)
        triangles = answer["primitive_ids"].numpy().astype(np.int64)
        # open3d answers in float32: project again in float64 onto the triangle's plane
        on_mesh = answer["points"].numpy().astype(np.float64)
        normals = self.face_normals[triangles]
        on_plane = (
            on_mesh
            - np.einsum("ij,ij->i", on_mesh - self.vertices[self.faces[triangles, 0]], normals)[:, None] * normals
        )
        return Closest(on_plane, triangles, normals, np.linalg.norm(points - on_plane, axis=1))

    def on_border(self, found):
        """(n,) bool: the closest points ``found`` (:meth:`closest`) may lie on their triangle's
        edge or corner (smallest barycentric coordinate below :attr:`pipeline.tol.Tolerances.border`;
        open3d answers in float32), where the triangle's normal is not the contact's."""
        weights = barycentric(found.points, self.vertices[self.faces[found.triangles]])
        return ~(weights.min(axis=1) > tol.border)

    def clamp_on_border(self, normals, found):
        """(k, 3) ``normals`` at the closest points ``found`` (on an edge or corner of their
        triangle, :meth:`on_border`) moved into that edge's or corner's normal cone."""
        return self.cones.clamp(normals, found.points, found.triangles)

    def distance(self, points):
        """(n,) exact unsigned distances (m) of (n, 3) points to the mesh."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0)
        return self.scene.compute_distance(self._tensor(points), nthreads=self.threads).numpy().astype(np.float64)

    def inside(self, points):
        """(n,) bool: inside the closed mesh (exact, by ray parity)."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0, bool)
        return self.scene.compute_occupancy(self._tensor(points), nthreads=self.threads).numpy() > 0.5

    def exit_distance(self, points, directions):
        """(n,) distance (m) from each of the (n, 3) points inside the mesh along its (n, 3) unit
        direction to the mesh's first triangle (exact ray casts, float32); 0 where no triangle
        is hit (a point outside, on a ray that misses)."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0)
        rays = np.concatenate([points, np.asarray(directions, np.float64).reshape(-1, 3)], axis=1)
        hit = self.scene.cast_rays(self._tensor(rays), nthreads=self.threads)["t_hit"].numpy().astype(np.float64)
        return np.where(np.isfinite(hit), hit, 0.0)

    def signed_distance(self, points):
        """(n,) exact signed distances (m), negative inside."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0)
        return (
            self.scene.compute_signed_distance(self._tensor(points), nthreads=self.threads).numpy().astype(np.float64)
        )

    def bounds(self, points):
        """(n,) lower and (n,) upper bounds (m) on the signed distance of (n, 3) points, from the
        grid's nearest node (valid anywhere: far outside the grid they are loose, not wrong)."""
        points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        return grid_bounds(points, self.grid, self.origin, self.voxel, tol.grid_slack * self.voxel)

    @property
    def clearance_grid(self):
        """What :func:`grid_clearance` takes after the points: the grid, its origin, voxel, slack
        and the mesh's bounding box."""
        return self.grid, self.origin, self.voxel, tol.grid_slack * self.voxel, self.box

    def clearance(self, points):
        """(n,) lower bound (m) on the unsigned distance of (n, 3) points to the mesh: the grid's,
        or beyond the grid the distance to the mesh's bounding box."""
        points = np.ascontiguousarray(points, np.float64).reshape(-1, 3)
        return grid_clearance(points, *self.clearance_grid)

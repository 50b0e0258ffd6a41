"""The object as the grasp trial sees it: its triangle mesh, queried exactly.

Exact queries (open3d's ``RaycastingScene``, facts.md 10): the closest mesh point of a point,
the triangle it lies on and that triangle's outward normal; the distance; inside or outside
(ray parity, so the mesh must be closed, as ``sample`` makes sure). They decide every contact,
stop and collision of a trial.

One approximate structure makes the trial's steps cheap and is never used to decide anything:
a signed distance grid, exact at its nodes. The signed distance is 1-Lipschitz, so for any
point p and any node v, ``s(v) - |p - v| <= s(p) <= s(v) + |p - v|``: :meth:`ObjectMesh.bounds`
returns these bounds from the nearest node, and a point whose bounds do not straddle a
threshold needs no exact query.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class Closest:
    """Exact closest-point answers for (n,) queries: ``points`` (n, 3) on the mesh, ``triangles``
    (n,) int, ``normals`` (n, 3) the triangles' outward unit normals, ``distances`` (n,) m."""

    points: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    distances: np.ndarray


class ObjectMesh:
    """A closed triangle mesh (metres, object frame) with exact queries and a distance grid.

    Parameters
    ----------
    vertices : (v, 3) float
    faces : (f, 3) int
    grid_cells : int
        Grid nodes along the longest side of the bounding box (plus a margin of two cells).
    """

    def __init__(self, vertices, faces, *, grid_cells=40):
        import open3d

        self._o3d = open3d
        self.vertices = np.asarray(vertices, np.float64)
        self.faces = np.asarray(faces, np.int64)
        corners = self.vertices[self.faces]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        self.face_normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        self.scene = open3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(open3d.core.Tensor(self.vertices.astype(np.float32)),
                                 open3d.core.Tensor(self.faces.astype(np.uint32)))
        self.vertex_tree = cKDTree(self.vertices)
        # vertex normals (area weighted) orient contacts found from mesh vertices
        accumulated = np.zeros_like(self.vertices)
        for corner in range(3):
            np.add.at(accumulated, self.faces[:, corner], normals)
        self.vertex_normals = accumulated / np.maximum(np.linalg.norm(accumulated, axis=1, keepdims=True), 1e-300)
        low, high = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.voxel = float((high - low).max() / grid_cells)
        self.origin = low - 2 * self.voxel
        shape = np.ceil((high - low) / self.voxel).astype(int) + 5
        axes = [self.origin[k] + self.voxel * np.arange(shape[k]) for k in range(3)]
        nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        self.grid = self.signed_distance(nodes).reshape(shape)

    def _tensor(self, points):
        return self._o3d.core.Tensor(np.ascontiguousarray(points, np.float32))

    def closest(self, points):
        """Exact closest mesh points of (n, 3) points; a :class:`Closest`."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return Closest(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
        answer = self.scene.compute_closest_points(self._tensor(points))
        triangles = answer["primitive_ids"].numpy().astype(np.int64)
        # open3d answers in float32: project again in float64 onto the triangle's plane
        on_mesh = answer["points"].numpy().astype(np.float64)
        normals = self.face_normals[triangles]
        on_plane = on_mesh - np.einsum("ij,ij->i", on_mesh - self.vertices[self.faces[triangles, 0]], normals)[:, None] * normals
        return Closest(on_plane, triangles, normals, np.linalg.norm(points - on_plane, axis=1))

    def distance(self, points):
        """(n,) exact unsigned distances (m) of (n, 3) points to the mesh."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0)
        return self.scene.compute_distance(self._tensor(points)).numpy().astype(np.float64)

    def inside(self, points):
        """(n,) bool: inside the closed mesh (exact, by ray parity)."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0, bool)
        return self.scene.compute_occupancy(self._tensor(points)).numpy() > 0.5

    def signed_distance(self, points):
        """(n,) exact signed distances (m), negative inside."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(points):
            return np.zeros(0)
        return self.scene.compute_signed_distance(self._tensor(points)).numpy().astype(np.float64)

    def bounds(self, points):
        """(n,) lower and (n,) upper bounds (m) on the signed distance of (n, 3) points, from the
        grid's nearest node (valid anywhere: far outside the grid they are loose, not wrong)."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        cell = np.clip(np.rint((points - self.origin) / self.voxel).astype(np.int64), 0, np.array(self.grid.shape) - 1)
        node = self.grid[cell[:, 0], cell[:, 1], cell[:, 2]]
        slack = np.linalg.norm(points - (self.origin + cell * self.voxel), axis=1)
        # open3d's float32 distances are good to about 1e-7 of the object's size
        slack += 1e-6 * self.voxel
        return node - slack, node + slack

    def clearance(self, points):
        """(n,) lower bound (m) on the unsigned distance of (n, 3) points to the mesh."""
        low, high = self.bounds(points)
        return np.maximum(np.maximum(low, -high), 0.0)

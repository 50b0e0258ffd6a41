"""A slow, independent reference for :mod:`pipeline.trial.engine`: the same trial protocol, its
geometry computed another way, by brute force.

- **Distances and collisions** are pybullet's exact queries. pybullet holds the object as a
  static concave triangle mesh and each of a link's collision shapes (a mesh as its convex
  hull) as a body of its own, all with collision margin 0: through the URDF's links pybullet
  keeps the importer's 1 mm margin on each shape of a compound (only the compound's is set by
  ``changeDynamics``), which rounded box edges and corners (distances up to 0.73 mm long). A
  link swallowed whole by the object, which pybullet cannot see (the mesh is only a surface),
  is caught by the winding number of the link's box centres (:func:`winding_number`).
- **Touching pairs** (:mod:`pipeline.trial.contacts`' definition 1), from which the closing rule
  decides whether a link is pressed and the contacts are merged: every link hull edge sampled
  every :data:`REFERENCE_SPACING_M` against every object triangle near it
  (:func:`closest_on_triangles`), and every object vertex and creased-edge point at that
  spacing against every link hull (:func:`_hull_gap`), in numpy and scipy's k-d trees, where
  the engine uses open3d, a distance grid, cover spheres and 3 mm samples.
- **Kinematics** of whether closing presses a touching link into the object: pybullet's joint
  frames and axes (the velocity of a point summed down its chain).

Placement, the closing and approach rules, and the contact merging and quality definitions are
the engine's (they are what the two share by design). One trial costs tens of pybullet queries
per step: use it on small samples (bench, tests).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, cKDTree
from scipy.spatial.transform import Rotation

from ..bullet import BulletClient, load_hand_body, pybullet
from ..geometry.mesh_query import NormalCones, edge_points, feature_contact_normals
from ..hands.kinematics import base_poses, hand_model, link_poses
from ..tol import tol
from ..geometry.mass import centre_of_mass
from .engine import TrialResult, grade


def winding_number(vertices, faces, points):
    """(n,) generalised winding number of a closed mesh at (n, 3) points: 1 inside, 0 outside
    (the triangles' solid angles, Van Oosterom and Strackee 1983)."""
    corners = vertices[faces][None] - np.asarray(points, float)[:, None, None]
    a, b, c = corners[:, :, 0], corners[:, :, 1], corners[:, :, 2]
    la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
    numerator = np.einsum("ntk,ntk->nt", a, np.cross(b, c))
    denominator = (
        la * lb * lc
        + np.einsum("ntk,ntk->nt", a, b) * lc
        + np.einsum("ntk,ntk->nt", b, c) * la
        + np.einsum("ntk,ntk->nt", c, a) * lb
    )
    return (2.0 * np.arctan2(numerator, denominator)).sum(axis=1) / (4.0 * np.pi)


REFERENCE_SPACING_M = 0.0005
"""Spacing (m) of the reference's points along link edges and the object's creased edges (the
engine's ``link_point_spacing_m`` is 3 mm)."""


@dataclass(frozen=True)
class _Probe:
    """One collision shape: its pybullet body, its frame in its link's inertial frame, its
    convex hull's ``triangles`` (t, 3, 3) and face ``planes`` (t, 4: outward normal, offset;
    n . x + d <= 0 inside) and points ``surface`` (s, 3) along its edges, all in its own frame."""

    body: int
    position: tuple
    quaternion: tuple
    triangles: np.ndarray
    planes: np.ndarray
    surface: np.ndarray


def closest_on_triangles(points, triangles):
    """(n, 3) closest points on (n, 3, 3) triangles to (n, 3) points, pairwise (Ericson,
    *Real-Time Collision Detection*, 5.1.5: the Voronoi region of a corner, an edge or the
    face), and (n,) bool: on a corner or an edge."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, ac = b - a, c - a
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    d1, d2 = dot(ab, points - a), dot(ac, points - a)
    d3, d4 = dot(ab, points - b), dot(ac, points - b)
    d5, d6 = dot(ab, points - c), dot(ac, points - c)
    vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        on_ab = a + (d1 / (d1 - d3))[:, None] * ab
        on_ac = a + (d2 / (d2 - d6))[:, None] * ac
        on_bc = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None] * (c - b)
        total = va + vb + vc
        inside = a + (vb / total)[:, None] * ab + (vc / total)[:, None] * ac
    regions = [
        (d1 <= 0) & (d2 <= 0),
        (d3 >= 0) & (d4 <= d3),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),
        (d6 >= 0) & (d5 <= d6),
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
    ]
    choices = [a, b, on_ab, c, on_ac, on_bc]
    return np.select([region[:, None] for region in regions], choices, inside), np.any(regions, axis=0)


def _hull_edge_points(hull, spacing):
    """Points (m, 3) along the edges of a :class:`scipy.spatial.ConvexHull` between faces that
    are not coplanar, ends included, at most ``spacing`` apart: the link surface points of
    :mod:`pipeline.trial.contacts` (a flat link face meets the object through the object's features)."""
    owner, neighbour = np.repeat(np.arange(len(hull.simplices)), 3), hull.neighbors.ravel()
    bent = (owner < neighbour) & (
        np.einsum("ij,ij->i", hull.equations[owner, :3], hull.equations[neighbour, :3]) < 1 - 1e-9
    )
    # the edge facing corner k of a simplex is the other two corners
    corner = np.tile(np.arange(3), len(hull.simplices))[bent]
    simplices = hull.simplices[owner[bent]]
    starts = hull.points[simplices[np.arange(len(corner)), (corner + 1) % 3]]
    ends = hull.points[simplices[np.arange(len(corner)), (corner + 2) % 3]]
    points = [
        start
        + np.outer(np.linspace(0.0, 1.0, max(int(np.ceil(np.linalg.norm(end - start) / spacing)), 1) + 1), end - start)
        for start, end in zip(starts, ends)
    ]
    return np.unique(np.round(np.concatenate(points), 12), axis=0)


def _hull_gap(triangles, planes, points, facing, tie=1e-9):
    """Signed distance (n,) of (n, 3) points to a convex hull (``triangles`` (t, 3, 3),
    ``planes`` (t, 4)), negative inside, and the row of ``planes`` of the contact's normal
    (n,): inside, the nearest face's; outside, of the faces through the nearest hull point the
    one whose normal best agrees with ``facing`` (n, 3)."""
    signed = points @ planes[:, :3].T + planes[:, 3]
    gap, face = signed.max(axis=1), signed.argmax(axis=1)
    outside = np.flatnonzero(gap > 0)
    if len(outside):
        count = len(triangles)
        owner = np.repeat(outside, count)
        closest = closest_on_triangles(points[owner], np.tile(triangles, (len(outside), 1, 1)))[0]
        distance = np.linalg.norm(points[owner] - closest, axis=1).reshape(-1, count)
        nearest = closest.reshape(-1, count, 3)[np.arange(len(outside)), distance.argmin(axis=1)]
        through = np.abs(nearest @ planes[:, :3].T + planes[:, 3]) <= tie
        agree = np.where(through, facing[outside] @ planes[:, :3].T, -np.inf)
        gap[outside], face[outside] = distance.min(axis=1), agree.argmax(axis=1)
    return gap, face


class ReferenceEngine(BulletClient):
    """``run`` and ``trial`` as :class:`pipeline.trial.engine.GraspEngine`'s, from pybullet."""

    def __init__(self, surface, hand, settings=None, **overrides):
        from .engine import trial_settings

        self.settings = trial_settings(settings, **overrides)
        self.hand, self.model = hand, hand_model(hand, spacing=self.settings.link_point_spacing_m)
        self.vertices, self.faces = surface.vertices, surface.faces
        self.centre = centre_of_mass(surface.vertices, surface.faces)
        self.torque_scale = float(np.linalg.norm(surface.vertices - self.centre, axis=1).max())
        self._index_object(np.asarray(surface.vertices, float), np.asarray(surface.faces))
        super().__init__()
        shape = self._call(
            pybullet.createCollisionShape,
            pybullet.GEOM_MESH,
            vertices=surface.vertices.tolist(),
            indices=surface.faces.ravel().tolist(),
            flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
        )
        self.object = self._call(pybullet.createMultiBody, 0, shape)
        self._call(pybullet.changeDynamics, self.object, -1, collisionMargin=0.0)
        self.body = load_hand_body(hand, self.client)
        info = [
            self._call(pybullet.getJointInfo, self.body, k) for k in range(self._call(pybullet.getNumJoints, self.body))
        ]
        self.joint_index = {row[1].decode(): row[0] for row in info}
        link_index = {row[12].decode(): row[0] for row in info}
        # pybullet link index of each model link (-1: the base)
        self.links = [-1] + [link_index[name] for name in self.model.links[1:]]
        # each model link's joint axis in its own (the joint's) frame
        self.joint_axes = np.array([[0.0, 0.0, 0.0]] + [info[index][13] for index in self.links[1:]])
        for link in self.links:
            self._call(pybullet.changeDynamics, self.body, link, collisionMargin=0.0)
        self.probes = [
            [self._probe(row) for row in self._call(pybullet.getCollisionShapeData, self.body, index)]
            for index in self.links
        ]
        self.base_inertial = self._call(pybullet.getDynamicsInfo, self.body, -1)[3:5]

    def _index_object(self, vertices, faces):
        """The object's triangles, vertices and features (vertices, with area-weighted normals,
        and points along creased edges at :data:`REFERENCE_SPACING_M`, with their two faces' mean
        normal) in k-d trees, for :meth:`_touching_pairs`."""
        corners = vertices[faces]
        crossed = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        self.face_normals = crossed / np.linalg.norm(crossed, axis=1, keepdims=True)
        self.longest_edge = float(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max())
        self.vertex_tree, self.centroid_tree = cKDTree(vertices), cKDTree(corners.mean(axis=1))
        self.cones = NormalCones.of(vertices, faces, self.face_normals)
        along, along_normals, along_half, along_edges = edge_points(
            vertices, faces, self.face_normals, REFERENCE_SPACING_M
        )
        self.features = np.concatenate([vertices, along])
        self.feature_normals = np.concatenate([self.cones.vertex_normals, along_normals])
        self.feature_half = np.concatenate([self.cones.vertex_half, along_half])
        self.feature_edges = np.concatenate([np.zeros_like(vertices), along_edges])
        self.feature_tree = cKDTree(self.features)

    def _pose(self, base, q):
        position, quaternion = base[:3, 3], Rotation.from_matrix(base[:3, :3]).as_quat()
        position, quaternion = pybullet.multiplyTransforms(tuple(position), tuple(quaternion), *self.base_inertial)
        self._call(pybullet.resetBasePositionAndOrientation, self.body, position, quaternion)
        for name, value in self.model.joint_values(q).items():
            self._call(pybullet.resetJointState, self.body, self.joint_index[name], value)

    def _probe(self, row):
        """One collision shape (a ``getCollisionShapeData`` row) as a :class:`_Probe`: a base-only
        body (margin 0) and the shape's convex hull, with its frame in its link's inertial frame."""
        kind, dimensions, filename, position, quaternion = row[2], row[3], row[4], row[5], row[6]
        if kind == pybullet.GEOM_BOX:
            shape = dict(halfExtents=[size / 2 for size in dimensions])
            corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
            vertices = corners * np.asarray(dimensions) / 2
        elif kind == pybullet.GEOM_MESH:
            import trimesh

            shape = dict(fileName=filename.decode(), meshScale=dimensions)
            vertices = trimesh.load(filename.decode(), force="mesh").vertices * np.asarray(dimensions)
        else:  # the built-in hands and franka use boxes and meshes only
            raise NotImplementedError(f"the reference takes box and mesh collision shapes, not pybullet kind {kind}")
        body = self._call(pybullet.createMultiBody, 0, self._call(pybullet.createCollisionShape, kind, **shape))
        self._call(pybullet.changeDynamics, body, -1, collisionMargin=0.0)
        hull = ConvexHull(vertices)
        triangles = hull.points[hull.simplices]
        return _Probe(
            body, position, quaternion, triangles, hull.equations, _hull_edge_points(hull, REFERENCE_SPACING_M)
        )

    def _placed(self, link):
        """The probes of model link ``link`` at the hand's current pose: (probe, (3,) position,
        (3, 3) rotation) each, the probes' bodies moved there."""
        if self.links[link] < 0:
            frame = self._call(pybullet.getBasePositionAndOrientation, self.body)
        else:
            frame = self._call(pybullet.getLinkState, self.body, self.links[link], computeForwardKinematics=True)[:2]
        placed = []
        for probe in self.probes[link]:
            position, quaternion = pybullet.multiplyTransforms(*frame, probe.position, probe.quaternion)
            self._call(pybullet.resetBasePositionAndOrientation, probe.body, position, quaternion)
            rotation = np.array(pybullet.getMatrixFromQuaternion(quaternion)).reshape(3, 3)
            placed.append((probe, np.asarray(position), rotation))
        return placed

    def _hits(self, link, distance):
        """pybullet's closest points of model link ``link``'s shapes within ``distance`` of the object."""
        return [
            hit
            for probe, _, _ in self._placed(link)
            for hit in self._call(pybullet.getClosestPoints, probe.body, self.object, distance)
        ]

    def _touching_pairs(self, link, tolerance):
        """The touching pairs of :mod:`pipeline.trial.contacts` (its definition 1) of model link ``link``
        within ``tolerance``, brute force: distances (k,), object points (k, 3) and outward
        normals (k, 3). A link surface point (along every shape's hull edges at
        :data:`REFERENCE_SPACING_M`) gives its closest mesh point and that triangle's normal (on
        an object edge or corner, minus the normal of the shape's face through it that best faces
        the object there); a
        mesh feature (every vertex, and points along creased edges at that spacing) gives itself
        and the shape face's normal reversed (off an edge or corner, of the faces through its
        nearest point the one that best faces the object's normal there)."""
        gaps, points, normals = [], [], []
        for probe, position, rotation in self._placed(link):
            world = probe.surface @ rotation.T + position
            near = np.isfinite(self.vertex_tree.query(world, distance_upper_bound=tolerance + self.longest_edge)[0])
            distance, closest, triangle, border = self._closest_on_object(world[near], tolerance)
            touching = distance <= tolerance
            gaps.append(distance[touching])
            points.append(closest[touching])
            normal = self.face_normals[triangle[touching]]
            # on an object edge or corner: minus the normal of the shape's face through the
            # point that best faces the object there
            on_edge = border[touching]
            local = probe.surface[near][touching][on_edge]
            offset = (world[near][touching][on_edge] - closest[touching][on_edge]) @ rotation
            through = np.abs(local @ probe.planes[:, :3].T + probe.planes[:, 3]) <= 1e-9
            score = np.where(through, -offset @ probe.planes[:, :3].T, -np.inf)
            best = score.argmax(axis=1)
            found = np.isfinite(score[np.arange(len(best)), best])
            normal[np.flatnonzero(on_edge)[found]] = -probe.planes[best[found], :3] @ rotation.T
            # as far as the object feature's normal cone allows
            edge_rows = np.flatnonzero(on_edge)
            normal[edge_rows] = self.cones.clamp(
                normal[edge_rows], closest[touching][edge_rows], triangle[touching][edge_rows]
            )
            normals.append(normal)
            centre = probe.triangles.reshape(-1, 3).mean(axis=0)
            reach = np.linalg.norm(probe.triangles.reshape(-1, 3) - centre, axis=1).max() + tolerance
            nearby = np.asarray(self.feature_tree.query_ball_point(centre @ rotation.T + position, reach), int)
            local = (self.features[nearby] - position) @ rotation
            gap, face = _hull_gap(probe.triangles, probe.planes, local, -self.feature_normals[nearby] @ rotation)
            touching = gap <= tolerance
            gaps.append(np.maximum(gap[touching], 0.0))
            points.append(self.features[nearby[touching]])
            index = nearby[touching]
            normals.append(
                feature_contact_normals(
                    -probe.planes[face[touching], :3] @ rotation.T,
                    self.feature_normals[index],
                    self.feature_half[index],
                    self.feature_edges[index],
                )
            )
        return np.concatenate(gaps), np.concatenate(points), np.concatenate(normals)

    def _closest_on_object(self, points, reach):
        """Distance (n,), closest point (n, 3), triangle (n,) and whether on its edge or corner
        (n,) on the object of (n, 3) points known to be within ``reach`` plus the longest edge
        of a vertex (at a tie, the triangle whose normal best faces the point)."""
        if not len(points):
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, int), np.zeros(0, bool)
        found = self.centroid_tree.query_ball_point(points, reach + self.longest_edge)
        owner = np.repeat(np.arange(len(points)), [len(row) for row in found])
        triangle = np.concatenate([np.asarray(row, int) for row in found])
        closest, border = closest_on_triangles(points[owner], self.vertices[self.faces[triangle]])
        offset = points[owner] - closest
        distance = np.linalg.norm(offset, axis=1)
        facing = np.einsum("ij,ij->i", offset, self.face_normals[triangle])
        best = np.lexsort((-facing, np.round(distance, 12), owner))
        first = best[np.flatnonzero(np.diff(owner[best], prepend=-1))]
        result = (
            np.full(len(points), np.inf),
            np.zeros((len(points), 3)),
            np.zeros(len(points), int),
            np.zeros(len(points), bool),
        )
        for values, found in zip(result, (distance, closest, triangle, border)):
            values[owner[first]] = found[first]
        return result

    def _gap(self, link, reach=1.0):
        """Exact distance (m) of model link ``link`` to the object, negative when penetrating."""
        hits = self._hits(link, reach)
        return min((hit[8] for hit in hits), default=reach)

    def _link_frame(self, link):
        if self.links[link] < 0:
            state = self._call(pybullet.getBasePositionAndOrientation, self.body)
        else:
            state = self._call(pybullet.getLinkState, self.body, self.links[link], computeForwardKinematics=True)[4:6]
        return np.asarray(state[0]), np.array(pybullet.getMatrixFromQuaternion(state[1])).reshape(3, 3)

    def _pressed(self, active, link):
        """Whether closing the ``active`` joints presses link ``link``'s touching pairs
        (:meth:`_touching_pairs`) into the object: their velocity (:meth:`_velocity`) against
        the object's normal there, by more than :attr:`pipeline.tol.Tolerances.sliding` of
        their speed."""
        _, points, normals = self._touching_pairs(link, self.settings.contact_tolerance_m)
        velocity = self._velocity(link, points, active)
        into = np.einsum("ij,ij->i", velocity, normals) < -tol.sliding * np.linalg.norm(velocity, axis=1)
        return bool(into.any())

    def _velocity(self, link, points, active):
        """(k, 3) velocity (m per unit of closing) of world ``points`` (k, 3) on model link
        ``link`` under the ``active`` joints closing, from pybullet's joint frames and axes down
        the chain (pybullet's link states are float32: a numerical derivative over a small
        closing step was off by 2e-4 of the speed, enough to press a face sliding past a vertex)."""
        model, velocity, walk = self.model, np.zeros_like(points), link
        while walk > 0:
            joint = model.driver[walk]
            if joint >= 0 and active[joint]:
                origin, rotation = self._link_frame(walk)
                axis = rotation @ self.joint_axes[walk]
                rate = model.closing[joint] * model.multiplier[walk]
                velocity += rate * (axis if model.prismatic[walk] else np.cross(axis, points - origin))
            walk = model.parent[walk]
        return velocity

    def _collides(self, base, q):
        geometric = [link for link in range(len(self.model.links)) if self.model.link_radius[link] > 0]
        if any(self._gap(link, 0.0) < -1e-6 for link in geometric):
            return True
        poses = link_poses(self.model, base[None], q[None])[0]
        centres = (
            np.einsum("sij,sj->si", poses[self.model.box_link, :3, :3], self.model.box_centre)
            + poses[self.model.box_link, :3, 3]
        )
        return bool((winding_number(self.vertices, self.faces, centres) > 0.5).any())

    def run(self, grasp, approach, orient, preshapes):
        return [self.trial(*target) for target in zip(grasp, approach, orient, preshapes)]

    def trial(self, grasp_point, approach, orient, preshape=None):
        """One trial, as :meth:`pipeline.trial.engine.GraspEngine.trial`."""
        model, settings = self.model, self.settings
        tolerance = settings.contact_tolerance_m
        approach = np.asarray(approach, float) / np.linalg.norm(approach)
        base = base_poses(
            self.hand, np.asarray(grasp_point, float)[None], approach[None], np.asarray(orient, float)[None]
        )[0]
        q = np.array([self.hand.preshape(preshape)[name] for name in model.joints], float)
        retreat = None
        for offset in np.arange(0.0, settings.retract_max_m + 1e-12, settings.retract_step_m):
            moved = base.copy()
            moved[:3, 3] -= offset * approach
            self._pose(moved, q)
            if not self._collides(moved, q):
                retreat = offset
                break
        if retreat is None:
            return TrialResult("collision")
        geometric = [link for link in range(len(model.links)) if model.link_radius[link] > 0]
        farthest = -(self.hand.max_graspable_diameter if settings.approach_max_m == -1 else settings.approach_max_m)
        offset = retreat
        while settings.approach_to_contact:  # on along +P_d until the first link is within the tolerance
            moved = base.copy()
            moved[:3, 3] -= offset * approach
            self._pose(moved, q)
            gap = min(self._gap(link) for link in geometric)
            if gap <= tolerance:
                break
            if offset - farthest <= 1e-9:
                return TrialResult("no_contact", retract_m=farthest, approach_m=float(retreat - farthest))
            step = max(
                settings.approach_step_m,
                np.floor((gap - tolerance) / settings.approach_step_m) * settings.approach_step_m,
            )
            offset = max(offset - step, farthest)
        base[:3, 3] -= offset * approach
        near = max(settings.near_m, tolerance)  # the engine's closing steps, as it sizes them
        direction = np.sign(model.closing)
        active = (direction != 0) & ~np.where(direction > 0, q >= model.upper, q <= model.lower)
        by_contact = np.zeros_like(active)
        steps = 0
        for _ in range(settings.max_close_steps):
            if not active.any():
                break
            steps += 1
            self._pose(base, q)
            wanted = (active.astype(float) @ model.moves) > 0
            distance = np.array(
                [
                    self._gap(link) if wanted[link] and model.link_radius[link] > 0 else np.inf
                    for link in range(len(model.links))
                ]
            )
            touching = np.flatnonzero(distance <= tolerance)
            pressing = np.zeros(len(model.links), bool)
            pressing[touching] = [self._pressed(active, link) for link in touching]
            stopped = active & ((pressing.astype(float) @ model.moves.T) > 0)
            by_contact |= stopped
            active &= ~stopped
            for finger in range(model.fingers):
                joints = np.flatnonzero(active & (model.finger == finger))
                if not len(joints):
                    continue
                motion = np.abs(model.closing[joints]) @ model.lever[joints]
                links = np.flatnonzero(motion > 0)
                room = np.maximum(np.minimum(distance[links], near) - tolerance / 2, tolerance / 2)
                advance = (room / motion[links]).min()
                q[joints] = np.clip(
                    q[joints] + model.closing[joints] * advance, model.lower[joints], model.upper[joints]
                )
                reached = np.where(
                    direction[joints] > 0, q[joints] >= model.upper[joints], q[joints] <= model.lower[joints]
                )
                active[joints[reached]] = False
        stops = tuple(
            "step_cap"
            if (active & (model.finger == f)).any()
            else "contact"
            if (by_contact & (model.finger == f)).any()
            else "limit"
            for f in range(model.fingers)
        )
        self._pose(base, q)
        pose = dict(
            retract_m=float(offset),
            approach_m=float(retreat - offset),
            base_position=tuple(base[:3, 3]),
            base_orientation=tuple(Rotation.from_matrix(base[:3, :3]).as_quat()),
            joint_positions=tuple(map(float, q)),
            close_steps=steps,
            finger_stops=stops,
        )
        if "step_cap" in stops:
            return TrialResult("step_cap", **pose)
        regions = []
        for link in geometric:
            if self._gap(link, tolerance) <= tolerance:
                _, points, normals = self._touching_pairs(link, tolerance)
                if len(points):
                    regions.append((link, points, normals))
        return grade(regions, model, settings, centre=self.centre, torque_scale=self.torque_scale, **pose)

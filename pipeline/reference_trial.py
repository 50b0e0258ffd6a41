"""A slow, independent reference for :mod:`pipeline.simulation`: the same trial protocol with
every distance, collision and contact point taken from pybullet's exact queries instead.

pybullet holds the object as a static concave triangle mesh (collision margin 0) and the hand
as its URDF (a mesh link as its convex hull); ``getClosestPoints`` gives exact distances and the
object points near each link, with the normal on the object. A link swallowed whole by the
object, which pybullet cannot see (the mesh is only a surface), is caught by the winding number
of the link's box centres (:func:`winding_number`). Placement, the closing rule and the contact merging and quality
definitions are the engine's (they are what the two share by design); the geometry is not,
nor the kinematics of whether closing presses a touching link into the object (pybullet's link
states, differentiated numerically). One
trial costs tens of pybullet queries per step: use it on small samples (bench, tests).
"""

import numpy as np
from scipy.spatial.transform import Rotation

from .bullet import load_hand, pybullet
from .kinematics import base_poses, hand_model, link_poses
from .simulation import TrialResult, grade, mass_properties


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


class ReferenceEngine:
    """``run`` and ``trial`` as :class:`pipeline.simulation.GraspEngine`'s, from pybullet."""

    def __init__(self, surface, hand, **settings):
        from .simulation import TrialSettings
        from .params import SimulateParams

        self.settings = TrialSettings(**{**SimulateParams().world_settings(), **settings})
        self.hand, self.model = hand, hand_model(hand, spacing=self.settings.link_point_spacing_m)
        self.vertices, self.faces = surface.vertices, surface.faces
        self.centre = mass_properties(surface.vertices, surface.faces)
        self.torque_scale = float(np.linalg.norm(surface.vertices - self.centre, axis=1).max())
        self.client = pybullet.connect(pybullet.DIRECT)
        shape = self._call(
            pybullet.createCollisionShape,
            pybullet.GEOM_MESH,
            vertices=surface.vertices.tolist(),
            indices=surface.faces.ravel().tolist(),
            flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
        )
        self.object = self._call(pybullet.createMultiBody, 0, shape)
        self._call(pybullet.changeDynamics, self.object, -1, collisionMargin=0.0)
        self.body = load_hand(hand, self.client)
        info = [
            self._call(pybullet.getJointInfo, self.body, k) for k in range(self._call(pybullet.getNumJoints, self.body))
        ]
        self.joint_index = {row[1].decode(): row[0] for row in info}
        link_index = {row[12].decode(): row[0] for row in info}
        # pybullet link index of each model link (-1: the base)
        self.links = [-1] + [link_index[name] for name in self.model.links[1:]]
        for link in self.links:
            self._call(pybullet.changeDynamics, self.body, link, collisionMargin=0.0)
        self.base_inertial = self._call(pybullet.getDynamicsInfo, self.body, -1)[3:5]

    def _call(self, function, *args, **kwargs):
        return function(*args, physicsClientId=self.client, **kwargs)

    def close(self):
        if self.client is not None:
            pybullet.disconnect(physicsClientId=self.client)
            self.client = None

    def _pose(self, base, q):
        position, quaternion = base[:3, 3], Rotation.from_matrix(base[:3, :3]).as_quat()
        position, quaternion = pybullet.multiplyTransforms(tuple(position), tuple(quaternion), *self.base_inertial)
        self._call(pybullet.resetBasePositionAndOrientation, self.body, position, quaternion)
        for name, value in self.model.joint_values(q).items():
            self._call(pybullet.resetJointState, self.body, self.joint_index[name], value)

    def _hits(self, link, distance):
        return self._call(pybullet.getClosestPoints, self.body, self.object, distance, linkIndexA=self.links[link])

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

    def _pressed(self, base, q, active, link, step=1e-5):
        """Whether closing the ``active`` joints presses link ``link``'s touching points into the
        object: their motion over a tiny closing step (pybullet's kinematics, numerically) against
        the object's normal there."""
        hits = self._hits(link, self.settings.contact_tolerance_m)
        points, normals = np.array([hit[6] for hit in hits]), np.array([hit[7] for hit in hits])
        origin, rotation = self._link_frame(link)
        local = (points - origin) @ rotation
        self._pose(base, np.where(active, q + step * self.model.closing, q))
        origin, rotation = self._link_frame(link)
        self._pose(base, q)
        moved = local @ rotation.T + origin - points
        return bool((np.einsum("ij,ij->i", moved, normals) < 0).any())

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
        """One trial, as :meth:`pipeline.simulation.GraspEngine.trial`."""
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
        offset = retreat
        while offset > 0:  # back toward the object until the first link is within the tolerance
            moved = base.copy()
            moved[:3, 3] -= offset * approach
            self._pose(moved, q)
            gap = min(self._gap(link) for link in geometric)
            if gap <= tolerance:
                break
            step = max(
                settings.approach_step_m,
                np.floor((gap - tolerance) / settings.approach_step_m) * settings.approach_step_m,
            )
            offset = max(offset - step, 0.0)
        base[:3, 3] -= offset * approach
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
            pressing[touching] = [self._pressed(base, q, active, link) for link in touching]
            stopped = active & ((pressing.astype(float) @ model.moves.T) > 0)
            by_contact |= stopped
            active &= ~stopped
            for finger in range(model.fingers):
                joints = np.flatnonzero(active & (model.finger == finger))
                if not len(joints):
                    continue
                motion = np.abs(model.closing[joints]) @ model.lever[joints]
                links = np.flatnonzero(motion > 0)
                room = np.maximum(distance[links] - tolerance / 2, tolerance / 2)
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
            hits = self._hits(link, tolerance)
            if hits:
                regions.append((link, np.array([hit[6] for hit in hits]), np.array([hit[7] for hit in hits])))
        return grade(regions, model, settings, centre=self.centre, torque_scale=self.torque_scale, **pose)

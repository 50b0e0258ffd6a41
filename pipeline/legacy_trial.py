"""The grasp trial engine before issue 13 (pybullet, sample distances), kept only so that
``python -m pipeline bench --only trials`` can time it beside :mod:`pipeline.simulation`.

Grasp trials in pybullet (stage ``simulate``, paper IV).

A trial is kinematic: the object is a static exact triangle mesh (concave), the hand a fixed-base
URDF whose joints are set directly. Per candidate (P_g, P_d, P_o, preshape):

1. place the hand so its grasp centre is at P_g, its approach axis along P_d and its wrap axis
   along P_o, in the preshape;
2. retract along -P_d in ``retract_step_m`` steps, at most ``retract_max_m``, until the hand is
   clear; never clear -> ``collision``. Each link's box is covered by spheres; a retreat is
   clear at once when every sphere is farther from the surface samples than its radius, and in
   collision when a sample lies in a sphere inscribed in a link or a sphere centre is in the
   interior voxels (pybullet sees only the mesh surface, so a link swallowed whole is invisible
   to it); otherwise pybullet checks the links near the mesh, then the samples' normals;
3. close every finger at once, joints coupled by their ratios, by conservative advancement: each
   step moves no point of a link farther than its distance to the surface samples (exact below
   ``near_m``, a voxel bound beyond), so no finger tunnels through the object. A link within
   ``contact_tolerance_m`` of the samples stops its joint and the joints before it; the joints
   after it close on (the Barrett breakaway). Distances to samples stand in for distances to the
   mesh here: pybullet queries against a concave mesh cost about 1 ms each, 10-50x a step;
4. contacts = the mesh points (pybullet) within ``contact_tolerance_m`` of the closed hand, two
   per touching link (:func:`_patch_ends`), normals from the nearest surface sample (pybullet's
   are unreliable on triangle edges);
5. Ferrari-Canny epsilon (:mod:`pipeline.quality`), torque scaled by the object's largest
   distance from its centre of mass (GraspIt, Dex-Net).

Outcomes: ``force_closure``, ``no_force_closure``, ``no_contact``, ``collision``, ``error``.
"""

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .bullet import load_hand, pybullet
from .errors import BadParamsError
from .quality import epsilon_quality
from .simulation import mass_properties

OUTCOMES = ("force_closure", "no_force_closure", "no_contact", "collision", "error")
_MAX_CLOSE_STEPS = 60


@dataclass(frozen=True)
class TrialResult:
    """One trial: outcome, quality, the hand's base pose after retract and its closed joints."""

    outcome: str
    epsilon: float = 0.0
    volume: float = 0.0
    retract_m: float = float("nan")
    base_position: tuple = (float("nan"),) * 3
    base_orientation: tuple = (float("nan"),) * 4
    joint_positions: tuple = ()
    contact_points: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    contact_normals: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    contact_links: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    message: str = ""


def hand_rotation(hand, approach, orient):
    """(3, 3) rotation taking the hand's approach and wrap axes onto P_d and P_o (unit, orthogonal)."""
    hand_axes = np.column_stack([hand.approach, hand.wrap, np.cross(hand.approach, hand.wrap)])
    orient = orient - np.dot(orient, approach) * approach  # tolerate rounding in the candidate table
    orient /= np.linalg.norm(orient)
    world_axes = np.column_stack([approach, orient, np.cross(approach, orient)])
    return world_axes @ hand_axes.T


class GraspWorld:
    """A pybullet DIRECT client holding one object and one hand; :meth:`trial` runs a grasp."""

    def __init__(
        self,
        surface,
        hand,
        *,
        mu=0.5,
        cone_edges=8,
        torsional_friction_m=0.0,
        contact_tolerance_m=0.002,
        retract_step_m=0.005,
        retract_max_m=0.2,
        near_m=0.004,
    ):
        self.hand = hand
        self.mu, self.cone_edges, self.torsional_friction = mu, cone_edges, torsional_friction_m
        self.touch, self.step, self.retract_max, self.near = (
            contact_tolerance_m,
            retract_step_m,
            retract_max_m,
            near_m,
        )
        self.samples, self.sample_normals = surface.points, surface.normals
        self.tree = cKDTree(surface.points)  # pykdtree's OpenMP costs ms on small queries
        self.interior = InteriorGrid.build(surface)
        self.centre = mass_properties(surface.vertices, surface.faces)
        self.torque_scale = float(np.linalg.norm(surface.points - self.centre, axis=1).max())
        self.client = pybullet.connect(pybullet.DIRECT)
        shape = pybullet.createCollisionShape(
            pybullet.GEOM_MESH,
            vertices=surface.vertices.tolist(),
            indices=surface.faces.ravel().tolist(),
            flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
            physicsClientId=self.client,
        )
        self.object = pybullet.createMultiBody(0, shape, physicsClientId=self.client)
        # exact distances: Bullet pads meshes with a 1 mm margin by default
        pybullet.changeDynamics(self.object, -1, collisionMargin=0.0, physicsClientId=self.client)
        self.body = load_hand(self.hand, self.client)
        self._index_joints()

    def _call(self, function, *args, **kwargs):
        return function(*args, physicsClientId=self.client, **kwargs)

    def _index_joints(self):
        info = [
            self._call(pybullet.getJointInfo, self.body, index)
            for index in range(self._call(pybullet.getNumJoints, self.body))
        ]
        self.joint_index = {row[1].decode(): row[0] for row in info}
        missing = [joint for joint in self.hand.limits if joint not in self.joint_index]
        if missing:
            raise BadParamsError(f"hand {self.hand.name}: joint {missing[0]!r} is not in its URDF")
        self.prismatic = {row[1].decode() for row in info if row[2] == pybullet.JOINT_PRISMATIC}
        for link in range(-1, len(info)):
            self._call(pybullet.changeDynamics, self.body, link, collisionMargin=0.0)
        # pybullet places a base by its inertial frame; the hand's declarations use the URDF frame
        self.base_inertial = self._call(pybullet.getDynamicsInfo, self.body, -1)[3:5]
        self.links = np.arange(-1, len(info))
        self.finger_links = np.array(
            [self.joint_index[joint] for finger in self.hand.fingers for joint in finger.joints]
        )
        self.boxes = self._boxes()
        self.cover = _cover_spheres(self.boxes[2])
        finger = np.isin(self.cover[2], self.finger_links + 1)  # the cover is sorted by link
        self.finger_cover = finger, np.flatnonzero(np.diff(self.cover[2][finger], prepend=-2))
        self.levers = self._levers()

    def _boxes(self):
        """Each link's collision box (slot = link + 1): centre (n, 3) and rotation (n, 3, 3) in its
        inertial frame, half extents (n, 3); spheres, capsules and cylinders get their bounding box,
        a link without collision shape an empty box."""
        centres, rotations, halves = [], [], []
        for link in self.links:
            shapes = self._call(pybullet.getCollisionShapeData, self.body, int(link))
            if len(shapes) > 1:
                raise BadParamsError(f"hand {self.hand.name}: a link has {len(shapes)} collision shapes (use one)")
            if not shapes:
                shapes = [(0, link, pybullet.GEOM_SPHERE, (0.0, 0.0, 0.0), b"", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))]
            geometry, dimensions, centre, orientation = shapes[0][2], shapes[0][3], shapes[0][5], shapes[0][6]
            centres.append(centre)
            rotations.append(_matrices(np.asarray(orientation)[None])[0])
            halves.append(_half_extents(geometry, dimensions, self.hand.name))
        return np.array(centres), np.array(rotations), np.array(halves)

    def link_boxes(self, base_position, base_orientation, joints):
        """Every link's collision box with the hand's URDF base at ``base_position`` (m) and
        ``base_orientation`` (quaternion x y z w) and ``joints`` (name -> value): world centres
        (n, 3), rotations (n, 3, 3) and half extents (n, 3), slot = link + 1."""
        self._set_joints(joints)
        self._place(base_position, base_orientation)
        centres, rotations = self._poses()
        return centres, rotations, self.boxes[2]

    def _levers(self):
        """Per finger, ``levers[i, k]``: how far (m) a point of link k moves per unit of joint i
        (radius about a revolute joint, open hand; 1 for a prismatic joint); 0 when i > k."""
        self._set_joints(self.hand.preshape())
        self._place(np.zeros(3), (0.0, 0.0, 0.0, 1.0))
        corners = self._finger_corners()
        position_of = {int(link): index for index, link in enumerate(self.finger_links)}
        levers = []
        for finger in self.hand.fingers:
            columns = [position_of[self.joint_index[joint]] for joint in finger.joints]
            table = np.zeros((len(columns), len(columns)))
            for i, joint in enumerate(finger.joints):
                origin = np.array(self._call(pybullet.getLinkState, self.body, self.joint_index[joint])[4])
                for k in range(i, len(columns)):
                    table[i, k] = (
                        1.0 if joint in self.prismatic else np.linalg.norm(corners[columns[k]] - origin, axis=1).max()
                    )
            levers.append(table)
        return levers

    def _poses(self):
        """World centre (n, 3) and rotation (n, 3, 3) of every link's box (slot = link + 1)."""
        base = self._call(pybullet.getBasePositionAndOrientation, self.body)
        states = [base] + list(self._call(pybullet.getLinkStates, self.body, self.links[1:].tolist()))
        rotations = _matrices(np.array([state[1] for state in states])) @ self.boxes[1]
        centres = np.array([state[0] for state in states]) + np.einsum("nij,nj->ni", rotations, self.boxes[0])
        return centres, rotations

    def _finger_corners(self):
        centres, rotations = self._poses()
        return np.array([_box_corners(*box) for box in zip(centres, rotations, self.boxes[2])])[self.finger_links + 1]

    def _cover(self, centres, rotations):
        """World centres (m, 3) of the spheres covering the link boxes."""
        local, _, owner, _ = self.cover
        return centres[owner] + np.einsum("nij,nj->ni", rotations[owner], local)

    def _place(self, position, quaternion):
        position, quaternion = pybullet.multiplyTransforms(tuple(position), tuple(quaternion), *self.base_inertial)
        self._call(pybullet.resetBasePositionAndOrientation, self.body, position, quaternion)

    def _set_joints(self, values):
        for joint, value in values.items():
            self._call(pybullet.resetJointState, self.body, self.joint_index[joint], value)

    def _finger_distances(self, cache, wanted):
        """Per link slot: its distance (m) to the surface samples, exact below ``self.near`` and a
        lower bound above (from the spheres covering each box), for the slots in the boolean
        mask ``wanted`` only (inf for the others), so closing steps stay conservative.

        ``cache`` (slot -> (corners, sample indices)) keeps the samples gathered round a link
        until the link has moved ``self.near`` from where they were gathered."""
        centres, rotations = self._poses()
        _, radii, owner, _ = self.cover
        spheres = self._cover(centres, rotations)
        finger, starts = self.finger_cover
        distances = np.full(len(centres), np.inf)
        distances[owner[finger][starts]] = np.minimum.reduceat(
            self.interior.distance_bound(spheres[finger]) - radii[finger], starts
        )
        distances[~wanted] = np.inf  # stopped fingers: their exact distances would cost the most
        for slot in np.flatnonzero(distances < self.near):
            corners = _box_corners(centres[slot], rotations[slot], self.boxes[2][slot])
            if slot not in cache or np.linalg.norm(corners - cache[slot][0], axis=1).max() > self.near:
                mine = owner == slot
                balls = self.tree.query_ball_point(spheres[mine], radii[mine] + 2 * self.near)
                cache[slot] = corners, np.unique(np.fromiter(itertools.chain.from_iterable(balls), dtype=np.intp))
            near = cache[slot][1]
            if not near.size:
                distances[slot] = self.near
                continue
            local = np.abs((self.samples[near] - centres[slot]) @ rotations[slot])
            exact = np.sqrt(np.square(np.maximum(local - self.boxes[2][slot], 0.0)).sum(axis=1).min())
            # samples left out of the gathering are farther than self.near: beyond it, a bound
            distances[slot] = min(exact, self.near)
        return distances

    def _retract(self, base, quaternion, approach):
        """The smallest retreat (m, a multiple of ``self.step``) that leaves the hand clear of the
        object, or None. A retreat is clear at once when every covering sphere is farther from the
        samples than its radius; it is in collision when a sphere centre lies inside the object
        (pybullet sees only the mesh surface); otherwise pybullet decides."""
        offsets = np.arange(0.0, self.retract_max + 1e-12, self.step)
        _, radii, _, inscribed = self.cover
        spheres = (self._cover(*self._poses())[None] - offsets[:, None, None] * approach).reshape(-1, 3)
        gap, _ = self.tree.query(spheres, k=1, distance_upper_bound=radii.max())
        gap = gap.reshape(len(offsets), -1)
        # a sample in a cell's inscribed sphere lies on the mesh and inside a link
        colliding = self.interior.contains(spheres).reshape(len(offsets), -1).any(axis=1) | (gap < inscribed).any(
            axis=1
        )
        unsure = gap <= radii
        spheres = spheres.reshape(len(offsets), -1, 3)
        for step in np.flatnonzero(~colliding):
            if not unsure[step].any():
                return offsets[step]
            self._place(base - offsets[step] * approach, quaternion)
            # only the links near the mesh: a query's cost grows with the triangles in its box
            links = np.unique(self.cover[2][unsure[step]]) - 1
            if any(
                hit[8] < 0
                for link in links
                for hit in self._call(pybullet.getClosestPoints, self.body, self.object, 0.0, linkIndexA=int(link))
            ):
                continue
            # no link crosses the mesh; near the surface the samples' normals tell inside from out
            # (a sphere clear of the samples is outside, or deep enough for the interior voxels)
            if not self._inside(spheres[step][unsure[step]]).any():
                return offsets[step]
        return None

    def _touching_links(self):
        """Links that may lie within the contact tolerance of the mesh: a covering sphere comes
        within the tolerance of a sample, with ``self.near`` to spare for the mesh between samples."""
        reach = self.cover[1] + self.touch + self.near
        gap, _ = self.tree.query(self._cover(*self._poses()), k=1, distance_upper_bound=reach.max())
        return [int(slot) - 1 for slot in np.unique(self.cover[2][gap <= reach])]

    def _inside(self, points):
        """(n, 3) points -> bool (n,): behind the nearest oriented surface sample."""
        _, nearest = self.tree.query(points, k=1)
        return np.einsum("ij,ij->i", points - self.samples[nearest], self.sample_normals[nearest]) < 0

    def trial(self, grasp_point, approach, orient, preshape=None):
        """Run one grasp trial; returns a :class:`TrialResult` (pybullet failures -> ``error``)."""
        try:
            return self._trial(
                np.asarray(grasp_point, float), np.asarray(approach, float), np.asarray(orient, float), preshape
            )
        except Exception as err:  # noqa: BLE001 - one failed trial is counted, never kills the run
            return TrialResult("error", message=f"{type(err).__name__}: {err}")

    def _trial(self, grasp_point, approach, orient, preshape):
        rotation = hand_rotation(self.hand, approach, orient)
        quaternion = _quaternion(rotation)
        base = grasp_point - rotation @ np.asarray(self.hand.grasp_centre)
        joints = self.hand.preshape(preshape)
        self._set_joints(joints)
        self._place(base, quaternion)
        cleared = self._retract(base, quaternion, approach)
        if cleared is None:
            return TrialResult("collision")
        base = base - cleared * approach
        self._place(base, quaternion)
        joints = self._close(joints)
        hits = [
            hit
            for link in self._touching_links()
            for hit in self._call(pybullet.getClosestPoints, self.body, self.object, self.touch, linkIndexA=link)
        ]
        pose = dict(
            retract_m=float(cleared),
            base_position=tuple(base),
            base_orientation=tuple(quaternion),
            joint_positions=tuple(joints[name] for name in self.hand.limits),
        )
        if not hits:
            return TrialResult("no_contact", **pose)
        points, links = _patch_ends(
            np.array([hit[6] for hit in hits]), np.array([hit[3] for hit in hits]), np.array([hit[8] for hit in hits])
        )
        _, nearest = self.tree.query(points, k=1)
        normals = self.sample_normals[nearest]
        quality = epsilon_quality(
            points,
            -normals,
            mu=self.mu,
            edges=self.cone_edges,
            torque_scale=self.torque_scale,
            torsional_friction=self.torsional_friction,
            center=self.centre,
        )
        outcome = "force_closure" if quality.force_closure else "no_force_closure"
        return TrialResult(
            outcome,
            quality.epsilon,
            quality.volume,
            contact_points=points,
            contact_normals=normals,
            contact_links=links,
            **pose,
        )

    def _close(self, joints):
        """Close all fingers from ``joints`` (name -> value) by conservative advancement against
        the surface samples; returns the closed joint values."""
        joints = dict(joints)
        fingers = [
            (
                finger,
                np.array([self.joint_index[joint] + 1 for joint in finger.joints]),
                np.ones(len(finger.joints), bool),
                levers,
            )
            for finger, levers in zip(self.hand.fingers, self.levers)
        ]
        cache = {}
        for _ in range(_MAX_CLOSE_STEPS):
            if not any(moving.any() for _, _, moving, _ in fingers):
                break
            wanted = np.zeros(len(self.links), bool)  # the links that moving joints carry
            for _, columns, moving, _ in fingers:
                if moving.any():
                    wanted[columns[np.argmax(moving) :]] = True
            distances = self._finger_distances(cache, wanted)
            moved = {}
            for finger, columns, moving, levers in fingers:
                finger_d = distances[columns]
                touching = np.flatnonzero(finger_d <= self.touch)
                if touching.size:
                    moving[: touching.max() + 1] = False  # breakaway: joints beyond the contact go on
                if not moving.any():
                    continue
                ratios = np.where(moving, finger.ratios, 0.0)
                motion = ratios @ levers  # per link: metres moved per unit of closing
                carried = motion > 0
                # no point of any link moves farther than that link's clearance: nothing tunnels
                advance = (np.maximum(finger_d[carried] - self.touch / 2, self.touch / 2) / motion[carried]).min()
                for position in np.flatnonzero(moving):
                    joint = finger.joints[position]
                    upper = self.hand.limits[joint][1]
                    joints[joint] = moved[joint] = min(joints[joint] + finger.ratios[position] * advance, upper)
                    if joints[joint] >= upper:
                        moving[position] = False
            self._set_joints(moved)
        return joints

    def close(self):
        """Disconnect the pybullet client."""
        if self.client is not None:
            pybullet.disconnect(physicsClientId=self.client)
            self.client = None


@dataclass(frozen=True)
class InteriorGrid:
    """Voxels of a closed surface sample cloud: ``inside`` marks the interior (what a flood fill
    from the border cannot reach past the dilated surface voxels: deep points only, a voxel or
    two from the surface is left to the caller), ``clearance`` the distance (m) between a
    voxel's centre and the nearest surface voxel's centre."""

    origin: np.ndarray
    voxel: float
    inside: np.ndarray
    clearance: np.ndarray
    bounds: np.ndarray

    @classmethod
    def build(cls, surface, *, voxels_per_spacing=3.0, max_cells=160, margin_cells=10):
        """``voxel`` = the larger of 3 sample spacings (so surface voxels leave no gap) and the
        bounding-box diagonal / ``max_cells``; the grid reaches ``margin_cells`` past the box."""
        from scipy import ndimage

        low, high = surface.points.min(axis=0), surface.points.max(axis=0)
        voxel = max(voxels_per_spacing * surface.spacing, np.linalg.norm(high - low) / max_cells)
        origin = low - margin_cells * voxel
        shape = np.ceil((high - low) / voxel).astype(int) + 2 * margin_cells + 1
        shell = np.zeros(shape, bool)
        shell[tuple(np.floor((surface.points - origin) / voxel).astype(int).T)] = True
        clearance = (ndimage.distance_transform_edt(~shell) * voxel).astype(np.float32)
        # random samples leave gaps wider than the median spacing: a one-voxel dilation seals them
        sealed = ndimage.binary_dilation(shell)
        return cls(origin, voxel, ndimage.binary_fill_holes(sealed) & ~sealed, clearance, np.array([low, high]))

    def _cells(self, points):
        cell = np.floor((points - self.origin) / self.voxel).astype(np.int64)
        return cell, ((cell >= 0) & (cell < self.inside.shape)).all(axis=1)

    def contains(self, points):
        """(n, 3) points -> bool (n,): inside an interior voxel."""
        cell, valid = self._cells(points)
        result = np.zeros(len(points), bool)
        result[valid] = self.inside[tuple(cell[valid].T)]
        return result

    def distance_bound(self, points):
        """(n, 3) points -> (n,) lower bound (m) on their distance to the samples: the voxel
        clearance less a voxel diagonal, or outside the grid the distance to the samples' box."""
        outside = np.maximum(np.maximum(self.bounds[0] - points, points - self.bounds[1]), 0.0)
        bound = np.linalg.norm(outside, axis=1)
        cell, valid = self._cells(points)
        bound[valid] = np.maximum(bound[valid], self.clearance[tuple(cell[valid].T)] - np.sqrt(3) * self.voxel)
        return bound


def _half_extents(geometry, dimensions, hand_name):
    """Half extents (3,) of the box around a pybullet collision shape, in its local frame."""
    if geometry == pybullet.GEOM_BOX:
        return np.asarray(dimensions) / 2
    if geometry == pybullet.GEOM_SPHERE:
        return np.full(3, dimensions[0])
    if geometry in (pybullet.GEOM_CAPSULE, pybullet.GEOM_CYLINDER):
        length, radius = dimensions[0], dimensions[1]
        return np.array([radius, radius, length / 2 + (radius if geometry == pybullet.GEOM_CAPSULE else 0)])
    raise BadParamsError(f"hand {hand_name}: finger links must use box, sphere, capsule or cylinder collision shapes")


def _cover_spheres(halves, max_cell=0.02):
    """Spheres covering boxes of half extents (n, 3): each box is cut into near-cubic cells
    no wider than ``max_cell`` (m), one sphere round each.

    Returns centres (m, 3) in box frames, radii (m,), owner box (m,) and the radii of the
    spheres inscribed in the cells (m,)."""
    cover = [], [], [], []
    for index, half in enumerate(halves):
        cells = np.maximum(1, np.ceil(2 * half / min(2 * half.min(), max_cell) - 1e-9)).astype(int)
        size = 2 * half / cells
        axes = [(np.arange(count) + 0.5) * step - extent for count, step, extent in zip(cells, size, half)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        cover[0].append(grid)
        cover[1].append(np.full(len(grid), np.linalg.norm(size) / 2))
        cover[2].append(np.full(len(grid), index))
        cover[3].append(np.full(len(grid), size.min() / 2))
    return tuple(np.concatenate(part) for part in cover)


_SIGNS = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T


def _box_corners(centre, rotation, half):
    """(8, 3) corners of a box with world ``centre`` (3,), ``rotation`` (3, 3), ``half`` extents (3,)."""
    return centre + (_SIGNS * half) @ rotation.T


def _matrices(quaternions):
    """(n, 4) unit quaternions (x, y, z, w) -> (n, 3, 3) rotation matrices."""
    x, y, z, w = quaternions.T
    return np.column_stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - z * w),
            2 * (x * z + y * w),
            2 * (x * y + z * w),
            1 - 2 * (x * x + z * z),
            2 * (y * z - x * w),
            2 * (x * z - y * w),
            2 * (y * z + x * w),
            1 - 2 * (x * x + y * y),
        ]
    ).reshape(-1, 3, 3)


def _patch_ends(points, links, distances, min_length=0.002):
    """Two contacts per touching link: its closest point and the touching point farthest from it.

    A link lying on a face or along a cylinder touches a patch or a line, which pybullet reports
    as one point per triangle; the ends of the patch are the standard two-point discretisation
    of a line contact, and they keep the 6D wrench hull small enough for Qhull to be fast.
    """
    order = np.lexsort((distances, links))
    points, links = points[order], links[order]
    first = np.flatnonzero(np.r_[True, links[1:] != links[:-1]])
    closest = np.repeat(first, np.diff(np.r_[first, len(links)]))
    reach = np.linalg.norm(points - points[closest], axis=1)
    group = np.cumsum(np.r_[True, links[1:] != links[:-1]]) - 1
    by_reach = np.lexsort((-reach, group))
    farthest = by_reach[np.flatnonzero(np.r_[True, group[by_reach][1:] != group[by_reach][:-1]])]
    farthest = farthest[reach[farthest] > min_length]
    keep = np.sort(np.concatenate([first, farthest]))
    return points[keep], links[keep]


def _quaternion(rotation):
    """(x, y, z, w) of a proper rotation matrix."""
    from scipy.spatial.transform import Rotation

    return tuple(Rotation.from_matrix(rotation).as_quat())
